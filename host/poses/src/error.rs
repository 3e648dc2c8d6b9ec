//! Typed failures and warnings of pose estimation.

use serde::{Deserialize, Serialize};

/// A pose could not be estimated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseError {
    /// A camera to be calibrated has no starting focal length and none can be found.
    #[error(
        "no starting focal length for the camera to be calibrated: {why}; state the lens \
         (`focal_guess_px` under [camera] in session.toml, or `--camera` at ingest)"
    )]
    NoFocalStart {
        /// Why none was found.
        why: &'static str,
    },
    /// Not enough targets or points were seen.
    #[error("too few targets: {found} targets ({points} points) found, {needed} needed")]
    TooFewTargets {
        /// Targets found.
        found: usize,
        /// Points found.
        points: usize,
        /// Targets needed.
        needed: usize,
    },
    /// The configuration does not determine the unknowns.
    #[error("degenerate configuration: {what} (measure {measure:.3e})")]
    Degenerate {
        /// What is degenerate.
        what: &'static str,
        /// The measure (e.g. ratio of singular values).
        measure: f64,
    },
    /// The normal equations are too ill-conditioned to trust the solution.
    #[error("ill-conditioned estimate: condition number {condition_number:.3e}")]
    IllConditioned {
        /// Condition number of the column-scaled normal matrix.
        condition_number: f64,
    },
    /// No hypothesis explained the observations.
    #[error("no consistent pose among {targets} targets")]
    NoConsensus {
        /// Targets tried.
        targets: usize,
    },
    /// The survey has unplaced reference targets but no placed one to fix the world frame.
    #[error(
        "the placement survey needs the world's origin: give the corners of at least one \
         reference target (or a reference sheet's placement) in the rig"
    )]
    SurveyGauge,
    /// The survey places reference and headdress targets only.
    #[error(
        "target {id} of the {group} group has no placement: flash and standard targets are \
         placed by their printed layouts (give their corners in the rig)"
    )]
    SurveyUnsupported {
        /// The target.
        id: u32,
        /// Its group's name.
        group: &'static str,
    },
    /// The session still has unplaced reference or headdress targets.
    #[error(
        "{targets} reference or headdress target(s) have no placement: run the placement \
         survey first (`skinbrdf survey SESSION`, or `skinbrdf process`, which plans it)"
    )]
    Unsurveyed {
        /// How many.
        targets: usize,
    },
    /// The survey's adjustment had nothing to adjust or a singular normal matrix.
    #[error(
        "the placement survey's adjustment is singular: {}",
        match start_focal_px {
            Some(f) => format!(
                "the camera is to be calibrated and, from the starting focal length {f:.0} px, \
                 the images do not agree on the targets' places; state the lens's focal length \
                 (`focal_guess_px` under [camera], or `--camera` at ingest), or check the one \
                 stated"
            ),
            None => "too few images see the targets".to_string(),
        }
    )]
    SurveySingular {
        /// The starting focal length, px, when the camera is to be calibrated.
        start_focal_px: Option<f64>,
    },
    /// An image could not be read.
    #[error("image {file}: {problem}")]
    Image {
        /// The file.
        file: String,
        /// What went wrong.
        problem: String,
    },
}

/// A warning attached to an estimate (the estimate is still returned).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum Diagnostic {
    /// A target is seen at a grazing angle (angle between its normal and the view direction).
    GrazingTarget {
        /// Tag ID.
        target: u32,
        /// Angle, degrees.
        angle_deg: f64,
        /// Whether it was still used.
        used: bool,
    },
    /// Targets whose corners disagree with the consensus were dropped.
    OutlierTargets {
        /// Tag IDs.
        targets: Vec<u32>,
    },
    /// The normal matrix is poorly conditioned (near-planar / near-collinear / small field).
    IllConditioned {
        /// Condition number.
        condition_number: f64,
    },
    /// Only one target was used: its pose may be ambiguous (planar flip).
    SingleTarget,
    /// The points are nearly collinear (second singular value of the centred points over the
    /// first): the rotation about their line is weakly determined.
    NearCollinear {
        /// The spread ratio (collinear = 0; refused below `pnp::COLLINEAR_RATIO`).
        spread_ratio: f64,
    },
    /// A detected target is partly hidden: these corners (in the layout's corner order) were
    /// marked occluded by the detector (`Detection::occluded_corners`) and not used; its other
    /// corners were.
    OccludedCorners {
        /// Tag ID.
        target: u32,
        /// Indices of the corners left out (0..4).
        corners: Vec<usize>,
    },
    /// A stage was skipped because the session gives the quantity.
    Skipped {
        /// What was skipped and why.
        reason: String,
    },
}

impl std::fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let list = |v: &[String]| v.join(", ");
        match self {
            Self::GrazingTarget {
                target,
                angle_deg,
                used,
            } => write!(
                f,
                "target {target} seen at {angle_deg:.1} degrees from its normal ({})",
                if *used { "used" } else { "not used" }
            ),
            Self::OutlierTargets { targets } => write!(
                f,
                "target(s) {} disagree with the others and were left out",
                list(&targets.iter().map(u32::to_string).collect::<Vec<_>>())
            ),
            Self::IllConditioned { condition_number } => write!(
                f,
                "poorly conditioned (condition number {condition_number:.3e}): the targets are \
                 nearly planar, collinear or small in the field"
            ),
            Self::SingleTarget => write!(
                f,
                "one target only: its pose may be ambiguous (a planar flip)"
            ),
            Self::NearCollinear { spread_ratio } => write!(
                f,
                "the points are nearly collinear (spread ratio {spread_ratio:.3}): the rotation \
                 about their line is weakly determined"
            ),
            Self::OccludedCorners { target, corners } => write!(
                f,
                "target {target}: corner(s) {} partly hidden and not used",
                list(&corners.iter().map(usize::to_string).collect::<Vec<_>>())
            ),
            Self::Skipped { reason } => write!(f, "skipped: {reason}"),
        }
    }
}
