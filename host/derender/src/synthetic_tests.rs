//! End-to-end tests on a scene rendered here analytically: an exact sphere (the "head") seen by
//! a distorted camera from several poses, lit by a point light, with a Lafortune BRDF; and a
//! Lambertian standard. Derendering uses a tessellated copy of the sphere, so the test covers
//! the mesh approximation, the planar-fit normals, the ray/pose/distortion chain and the
//! radiometry (equations 2 and 3).

#![allow(clippy::manual_is_multiple_of, clippy::needless_range_loop)]

use glam::{DQuat, DVec2, DVec3};
use skinbrdf_brdf::{BrdfModel, Lafortune, LafortuneLobe};
use skinbrdf_core::{BrdfAngles, BrownConrady, CameraModel, Pose, TriMesh};
use skinbrdf_mesh::NormalMethod;

use crate::*;

const RADIUS: f64 = 0.08;
const C_TRUE: [f64; 3] = [2.0, 2.5, 3.0];

fn brdf() -> BrdfModel {
    BrdfModel::Lafortune(Lafortune {
        diffuse_albedo: [0.55, 0.35, 0.25],
        lobes: vec![LafortuneLobe {
            cxy: [-0.9; 3],
            cz: [0.9; 3],
            exponent: [12.0; 3],
        }],
    })
}

fn camera() -> CameraModel {
    let mut c = CameraModel::from_fov(320, 240, 30f64.to_radians());
    c.distortion = BrownConrady {
        k1: -0.08,
        k2: 0.01,
        ..BrownConrady::NONE
    };
    c
}

fn uv_sphere(r: f32, n_lat: u32, n_lon: u32) -> TriMesh {
    skinbrdf_mesh::shapes::uv_sphere(DVec3::ZERO, f64::from(r), n_lat, n_lon)
}

/// Renders the exact sphere (head frame centre at the origin) analytically: one ray per pixel
/// centre, `V = rho cos θ_i / (C D²)`.
fn render_sphere(cam: &CameraModel, wfc: &Pose, wfh: &Pose, light_w: DVec3) -> OwnedImage {
    let hfw = wfh.inverse();
    let hfc = hfw * *wfc;
    let light = hfw.transform_point(light_w);
    let o = hfc.translation_m;
    let model = brdf();
    let n = (cam.width_px * cam.height_px) as usize;
    let mut rgb = vec![[0.0f32; 3]; n];
    for y in 0..cam.height_px {
        for x in 0..cam.width_px {
            let Some(dc) = cam.pixel_ray(DVec2::new(x as f64, y as f64)) else {
                continue;
            };
            let d = hfc.transform_vector(dc);
            let b = o.dot(d);
            let disc = b * b - (o.length_squared() - RADIUS * RADIUS);
            if disc <= 0.0 {
                continue;
            }
            let t = -b - disc.sqrt();
            let p = o + d * t;
            let nrm = p.normalize();
            let wi = (light - p).normalize();
            let dist = (light - p).length();
            let we = -d;
            if nrm.dot(wi) <= 0.0 {
                continue;
            }
            let a = BrdfAngles::from_world(nrm, wi, we);
            let rho = model.eval_angles(a.theta_i_rad, a.theta_e_rad, a.phi_d_rad);
            rgb[(y * cam.width_px + x) as usize] =
                std::array::from_fn(|c| (rho[c] * nrm.dot(wi) / (C_TRUE[c] * dist * dist)) as f32);
        }
    }
    OwnedImage {
        cfa: None,
        width: cam.width_px,
        height: cam.height_px,
        rgb,
        saturated: vec![false; n],
        mask: None,
        targets: None,
    }
}

/// Renders a Lambertian standard (albedo 0.99) in the plane z = 0 of its frame.
fn render_standard(
    cam: &CameraModel,
    wfc: &Pose,
    wfs: &Pose,
    light_w: DVec3,
    size: f64,
) -> OwnedImage {
    let sfw = wfs.inverse();
    let sfc = sfw * *wfc;
    let light = sfw.transform_point(light_w);
    let o = sfc.translation_m;
    let n = (cam.width_px * cam.height_px) as usize;
    let mut rgb = vec![[0.0f32; 3]; n];
    for y in 0..cam.height_px {
        for x in 0..cam.width_px {
            let Some(dc) = cam.pixel_ray(DVec2::new(x as f64, y as f64)) else {
                continue;
            };
            let d = sfc.transform_vector(dc);
            if d.z >= 0.0 {
                continue;
            }
            let t = -o.z / d.z;
            let p = o + d * t;
            if p.x.abs() > size / 2.0 || p.y.abs() > size / 2.0 {
                continue;
            }
            let wi = (light - p).normalize();
            let dist = (light - p).length();
            rgb[(y * cam.width_px + x) as usize] = std::array::from_fn(|c| {
                (0.99 / std::f64::consts::PI * wi.z / (C_TRUE[c] * dist * dist)) as f32
            });
        }
    }
    OwnedImage {
        cfa: None,
        width: cam.width_px,
        height: cam.height_px,
        rgb,
        saturated: vec![false; n],
        mask: None,
        targets: None,
    }
}

struct Scene {
    inputs: DerenderInputs,
    images: Vec<OwnedImage>,
}

fn scene() -> Scene {
    let cam = camera();
    let light = DVec3::new(0.12, -0.08, 0.7);
    // The head sits at the world origin, turned differently per image; the camera is fixed.
    let wfc = Pose::look_at(DVec3::new(0.0, 0.0, 0.75), DVec3::ZERO, DVec3::Y).unwrap();
    let mut images = Vec::new();
    let mut measurements = Vec::new();
    for k in 0..4 {
        let yaw = -0.5 + 0.33 * k as f64;
        let wfh = Pose::new(
            DQuat::from_rotation_y(yaw) * DQuat::from_rotation_x(0.2),
            DVec3::new(0.005 * k as f64, 0.0, 0.0),
        );
        images.push(render_sphere(&cam, &wfc, &wfh, light));
        measurements.push((
            k,
            ImagePoses {
                world_from_camera: wfc,
                world_from_head: wfh,
            },
        ));
    }
    let wfs = Pose::new(DQuat::from_rotation_x(0.3), DVec3::new(0.0, 0.0, 0.05));
    images.push(render_standard(&cam, &wfc, &wfs, light, 0.1));
    Scene {
        inputs: DerenderInputs {
            camera: cam,
            light_position_m: light,
            calibration: CalibrationInput::Standard {
                brdf: BrdfModel::Lambertian { albedo: [0.99; 3] },
                size_m: [0.1, 0.1],
                world_from_standard: wfs,
                images: vec![(4, wfc)],
            },
            measurements,
            pose_source: PoseSource::Truth,
        },
        images,
    }
}

fn geometry(normals: NormalMethod) -> Geometry {
    let roi = Roi {
        centre_m: DVec3::new(0.0, 0.0, RADIUS),
        radius_m: 0.06,
    };
    Geometry::new(uv_sphere(RADIUS as f32, 160, 320), normals, Some(roi)).unwrap()
}

#[test]
fn noise_free_sphere_derenders_within_half_a_percent() {
    let s = scene();
    let geom = geometry(NormalMethod::PlanarFit { radius_m: 0.004 });
    assert!(!geom.can_self_shadow, "a sphere is convex");
    let cfg = DerenderConfig::DEFAULT;
    let r = derender_with_loader(&geom, &s.inputs, &cfg, |i| Ok(s.images[i].clone())).unwrap();
    let cal = r.calibration.as_ref().unwrap();
    for c in 0..3 {
        assert!(
            (cal.c[c] - C_TRUE[c]).abs() / C_TRUE[c] < 1e-3,
            "C {:?} vs {C_TRUE:?}",
            cal.c
        );
        assert!(cal.rel_spread[c] < 1e-3);
    }
    assert!(!r.shadow_rays && r.shadow_rays_cast == 0);
    assert!(r.counts.kept > 5000, "{:?}", r.counts);
    assert!(r.counts.grazing > 0 && r.counts.off_region > 0);
    let e = truth_error(&r.samples, &brdf()).unwrap();
    assert!(e.median_rel_error < 0.005, "{e:?}");
    // Counts add up.
    assert_eq!(r.counts.dropped() + r.counts.kept, r.counts.considered);
}

/// How far a sample's recorded surface point may lie from its pixel's ray, metres: f32
/// positions and barycentrics at 0.75 m from the camera are good to ~0.1 µm; 1 µm is a
/// thousandth of the test camera's pixel footprint (~1.3 mm), so a sample attributed to a
/// neighbouring pixel's point, or to another triangle, fails.
const ON_RAY_TOL_M: f64 = 1e-6;
/// How far inside the exact sphere the recorded point may lie, metres: a triangle of the
/// tessellation (edges up to 1.6 mm, circumradius α·R with α ≈ 0.014 on an 8 cm sphere) lies
/// up to R·α²/2 ≈ 8 µm inside it.
const TESSELLATION_TOL_M: f64 = 1e-5;
/// How far along the ray the recorded point may lie from where the ray first meets the exact
/// sphere, metres: the tessellation's gap seen at up to 75° from the normal (8 µm / cos 75° ≈
/// 31 µm), far below the centimetres between the ray's near and far intersections, so a point
/// on the far side fails.
const FRONT_TOL_M: f64 = 1e-4;
/// Texture coordinates: f32 interpolation of coordinates of order 1.
const UV_TOL: f32 = 1e-5;
/// Extent of the planar texture map of the test's textured sphere, metres.
const UV_EXTENT_M: f32 = 0.2;

/// The test's texture map: the sphere's front projected onto the xy plane, linear in the
/// position, so its barycentric blend over a triangle is exact.
fn planar_uv(p: glam::Vec3) -> glam::Vec2 {
    glam::Vec2::new(p.x / UV_EXTENT_M + 0.5, p.y / UV_EXTENT_M + 0.5)
}

#[test]
fn samples_record_the_surface_point_their_pixel_sees() {
    let s = scene();
    let plain = geometry(NormalMethod::Vertex);
    let uv: skinbrdf_mesh::CornerUv = (0..plain.mesh.indices.len())
        .map(|t| Some(plain.mesh.triangle(t).map(planar_uv)))
        .collect();
    let textured = geometry(NormalMethod::Vertex).with_texture_coordinates(Some(uv));
    let cfg = DerenderConfig {
        stride: 3,
        ..DerenderConfig::DEFAULT
    };
    let load = |i: usize| Ok(s.images[i].clone());
    let without = derender_with_loader(&plain, &s.inputs, &cfg, load).unwrap();
    let with = derender_with_loader(&textured, &s.inputs, &cfg, load).unwrap();
    assert!(with.samples.len() > 500, "{:?}", with.counts);
    // Texture coordinates change nothing else.
    assert_eq!(without.samples.len(), with.samples.len());
    for (a, b) in without.samples.iter().zip(&with.samples) {
        assert_eq!(a.surface.triangle, b.surface.triangle);
        assert_eq!(a.surface.barycentric, b.surface.barycentric);
        assert_eq!(
            a.surface.texture_uv(),
            None,
            "a scan without texture coordinates"
        );
        assert_eq!((a.pixel, a.rho), (b.pixel, b.rho));
    }
    let cam = &s.inputs.camera;
    let mesh = &textured.mesh;
    for smp in &with.samples {
        let [w0, w1, w2] = smp
            .surface
            .weights()
            .expect("a derendered sample has a point");
        assert!(
            [w0, w1, w2]
                .iter()
                .all(|w| (-1e-6..=1.0 + 1e-6).contains(w)),
            "{:?}",
            smp.surface
        );
        let tri = mesh.triangle(smp.surface.triangle as usize);
        let p = (tri[0].as_dvec3() * f64::from(w0))
            + tri[1].as_dvec3() * f64::from(w1)
            + tri[2].as_dvec3() * f64::from(w2);
        // The pixel's own ray (the exact lens model, not the derender's table) in the head frame.
        let (_, poses) = s
            .inputs
            .measurements
            .iter()
            .find(|(k, _)| *k == usize::from(smp.image_index))
            .expect("the sample's image");
        let hfc = poses.world_from_head.inverse() * poses.world_from_camera;
        let px = DVec2::new(f64::from(smp.pixel[0]), f64::from(smp.pixel[1]));
        let d = hfc
            .transform_vector(cam.pixel_ray(px).expect("ray"))
            .normalize();
        let o = hfc.translation_m;
        let off_ray = (p - o).cross(d).length();
        assert!(off_ray < ON_RAY_TOL_M, "{off_ray} m off the ray: {smp:?}");
        // On the sphere, where the ray first meets it.
        let inside = RADIUS - p.length();
        assert!(
            (-ON_RAY_TOL_M..TESSELLATION_TOL_M).contains(&inside),
            "{inside} m inside the sphere: {smp:?}"
        );
        let b = o.dot(d);
        let t_sphere = -b - (b * b - (o.length_squared() - RADIUS * RADIUS)).sqrt();
        let along = ((p - o).dot(d) - t_sphere).abs();
        assert!(along < FRONT_TOL_M, "{along} m from the near hit: {smp:?}");
        // The texture coordinate is the map's value at the point.
        let want = planar_uv(p.as_vec3());
        let got = smp
            .surface
            .texture_uv()
            .expect("the scan has texture coordinates");
        assert!(
            (got[0] - want.x).abs() < UV_TOL && (got[1] - want.y).abs() < UV_TOL,
            "{got:?} vs {want}"
        );
    }
}

#[test]
fn known_c_forced_shadows_and_stride() {
    let mut s = scene();
    s.inputs.calibration = CalibrationInput::Known(C_TRUE);
    let geom = geometry(NormalMethod::Vertex);
    let cfg = DerenderConfig {
        stride: 2,
        shadows: ShadowMode::Always,
        ..DerenderConfig::DEFAULT
    };
    let r = derender_with_loader(&geom, &s.inputs, &cfg, |i| Ok(s.images[i].clone())).unwrap();
    assert!(r.shadow_rays_cast > 0);
    // Lit hemisphere of a sphere: shadow rays find nothing within the grazing bound.
    assert_eq!(r.counts.shadowed, 0);
    let e = truth_error(&r.samples, &brdf()).unwrap();
    assert!(e.median_rel_error < 0.005, "{e:?}");
    for smp in &r.samples {
        assert!(smp.pixel[0] % 2 == 0 && smp.pixel[1] % 2 == 0);
    }
}

#[test]
fn saturation_floor_and_masks_are_counted() {
    let s = scene();
    let geom = geometry(NormalMethod::Vertex);
    let mut img = s.images[0].clone();
    let n = img.rgb.len();
    img.saturated = (0..n).map(|i| i % 7 == 0).collect();
    img.mask = Some((0..n).map(|i| i % 5 != 0).collect());
    // Damaged pixels: NaN is counted as non-finite, not as dark.
    for i in (0..n).filter(|i| i % 13 == 0) {
        img.rgb[i][1] = f32::NAN;
    }
    img.targets = Some(
        (0..n)
            .map(|i| if i % 11 == 0 { 0.0 } else { f32::INFINITY })
            .collect(),
    );
    let mut inputs = s.inputs.clone();
    inputs.calibration = CalibrationInput::Known(C_TRUE);
    inputs.measurements.truncate(1);
    let cfg = DerenderConfig {
        noise_floor: 0.05,
        ..DerenderConfig::DEFAULT
    };
    let r = derender_with_loader(&geom, &inputs, &cfg, |_| Ok(img.clone())).unwrap();
    let c = r.counts;
    assert!(
        c.off_mask > 0
            && c.on_target > 0
            && c.saturated > 0
            && c.below_noise_floor > 0
            && c.non_finite > 0,
        "{c:?}"
    );
    assert_eq!(c.dropped() + c.kept, c.considered);
    for smp in &r.samples {
        let i = smp.pixel[1] as usize * img.width as usize + smp.pixel[0] as usize;
        assert!(i % 7 != 0 && i % 5 != 0 && i % 11 != 0 && i % 13 != 0);
    }
}

#[test]
fn bad_config_is_refused() {
    let s = scene();
    let geom = geometry(NormalMethod::Vertex);
    for cfg in [
        DerenderConfig {
            grazing_limit_deg: 90.0,
            ..DerenderConfig::DEFAULT
        },
        DerenderConfig {
            stride: 0,
            ..DerenderConfig::DEFAULT
        },
        DerenderConfig {
            noise_floor: f64::NAN,
            ..DerenderConfig::DEFAULT
        },
    ] {
        assert!(matches!(
            derender_with_loader(&geom, &s.inputs, &cfg, |i| Ok(s.images[i].clone())),
            Err(DerenderError::Config { .. })
        ));
    }
}

/// One measurement image with known C: the counts of `img` derendered alone.
fn counts_of(img: &OwnedImage) -> FilterCounts {
    let s = scene();
    let geom = geometry(NormalMethod::Vertex);
    let mut inputs = s.inputs.clone();
    inputs.calibration = CalibrationInput::Known(C_TRUE);
    inputs.measurements.truncate(1);
    let r = derender_with_loader(
        &geom,
        &inputs,
        &DerenderConfig::DEFAULT,
        |_| Ok(img.clone()),
    )
    .unwrap();
    assert_eq!(r.counts.dropped() + r.counts.kept, r.counts.considered);
    r.counts
}

#[test]
fn a_ray_that_misses_the_scan_under_a_target_counts_no_surface() {
    let clean = scene().images[0].clone();
    let base = counts_of(&clean);
    // The region's bounding box reaches past the sphere's outline: some rays miss it.
    assert!(base.no_surface > 0, "{base:?}");
    // A target at distance 0 hides every surface: it projects onto every pixel.
    let mut img = clean.clone();
    img.targets = Some(vec![0.0; img.rgb.len()]);
    let c = counts_of(&img);
    assert_eq!(c.no_surface, base.no_surface, "{c:?}");
    assert_eq!(c.kept, 0, "{c:?}");
    assert_eq!(
        c.on_target,
        base.considered - base.off_mask - base.no_ray - base.no_surface,
        "{c:?}"
    );
}

#[test]
fn non_finite_values_are_not_below_the_noise_floor() {
    let clean = scene().images[0].clone();
    let base = counts_of(&clean);
    let mut img = clean.clone();
    let mut poisoned = 0u64;
    for (i, v) in img.rgb.iter_mut().enumerate() {
        // Only pixels that were kept: each moves from kept to one reason.
        if i % 13 == 0
            && v.iter()
                .all(|&c| f64::from(c) >= DerenderConfig::DEFAULT.noise_floor)
        {
            v[i % 3] = if i % 2 == 0 {
                f32::NAN
            } else {
                f32::NEG_INFINITY
            };
            poisoned += 1;
        }
    }
    let c = counts_of(&img);
    assert!(c.non_finite > 0, "{c:?}");
    assert_eq!(c.below_noise_floor, base.below_noise_floor, "{c:?}");
    assert_eq!(c.kept + c.non_finite, base.kept, "{c:?}");
    assert!(c.non_finite <= poisoned);
}

/// A camera raw image loaded per photosite: each pixel keeps the channel of its filter
/// (phase `phase` at pixel `(0, 0)`), the other two NaN.
fn mosaic(img: &OwnedImage, phase: skinbrdf_session::BayerPhase) -> OwnedImage {
    let w = img.width as usize;
    let rgb = img
        .rgb
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let c = usize::from(phase.colour_at(i % w, i / w).dng_code());
            std::array::from_fn(|k| if k == c { p[k] } else { f32::NAN })
        })
        .collect();
    OwnedImage {
        cfa: Some(phase),
        rgb,
        ..img.clone()
    }
}

#[test]
fn photosites_give_partial_samples_as_accurate_as_full_pixels() {
    // The per-channel medians of a subset of the same pixels: sampling differences only.
    const SAME_PIXELS_MEDIAN_PP: f64 = 0.03;
    let s = scene();
    let geom = geometry(NormalMethod::PlanarFit { radius_m: 0.004 });
    let cfg = DerenderConfig::DEFAULT;
    let full = derender_with_loader(&geom, &s.inputs, &cfg, |i| Ok(s.images[i].clone())).unwrap();
    let phase = skinbrdf_session::BayerPhase::Gbrg;
    let photo =
        derender_with_loader(&geom, &s.inputs, &cfg, |i| Ok(mosaic(&s.images[i], phase))).unwrap();
    // C per channel from the standard's photosites of that channel.
    let cal = photo.calibration.as_ref().unwrap();
    for c in 0..3 {
        assert!(
            (cal.c[c] - C_TRUE[c]).abs() / C_TRUE[c] < 1e-3,
            "C {:?} vs {C_TRUE:?}",
            cal.c
        );
    }
    // One sample per pixel, one channel each: the pixel's own.
    assert_eq!(photo.counts.kept, full.counts.kept, "{:?}", photo.counts);
    assert_eq!(
        photo.counts.dropped() + photo.counts.kept,
        photo.counts.considered
    );
    for smp in &photo.samples {
        let own = usize::from(
            phase
                .colour_at(usize::from(smp.pixel[0]), usize::from(smp.pixel[1]))
                .dng_code(),
        );
        assert!(smp.is_partial());
        assert_eq!(smp.measured(), std::array::from_fn(|k| k == own), "{smp:?}");
    }
    let e_full = truth_error(&full.samples, &brdf()).unwrap();
    let e_photo = truth_error(&photo.samples, &brdf()).unwrap();
    for c in 0..3 {
        let (a, b) = (
            e_full.median_rel_error_rgb[c].unwrap(),
            e_photo.median_rel_error_rgb[c].unwrap(),
        );
        assert!(
            (a - b).abs() * 100.0 <= SAME_PIXELS_MEDIAN_PP,
            "channel {c}: full {a} photosite {b}"
        );
    }
}

#[test]
fn a_photosite_counts_only_its_own_channel() {
    let s = scene();
    let mut img = mosaic(&s.images[0], skinbrdf_session::BayerPhase::Rggb);
    // Dark or broken values in channels a photosite did not measure change nothing.
    for (i, p) in img.rgb.iter_mut().enumerate() {
        let x = i % img.width as usize;
        let y = i / img.width as usize;
        let own = usize::from(
            skinbrdf_session::BayerPhase::Rggb
                .colour_at(x, y)
                .dng_code(),
        );
        for (k, v) in p.iter_mut().enumerate() {
            if k != own {
                *v = if (x + y) % 2 == 0 { -1.0 } else { f32::NAN };
            }
        }
    }
    let cfa = counts_of(&img);
    let plain = counts_of(&mosaic(&s.images[0], skinbrdf_session::BayerPhase::Rggb));
    assert_eq!(cfa, plain);
    assert_eq!(plain.non_finite, 0, "{plain:?}");
}
