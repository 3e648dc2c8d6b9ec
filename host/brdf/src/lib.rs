//! BRDF models.
//!
//! Every model evaluates `rho(w_i, w_e)` per RGB channel (1/sr) from local unit directions
//! (+z = normal, both pointing away from the surface; see [`skinbrdf_core::angles`]).
//! [`BrdfModel`] is the serialisable sum of the models, used by scene files, `truth.json` and
//! fit results.

pub mod lafortune;

pub use lafortune::{Lafortune, LafortuneLobe};

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Any BRDF the project knows, serialised with a `model` tag.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum BrdfModel {
    /// Ideal diffuse reflector: `rho = albedo / pi`.
    Lambertian {
        /// Diffuse albedo per channel, in `[0, 1]`.
        albedo: [f64; 3],
    },
    /// Lambertian plus generalized cosine lobes (Lafortune et al. 1997).
    Lafortune(Lafortune),
}

impl BrdfModel {
    /// Evaluates the BRDF per channel (1/sr) for local directions. Directions below the surface
    /// give zero.
    pub fn eval(&self, wi: DVec3, we: DVec3) -> [f64; 3] {
        if wi.z <= 0.0 || we.z <= 0.0 {
            return [0.0; 3];
        }
        match self {
            Self::Lambertian { albedo } => albedo.map(|a| a * std::f64::consts::FRAC_1_PI),
            Self::Lafortune(l) => l.eval(wi, we),
        }
    }

    /// Evaluates from the isotropic angles (see [`skinbrdf_core::BrdfAngles`]).
    pub fn eval_angles(&self, theta_i_rad: f64, theta_e_rad: f64, phi_d_rad: f64) -> [f64; 3] {
        let (wi, we) =
            skinbrdf_core::BrdfAngles::canonical_directions(theta_i_rad, theta_e_rad, phi_d_rad);
        self.eval(wi, we)
    }
}
