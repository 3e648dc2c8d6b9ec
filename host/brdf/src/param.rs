//! The fitting interface: one scalar channel of a model as a function of a parameter vector,
//! with bounds and analytic derivatives.
//!
//! Every model here is fitted per RGB channel (the channels share the angles, not the
//! parameters), so a [`ChannelModel`] maps `(params, geometry)` to one reflectance value in 1/sr
//! and its gradient. Parametrisations are chosen for conditioning (log exponents, log lobe
//! albedos, lobe shape separated from lobe magnitude); see each model's docs.

use crate::{BrdfError, BrdfModel, Geom};

/// Closed parameter interval `[lo, hi]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamBound {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
}

impl ParamBound {
    /// A bound.
    pub const fn new(lo: f64, hi: f64) -> Self {
        Self { lo, hi }
    }

    /// Clamps a value into the bound.
    pub fn clamp(&self, v: f64) -> f64 {
        v.clamp(self.lo, self.hi)
    }
}

/// Rough levels of the data a model starts from: used to derive starting points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartHint {
    /// A typical off-peak (diffuse) reflectance, 1/sr (e.g. a low quantile of the samples).
    pub diffuse_rho: f64,
    /// The largest reflectance seen, 1/sr.
    pub peak_rho: f64,
}

/// One channel of a parametric BRDF model.
pub trait ChannelModel: Send + Sync + std::fmt::Debug {
    /// Short name (`lafortune2`, ...).
    fn name(&self) -> String;
    /// Parameters per channel.
    fn n_params(&self) -> usize;
    /// Parameter names, in order.
    fn param_names(&self) -> Vec<String>;
    /// Parameter bounds, in order.
    fn bounds(&self) -> Vec<ParamBound>;
    /// Reflectance (1/sr) of one channel.
    fn eval(&self, p: &[f64], g: &Geom) -> f64;
    /// Reflectance and its gradient with respect to `p` (written into `grad`, length
    /// [`n_params`](Self::n_params)).
    fn eval_grad(&self, p: &[f64], g: &Geom, grad: &mut [f64]) -> f64;
    /// Several starting points inside the bounds for a multi-start fit.
    fn starting_points(&self, hint: &StartHint) -> Vec<Vec<f64>>;
    /// The serialisable model of three fitted channels.
    fn to_model(&self, params: &[Vec<f64>; 3]) -> Result<BrdfModel, BrdfError>;
    /// The parameters of one channel of a model of this kind, if it is of this kind.
    fn params_from_model(&self, model: &BrdfModel, channel: usize) -> Option<Vec<f64>>;
}

/// Checks a parameter vector's length.
pub(crate) fn check_len(m: &dyn ChannelModel, p: &[f64]) -> Result<(), BrdfError> {
    if p.len() == m.n_params() {
        Ok(())
    } else {
        Err(BrdfError::ParamCount {
            model: m.name(),
            expected: m.n_params(),
            found: p.len(),
        })
    }
}

/// Which model to fit, as named on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelSpec {
    /// [`crate::LambertianFit`].
    Lambertian,
    /// [`crate::LafortuneFit`] with 1 to 3 forward/retro/off-specular lobes.
    Lafortune {
        /// Number of lobes (1..=3).
        lobes: usize,
    },
    /// [`crate::CookTorranceFit`] (GGX, dielectric Fresnel).
    CookTorrance,
}

impl std::str::FromStr for ModelSpec {
    type Err = BrdfError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "lambertian" => Ok(Self::Lambertian),
            "lafortune1" => Ok(Self::Lafortune { lobes: 1 }),
            "lafortune2" | "lafortune" => Ok(Self::Lafortune { lobes: 2 }),
            "lafortune3" => Ok(Self::Lafortune { lobes: 3 }),
            "cook-torrance" | "cook_torrance" | "ggx" => Ok(Self::CookTorrance),
            _ => Err(BrdfError::UnknownModel(s.to_owned())),
        }
    }
}

impl std::fmt::Display for ModelSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Lambertian => write!(f, "lambertian"),
            Self::Lafortune { lobes } => write!(f, "lafortune{lobes}"),
            Self::CookTorrance => write!(f, "cook-torrance"),
        }
    }
}

impl ModelSpec {
    /// The channel model to fit.
    pub fn channel_model(&self) -> Box<dyn ChannelModel> {
        match *self {
            Self::Lambertian => Box::new(crate::LambertianFit),
            Self::Lafortune { lobes } => Box::new(crate::LafortuneFit::standard(lobes.clamp(1, 3))),
            Self::CookTorrance => Box::new(crate::CookTorranceFit::default()),
        }
    }
}
