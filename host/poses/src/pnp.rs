//! Camera pose from known 3D points (perspective-n-point) with RANSAC over targets and
//! Levenberg-Marquardt refinement.
//!
//! # Method
//!
//! * **Hypotheses.** Every target (a group of four coplanar corners) gives a pose from its plane
//!   homography; all points together give one more (plane homography when they are coplanar,
//!   the 6-point DLT otherwise). Each hypothesis is scored by the number of targets whose corners
//!   all reproject within [`PnpConfig::inlier_px`]; the best one is kept (exhaustive "RANSAC"
//!   over targets: deterministic, and a wrong target cannot seed the solution when most are
//!   right).
//! * **Refinement.** LM on the whitened reprojection error of the inlier targets with a Huber loss
//!   (see [`crate::lm`]). Parameters: a rotation increment `δ` (world frame, `R = exp(δ) R₀`) and
//!   the camera centre `C`, so the covariance is directly that of the camera's orientation (rad²)
//!   and position (m²) in the layout's frame. After a first pass, targets with a corner beyond
//!   [`PnpConfig::outlier_sigma`] standard deviations and 1 px are dropped and LM runs again.
//!   LM only accepts steps that lower the cost, so the refined pose is never worse than its input.
//! * **Diagnostics.** Too few targets, collinear points, an ill-conditioned normal matrix and
//!   targets seen at grazing angles are detected and reported ([`crate::Diagnostic`]); hard
//!   failures are [`crate::PoseError`]s.

use crate::error::{Diagnostic, PoseError};
use crate::geometry::{dlt_pose, fit_plane, homography, pose_from_plane_homography};
use crate::lm::{minimize, LmConfig};
use glam::{DVec2, DVec3};
use nalgebra::DVector;
use serde::{Deserialize, Serialize};
use skinbrdf_core::{CameraModel, Pose};

/// One observed point: a known 3D point in the layout's frame and its image position.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PointObs {
    /// Point in the layout's frame, metres.
    pub object_m: DVec3,
    /// Observed pixel (pixel-centre convention).
    pub image_px: DVec2,
    /// Standard deviation of the observation, pixels.
    pub sigma_px: f64,
    /// The target (tag ID) the point belongs to.
    pub target: u32,
    /// Outward normal of the target's face in the layout's frame (for the grazing-angle check),
    /// or zero when unknown.
    pub normal: DVec3,
}

/// Settings of [`estimate_pose`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PnpConfig {
    /// A target agrees with a hypothesis when all its corners reproject within this, pixels.
    pub inlier_px: f64,
    /// After the first refinement, targets with a corner beyond this many sigmas (and 1 px) are
    /// dropped as outliers.
    pub outlier_sigma: f64,
    /// Floor of the per-point sigma used for weighting, pixels (detector sigmas can be optimistic).
    pub sigma_floor_px: f64,
    /// Minimum number of targets (groups of 4 corners).
    pub min_targets: usize,
    /// Targets seen more obliquely than this are reported, degrees.
    pub grazing_warn_deg: f64,
    /// Targets seen more obliquely than this are not used, degrees.
    pub grazing_reject_deg: f64,
    /// Condition number of the normal matrix above which the pose is refused.
    pub max_condition: f64,
    /// Condition number above which a warning is reported.
    pub warn_condition: f64,
}

impl PnpConfig {
    /// Defaults.
    pub const DEFAULT: Self = Self {
        inlier_px: 4.0,
        outlier_sigma: 6.0,
        sigma_floor_px: 0.05,
        min_targets: 1,
        grazing_warn_deg: 70.0,
        grazing_reject_deg: 82.0,
        max_condition: 1e12,
        warn_condition: 1e8,
    };
}

impl Default for PnpConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A refined pose with its uncertainty.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseEstimate {
    /// The layout's frame from the camera (`world_from_camera` for reference targets).
    pub frame_from_camera: Pose,
    /// 6 x 6 covariance, row-major: orientation increment (rad, layout frame) then camera
    /// centre (m, layout frame).
    pub covariance: Vec<f64>,
    /// RMS reprojection error of the inliers, pixels.
    pub rms_px: f64,
    /// Targets used.
    pub targets_used: Vec<u32>,
    /// Targets rejected (outliers, grazing).
    pub targets_rejected: Vec<u32>,
    /// Points used.
    pub points_used: usize,
    /// LM iterations.
    pub iterations: usize,
    /// Condition number of the normal matrix.
    pub condition_number: f64,
    /// Warnings.
    pub diagnostics: Vec<Diagnostic>,
}

impl PoseEstimate {
    /// Standard deviation of the camera position along its worst axis, metres (trace-based).
    pub fn position_sigma_m(&self) -> f64 {
        (self.covariance[21] + self.covariance[28] + self.covariance[35])
            .max(0.0)
            .sqrt()
    }

    /// Standard deviation of the orientation (root of the trace), radians.
    pub fn orientation_sigma_rad(&self) -> f64 {
        (self.covariance[0] + self.covariance[7] + self.covariance[14])
            .max(0.0)
            .sqrt()
    }
}

/// Exponential map: rotation vector to quaternion.
pub fn exp_so3(v: DVec3) -> glam::DQuat {
    Pose::from_rotation_vector(v, DVec3::ZERO).rotation
}

/// Projects `obj` with camera pose `frame_from_camera`.
fn project(cam: &CameraModel, frame_from_camera: &Pose, obj: DVec3) -> Option<DVec2> {
    let p = frame_from_camera.rotation.inverse() * (obj - frame_from_camera.translation_m);
    cam.project(p)
}

/// The pose from parameters `[δ, C]` around `base`.
fn pose_from_params(base: &Pose, x: &[f64]) -> Pose {
    let rot = exp_so3(DVec3::new(x[0], x[1], x[2])) * base.rotation;
    Pose::new(rot, DVec3::new(x[3], x[4], x[5]))
}

/// Residual vector (whitened) of points for a pose.
fn residuals(cam: &CameraModel, pose: &Pose, pts: &[PointObs], floor: f64) -> Option<DVector<f64>> {
    let mut r = DVector::zeros(2 * pts.len());
    for (i, p) in pts.iter().enumerate() {
        let proj = project(cam, pose, p.object_m)?;
        let s = p.sigma_px.max(floor);
        r[2 * i] = (proj.x - p.image_px.x) / s;
        r[2 * i + 1] = (proj.y - p.image_px.y) / s;
    }
    Some(r)
}

fn reproj_errors(cam: &CameraModel, pose: &Pose, pts: &[PointObs]) -> Vec<f64> {
    pts.iter()
        .map(|p| {
            project(cam, pose, p.object_m)
                .map(|q| q.distance(p.image_px))
                .unwrap_or(f64::INFINITY)
        })
        .collect()
}

fn group_ids(pts: &[PointObs]) -> Vec<u32> {
    let mut ids: Vec<u32> = pts.iter().map(|p| p.target).collect();
    ids.sort_unstable();
    ids.dedup();
    ids
}

/// Pose hypothesis from coplanar points via their plane homography (`frame_from_camera`).
fn planar_hypothesis(cam: &CameraModel, pts: &[PointObs]) -> Option<Pose> {
    let obj: Vec<DVec3> = pts.iter().map(|p| p.object_m).collect();
    let (world_from_plane, _) = fit_plane(&obj)?;
    let plane_from_world = world_from_plane.inverse();
    let mut src = Vec::with_capacity(pts.len());
    let mut dst = Vec::with_capacity(pts.len());
    for p in pts {
        let q = plane_from_world.transform_point(p.object_m);
        src.push(DVec2::new(q.x, q.y));
        dst.push(cam.undistort_pixel(p.image_px)?);
    }
    let h = homography(&src, &dst)?;
    let cam_from_plane = pose_from_plane_homography(&h)?;
    Some((cam_from_plane * plane_from_world).inverse())
}

fn dlt_hypothesis(cam: &CameraModel, pts: &[PointObs]) -> Option<Pose> {
    let obj: Vec<DVec3> = pts.iter().map(|p| p.object_m).collect();
    let norm: Option<Vec<DVec2>> = pts
        .iter()
        .map(|p| cam.undistort_pixel(p.image_px))
        .collect();
    Some(dlt_pose(&obj, &norm?)?.inverse())
}

/// Relative planarity below which points are treated as coplanar.
const PLANAR_RATIO: f64 = 1e-3;
/// Relative spread below which points are collinear (no pose).
pub const COLLINEAR_RATIO: f64 = 1e-3;
/// Relative spread below which a pose is returned with a [`Diagnostic::NearCollinear`] warning
/// (a row of targets: the rotation about the row is then several times less certain).
pub const NEAR_COLLINEAR_RATIO: f64 = 0.05;

/// Hypotheses refined by local optimisation (the best by score).
const LO_HYPOTHESES: usize = 6;
/// Refine-and-rescore rounds per hypothesis.
const LO_ROUNDS: usize = 4;
/// A short robust LM for the local optimisation.
const LO_LM: LmConfig = LmConfig {
    max_iterations: 8,
    ..LmConfig::DEFAULT
};

/// LM refinement of a pose on `pts` (parameters `[δ, C]` around `base`).
fn refine(
    cam: &CameraModel,
    base: &Pose,
    pts: &[PointObs],
    floor: f64,
    lm_cfg: &LmConfig,
) -> Option<(Pose, crate::lm::LmResult)> {
    let x0 = DVector::from_vec(vec![
        0.0,
        0.0,
        0.0,
        base.translation_m.x,
        base.translation_m.y,
        base.translation_m.z,
    ]);
    let f = |x: &DVector<f64>| residuals(cam, &pose_from_params(base, x.as_slice()), pts, floor);
    let res = minimize(f, x0, lm_cfg)?;
    Some((pose_from_params(base, res.x.as_slice()), res))
}

/// Estimates `frame_from_camera` from point observations. `initial` (if any) is used as an
/// extra hypothesis (e.g. the previous image's pose or a known pose).
pub fn estimate_pose(
    cam: &CameraModel,
    pts: &[PointObs],
    initial: Option<Pose>,
    cfg: &PnpConfig,
) -> Result<PoseEstimate, PoseError> {
    let ids = group_ids(pts);
    if ids.len() < cfg.min_targets || pts.len() < 4 {
        return Err(PoseError::TooFewTargets {
            found: ids.len(),
            points: pts.len(),
            needed: cfg.min_targets.max(1),
        });
    }
    let obj: Vec<DVec3> = pts.iter().map(|p| p.object_m).collect();
    let (_, sv) = fit_plane(&obj).ok_or(PoseError::Degenerate {
        what: "points",
        measure: 0.0,
    })?;
    if sv[1] < COLLINEAR_RATIO * sv[0] {
        return Err(PoseError::Degenerate {
            what: "collinear target points",
            measure: sv[1] / sv[0].max(1e-300),
        });
    }
    let planar = sv[2] < PLANAR_RATIO * sv[0];
    let mut diagnostics = Vec::new();
    if sv[1] < NEAR_COLLINEAR_RATIO * sv[0] {
        diagnostics.push(Diagnostic::NearCollinear {
            spread_ratio: sv[1] / sv[0].max(1e-300),
        });
    }
    // Hypotheses.
    let mut hyps: Vec<Pose> = Vec::new();
    hyps.extend(initial);
    if planar {
        hyps.extend(planar_hypothesis(cam, pts));
    } else if pts.len() >= 6 {
        hyps.extend(dlt_hypothesis(cam, pts));
    }
    for id in &ids {
        let g: Vec<PointObs> = pts.iter().copied().filter(|p| p.target == *id).collect();
        if g.len() >= 4 {
            hyps.extend(planar_hypothesis(cam, &g));
        }
    }
    // Score: inlier targets, then total error.
    let score = |pose: &Pose| -> (usize, f64) {
        let errs = reproj_errors(cam, pose, pts);
        let mut n = 0;
        let mut total = 0.0;
        for id in &ids {
            let worst = pts
                .iter()
                .zip(&errs)
                .filter(|(p, _)| p.target == *id)
                .map(|(_, e)| *e)
                .fold(0.0, f64::max);
            if worst < cfg.inlier_px {
                n += 1;
                total += worst;
            }
        }
        (n, total)
    };
    let better = |a: (usize, f64), b: (usize, f64)| a.0 > b.0 || (a.0 == b.0 && a.1 < b.1);
    let mut scored: Vec<(Pose, (usize, f64))> = hyps
        .into_iter()
        .filter(|h| h.is_finite())
        .map(|h| (h, score(&h)))
        .collect();
    scored.sort_by(|a, b| b.1 .0.cmp(&a.1 .0).then(a.1 .1.total_cmp(&b.1 .1)));
    // Local optimisation (LO-RANSAC): the best few hypotheses are refined on their inlier
    // targets and rescored while that gains targets. A single small tag's pose predicts far
    // targets poorly; refined on itself and its neighbours it recruits the rest.
    let mut best: Option<(Pose, (usize, f64))> = scored.first().copied();
    for (h, s) in scored.iter().take(LO_HYPOTHESES) {
        let (mut pose, mut sc) = (*h, *s);
        for _ in 0..LO_ROUNDS {
            let errs = reproj_errors(cam, &pose, pts);
            let inl: Vec<PointObs> = ids
                .iter()
                .filter(|id| {
                    pts.iter()
                        .zip(&errs)
                        .filter(|(p, _)| p.target == **id)
                        .all(|(_, e)| *e < cfg.inlier_px)
                })
                .flat_map(|id| pts.iter().copied().filter(move |p| p.target == *id))
                .collect();
            if inl.len() < 4 {
                break;
            }
            let Some((refined, _)) = refine(cam, &pose, &inl, cfg.sigma_floor_px, &LO_LM) else {
                break;
            };
            let s2 = score(&refined);
            if !better(s2, sc) {
                break;
            }
            pose = refined;
            sc = s2;
        }
        if best.as_ref().is_none_or(|(_, b)| better(sc, *b)) {
            best = Some((pose, sc));
        }
    }
    // With no target within `inlier_px` of any hypothesis, all targets are refined from the
    // best-effort hypothesis and LM decides.
    let (mut pose, (n_in, _)) = best.ok_or(PoseError::NoConsensus { targets: ids.len() })?;
    // Grazing angles with the hypothesis.
    let mut rejected: Vec<u32> = Vec::new();
    let centre = pose.translation_m;
    for id in &ids {
        let g: Vec<&PointObs> = pts.iter().filter(|p| p.target == *id).collect();
        let n = g[0].normal;
        if n.length_squared() < 0.5 {
            continue;
        }
        let c = g.iter().map(|p| p.object_m).sum::<DVec3>() / g.len() as f64;
        let to_cam = (centre - c).normalize_or_zero();
        let ang = n.dot(to_cam).clamp(-1.0, 1.0).acos().to_degrees();
        if ang > cfg.grazing_reject_deg {
            rejected.push(*id);
            diagnostics.push(Diagnostic::GrazingTarget {
                target: *id,
                angle_deg: ang,
                used: false,
            });
        } else if ang > cfg.grazing_warn_deg {
            diagnostics.push(Diagnostic::GrazingTarget {
                target: *id,
                angle_deg: ang,
                used: true,
            });
        }
    }
    // Inlier set from the hypothesis.
    let errs = reproj_errors(cam, &pose, pts);
    let mut used: Vec<u32> = ids
        .iter()
        .copied()
        .filter(|id| !rejected.contains(id))
        .filter(|id| {
            n_in == 0
                || pts
                    .iter()
                    .zip(&errs)
                    .filter(|(p, _)| p.target == *id)
                    .all(|(_, e)| *e < cfg.inlier_px)
        })
        .collect();
    for id in &ids {
        if !used.contains(id) && !rejected.contains(id) {
            rejected.push(*id);
        }
    }
    let lm_cfg = LmConfig::DEFAULT;
    let mut result = None;
    for pass in 0..2 {
        let inl: Vec<PointObs> = pts
            .iter()
            .copied()
            .filter(|p| used.contains(&p.target))
            .collect();
        if inl.len() < 4 {
            return Err(PoseError::TooFewTargets {
                found: used.len(),
                points: inl.len(),
                needed: cfg.min_targets.max(1),
            });
        }
        let (refined, res) = refine(cam, &pose, &inl, cfg.sigma_floor_px, &lm_cfg).ok_or(
            PoseError::NoConsensus {
                targets: used.len(),
            },
        )?;
        pose = refined;
        // Outlier targets.
        let errs = reproj_errors(cam, &pose, &inl);
        let mut bad: Vec<u32> = Vec::new();
        for (p, e) in inl.iter().zip(&errs) {
            let s = p.sigma_px.max(cfg.sigma_floor_px) * res.variance_factor.sqrt().max(1.0);
            if *e > 1.0 && *e > cfg.outlier_sigma * s && !bad.contains(&p.target) {
                bad.push(p.target);
            }
        }
        let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len().max(1) as f64).sqrt();
        result = Some((res, rms, inl.len()));
        if pass == 0 && !bad.is_empty() && bad.len() < used.len() {
            used.retain(|id| !bad.contains(id));
            diagnostics.push(Diagnostic::OutlierTargets {
                targets: bad.clone(),
            });
            rejected.extend(bad);
            continue;
        }
        break;
    }
    let (res, rms_px, points_used) = result.ok_or(PoseError::NoConsensus { targets: ids.len() })?;
    if res.condition_number > cfg.max_condition {
        return Err(PoseError::IllConditioned {
            condition_number: res.condition_number,
        });
    }
    if res.condition_number > cfg.warn_condition {
        diagnostics.push(Diagnostic::IllConditioned {
            condition_number: res.condition_number,
        });
    }
    if used.len() == 1 {
        diagnostics.push(Diagnostic::SingleTarget);
    }
    let covariance = res
        .covariance
        .as_ref()
        .map(|c| c.transpose().as_slice().to_vec())
        .ok_or(PoseError::IllConditioned {
            condition_number: res.condition_number,
        })?;
    rejected.sort_unstable();
    rejected.dedup();
    Ok(PoseEstimate {
        frame_from_camera: pose,
        covariance,
        rms_px,
        targets_used: used,
        targets_rejected: rejected,
        points_used,
        iterations: res.iterations,
        condition_number: res.condition_number,
        diagnostics,
    })
}

/// Points for a set of targets: pairs of `(corners_m, outward normal)` with their detected
/// corners and corner sigmas.
pub fn target_points(
    target: u32,
    corners_m: &[DVec3; 4],
    normal: DVec3,
    corners_px: &[DVec2; 4],
    sigma_px: &[f64; 4],
) -> [PointObs; 4] {
    std::array::from_fn(|k| PointObs {
        object_m: corners_m[k],
        image_px: corners_px[k],
        sigma_px: sigma_px[k],
        target,
        normal,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn camera() -> CameraModel {
        let mut c = CameraModel::from_fov(1524, 1012, 45f64.to_radians());
        c.distortion.k1 = -0.08;
        c.distortion.k2 = 0.02;
        c
    }

    /// A field of square targets on two planes (non-planar) or one plane.
    fn field(planar: bool) -> Vec<(u32, [DVec3; 4], DVec3)> {
        let mut out = Vec::new();
        let s = 0.03;
        let mut id = 0;
        for i in -2..=2 {
            for j in -2..=2 {
                let c = DVec3::new(i as f64 * 0.08, j as f64 * 0.06, 0.0);
                let z = if planar || i < 1 {
                    0.0
                } else {
                    0.05 * i as f64
                };
                let c = c + DVec3::new(0.0, 0.0, z);
                let corners = [
                    c + DVec3::new(-s / 2.0, s / 2.0, 0.0),
                    c + DVec3::new(s / 2.0, s / 2.0, 0.0),
                    c + DVec3::new(s / 2.0, -s / 2.0, 0.0),
                    c + DVec3::new(-s / 2.0, -s / 2.0, 0.0),
                ];
                out.push((id, corners, DVec3::new(0.0, 0.0, -1.0)));
                id += 1;
            }
        }
        out
    }

    fn observe(
        cam: &CameraModel,
        world_from_camera: &Pose,
        targets: &[(u32, [DVec3; 4], DVec3)],
        noise_px: f64,
        seed: u64,
    ) -> Vec<PointObs> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut pts = Vec::new();
        for (id, corners, n) in targets {
            for c in corners {
                let p = world_from_camera.inverse().transform_point(*c);
                let Some(px) = cam.project(p) else { continue };
                let noise = DVec2::new(
                    rng.random_range(-1.0..1.0) * noise_px * 1.7,
                    rng.random_range(-1.0..1.0) * noise_px * 1.7,
                );
                pts.push(PointObs {
                    object_m: *c,
                    image_px: px + noise,
                    sigma_px: noise_px,
                    target: *id,
                    normal: *n,
                });
            }
        }
        pts
    }

    fn truth_pose() -> Pose {
        Pose::look_at(
            DVec3::new(0.15, -0.1, -0.7),
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(0.0, -1.0, 0.0),
        )
        .expect("valid look-at")
    }

    #[test]
    fn recovers_pose_from_noisy_planar_and_nonplanar_fields() {
        let cam = camera();
        for planar in [true, false] {
            let truth = truth_pose();
            let pts = observe(&cam, &truth, &field(planar), 0.1, 3);
            let est = estimate_pose(&cam, &pts, None, &PnpConfig::DEFAULT).expect("pose");
            let dp = est.frame_from_camera.distance_to_m(&truth);
            let da = est.frame_from_camera.angle_to_rad(&truth).to_degrees();
            assert!(dp < 1e-3, "planar {planar}: position error {dp}");
            assert!(da < 0.05, "planar {planar}: angle error {da}");
            assert!(da.to_radians() < 4.0 * est.orientation_sigma_rad() + 1e-9);
            assert!(est.rms_px < 0.3);
            // The stated uncertainty covers the actual error (within 4 sigma).
            assert!(
                dp < 4.0 * est.position_sigma_m() + 1e-6,
                "{dp} vs {}",
                est.position_sigma_m()
            );
        }
    }

    #[test]
    fn rejects_a_wrong_target_and_says_so() {
        let cam = camera();
        let truth = truth_pose();
        let mut pts = observe(&cam, &truth, &field(false), 0.05, 4);
        // Target 3 is misplaced in the layout by 2 cm: its observations disagree.
        for p in pts.iter_mut().filter(|p| p.target == 3) {
            p.object_m.x += 0.02;
        }
        let est = estimate_pose(&cam, &pts, None, &PnpConfig::DEFAULT).expect("pose");
        assert!(est.targets_rejected.contains(&3));
        assert!(est.frame_from_camera.distance_to_m(&truth) < 1e-3);
    }

    #[test]
    fn refinement_never_worsens_a_perfect_initial_pose() {
        let cam = camera();
        let truth = truth_pose();
        let pts = observe(&cam, &truth, &field(false), 0.0, 5);
        let est = estimate_pose(&cam, &pts, Some(truth), &PnpConfig::DEFAULT).expect("pose");
        assert!(est.frame_from_camera.distance_to_m(&truth) < 1e-9);
    }

    #[test]
    fn degenerate_inputs_give_typed_errors() {
        let cam = camera();
        let truth = truth_pose();
        let pts = observe(&cam, &truth, &field(true), 0.1, 6);
        // Too few points.
        assert!(matches!(
            estimate_pose(&cam, &pts[..3], None, &PnpConfig::DEFAULT),
            Err(PoseError::TooFewTargets { .. })
        ));
        // Collinear points: put every point on a line.
        let line: Vec<PointObs> = pts
            .iter()
            .enumerate()
            .map(|(i, p)| PointObs {
                object_m: DVec3::new(i as f64 * 0.01, 0.0, 0.0),
                ..*p
            })
            .collect();
        assert!(matches!(
            estimate_pose(&cam, &line, None, &PnpConfig::DEFAULT),
            Err(PoseError::Degenerate { .. })
        ));
    }

    #[test]
    fn grazing_targets_are_reported() {
        let cam = camera();
        // A planar field seen from `deg` off its normal (rotating about the x axis).
        let view = |deg: f64| {
            let a = deg.to_radians();
            let eye = DVec3::new(0.0, -0.7 * a.sin(), -0.7 * a.cos());
            Pose::look_at(eye, DVec3::ZERO, DVec3::new(0.0, 0.0, -1.0)).expect("valid")
        };
        let grazing = |est: &PoseEstimate, used: bool| -> Vec<f64> {
            est.diagnostics
                .iter()
                .filter_map(|d| match d {
                    Diagnostic::GrazingTarget {
                        angle_deg, used: u, ..
                    } if *u == used => Some(*angle_deg),
                    _ => None,
                })
                .collect()
        };
        // 40 degrees: nothing to report.
        let pts = observe(&cam, &view(40.0), &field(true), 0.05, 7);
        let est = estimate_pose(&cam, &pts, None, &PnpConfig::DEFAULT).expect("pose");
        assert!(grazing(&est, true).is_empty() && grazing(&est, false).is_empty());
        // 76 degrees: every target reported, still used, with its angle.
        let pts = observe(&cam, &view(76.0), &field(true), 0.05, 7);
        let est = estimate_pose(&cam, &pts, None, &PnpConfig::DEFAULT).expect("pose");
        let used = grazing(&est, true);
        assert_eq!(used.len(), 25, "{:?}", est.diagnostics);
        assert!(used.iter().all(|a| (70.0..82.0).contains(a)), "{used:?}");
        assert!(est.targets_rejected.is_empty());
        // 86 degrees: all beyond the limit: refused, with the reason.
        let pts = observe(&cam, &view(86.0), &field(true), 0.05, 7);
        match estimate_pose(&cam, &pts, None, &PnpConfig::DEFAULT) {
            Err(PoseError::TooFewTargets { found: 0, .. }) => {}
            other => panic!("expected TooFewTargets, got {other:?}"),
        }
    }

    #[test]
    fn too_few_targets_error_counts_what_was_seen() {
        let cam = camera();
        let pts = observe(&cam, &truth_pose(), &field(false), 0.05, 8);
        let two: Vec<PointObs> = pts.iter().copied().filter(|p| p.target < 2).collect();
        let cfg = PnpConfig {
            min_targets: 3,
            ..PnpConfig::DEFAULT
        };
        assert_eq!(
            estimate_pose(&cam, &two, None, &cfg).err(),
            Some(PoseError::TooFewTargets {
                found: 2,
                points: 8,
                needed: 3
            })
        );
    }

    #[test]
    fn a_row_of_targets_is_reported_near_collinear_and_its_uncertainty_says_so() {
        let cam = camera();
        // Small targets along one line: the spread across the row is the tag size only.
        let row: Vec<(u32, [DVec3; 4], DVec3)> = (0..7)
            .map(|i| {
                let c = DVec3::new(-0.18 + 0.06 * i as f64, 0.0, 0.0);
                let s = 0.012;
                (
                    i,
                    [
                        c + DVec3::new(-s / 2.0, s / 2.0, 0.0),
                        c + DVec3::new(s / 2.0, s / 2.0, 0.0),
                        c + DVec3::new(s / 2.0, -s / 2.0, 0.0),
                        c + DVec3::new(-s / 2.0, -s / 2.0, 0.0),
                    ],
                    DVec3::new(0.0, 0.0, -1.0),
                )
            })
            .collect();
        let truth = truth_pose();
        let pts = observe(&cam, &truth, &row, 0.1, 9);
        let est = estimate_pose(&cam, &pts, None, &PnpConfig::DEFAULT).expect("pose");
        let ratio = est.diagnostics.iter().find_map(|d| match d {
            Diagnostic::NearCollinear { spread_ratio } => Some(*spread_ratio),
            _ => None,
        });
        let ratio = ratio.expect("near-collinear reported");
        assert!(
            ratio > COLLINEAR_RATIO && ratio < NEAR_COLLINEAR_RATIO,
            "{ratio}"
        );
        // The same number of points on a 2-D field is far better determined: the stated
        // orientation uncertainty of the row is several times larger, and still honest.
        let grid = observe(&cam, &truth, &field(true), 0.1, 9);
        let g = estimate_pose(&cam, &grid, None, &PnpConfig::DEFAULT).expect("pose");
        assert!(est.orientation_sigma_rad() > 3.0 * g.orientation_sigma_rad());
        let err = est.frame_from_camera.angle_to_rad(&truth);
        assert!(
            err < 4.0 * est.orientation_sigma_rad(),
            "{err} vs {}",
            est.orientation_sigma_rad()
        );
        // A full field is not flagged.
        assert!(!g
            .diagnostics
            .iter()
            .any(|d| matches!(d, Diagnostic::NearCollinear { .. })));
    }
}
