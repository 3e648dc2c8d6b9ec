//! Derendering a `skinbrdf-session` directory: [`derender_session`].
//!
//! Inputs are resolved in this order, and the report says where each came from:
//!
//! * **camera**: `[camera]` when calibrated, else `truth.json`'s camera (synthetic sessions);
//! * **poses**: per image `world_from_camera` / `world_from_head` from `session.toml` (a
//!   stationary sample reuses the first head pose), else `truth.json`, or the pose stage's
//!   result (`PoseChoice::Estimated`, `out/poses.json`);
//! * **light**: `known.light_position_m`, else `known.world_from_flash` applied to the flash's
//!   emitting point, else truth;
//! * **C**: `known.calibration_c`, else from the `reference-standard` images (the standard's
//!   pose from `known.world_from_standard`, else truth);
//! * **geometry**: the scan (units from `session.toml`, validated and repaired), or a
//!   tessellated sphere/cylinder at about [`SHAPE_EDGE_M`] edge length;
//! * **masks**: a per-image user mask (`images[].mask`), and the printed targets of the
//!   headdress, the reference structure and the flash projected into each image
//!   ([`target_depths`]: each printed square with its white ring, plus
//!   [`TARGET_MASK_MARGIN_PX`]); a target masks a pixel only where it lies in front of the
//!   surface the pixel sees (a target behind the head hides nothing).

use std::path::Path;
use std::time::Instant;

use glam::{DVec2, DVec3};
use serde::Serialize;
use skinbrdf_core::Pose;
use skinbrdf_mesh::{load_mesh, CameraRays, LengthUnit, LoadOptions, MeshReport};
use skinbrdf_session::{GeometrySpec, ImageRole, Session, Target, Truth};

use crate::geometry::{Geometry, Roi};
use crate::session::{
    derender_with_loader, CalibrationInput, DerenderInputs, DerenderReport, ImagePoses, OwnedImage,
    PoseSource,
};
use crate::{truth_error, DerenderConfig, DerenderError};

/// Edge length of tessellated ideal shapes (1 mm: the sagitta error on an 8 cm sphere is
/// 1.6 µm, far below any effect on D or the normal).
pub const SHAPE_EDGE_M: f64 = 0.001;

/// Which poses to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum PoseChoice {
    /// `session.toml` where every measurement image has them, else `truth.json`.
    #[default]
    Auto,
    /// Only `session.toml`.
    Session,
    /// Only `truth.json`.
    Truth,
    /// The pose stage's output ([`SessionOptions::estimated`]): camera, per-image poses,
    /// light and standard; known quantities in `session.toml` still take precedence for the
    /// light and the standard.
    Estimated,
}

/// Options of [`derender_session`] besides the [`DerenderConfig`].
#[derive(Debug, Clone, Default)]
pub struct SessionOptions {
    /// Pose source.
    pub poses: PoseChoice,
    /// Do not mask the printed targets.
    pub skip_target_mask: bool,
    /// The pose stage's result (`skinbrdf_poses::estimate_session`, or `out/poses.json`),
    /// used with [`PoseChoice::Estimated`].
    pub estimated: Option<skinbrdf_poses::SessionPoses>,
}

/// What [`derender_session`] returns besides the report.
#[derive(Debug, Clone, Serialize)]
pub struct SessionRun {
    /// The derender report (samples inside).
    pub report: DerenderReport,
    /// The scan's validation/repair (scans only).
    pub mesh_report: Option<MeshReport>,
    /// Triangles of the geometry.
    pub triangles: usize,
    /// Where the camera model came from.
    pub camera_source: &'static str,
    /// Where the light position came from.
    pub light_source: &'static str,
    /// Where C came from.
    pub c_source: &'static str,
}

fn input<T>(v: Option<T>, what: &str) -> Result<T, DerenderError> {
    v.ok_or_else(|| DerenderError::Input(what.to_string()))
}

/// Loads the session's geometry as a mesh in metres (head frame).
pub fn session_geometry(
    session: &Session,
    cfg: &DerenderConfig,
) -> Result<(Geometry, Option<MeshReport>, f64), DerenderError> {
    let t = Instant::now();
    let (mesh, report) = match &session.file.geometry {
        GeometrySpec::Scan { file, units } => {
            let l = load_mesh(
                &session.path(file),
                &LoadOptions {
                    unit: LengthUnit::Custom(units.to_m()),
                    ..Default::default()
                },
            )?;
            (l.mesh, Some(l.report))
        }
        GeometrySpec::Sphere { centre_m, radius_m } => {
            let n_lon =
                ((std::f64::consts::TAU * radius_m / SHAPE_EDGE_M).ceil() as u32).clamp(16, 4096);
            (
                skinbrdf_mesh::shapes::uv_sphere(*centre_m, *radius_m, n_lon / 2, n_lon),
                None,
            )
        }
        GeometrySpec::Cylinder {
            centre_m,
            axis,
            radius_m,
            length_m,
        } => {
            let n_around =
                ((std::f64::consts::TAU * radius_m / SHAPE_EDGE_M).ceil() as u32).clamp(16, 4096);
            let n_len = ((length_m / SHAPE_EDGE_M).ceil() as u32).clamp(1, 4096);
            (
                skinbrdf_mesh::shapes::cylinder(
                    *centre_m, *axis, *radius_m, *length_m, n_len, n_around,
                ),
                None,
            )
        }
    };
    let load_s = t.elapsed().as_secs_f64();
    let roi = session.file.roi.map(|r| Roi {
        centre_m: r.centre_m,
        radius_m: r.radius_m,
    });
    Ok((
        Geometry::with_quality(mesh, cfg.normals, roi, cfg.bvh_quality)?,
        report,
        load_s,
    ))
}

/// Half extent of a printed tag36h11 target in units of half its black square: the code's
/// 8 x 8 cells (black border included) plus the one-cell white ring each side, 10/8. The ring
/// is part of the printed target (the detector needs it), so it is masked with the square.
pub const TARGET_PRINT_HALF_EXTENT: f64 = 1.25;
/// Pixels added around each projected printed target (white ring included). Three parts, each
/// about a pixel at the default framing (0.37 mm per pixel, 25 mm tags):
///
/// * **pose uncertainty**: estimated head and camera poses reproject the targets' corners to
///   within ~0.5–1 px (`docs/benchmarks-poses.md`), the layout's own error adds to that;
/// * **blur and the pixel footprint**: a pixel whose footprint (half-diagonal 0.71 px) or the
///   lens blur reaches the paper mixes paper into skin;
/// * **paper trim**: the paper may extend a quarter cell beyond the white ring (0.8 mm, ~2 px
///   at the default framing; the synthetic sessions print it so).
///
/// The synthetic test `no_kept_sample_sees_a_printed_target` checks the sum against the truth
/// masks (pixels touching any printed target, paper included).
pub const TARGET_MASK_MARGIN_PX: f64 = 3.0;

/// Rasterizes the projected printed targets (square and white ring, [`TARGET_PRINT_HALF_EXTENT`],
/// grown by [`TARGET_MASK_MARGIN_PX`]) into a per-pixel distance from the camera centre to the
/// nearest target along the pixel's ray, metres (`f32::INFINITY` where no target projects).
///
/// The distance is where the pixel's ray meets the target's plane, clamped to the range of
/// distances of the target's (grown) corners (a ray nearly parallel to the plane, or a pixel in
/// the margin, gets a distance within the target's own). Derendering drops a pixel as
/// `on_target` only when that distance is not behind the surface it sees
/// ([`crate::image::TARGET_DEPTH_TOL_M`]): a target on the far side of the head projects onto the forehead
/// but hides none of it.
pub fn target_depths(
    rays: &CameraRays,
    quads: &[(Pose, &Target)],
    width: u32,
    height: u32,
) -> Vec<f32> {
    let camera = rays.camera();
    let mut depth = vec![f32::INFINITY; width as usize * height as usize];
    for (cam_from_layout, t) in quads {
        let c = t.centre();
        let corners: [DVec3; 4] = t
            .corners_m
            .map(|p| cam_from_layout.transform_point(c + (p - c) * TARGET_PRINT_HALF_EXTENT));
        let pts: Option<Vec<DVec2>> = corners.iter().map(|p| camera.project(*p)).collect();
        let Some(pts) = pts else { continue };
        let centre_cam = cam_from_layout.transform_point(c);
        let normal_cam = (corners[1] - corners[0]).cross(corners[3] - corners[0]);
        let (d_lo, d_hi) = corners.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
            (lo.min(p.length()), hi.max(p.length()))
        });
        // Orientation of the projected quad (its edges' inward side).
        let area2: f64 = (0..4).map(|k| pts[k].perp_dot(pts[(k + 1) % 4])).sum();
        if area2 == 0.0 || !area2.is_finite() {
            continue;
        }
        let orient = area2.signum();
        let m = TARGET_MASK_MARGIN_PX;
        let lo = pts
            .iter()
            .fold(DVec2::splat(f64::INFINITY), |a, p| a.min(*p))
            - m;
        let hi = pts
            .iter()
            .fold(DVec2::splat(f64::NEG_INFINITY), |a, p| a.max(*p))
            + m;
        if hi.x < 0.0 || hi.y < 0.0 || lo.x > width as f64 - 1.0 || lo.y > height as f64 - 1.0 {
            continue;
        }
        let x0 = lo.x.ceil().max(0.0) as u32;
        let y0 = lo.y.ceil().max(0.0) as u32;
        let x1 = hi.x.floor().min(width as f64 - 1.0) as u32;
        let y1 = hi.y.floor().min(height as f64 - 1.0) as u32;
        // Inside the quad grown by m: no edge has the point more than m outside it.
        let inside = |q: DVec2| {
            (0..4).all(|k| {
                let a = pts[k];
                let e = pts[(k + 1) % 4] - a;
                let len = e.length();
                len > 0.0 && orient * e.perp_dot(q - a) / len >= -m
            })
        };
        for y in y0..=y1 {
            for x in x0..=x1 {
                let q = DVec2::new(x as f64, y as f64);
                if !inside(q) {
                    continue;
                }
                let d = rays.pixel_ray(q).map_or(d_lo, |r| {
                    let den = r.dot(normal_cam);
                    let t = centre_cam.dot(normal_cam) / den;
                    if t.is_finite() && t > 0.0 {
                        t.clamp(d_lo, d_hi)
                    } else {
                        d_lo
                    }
                });
                let cell = &mut depth[(y * width + x) as usize];
                *cell = cell.min(d as f32);
            }
        }
    }
    depth
}

/// Resolves every input from the session (and `truth.json` where allowed).
pub fn session_inputs(
    session: &Session,
    truth: Option<&Truth>,
    opts: &SessionOptions,
) -> Result<(DerenderInputs, [&'static str; 3]), DerenderError> {
    let f = &session.file;
    if opts.poses == PoseChoice::Estimated {
        return estimated_inputs(session, opts);
    }
    let use_truth = opts.poses != PoseChoice::Session;
    let truth_ok = truth.filter(|_| use_truth);
    let (camera, camera_source) = match (f.camera.model(), truth_ok) {
        (Some(m), _) => (*m, "session"),
        (None, Some(t)) => (t.camera, "truth"),
        (None, None) => {
            return Err(DerenderError::Input(
                "the camera is not calibrated in session.toml and there is no truth.json".into(),
            ))
        }
    };
    let meas: Vec<usize> = session
        .images_with_role(ImageRole::Measurement)
        .map(|(i, _)| i)
        .collect();
    if meas.is_empty() {
        return Err(DerenderError::Input(
            "the session has no measurement images".into(),
        ));
    }
    let first_head = meas
        .iter()
        .find_map(|&i| f.images[i].world_from_head)
        .unwrap_or(Pose::IDENTITY);
    let session_pose = |i: usize| -> Option<ImagePoses> {
        let e = &f.images[i];
        let head = e
            .world_from_head
            .or(f.known.stationary_sample.then_some(first_head))?;
        Some(ImagePoses {
            world_from_camera: e.world_from_camera?,
            world_from_head: head,
        })
    };
    let truth_pose = |i: usize| -> Option<ImagePoses> {
        let t = truth_ok?.image(&f.images[i].file)?;
        Some(ImagePoses {
            world_from_camera: t.world_from_camera,
            world_from_head: t.world_from_head,
        })
    };
    let all_session = meas.iter().all(|&i| session_pose(i).is_some());
    let (measurements, pose_source) = match opts.poses {
        PoseChoice::Session | PoseChoice::Auto if all_session => (
            meas.iter()
                .filter_map(|&i| Some((i, session_pose(i)?)))
                .collect::<Vec<_>>(),
            PoseSource::Session,
        ),
        PoseChoice::Session => {
            return Err(DerenderError::Input(
                "some measurement images have no world_from_camera/world_from_head in session.toml (run the pose stage)".into(),
            ))
        }
        _ => {
            let mut v = Vec::new();
            for &i in &meas {
                let p = input(
                    truth_pose(i),
                    &format!(
                        "image {i} ({}): no poses in session.toml or truth.json (run the pose stage)",
                        f.images[i].file
                    ),
                )?;
                v.push((i, p));
            }
            (v, PoseSource::Truth)
        }
    };
    let (light_position_m, light_source) = if let Some(l) = f.known.light_position_m {
        (l, "session known.light_position_m")
    } else if let Some(wff) = f.known.world_from_flash {
        (
            wff.transform_point(f.flash.light_centre_m),
            "session known.world_from_flash",
        )
    } else {
        (
            input(
                truth_ok.map(|t| t.light_position_m),
                "no light position (known.light_position_m / world_from_flash) and no truth.json",
            )?,
            "truth",
        )
    };
    let (calibration, c_source) = if let Some(c) = f.known.calibration_c {
        (CalibrationInput::Known(c), "session known.calibration_c")
    } else {
        let std = input(
            f.standard.as_ref(),
            "no known.calibration_c and no [standard] to calibrate from",
        )?;
        let world_from_standard = match f.known.world_from_standard {
            Some(p) => p,
            None => input(
                truth_ok.map(|t| t.world_from_standard),
                "no known.world_from_standard and no truth.json",
            )?,
        };
        let mut images = Vec::new();
        for (i, e) in session.images_with_role(ImageRole::ReferenceStandard) {
            let wfc = match e.world_from_camera {
                Some(p) => p,
                None => input(
                    truth_ok
                        .and_then(|t| t.image(&e.file))
                        .map(|t| t.world_from_camera),
                    &format!("standard image {i} ({}): no camera pose", e.file),
                )?,
            };
            images.push((i, wfc));
        }
        if images.is_empty() {
            return Err(DerenderError::Input(
                "no reference-standard images and no known.calibration_c".into(),
            ));
        }
        (
            CalibrationInput::Standard {
                brdf: std.brdf.clone(),
                size_m: std.size_m,
                world_from_standard,
                images,
            },
            "reference standard (equation 3)",
        )
    };
    Ok((
        DerenderInputs {
            camera,
            light_position_m,
            calibration,
            measurements,
            pose_source,
        },
        [camera_source, light_source, c_source],
    ))
}

/// Inputs from the pose stage's result.
fn estimated_inputs(
    session: &Session,
    opts: &SessionOptions,
) -> Result<(DerenderInputs, [&'static str; 3]), DerenderError> {
    let f = &session.file;
    let est = input(
        opts.estimated.as_ref(),
        "--poses estimated needs the pose stage's result (out/poses.json)",
    )?;
    if est.images.len() != f.images.len() {
        return Err(DerenderError::Input(format!(
            "poses.json has {} images but the session has {}",
            est.images.len(),
            f.images.len()
        )));
    }
    let mut measurements = Vec::new();
    for (i, e) in session.images_with_role(ImageRole::Measurement) {
        let p = &est.images[i];
        match (&p.world_from_camera, &p.world_from_head) {
            (Some(c), Some(h)) => measurements.push((
                i,
                ImagePoses {
                    world_from_camera: c.pose,
                    world_from_head: h.pose,
                },
            )),
            // An image whose poses could not be estimated is skipped (the pose stage reports why).
            _ => tracing_skip(i, &e.file),
        }
    }
    if measurements.is_empty() {
        return Err(DerenderError::Input(
            "the pose stage found poses for no measurement image".into(),
        ));
    }
    let (light_position_m, light_source) = match (f.known.light_position_m, est.light_position_m) {
        (Some(l), _) => (l, "session known.light_position_m"),
        (None, Some(l)) => (l, "pose stage"),
        (None, None) => {
            return Err(DerenderError::Input(
                "no light position: neither known nor estimated".into(),
            ))
        }
    };
    let (calibration, c_source) = if let Some(c) = f.known.calibration_c {
        (CalibrationInput::Known(c), "session known.calibration_c")
    } else {
        let std = input(
            f.standard.as_ref(),
            "no known.calibration_c and no [standard]",
        )?;
        let world_from_standard = input(
            f.known
                .world_from_standard
                .or(est.world_from_standard.as_ref().map(|p| p.pose)),
            "no world_from_standard: neither known nor estimated",
        )?;
        let images: Vec<(usize, Pose)> = session
            .images_with_role(ImageRole::ReferenceStandard)
            .filter_map(|(i, _)| Some((i, est.images[i].world_from_camera.as_ref()?.pose)))
            .collect();
        if images.is_empty() {
            return Err(DerenderError::Input(
                "no reference-standard image with an estimated camera pose".into(),
            ));
        }
        (
            CalibrationInput::Standard {
                brdf: std.brdf.clone(),
                size_m: std.size_m,
                world_from_standard,
                images,
            },
            "reference standard (equation 3)",
        )
    };
    Ok((
        DerenderInputs {
            camera: est.camera,
            light_position_m,
            calibration,
            measurements,
            pose_source: PoseSource::Estimated,
        },
        ["pose stage", light_source, c_source],
    ))
}

fn tracing_skip(index: usize, file: &str) {
    tracing::warn!("image {index} ({file}) has no estimated poses; skipped");
}

/// Derenders a session end to end (see the module docs).
pub fn derender_session(
    session: &Session,
    opts: &SessionOptions,
    cfg: &DerenderConfig,
) -> Result<SessionRun, DerenderError> {
    cfg.validate()?;
    let start = Instant::now();
    let truth = match session.load_truth() {
        None => None,
        Some(r) => Some(r.map_err(|e| DerenderError::Input(e.to_string()))?),
    };
    let (inputs, [camera_source, light_source, c_source]) =
        session_inputs(session, truth.as_ref(), opts)?;
    let (geom, mesh_report, mesh_load_s) = session_geometry(session, cfg)?;
    let f = &session.file;
    let camera_rays = CameraRays::new(&inputs.camera);
    let world_from_flash = f
        .known
        .world_from_flash
        .or(opts
            .estimated
            .as_ref()
            .and_then(|e| e.world_from_flash.as_ref().map(|p| p.pose)))
        .or(truth.as_ref().map(|t| t.world_from_flash));
    let poses_of = |i: usize| {
        inputs
            .measurements
            .iter()
            .find(|(k, _)| *k == i)
            .map(|(_, p)| *p)
    };
    let loader = |i: usize| -> Result<OwnedImage, DerenderError> {
        let img = session
            .load_image(i)
            .map_err(|e| DerenderError::Input(e.to_string()))?;
        let e = &f.images[i];
        let mask = match &e.mask {
            Some(m) => {
                let mk = skinbrdf_session::load_mask(&session.path(m))
                    .map_err(|e| DerenderError::Input(e.to_string()))?;
                if (mk.width, mk.height) != (img.width, img.height) {
                    return Err(DerenderError::Input(format!(
                        "{m}: mask is {}x{} but the image is {}x{}",
                        mk.width, mk.height, img.width, img.height
                    )));
                }
                Some(mk.data)
            }
            None => None,
        };
        let targets = match poses_of(i) {
            Some(p) if !opts.skip_target_mask => {
                let cam_from_world = p.world_from_camera.inverse();
                let mut quads: Vec<(Pose, &Target)> = Vec::new();
                let cfh = cam_from_world * p.world_from_head;
                quads.extend(f.targets.headdress.iter().map(|t| (cfh, t)));
                quads.extend(f.targets.reference.iter().map(|t| (cam_from_world, t)));
                if let Some(wff) = world_from_flash {
                    quads.extend(f.flash.targets.iter().map(|t| (cam_from_world * wff, t)));
                }
                Some(target_depths(&camera_rays, &quads, img.width, img.height))
            }
            _ => None,
        };
        Ok(OwnedImage {
            width: img.width,
            height: img.height,
            rgb: img.rgb,
            saturated: img.saturated,
            mask,
            targets,
        })
    };
    let mut report = derender_with_loader(&geom, &inputs, cfg, loader)?;
    report.times.mesh_load_s = mesh_load_s;
    if let Some(t) = &truth {
        report.truth_error = truth_error(&report.samples, &t.brdf);
    }
    report.times.total_s = start.elapsed().as_secs_f64();
    Ok(SessionRun {
        triangles: geom.mesh.indices.len(),
        report,
        mesh_report,
        camera_source,
        light_source,
        c_source,
    })
}

/// Writes the samples (binary `.skbs` and optionally CSV) atomically.
pub fn write_samples(
    path: &Path,
    csv: Option<&Path>,
    run: &SessionRun,
    session: &Session,
) -> Result<(), DerenderError> {
    let out = |e: skinbrdf_samples::SamplesError, p: &Path| DerenderError::Output {
        path: p.to_path_buf(),
        reason: e.to_string(),
    };
    let mut header = skinbrdf_samples::SampleHeader::new(
        &format!("skinbrdf derender {}", session.dir.display()),
        &format!(
            "C = {:?}, grazing limit {}°, noise floor {}, poses from {:?}",
            run.report.c,
            run.report.config.grazing_limit_deg,
            run.report.config.noise_floor,
            run.report.pose_source
        ),
    );
    header.image_count = Some(session.file.images.len() as u32);
    header.calibration_c = Some(run.report.c);
    header.extra = serde_json::to_value(&run.report).unwrap_or(serde_json::Value::Null);
    skinbrdf_samples::write_samples(path, &header, &run.report.samples)
        .map_err(|e| out(e, path))?;
    if let Some(c) = csv {
        skinbrdf_samples::write_csv(c, &run.report.samples).map_err(|e| out(e, c))?;
    }
    Ok(())
}
