//! The planned processing pipeline.
//!
//! `skinbrdf process SESSION_DIR` runs photogrammetry, derendering, smoothing and fitting. What
//! it runs is derived from the scene (see [`plan`]): a stage whose result the session already
//! has, or whose effect cannot occur in this scene, is skipped, and the plan says why. Stages
//! whose inputs have not changed since the last run are reused (see [`ledger`]). Every stage
//! that runs reports its accuracy and its cost (see [`report`]).

pub mod bench;
pub mod checks;
pub mod demo;
pub mod derender_request;
pub mod ledger;
pub mod metrics;
pub mod plan;
pub mod pose_inputs;
pub mod process;
pub mod report;
pub mod scenes;
pub mod stages;
pub mod survey;

pub use ledger::{Fingerprint, Ledger, LedgerError, RunLock, Unit};
pub use metrics::StageMetrics;
pub use plan::{Action, Geometry, Plan, PlanOptions, PlannedStage, SceneFacts, Stage};
pub use process::{process, Event, ProcessConfig, ProcessError, ProcessOutput};
pub use report::{Metric, RunReport, StageReport};
