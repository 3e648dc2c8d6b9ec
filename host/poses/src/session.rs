//! Every pose of a session from its images: camera per image (reference targets), head per image
//! (headdress targets), the flash (light-position images), the reflectance standard
//! (standard-position images), and, when the camera is not calibrated, its intrinsics from the
//! reference field.
//!
//! Survey images (role `survey`: taken before the subject sits, without the flash) are posed
//! like the others by their reference targets and serve the calibration and the joint
//! adjustment; they have no head pose (a headdress seen in one is not on the head), and the
//! flash and standard come only from their own roles' images.
//!
//! Known quantities in the session skip their stage and say so in [`SessionPoses::skipped`]:
//! a known `world_from_camera`/`world_from_head` per image, `known.world_from_flash` or
//! `known.light_position_m`, `known.world_from_standard`, `known.stationary_sample`.
//!
//! Corners the detector marks occluded (a partly hidden tag, `Detection::occluded_corners`)
//! are not used by any pose or the bundle adjustment; each such target is listed in its image's
//! diagnostics ([`Diagnostic::OccludedCorners`]) with the corners left out.
//!
//! Composite poses (head, flash, standard in the world) combine two PnP estimates; their
//! covariance is propagated to first order through the composition (numerical Jacobian), with
//! the two estimates independent (they use disjoint targets). The flash position is the
//! inverse-covariance-weighted mean over the light-position images.
//!
//! Finally (unless [`PoseConfig::bundle`] disables it) a joint bundle adjustment
//! ([`crate::bundle`]) refines every estimated pose together, with a robust loss and exact
//! marginal covariances; its cost before and after is in [`SessionPoses::bundle`]. It never
//! returns a worse result than the per-image estimates (in its robust cost); when it cannot run
//! (singular system), the per-image estimates stand and the reason is in `skipped`.

use crate::bundle::{bundle_adjust, BundleConfig, BundleImage, BundleProblem, BundleReport, Frame};
use crate::calib::{calibrate, guess_camera, CalibConfig, Calibration};
use crate::error::{Diagnostic, PoseError};
use crate::pnp::{estimate_pose, exp_so3, target_points, PnpConfig, PointObs, PoseEstimate};
use glam::{DVec2, DVec3};
use nalgebra::{DMatrix, Matrix3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_session::{CameraSpec, ImageRole, Session, Target, TargetGroup, Truth};
use skinbrdf_targets::{detect::detect_with_stats, Detection, DetectorConfig, GrayF32};
use std::collections::HashMap;
use std::time::Instant;

/// Minimum number of targets for a head, flash or standard pose (one small tag alone is
/// ambiguous: its planar flip fits about as well).
pub const MIN_TARGETS_COMPOSITE: usize = 2;

/// Settings of [`estimate_session`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseConfig {
    /// Target detection.
    pub detector: DetectorConfig,
    /// Per-image PnP.
    pub pnp: PnpConfig,
    /// Calibration (used when the camera is `to-be-calibrated`, or when `recalibrate`).
    pub calib: CalibConfig,
    /// Recalibrate even a calibrated camera from the reference field.
    pub recalibrate: bool,
    /// The final joint bundle adjustment.
    #[serde(default)]
    pub bundle: BundleConfig,
}

impl PoseConfig {
    /// Defaults.
    pub const DEFAULT: Self = Self {
        detector: DetectorConfig::DEFAULT,
        pnp: PnpConfig::DEFAULT,
        calib: CalibConfig::DEFAULT,
        recalibrate: false,
        bundle: BundleConfig::DEFAULT,
    };
}

impl Default for PoseConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A pose with its 6 x 6 covariance (orientation increment rad, then position m; world frame).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCov {
    /// The pose (`world_from_x`).
    pub pose: Pose,
    /// Row-major 6 x 6 covariance (empty when the pose was given, not estimated).
    pub covariance: Vec<f64>,
    /// RMS reprojection error of the targets used, pixels (0 when given).
    pub rms_px: f64,
    /// Targets used.
    pub targets_used: usize,
    /// Where it came from: `estimated` or `known`.
    pub source: String,
}

impl PoseWithCov {
    fn known(pose: Pose) -> Self {
        Self {
            pose,
            covariance: Vec::new(),
            rms_px: 0.0,
            targets_used: 0,
            source: "known".into(),
        }
    }

    fn from_estimate(e: &PoseEstimate) -> Self {
        Self {
            pose: e.frame_from_camera,
            covariance: e.covariance.clone(),
            rms_px: e.rms_px,
            targets_used: e.targets_used.len(),
            source: "estimated".into(),
        }
    }

    /// Position standard deviation (root of the covariance trace), metres.
    pub fn position_sigma_m(&self) -> f64 {
        if self.covariance.len() < 36 {
            return 0.0;
        }
        (self.covariance[21] + self.covariance[28] + self.covariance[35])
            .max(0.0)
            .sqrt()
    }
}

/// The poses of one image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImagePoses {
    /// Image file (as in `session.toml`).
    pub file: String,
    /// Its role.
    pub role: ImageRole,
    /// Tags detected, per layout (`reference`, `headdress`, `flash`, `standard`, `unknown`).
    pub targets_found: HashMap<String, usize>,
    /// World from camera.
    pub world_from_camera: Option<PoseWithCov>,
    /// World from head.
    pub world_from_head: Option<PoseWithCov>,
    /// World from flash (light-position images).
    pub world_from_flash: Option<PoseWithCov>,
    /// World from standard (standard-position images).
    pub world_from_standard: Option<PoseWithCov>,
    /// Detection time, milliseconds.
    pub detect_ms: f64,
    /// Pose estimation time, milliseconds.
    pub pose_ms: f64,
    /// Warnings.
    pub diagnostics: Vec<Diagnostic>,
    /// Failures of individual estimates (the image's other poses may still be valid).
    pub errors: Vec<String>,
    /// The tags detected, with their corners (older `poses.json` files have none).
    #[serde(default)]
    pub detections: Vec<DetectedTag>,
}

/// One tag found in an image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectedTag {
    /// tag36h11 id.
    pub id: u32,
    /// The layout the id belongs to (`unknown` for an id no layout lists).
    pub layout: String,
    /// Corners in pixels, in the layout's corner order.
    pub corners_px: [DVec2; 4],
    /// Standard deviation of each corner along its worst direction, pixels.
    pub corner_sigma_px: [f64; 4],
    /// Per corner, whether the detector marked it occluded (partly hidden tag); such corners
    /// are not used by the poses.
    #[serde(default)]
    pub occluded_corners: [bool; 4],
}

/// All poses of a session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionPoses {
    /// The camera used (given, or calibrated here).
    pub camera: CameraModel,
    /// The calibration, when one was run.
    pub calibration: Option<Calibration>,
    /// Per image, in session order.
    pub images: Vec<ImagePoses>,
    /// The flash's emitting point, world frame.
    pub light_position_m: Option<DVec3>,
    /// Its 3 x 3 covariance, m², row-major.
    pub light_position_cov_m2: Vec<f64>,
    /// How the light-position images agree on it (two or more placed it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_agreement: Option<LightAgreement>,
    /// World from flash (from the first light-position image that saw the flash, or known).
    pub world_from_flash: Option<PoseWithCov>,
    /// World from standard.
    pub world_from_standard: Option<PoseWithCov>,
    /// Stages skipped because the session gives the quantity.
    pub skipped: Vec<String>,
    /// Total wall time, milliseconds.
    pub total_ms: f64,
    /// The joint bundle adjustment's report (None when it did not run).
    #[serde(default)]
    pub bundle: Option<BundleReport>,
}

/// Which layout a tag belongs to, with its geometry.
#[derive(Debug, Clone, Copy)]
enum Layout {
    Reference,
    Headdress,
    Flash,
    Standard,
}

impl Layout {
    fn name(self) -> &'static str {
        match self {
            Self::Reference => "reference",
            Self::Headdress => "headdress",
            Self::Flash => "flash",
            Self::Standard => "standard",
        }
    }
}

fn layout_table(session: &Session) -> HashMap<u32, (Layout, Target)> {
    let f = &session.file;
    let mut m = HashMap::new();
    for t in &f.targets.reference {
        m.insert(t.id, (Layout::Reference, *t));
    }
    for t in &f.targets.headdress {
        m.insert(t.id, (Layout::Headdress, *t));
    }
    for t in &f.flash.targets {
        m.insert(t.id, (Layout::Flash, *t));
    }
    if let Some(s) = &f.standard {
        for t in &s.targets {
            m.insert(t.id, (Layout::Standard, *t));
        }
    }
    m
}

/// Loads an image as grey at its full resolution (the mean of the linear channels; green,
/// interpolated at red and blue, for a raw image loaded per photosite: see
/// [`Session::load_geometry_grey`]).
fn load_grey(session: &Session, index: usize) -> Result<GrayF32, PoseError> {
    let img = session
        .load_geometry_grey(index)
        .map_err(|e| PoseError::Image {
            file: session.file.images[index].file.clone(),
            problem: skinbrdf_core::error_text(&e),
        })?;
    GrayF32::new(img.width as usize, img.height as usize, img.data).map_err(|e| PoseError::Image {
        file: session.file.images[index].file.clone(),
        problem: e.to_string(),
    })
}

fn points_for(
    dets: &[Detection],
    table: &HashMap<u32, (Layout, Target)>,
    which: &str,
) -> Vec<PointObs> {
    let mut pts = Vec::new();
    for d in dets {
        if let Some((l, t)) = table.get(&d.id) {
            if l.name() == which {
                // Corners the detector marks occluded are left out (reported per image).
                let all = target_points(
                    d.id,
                    &t.corners_m,
                    t.outward_normal(),
                    &d.corners_px,
                    &d.corner_sigma_px(),
                );
                pts.extend(
                    all.into_iter()
                        .zip(d.occluded_corners)
                        .filter(|(_, hidden)| !hidden)
                        .map(|(p, _)| p),
                );
            }
        }
    }
    pts
}

/// Composes `world_from_camera * (frame_from_camera)⁻¹` with first-order covariance.
fn compose(cam: &PoseWithCov, frame: &PoseEstimate) -> PoseWithCov {
    let f = |x: &[f64]| -> Pose {
        let wc = Pose::new(
            exp_so3(DVec3::new(x[0], x[1], x[2])) * cam.pose.rotation,
            cam.pose.translation_m + DVec3::new(x[3], x[4], x[5]),
        );
        let fc = Pose::new(
            exp_so3(DVec3::new(x[6], x[7], x[8])) * frame.frame_from_camera.rotation,
            frame.frame_from_camera.translation_m + DVec3::new(x[9], x[10], x[11]),
        );
        wc * fc.inverse()
    };
    let x0 = [0.0; 12];
    let p0 = f(&x0);
    let mut sigma_in = DMatrix::<f64>::zeros(12, 12);
    if cam.covariance.len() == 36 {
        for i in 0..6 {
            for j in 0..6 {
                sigma_in[(i, j)] = cam.covariance[i * 6 + j];
            }
        }
    }
    for i in 0..6 {
        for j in 0..6 {
            sigma_in[(6 + i, 6 + j)] = frame.covariance[i * 6 + j];
        }
    }
    let mut jac = DMatrix::<f64>::zeros(6, 12);
    for c in 0..12 {
        let h = 1e-7;
        let mut xp = x0;
        xp[c] = h;
        let mut xm = x0;
        xm[c] = -h;
        let (pp, pm) = (f(&xp), f(&xm));
        let dr = (pp.rotation * pm.rotation.inverse()).normalize();
        let drv = Pose::new(dr, DVec3::ZERO).rotation_vector() / (2.0 * h);
        let dt = (pp.translation_m - pm.translation_m) / (2.0 * h);
        for (r, v) in [drv.x, drv.y, drv.z, dt.x, dt.y, dt.z].iter().enumerate() {
            jac[(r, c)] = *v;
        }
    }
    let out = &jac * sigma_in * jac.transpose();
    PoseWithCov {
        pose: p0,
        covariance: out.transpose().as_slice().to_vec(),
        rms_px: frame.rms_px,
        targets_used: frame.targets_used.len(),
        source: "estimated".into(),
    }
}

/// The tags found in one image.
pub(crate) struct Detected {
    pub(crate) dets: Vec<Detection>,
    pub(crate) detect_ms: f64,
    pub(crate) error: Option<String>,
}

/// The tags found in every image of a session by one detector configuration: detection
/// depends only on the images, their linearization and the detector, so the survey's
/// detections serve the pose stage on the surveyed session (the same images with placements
/// written in) instead of decoding and detecting every image again.
pub struct SessionDetections {
    dir: std::path::PathBuf,
    images: Vec<skinbrdf_session::ImageEntry>,
    linearization: skinbrdf_session::Linearization,
    detector: DetectorConfig,
    pub(crate) detected: Vec<Detected>,
}

impl std::fmt::Debug for SessionDetections {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SessionDetections")
            .field("dir", &self.dir)
            .field("images", &self.images.len())
            .field(
                "tags",
                &self.detected.iter().map(|d| d.dets.len()).sum::<usize>(),
            )
            .finish_non_exhaustive()
    }
}

impl SessionDetections {
    /// Detects the tags of every image of `session` with `detector` (parallel over images).
    pub fn detect(session: &Session, detector: &DetectorConfig) -> Self {
        Self {
            dir: session.dir.clone(),
            images: session.file.images.clone(),
            linearization: session.file.linearization.clone(),
            detector: *detector,
            detected: detect_all(session, detector),
        }
    }

    /// Whether these are the detections `detector` finds in `session`'s images: the same
    /// directory, image entries (files, roles, linearizations) and default linearization.
    pub fn fits(&self, session: &Session, detector: &DetectorConfig) -> bool {
        self.dir == session.dir
            && self.images == session.file.images
            && self.linearization == session.file.linearization
            && self.detector == *detector
    }
}

/// Detects the tags of every image (parallel over images).
pub(crate) fn detect_all(session: &Session, detector: &DetectorConfig) -> Vec<Detected> {
    (0..session.file.images.len())
        .into_par_iter()
        .map(|i| {
            let t = Instant::now();
            match load_grey(session, i) {
                Ok(img) => {
                    let (dets, _) = detect_with_stats(&img, detector);
                    Detected {
                        dets,
                        detect_ms: t.elapsed().as_secs_f64() * 1e3,
                        error: None,
                    }
                }
                Err(e) => Detected {
                    dets: Vec::new(),
                    detect_ms: t.elapsed().as_secs_f64() * 1e3,
                    error: Some(skinbrdf_core::error_text(&e)),
                },
            }
        })
        .collect()
}

/// Estimates every pose of the session from its images.
pub fn estimate_session(session: &Session, cfg: &PoseConfig) -> Result<SessionPoses, PoseError> {
    estimate_session_stages(session, cfg).map(|(_, last)| last)
}

/// Like [`estimate_session`], also returning the per-image estimates as they were before the
/// joint bundle adjustment (the same value twice when it is disabled or cannot run), to
/// measure what the adjustment brings.
pub fn estimate_session_stages(
    session: &Session,
    cfg: &PoseConfig,
) -> Result<(SessionPoses, SessionPoses), PoseError> {
    estimate_session_stages_with(session, cfg, None)
}

/// Like [`estimate_session`], with the tags already found in the session's images (the
/// survey's, say); detections that do not [fit](SessionDetections::fits) the session and the
/// configuration's detector are not used: the images are detected again.
pub fn estimate_session_detected(
    session: &Session,
    cfg: &PoseConfig,
    detections: &SessionDetections,
) -> Result<SessionPoses, PoseError> {
    estimate_session_stages_with(session, cfg, Some(detections)).map(|(_, last)| last)
}

fn estimate_session_stages_with(
    session: &Session,
    cfg: &PoseConfig,
    detections: Option<&SessionDetections>,
) -> Result<(SessionPoses, SessionPoses), PoseError> {
    let t0 = Instant::now();
    let file = &session.file;
    let unsurveyed = file
        .targets
        .unplaced
        .iter()
        .filter(|t| matches!(t.group, TargetGroup::Reference | TargetGroup::Headdress))
        .count();
    if unsurveyed > 0 {
        return Err(PoseError::Unsurveyed {
            targets: unsurveyed,
        });
    }
    let table = layout_table(session);
    let mut skipped = Vec::new();
    // 1. Detection in every image (parallel), unless given.
    let fresh;
    let detected: &[Detected] = match detections.filter(|d| d.fits(session, &cfg.detector)) {
        Some(d) => &d.detected,
        None => {
            fresh = detect_all(session, &cfg.detector);
            &fresh
        }
    };
    // 2. The camera: given, or calibrated from the reference field.
    let (camera, calibration) = match (&file.camera, cfg.recalibrate) {
        (CameraSpec::Calibrated(m), false) => {
            skipped.push("camera calibration (camera is calibrated in session.toml)".into());
            (*m, None)
        }
        (spec, _) => {
            let (w, h) = spec.size_px();
            let views: Vec<Vec<PointObs>> = detected
                .iter()
                .map(|d| points_for(&d.dets, &table, "reference"))
                .filter(|v| v.len() >= 16)
                .collect();
            let init = match spec {
                CameraSpec::Calibrated(m) => *m,
                CameraSpec::ToBeCalibrated {
                    focal_guess_px: Some(f),
                    ..
                } => CameraModel {
                    fx_px: *f,
                    fy_px: *f,
                    ..CameraModel::from_fov(w, h, 1.0)
                },
                CameraSpec::ToBeCalibrated { .. } => {
                    guess_camera(w, h, &views).ok_or(PoseError::NoFocalStart {
                        why: "no image sees 16 or more reference target corners",
                    })?
                }
            };
            let cal = calibrate(&init, &views, &cfg.calib)?;
            (cal.camera, Some(cal))
        }
    };
    // 3. Per-image poses (parallel).
    let stationary = file.known.stationary_sample;
    let flash_known =
        file.known.world_from_flash.is_some() || file.known.light_position_m.is_some();
    let standard_known = file.known.world_from_standard.is_some();
    let images: Vec<ImagePoses> = file
        .images
        .par_iter()
        .zip(detected.par_iter())
        .map(|(entry, det)| {
            let t = Instant::now();
            let mut out = ImagePoses {
                file: entry.file.clone(),
                role: entry.role,
                targets_found: HashMap::new(),
                world_from_camera: None,
                world_from_head: None,
                world_from_flash: None,
                world_from_standard: None,
                detect_ms: det.detect_ms,
                pose_ms: 0.0,
                diagnostics: Vec::new(),
                errors: det.error.iter().cloned().collect(),
                detections: Vec::with_capacity(det.dets.len()),
            };
            for d in &det.dets {
                let name = table.get(&d.id).map(|(l, _)| l.name()).unwrap_or("unknown");
                *out.targets_found.entry(name.to_string()).or_insert(0) += 1;
                out.detections.push(DetectedTag {
                    id: d.id,
                    layout: name.to_string(),
                    corners_px: d.corners_px,
                    corner_sigma_px: d.corner_sigma_px(),
                    occluded_corners: d.occluded_corners,
                });
                if d.occluded_corners.contains(&true) {
                    out.diagnostics.push(Diagnostic::OccludedCorners {
                        target: d.id,
                        corners: (0..4).filter(|&k| d.occluded_corners[k]).collect(),
                    });
                }
            }
            // Camera.
            if let Some(p) = entry.world_from_camera {
                out.world_from_camera = Some(PoseWithCov::known(p));
            } else {
                let pts = points_for(&det.dets, &table, "reference");
                match estimate_pose(&camera, &pts, None, &cfg.pnp) {
                    Ok(e) => {
                        out.diagnostics.extend(e.diagnostics.iter().cloned());
                        out.world_from_camera = Some(PoseWithCov::from_estimate(&e));
                    }
                    Err(e) => out.errors.push(format!("camera pose: {}", skinbrdf_core::error_text(&e))),
                }
            }
            let Some(wc) = out.world_from_camera.clone() else {
                out.pose_ms = t.elapsed().as_secs_f64() * 1e3;
                return out;
            };
            let mut sub = |which: &str| -> Option<PoseWithCov> {
                let pts = points_for(&det.dets, &table, which);
                if pts.is_empty() {
                    return None;
                }
                // A single small target's pose can be the planar flip: composite poses need two.
                let sub_cfg = PnpConfig {
                    min_targets: cfg.pnp.min_targets.max(MIN_TARGETS_COMPOSITE),
                    ..cfg.pnp
                };
                match estimate_pose(&camera, &pts, None, &sub_cfg) {
                    Ok(e) if e.targets_used.len() < MIN_TARGETS_COMPOSITE => {
                        out.errors.push(format!(
                            "{which} pose: only {} target(s) consistent, {MIN_TARGETS_COMPOSITE} needed",
                            e.targets_used.len()
                        ));
                        None
                    }
                    Ok(e) => {
                        out.diagnostics.extend(e.diagnostics.iter().cloned());
                        Some(compose(&wc, &e))
                    }
                    Err(e) => {
                        out.errors.push(format!("{which} pose: {}", skinbrdf_core::error_text(&e)));
                        None
                    }
                }
            };
            // Head: none in a survey image (taken before the subject sits; a headdress seen
            // there is not on the head).
            let head = if !entry.role.has_subject() {
                None
            } else if let Some(p) = entry.world_from_head {
                Some(PoseWithCov::known(p))
            } else if stationary {
                None
            } else {
                sub("headdress")
            };
            let flash = if entry.role == ImageRole::LightPosition && !flash_known {
                sub("flash")
            } else {
                None
            };
            let standard = if entry.role == ImageRole::StandardPosition && !standard_known {
                sub("standard")
            } else {
                None
            };
            out.world_from_head = head;
            out.world_from_flash = flash;
            out.world_from_standard = standard;
            out.pose_ms = t.elapsed().as_secs_f64() * 1e3;
            out
        })
        .collect();
    if stationary {
        skipped.push("head tracking (known.stationary_sample)".into());
    }
    // 4. Flash: combine the light-position images.
    let light_centre = file.flash.light_centre_m;
    let mut light_agreement = None;
    let (light_position_m, light_position_cov_m2, world_from_flash) =
        if let Some(p) = file.known.world_from_flash {
            skipped.push("flash location (known.world_from_flash)".into());
            (
                Some(p.transform_point(light_centre)),
                Vec::new(),
                Some(PoseWithCov::known(p)),
            )
        } else if let Some(l) = file.known.light_position_m {
            skipped.push("flash location (known.light_position_m)".into());
            (Some(l), Vec::new(), None)
        } else {
            let combined = combine_light_points(&images, light_centre);
            light_agreement = combined.agreement;
            (combined.position_m, combined.cov_m2, combined.first_pose)
        };
    let world_from_standard = if let Some(p) = file.known.world_from_standard {
        skipped.push("standard location (known.world_from_standard)".into());
        Some(PoseWithCov::known(p))
    } else {
        images
            .iter()
            .filter_map(|i| i.world_from_standard.clone())
            .min_by(|a, b| a.position_sigma_m().total_cmp(&b.position_sigma_m()))
    };
    let mut out = SessionPoses {
        camera,
        calibration,
        images,
        light_position_m,
        light_position_cov_m2,
        light_agreement,
        world_from_flash,
        world_from_standard,
        skipped,
        total_ms: 0.0,
        bundle: None,
    };
    out.total_ms = t0.elapsed().as_secs_f64() * 1e3;
    let per_image = out.clone();
    if cfg.bundle.enabled {
        let mut bcfg = cfg.bundle;
        bcfg.refine_intrinsics |= out.calibration.is_some();
        run_bundle(&mut out, detected, &table, light_centre, &bcfg);
    } else {
        out.skipped
            .push("bundle adjustment (disabled in the configuration)".into());
    }
    out.total_ms = t0.elapsed().as_secs_f64() * 1e3;
    Ok((per_image, out))
}

/// The light-position images' flash poses combined into one light point.
struct CombinedLight {
    /// The information-weighted mean of the single-view light points.
    position_m: Option<DVec3>,
    /// Its 3 x 3 covariance, row-major (empty when none).
    cov_m2: Vec<f64>,
    /// The first image's flash pose.
    first_pose: Option<PoseWithCov>,
    /// How the single views agree (two or more).
    agreement: Option<LightAgreement>,
}

/// Combines every image's single-view flash pose: each gives the light point `p_i` with
/// covariance `C_i` (the pose's position block plus the lever arm to the light centre through
/// its rotation block); the combined point is `m = (Σ C_i⁻¹)⁻¹ Σ C_i⁻¹ p_i`.
fn combine_light_points(images: &[ImagePoses], light_centre: DVec3) -> CombinedLight {
    let views: Vec<(&ImagePoses, &PoseWithCov)> = images
        .iter()
        .filter_map(|i| Some((i, i.world_from_flash.as_ref()?)))
        .collect();
    let points: Vec<(&str, DVec3, Matrix3<f64>)> = views
        .iter()
        .filter_map(|(img, e)| {
            let (p, cov) = light_point(e, light_centre);
            let c = (cov.len() == 9).then(|| Matrix3::from_row_slice(&cov))?;
            Some((img.file.as_str(), p, c.try_inverse()?))
        })
        .collect();
    let mut info = Matrix3::<f64>::zeros();
    let mut acc = nalgebra::Vector3::<f64>::zeros();
    for (_, p, inv) in &points {
        info += inv;
        acc += inv * nalgebra::Vector3::new(p.x, p.y, p.z);
    }
    let first_pose = views.first().map(|(_, e)| (*e).clone());
    match info.try_inverse() {
        Some(cov) if !points.is_empty() => {
            let m = cov * acc;
            let position = DVec3::new(m[0], m[1], m[2]);
            CombinedLight {
                position_m: Some(position),
                cov_m2: cov.transpose().as_slice().to_vec(),
                first_pose,
                agreement: light_agreement(&points, position),
            }
        }
        _ => CombinedLight {
            position_m: None,
            cov_m2: Vec::new(),
            first_pose,
            agreement: None,
        },
    }
}

/// How single-view light points `(file, p_i, C_i⁻¹)` agree about their combined point `m`:
/// `χ² = Σ (p_i - m)ᵀ C_i⁻¹ (p_i - m)` over its `3 (n - 1)` degrees of freedom. `None` for
/// fewer than two views.
fn light_agreement(points: &[(&str, DVec3, Matrix3<f64>)], m: DVec3) -> Option<LightAgreement> {
    if points.len() < 2 {
        return None;
    }
    let mut chi2 = 0.0;
    let mut worst: Option<(&str, f64)> = None;
    for (file, p, inv) in points {
        let d = *p - m;
        let v = nalgebra::Vector3::new(d.x, d.y, d.z);
        chi2 += (v.transpose() * inv * v)[(0, 0)];
        let off_mm = d.length() * 1e3;
        if worst.is_none_or(|(_, w)| off_mm > w) {
            worst = Some((file, off_mm));
        }
    }
    let (file, offset_mm) = worst?;
    Some(LightAgreement {
        images: points.len(),
        reduced_chi2: chi2 / (3.0 * (points.len() - 1) as f64),
        farthest_image: file.to_string(),
        farthest_offset_mm: offset_mm,
    })
}

/// How the light-position images agree on the flash (each places it from its own view).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LightAgreement {
    /// Images that placed the flash.
    pub images: usize,
    /// Their light points' reduced chi-square about the combined point (their stated
    /// covariances): near 1 when they agree, large when the flash or a light-position camera
    /// moved, or a pose is wrong.
    pub reduced_chi2: f64,
    /// The image whose light point is farthest from the combined one.
    pub farthest_image: String,
    /// Its distance from the combined point, mm.
    pub farthest_offset_mm: f64,
}

/// The light point (flash frame `light_centre`) of a flash pose with its 3 x 3 covariance.
fn light_point(p: &PoseWithCov, light_centre: DVec3) -> (DVec3, Vec<f64>) {
    let pos = p.pose.transform_point(light_centre);
    if p.covariance.len() != 36 {
        return (pos, Vec::new());
    }
    let c = |i: usize, j: usize| p.covariance[i * 6 + j];
    let arm = p.pose.rotation * light_centre;
    let skew = Matrix3::new(0.0, arm.z, -arm.y, -arm.z, 0.0, arm.x, arm.y, -arm.x, 0.0);
    let crr = Matrix3::from_fn(c);
    let ctt = Matrix3::from_fn(|i, j| c(3 + i, 3 + j));
    let crt = Matrix3::from_fn(|i, j| c(i, 3 + j));
    // δp = δt − [arm]× δθ  (world-frame rotation increment).
    let cov = ctt + skew * crr * skew.transpose() + skew * crt + crt.transpose() * skew.transpose();
    (pos, cov.transpose().as_slice().to_vec())
}

/// Runs the joint bundle adjustment on the per-image estimates and writes its results back.
fn run_bundle(
    out: &mut SessionPoses,
    detected: &[Detected],
    table: &HashMap<u32, (Layout, Target)>,
    light_centre: DVec3,
    cfg: &BundleConfig,
) {
    let est = |p: &Option<PoseWithCov>| p.as_ref().map(|p| (p.pose, p.source == "estimated"));
    let flash = out
        .world_from_flash
        .as_ref()
        .map(|p| (p.pose, p.source == "estimated"));
    let standard = est(&out.world_from_standard);
    let mut index = Vec::new();
    let mut images = Vec::new();
    for (i, (im, det)) in out.images.iter().zip(detected).enumerate() {
        let Some((wc, cam_free)) = est(&im.world_from_camera) else {
            continue;
        };
        let head = est(&im.world_from_head);
        let mut points = Vec::new();
        for (frame, name, on) in [
            (Frame::World, "reference", true),
            (Frame::Head, "headdress", head.is_some()),
            (Frame::Flash, "flash", flash.is_some()),
            (Frame::Standard, "standard", standard.is_some()),
        ] {
            if on {
                points.extend(
                    points_for(&det.dets, table, name)
                        .into_iter()
                        .map(|p| (frame, p)),
                );
            }
        }
        index.push(i);
        images.push(BundleImage {
            world_from_camera: wc,
            camera_free: cam_free,
            world_from_head: head.map(|h| h.0),
            head_free: head.is_some_and(|h| h.1),
            points,
        });
    }
    let problem = BundleProblem {
        camera: out.camera,
        images,
        world_from_flash: flash,
        world_from_standard: standard,
        bodies: Vec::new(),
    };
    let Some(r) = bundle_adjust(&problem, cfg) else {
        out.skipped.push(
            "bundle adjustment (nothing to adjust, or singular normal matrix): per-image estimates kept"
                .into(),
        );
        return;
    };
    let set = |slot: &mut Option<PoseWithCov>, pose: Pose, cov: Vec<f64>| {
        if let Some(p) = slot.as_mut().filter(|p| p.source == "estimated") {
            p.pose = pose;
            if cov.len() == 36 {
                p.covariance = cov;
            }
        }
    };
    for (k, &i) in index.iter().enumerate() {
        let ((wc, cc), head) = r.images[k].clone();
        let im = &mut out.images[i];
        set(&mut im.world_from_camera, wc, cc);
        if let Some((wh, hc)) = head {
            set(&mut im.world_from_head, wh, hc);
        }
        if let Some((wf, fc)) = &r.world_from_flash {
            set(&mut im.world_from_flash, *wf, fc.clone());
        }
        if let Some((ws, sc)) = &r.world_from_standard {
            set(&mut im.world_from_standard, *ws, sc.clone());
        }
    }
    if let Some((wf, fc)) = r.world_from_flash {
        set(&mut out.world_from_flash, wf, fc);
        if let Some(f) = out
            .world_from_flash
            .as_ref()
            .filter(|p| p.source == "estimated")
        {
            let (pos, cov) = light_point(f, light_centre);
            out.light_position_m = Some(pos);
            out.light_position_cov_m2 = cov;
        }
    }
    if let Some((ws, sc)) = r.world_from_standard {
        set(&mut out.world_from_standard, ws, sc);
    }
    if r.report.intrinsics_refined {
        out.camera = r.camera;
    }
    out.bundle = Some(r.report);
}

/// Errors of the estimated poses against `truth.json`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TruthErrors {
    /// Per image: camera position error, m (NaN when not estimated).
    pub camera_position_error_m: Vec<f64>,
    /// Per image: camera orientation error, degrees.
    pub camera_orientation_error_deg: Vec<f64>,
    /// Per image: head position error (head origin), m.
    pub head_position_error_m: Vec<f64>,
    /// Per image: head orientation error, degrees.
    pub head_orientation_error_deg: Vec<f64>,
    /// Flash position error, m.
    pub light_position_error_m: Option<f64>,
    /// Standard position error, m.
    pub standard_position_error_m: Option<f64>,
    /// Standard orientation error, degrees.
    pub standard_orientation_error_deg: Option<f64>,
    /// Focal length error of the calibrated camera, pixels.
    pub focal_error_px: Option<f64>,
    /// Per layout: the distance of every detected corner from its true image position, pixels
    /// (targets the truth lists as fully visible; detections of ids it does not list in that
    /// image are counted in `false_detections`).
    pub corner_error_px: std::collections::BTreeMap<String, Vec<f64>>,
    /// Per layout: each of those distances over the corner's stated standard deviation (worst
    /// direction); for honest sigmas and Gaussian errors its median is about 1.18 (Rayleigh).
    pub corner_error_over_sigma: std::collections::BTreeMap<String, Vec<f64>>,
    /// Detections of ids the truth does not list in their image.
    pub false_detections: usize,
    /// Fully visible targets the truth lists that were not detected, per layout.
    pub missed_targets: std::collections::BTreeMap<String, usize>,
}

/// Detection accuracy of one layout against the truth. Each statistic is `None` when no corner
/// of the layout was compared (every target missed): a statistic of nothing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CornerErrorSummary {
    /// Corners compared.
    pub corners: usize,
    /// Median distance from the true corner, pixels.
    pub corner_error_median_px: Option<f64>,
    /// 90th percentile, pixels.
    pub corner_error_p90_px: Option<f64>,
    /// Largest, pixels.
    pub corner_error_max_px: Option<f64>,
    /// Fully visible targets of the layout not detected.
    pub missed_targets: usize,
    /// Median of the corner errors over their stated sigmas (about 1.18 when the sigmas are
    /// honest, larger when they are optimistic).
    pub error_over_sigma_median: Option<f64>,
}

impl TruthErrors {
    /// Per layout: the corner error statistics.
    pub fn corner_summary(&self) -> std::collections::BTreeMap<String, CornerErrorSummary> {
        let mut layouts: std::collections::BTreeSet<&String> =
            self.corner_error_px.keys().collect();
        layouts.extend(self.missed_targets.keys());
        layouts
            .into_iter()
            .map(|l| {
                let mut v: Vec<f64> = self
                    .corner_error_px
                    .get(l)
                    .map(|v| v.iter().copied().filter(|x| x.is_finite()).collect())
                    .unwrap_or_default();
                v.sort_by(f64::total_cmp);
                let at = |q: f64| {
                    (!v.is_empty()).then(|| v[((v.len() - 1) as f64 * q).round() as usize])
                };
                (
                    l.clone(),
                    CornerErrorSummary {
                        corners: v.len(),
                        corner_error_median_px: at(0.5),
                        corner_error_p90_px: at(0.9),
                        corner_error_max_px: at(1.0),
                        missed_targets: self.missed_targets.get(l).copied().unwrap_or(0),
                        error_over_sigma_median: Some(median(
                            self.corner_error_over_sigma
                                .get(l)
                                .map(Vec::as_slice)
                                .unwrap_or(&[]),
                        ))
                        .filter(|m| m.is_finite()),
                    },
                )
            })
            .collect()
    }
}

/// Median of the finite values (NaN when none).
pub fn median(v: &[f64]) -> f64 {
    let mut f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if f.is_empty() {
        return f64::NAN;
    }
    f.sort_by(f64::total_cmp);
    f[f.len() / 2]
}

/// Compares the estimate with the truth.
pub fn compare_truth(est: &SessionPoses, truth: &Truth) -> TruthErrors {
    let mut e = TruthErrors::default();
    for img in &est.images {
        let t = truth.image(&img.file);
        let pair = |p: &Option<PoseWithCov>, tp: Option<Pose>| -> (f64, f64) {
            match (p.as_ref().filter(|p| p.source == "estimated"), tp) {
                (Some(p), Some(tp)) => (
                    p.pose.distance_to_m(&tp),
                    p.pose.angle_to_rad(&tp).to_degrees(),
                ),
                _ => (f64::NAN, f64::NAN),
            }
        };
        let (cp, co) = pair(&img.world_from_camera, t.map(|t| t.world_from_camera));
        let (mut hp, ho) = pair(&img.world_from_head, t.map(|t| t.world_from_head));
        // Head position at the head's centre (the origin unless the truth says otherwise: a
        // scan's frame may be far from the head).
        if let (Some(c), Some(p), Some(t)) = (
            truth.head_point_m,
            img.world_from_head
                .as_ref()
                .filter(|p| p.source == "estimated"),
            t,
        ) {
            hp = p
                .pose
                .transform_point(c)
                .distance(t.world_from_head.transform_point(c));
        }
        e.camera_position_error_m.push(cp);
        e.camera_orientation_error_deg.push(co);
        e.head_position_error_m.push(hp);
        e.head_orientation_error_deg.push(ho);
        let Some(t) = t else { continue };
        for d in &img.detections {
            match t.targets.iter().find(|tt| tt.id == d.id) {
                Some(tt) if tt.fully_visible => {
                    let dist: [f64; 4] =
                        std::array::from_fn(|k| d.corners_px[k].distance(tt.corners_px[k]));
                    e.corner_error_px
                        .entry(tt.layout.clone())
                        .or_default()
                        .extend(dist);
                    e.corner_error_over_sigma
                        .entry(tt.layout.clone())
                        .or_default()
                        .extend((0..4).map(|k| dist[k] / d.corner_sigma_px[k].max(1e-9)));
                }
                Some(_) => {}
                None => e.false_detections += 1,
            }
        }
        // Only images whose detections were recorded count misses (older poses.json files).
        if !img.detections.is_empty() {
            for tt in t.targets.iter().filter(|tt| tt.fully_visible) {
                if !img.detections.iter().any(|d| d.id == tt.id) {
                    *e.missed_targets.entry(tt.layout.clone()).or_default() += 1;
                }
            }
        }
    }
    e.light_position_error_m = est
        .light_position_m
        .map(|l| l.distance(truth.light_position_m));
    if let Some(s) = est
        .world_from_standard
        .as_ref()
        .filter(|s| s.source == "estimated")
    {
        e.standard_position_error_m = Some(s.pose.distance_to_m(&truth.world_from_standard));
        e.standard_orientation_error_deg =
            Some(s.pose.angle_to_rad(&truth.world_from_standard).to_degrees());
    }
    if est.calibration.is_some() {
        e.focal_error_px = Some((est.camera.fx_px - truth.camera.fx_px).abs());
    }
    e
}

/// A difference between the truth's head frame and the session's that is the same in every
/// image: the truth was stated for another scan's frame, so the head errors measure the two
/// frames' difference, not the measurement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeadFrameOffset {
    /// Translation of the common offset, mm.
    pub distance_mm: f64,
    /// Rotation of the common offset, degrees.
    pub angle_deg: f64,
    /// Images whose estimated head pose was compared.
    pub images: usize,
}

/// Smallest common head-frame offset called a frame difference: far beyond any head pose
/// error the pose stage reaches (bounded at 1 mm and 0.1 degree), and beyond a poor
/// registration of the scan.
const HEAD_FRAME_OFFSET_MIN_MM: f64 = 20.0;
/// The same for the rotation.
const HEAD_FRAME_OFFSET_MIN_DEG: f64 = 2.0;
/// The per-image offsets agree to this fraction of their size when the frames differ (a
/// measurement error varies from image to image; a frame difference does not).
const HEAD_FRAME_OFFSET_AGREEMENT: f64 = 0.05;
/// Images needed to call an offset common.
const HEAD_FRAME_OFFSET_MIN_IMAGES: usize = 3;

/// The common head-frame offset between the estimate and the truth, when the head errors are
/// one rigid transform repeated in every image (see [`HeadFrameOffset`]); `None` when they are
/// small or vary between images.
///
/// Per image `T_i = (world_from_head_true)⁻¹ · world_from_head_est`, the estimated head frame
/// seen from the true one; a frame difference makes every `T_i` the same transform `T`. The
/// reference `T` is the image's offset with the median translation; the others must lie within
/// [`HEAD_FRAME_OFFSET_AGREEMENT`] of its size.
pub fn head_frame_offset(est: &SessionPoses, truth: &Truth) -> Option<HeadFrameOffset> {
    let offsets: Vec<Pose> = est
        .images
        .iter()
        .filter_map(|img| {
            let p = img
                .world_from_head
                .as_ref()
                .filter(|p| p.source == "estimated")?;
            let t = truth.image(&img.file)?;
            Some(t.world_from_head.inverse() * p.pose)
        })
        .collect();
    if offsets.len() < HEAD_FRAME_OFFSET_MIN_IMAGES {
        return None;
    }
    let mut by_size: Vec<&Pose> = offsets.iter().collect();
    by_size.sort_by(|a, b| {
        a.translation_m
            .length()
            .total_cmp(&b.translation_m.length())
    });
    let reference = *by_size[by_size.len() / 2];
    let distance_mm = reference.translation_m.length() * 1e3;
    let angle_deg = reference.angle_to_rad(&Pose::IDENTITY).to_degrees();
    if distance_mm < HEAD_FRAME_OFFSET_MIN_MM && angle_deg < HEAD_FRAME_OFFSET_MIN_DEG {
        return None;
    }
    let agrees = offsets.iter().all(|o| {
        o.distance_to_m(&reference) * 1e3 <= HEAD_FRAME_OFFSET_AGREEMENT * distance_mm.max(1.0)
            && o.angle_to_rad(&reference).to_degrees()
                <= HEAD_FRAME_OFFSET_AGREEMENT * angle_deg.max(1.0)
    });
    agrees.then_some(HeadFrameOffset {
        distance_mm,
        angle_deg,
        images: offsets.len(),
    })
}

/// Reprojects a session target through a camera pose (for overlays and checks).
pub fn reproject_target(
    cam: &CameraModel,
    world_from_camera: &Pose,
    corners_world: &[DVec3; 4],
) -> Option<[DVec2; 4]> {
    let inv = world_from_camera.inverse();
    let mut out = [DVec2::ZERO; 4];
    for (o, c) in out.iter_mut().zip(corners_world) {
        *o = cam.project(inv.transform_point(*c))?;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_images_that_agree_have_chi2_near_one_and_a_moved_one_stands_out() {
        // Each view places the light point with a 1 mm sd per axis.
        let info = Matrix3::<f64>::identity() * 1e6;
        let m = DVec3::new(0.4, 1.2, 1.5);
        let agree = [
            ("a.dng", m + DVec3::new(0.0007, -0.0005, 0.0009), info),
            ("b.dng", m + DVec3::new(-0.0011, 0.0004, -0.0002), info),
            ("c.dng", m + DVec3::new(0.0004, 0.0001, -0.0007), info),
        ];
        let a = light_agreement(&agree, m).expect("three views");
        assert_eq!(a.images, 3);
        assert!(a.reduced_chi2 < 2.0, "{a:?}");
        assert_eq!(a.farthest_image, "a.dng");
        let mut moved = agree;
        moved[2].1 = m + DVec3::new(0.012, 0.0, 0.0);
        let a = light_agreement(&moved, m).expect("three views");
        assert!(a.reduced_chi2 > 20.0, "{a:?}");
        assert_eq!(a.farthest_image, "c.dng");
        assert!((a.farthest_offset_mm - 12.0).abs() < 1e-9);
        assert_eq!(light_agreement(&agree[..1], m), None);
    }

    #[test]
    fn occluded_corners_are_left_out_of_the_pose_points() {
        let corners_m = [
            DVec3::new(-0.01, 0.01, 0.0),
            DVec3::new(0.01, 0.01, 0.0),
            DVec3::new(0.01, -0.01, 0.0),
            DVec3::new(-0.01, -0.01, 0.0),
        ];
        let target = Target {
            id: 7,
            size_m: 0.02,
            corners_m,
            centre_m: None,
        };
        let table = HashMap::from([(7, (Layout::Headdress, target))]);
        let det = Detection {
            id: 7,
            corners_px: [
                DVec2::new(10.0, 30.0),
                DVec2::new(30.0, 30.0),
                DVec2::new(30.0, 10.0),
                DVec2::new(10.0, 10.0),
            ],
            corner_cov_px2: [[0.01, 0.0, 0.01]; 4],
            center_px: DVec2::new(20.0, 20.0),
            hamming: 0,
            decision_margin: 0.4,
            edge_rms_px: 0.05,
            occluded_corners: [false, true, false, false],
        };
        let pts = points_for(&[det], &table, "headdress");
        assert_eq!(pts.len(), 3);
        assert!(pts.iter().all(|p| p.image_px != DVec2::new(30.0, 30.0)));
        assert_eq!(pts[1].object_m, corners_m[2]);
        assert!(points_for(&[det], &table, "reference").is_empty());
    }
}
