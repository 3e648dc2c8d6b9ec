//! Finding the headdress targets on a textured scan.
//!
//! # Method
//!
//! 1. **Overview.** The scan's albedo (its texture colour at the closest hit, as grey) is
//!    rendered by ray casting ([`skinbrdf_mesh::MeshBvh`]) from [`ScanTargetConfig::overview_views`]
//!    pinhole cameras spread evenly over a sphere around the scan's centroid (a Fibonacci
//!    lattice: the scan's frame is arbitrary, so no side is privileged), each framing the whole
//!    scan. The tags are detected with the project's detector ([`skinbrdf_targets::detect()`]).
//! 2. **Back-projection.** Each detected corner's pixel ray is cast onto the mesh; the hit is
//!    the corner on the scan. A detection is kept when all four corners hit, its sides are the
//!    target's size within [`ScanTargetConfig::max_size_error`], and it is seen from the
//!    printed side (the outward normal of the back-projected corners, `-(x × y)` with
//!    `x = c1 - c0`, `y = c0 - c3`, faces the camera: a paper seen through from behind shows
//!    its print mirrored, which never decodes to the right corners).
//! 3. **Detail views.** For each target found, cameras aimed at its centre: one along its
//!    normal and [`ScanTargetConfig::detail_ring`] tilted by [`ScanTargetConfig::detail_tilt_deg`]
//!    around it, at a distance that gives [`ScanTargetConfig::detail_mm_per_px`] on the
//!    paper (finer than the texture, so the detector sees the print's own edges). Only the
//!    aimed target is taken from each, and preferably only its corners the detector does not
//!    flag as occluded ([`MIN_CLEAN_SAMPLES`]).
//! 4. **Merge.** Each corner's back-projected points over the detail views (the overview's
//!    when no detail view saw it) are merged robustly: the component-wise median `m`, then the
//!    mean of the points within `max(MERGE_RADIUS_FACTOR × median |p - m|, MERGE_FLOOR_M)`
//!    of it. Their RMS distance from the mean is the corner's spread.
//! 5. **Square fit.** The printed black square is a square of known edge `s` on a flat paper:
//!    the ideal corners `(-s/2, s/2, 0)`, `(s/2, s/2, 0)`, `(s/2, -s/2, 0)`, `(-s/2, -s/2, 0)`
//!    (tag frame, x right, y down) are fitted to the four merged corners by Kabsch (rotation
//!    and translation, no scale). The fitted corners are reported: they carry the known size
//!    and flatness and average the four corners' errors; the RMS distance of the merged
//!    corners from them is the fit residual, which flags a creased or partly scanned paper or
//!    a wrong size.

use std::time::Instant;

use glam::{DQuat, DVec2, DVec3, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_mesh::{Appearance, BuildQuality, MeshBvh, TexturedMesh};
use skinbrdf_targets::{detect, DetectorConfig, GrayF32};

use crate::align::{umeyama, AlignKind, Correspondence};
use crate::RegisterError;

/// A corner's points within this many times their median distance from their median are
/// averaged (for 3-D Gaussian scatter the median distance is 1.54 σ, so the cut is at ~4.6 σ:
/// it removes a view whose detection slipped, never the scatter itself).
pub const MERGE_RADIUS_FACTOR: f64 = 3.0;
/// ... or within this distance, metres (0.05 mm: below the scan's own noise, so a tight
/// cluster is not cut down to its median).
pub const MERGE_FLOOR_M: f64 = 5e-5;
/// A corner's detail-view points the detector does not flag as occluded are merged alone when
/// there are at least this many; otherwise all its detail-view points are. The detector flags
/// a corner whose side bends by [`skinbrdf_targets::detect::MIN_BEND_PX`] (0.15 px): on a
/// scan's slightly uneven paper seen at a tilt, that is the scan's depth noise, not an
/// occluder, and the robust merge removes a corner that really slipped.
pub const MIN_CLEAN_SAMPLES: usize = 2;
/// Horizontal field of view of the detail cameras, degrees (their distance follows from
/// [`ScanTargetConfig::detail_mm_per_px`]; a narrow view keeps the tilt across the tag small).
pub const DETAIL_HFOV_DEG: f64 = 30.0;
/// Grey level of a ray that misses the scan (a dark background: the paper's white ring stands
/// out from it as from the skin).
pub const BACKGROUND_GREY: f32 = 0.1;

/// Settings of [`find_scan_targets`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScanTargetConfig {
    /// Overview cameras on the sphere around the scan.
    pub overview_views: usize,
    /// Overview image side, pixels.
    pub overview_px: u32,
    /// Overview horizontal field of view, degrees.
    pub overview_hfov_deg: f64,
    /// Detail image side, pixels.
    pub detail_px: u32,
    /// Detail resolution on the paper, millimetres per pixel.
    pub detail_mm_per_px: f64,
    /// Tilted detail views around the frontal one.
    pub detail_ring: usize,
    /// Tilt of the ring's views from the target's normal, degrees.
    pub detail_tilt_deg: f64,
    /// Largest relative deviation of a back-projected side from the target's size.
    pub max_size_error: f64,
    /// The tag detector.
    pub detector: DetectorConfig,
}

impl Default for ScanTargetConfig {
    fn default() -> Self {
        Self {
            overview_views: 14,
            overview_px: 768,
            overview_hfov_deg: 40.0,
            detail_px: 448,
            detail_mm_per_px: 0.12,
            detail_ring: 4,
            detail_tilt_deg: 20.0,
            max_size_error: 0.1,
            detector: DetectorConfig::DEFAULT,
        }
    }
}

/// One target found on the scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScanTarget {
    /// tag36h11 id.
    pub id: u32,
    /// Edge of the black square, metres (as asked for).
    pub size_m: f64,
    /// The fitted square's corners, scan frame, metres, session order (bottom-left,
    /// bottom-right, top-right, top-left of the printed tag).
    pub corners_m: [DVec3; 4],
    /// The merged back-projected corners before the square fit.
    pub measured_corners_m: [DVec3; 4],
    /// Views whose detection contributed.
    pub views: usize,
    /// RMS distance of the measured corners from the fitted square, millimetres.
    pub fit_residual_mm: f64,
    /// Per corner, the RMS spread of its points over the views, millimetres.
    pub corner_spread_mm: [f64; 4],
    /// Per corner, the points merged (after the robust cut) and the points available.
    pub corner_samples: [(usize, usize); 4],
    /// Mean side of the measured corners, metres.
    pub measured_size_m: f64,
}

/// Run times of [`find_scan_targets`], seconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ScanTargetTiming {
    /// Building the BVH.
    pub bvh_s: f64,
    /// Rendering and detecting the overview.
    pub overview_s: f64,
    /// Rendering and detecting the detail views.
    pub detail_s: f64,
    /// Merging and fitting.
    pub fit_s: f64,
    /// Everything.
    pub total_s: f64,
}

/// What [`find_scan_targets`] found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScanTargets {
    /// The targets found, by id.
    pub targets: Vec<ScanTarget>,
    /// Wanted ids not found.
    pub missing: Vec<u32>,
    /// Views rendered (overview and detail).
    pub views_rendered: usize,
    /// Run times.
    pub timing: ScanTargetTiming,
}

/// A virtual camera.
#[derive(Debug, Clone, Copy)]
struct View {
    camera: CameraModel,
    scan_from_camera: Pose,
}

/// One detection cast onto the scan.
#[derive(Debug, Clone, Copy)]
struct Seen {
    id: u32,
    corners_m: [DVec3; 4],
    usable: [bool; 4],
}

/// Renders the scan's grey albedo from a view: one ray per pixel centre.
fn render(scan: &TexturedMesh, bvh: &MeshBvh, view: &View) -> GrayF32 {
    let cam = &view.camera;
    let (w, h) = (cam.width_px as usize, cam.height_px as usize);
    let rot = view.scan_from_camera.rotation;
    let dirs: Vec<Vec3> = (0..w * h)
        .map(|k| {
            let px = DVec2::new((k % w) as f64, (k / w) as f64);
            cam.pixel_ray(px)
                .map(|d| (rot * d).as_vec3())
                .unwrap_or(Vec3::ZERO)
        })
        .collect();
    let origin = view.scan_from_camera.translation_m.as_vec3();
    let hits = bvh.intersect_grid(origin, &dirs, w, f32::INFINITY);
    let data = hits
        .iter()
        .map(|h| h.map_or(BACKGROUND_GREY, |h| scan.grey_at(&h)))
        .collect();
    GrayF32 {
        width: w,
        height: h,
        data,
    }
}

/// Casts a pixel's ray onto the scan.
fn back_project(bvh: &MeshBvh, view: &View, px: DVec2) -> Option<DVec3> {
    let d = view.scan_from_camera.rotation * view.camera.pixel_ray(px)?;
    let o = view.scan_from_camera.translation_m;
    let hit = bvh.intersect(o.as_vec3(), d.as_vec3(), f32::INFINITY)?;
    Some(o + d * f64::from(hit.t_m))
}

/// Renders, detects and back-projects the wanted targets seen in one view (`only`: just that
/// id).
fn observe(
    scan: &TexturedMesh,
    bvh: &MeshBvh,
    view: &View,
    wanted: &[(u32, f64)],
    only: Option<u32>,
    cfg: &ScanTargetConfig,
) -> Vec<Seen> {
    let img = render(scan, bvh, view);
    let mut out = Vec::new();
    for det in detect(&img, &cfg.detector) {
        if only.is_some_and(|id| id != det.id) {
            continue;
        }
        let Some(&(_, size_m)) = wanted.iter().find(|(id, _)| *id == det.id) else {
            continue;
        };
        let pts: Option<Vec<DVec3>> = det
            .corners_px
            .iter()
            .map(|&px| back_project(bvh, view, px))
            .collect();
        let Some(pts) = pts else { continue };
        let c = [pts[0], pts[1], pts[2], pts[3]];
        let sides_ok = (0..4).all(|k| {
            let side = c[k].distance(c[(k + 1) % 4]);
            (side / size_m - 1.0).abs() <= cfg.max_size_error
        });
        let out_n = -((c[1] - c[0]).cross(c[0] - c[3]));
        let centre = (c[0] + c[1] + c[2] + c[3]) * 0.25;
        let facing = out_n.dot(view.scan_from_camera.translation_m - centre) > 0.0;
        if !(sides_ok && facing) {
            continue;
        }
        out.push(Seen {
            id: det.id,
            corners_m: c,
            usable: det.occluded_corners.map(|o| !o),
        });
    }
    out
}

/// A camera at `eye` looking at `target`, with `hfov` and `px` square pixels.
fn view_at(eye: DVec3, target: DVec3, px: u32, hfov_rad: f64) -> Option<View> {
    let fwd = (target - eye).try_normalize()?;
    let up = if fwd.z.abs() < 0.9 {
        DVec3::Z
    } else {
        DVec3::X
    };
    Some(View {
        camera: CameraModel::from_fov(px, px, hfov_rad),
        scan_from_camera: Pose::look_at(eye, target, up)?,
    })
}

/// Evenly spread unit directions (Fibonacci lattice).
fn sphere_directions(n: usize) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let a = golden * i as f64;
            DVec3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

/// Robust mean of points (see the module docs): the mean, the RMS spread (metres) and the
/// number of points kept.
fn robust_mean(points: &[DVec3]) -> Option<(DVec3, f64, usize)> {
    if points.is_empty() {
        return None;
    }
    let med = |f: &dyn Fn(&DVec3) -> f64| {
        let mut v: Vec<f64> = points.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    };
    let m = DVec3::new(med(&|p| p.x), med(&|p| p.y), med(&|p| p.z));
    let mad = med(&|p| p.distance(m));
    let radius = (MERGE_RADIUS_FACTOR * mad).max(MERGE_FLOOR_M);
    let kept: Vec<DVec3> = points
        .iter()
        .copied()
        .filter(|p| p.distance(m) <= radius)
        .collect();
    let kept = if kept.is_empty() { vec![m] } else { kept };
    let mean = kept.iter().copied().sum::<DVec3>() / kept.len() as f64;
    let spread =
        (kept.iter().map(|p| p.distance_squared(mean)).sum::<f64>() / kept.len() as f64).sqrt();
    Some((mean, spread, kept.len()))
}

/// Fits the ideal square of edge `size_m` to four corners (Kabsch): the fitted corners and the
/// RMS residual, metres.
pub fn fit_square(corners_m: &[DVec3; 4], size_m: f64) -> Result<([DVec3; 4], f64), RegisterError> {
    let h = 0.5 * size_m;
    let ideal = [
        DVec3::new(-h, h, 0.0),
        DVec3::new(h, h, 0.0),
        DVec3::new(h, -h, 0.0),
        DVec3::new(-h, -h, 0.0),
    ];
    let pairs: Vec<Correspondence> = (0..4)
        .map(|k| Correspondence {
            id: 0,
            corner: k as u8,
            survey_m: ideal[k],
            scan_m: corners_m[k],
        })
        .collect();
    let (r, t, _) = umeyama(&pairs, AlignKind::Rigid)?;
    let fitted = ideal.map(|p| r * p + t);
    let rms = ((0..4)
        .map(|k| fitted[k].distance_squared(corners_m[k]))
        .sum::<f64>()
        / 4.0)
        .sqrt();
    Ok((fitted, rms))
}

/// Finds the `wanted` targets (id, black-square edge in metres) on a textured scan (see the
/// module docs). Targets not found are listed in [`ScanTargets::missing`]; an error when none
/// is found or the scan has no colours.
pub fn find_scan_targets(
    scan: &TexturedMesh,
    wanted: &[(u32, f64)],
    cfg: &ScanTargetConfig,
) -> Result<ScanTargets, RegisterError> {
    let t0 = Instant::now();
    if matches!(scan.appearance, Appearance::None) {
        return Err(RegisterError::Untextured);
    }
    if let Some((id, s)) = wanted.iter().find(|(_, s)| !(s.is_finite() && *s > 0.0)) {
        return Err(RegisterError::InvalidParameter {
            field: "wanted",
            reason: format!("target {id}: size {s} m must be positive"),
        });
    }
    let valid = cfg.overview_views > 0
        && cfg.overview_px >= 64
        && cfg.detail_px >= 64
        && cfg.detail_mm_per_px > 0.0
        && cfg.overview_hfov_deg > 1.0
        && cfg.overview_hfov_deg < 150.0
        && cfg.max_size_error > 0.0;
    if !valid {
        return Err(RegisterError::InvalidParameter {
            field: "scan target config",
            reason: format!(
                "out of range: overview_views {} (> 0), overview_px {} and detail_px {} (>= 64), \
                 detail_mm_per_px {} (> 0), overview_hfov_deg {} (1 to 150), max_size_error {} \
                 (> 0)",
                cfg.overview_views,
                cfg.overview_px,
                cfg.detail_px,
                cfg.detail_mm_per_px,
                cfg.overview_hfov_deg,
                cfg.max_size_error
            ),
        });
    }
    let bvh = MeshBvh::build(&scan.mesh, BuildQuality::Medium)?;
    let bvh_s = t0.elapsed().as_secs_f64();

    // Overview.
    let t1 = Instant::now();
    let n = scan.mesh.positions.len().max(1) as f64;
    let centroid = scan
        .mesh
        .positions
        .iter()
        .map(|p| p.as_dvec3())
        .sum::<DVec3>()
        / n;
    let radius = scan
        .mesh
        .positions
        .iter()
        .map(|p| p.as_dvec3().distance(centroid))
        .fold(0.0, f64::max)
        .max(1e-3);
    let hfov = cfg.overview_hfov_deg.to_radians();
    let dist = radius / (0.5 * hfov).sin() * 1.02;
    let overview: Vec<View> = sphere_directions(cfg.overview_views)
        .into_iter()
        .filter_map(|d| view_at(centroid + d * dist, centroid, cfg.overview_px, hfov))
        .collect();
    let seen: Vec<Vec<Seen>> = overview
        .par_iter()
        .map(|v| observe(scan, &bvh, v, wanted, None, cfg))
        .collect();
    let overview_s = t1.elapsed().as_secs_f64();

    // Detail views per target found.
    let t2 = Instant::now();
    let mut ids: Vec<u32> = seen.iter().flatten().map(|s| s.id).collect();
    ids.sort_unstable();
    ids.dedup();
    let detail_hfov = DETAIL_HFOV_DEG.to_radians();
    let mut detail_jobs: Vec<(u32, View)> = Vec::new();
    for &id in &ids {
        let obs: Vec<&Seen> = seen.iter().flatten().filter(|s| s.id == id).collect();
        let centres: Vec<DVec3> = obs
            .iter()
            .map(|s| s.corners_m.iter().copied().sum::<DVec3>() * 0.25)
            .collect();
        let Some((centre, _, _)) = robust_mean(&centres) else {
            continue;
        };
        let normal = obs
            .iter()
            .map(|s| {
                let c = s.corners_m;
                -((c[1] - c[0]).cross(c[0] - c[3])).normalize_or_zero()
            })
            .sum::<DVec3>()
            .normalize_or_zero();
        if normal == DVec3::ZERO {
            continue;
        }
        let footprint_m = cfg.detail_mm_per_px * 1e-3;
        let d = footprint_m * f64::from(cfg.detail_px) / (2.0 * (0.5 * detail_hfov).tan());
        let side = normal.any_orthonormal_vector();
        let tilt = cfg.detail_tilt_deg.to_radians();
        let mut dirs = vec![normal];
        for k in 0..cfg.detail_ring {
            let az = std::f64::consts::TAU * k as f64 / cfg.detail_ring as f64;
            let axis = DQuat::from_axis_angle(normal, az) * side;
            dirs.push(DQuat::from_axis_angle(axis, tilt) * normal);
        }
        for dir in dirs {
            if let Some(v) = view_at(centre + dir * d, centre, cfg.detail_px, detail_hfov) {
                detail_jobs.push((id, v));
            }
        }
    }
    let detail: Vec<(u32, Vec<Seen>)> = detail_jobs
        .par_iter()
        .map(|(id, v)| (*id, observe(scan, &bvh, v, wanted, Some(*id), cfg)))
        .collect();
    let detail_s = t2.elapsed().as_secs_f64();

    // Merge and fit.
    let t3 = Instant::now();
    let mut targets = Vec::new();
    for &id in &ids {
        let Some(&(_, size_m)) = wanted.iter().find(|(w, _)| *w == id) else {
            continue;
        };
        let fine: Vec<&Seen> = detail
            .iter()
            .filter(|(j, _)| *j == id)
            .flat_map(|(_, s)| s.iter())
            .collect();
        let coarse: Vec<&Seen> = seen.iter().flatten().filter(|s| s.id == id).collect();
        let mut merged = [DVec3::ZERO; 4];
        let mut spread = [0.0; 4];
        let mut samples = [(0, 0); 4];
        let mut ok = true;
        for k in 0..4 {
            let pick = |set: &[&Seen]| -> Vec<DVec3> {
                set.iter()
                    .filter(|s| s.usable[k])
                    .map(|s| s.corners_m[k])
                    .collect()
            };
            let all =
                |set: &[&Seen]| -> Vec<DVec3> { set.iter().map(|s| s.corners_m[k]).collect() };
            let mut pts = pick(&fine);
            if pts.len() < MIN_CLEAN_SAMPLES {
                pts = all(&fine);
            }
            if pts.is_empty() {
                pts = pick(&coarse);
            }
            if pts.is_empty() {
                pts = all(&coarse);
            }
            match robust_mean(&pts) {
                Some((m, s, n)) => {
                    merged[k] = m;
                    spread[k] = s * 1e3;
                    samples[k] = (n, pts.len());
                }
                None => ok = false,
            }
        }
        if !ok {
            continue;
        }
        let (fitted, rms) = fit_square(&merged, size_m)?;
        let measured_size_m = (0..4)
            .map(|k| merged[k].distance(merged[(k + 1) % 4]))
            .sum::<f64>()
            / 4.0;
        targets.push(ScanTarget {
            id,
            size_m,
            corners_m: fitted,
            measured_corners_m: merged,
            views: if fine.is_empty() {
                coarse.len()
            } else {
                fine.len()
            },
            fit_residual_mm: rms * 1e3,
            corner_spread_mm: spread,
            corner_samples: samples,
            measured_size_m,
        });
    }
    let fit_s = t3.elapsed().as_secs_f64();
    let views_rendered = overview.len() + detail_jobs.len();
    if targets.is_empty() {
        return Err(RegisterError::NoTargetsFound {
            wanted: wanted.iter().map(|(id, _)| *id).collect(),
            views: views_rendered,
        });
    }
    let missing = wanted
        .iter()
        .map(|(id, _)| *id)
        .filter(|id| !targets.iter().any(|t| t.id == *id))
        .collect();
    Ok(ScanTargets {
        targets,
        missing,
        views_rendered,
        timing: ScanTargetTiming {
            bvh_s,
            overview_s,
            detail_s,
            fit_s,
            total_s: t0.elapsed().as_secs_f64(),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_square_fit_recovers_a_noisy_square() {
        let pose =
            Pose::from_rotation_vector(DVec3::new(0.4, 0.1, -0.9), DVec3::new(0.1, 0.0, 0.2));
        let h = 0.0125;
        let ideal = [
            DVec3::new(-h, h, 0.0),
            DVec3::new(h, h, 0.0),
            DVec3::new(h, -h, 0.0),
            DVec3::new(-h, -h, 0.0),
        ];
        let noise = [
            DVec3::new(1e-4, 0.0, -5e-5),
            DVec3::new(-5e-5, 1e-4, 0.0),
            DVec3::new(0.0, -1e-4, 5e-5),
            DVec3::new(5e-5, 0.0, 1e-4),
        ];
        let measured: [DVec3; 4] =
            std::array::from_fn(|k| pose.transform_point(ideal[k]) + noise[k]);
        let (fitted, rms) = fit_square(&measured, 0.025).expect("fit");
        for k in 0..4 {
            assert!(fitted[k].distance(pose.transform_point(ideal[k])) < 1e-4);
        }
        assert!(rms > 0.0 && rms < 1.5e-4, "{rms}");
    }

    #[test]
    fn robust_mean_ignores_an_outlier() {
        let mut pts: Vec<DVec3> = (0..6).map(|i| DVec3::X * (f64::from(i) * 1e-5)).collect();
        pts.push(DVec3::Y * 0.01);
        let (m, s, n) = robust_mean(&pts).expect("mean");
        assert_eq!(n, 6);
        assert!((m.x - 2.5e-5).abs() < 1e-9 && m.y.abs() < 1e-12, "{m:?}");
        assert!(s < 3e-5);
    }
}
