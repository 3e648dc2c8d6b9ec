//! Photogrammetry: camera calibration, PnP with RANSAC, Levenberg-Marquardt pose refinement,
//! flash triangulation, and the per-session pose estimate.
//!
//! * [`pnp::estimate_pose`]: a camera pose from known 3D points, with covariance and diagnostics.
//! * [`calib::calibrate`]: intrinsics and distortion by bundle adjustment over several views.
//! * [`session::estimate_session`]: every pose of a session (camera per image, head per
//!   measurement image, flash, reference standard), the entry point of the pipeline.
//! * [`lm`]: the dense robust Levenberg-Marquardt solver they share.
//! * [`bundle::bundle_adjust`]: the joint, block-sparse, robust bundle adjustment over the
//!   whole session that [`session::estimate_session`] ends with.
//! * [`survey::survey`]: the placements of targets nobody measured, estimated with every pose
//!   by the same adjustment.

pub mod bundle;
pub mod calib;
pub mod error;
pub mod geometry;
pub mod lm;
pub mod pnp;
pub mod session;
pub mod survey;

pub use bundle::{BundleConfig, BundleReport, RobustLoss};
pub use error::{Diagnostic, PoseError};
pub use pnp::{estimate_pose, PnpConfig, PointObs, PoseEstimate};
pub use session::{
    estimate_session, estimate_session_detected, LightAgreement, PoseConfig, SessionDetections,
    SessionPoses,
};
pub use survey::{
    survey, survey_detected, FrameUncertainty, HeadGauge, Survey, SurveyConfig, SurveyIssue,
};
