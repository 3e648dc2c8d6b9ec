//! One BRDF sample, as derendering produces it and fitting consumes it.

use serde::{Deserialize, Serialize};

use crate::BrdfAngles;

/// A BRDF sample: the angles of one (light, camera) pair at one surface point and the measured
/// reflectance per RGB channel (1/sr). Compact (f32) because sessions hold millions.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct BrdfSample {
    /// Incident polar angle.
    pub theta_i_rad: f32,
    /// Exitant polar angle.
    pub theta_e_rad: f32,
    /// Relative azimuth in `[0, pi]` (0 = retro side, pi = mirror side).
    pub phi_d_rad: f32,
    /// Half-vector polar angle (Rusinkiewicz).
    pub theta_h_rad: f32,
    /// Difference polar angle (Rusinkiewicz).
    pub theta_diff_rad: f32,
    /// Difference azimuth in `[0, pi]` (Rusinkiewicz).
    pub phi_diff_rad: f32,
    /// Reflectance per channel, 1/sr.
    pub rho: [f32; 3],
    /// Index of the source image in the session (u16::MAX for samples from elsewhere).
    pub image_index: u16,
    /// Source pixel (column, row).
    pub pixel: [u16; 2],
    /// Relative weight (1 for an ordinary sample; fitting multiplies residuals by it).
    pub weight: f32,
}

impl BrdfSample {
    /// A sample from angles and a value, with no image provenance and unit weight.
    pub fn from_angles(angles: &BrdfAngles, rho: [f32; 3]) -> Self {
        Self {
            theta_i_rad: angles.theta_i_rad as f32,
            theta_e_rad: angles.theta_e_rad as f32,
            phi_d_rad: angles.phi_d_rad as f32,
            theta_h_rad: angles.theta_h_rad as f32,
            theta_diff_rad: angles.theta_diff_rad as f32,
            phi_diff_rad: angles.phi_diff_rad as f32,
            rho,
            image_index: u16::MAX,
            pixel: [0, 0],
            weight: 1.0,
        }
    }

    /// The sample's angles in f64.
    pub fn angles(&self) -> BrdfAngles {
        BrdfAngles {
            theta_i_rad: self.theta_i_rad as f64,
            theta_e_rad: self.theta_e_rad as f64,
            phi_d_rad: self.phi_d_rad as f64,
            theta_h_rad: self.theta_h_rad as f64,
            theta_diff_rad: self.theta_diff_rad as f64,
            phi_diff_rad: self.phi_diff_rad as f64,
        }
    }
}
