//! From the camera's card to a session.
//!
//! * [`matching`]: which camera file is which of the controller's exposures, by time (the camera
//!   clock's offset and drift estimated by a monotone alignment), with test shots, missing files,
//!   duplicates and other bodies reported by name and ambiguous cases refused.
//! * [`mod@ingest`]: the card, the capture record, the rig file and the scan to a session
//!   directory (`skinbrdf ingest`); see `docs/ingest.md`.
//! * [`focal`]: a camera to be calibrated starts where the lens is: the focal length in the
//!   session's pixels from the photographs' metadata.

pub mod focal;
pub mod ingest;
pub mod matching;

pub use ingest::{
    ingest, read_camera, read_capture, ExposurePolicy, IngestConfig, IngestError, IngestReport,
};
