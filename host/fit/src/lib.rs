//! Local quadratic regression smoothing, nonlinear least-squares BRDF fitting, polar plots and
//! renderings.
//!
//! * [`lm`]: a bounded, parallel Levenberg-Marquardt solver forming `J^T J` directly.
//! * [`fit`]: multi-start per-channel model fits with uncertainties ([`fit_rgb`]).
//! * [`loess`]: local quadratic regression with confidence bands, parity-tested against netlib.
//! * [`plot`]: polar / scatter / overlay figures in PNG and SVG, and the session-difference test.
//! * [`report`]: the `skinbrdf fit` / `compare` work (inputs, outputs, Markdown report).
//! * [`export`]: MERL binary tables and Cornell `.brdf` files of fitted models.

pub mod export;
pub mod fit;
pub mod lm;
pub mod loess;
pub mod plot;
pub mod report;
pub mod synthetic;

pub use fit::{fit_data, fit_rgb, ChannelFit, ErrorMetrics, FitConfig, FitData, FitError, RgbFit};
pub use lm::{LmConfig, LmStatus, ResidualKind};
