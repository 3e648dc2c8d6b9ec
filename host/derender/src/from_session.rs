//! Derendering a `skinbrdf-session` directory: [`derender_session`].
//!
//! The poses come resolved ([`ResolvedPoses`]: the pipeline's `pose_inputs::resolve_poses`, or
//! [`ResolvedPoses::from_truth`]); this module adds what only the session directory has:
//!
//! * **C**: `known.calibration_c`, else from the `reference-standard` images
//!   ([`DerenderInputs::new`]);
//! * **geometry**: the scan (units from `session.toml`, validated and repaired, with its
//!   texture coordinates when it has them, which the samples record), or a tessellated
//!   sphere/cylinder at about [`SHAPE_EDGE_M`] edge length;
//! * **masks**: a per-image user mask (`images[].mask`), and the printed targets of the
//!   headdress, the reference structure and the flash projected into each image
//!   ([`target_depths`]: each printed square with its white ring, plus
//!   [`TARGET_MASK_MARGIN_PX`]); a target masks a pixel only where it lies in front of the
//!   surface the pixel sees (a target behind the head hides nothing);
//! * **scoring**: when `truth.json` is present, the samples' error against the true BRDF (the
//!   only use of the truth here).

use std::path::Path;
use std::time::Instant;

use glam::{DVec2, DVec3};
use serde::Serialize;
use skinbrdf_core::Pose;
use skinbrdf_mesh::{load_mesh_with_uv, CameraRays, LengthUnit, LoadOptions, MeshReport};
use skinbrdf_session::{GeometrySpec, Session, Target};

use crate::from_inputs::{
    derender_with_loader, CalibrationSource, DerenderInputs, DerenderReport, OwnedImage, PoseSource,
};
use crate::geometry::{Geometry, Roi};
use crate::poses::ResolvedPoses;
use crate::{truth_error, DerenderConfig, DerenderError};

/// Edge length of tessellated ideal shapes (1 mm: the sagitta error on an 8 cm sphere is
/// 1.6 µm, far below any effect on D or the normal).
pub const SHAPE_EDGE_M: f64 = 0.001;

/// Whether the printed targets are masked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum TargetMask {
    /// Project the headdress, reference and flash targets and drop the pixels they hide.
    #[default]
    Printed,
    /// Do not mask the printed targets.
    Skip,
}

/// What [`derender_session`] returns besides the report.
#[derive(Debug, Clone, Serialize)]
pub struct SessionRun {
    /// The derender report (samples inside).
    pub report: DerenderReport,
    /// The scan's validation/repair (scans only).
    pub mesh_report: Option<MeshReport>,
    /// Triangles of the geometry (the samples' surface points index them).
    pub triangles: usize,
    /// Whether the geometry has texture coordinates (the samples' surface points then carry
    /// them).
    pub texture_coordinates: bool,
    /// Where the camera model came from.
    pub camera_source: PoseSource,
    /// Where the light position came from.
    pub light_source: PoseSource,
    /// Where C came from.
    pub c_source: CalibrationSource,
    /// Measurement images left out for want of poses.
    pub unposed: Vec<usize>,
}

/// The repair policy for a session's scan: the mesh crate's default limit on dropped triangles,
/// or the larger fraction the session accepts (`geometry.accept_repair_loss`).
pub fn scan_repair_policy(accept_repair_loss: Option<f64>) -> skinbrdf_mesh::RepairPolicy {
    match accept_repair_loss {
        Some(f) => skinbrdf_mesh::RepairPolicy::accepting(f),
        None => skinbrdf_mesh::RepairPolicy::repair(),
    }
}

/// Loads the session's geometry as a mesh in metres (head frame).
pub fn session_geometry(
    session: &Session,
    cfg: &DerenderConfig,
) -> Result<(Geometry, Option<MeshReport>, f64), DerenderError> {
    let t = Instant::now();
    let (mesh, report, uv) = match &session.file.geometry {
        GeometrySpec::Scan {
            file,
            units,
            accept_repair_loss,
        } => {
            let (l, uv) = load_mesh_with_uv(
                &session.path(file),
                &LoadOptions {
                    unit: LengthUnit::Custom(units.to_m()),
                    policy: scan_repair_policy(*accept_repair_loss),
                },
            )?;
            (l.mesh, Some(l.report), uv)
        }
        GeometrySpec::Sphere { centre_m, radius_m } => {
            let n_lon =
                ((std::f64::consts::TAU * radius_m / SHAPE_EDGE_M).ceil() as u32).clamp(16, 4096);
            (
                skinbrdf_mesh::shapes::uv_sphere(*centre_m, *radius_m, n_lon / 2, n_lon),
                None,
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
        Geometry::with_quality(mesh, cfg.normals, roi, cfg.bvh_quality)?
            .with_texture_coordinates(uv),
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

/// Derenders a session end to end with resolved poses (see the module docs).
pub fn derender_session(
    session: &Session,
    poses: &ResolvedPoses,
    mask: TargetMask,
    cfg: &DerenderConfig,
) -> Result<SessionRun, DerenderError> {
    cfg.validate()?;
    let start = Instant::now();
    let inputs = DerenderInputs::new(session, poses)?;
    let (geom, mesh_report, mesh_load_s) = session_geometry(session, cfg)?;
    let f = &session.file;
    let camera_rays = CameraRays::new(&inputs.camera);
    let world_from_flash = poses.world_from_flash.map(|p| p.value);
    let loader = |i: usize| -> Result<OwnedImage, DerenderError> {
        let img = session
            .load_image(i)
            .map_err(|error| DerenderError::Image { index: i, error })?;
        let camera_px = [inputs.camera.width_px, inputs.camera.height_px];
        if [img.width, img.height] != camera_px {
            return Err(DerenderError::ImageSize {
                index: i,
                image_px: [img.width, img.height],
                camera_px,
            });
        }
        let e = &f.images[i];
        let mask_px = match &e.mask {
            Some(m) => {
                let file = session.path(m);
                let mk = skinbrdf_session::load_mask(&file)
                    .map_err(|error| DerenderError::Mask { index: i, error })?;
                if (mk.width, mk.height) != (img.width, img.height) {
                    return Err(DerenderError::MaskSize {
                        file,
                        mask_px: [mk.width, mk.height],
                        image_px: [img.width, img.height],
                    });
                }
                Some(mk.data)
            }
            None => None,
        };
        let targets = match poses.image(i) {
            Some(p) if mask == TargetMask::Printed => {
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
            cfa: img.cfa,
            mask: mask_px,
            targets,
        })
    };
    let mut report = derender_with_loader(&geom, &inputs, cfg, loader)?;
    report.times.mesh_load_s = mesh_load_s;
    // Scoring only: the truth never feeds the derender itself.
    if let Some(t) = session.load_truth() {
        let t = t.map_err(|error| DerenderError::Truth { error })?;
        report.truth_error = truth_error(&report.samples, &t.brdf);
    }
    report.times.total_s = start.elapsed().as_secs_f64();
    Ok(SessionRun {
        triangles: geom.mesh.indices.len(),
        texture_coordinates: geom.uv.is_some(),
        report,
        mesh_report,
        camera_source: poses.camera.source,
        light_source: poses.light_position_m.source,
        c_source: inputs.calibration.source(),
        unposed: poses.unposed.clone(),
    })
}

/// Writes the samples (binary `.skbs` and optionally CSV) atomically.
pub fn write_samples(
    path: &Path,
    csv: Option<&Path>,
    run: &SessionRun,
    session: &Session,
) -> Result<(), DerenderError> {
    let mut header = skinbrdf_samples::SampleHeader::new(
        &format!("skinbrdf derender {}", session.dir.display()),
        &format!(
            "C = {} {} {}, grazing limit {}°, noise floor {}, poses from {}",
            run.report.c[0],
            run.report.c[1],
            run.report.c[2],
            run.report.config.grazing_limit_deg,
            run.report.config.noise_floor,
            run.report.pose_source
        ),
    );
    header.image_count = Some(session.file.images.len() as u32);
    header.calibration_c = Some(run.report.c);
    header.extra = skinbrdf_core::json::to_value(path, &run.report).map_err(|e| {
        skinbrdf_samples::SamplesError::BadHeader {
            path: path.to_path_buf(),
            problem: format!("cannot serialise the provenance header: {}", e.problem()),
        }
    })?;
    skinbrdf_samples::write_samples(path, &header, &run.report.samples)?;
    if let Some(c) = csv {
        skinbrdf_samples::write_csv(c, &run.report.samples)?;
    }
    Ok(())
}
