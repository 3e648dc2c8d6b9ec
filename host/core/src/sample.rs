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
    /// Reflectance per channel, 1/sr; NaN in a channel the sample did not measure (a
    /// *partial* sample: a camera raw photosite measures its own filter's channel only).
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

    /// The channels the sample measured: those whose `rho` is not NaN.
    pub fn measured(&self) -> [bool; 3] {
        self.rho.map(|r| !r.is_nan())
    }

    /// True when the sample measured channel `c` (0 red, 1 green, 2 blue).
    pub fn measures(&self, c: usize) -> bool {
        self.rho.get(c).is_some_and(|r| !r.is_nan())
    }

    /// True when the sample measured fewer than three channels.
    pub fn is_partial(&self) -> bool {
        self.rho.iter().any(|r| r.is_nan())
    }

    /// The mean of the measured channels' `rho` (NaN when none is measured).
    pub fn mean_measured_rho(&self) -> f32 {
        let (sum, n) = self
            .rho
            .iter()
            .filter(|r| !r.is_nan())
            .fold((0.0f32, 0u8), |(s, n), r| (s + r, n + 1));
        if n == 0 {
            f32::NAN
        } else {
            sum / f32::from(n)
        }
    }
}
