//! Local quadratic regression smoothing, nonlinear least-squares BRDF fitting, polar plots and
//! renderings.
//!
//! * [`lm`]: a bounded, parallel Levenberg-Marquardt solver forming `J^T J` directly.
//! * [`fit`]: multi-start per-channel model fits with uncertainties ([`fit_rgb`]).

pub mod fit;
pub mod lm;
pub mod loess;

pub use fit::{fit_data, fit_rgb, ChannelFit, ErrorMetrics, FitConfig, FitData, FitError, RgbFit};
pub use lm::{LmConfig, LmStatus, ResidualKind};
