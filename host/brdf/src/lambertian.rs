//! The Lambertian model as a fittable channel: `rho = albedo / pi`, one parameter.

use crate::param::check_len;
use crate::{BrdfError, BrdfModel, ChannelModel, Geom, ParamBound, StartHint};

/// Upper albedo bound: physical albedo is at most 1; the slack absorbs calibration error.
pub const MAX_ALBEDO: f64 = 1.5;

/// Fittable Lambertian channel. Parameter: `[albedo]`.
#[derive(Debug, Clone, Copy, Default)]
pub struct LambertianFit;

impl ChannelModel for LambertianFit {
    fn name(&self) -> String {
        "lambertian".into()
    }
    fn n_params(&self) -> usize {
        1
    }
    fn param_names(&self) -> Vec<String> {
        vec!["albedo".into()]
    }
    fn bounds(&self) -> Vec<ParamBound> {
        vec![ParamBound::new(0.0, MAX_ALBEDO)]
    }
    fn eval(&self, p: &[f64], _g: &Geom) -> f64 {
        p[0] * std::f64::consts::FRAC_1_PI
    }
    fn eval_grad(&self, p: &[f64], g: &Geom, grad: &mut [f64]) -> f64 {
        grad[0] = std::f64::consts::FRAC_1_PI;
        self.eval(p, g)
    }
    fn starting_points(&self, hint: &StartHint) -> Vec<Vec<f64>> {
        vec![vec![
            (hint.diffuse_rho * std::f64::consts::PI).clamp(0.0, MAX_ALBEDO)
        ]]
    }
    fn to_model(&self, params: &[Vec<f64>; 3]) -> Result<BrdfModel, BrdfError> {
        for p in params {
            check_len(self, p)?;
        }
        Ok(BrdfModel::Lambertian {
            albedo: std::array::from_fn(|c| params[c][0]),
        })
    }
    fn params_from_model(&self, model: &BrdfModel, channel: usize) -> Option<Vec<f64>> {
        match model {
            BrdfModel::Lambertian { albedo } => Some(vec![albedo[channel]]),
            _ => None,
        }
    }
}
