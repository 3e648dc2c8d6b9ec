//! The Lafortune generalized cosine-lobe model (Lafortune, Foo, Torrance, Greenberg 1997).
//!
//! For local directions `u = w_i`, `v = w_e` the isotropic model is, per channel,
//!
//! ```text
//! rho(u, v) = albedo / pi + sum_k max(0, Cxy_k (u_x v_x + u_y v_y) + Cz_k u_z v_z) ^ n_k
//! ```
//!
//! `Cxy < 0, Cz > 0` is a forward (specular-like) lobe: with `-Cxy = Cz` it peaks at the mirror
//! direction; `Cxy > 0` a retro-reflective lobe; `|Cxy| < Cz` an off-specular lobe tilted towards
//! the normal. The exponent `n` sets the width (1 to several thousand for near-mirror lobes);
//! the lobe's magnitude is carried by `|C|^n`.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// One lobe with separate coefficients per RGB channel.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LafortuneLobe {
    /// Tangential coefficient per channel.
    pub cxy: [f64; 3],
    /// Normal coefficient per channel.
    pub cz: [f64; 3],
    /// Exponent per channel.
    pub exponent: [f64; 3],
}

impl LafortuneLobe {
    /// The lobe's value for one channel. Uses `exp(n ln base)` so exponents in the thousands
    /// neither overflow nor lose the tail.
    pub fn eval_channel(&self, c: usize, wi: DVec3, we: DVec3) -> f64 {
        let base = self.cxy[c] * (wi.x * we.x + wi.y * we.y) + self.cz[c] * wi.z * we.z;
        if base <= 0.0 {
            0.0
        } else {
            (self.exponent[c] * base.ln()).exp()
        }
    }
}

/// Diffuse term plus lobes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Lafortune {
    /// Diffuse albedo per channel.
    pub diffuse_albedo: [f64; 3],
    /// The lobes.
    pub lobes: Vec<LafortuneLobe>,
}

impl Lafortune {
    /// Evaluates every channel.
    pub fn eval(&self, wi: DVec3, we: DVec3) -> [f64; 3] {
        std::array::from_fn(|c| {
            self.diffuse_albedo[c] * std::f64::consts::FRAC_1_PI
                + self
                    .lobes
                    .iter()
                    .map(|l| l.eval_channel(c, wi, we))
                    .sum::<f64>()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_core::BrdfAngles;

    #[test]
    fn mirror_lobe_peaks_at_the_mirror_direction() {
        let lobe = LafortuneLobe {
            cxy: [-1.0; 3],
            cz: [1.0; 3],
            exponent: [2000.0; 3],
        };
        let (wi, mirror) = BrdfAngles::canonical_directions(0.5, 0.5, std::f64::consts::PI);
        let (_, off) = BrdfAngles::canonical_directions(0.5, 0.55, std::f64::consts::PI);
        let peak = lobe.eval_channel(0, wi, mirror);
        assert!((peak - 1.0).abs() < 1e-9);
        assert!(lobe.eval_channel(0, wi, off) < 0.1 * peak);
    }
}
