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
//! one candidate `group_from_camera · camera_from_body` per image. A body is placed from the
//! largest set of candidates that agree with one of them, when that set has at least
//! [`SurveyConfig::min_views`] members. Positions agree within
//! [`SurveyConfig::consensus_position_m`] plus 1 % of the camera-to-body range (a camera chained
//! through small targets is up to about a degree off, which moves a body 2.5 m away by
//! centimetres), at most 0.9 of [`SurveyConfig::two_places_min_m`]. Orientations agree within
//! [`SurveyConfig::consensus_angle_deg`], tested only where both views see the body at least
//! 40 px across: a single small tag's pose can be its planar flip, and at 20 px its orientation
//! scatters by tens of degrees while its position still agrees. A single target is then placed
//! from its corners triangulated over the agreeing views (each corner the least-squares point
//! nearest its rays, the square fitted to them; used when the rays are at least 5 deg apart and
//! the triangulated edges within 20 % of the printed size); a sheet, or a target the views do
//! not triangulate, at the mean of the agreeing candidates.
//!
//! The single-view poses rest on the intrinsics. When the camera is to be calibrated they start
//! from a guess (the EXIF focal length): a focal length off by a share `e` moves each view's
//! placement along its line of sight by `e` times its range, so views of one target from
//! different distances disagree by centimetres and could pass for two places. The whole survey
//! is then run twice ([`Survey::intrinsics_restart`]): the second round starts from the
//! intrinsics the first refined.
//!
//! # Robustness
//!
//! The adjustment runs twice: ungated with the robust loss (the chained start is a few
//! millimetres off), then with the input gate of [`BundleConfig::gate_sigma`] at the first
//! pass's solution. Between the two, moved bodies are named [`SurveyIssue::Moved`] and left
//! out, not averaged in:
//!
//! * **Change point.** A target whose tape slipped half-way sits in one place in the images
//!   before the slip and in another after it; the joint placement lies between, off in most
//!   views on both sides, often by less than any per-image gate. So each body's views, in the
//!   order they were taken, are split at every point leaving
//!   [`SurveyConfig::change_point_min_views`] on each side; the body is fitted to each side
//!   alone (cameras and group frames held at the first pass's solution) and the chi-square the
//!   split explains, `(C_joint − C_before − C_after) / σ̂²`, is compared with
//!   [`CHANGE_POINT_CHI2`] (a chi-square law of 6 degrees of freedom without a move). The
//!   best split is a move when it passes, when the two placements differ by at least
//!   [`MOVED_MIN_SHIFT_MM`] at some corner, and when the median view on each side gains at
//!   least [`CHANGE_POINT_VIEW_CHI2`] from it (one bad view among many explains the same
//!   chi-square from one side's few views; a move is seen in most of them). The reported
//!   displacement is measured again with the second pass's cameras, which the moved body no
//!   longer pulls.
//! * **Gate.** A body seen too few times for the split whose corners are off by more than the
//!   gate in at least [`SurveyConfig::moved_min_images`] images and in at least
//!   [`SurveyConfig::moved_min_fraction`] of its images.
//!
//! A tag id detected twice in one image is named [`SurveyIssue::Duplicated`] and left out
//! everywhere.
//!
//! # Uncertainty
//!
//! Each body's 6 x 6 marginal covariance (times the session's a-posteriori variance factor)
//! gives its targets' centre sigma `sqrt(trace(J C Jᵀ))` with `J = [−[a]×, I]`, `a` the
//! centre's lever from the body origin, and the orientation sigma `sqrt(trace(C_rr))`. A body
//! whose own corners fit worse than the session's (its chi-square over its `2 n − 6` degrees of
//! freedom above the session's factor: a corner hidden but not marked, a slightly bent sheet)
//! has its covariance scaled by the ratio ([`SurveyedTarget::variance_ratio`]): the session's
//! factor speaks for the typical body, not for one seen in three images with one bad view.
//!
//! The sigmas decide what is placed: a target placed less certainly than its group's accuracy
//! target ([`MAX_SIGMA_REFERENCE_MM`], [`MAX_SIGMA_HEADDRESS_MM`]; [`MAX_SIGMA_FLASH_ONLY_MM`]
//! for a reference target that serves the flash alone: no measurement or standard image sees
//! it, and light-position images do or a link shot shows it with one they see) is left out
//! ([`SurveyIssue::Uncertain`], with the advice that survey images seeing it from other
//! directions would place it) rather than held fixed in the poses with that error.
//!
//! # Survey images
//!
//! Images of role `survey` (taken by hand before the subject sits, without the flash) are used
//! like the others: each gets a camera pose in the chained start and in both passes of the
//! adjustment, and its views count for every body's consensus, change-point test and
//! uncertainty. They have no head: their headdress detections (a headdress lying about is not
//! on the head) are dropped, so they add no head block. Seeing the targets the head hides from
//! the measurement arc, and seeing the cage from other heights and sides, they place targets
//! the arc leaves [`SurveyIssue::NotSeen`] or [`SurveyIssue::Uncertain`]; the session lists
//! them in the order taken (before the session's images), as the change-point test needs.
//!
//! # What cannot be placed
//!
//! A body seen in fewer than [`SurveyConfig::min_views`] images is [`SurveyIssue::NotSeen`]; one
//! seen often enough but only in images that share too few placed targets to be posed in its
//! group's frame (the flash stand's panel, seen only from the subject's position) is
//! [`SurveyIssue::Unlinked`], grouped with the other bodies those images see and named with
//! them; one whose single-view placements disagree is [`SurveyIssue::NoConsensus`].

use std::collections::{BTreeMap, HashMap, HashSet};
use std::time::Instant;

use glam::{DQuat, DVec2, DVec3};
use nalgebra::DVector;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_session::rig::{RigFile, RigTarget};
use skinbrdf_session::{CameraSpec, ImageRole, Session, SessionFile, Target, TargetGroup};
use skinbrdf_targets::DetectorConfig;

use crate::bundle::{
    bundle_adjust, BundleBody, BundleConfig, BundleImage, BundleProblem, BundleReport, Frame,
    GATE_MIN_PX,
};
use crate::calib::focal_from_squares;
use crate::error::PoseError;
use crate::pnp::{estimate_pose, target_points, PnpConfig, PointObs};
use crate::session::{Detected, SessionDetections};

/// The change-point test's threshold on the chi-square a split explains. Splitting a body's
/// views adds 6 parameters (a second pose), so without a move the explained chi-square follows
/// a chi-square law of 6 degrees of freedom; over every split of every body of a session (a few
/// thousand tests) a false alarm rate of 1 % needs its `1 − 10⁻⁶` quantile, 35.9. The margin
/// above it covers corner sigmas that are not exactly right.
pub const CHANGE_POINT_CHI2: f64 = 45.0;

/// What the median view on each side of a change point must gain from the split, in units of
/// the session's variance factor: the chi-square of one 4-corner view with 1 degree of freedom
/// at 2 sigma. A move seen in most views gains far more; one bad view among many gains nothing
/// for its neighbours.
pub const CHANGE_POINT_VIEW_CHI2: f64 = 4.0;

/// A placement change smaller than this at every corner is not named a move, mm: it is below
/// the survey's accuracy target for the reference structure, so averaging it in cannot push the
/// placement beyond that target.
pub const MOVED_MIN_SHIFT_MM: f64 = 0.3;

/// Two consistent groups of single-view placements this far apart, metres, are two places: a
/// target pitch of the printed sheets (a copy elsewhere on the rig), well beyond the
/// single-view scatter the consensus allows (15 mm, up to 45 mm for a body far from the
/// cameras) and a planar flip (which turns the target about its centre rather than moving it).
pub const TWO_PLACES_MIN_M: f64 = 0.05;

/// A flat sheet's layout fits a single view's corners to their noise (a few tenths of a pixel
/// with an unmarked partial occlusion); a corner 3 px off in most views is a bend, pixels.
pub const NOT_RIGID_PX: f64 = 3.0;

/// A sheet whose corners scatter about its fitted layout with 4 times the session's variance
/// (its sigmas twice the typical body's) is bent: a sheet of 8 corners per view in several views
/// reaches that ratio by chance with negligible probability.
pub const NOT_RIGID_VARIANCE_RATIO: f64 = 4.0;

/// The survey's accuracy target for the reference structure, mm: the bound its placements are
/// held to. A target placed less certainly is left out rather than held fixed with that error.
pub const MAX_SIGMA_REFERENCE_MM: f64 = 0.3;

/// The survey's accuracy target for the headdress, mm.
pub const MAX_SIGMA_HEADDRESS_MM: f64 = 0.5;

/// The survey's accuracy target for a reference target that serves the flash alone, mm: one
/// that light-position images see and no measurement or standard image does (a panel on the
/// flash stand), or one that links such a target to the rest without being seen by a
/// measurement or standard image either (a relay). It places the cameras that place the flash
/// and nothing else, so it is held to the flash's bound (the emitting point within 2 mm) with
/// room for the light-position images' own error, not to the reference structure's (the panel
/// is far from the cage, linked to it only through a chain of survey shots).
pub const MAX_SIGMA_FLASH_ONLY_MM: f64 = 1.5;

/// The chained start's gate, as a fraction of the image's diagonal (40 px of a 762 x 506
/// image). Its error (the guessed intrinsics' missing distortion, single-view placements from
/// a tag's few pixels) and a flipped view's offset both scale with the image's pixel count,
/// which doubles per axis when raw files are read per photosite rather than as superpixels: a
/// gate in pixels would leave out, read per photosite, the far corners of a strongly
/// distorting lens that the same card read as superpixels keeps.
pub const START_GATE_DIAGONAL_FRACTION: f64 = 0.044;

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
    /// A target of an image whose start is off by more than this fraction of the image's
    /// diagonal is left out of that image (the chained start is close; a flipped view is far
    /// off). See [`START_GATE_DIAGONAL_FRACTION`].
    pub start_gate_diagonal_fraction: f64,
    /// A body is "moved" when it disagrees in at least this many images ...
    pub moved_min_images: usize,
    /// ... and in at least this fraction of the images that see it.
    pub moved_min_fraction: f64,
    /// Change-point test: a split of a body's time-ordered views into a before and an after
    /// placement must explain at least this chi-square (in units of the session's variance
    /// factor) to name the body moved.
    pub change_point_chi2: f64,
    /// ... with at least this many views on each side of the split ...
    pub change_point_min_views: usize,
    /// ... and the two placements at least this far apart at some corner, mm ...
    pub moved_min_shift_mm: f64,
    /// ... and the median view of each side explaining at least this chi-square.
    pub change_point_view_chi2: f64,
    /// A body whose single-view placements form two consistent groups at least this far
    /// apart, metres, is at two places ([`SurveyIssue::TwoPlaces`]).
    pub two_places_min_m: f64,
    /// A sheet whose layout leaves a corner off by more than this in single views (pixels)
    /// is not rigid (see [`SurveyIssue::NotRigid`]).
    pub not_rigid_px: f64,
    /// ... or whose own variance factor after the first adjustment exceeds the session's by
    /// this ratio.
    pub not_rigid_variance_ratio: f64,
    /// A reference target placed less certainly than this (position sd, mm) is left out
    /// ([`SurveyIssue::Uncertain`]).
    pub max_sigma_reference_mm: f64,
    /// The same for a headdress target.
    pub max_sigma_headdress_mm: f64,
    /// The same for a reference target seen in light-position images and in no measurement or
    /// standard image (it serves the flash alone).
    pub max_sigma_flash_only_mm: f64,
}

impl SurveyConfig {
    /// Defaults. The consensus tolerances cover a single-tag start (a camera posed from one
    /// 25-35 mm tag is about a degree off, a few millimetres at the neighbouring targets; the
    /// range-dependent share is added in the consensus) and, where the orientation is tested,
    /// are far below a planar flip (tens of degrees).
    pub const DEFAULT: Self = Self {
        detector: DetectorConfig::DEFAULT,
        pnp: PnpConfig::DEFAULT,
        bundle: BundleConfig::DEFAULT,
        consensus_position_m: 0.015,
        consensus_angle_deg: 8.0,
        min_views: 2,
        estimate_print_scale: true,
        start_gate_diagonal_fraction: START_GATE_DIAGONAL_FRACTION,
        moved_min_images: 2,
        moved_min_fraction: 0.2,
        change_point_chi2: CHANGE_POINT_CHI2,
        change_point_min_views: 3,
        moved_min_shift_mm: MOVED_MIN_SHIFT_MM,
        change_point_view_chi2: CHANGE_POINT_VIEW_CHI2,
        two_places_min_m: TWO_PLACES_MIN_M,
        not_rigid_px: NOT_RIGID_PX,
        not_rigid_variance_ratio: NOT_RIGID_VARIANCE_RATIO,
        max_sigma_reference_mm: MAX_SIGMA_REFERENCE_MM,
        max_sigma_headdress_mm: MAX_SIGMA_HEADDRESS_MM,
        max_sigma_flash_only_mm: MAX_SIGMA_FLASH_ONLY_MM,
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

impl std::fmt::Display for HeadGauge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Declared { targets } => {
                let ids: Vec<String> = targets.iter().map(u32::to_string).collect();
                write!(
                    f,
                    "fixed by the headdress targets the rig places ({})",
                    ids.join(", ")
                )
            }
            Self::Provisional { anchor } => write!(
                f,
                "provisional: the frame of headdress target {anchor}, not yet related to the scan"
            ),
            Self::Registered { method } => write!(f, "registered to the head scan ({method})"),
            Self::None => f.write_str("no headdress target to survey"),
        }
    }
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
    /// Seen in no measurement or standard image, and either seen in light-position images or
    /// seen together with such a target (a relay's link shots): it serves the flash alone and
    /// is held to [`SurveyConfig::max_sigma_flash_only_mm`] (a reference target; false for
    /// others).
    #[serde(default)]
    pub flash_only: bool,
    /// Serves the flash alone and is seen in light-position images: the flash stand's panel,
    /// which places the light-position cameras (false for the relay and for others).
    #[serde(default)]
    pub light_position: bool,
    /// RMS reprojection error of its corners at the solution, pixels.
    pub rms_px: f64,
    /// Its body's own variance factor over the session's (its sigmas are scaled by the root of
    /// this when above 1).
    #[serde(default = "one")]
    pub variance_ratio: f64,
}

const fn one() -> f64 {
    1.0
}

/// The uncertainty of a frame registration (the head scan's frame found from the headdress).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameUncertainty {
    /// Standard error of the translation at the registered targets' centroid, mm.
    pub centroid_sd_mm: f64,
    /// Standard error of the rotation, degrees.
    pub rotation_sd_deg: f64,
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
        /// Its group (older survey files have none: reference).
        #[serde(default = "reference_group")]
        group: TargetGroup,
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
        /// Images where it disagrees with its surveyed placement: the images after the change
        /// when the change-point test found it, else those beyond the input gate.
        disagreeing_images: Vec<String>,
        /// Images where it agrees.
        agreeing: usize,
        /// Worst corner error in the disagreeing images at the joint placement, pixels.
        worst_px: f64,
        /// The largest corner displacement between the placements fitted before and after the
        /// change, mm (change-point test only).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        shift_mm: Option<f64>,
        /// The chi-square the split explains, in units of the session's variance factor
        /// (change-point test only).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        chi2: Option<f64>,
    },
    /// Placed, but less certainly than the survey's accuracy target for its group
    /// ([`SurveyConfig::max_sigma_reference_mm`], [`SurveyConfig::max_sigma_headdress_mm`]):
    /// held fixed in the poses, its error would pass into every pose that uses it. Left out;
    /// survey images that see it from other directions would place a reference target (more
    /// measurement images, a headdress target).
    Uncertain {
        /// The target.
        id: u32,
        /// Its group (older survey files have none: reference).
        #[serde(default = "reference_group")]
        group: TargetGroup,
        /// Images whose corners were used.
        views: usize,
        /// Standard deviation of its centre, mm.
        position_sigma_mm: f64,
        /// The bound it exceeds, mm.
        bound_mm: f64,
    },
    /// Seen in enough images, but only in images that share too few placed targets with the
    /// rest of the session to get a camera pose in the group's frame (too few targets in common
    /// between image groups). Left out.
    Unlinked {
        /// The targets seen together in those images.
        ids: Vec<u32>,
        /// The images that see them.
        images: Vec<String>,
        /// How many of those images have a pose in the group's frame.
        linked_images: usize,
    },
    /// Its single-view placements agree on two places far apart: the same id printed twice
    /// on the rig (never seen together in one image), or a target that moved far. Left out.
    TwoPlaces {
        /// The target.
        id: u32,
        /// The distance between the two places, mm.
        apart_mm: f64,
        /// The images that put it at the first place.
        first: Vec<String>,
        /// The images that put it at the second.
        second: Vec<String>,
    },
    /// A printed sheet whose targets do not keep their layout (bent, folded, or a band wrapped
    /// round the head): a warning, its targets are surveyed one by one instead.
    NotRigid {
        /// The sheet.
        sheet: String,
        /// Its targets: id and printed size, metres.
        targets: Vec<(u32, f64)>,
        /// The single-view test's worst corner, pixels (when that test found it).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        worst_px: Option<f64>,
        /// The adjustment's variance ratio (when that test found it).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        variance_ratio: Option<f64>,
    },
    /// The same id was detected twice in one image. Left out.
    Duplicated {
        /// The id.
        id: u32,
        /// The image.
        image: String,
    },
}

impl SurveyIssue {
    /// Whether the issue is a warning whose targets the survey still placed (a sheet found
    /// not rigid, surveyed target by target), rather than targets left out.
    pub const fn is_warning(&self) -> bool {
        matches!(self, Self::NotRigid { .. })
    }

    /// Whether survey images (role `survey`: seeing the target from other directions, or at
    /// all) would place the issue's targets: a reference target seen too rarely or placed too
    /// uncertainly (survey images are taken without the subject: they never see the
    /// headdress).
    pub fn survey_images_would_help(&self) -> bool {
        matches!(
            self,
            Self::NotSeen { group, .. } | Self::Uncertain { group, .. }
                if *group == TargetGroup::Reference
        )
    }

    /// The issue's prefix in reports: `warning` or `left out`.
    pub const fn label(&self) -> &'static str {
        if self.is_warning() {
            "warning"
        } else {
            "left out"
        }
    }
}

/// Target ids in words: `3, 7, 12`.
fn id_list(ids: &[u32]) -> String {
    ids.iter()
        .map(u32::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

impl std::fmt::Display for SurveyIssue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotSeen { id, views, .. } => {
                write!(
                    f,
                    "target {id}: seen in {views} image(s) with a camera pose, too few"
                )?;
                if self.survey_images_would_help() {
                    write!(
                        f,
                        " (survey images that see it would place it: `skinbrdf ingest --survey`)"
                    )?;
                }
                Ok(())
            }
            Self::NoConsensus {
                id,
                candidates,
                agreeing,
            } => write!(
                f,
                "target {id}: its {candidates} single-view placements do not agree (at most \
                 {agreeing})"
            ),
            Self::Moved {
                ids,
                disagreeing_images,
                agreeing,
                worst_px,
                shift_mm,
                chi2,
            } => {
                write!(f, "target(s) {} moved during the session: ", id_list(ids))?;
                match (shift_mm, chi2, disagreeing_images.first()) {
                    (Some(mm), Some(c), Some(first)) => write!(
                        f,
                        "placed {mm:.2} mm apart before and after {first} (chi-square {c:.0}; \
                         {agreeing} image(s) before, {} from it on, up to {worst_px:.2} px off)",
                        disagreeing_images.len()
                    ),
                    _ => write!(
                        f,
                        "off by up to {worst_px:.1} px in {} image(s) ({}), in place in \
                         {agreeing}",
                        disagreeing_images.len(),
                        disagreeing_images.join(", ")
                    ),
                }
            }
            Self::Uncertain {
                id,
                views,
                position_sigma_mm,
                bound_mm,
                ..
            } => write!(
                f,
                "target {id}: placed from {views} image(s) to {position_sigma_mm:.2} mm (sd), \
                 above the {bound_mm} mm target; {}",
                if self.survey_images_would_help() {
                    "survey images that see it from other directions would place it \
                     (`skinbrdf ingest --survey`)"
                } else {
                    "more images that see it from other directions would place it"
                }
            ),
            Self::Unlinked {
                ids,
                images,
                linked_images,
            } => write!(
                f,
                "target(s) {}: seen only in {} ({linked_images} of them linked to the \
                 rest of the session): too few targets in common with the images that see \
                 placed targets; photograph them together with placed ones",
                id_list(ids),
                images.join(", ")
            ),
            Self::TwoPlaces {
                id,
                apart_mm,
                first,
                second,
            } => write!(
                f,
                "target {id}: seen at two places {apart_mm:.0} mm apart ({} image(s): {}; {} \
                 image(s): {}): its id is printed twice on the rig or it moved; left out",
                first.len(),
                first.join(", "),
                second.len(),
                second.join(", ")
            ),
            Self::NotRigid {
                sheet,
                targets,
                worst_px,
                variance_ratio,
            } => {
                let ids: Vec<u32> = targets.iter().map(|t| t.0).collect();
                write!(
                    f,
                    "sheet `{sheet}` (targets {}) is not rigid: ",
                    id_list(&ids)
                )?;
                match (worst_px, variance_ratio) {
                    (Some(px), _) => write!(f, "its layout leaves corners up to {px:.1} px off")?,
                    (_, Some(r)) => write!(
                        f,
                        "its corners scatter about its layout {r:.1} times the session's variance"
                    )?,
                    _ => {}
                }
                write!(f, "; its targets are surveyed one by one")
            }
            Self::Duplicated { id, image } => write!(f, "target {id}: detected twice in {image}"),
        }
    }
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
    /// Of those, survey images (role `survey`).
    #[serde(default)]
    pub survey_images_used: usize,
    /// Timings.
    pub timing: SurveyTiming,
    /// The camera was to be calibrated and the survey ran twice: a first round from the
    /// guessed intrinsics, then the whole survey again starting from the intrinsics that round
    /// refined (the single-view placements of the chained start need them; see
    /// [`survey_detected`]). The timings are the second round's, the total both.
    #[serde(default)]
    pub intrinsics_restart: bool,
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

/// One detection: corners, sigmas, occluded flags, apparent side.
#[derive(Debug, Clone, Copy)]
struct Obs {
    corners_px: [DVec2; 4],
    sigma_px: [f64; 4],
    occluded: [bool; 4],
    /// Mean side, pixels ([`skinbrdf_targets::Detection::side_px`]).
    side_px: f64,
}

/// One image's single-view placement of a body in the chained start.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    image: usize,
    group_from_body: Pose,
    /// The body's apparent size there: its largest seen target's mean side, pixels.
    side_px: f64,
    /// Distance from the camera, metres.
    range_m: f64,
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

/// The group of an issue read from a survey file written before issues named their group.
const fn reference_group() -> TargetGroup {
    TargetGroup::Reference
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

/// A single target's pose from its corners triangulated over `views` (their cameras in the
/// group frame, `gfc`): each corner is the point nearest all its rays in the least-squares
/// sense, and the pose maps the target's square onto the triangulated one (origin at the
/// centroids, axes from the square's edge directions). Several views of a small tag place it
/// far better this way than the mean of its single-view poses, whose orientations scatter by
/// tens of degrees when the tag is 20 px across. `None` for a body of several targets (a
/// sheet's single-view poses are already good), when a corner has fewer than two rays or rays
/// closer than [`MIN_TRIANGULATION_ANGLE_DEG`], or when the triangulated square's edges are
/// off its printed size by more than [`MAX_TRIANGULATED_EDGE_ERROR`].
fn triangulated_pose(
    def: &BodyDef,
    views: &[usize],
    gfc: &[Option<Pose>],
    obs: &[HashMap<u32, Obs>],
    camera: &CameraModel,
) -> Option<Pose> {
    let [(id, size_m, body)] = def.members.as_slice() else {
        return None;
    };
    let mut corners = [DVec3::ZERO; 4];
    for (k, corner) in corners.iter_mut().enumerate() {
        let rays: Vec<(DVec3, DVec3)> = views
            .iter()
            .filter_map(|&i| {
                let wc = gfc.get(i).copied().flatten()?;
                let o = obs.get(i)?.get(id)?;
                if o.occluded[k] {
                    return None;
                }
                let d = camera.pixel_ray(o.corners_px[k])?;
                Some((wc.translation_m, wc.rotation * d))
            })
            .collect();
        let widest = rays
            .iter()
            .flat_map(|a| rays.iter().map(move |b| a.1.angle_between(b.1)))
            .fold(0.0f64, f64::max);
        if rays.len() < 2 || widest.to_degrees() < MIN_TRIANGULATION_ANGLE_DEG {
            return None;
        }
        // Σ (I − d dᵀ) X = Σ (I − d dᵀ) o.
        let mut a = glam::DMat3::ZERO;
        let mut rhs = DVec3::ZERO;
        for (o, d) in &rays {
            let m = glam::DMat3::IDENTITY - glam::DMat3::from_cols(*d * d.x, *d * d.y, *d * d.z);
            a += m;
            rhs += m * *o;
        }
        if a.determinant().abs() < 1e-12 {
            return None;
        }
        *corner = a.inverse() * rhs;
    }
    let edge_ok = (0..4).all(|k| {
        let e = corners[k].distance(corners[(k + 1) % 4]);
        (e / size_m - 1.0).abs() <= MAX_TRIANGULATED_EDGE_ERROR
    });
    if !edge_ok {
        return None;
    }
    let frame = |p: &[DVec3; 4]| {
        let x = ((p[1] - p[0]) + (p[2] - p[3])).normalize_or_zero();
        let y0 = (p[0] - p[3]) + (p[1] - p[2]);
        let z = x.cross(y0).normalize_or_zero();
        let y = z.cross(x);
        let c = p.iter().copied().sum::<DVec3>() * 0.25;
        (glam::DMat3::from_cols(x, y, z), c)
    };
    let (rb, cb) = frame(body);
    let (rg, cg) = frame(&corners);
    let r = rg * rb.transpose();
    if !r.is_finite() || (r.determinant() - 1.0).abs() > 1e-6 {
        return None;
    }
    let q = DQuat::from_mat3(&r).normalize();
    Some(Pose::new(q, cg - q * cb))
}

/// Share of the camera-to-body range added to [`SurveyConfig::consensus_position_m`] in the
/// consensus: a camera chained through small targets (a link shot posed from a relay 1 m
/// away) is off by a fraction of a degree to a degree, so its candidates for a body 2.5 m
/// away scatter by centimetres; with the fixed part, 1 % allows about 40 mm there.
const CONSENSUS_RANGE_FRACTION: f64 = 0.01;

/// The consensus distance stays below this share of [`SurveyConfig::two_places_min_m`], so
/// that two places remain two sets.
const CONSENSUS_MAX_OF_TWO_PLACES: f64 = 0.9;

/// A body seen smaller than this in either of two views (its largest target's mean edge, px)
/// has their single-view orientations left out of the consensus: at 20 px a tag's orientation
/// scatters by tens of degrees (its planar flip among them), while its position still agrees.
/// Its orientation then comes from the corners triangulated over the agreeing views.
const CONSENSUS_ORIENTATION_MIN_SIDE_PX: f64 = 40.0;

/// Least angle between two rays of a corner for [`triangulated_pose`], degrees: below it the
/// depth rests on the tag's apparent size, as in a single view.
const MIN_TRIANGULATION_ANGLE_DEG: f64 = 5.0;

/// Largest relative error of a triangulated square's edge against the printed size for
/// [`triangulated_pose`] to be used: beyond it the cameras are too far off for triangulation
/// to beat the single-view mean.
const MAX_TRIANGULATED_EDGE_ERROR: f64 = 0.2;

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
                side_px: t.side_px(),
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
    names: &[String],
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
    let mut two_places: HashSet<usize> = HashSet::new();
    loop {
        // (1) Cameras in the group frame from what is placed (parallel over images).
        let placed_pose: &[Option<Pose>] = pose;
        obs.par_iter()
            .zip(gfc.par_iter_mut())
            .for_each(|(o, gfc_i)| {
                let mut pts = Vec::new();
                let mut n = 0;
                for (id, c) in &g.placed {
                    if let Some(d) = o.get(id) {
                        pts.extend(points(*id, c, d));
                        n += 1;
                    }
                }
                for &b in &g.bodies {
                    let Some(p) = placed_pose[b] else { continue };
                    for (id, _, c) in &g.defs[b].members {
                        if let Some(d) = o.get(id) {
                            pts.extend(points(*id, &c.map(|x| p.transform_point(x)), d));
                            n += 1;
                        }
                    }
                }
                let need = if allow_single { 1 } else { 2 };
                *gfc_i = if n >= need {
                    estimate_pose(camera, &pts, None, &pnp_n(need.min(n)))
                        .ok()
                        .map(|e| e.frame_from_camera)
                } else {
                    None
                };
            });
        // (2) Candidates for the bodies not yet placed.
        let mut placed_now = 0;
        for &b in &g.bodies {
            if pose[b].is_some() {
                continue;
            }
            if two_places.contains(&b) {
                continue;
            }
            // Single-view poses of the body in every image with a camera (parallel).
            let cands: Vec<Candidate> = obs
                .par_iter()
                .enumerate()
                .filter_map(|(i, o)| {
                    let wc = gfc[i]?;
                    let mut pts = Vec::new();
                    let mut side_px = 0.0f64;
                    for (id, _, c) in &g.defs[b].members {
                        if let Some(d) = o.get(id) {
                            pts.extend(points(*id, c, d));
                            side_px = side_px.max(d.side_px);
                        }
                    }
                    if pts.len() < 4 {
                        return None;
                    }
                    estimate_pose(camera, &pts, None, &pnp_n(1)).ok().map(|e| {
                        let p = wc * e.frame_from_camera.inverse();
                        Candidate {
                            image: i,
                            group_from_body: p,
                            side_px,
                            range_m: p.translation_m.distance(wc.translation_m),
                        }
                    })
                })
                .collect();
            // Positions agree within the configured distance plus a share of the range (the
            // chained cameras' angular error carried to the body), below the distance that
            // makes two places; orientations only where both views see the body large enough
            // for a single view's orientation to mean anything.
            let agree = |a: &Candidate, b: &Candidate| {
                let (pa, pb) = (a.group_from_body, b.group_from_body);
                let tol_m = (cfg.consensus_position_m
                    + CONSENSUS_RANGE_FRACTION * a.range_m.max(b.range_m))
                .min(CONSENSUS_MAX_OF_TWO_PLACES * cfg.two_places_min_m)
                .max(cfg.consensus_position_m);
                pa.translation_m.distance(pb.translation_m) < tol_m
                    && (a.side_px.min(b.side_px) < CONSENSUS_ORIENTATION_MIN_SIDE_PX
                        || angle_deg(pa.rotation, pb.rotation) < cfg.consensus_angle_deg)
            };
            let largest = |cs: &[Candidate]| -> Vec<Candidate> {
                cs.iter()
                    .map(|c| cs.iter().filter(|d| agree(c, d)).copied().collect())
                    .max_by_key(|v: &Vec<Candidate>| v.len())
                    .unwrap_or_default()
            };
            let best = largest(&cands);
            last_candidates.insert(b, (cands.len(), best.len()));
            if best.len() < cfg.min_views {
                continue;
            }
            let poses = |v: &[Candidate]| v.iter().map(|c| c.group_from_body).collect::<Vec<_>>();
            let views: Vec<usize> = best.iter().map(|c| c.image).collect();
            let here = triangulated_pose(&g.defs[b], &views, &gfc, obs, camera)
                .or_else(|| mean_pose(&poses(&best)));
            // A second consistent placement far from the first: the same id printed twice (or a
            // target that moved far): named, not averaged in.
            let rest: Vec<Candidate> = cands
                .iter()
                .filter(|c| !best.iter().any(|d| d.image == c.image))
                .copied()
                .collect();
            let second = largest(&rest);
            let there = mean_pose(&poses(&second));
            if let (Some(a), Some(z)) = (here, there) {
                let apart = a.translation_m.distance(z.translation_m);
                if second.len() >= cfg.min_views && apart > cfg.two_places_min_m {
                    two_places.insert(b);
                    let imgs = |v: &[Candidate]| -> Vec<String> {
                        let mut i: Vec<usize> = v.iter().map(|c| c.image).collect();
                        i.sort_unstable();
                        i.into_iter().map(|i| names[i].clone()).collect()
                    };
                    for (id, _, _) in &g.defs[b].members {
                        issues.push(SurveyIssue::TwoPlaces {
                            id: *id,
                            apart_mm: apart * 1e3,
                            first: imgs(&best),
                            second: imgs(&second),
                        });
                    }
                    continue;
                }
            }
            pose[b] = here;
            placed_now += 1;
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
    // What could not be placed, and why: seen too rarely, seen only in images that share too
    // few targets with the placed ones (grouped by the images linking them), or inconsistent.
    let sees =
        |b: usize, o: &HashMap<u32, Obs>| g.defs[b].members.iter().any(|m| o.contains_key(&m.0));
    let mut unlinked: Vec<usize> = Vec::new();
    for &b in &g.bodies {
        if pose[b].is_some() || two_places.contains(&b) {
            continue;
        }
        let (cands, agreeing) = last_candidates.get(&b).copied().unwrap_or((0, 0));
        let views = obs.iter().filter(|o| sees(b, o)).count();
        let posed = obs
            .iter()
            .zip(&gfc)
            .filter(|(o, c)| c.is_some() && sees(b, o))
            .count();
        if cands < cfg.min_views && views >= cfg.min_views && posed < cfg.min_views {
            unlinked.push(b);
            continue;
        }
        for (id, _, _) in &g.defs[b].members {
            issues.push(if cands >= cfg.min_views {
                SurveyIssue::NoConsensus {
                    id: *id,
                    candidates: cands,
                    agreeing,
                }
            } else {
                SurveyIssue::NotSeen {
                    id: *id,
                    views,
                    group: g.defs[b].group,
                }
            });
        }
    }
    // Unlinked bodies seen together in an image form one group of the issue.
    let mut component: Vec<usize> = (0..unlinked.len()).collect();
    fn root(c: &mut [usize], mut i: usize) -> usize {
        while c[i] != i {
            c[i] = c[c[i]];
            i = c[i];
        }
        i
    }
    for o in obs {
        let here: Vec<usize> = (0..unlinked.len())
            .filter(|&k| sees(unlinked[k], o))
            .collect();
        for w in here.windows(2) {
            let (a, b) = (root(&mut component, w[0]), root(&mut component, w[1]));
            component[a] = b;
        }
    }
    let mut groups: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (k, &b) in unlinked.iter().enumerate() {
        let r = root(&mut component, k);
        groups.entry(r).or_default().push(b);
    }
    for bodies in groups.values() {
        let mut ids: Vec<u32> = bodies
            .iter()
            .flat_map(|&b| g.defs[b].members.iter().map(|m| m.0))
            .collect();
        ids.sort_unstable();
        let images: Vec<String> = obs
            .iter()
            .enumerate()
            .filter(|(_, o)| bodies.iter().any(|&b| sees(b, o)))
            .map(|(i, _)| names[i].clone())
            .collect();
        let shared = obs
            .iter()
            .zip(&gfc)
            .filter(|(o, c)| c.is_some() && bodies.iter().any(|&b| sees(b, o)))
            .count();
        issues.push(SurveyIssue::Unlinked {
            ids,
            images,
            linked_images: shared,
        });
    }
    gfc
}

/// The bodies of a session's unplaced reference and headdress targets; the targets of the
/// sheets in `split` (found not rigid) are bodies of their own.
fn bodies_of(
    file: &SessionFile,
    split: &BTreeMap<String, SurveyIssue>,
) -> Result<Vec<BodyDef>, PoseError> {
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
            (Some(name), Some(c)) if !split.contains_key(name) => sheets
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

/// What one round of the survey ended with.
enum Round {
    /// The survey.
    Done(Box<Survey>),
    /// Sheets found not rigid: survey again with their targets one by one.
    NotRigid(Vec<SurveyIssue>),
}

/// Surveys every unplaced reference and headdress target of the session (see the module docs).
pub fn survey(session: &Session, cfg: &SurveyConfig) -> Result<Survey, PoseError> {
    survey_detected(session, cfg).map(|(s, _)| s)
}

/// Like [`survey`], also returning the tags found in the session's images, for the pose
/// stage on the surveyed session ([`crate::session::estimate_session_detected`]).
pub fn survey_detected(
    session: &Session,
    cfg: &SurveyConfig,
) -> Result<(Survey, SessionDetections), PoseError> {
    let t0 = Instant::now();
    let file = &session.file;
    // Every unplaced flash or standard target is refused before any image is read.
    bodies_of(file, &BTreeMap::new())?;
    let detections = SessionDetections::detect(session, &cfg.detector);
    let detected = &detections.detected;
    for (i, d) in detected.iter().enumerate() {
        if let Some(e) = &d.error {
            return Err(PoseError::Image {
                file: file.images[i].file.clone(),
                problem: e.clone(),
            });
        }
    }
    // Sheets found bent are surveyed again target by target; each round splits at least one
    // more sheet, so the rounds end.
    let mut split: BTreeMap<String, SurveyIssue> = BTreeMap::new();
    // The intrinsics the chained start uses when the camera is to be calibrated: first the
    // guess, then (once) what the first complete round refined.
    let guessed = matches!(file.camera, CameraSpec::ToBeCalibrated { .. });
    let mut refined_start: Option<CameraModel> = None;
    loop {
        match survey_with(session, cfg, detected, &split, refined_start.as_ref(), t0)? {
            Round::Done(s) if guessed && refined_start.is_none() => {
                // The chained start's single-view placements rest on the guessed intrinsics:
                // a focal length a few per cent off moves each view's placement along its
                // line of sight by that share of its range, so views from different distances
                // disagree by tens of millimetres (enough to look like two places). Start
                // again from the intrinsics the first round refined.
                refined_start = Some(s.camera);
            }
            Round::Done(mut s) => {
                s.intrinsics_restart = refined_start.is_some();
                s.issues.extend(split.into_values());
                return Ok((*s, detections));
            }
            Round::NotRigid(found) => {
                let before = split.len();
                for i in found {
                    if let SurveyIssue::NotRigid { sheet, .. } = &i {
                        split.entry(sheet.clone()).or_insert(i);
                    }
                }
                if split.len() == before {
                    return Err(PoseError::SurveySingular {
                        start_focal_px: None,
                    });
                }
            }
        }
    }
}

/// The starting camera of a survey whose camera is to be calibrated and states no focal
/// length: the focal length every tag seen implies ([`focal_from_squares`]; tags with a
/// corner marked occluded are left out), the principal point at the centre, no distortion.
fn squares_start(
    width_px: u32,
    height_px: u32,
    detected: &[Detected],
) -> Result<CameraModel, PoseError> {
    let squares: Vec<[DVec2; 4]> = detected
        .iter()
        .flat_map(|d| &d.dets)
        .filter(|t| !t.occluded_corners.contains(&true))
        .map(|t| t.corners_px)
        .collect();
    let f_px =
        focal_from_squares(width_px, height_px, &squares).ok_or(PoseError::NoFocalStart {
            why: "the tags seen do not determine a focal length",
        })?;
    Ok(CameraModel {
        fx_px: f_px,
        fy_px: f_px,
        ..CameraModel::from_fov(width_px, height_px, 1.0)
    })
}

/// One round of the survey, with the sheets in `split` surveyed target by target; a camera
/// to be calibrated starts from `refined_start` when given, else from its guess.
fn survey_with(
    session: &Session,
    cfg: &SurveyConfig,
    detected: &[Detected],
    split: &BTreeMap<String, SurveyIssue>,
    refined_start: Option<&CameraModel>,
    t0: Instant,
) -> Result<Round, PoseError> {
    let file = &session.file;
    let defs = bodies_of(file, split)?;
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
    let detect_ms: f64 = detected.iter().map(|d| d.detect_ms).sum();
    let t_init = Instant::now();
    let (mut obs, dups) = observations(session, detected, &mut issues);
    // A survey image is taken before the subject sits: a headdress it sees is not on the head
    // (and a band off the head is not the shape it has on it), so its headdress targets are
    // not observations of the head frame. The image serves the reference group only.
    let head_ids: HashSet<u32> = placed_head
        .keys()
        .copied()
        .chain(
            defs.iter()
                .filter(|d| d.group == TargetGroup::Headdress)
                .flat_map(|d| d.members.iter().map(|m| m.0)),
        )
        .collect();
    for (o, entry) in obs.iter_mut().zip(&file.images) {
        if !entry.role.has_subject() {
            o.retain(|id, _| !head_ids.contains(id));
        }
    }
    let names: Vec<String> = file.images.iter().map(|e| e.file.clone()).collect();
    // The camera: given, or a starting guess refined by the adjustment.
    let (camera, refine_intrinsics) = match (&file.camera, refined_start) {
        (CameraSpec::Calibrated(m), _) => (*m, cfg.bundle.refine_intrinsics),
        (CameraSpec::ToBeCalibrated { .. }, Some(c)) => (*c, true),
        (
            CameraSpec::ToBeCalibrated {
                width_px,
                height_px,
                focal_guess_px,
            },
            None,
        ) => {
            let c = match focal_guess_px {
                Some(f) => CameraModel {
                    fx_px: *f,
                    fy_px: *f,
                    ..CameraModel::from_fov(*width_px, *height_px, 1.0)
                },
                None => squares_start(*width_px, *height_px, detected)?,
            };
            (c, true)
        }
    };
    // Sheets whose layout does not fit their corners in single views are not rigid.
    let bent: Vec<SurveyIssue> = defs
        .iter()
        .filter_map(|d| single_view_rigidity(d, &obs, &camera, cfg))
        .collect();
    if !bent.is_empty() {
        return Ok(Round::NotRigid(bent));
    }
    let mut pose: Vec<Option<Pose>> = vec![None; defs.len()];
    let of_group = |g: TargetGroup| -> Vec<usize> {
        (0..defs.len()).filter(|&b| defs[b].group == g).collect()
    };
    let ref_init = GroupInit {
        placed: placed_ref.clone(),
        bodies: of_group(TargetGroup::Reference),
        defs: &defs,
    };
    let world_from_camera = init_group(
        &ref_init,
        &obs,
        &names,
        &camera,
        cfg,
        &mut pose,
        &mut issues,
    );
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
    let head_from_camera = init_group(
        &head_init,
        &obs,
        &names,
        &camera,
        cfg,
        &mut pose,
        &mut issues,
    );
    // A duplicated id is named once, as duplicated.
    issues.retain(|i| !matches!(i, SurveyIssue::NotSeen { id, .. } if dups.contains(id)));
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
    let start_gate_px = cfg.start_gate_diagonal_fraction
        * f64::from(camera.width_px).hypot(f64::from(camera.height_px));
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
                    if off > start_gate_px {
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
    let singular = PoseError::SurveySingular {
        start_focal_px: matches!(file.camera, CameraSpec::ToBeCalibrated { .. })
            .then_some(camera.fx_px),
    };
    let r1 = bundle_adjust(&p1, &pass1_cfg).ok_or_else(|| singular.clone())?;
    // A sheet whose corners fit its layout much worse than the session's bodies fit theirs is
    // bent (the single-view test sees only strong bends).
    let mut bent = Vec::new();
    for (b, def) in defs.iter().enumerate() {
        let (Some(k), Some(name)) = (body_index[b], def.sheet.as_ref()) else {
            continue;
        };
        if def.members.len() < 2 {
            continue;
        }
        let ((gp, _), scale, _) = &r1.bodies[k];
        let ratio = local_variance_ratio(
            def,
            &BodyFit {
                group_from_body: gp,
                scale: *scale,
                scale_free: cfg.estimate_print_scale,
            },
            &r1,
            &index1,
            &obs,
            &BundleConfig {
                gate_sigma: f64::INFINITY,
                ..cfg.bundle
            },
        );
        if ratio > cfg.not_rigid_variance_ratio {
            bent.push(SurveyIssue::NotRigid {
                sheet: name.clone(),
                targets: def.members.iter().map(|m| (m.0, m.1)).collect(),
                worst_px: None,
                variance_ratio: Some(ratio),
            });
        }
    }
    if !bent.is_empty() {
        return Ok(Round::NotRigid(bent));
    }
    // Moved bodies: a change point in each body's time-ordered views (a move half-way) ...
    let mut change_points: Vec<(usize, usize, usize)> = Vec::new();
    for (b, def) in defs.iter().enumerate() {
        let Some(k) = body_index[b] else { continue };
        if left_out.contains(&b) || anchor == Some(b) {
            continue;
        }
        let ((gp, _), scale, _) = &r1.bodies[k];
        let views = body_views(def, *scale, &r1, &index1, &obs);
        if let Some(cp) = change_point(&r1.camera, &views, gp, r1.report.variance_factor, cfg) {
            left_out.insert(b);
            change_points.push((b, issues.len(), views[cp.split].image));
            let after: Vec<String> = views[cp.split..]
                .iter()
                .map(|v| file.images[v.image].file.clone())
                .collect();
            issues.push(SurveyIssue::Moved {
                ids: def.members.iter().map(|m| m.0).collect(),
                disagreeing_images: after,
                agreeing: cp.split,
                worst_px: cp.worst_px,
                shift_mm: Some(cp.shift_mm),
                chi2: Some(cp.chi2),
            });
        }
    }
    // ... or, for the bodies seen too few times for it, the images where its corners are off
    // by more than the gate.
    for (b, def) in defs.iter().enumerate() {
        let Some(k) = body_index[b] else { continue };
        if left_out.contains(&b) {
            continue;
        }
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
                shift_mm: None,
                chi2: None,
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
    let r2 = bundle_adjust(&p2, &pass2_cfg).ok_or(singular)?;
    let bundle_ms = t_ba.elapsed().as_secs_f64() * 1e3;
    // A moved body's displacement, measured again with the cameras it no longer pulls.
    for &(b, issue, first_after) in &change_points {
        let Some(k) = body_index[b] else { continue };
        let ((gp, _), scale, _) = &r1.bodies[k];
        let views = body_views(&defs[b], *scale, &r2, &index2, &obs);
        let split = views.partition_point(|v| v.image < first_after);
        let floor = cfg.bundle.sigma_floor_px;
        let fits = (
            fit_body(&r2.camera, &views[..split], gp, floor),
            fit_body(&r2.camera, &views[split..], gp, floor),
        );
        if let ((Some((before, _)), Some((after, _))), Some(SurveyIssue::Moved { shift_mm, .. })) =
            (fits, issues.get_mut(issue))
        {
            *shift_mm = Some(max_corner_shift_mm(&views, &before, &after));
        }
    }

    // Results.
    let reference: HashSet<u32> = defs
        .iter()
        .filter(|d| d.group == TargetGroup::Reference)
        .flat_map(|d| d.members.iter().map(|m| m.0))
        .collect();
    let (flash_only, lit) = flash_only_ids(file, &obs, &reference);
    let mut targets = Vec::new();
    let mut sheets = Vec::new();
    for (b, def) in defs.iter().enumerate() {
        let Some(k) = body_index[b] else { continue };
        if left_out.contains(&b) {
            continue;
        }
        let ((gp, cov), scale, scale_var) = &r2.bodies[k];
        // The body's own scatter: when its corners fit worse than the session's, its
        // covariance is scaled by the ratio (see the module docs).
        let local = local_variance_ratio(
            def,
            &BodyFit {
                group_from_body: gp,
                scale: *scale,
                scale_free: def.sheet.is_some() && cfg.estimate_print_scale,
            },
            &r2,
            &index2,
            &obs,
            &cfg.bundle,
        );
        let inflate = local.max(1.0);
        let sig = |lever: DVec3| -> (f64, f64) {
            if cov.len() != 36 {
                return (0.0, 0.0);
            }
            let c = nalgebra::Matrix6::from_row_slice(cov) * inflate;
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
            let flash_only = def.group == TargetGroup::Reference && flash_only.contains(id);
            let bound_mm = match def.group {
                TargetGroup::Headdress => cfg.max_sigma_headdress_mm,
                _ if flash_only => cfg.max_sigma_flash_only_mm,
                _ => cfg.max_sigma_reference_mm,
            };
            if ps > bound_mm {
                issues.push(SurveyIssue::Uncertain {
                    id: *id,
                    group: def.group,
                    views,
                    position_sigma_mm: ps,
                    bound_mm,
                });
                continue;
            }
            targets.push(SurveyedTarget {
                id: *id,
                group: def.group,
                sheet: def.sheet.clone(),
                size_m: size_m * scale,
                corners_m,
                position_sigma_mm: ps,
                orientation_sigma_deg: os,
                views,
                flash_only,
                light_position: flash_only && lit.contains(id),
                rms_px: rms,
                variance_ratio: local,
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
    Ok(Round::Done(Box::new(Survey {
        targets,
        sheets,
        issues,
        head_gauge,
        camera: r2.camera,
        bodies: r2.bodies.len(),
        images_used: index2.len(),
        survey_images_used: index2
            .iter()
            .filter(|&&i| file.images[i].role == ImageRole::Survey)
            .count(),
        bundle: r2.report,
        timing: SurveyTiming {
            detect_ms,
            init_ms,
            bundle_ms,
            total_ms: t0.elapsed().as_secs_f64() * 1e3,
        },
        intrinsics_restart: false,
    })))
}

/// The single-view rigidity test of a sheet: in every image that sees at least two of its
/// targets, its layout is fitted to their corners (PnP); the sheet is not rigid when, in at
/// least half of those images (and two), some corner stays off by more than
/// [`SurveyConfig::not_rigid_px`]: a flat sheet's layout fits every view to the corners'
/// noise, whatever its tilt or print scale (a scaled print is a nearer or farther sheet).
fn single_view_rigidity(
    def: &BodyDef,
    obs: &[HashMap<u32, Obs>],
    camera: &CameraModel,
    cfg: &SurveyConfig,
) -> Option<SurveyIssue> {
    let name = def.sheet.as_ref()?;
    if def.members.len() < 2 {
        return None;
    }
    let pnp = PnpConfig {
        min_targets: 1,
        ..cfg.pnp
    };
    let (mut tested, mut off, mut worst) = (0usize, 0usize, 0.0f64);
    for o in obs {
        let seen: Vec<_> = def
            .members
            .iter()
            .filter_map(|(id, _, c)| o.get(id).map(|d| (*id, c, d)))
            .collect();
        if seen.len() < 2 {
            continue;
        }
        let pts: Vec<PointObs> = seen
            .iter()
            .flat_map(|(id, c, d)| points(*id, c, d))
            .collect();
        let Ok(e) = estimate_pose(camera, &pts, None, &pnp) else {
            continue;
        };
        let camera_from_sheet = e.frame_from_camera.inverse();
        let mut w = 0.0f64;
        for (_, c, d) in &seen {
            for (q, corner) in c.iter().enumerate() {
                if d.occluded[q] {
                    continue;
                }
                let e = camera
                    .project(camera_from_sheet.transform_point(*corner))
                    .map_or(f64::INFINITY, |px| px.distance(d.corners_px[q]));
                w = w.max(e);
            }
        }
        tested += 1;
        if w > cfg.not_rigid_px {
            off += 1;
            worst = worst.max(w);
        }
    }
    (off >= 2 && 2 * off >= tested).then(|| SurveyIssue::NotRigid {
        sheet: name.clone(),
        targets: def.members.iter().map(|m| (m.0, m.1)).collect(),
        worst_px: Some(worst),
        variance_ratio: None,
    })
}

/// One view of a body at the first pass's solution: the camera and the group's frame there, and
/// the body's visible corners (body frame, scaled) with their observations.
#[derive(Debug, Clone)]
struct BodyView {
    /// Index of the image in the session.
    image: usize,
    world_from_group: Pose,
    camera_from_world: Pose,
    /// Body-frame point, observed pixel, sigma (pixels).
    corners: Vec<(DVec3, DVec2, f64)>,
}

/// The views of a body, in the order the images were taken (the session lists them so).
fn body_views(
    def: &BodyDef,
    scale: f64,
    r: &crate::bundle::BundleResult,
    index: &[usize],
    obs: &[HashMap<u32, Obs>],
) -> Vec<BodyView> {
    let mut out = Vec::new();
    for (j, &i) in index.iter().enumerate() {
        let ((wc, _), head) = &r.images[j];
        let world_from_group = match def.group {
            TargetGroup::Headdress => match head {
                Some((wh, _)) => *wh,
                None => continue,
            },
            _ => Pose::IDENTITY,
        };
        let mut corners = Vec::new();
        for (id, _, c) in &def.members {
            let Some(d) = obs[i].get(id) else { continue };
            for (q, corner) in c.iter().enumerate() {
                if !d.occluded[q] {
                    corners.push((*corner * scale, d.corners_px[q], d.sigma_px[q]));
                }
            }
        }
        if !corners.is_empty() {
            out.push(BodyView {
                image: i,
                world_from_group,
                camera_from_world: wc.inverse(),
                corners,
            });
        }
    }
    out.sort_by_key(|v| v.image);
    out
}

/// `start` turned by the rotation vector `x[0..3]` (group frame) and moved by `x[3..6]`.
fn perturbed(start: &Pose, x: &DVector<f64>) -> Pose {
    Pose::new(
        crate::pnp::exp_so3(DVec3::new(x[0], x[1], x[2])) * start.rotation,
        start.translation_m + DVec3::new(x[3], x[4], x[5]),
    )
}

/// The body's placement fitted to `views` alone (cameras and group frames held), with its robust
/// cost in whitened units.
fn fit_body(
    camera: &CameraModel,
    views: &[BodyView],
    start: &Pose,
    floor_px: f64,
) -> Option<(Pose, f64)> {
    let residuals = |x: &DVector<f64>| -> Option<DVector<f64>> {
        let p = perturbed(start, x);
        let mut r = Vec::with_capacity(views.iter().map(|v| 2 * v.corners.len()).sum());
        for v in views {
            let from_body = v.camera_from_world * v.world_from_group * p;
            for (pb, px, s) in &v.corners {
                let q = camera.project(from_body.transform_point(*pb))?;
                let s = s.max(floor_px);
                r.push((q.x - px.x) / s);
                r.push((q.y - px.y) / s);
            }
        }
        Some(DVector::from_vec(r))
    };
    let cfg = crate::lm::LmConfig {
        max_iterations: 30,
        huber_k: Some(CHANGE_POINT_HUBER_K),
        cost_tolerance: 1e-10,
    };
    let res = crate::lm::minimize(residuals, DVector::zeros(6), &cfg)?;
    Some((perturbed(start, &res.x), res.cost))
}

/// A body's adjusted placement.
#[derive(Debug, Clone, Copy)]
struct BodyFit<'a> {
    group_from_body: &'a Pose,
    scale: f64,
    scale_free: bool,
}

/// The body's own a-posteriori variance factor over the session's: its corners' whitened
/// squared residuals (those the adjustment's input gate kept) over their degrees of freedom
/// (two per corner, less the body's own 6 or 7 parameters), divided by the session's factor.
fn local_variance_ratio(
    def: &BodyDef,
    fit: &BodyFit<'_>,
    r: &crate::bundle::BundleResult,
    index: &[usize],
    obs: &[HashMap<u32, Obs>],
    bundle: &BundleConfig,
) -> f64 {
    let views = body_views(def, fit.scale, r, index, obs);
    let mut chi2 = 0.0;
    let mut n = 0usize;
    for v in &views {
        let from_body = v.camera_from_world * v.world_from_group * *fit.group_from_body;
        for (pb, px, s) in &v.corners {
            let Some(q) = r.camera.project(from_body.transform_point(*pb)) else {
                continue;
            };
            let s = s.max(bundle.sigma_floor_px);
            let e = q.distance(*px);
            if e > (bundle.gate_sigma * s).max(GATE_MIN_PX) {
                continue;
            }
            chi2 += (e / s).powi(2);
            n += 1;
        }
    }
    let params = 6 + usize::from(fit.scale_free);
    let dof = (2 * n).saturating_sub(params).max(1) as f64;
    let vf = r.report.variance_factor;
    if n == 0 || !(vf.is_finite() && vf > 0.0) {
        return 1.0;
    }
    chi2 / dof / vf
}

/// The largest displacement of the body's corners between two placements, mm.
fn max_corner_shift_mm(views: &[BodyView], a: &Pose, b: &Pose) -> f64 {
    views
        .iter()
        .flat_map(|v| v.corners.iter().map(|c| c.0))
        .map(|p| a.transform_point(p).distance(b.transform_point(p)) * 1e3)
        .fold(0.0, f64::max)
}

/// The robust (Huber, as [`fit_body`]) cost of one view at a placement, whitened units.
fn view_cost(camera: &CameraModel, v: &BodyView, p: &Pose, floor_px: f64) -> f64 {
    let from_body = v.camera_from_world * v.world_from_group * *p;
    v.corners
        .iter()
        .map(|(pb, px, s)| {
            let e = camera
                .project(from_body.transform_point(*pb))
                .map_or(f64::INFINITY, |q| q.distance(*px))
                / s.max(floor_px);
            crate::bundle::RobustLoss::Huber
                .eval(e, CHANGE_POINT_HUBER_K)
                .0
        })
        .sum()
}

/// The Huber threshold of the change-point fits, whitened units (the adjustment's).
const CHANGE_POINT_HUBER_K: f64 = 3.0;

/// A change point found in a body's views.
#[derive(Debug, Clone, Copy)]
struct ChangePoint {
    /// The first view after the change (index into the views).
    split: usize,
    /// Explained chi-square over the variance factor.
    chi2: f64,
    /// Largest corner displacement between the two placements, mm.
    shift_mm: f64,
    /// Worst corner error of the views after the change at the joint placement, pixels.
    worst_px: f64,
}

/// The change-point test (see the module docs): the body's time-ordered views are split at every
/// point that leaves [`SurveyConfig::change_point_min_views`] on each side; the before and after
/// views are fitted apart (cameras and group frames held at the first pass's solution) and
/// against the joint fit. The best split is a move when the chi-square it explains, over the
/// session's variance factor, exceeds [`SurveyConfig::change_point_chi2`] and the two placements
/// differ by at least [`SurveyConfig::moved_min_shift_mm`] at some corner.
fn change_point(
    camera: &CameraModel,
    views: &[BodyView],
    placed: &Pose,
    variance_factor: f64,
    cfg: &SurveyConfig,
) -> Option<ChangePoint> {
    let m = cfg.change_point_min_views.max(1);
    if views.len() < 2 * m {
        return None;
    }
    let floor = cfg.bundle.sigma_floor_px;
    let (joint, joint_cost) = fit_body(camera, views, placed, floor)?;
    let vf = if variance_factor.is_finite() {
        variance_factor.max(0.1)
    } else {
        1.0
    };
    let mut best: Option<(usize, f64, Pose, Pose)> = None;
    for split in m..=views.len() - m {
        let Some((before, cb)) = fit_body(camera, &views[..split], &joint, floor) else {
            continue;
        };
        let Some((after, ca)) = fit_body(camera, &views[split..], &joint, floor) else {
            continue;
        };
        let chi2 = (joint_cost - cb - ca) / vf;
        if best.as_ref().is_none_or(|b| chi2 > b.1) {
            best = Some((split, chi2, before, after));
        }
    }
    let (split, chi2, before, after) = best?;
    if chi2 < cfg.change_point_chi2 {
        return None;
    }
    // A move puts the joint placement between the two, so it is seen in most views on both
    // sides; a few bad views (a corner hidden but not marked) explain the same chi-square from
    // one side's few views. The typical view of each side must gain from the split.
    let gain = |vs: &[BodyView], side: &Pose| -> f64 {
        let gains: Vec<f64> = vs
            .iter()
            .map(|v| (view_cost(camera, v, &joint, floor) - view_cost(camera, v, side, floor)) / vf)
            .collect();
        skinbrdf_core::stats::median(&gains)
    };
    if gain(&views[..split], &before).min(gain(&views[split..], &after))
        < cfg.change_point_view_chi2
    {
        return None;
    }
    let shift_mm = max_corner_shift_mm(views, &before, &after);
    if shift_mm < cfg.moved_min_shift_mm {
        return None;
    }
    let worst_px = views[split..]
        .iter()
        .flat_map(|v| {
            let from_body = v.camera_from_world * v.world_from_group * joint;
            v.corners.iter().map(move |(pb, px, _)| {
                camera
                    .project(from_body.transform_point(*pb))
                    .map_or(f64::INFINITY, |q| q.distance(*px))
            })
        })
        .fold(0.0, f64::max);
    Some(ChangePoint {
        split,
        chi2,
        shift_mm,
        worst_px,
    })
}

/// The reference targets that serve the flash alone. No measurement or standard image sees
/// them, so no camera or head pose of the measurement rests on them; they place the
/// light-position cameras, hence the flash, and nothing else. They are those the light-position
/// images see (the flash stand's panel) and those seen in an image (a link shot) together with
/// one of these (a relay's targets that the shots from behind it frame with the panel). Each is
/// held to the flash's bound, not the reference structure's. Returns them, and those of the
/// first kind.
fn flash_only_ids(
    file: &SessionFile,
    obs: &[HashMap<u32, Obs>],
    reference: &HashSet<u32>,
) -> (HashSet<u32>, HashSet<u32>) {
    let measured: HashSet<u32> = file
        .images
        .iter()
        .zip(obs)
        .filter(|(e, _)| !matches!(e.role, ImageRole::LightPosition | ImageRole::Survey))
        .flat_map(|(_, o)| o.keys().copied())
        .collect();
    let unmeasured = |id: &u32| reference.contains(id) && !measured.contains(id);
    let lit: HashSet<u32> = file
        .images
        .iter()
        .zip(obs)
        .filter(|(e, _)| e.role == ImageRole::LightPosition)
        .flat_map(|(_, o)| o.keys().copied().filter(|id| unmeasured(id)))
        .collect();
    // One step only: a target seen with the cage's and not with the panel's is, from the
    // images alone, no different from a cage target that only survey shots see.
    let links = obs
        .iter()
        .filter(|o| o.keys().any(|id| lit.contains(id)))
        .flat_map(|o| o.keys().copied().filter(|id| unmeasured(id)));
    let all = lit.iter().copied().chain(links).collect();
    (all, lit)
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
    /// The registration's own uncertainty (`frame_sd`) is added to every headdress target's:
    /// at a target a distance `d` from the targets' centroid, `sd² + (d σ_rot)²` to its
    /// position and `σ_rot²` to its orientation, so the gauge target (held at the identity in
    /// the survey, its sigma zero there) states the registration's error.
    ///
    /// `scale` is a similarity's scale (1 for a rigid registration): a point `x` of the
    /// provisional frame goes to `R (scale x) + t`, and the headdress targets' sizes (and its
    /// sheets' print scales) grow by it.
    pub fn transform_head(
        &mut self,
        head_from_provisional: &Pose,
        scale: f64,
        method: &str,
        frame_sd: &FrameUncertainty,
    ) {
        let map = |c: DVec3| head_from_provisional.transform_point(c * scale);
        let mut centres = Vec::new();
        for t in &mut self.targets {
            if t.group == TargetGroup::Headdress {
                t.corners_m = t.corners_m.map(map);
                t.size_m *= scale;
                centres.push(t.corners_m.iter().copied().sum::<DVec3>() * 0.25);
            }
        }
        let centroid = centres.iter().copied().sum::<DVec3>() / centres.len().max(1) as f64;
        let rot_rad = frame_sd.rotation_sd_deg.to_radians();
        for t in &mut self.targets {
            if t.group == TargetGroup::Headdress {
                let c = t.corners_m.iter().copied().sum::<DVec3>() * 0.25;
                let lever_mm = c.distance(centroid) * 1e3;
                t.position_sigma_mm = (t.position_sigma_mm.powi(2)
                    + frame_sd.centroid_sd_mm.powi(2)
                    + (lever_mm * rot_rad).powi(2))
                .sqrt();
                t.orientation_sigma_deg =
                    (t.orientation_sigma_deg.powi(2) + frame_sd.rotation_sd_deg.powi(2)).sqrt();
            }
        }
        for s in &mut self.sheets {
            if s.group == TargetGroup::Headdress {
                s.group_from_sheet = Pose::new(
                    head_from_provisional.rotation * s.group_from_sheet.rotation,
                    map(s.group_from_sheet.translation_m),
                );
                s.print_scale *= scale;
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
    /// place or left out are dropped from the session (listed in [`Survey::issues`]). A camera
    /// still to be calibrated keeps that status, with the focal length the survey's adjustment
    /// refined as its guess: the pose stage's calibration refines the survey's, it does not
    /// start again.
    pub fn apply_to(&self, file: &mut SessionFile) {
        if let CameraSpec::ToBeCalibrated { focal_guess_px, .. } = &mut file.camera {
            *focal_guess_px = Some(self.camera.fx_px);
        }
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
    ///
    /// A sheet found not rigid is no longer listed as a sheet: its targets become cut-outs,
    /// placed where the survey put them (or unplaced when it could not).
    pub fn placed_rig(&self, rig: &RigFile) -> RigFile {
        let mut out = rig.clone();
        for issue in &self.issues {
            let SurveyIssue::NotRigid { sheet, targets, .. } = issue else {
                continue;
            };
            let Some(at) = out.sheets.iter().position(|s| &s.name == sheet) else {
                continue;
            };
            let group = out.sheets[at].group;
            out.sheets.remove(at);
            for &(id, size_m) in targets {
                out.targets.retain(|t| t.id != id);
                out.targets.push(RigTarget {
                    id,
                    size_m,
                    group,
                    sheet: None,
                    corners_m: None,
                });
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Views of one 35 mm target at the origin (facing +y) from cameras on a 2 m arc, with
    /// Gaussian corner noise of `sigma_px`; from view `moved_from` on, the target is displaced
    /// by `shift_m`.
    fn arc_views(n: usize, moved_from: usize, shift_m: DVec3, sigma_px: f64) -> Vec<BodyView> {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        let corners = tag_corners(0.035);
        // Face +y: the tag's z (into the surface) is −y.
        let group_from_body = Pose::new(
            DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2),
            DVec3::ZERO,
        );
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        (0..n)
            .map(|i| {
                let az = (-40.0 + 80.0 * i as f64 / (n - 1) as f64).to_radians();
                let eye = DVec3::new(2.0 * az.sin(), 2.0 * az.cos(), 0.1);
                let world_from_camera =
                    Pose::look_at(eye, DVec3::ZERO, DVec3::Z).expect("camera pose");
                let shift = if i >= moved_from {
                    shift_m
                } else {
                    DVec3::ZERO
                };
                let camera_from_world = world_from_camera.inverse();
                let pts = corners
                    .iter()
                    .map(|&pb| {
                        let w = group_from_body.transform_point(pb) + shift;
                        let px = camera
                            .project(camera_from_world.transform_point(w))
                            .expect("in view");
                        let noise =
                            DVec2::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5)
                                * (sigma_px * 12f64.sqrt());
                        (pb, px + noise, sigma_px)
                    })
                    .collect();
                BodyView {
                    image: i,
                    world_from_group: Pose::IDENTITY,
                    camera_from_world,
                    corners: pts,
                }
            })
            .collect()
    }

    /// A whole detection with these corners and corner sigma (its side as the detector's).
    fn seen(corners_px: [DVec2; 4], sigma_px: f64) -> Obs {
        let side_px = (0..4)
            .map(|k| corners_px[k].distance(corners_px[(k + 1) % 4]))
            .sum::<f64>()
            / 4.0;
        Obs {
            corners_px,
            sigma_px: [sigma_px; 4],
            occluded: [false; 4],
            side_px,
        }
    }

    /// A 21 mm target 2.5 m from cameras spread over `spread_deg` of azimuth, seen about 20 px
    /// across at 762 px and 16 deg: its observations and cameras for [`triangulated_pose`].
    #[allow(clippy::type_complexity)]
    fn small_tag_views(
        spread_deg: f64,
        sigma_px: f64,
    ) -> (
        BodyDef,
        Pose,
        Vec<Option<Pose>>,
        Vec<HashMap<u32, Obs>>,
        CameraModel,
    ) {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        let corners = tag_corners(0.021);
        let def = BodyDef {
            group: TargetGroup::Reference,
            sheet: None,
            members: vec![(7, 0.021, corners)],
        };
        let truth = Pose::new(
            DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2) * DQuat::from_rotation_y(0.3),
            DVec3::new(0.1, -0.05, 0.2),
        );
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (mut gfc, mut obs) = (Vec::new(), Vec::new());
        for i in 0..4 {
            let az = (-0.5 * spread_deg + spread_deg * f64::from(i) / 3.0).to_radians();
            let eye = truth.translation_m + DVec3::new(2.5 * az.sin(), 2.5 * az.cos(), 0.2);
            let wc = Pose::look_at(eye, truth.translation_m, DVec3::Z).expect("camera");
            let cw = wc.inverse();
            let mut px = [DVec2::ZERO; 4];
            for (k, p) in px.iter_mut().enumerate() {
                let noise = DVec2::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5)
                    * (sigma_px * 12f64.sqrt());
                *p = camera
                    .project(cw.transform_point(truth.transform_point(corners[k])))
                    .expect("in view")
                    + noise;
            }
            gfc.push(Some(wc));
            obs.push(HashMap::from([(7, seen(px, sigma_px))]));
        }
        (def, truth, gfc, obs, camera)
    }

    #[test]
    fn a_small_tag_is_placed_from_its_triangulated_corners() {
        // Exact corners: the pose itself.
        let (def, truth, gfc, obs, camera) = small_tag_views(40.0, 0.0);
        let p = triangulated_pose(&def, &[0, 1, 2, 3], &gfc, &obs, &camera).expect("placed");
        assert!(p.translation_m.distance(truth.translation_m) < 1e-9);
        assert!(angle_deg(p.rotation, truth.rotation) < 1e-6);
        // Corner noise of 0.1 px: millimetres and a few degrees, where single views of a 20 px
        // tag scatter by tens of degrees.
        let (def, truth, gfc, obs, camera) = small_tag_views(40.0, 0.1);
        let p = triangulated_pose(&def, &[0, 1, 2, 3], &gfc, &obs, &camera).expect("placed");
        let e_mm = p.translation_m.distance(truth.translation_m) * 1e3;
        let e_deg = angle_deg(p.rotation, truth.rotation);
        assert!(e_mm < 2.0 && e_deg < 10.0, "{e_mm} mm, {e_deg} deg");
    }

    #[test]
    fn a_tag_seen_from_one_direction_or_in_a_sheet_is_not_triangulated() {
        // Rays under 5 deg apart: the depth would rest on the tag's size.
        let (def, _, gfc, obs, camera) = small_tag_views(3.0, 0.1);
        assert!(triangulated_pose(&def, &[0, 1, 2, 3], &gfc, &obs, &camera).is_none());
        // One view.
        let (def, _, gfc, obs, camera) = small_tag_views(40.0, 0.1);
        assert!(triangulated_pose(&def, &[2], &gfc, &obs, &camera).is_none());
        // The triangulated square is not the printed one (a 21 mm tag taken for 35 mm).
        let mut wrong = def.clone();
        wrong.members[0] = (7, 0.035, tag_corners(0.035));
        assert!(triangulated_pose(&wrong, &[0, 1, 2, 3], &gfc, &obs, &camera).is_none());
        // A body of two targets keeps the single-view mean.
        let mut sheet = def.clone();
        sheet.members.push((8, 0.021, tag_corners(0.021)));
        assert!(triangulated_pose(&sheet, &[0, 1, 2, 3], &gfc, &obs, &camera).is_none());
    }

    fn placed() -> Pose {
        Pose::new(
            DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2),
            DVec3::ZERO,
        )
    }

    /// A sheet of three 35 mm targets in a row (layout frame: x right, y up, z out of the
    /// paper), the first one folded back by `fold_deg` about the line half-way to the second.
    fn sheet(fold_deg: f64) -> (BodyDef, Vec<[DVec3; 4]>) {
        let h = 0.0175;
        let layout: Vec<[DVec3; 4]> = [-0.05, 0.0, 0.05]
            .iter()
            .map(|&x| {
                [
                    DVec3::new(x - h, -h, 0.0),
                    DVec3::new(x + h, -h, 0.0),
                    DVec3::new(x + h, h, 0.0),
                    DVec3::new(x - h, h, 0.0),
                ]
            })
            .collect();
        let fold = DQuat::from_rotation_y(fold_deg.to_radians());
        let hinge = DVec3::new(-0.025, 0.0, 0.0);
        let mut truth = layout.clone();
        truth[0] = truth[0].map(|p| hinge + fold * (p - hinge));
        let def = BodyDef {
            group: TargetGroup::Reference,
            sheet: Some("strip".into()),
            members: layout
                .iter()
                .enumerate()
                .map(|(k, c)| (k as u32, 0.035, *c))
                .collect(),
        };
        (def, truth)
    }

    /// Observations of the true sheet (facing +y at the origin) from six cameras on a 2 m arc.
    fn sheet_views(truth: &[[DVec3; 4]]) -> Vec<HashMap<u32, Obs>> {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        let world_from_sheet = Pose::new(
            DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2),
            DVec3::ZERO,
        );
        (0..6)
            .map(|i| {
                let az = (-40.0 + 16.0 * i as f64).to_radians();
                let eye = DVec3::new(2.0 * az.sin(), 2.0 * az.cos(), 0.2);
                let camera_from_world = Pose::look_at(eye, DVec3::ZERO, DVec3::Z)
                    .expect("camera")
                    .inverse();
                truth
                    .iter()
                    .enumerate()
                    .map(|(k, c)| {
                        let corners_px = c.map(|p| {
                            camera
                                .project(
                                    camera_from_world
                                        .transform_point(world_from_sheet.transform_point(p)),
                                )
                                .expect("in view")
                        });
                        (k as u32, seen(corners_px, 0.08))
                    })
                    .collect()
            })
            .collect()
    }

    /// A 35 mm target facing +y with its centre at `c` (world frame, session corner order).
    fn facing_y(c: DVec3) -> [DVec3; 4] {
        let h = 0.0175;
        // Tag frame (seen from +y): x right = −x, y down = −z, z into the surface = −y.
        [
            c + DVec3::new(h, 0.0, -h),
            c + DVec3::new(-h, 0.0, -h),
            c + DVec3::new(-h, 0.0, h),
            c + DVec3::new(h, 0.0, h),
        ]
    }

    /// Eight views on a 2 m arc of two placed targets and of target 7, which views `0..split`
    /// see at `a` and the others at `b` (never both in one image).
    fn two_place_views(
        a: DVec3,
        b: DVec3,
        split: usize,
    ) -> (GroupInitData, Vec<HashMap<u32, Obs>>) {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        let placed: HashMap<u32, [DVec3; 4]> = [
            (1, facing_y(DVec3::new(-0.12, 0.0, 0.0))),
            (2, facing_y(DVec3::new(0.12, 0.0, 0.06))),
        ]
        .into_iter()
        .collect();
        let obs = (0..8)
            .map(|i| {
                let az = (-30.0 + 8.0 * i as f64).to_radians();
                let eye = DVec3::new(2.0 * az.sin(), 2.0 * az.cos(), 0.1);
                let cw = Pose::look_at(eye, DVec3::ZERO, DVec3::Z)
                    .expect("camera")
                    .inverse();
                let see = |c: &[DVec3; 4]| {
                    seen(
                        c.map(|p| camera.project(cw.transform_point(p)).expect("in view")),
                        0.08,
                    )
                };
                let mut o: HashMap<u32, Obs> = placed.iter().map(|(id, c)| (*id, see(c))).collect();
                let at = if i < split { a } else { b };
                o.insert(7, see(&facing_y(at)));
                o
            })
            .collect();
        (
            GroupInitData {
                placed,
                defs: vec![BodyDef {
                    group: TargetGroup::Reference,
                    sheet: None,
                    members: vec![(7, 0.035, tag_corners(0.035))],
                }],
            },
            obs,
        )
    }

    struct GroupInitData {
        placed: HashMap<u32, [DVec3; 4]>,
        defs: Vec<BodyDef>,
    }

    fn init_one(
        data: &GroupInitData,
        obs: &[HashMap<u32, Obs>],
    ) -> (Option<Pose>, Vec<SurveyIssue>) {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        let g = GroupInit {
            placed: data.placed.clone(),
            bodies: vec![0],
            defs: &data.defs,
        };
        let names: Vec<String> = (0..obs.len()).map(|i| format!("m{i:02}")).collect();
        let mut pose = vec![None];
        let mut issues = Vec::new();
        init_group(
            &g,
            obs,
            &names,
            &camera,
            &SurveyConfig::DEFAULT,
            &mut pose,
            &mut issues,
        );
        (pose[0], issues)
    }

    #[test]
    fn an_id_seen_at_two_places_is_named_and_not_placed() {
        let a = DVec3::new(0.0, 0.0, 0.09);
        let (data, obs) = two_place_views(a, DVec3::new(0.0, 0.0, -0.09), 4);
        let (pose, issues) = init_one(&data, &obs);
        assert!(pose.is_none(), "placed anyway: {pose:?}");
        let Some(SurveyIssue::TwoPlaces {
            id,
            apart_mm,
            first,
            second,
        }) = issues.first()
        else {
            panic!("{issues:?}");
        };
        assert_eq!(*id, 7);
        assert!((apart_mm - 180.0).abs() < 5.0, "{apart_mm}");
        assert_eq!(first.len() + second.len(), 8);
        // At one place only, it is placed there.
        let (data, obs) = two_place_views(a, a, 4);
        let (pose, issues) = init_one(&data, &obs);
        assert!(issues.is_empty(), "{issues:?}");
        let placed = pose.expect("placed");
        assert!(placed.translation_m.distance(a) < 0.005, "{placed:?}");
    }

    #[test]
    fn a_flat_sheet_is_rigid_and_a_folded_one_is_not() {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        let (def, truth) = sheet(0.0);
        let obs = sheet_views(&truth);
        assert!(single_view_rigidity(&def, &obs, &camera, &SurveyConfig::DEFAULT).is_none());
        let (def, truth) = sheet(25.0);
        let obs = sheet_views(&truth);
        let found = single_view_rigidity(&def, &obs, &camera, &SurveyConfig::DEFAULT)
            .expect("the fold is found");
        let SurveyIssue::NotRigid { sheet, targets, .. } = &found else {
            panic!("{found:?}");
        };
        assert_eq!(sheet, "strip");
        assert_eq!(targets.len(), 3);
    }

    #[test]
    fn a_sheet_found_bent_is_written_back_as_cut_outs() {
        use skinbrdf_session::rig::RigSheet;
        let rig = RigFile {
            sheets: vec![RigSheet {
                name: "strip".into(),
                group: TargetGroup::Reference,
                layout: Some("strip.layout.toml".into()),
                group_from_sheet: None,
                print_scale: None,
            }],
            format_version: skinbrdf_session::RIG_FORMAT_VERSION,
            description: String::new(),
            family: "tag36h11".into(),
            targets: Vec::new(),
            flash: skinbrdf_session::rig::RigFlash {
                diameter_m: 0.082,
                light_centre_m: DVec3::ZERO,
                light_position_m: None,
                world_from_flash: None,
            },
            standard: None,
            camera: None,
            roi: None,
            geometry: None,
        };
        let corners = tag_corners(0.035);
        let survey = Survey {
            targets: vec![SurveyedTarget {
                id: 1,
                group: TargetGroup::Reference,
                sheet: None,
                size_m: 0.035,
                corners_m: corners,
                position_sigma_mm: 0.05,
                orientation_sigma_deg: 0.05,
                views: 6,
                flash_only: false,
                light_position: false,
                rms_px: 0.1,
                variance_ratio: 1.0,
            }],
            sheets: Vec::new(),
            issues: vec![SurveyIssue::NotRigid {
                sheet: "strip".into(),
                targets: vec![(0, 0.035), (1, 0.035)],
                worst_px: Some(5.0),
                variance_ratio: None,
            }],
            head_gauge: HeadGauge::None,
            camera: CameraModel::from_fov(762, 506, 0.3),
            bundle: crate::bundle::BundleReport::default(),
            bodies: 1,
            images_used: 6,
            survey_images_used: 0,
            timing: SurveyTiming::default(),
            intrinsics_restart: false,
        };
        let out = survey.placed_rig(&rig);
        assert!(out.sheets.is_empty());
        let placed: Vec<_> = out
            .targets
            .iter()
            .map(|t| (t.id, t.corners_m.is_some()))
            .collect();
        assert_eq!(placed, vec![(0, false), (1, true)]);
    }

    #[test]
    fn a_target_moved_half_way_is_found_at_its_move() {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        // 1 mm sideways after the sixth of twelve views: about 1.4 px at 2 m.
        let views = arc_views(12, 6, DVec3::new(0.001, 0.0, 0.0), 0.08);
        let cp = change_point(&camera, &views, &placed(), 1.0, &SurveyConfig::DEFAULT)
            .expect("the move is found");
        assert_eq!(cp.split, 6);
        assert!((cp.shift_mm - 1.0).abs() < 0.3, "{cp:?}");
    }

    #[test]
    fn a_target_that_stayed_is_not_named_moved() {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        let views = arc_views(12, 12, DVec3::ZERO, 0.08);
        assert!(change_point(&camera, &views, &placed(), 1.0, &SurveyConfig::DEFAULT).is_none());
    }

    #[test]
    fn one_bad_view_is_not_a_move() {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        let mut views = arc_views(12, 12, DVec3::ZERO, 0.08);
        // One side of the third view off by 2 px (a corner pair hidden but not marked).
        for c in &mut views[2].corners[1..3] {
            c.1 += DVec2::new(2.0, 0.0);
        }
        assert!(change_point(&camera, &views, &placed(), 1.0, &SurveyConfig::DEFAULT).is_none());
    }

    #[test]
    fn a_move_below_the_accuracy_target_is_not_named() {
        let camera = CameraModel::from_fov(762, 506, 16f64.to_radians());
        let views = arc_views(12, 6, DVec3::new(0.0001, 0.0, 0.0), 0.02);
        assert!(change_point(&camera, &views, &placed(), 1.0, &SurveyConfig::DEFAULT).is_none());
    }
}
