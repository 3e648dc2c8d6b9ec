//! The placement survey: where the targets nobody measured are, from the session's own images.
//!
//! # What is estimated
//!
//! A session from a rig without placements lists targets under `targets.unplaced`: each with
//! its printed size, its group (reference → world frame, headdress → head frame) and, for a
//! printed sheet with a layout file, its corners in the sheet's frame. Each unplaced cut-out
//! target, and each sheet, is one rigid **body** with a pose `group_from_body` (and, for a sheet,
//! optionally a print-scale factor). The survey estimates every body jointly with every camera
//! pose, every head pose and (when the camera is to be calibrated) the intrinsics, by the
//! block-sparse bundle adjustment of [`crate::bundle`] extended by the bodies' parameters.
//!
//! # Gauge
//!
//! * **World:** the reference group's placed targets (the rig's declared origin: a target or a
//!   sheet whose corners the rig states) are held fixed; without one the survey refuses
//!   ([`PoseError::SurveyGauge`]). Scale comes from the printed sizes.
//! * **Head:** the headdress group's placed targets when there are any ([`HeadGauge::Declared`]);
//!   otherwise the headdress target seen in the most images is held at the identity
//!   ([`HeadGauge::Provisional`]), and the head frame is provisional until the survey is
//!   registered to the head scan ([`Survey::transform_head`]).
//! * Flash and standard targets are placed by their printed layouts (their frames are defined
//!   by them); the survey leaves them to the pose stage and refuses unplaced ones.
//!
//! # Initialisation: single-view poses chained over the images
//!
//! Every detection of a target of known size gives a single-view pose `body_from_camera` (the
//! plane homography of its four corners, refined). Per group, rounds alternate: (1) each image
//! that sees at least two already placed targets of the group (one, when no image sees two)
//! gets `group_from_camera` by PnP over them; (2) each unplaced body seen in such images gets
//! one candidate `group_from_camera · camera_from_body` per image. A body is placed at the mean
//! of the largest set of candidates that agree (within [`SurveyConfig::consensus_position_m`]
//! and [`SurveyConfig::consensus_angle_deg`] of one of them), when that set has at least
//! [`SurveyConfig::min_views`] members. A single small tag's pose can be its planar flip; the
//! flipped candidates disagree with the others and are outvoted.
//!
//! # Robustness
//!
//! The adjustment runs twice: ungated with the robust loss (the chained start is a few
//! millimetres off), then with the input gate of [`BundleConfig::gate_sigma`] at the first
//! pass's solution. Between the two, a body whose corners are off by more than the gate in at
//! least [`SurveyConfig::moved_min_images`] images and in at least
//! [`SurveyConfig::moved_min_fraction`] of its images (a sheet whose tape slipped half-way) is
//! named [`SurveyIssue::Moved`] and left out, not averaged in. A tag id detected twice in one
//! image is named [`SurveyIssue::Duplicated`] and left out everywhere.
//!
//! # Uncertainty
//!
//! Each body's 6 x 6 marginal covariance (times the a-posteriori variance factor) gives its
//! targets' centre sigma `sqrt(trace(J C Jᵀ))` with `J = [−[a]×, I]`, `a` the centre's lever
//! from the body origin, and the orientation sigma `sqrt(trace(C_rr))`.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::time::Instant;

use glam::{DQuat, DVec2, DVec3};
use serde::{Deserialize, Serialize};
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_session::rig::RigFile;
use skinbrdf_session::{CameraSpec, Session, SessionFile, Target, TargetGroup};
use skinbrdf_targets::DetectorConfig;

use crate::bundle::{
    bundle_adjust, BundleBody, BundleConfig, BundleImage, BundleProblem, BundleReport, Frame,
    GATE_MIN_PX,
};
use crate::calib::guess_camera;
use crate::error::PoseError;
use crate::pnp::{estimate_pose, target_points, PnpConfig, PointObs};
use crate::session::{detect_all, Detected};

/// Settings of [`survey`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SurveyConfig {
    /// Target detection.
    pub detector: DetectorConfig,
    /// Per-image PnP (camera poses and single-view body poses of the initialisation).
    pub pnp: PnpConfig,
    /// The adjustment (its gate is used in the second pass).
    pub bundle: BundleConfig,
    /// Candidates of one body agree within this distance, metres.
    pub consensus_position_m: f64,
    /// ... and this angle, degrees.
    pub consensus_angle_deg: f64,
    /// A body is placed from at least this many agreeing images.
    pub min_views: usize,
    /// Estimate each sheet's print-scale factor.
    pub estimate_print_scale: bool,
    /// A target of an image whose start is off by more than this many pixels is left out of
    /// that image (the chained start is within a few pixels; a flipped view is far off).
    pub start_gate_px: f64,
    /// A body is "moved" when it disagrees in at least this many images ...
    pub moved_min_images: usize,
    /// ... and in at least this fraction of the images that see it.
    pub moved_min_fraction: f64,
}

impl SurveyConfig {
    /// Defaults. The consensus tolerances cover a single-tag start (a camera posed from one
    /// 25-35 mm tag is about a degree off, a few millimetres at the neighbouring targets) and
    /// are far below a planar flip (tens of degrees).
    pub const DEFAULT: Self = Self {
        detector: DetectorConfig::DEFAULT,
        pnp: PnpConfig::DEFAULT,
        bundle: BundleConfig::DEFAULT,
        consensus_position_m: 0.015,
        consensus_angle_deg: 8.0,
        min_views: 2,
        estimate_print_scale: true,
        start_gate_px: 40.0,
        moved_min_images: 2,
        moved_min_fraction: 0.2,
    };
}

impl Default for SurveyConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// How the head frame of the surveyed headdress is fixed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum HeadGauge {
    /// By the headdress targets the rig places (in the scan's frame).
    Declared {
        /// Their ids.
        targets: Vec<u32>,
    },
    /// By one surveyed target held at the identity: the head frame is that tag's frame until
    /// the survey is registered to the scan.
    Provisional {
        /// The anchor's id.
        anchor: u32,
    },
    /// Registered to the head scan (see the pipeline's registration report).
    Registered {
        /// The method (texture, points).
        method: String,
    },
    /// No headdress target to survey.
    None,
}

/// One surveyed target.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurveyedTarget {
    /// tag36h11 id.
    pub id: u32,
    /// Its group.
    pub group: TargetGroup,
    /// The sheet it is printed on, if surveyed as part of one.
    pub sheet: Option<String>,
    /// Printed edge length, metres (times the sheet's estimated print scale).
    pub size_m: f64,
    /// Corners in the group's frame, session corner order.
    pub corners_m: [DVec3; 4],
    /// Standard deviation of its centre, mm (root of the covariance trace).
    pub position_sigma_mm: f64,
    /// Standard deviation of its orientation, degrees (root of the covariance trace).
    pub orientation_sigma_deg: f64,
    /// Images whose corners were used.
    pub views: usize,
    /// RMS reprojection error of its corners at the solution, pixels.
    pub rms_px: f64,
}

/// One surveyed sheet.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurveyedSheet {
    /// The sheet's name.
    pub name: String,
    /// Its group.
    pub group: TargetGroup,
    /// Its pose in the group's frame.
    pub group_from_sheet: Pose,
    /// Its print scale relative to the rig's stated one (1 when not estimated).
    pub print_scale: f64,
    /// Standard deviation of the print scale (0 when not estimated).
    pub print_scale_sigma: f64,
    /// Standard deviation of its origin, mm.
    pub position_sigma_mm: f64,
    /// Standard deviation of its orientation, degrees.
    pub orientation_sigma_deg: f64,
}

/// A target the survey could not place, or left out.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum SurveyIssue {
    /// Seen in too few images with a camera pose (or not at all).
    NotSeen {
        /// The target.
        id: u32,
        /// Images that see it.
        views: usize,
    },
    /// Its candidates from single views did not agree.
    NoConsensus {
        /// The target.
        id: u32,
        /// Candidates.
        candidates: usize,
        /// The largest agreeing set.
        agreeing: usize,
    },
    /// It (or its sheet) sits elsewhere in some images than in others: it moved during the
    /// session. Left out.
    Moved {
        /// The targets of the body.
        ids: Vec<u32>,
        /// Images where it disagrees with its surveyed placement.
        disagreeing_images: Vec<String>,
        /// Images where it agrees.
        agreeing: usize,
        /// Worst corner error in the disagreeing images, pixels.
        worst_px: f64,
    },
    /// The same id was detected twice in one image. Left out.
    Duplicated {
        /// The id.
        id: u32,
        /// The image.
        image: String,
    },
}

/// Timings and counts.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SurveyTiming {
    /// Detection, ms (summed over the parallel workers' wall time).
    pub detect_ms: f64,
    /// Chained initialisation, ms.
    pub init_ms: f64,
    /// Both adjustment passes, ms.
    pub bundle_ms: f64,
    /// Total wall time, ms.
    pub total_ms: f64,
}

/// The survey's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Survey {
    /// Every surveyed target.
    pub targets: Vec<SurveyedTarget>,
    /// Every surveyed sheet.
    pub sheets: Vec<SurveyedSheet>,
    /// Targets not placed or left out, with the reason.
    pub issues: Vec<SurveyIssue>,
    /// How the head frame is fixed.
    pub head_gauge: HeadGauge,
    /// The camera (refined when it was to be calibrated).
    pub camera: CameraModel,
    /// The final adjustment's report.
    pub bundle: BundleReport,
    /// Parameters: bodies, images with a pose, and what one iteration costs.
    pub bodies: usize,
    /// Images used.
    pub images_used: usize,
    /// Timings.
    pub timing: SurveyTiming,
}

/// One body of the survey (a cut-out target or a sheet).
#[derive(Debug, Clone)]
struct BodyDef {
    group: TargetGroup,
    sheet: Option<String>,
    /// Members: id, printed size, corners in the body's frame.
    members: Vec<(u32, f64, [DVec3; 4])>,
}

/// The canonical corners of a tag of edge `s` in its own frame (x right, y down, z into the
/// surface; session corner order).
fn tag_corners(s: f64) -> [DVec3; 4] {
    let h = 0.5 * s;
    [
        DVec3::new(-h, h, 0.0),
        DVec3::new(h, h, 0.0),
        DVec3::new(h, -h, 0.0),
        DVec3::new(-h, -h, 0.0),
    ]
}

fn outward(c: &[DVec3; 4]) -> DVec3 {
    let x = c[1] - c[0];
    let y = c[0] - c[3];
    -(x.cross(y)).normalize_or_zero()
}

/// One detection: corners, sigmas, occluded flags.
#[derive(Debug, Clone, Copy)]
struct Obs {
    corners_px: [DVec2; 4],
    sigma_px: [f64; 4],
    occluded: [bool; 4],
}

fn points(id: u32, corners_m: &[DVec3; 4], o: &Obs) -> Vec<PointObs> {
    target_points(
        id,
        corners_m,
        outward(corners_m),
        &o.corners_px,
        &o.sigma_px,
    )
    .into_iter()
    .zip(o.occluded)
    .filter(|(_, hidden)| !hidden)
    .map(|(p, _)| p)
    .collect()
}

/// The angle between two rotations, degrees.
fn angle_deg(a: DQuat, b: DQuat) -> f64 {
    let d = a.dot(b).abs().min(1.0);
    (2.0 * d.acos()).to_degrees()
}

/// The mean of nearby poses (positions averaged, quaternions averaged on one hemisphere).
fn mean_pose(poses: &[Pose]) -> Option<Pose> {
    let first = poses.first()?;
    let mut q = glam::DVec4::ZERO;
    let mut t = DVec3::ZERO;
    for p in poses {
        let v = glam::DVec4::from(p.rotation);
        q += if v.dot(glam::DVec4::from(first.rotation)) < 0.0 {
            -v
        } else {
            v
        };
        t += p.translation_m;
    }
    let q = DQuat::from_vec4(q).normalize();
    Some(Pose::new(q, t / poses.len() as f64))
}

/// Per image: id → observation (ids detected twice are removed and reported).
fn observations(
    session: &Session,
    detected: &[Detected],
    issues: &mut Vec<SurveyIssue>,
) -> (Vec<HashMap<u32, Obs>>, HashSet<u32>) {
    let mut dup = HashSet::new();
    let mut per = Vec::with_capacity(detected.len());
    for (i, d) in detected.iter().enumerate() {
        let mut m: HashMap<u32, Obs> = HashMap::new();
        for t in &d.dets {
            let o = Obs {
                corners_px: t.corners_px,
                sigma_px: t.corner_sigma_px(),
                occluded: t.occluded_corners,
            };
            if m.insert(t.id, o).is_some() && dup.insert(t.id) {
                issues.push(SurveyIssue::Duplicated {
                    id: t.id,
                    image: session.file.images[i].file.clone(),
                });
            }
        }
        per.push(m);
    }
    for m in &mut per {
        m.retain(|id, _| !dup.contains(id));
    }
    (per, dup)
}

/// What one group's initialisation works with.
struct GroupInit<'a> {
    /// Placed targets (group frame).
    placed: HashMap<u32, [DVec3; 4]>,
    /// The group's bodies (indices into the survey's body list).
    bodies: Vec<usize>,
    defs: &'a [BodyDef],
}

/// Chains single-view poses over the images (see the module docs). Fills `pose` for the
/// group's bodies it can place; returns `group_from_camera` per image.
fn init_group(
    g: &GroupInit<'_>,
    obs: &[HashMap<u32, Obs>],
    camera: &CameraModel,
    cfg: &SurveyConfig,
    pose: &mut [Option<Pose>],
    issues: &mut Vec<SurveyIssue>,
) -> Vec<Option<Pose>> {
    let pnp_n = |n: usize| PnpConfig {
        min_targets: n,
        ..cfg.pnp
    };
    let mut allow_single = false;
    let mut gfc: Vec<Option<Pose>> = vec![None; obs.len()];
    let mut last_candidates: HashMap<usize, (usize, usize)> = HashMap::new();
    loop {
        // (1) Cameras in the group frame from what is placed.
        for (i, o) in obs.iter().enumerate() {
            let mut pts = Vec::new();
            let mut n = 0;
            for (id, c) in &g.placed {
                if let Some(d) = o.get(id) {
                    pts.extend(points(*id, c, d));
                    n += 1;
                }
            }
            for &b in &g.bodies {
                let Some(p) = pose[b] else { continue };
                for (id, _, c) in &g.defs[b].members {
                    if let Some(d) = o.get(id) {
                        pts.extend(points(*id, &c.map(|x| p.transform_point(x)), d));
                        n += 1;
                    }
                }
            }
            let need = if allow_single { 1 } else { 2 };
            gfc[i] = if n >= need {
                estimate_pose(camera, &pts, None, &pnp_n(need.min(n)))
                    .ok()
                    .map(|e| e.frame_from_camera)
            } else {
                None
            };
        }
        // (2) Candidates for the bodies not yet placed.
        let mut placed_now = 0;
        for &b in &g.bodies {
            if pose[b].is_some() {
                continue;
            }
            let mut cands = Vec::new();
            for (i, o) in obs.iter().enumerate() {
                let Some(wc) = gfc[i] else { continue };
                let mut pts = Vec::new();
                for (id, _, c) in &g.defs[b].members {
                    if let Some(d) = o.get(id) {
                        pts.extend(points(*id, c, d));
                    }
                }
                if pts.len() < 4 {
                    continue;
                }
                if let Ok(e) = estimate_pose(camera, &pts, None, &pnp_n(1)) {
                    cands.push(wc * e.frame_from_camera.inverse());
                }
            }
            let agree = |a: &Pose, b: &Pose| {
                a.translation_m.distance(b.translation_m) < cfg.consensus_position_m
                    && angle_deg(a.rotation, b.rotation) < cfg.consensus_angle_deg
            };
            let best = cands
                .iter()
                .map(|c| cands.iter().filter(|d| agree(c, d)).copied().collect())
                .max_by_key(|v: &Vec<Pose>| v.len())
                .unwrap_or_default();
            last_candidates.insert(b, (cands.len(), best.len()));
            if best.len() >= cfg.min_views {
                pose[b] = mean_pose(&best);
                placed_now += 1;
            }
        }
        if placed_now == 0 {
            if allow_single {
                break;
            }
            allow_single = true;
        } else {
            allow_single = false;
        }
    }
    for &b in &g.bodies {
        if pose[b].is_some() {
            continue;
        }
        let (cands, agreeing) = last_candidates.get(&b).copied().unwrap_or((0, 0));
        for (id, _, _) in &g.defs[b].members {
            let views = obs.iter().filter(|o| o.contains_key(id)).count();
            issues.push(if cands >= cfg.min_views {
                SurveyIssue::NoConsensus {
                    id: *id,
                    candidates: cands,
                    agreeing,
                }
            } else {
                SurveyIssue::NotSeen { id: *id, views }
            });
        }
    }
    gfc
}

/// The bodies of a session's unplaced reference and headdress targets.
fn bodies_of(file: &SessionFile) -> Result<Vec<BodyDef>, PoseError> {
    let mut sheets: BTreeMap<(TargetGroup, String), BodyDef> = BTreeMap::new();
    let mut out = Vec::new();
    for t in &file.targets.unplaced {
        if matches!(t.group, TargetGroup::Flash | TargetGroup::Standard) {
            return Err(PoseError::SurveyUnsupported {
                id: t.id,
                group: t.group.name(),
            });
        }
        match (&t.sheet, t.sheet_corners_m) {
            (Some(name), Some(c)) => sheets
                .entry((t.group, name.clone()))
                .or_insert_with(|| BodyDef {
                    group: t.group,
                    sheet: Some(name.clone()),
                    members: Vec::new(),
                })
                .members
                .push((t.id, t.size_m, c)),
            _ => out.push(BodyDef {
                group: t.group,
                sheet: None,
                members: vec![(t.id, t.size_m, tag_corners(t.size_m))],
            }),
        }
    }
    out.extend(sheets.into_values());
    Ok(out)
}

/// Surveys every unplaced reference and headdress target of the session (see the module docs).
pub fn survey(session: &Session, cfg: &SurveyConfig) -> Result<Survey, PoseError> {
    let t0 = Instant::now();
    let file = &session.file;
    let defs = bodies_of(file)?;
    let placed_ref: HashMap<u32, [DVec3; 4]> = file
        .targets
        .reference
        .iter()
        .map(|t| (t.id, t.corners_m))
        .collect();
    let placed_head: HashMap<u32, [DVec3; 4]> = file
        .targets
        .headdress
        .iter()
        .map(|t| (t.id, t.corners_m))
        .collect();
    let has_ref_bodies = defs.iter().any(|d| d.group == TargetGroup::Reference);
    if has_ref_bodies && placed_ref.is_empty() {
        return Err(PoseError::SurveyGauge);
    }
    let mut issues = Vec::new();
    let detected = detect_all(session, &cfg.detector);
    let detect_ms: f64 = detected.iter().map(|d| d.detect_ms).sum();
    for (i, d) in detected.iter().enumerate() {
        if let Some(e) = &d.error {
            return Err(PoseError::Image {
                file: file.images[i].file.clone(),
                problem: e.clone(),
            });
        }
    }
    let t_init = Instant::now();
    let (obs, _dups) = observations(session, &detected, &mut issues);
    // The camera: given, or a starting guess refined by the adjustment.
    let (camera, refine_intrinsics) = match &file.camera {
        CameraSpec::Calibrated(m) => (*m, cfg.bundle.refine_intrinsics),
        CameraSpec::ToBeCalibrated {
            width_px,
            height_px,
            focal_guess_px,
        } => {
            let c = match focal_guess_px {
                Some(f) => CameraModel {
                    fx_px: *f,
                    fy_px: *f,
                    ..CameraModel::from_fov(*width_px, *height_px, 1.0)
                },
                None => guess_camera(*width_px, *height_px, &[]),
            };
            (c, true)
        }
    };
    let mut pose: Vec<Option<Pose>> = vec![None; defs.len()];
    let of_group = |g: TargetGroup| -> Vec<usize> {
        (0..defs.len()).filter(|&b| defs[b].group == g).collect()
    };
    let ref_init = GroupInit {
        placed: placed_ref.clone(),
        bodies: of_group(TargetGroup::Reference),
        defs: &defs,
    };
    let world_from_camera = init_group(&ref_init, &obs, &camera, cfg, &mut pose, &mut issues);
    // Head gauge: declared targets, or the most-seen headdress body held at the identity.
    let head_bodies = of_group(TargetGroup::Headdress);
    let mut anchor = None;
    let head_gauge = if !placed_head.is_empty() {
        let mut ids: Vec<u32> = placed_head.keys().copied().collect();
        ids.sort_unstable();
        HeadGauge::Declared { targets: ids }
    } else if let Some(&b) = head_bodies.iter().max_by_key(|&&b| {
        let seen = obs
            .iter()
            .zip(&world_from_camera)
            .filter(|(o, c)| c.is_some() && defs[b].members.iter().any(|m| o.contains_key(&m.0)))
            .count();
        (seen, std::cmp::Reverse(defs[b].members[0].0))
    }) {
        pose[b] = Some(Pose::IDENTITY);
        anchor = Some(b);
        HeadGauge::Provisional {
            anchor: defs[b].members[0].0,
        }
    } else {
        HeadGauge::None
    };
    let head_init = GroupInit {
        placed: placed_head.clone(),
        bodies: head_bodies,
        defs: &defs,
    };
    let head_from_camera = init_group(&head_init, &obs, &camera, cfg, &mut pose, &mut issues);
    let init_ms = t_init.elapsed().as_secs_f64() * 1e3;

    // The adjustment.
    let t_ba = Instant::now();
    let body_index: Vec<Option<usize>> = {
        let mut k = 0;
        pose.iter()
            .map(|p| {
                p.map(|_| {
                    k += 1;
                    k - 1
                })
            })
            .collect()
    };
    let mut left_out: HashSet<usize> = HashSet::new();
    let build = |left_out: &HashSet<usize>| -> (BundleProblem, Vec<usize>) {
        let mut images = Vec::new();
        let mut index = Vec::new();
        for (i, o) in obs.iter().enumerate() {
            let entry = &file.images[i];
            let (wc, cam_free) = match (entry.world_from_camera, world_from_camera[i]) {
                (Some(p), _) => (p, false),
                (None, Some(p)) => (p, true),
                (None, None) => continue,
            };
            let head = match (entry.world_from_head, head_from_camera[i]) {
                (Some(p), _) => Some((p, false)),
                _ if file.known.stationary_sample => Some((
                    file.images
                        .iter()
                        .find_map(|e| e.world_from_head)
                        .unwrap_or(Pose::IDENTITY),
                    false,
                )),
                (None, Some(hc)) => Some((wc * hc.inverse(), true)),
                (None, None) => None,
            };
            let mut pts = Vec::new();
            for (id, c) in &placed_ref {
                if let Some(d) = o.get(id) {
                    pts.extend(points(*id, c, d).into_iter().map(|p| (Frame::World, p)));
                }
            }
            if head.is_some() {
                for (id, c) in &placed_head {
                    if let Some(d) = o.get(id) {
                        pts.extend(points(*id, c, d).into_iter().map(|p| (Frame::Head, p)));
                    }
                }
            }
            for (b, def) in defs.iter().enumerate() {
                let Some(k) = body_index[b] else { continue };
                if left_out.contains(&b) {
                    continue;
                }
                let frame = match def.group {
                    TargetGroup::Headdress if head.is_some() => Frame::HeadBody(k),
                    TargetGroup::Headdress => continue,
                    _ => Frame::WorldBody(k),
                };
                let Some(gp) = pose[b] else { continue };
                let to_world = match (frame, head) {
                    (Frame::HeadBody(_), Some((wh, _))) => wh * gp,
                    _ => gp,
                };
                for (id, _, c) in &def.members {
                    let Some(d) = o.get(id) else { continue };
                    // A start that puts the target far from where it is seen (a planar flip
                    // of a single view, or a target no longer where it was) is left out of
                    // this image: the adjustment starts within a few pixels.
                    let off = (0..4)
                        .filter(|&q| !d.occluded[q])
                        .map(|q| {
                            camera
                                .project(
                                    wc.inverse().transform_point(to_world.transform_point(c[q])),
                                )
                                .map_or(f64::INFINITY, |px| px.distance(d.corners_px[q]))
                        })
                        .fold(0.0, f64::max);
                    if off > cfg.start_gate_px {
                        continue;
                    }
                    pts.extend(points(*id, c, d).into_iter().map(|p| (frame, p)));
                }
            }
            // Every free block needs observations: a head with none of its targets left is
            // not adjusted, an image with no corners left is not used.
            let head_seen = pts.iter().any(|(f, _)| f.on_head());
            let head = head.filter(|_| head_seen);
            if head.is_none() {
                pts.retain(|(f, _)| !f.on_head());
            }
            if pts.iter().filter(|(f, _)| !f.on_head()).count() < 4 && cam_free {
                continue;
            }
            index.push(i);
            images.push(BundleImage {
                world_from_camera: wc,
                camera_free: cam_free,
                world_from_head: head.map(|h| h.0),
                head_free: head.is_some_and(|h| h.1),
                points: pts,
            });
        }
        let bodies = defs
            .iter()
            .enumerate()
            .filter_map(|(b, def)| {
                pose[b].map(|p| BundleBody {
                    group_from_body: p,
                    scale: 1.0,
                    free: anchor != Some(b) && !left_out.contains(&b),
                    scale_free: def.sheet.is_some()
                        && cfg.estimate_print_scale
                        && !left_out.contains(&b),
                })
            })
            .collect();
        (
            BundleProblem {
                camera,
                images,
                world_from_flash: None,
                world_from_standard: None,
                bodies,
            },
            index,
        )
    };
    let pass1_cfg = BundleConfig {
        gate_sigma: f64::INFINITY,
        refine_intrinsics,
        max_iterations: cfg.bundle.max_iterations.max(50),
        ..cfg.bundle
    };
    let (p1, index1) = build(&left_out);
    let r1 = bundle_adjust(&p1, &pass1_cfg).ok_or(PoseError::SurveySingular)?;
    // Moved bodies: per body, the images where its corners are off by more than the gate.
    for (b, def) in defs.iter().enumerate() {
        let Some(k) = body_index[b] else { continue };
        let ((gp, _), scale, _) = &r1.bodies[k];
        let mut bad = Vec::new();
        let mut good = 0usize;
        let mut worst = 0.0f64;
        for (j, &i) in index1.iter().enumerate() {
            let ((wc, _), head) = &r1.images[j];
            let to_world = match def.group {
                TargetGroup::Headdress => match head {
                    Some((wh, _)) => *wh * *gp,
                    None => continue,
                },
                _ => *gp,
            };
            let mut off = 0.0f64;
            let mut limit = f64::INFINITY;
            let mut any = false;
            for (id, _, c) in &def.members {
                let Some(d) = obs[i].get(id) else { continue };
                for (q, corner) in c.iter().enumerate() {
                    if d.occluded[q] {
                        continue;
                    }
                    let w = to_world.transform_point(*corner * *scale);
                    let e = r1
                        .camera
                        .project(wc.inverse().transform_point(w))
                        .map_or(f64::INFINITY, |px| px.distance(d.corners_px[q]));
                    off = off.max(e);
                    let l = (cfg.bundle.gate_sigma * d.sigma_px[q].max(cfg.bundle.sigma_floor_px))
                        .max(GATE_MIN_PX);
                    limit = limit.min(l);
                    any = true;
                }
            }
            if !any {
                continue;
            }
            if off > limit {
                bad.push(i);
                worst = worst.max(off);
            } else {
                good += 1;
            }
        }
        let n = bad.len() + good;
        if bad.len() >= cfg.moved_min_images
            && bad.len() as f64 >= cfg.moved_min_fraction * n as f64
            && anchor != Some(b)
        {
            left_out.insert(b);
            issues.push(SurveyIssue::Moved {
                ids: def.members.iter().map(|m| m.0).collect(),
                disagreeing_images: bad.iter().map(|&i| file.images[i].file.clone()).collect(),
                agreeing: good,
                worst_px: worst,
            });
        }
    }
    // Second pass from the first's solution, with the input gate.
    let (mut p2, index2) = build(&left_out);
    for (j, im) in p2.images.iter_mut().enumerate() {
        if let Some(k) = index1.iter().position(|&i| i == index2[j]) {
            let ((wc, _), head) = &r1.images[k];
            im.world_from_camera = *wc;
            if let (Some(h), Some((wh, _))) = (im.world_from_head.as_mut(), head) {
                *h = *wh;
            }
        }
    }
    for (b, r) in p2.bodies.iter_mut().zip(&r1.bodies) {
        b.group_from_body = r.0 .0;
        b.scale = r.1;
    }
    p2.camera = r1.camera;
    let pass2_cfg = BundleConfig {
        refine_intrinsics,
        ..cfg.bundle
    };
    let r2 = bundle_adjust(&p2, &pass2_cfg).ok_or(PoseError::SurveySingular)?;
    let bundle_ms = t_ba.elapsed().as_secs_f64() * 1e3;

    // Results.
    let mut targets = Vec::new();
    let mut sheets = Vec::new();
    for (b, def) in defs.iter().enumerate() {
        let Some(k) = body_index[b] else { continue };
        if left_out.contains(&b) {
            continue;
        }
        let ((gp, cov), scale, scale_var) = &r2.bodies[k];
        let sig = |lever: DVec3| -> (f64, f64) {
            if cov.len() != 36 {
                return (0.0, 0.0);
            }
            let c = nalgebra::Matrix6::from_row_slice(cov);
            let mut j = nalgebra::Matrix3x6::<f64>::zeros();
            // δc = δt − [a]× δθ
            let a = lever;
            let skew = nalgebra::Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0);
            j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-skew));
            j.fixed_view_mut::<3, 3>(0, 3)
                .copy_from(&nalgebra::Matrix3::identity());
            let pc = j * c * j.transpose();
            let rot = c.fixed_view::<3, 3>(0, 0).trace();
            (
                pc.trace().max(0.0).sqrt() * 1e3,
                rot.max(0.0).sqrt().to_degrees(),
            )
        };
        for (id, size_m, c) in &def.members {
            let corners_m = c.map(|x| gp.transform_point(x * *scale));
            let centre = corners_m.iter().copied().sum::<DVec3>() * 0.25;
            let (ps, os) = sig(centre - gp.translation_m);
            let (views, rms) = reprojection(&r2, &index2, &obs, def.group, *id, &corners_m);
            targets.push(SurveyedTarget {
                id: *id,
                group: def.group,
                sheet: def.sheet.clone(),
                size_m: size_m * scale,
                corners_m,
                position_sigma_mm: ps,
                orientation_sigma_deg: os,
                views,
                rms_px: rms,
            });
        }
        if let Some(name) = &def.sheet {
            let (ps, os) = sig(DVec3::ZERO);
            sheets.push(SurveyedSheet {
                name: name.clone(),
                group: def.group,
                group_from_sheet: *gp,
                print_scale: *scale,
                print_scale_sigma: scale_var.max(0.0).sqrt(),
                position_sigma_mm: ps,
                orientation_sigma_deg: os,
            });
        }
    }
    targets.sort_by_key(|t| t.id);
    Ok(Survey {
        targets,
        sheets,
        issues,
        head_gauge,
        camera: r2.camera,
        bodies: r2.bodies.len(),
        images_used: index2.len(),
        bundle: r2.report,
        timing: SurveyTiming {
            detect_ms,
            init_ms,
            bundle_ms,
            total_ms: t0.elapsed().as_secs_f64() * 1e3,
        },
    })
}

/// Views and RMS reprojection error of one target at the solution.
fn reprojection(
    r: &crate::bundle::BundleResult,
    index: &[usize],
    obs: &[HashMap<u32, Obs>],
    group: TargetGroup,
    id: u32,
    corners_m: &[DVec3; 4],
) -> (usize, f64) {
    let mut views = 0;
    let mut sq = 0.0;
    let mut n = 0;
    for (j, &i) in index.iter().enumerate() {
        let Some(d) = obs[i].get(&id) else { continue };
        let ((wc, _), head) = &r.images[j];
        let to_world = match (group, head) {
            (TargetGroup::Headdress, Some((wh, _))) => *wh,
            (TargetGroup::Headdress, None) => continue,
            _ => Pose::IDENTITY,
        };
        views += 1;
        for (q, corner) in corners_m.iter().enumerate() {
            if d.occluded[q] {
                continue;
            }
            let w = to_world.transform_point(*corner);
            if let Some(px) = r.camera.project(wc.inverse().transform_point(w)) {
                sq += px.distance_squared(d.corners_px[q]);
                n += 1;
            }
        }
    }
    (views, if n > 0 { (sq / n as f64).sqrt() } else { 0.0 })
}

impl Survey {
    /// Moves the surveyed headdress into the head (scan) frame: `head_from_provisional` maps
    /// the survey's provisional head frame to the scan's.
    pub fn transform_head(&mut self, head_from_provisional: &Pose, method: &str) {
        for t in &mut self.targets {
            if t.group == TargetGroup::Headdress {
                t.corners_m = t
                    .corners_m
                    .map(|c| head_from_provisional.transform_point(c));
            }
        }
        for s in &mut self.sheets {
            if s.group == TargetGroup::Headdress {
                s.group_from_sheet = *head_from_provisional * s.group_from_sheet;
            }
        }
        self.head_gauge = HeadGauge::Registered {
            method: method.to_string(),
        };
    }

    /// Whether the head frame is the scan's (declared or registered), so the headdress
    /// placements can be used for head poses.
    pub fn head_frame_fixed(&self) -> bool {
        !matches!(self.head_gauge, HeadGauge::Provisional { .. })
    }

    /// The surveyed headdress targets: `(id, corners_m)` in the survey's head frame.
    pub fn headdress_corners(&self) -> Vec<(u32, [DVec3; 4])> {
        self.targets
            .iter()
            .filter(|t| t.group == TargetGroup::Headdress)
            .map(|t| (t.id, t.corners_m))
            .collect()
    }

    /// The session with the surveyed placements: every surveyed reference and headdress target
    /// moves from `targets.unplaced` into its group's list; the targets the survey could not
    /// place or left out are dropped from the session (listed in [`Survey::issues`]).
    pub fn apply_to(&self, file: &mut SessionFile) {
        for t in &self.targets {
            let target = Target {
                id: t.id,
                size_m: t.size_m,
                corners_m: t.corners_m,
                centre_m: None,
            };
            match t.group {
                TargetGroup::Headdress => file.targets.headdress.push(target),
                _ => file.targets.reference.push(target),
            }
        }
        file.targets
            .unplaced
            .retain(|u| !matches!(u.group, TargetGroup::Reference | TargetGroup::Headdress));
    }

    /// The rig with the surveyed placements written in (a rig surveyed once can be loaded
    /// fixed next time).
    pub fn placed_rig(&self, rig: &RigFile) -> RigFile {
        let mut out = rig.clone();
        for s in &mut out.sheets {
            if let Some(v) = self.sheets.iter().find(|v| v.name == s.name) {
                s.group_from_sheet = Some(v.group_from_sheet);
                s.print_scale = Some(s.print_scale.unwrap_or(1.0) * v.print_scale);
            }
        }
        for t in &mut out.targets {
            if let Some(v) = self
                .targets
                .iter()
                .find(|v| v.id == t.id && v.sheet.is_none())
            {
                t.corners_m = Some(v.corners_m);
            }
        }
        out
    }
}
