//! Local quadratic regression smoothing, nonlinear least-squares BRDF fitting, polar plots and
//! renderings.
//!
//! One module per stage of the pipeline's plan, each a pure function over domain types with a
//! typed result that carries its own run time and metrics:
//!
//! * [`smooth`] (`SmoothIncidencePlane`, `SmoothHemisphere`): [`smooth::smooth`] →
//!   [`smooth::Smoothed`].
//! * [`fit`] (`Fit`): [`fit::fit_model`] → [`fit::Fitted`]; multi-start per-channel model fits
//!   with uncertainties ([`fit_rgb`]) on the [`lm`] solver.
//! * [`score`]: [`score::score_against_truth`] → [`score::TruthScore`] (synthetic sessions).
//! * [`figures`] (`Report`): [`figures::write_figures`] → [`figures::Figures`], drawn by [`plot`].
//! * [`export`] (`Report`): [`export::export`] → [`export::Exported`] (Cornell `.brdf`, MERL).
//! * [`report`] (`Report`): [`report::FitReport`], `params.json` and `report.md`
//!   ([`report::write_report`]), and [`report::fit_and_report`] composing all of the above.
//!
//! Also: [`loess`] (the smoother, parity-tested against netlib), [`input`] (loading samples,
//! Cornell files and sessions), [`compare`] (the session-difference test).

pub mod compare;
pub mod export;
pub mod figures;
pub mod fit;
pub mod input;
pub mod lm;
pub mod loess;
pub mod plot;
pub mod report;
pub mod score;
pub mod smooth;
pub mod synthetic;

pub use fit::{
    fit_data, fit_model, fit_rgb, ChannelFit, ErrorMetrics, FitConfig, FitData, FitError,
    FitStageKind, Fitted, RgbFit,
};
pub use lm::{LmConfig, LmStatus, ResidualKind};
