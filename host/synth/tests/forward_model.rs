//! The forward model is exact: at sampled pixels, the rendered noise-free value equals
//! `rho cos(theta_i) / (C D²)` computed independently from the truth (analytic ray/surface
//! intersection, analytic shadow test), i.e. the method's equation 2 inverts the renderer.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::too_many_arguments,
    clippy::needless_range_loop
)] // test helpers

use glam::{DVec2, DVec3};
use skinbrdf_core::ShadingFrame;
use skinbrdf_session::{ImageRole, Session};
use skinbrdf_synth::layout::{build_rig, plan_shots};
use skinbrdf_synth::photograph::Renderer;
use skinbrdf_synth::shape::Shape;
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// The file stores V rounded to the nearest code: half a quantum, with slack for the rounding
/// of the quantum itself.
const QUANTA: f64 = 0.51;
/// Relative `f32` rounding of V on its way through the renderer.
const REL_TOL: f64 = 2e-6;

/// Relative tolerance of the in-memory comparison: f32 storage of the pixel (6e-8) and the
/// f32 BVH hit refined onto the analytic surface in f64; 1e-5 leaves a wide margin.
const EXACT_REL_TOL: f64 = 1e-5;
/// Pixels seen within ~6 degrees of the silhouette are not compared (see `expected`).
const GRAZING_VIEW_COS: f64 = 0.1;

struct Expected {
    v: [f64; 3],
    d_m: f64,
    cos_i: f64,
    rho: [f64; 3],
}

/// Independent evaluation of one pixel-centre ray from the truth quantities.
fn expected(
    shape: &Shape,
    truth_cam: &skinbrdf_core::CameraModel,
    world_from_camera: &skinbrdf_core::Pose,
    world_from_head: &skinbrdf_core::Pose,
    light_world: DVec3,
    brdf: &skinbrdf_brdf::BrdfModel,
    c: [f64; 3],
    px: DVec2,
) -> Option<Expected> {
    let head_from_world = world_from_head.inverse();
    let dir_w = world_from_camera.transform_vector(truth_cam.pixel_ray(px)?);
    let o_h = head_from_world.transform_point(world_from_camera.translation_m);
    let d_h = head_from_world.transform_vector(dir_w);
    let t = shape.intersect_analytic(o_h, d_h)?;
    let p = o_h + d_h * t;
    let n = shape.normal(p);
    // Silhouette pixels: along a ray this grazing, the tessellation's few-µm offset from the
    // analytic surface becomes up to a millimetre, beyond the renderer's refinement window.
    if n.dot(-d_h) < GRAZING_VIEW_COS {
        return None;
    }
    let light = head_from_world.transform_point(light_world);
    let to = light - p;
    let d_m = to.length();
    let wi = to / d_m;
    let cos_i = n.dot(wi);
    if cos_i <= 0.0 {
        return None;
    }
    // Analytic shadow test.
    if let Some(ts) = shape.intersect_analytic(p + n * 1e-4, wi) {
        if ts < d_m {
            return None;
        }
    }
    let f = ShadingFrame::from_normal(n);
    let rho = brdf.eval(f.to_local(wi), f.to_local(-d_h));
    let v = std::array::from_fn(|k| rho[k] * cos_i / (c[k] * d_m * d_m));
    Some(Expected { v, d_m, cos_i, rho })
}

#[test]
fn rendered_skin_radiance_matches_equation_2_in_memory() {
    for name in [
        "default",
        "sphere",
        "cylinder",
        "near-mirror",
        "strong-distortion",
        "long-lens",
    ] {
        let mut scene = Scene::load(name).unwrap();
        scene.camera.width_px = 400;
        scene.camera.height_px = 266;
        scene.session.measurement_images = 5;
        let rig = build_rig(&scene);
        let shots = plan_shots(&scene, &rig);
        let mut renderer = Renderer::new(&scene, &rig).unwrap();
        renderer.set_samples_per_pixel(1);
        let mut checked = 0;
        for shot in shots.iter().filter(|s| s.role == ImageRole::Measurement) {
            let r = renderer.render(shot, &rig, 7, true);
            for y in 0..r.height {
                for x in 0..r.width {
                    let i = (y * r.width + x) as usize;
                    if !r.forehead[i] || (x + y) % 3 != 0 {
                        continue;
                    }
                    let px = DVec2::new(x as f64, y as f64);
                    let Some(e) = expected(
                        &rig.shape,
                        &rig.camera,
                        &shot.world_from_camera,
                        &shot.world_from_head,
                        rig.light_position_m(),
                        &scene.skin,
                        scene.radiometry.calibration_c,
                        px,
                    ) else {
                        continue;
                    };
                    if e.cos_i < 0.05 {
                        continue; // tessellation edge cases at the terminator
                    }
                    for k in 0..3 {
                        let got = f64::from(r.v[i][k]);
                        // Equation 2: rho = C D² V / cos(theta_i).
                        let rho_est =
                            scene.radiometry.calibration_c[k] * e.d_m * e.d_m * got / e.cos_i;
                        let tol = EXACT_REL_TOL * e.rho[k] + 1e-12;
                        assert!(
                            (rho_est - e.rho[k]).abs() <= tol,
                            "{name} pixel ({x},{y}) channel {k}: equation 2 gives {rho_est}, true rho {}, V {got} vs {}",
                            e.rho[k],
                            e.v[k]
                        );
                    }
                    checked += 1;
                }
            }
        }
        assert!(checked > 40, "{name}: only {checked} pixels checked");
    }
}

#[test]
fn written_session_matches_equation_2_through_files_and_truth() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = Scene::load("default").unwrap();
    scene.session.measurement_images = 4;
    let opts = SynthOptions {
        resolution: Some((400, 266)),
        capture: None,
        noise_free: true,
        samples_per_pixel: Some(1),
        studio: false,
        studio_only: false,
    };
    generate(&scene, &opts, dir.path()).unwrap();
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    let truth = s.load_truth().unwrap().unwrap();
    let shape = Shape::from_scene(&scene.geometry);
    let lin = s.linearization(0);
    let quantum = 1.0 / (lin.white_level.unwrap() - lin.black_level);
    let mut checked = 0;
    for (i, entry) in s.images_with_role(ImageRole::Measurement) {
        let img = s.load_image(i).unwrap();
        let it = truth.image(&entry.file).unwrap();
        let mask =
            skinbrdf_session::load_mask(&s.path(it.forehead_mask.as_ref().unwrap())).unwrap();
        for y in 0..img.height {
            for x in 0..img.width {
                if !mask.get(x, y) {
                    continue;
                }
                let Some(e) = expected(
                    &shape,
                    &truth.camera,
                    &it.world_from_camera,
                    &it.world_from_head,
                    truth.light_position_m,
                    &truth.brdf,
                    truth.calibration_c,
                    DVec2::new(x as f64, y as f64),
                ) else {
                    continue;
                };
                if e.cos_i < 0.05 || img.is_saturated(x, y) {
                    continue;
                }
                let v = img.get(x, y).unwrap();
                for k in 0..3 {
                    let got = f64::from(v[k]);
                    assert!(
                        (got - e.v[k]).abs() <= QUANTA * quantum + REL_TOL * e.v[k],
                        "{} ({x},{y}) channel {k}: file gives V {got}, truth {}",
                        entry.file,
                        e.v[k]
                    );
                }
                checked += 1;
            }
        }
    }
    assert!(checked > 100, "only {checked} pixels checked");
}

#[test]
fn culling_does_not_change_the_image() {
    let mut scene = Scene::load("strong-distortion").unwrap();
    scene.camera.width_px = 240;
    scene.camera.height_px = 160;
    scene.session.measurement_images = 3;
    let rig = build_rig(&scene);
    let shots = plan_shots(&scene, &rig);
    let renderer = Renderer::new(&scene, &rig).unwrap();
    for shot in shots.iter().step_by(2) {
        let a = renderer.render(shot, &rig, 3, true);
        let b = renderer.render(shot, &rig, 3, false);
        let differ = a.v.iter().zip(&b.v).filter(|(p, q)| p != q).count();
        assert_eq!(
            differ, 0,
            "{}: {differ} pixels differ with culling",
            shot.file
        );
        assert!(a.forehead == b.forehead && a.targets == b.targets);
        assert!(a.rays < b.rays || shot.role != ImageRole::Measurement);
    }
}
