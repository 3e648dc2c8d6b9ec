//! Cook-Torrance microfacet model: GGX (Trowbridge-Reitz) normal distribution, separable Smith
//! GGX shadowing and exact dielectric Fresnel, plus a Lambertian base. Per channel:
//!
//! ```text
//! rho = kd / pi + ks * F(cos_d) / F(1) * D(cos_h) * G1(cos_i) G1(cos_e) / (4 cos_i cos_e)
//! D(c)  = alpha^2 / (pi ((alpha^2 - 1) c^2 + 1)^2)
//! G1(c) = 2c / (c + sqrt(alpha^2 + (1 - alpha^2) c^2))
//! F     = unpolarised dielectric Fresnel reflectance at relative index `ior` (default 1.4, skin)
//! ```
//!
//! The Fresnel factor is normalised by its normal-incidence value so that `ks` carries the
//! specular magnitude (it would otherwise be a product `ks F0`, unidentifiable). `G1/c` is
//! evaluated as `2 / (c + sqrt(...))`, which stays finite at grazing (`c -> 0`).
//! Fitting parameters per channel: `[kd, ks, ln alpha]` (log roughness: alpha spans 0.005..1).

use serde::{Deserialize, Serialize};

use crate::lambertian::MAX_ALBEDO;
use crate::param::check_len;
use crate::{BrdfError, BrdfModel, ChannelModel, Geom, ParamBound, StartHint};

/// Refractive index of the outer skin layer (stratum corneum ~1.4-1.55; 1.4 is the usual choice).
pub const SKIN_IOR: f64 = 1.4;
/// Smallest roughness the fit explores (below it the model is a mirror the samples cannot resolve).
pub const MIN_ALPHA: f64 = 0.005;
/// Largest specular scale the fit explores.
pub const MAX_KS: f64 = 20.0;

/// The serialisable Cook-Torrance model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CookTorrance {
    /// Lambertian albedo per channel.
    pub diffuse_albedo: [f64; 3],
    /// Specular scale per channel (`ks`, Fresnel normalised to 1 at normal incidence).
    pub specular_scale: [f64; 3],
    /// GGX roughness alpha per channel.
    pub roughness_alpha: [f64; 3],
    /// Relative refractive index of the surface.
    pub ior: f64,
}

impl CookTorrance {
    /// Evaluates every channel.
    pub fn eval_geom(&self, g: &Geom) -> [f64; 3] {
        std::array::from_fn(|c| {
            channel(
                self.diffuse_albedo[c],
                self.specular_scale[c],
                self.roughness_alpha[c],
                self.ior,
                g,
                None,
            )
        })
    }
}

/// Unpolarised Fresnel reflectance of a dielectric for `cos` of the incidence angle.
pub fn fresnel_dielectric(cos_d: f64, ior: f64) -> f64 {
    let c = cos_d.clamp(0.0, 1.0);
    let g2 = ior * ior - 1.0 + c * c;
    if g2 <= 0.0 {
        return 1.0;
    }
    let g = g2.sqrt();
    let a = (g - c) / (g + c);
    let b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    0.5 * a * a * (1.0 + b * b)
}

/// One channel with optional gradient `[d/dkd, d/dks, d/dln_alpha]`.
fn channel(kd: f64, ks: f64, alpha: f64, ior: f64, g: &Geom, grad: Option<&mut [f64]>) -> f64 {
    let diffuse = kd * std::f64::consts::FRAC_1_PI;
    if !g.is_above() {
        if let Some(gr) = grad {
            gr.fill(0.0);
        }
        return 0.0;
    }
    let a2 = alpha * alpha;
    let x = g.cos_h * g.cos_h;
    let q = x * (a2 - 1.0) + 1.0;
    let d = a2 / (std::f64::consts::PI * q * q);
    let ri = (a2 + (1.0 - a2) * g.cos_i * g.cos_i).sqrt();
    let re = (a2 + (1.0 - a2) * g.cos_e * g.cos_e).sqrt();
    let pi_ = g.cos_i + ri;
    let pe = g.cos_e + re;
    // G1(ci) G1(ce) / (4 ci ce) = 1 / ((ci + ri)(ce + re)).
    let qg = 1.0 / (pi_ * pe);
    let f = fresnel_dielectric(g.cos_d, ior) / fresnel_dielectric(1.0, ior);
    let spec_unit = f * d * qg;
    if let Some(gr) = grad {
        gr[0] = std::f64::consts::FRAC_1_PI;
        gr[1] = spec_unit;
        let dd = 2.0 * alpha / (std::f64::consts::PI * q * q) * (1.0 - 2.0 * a2 * x / q);
        let dpi = alpha * (1.0 - g.cos_i * g.cos_i) / ri;
        let dpe = alpha * (1.0 - g.cos_e * g.cos_e) / re;
        let dqg = -qg * (dpi / pi_ + dpe / pe);
        gr[2] = alpha * ks * f * (dd * qg + d * dqg);
    }
    diffuse + ks * spec_unit
}

/// Fittable Cook-Torrance channel: `[kd, ks, ln alpha]` at a fixed index of refraction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CookTorranceFit {
    /// Relative refractive index (not fitted).
    pub ior: f64,
}

impl Default for CookTorranceFit {
    fn default() -> Self {
        Self { ior: SKIN_IOR }
    }
}

impl ChannelModel for CookTorranceFit {
    fn name(&self) -> String {
        "cook-torrance".into()
    }
    fn n_params(&self) -> usize {
        3
    }
    fn param_names(&self) -> Vec<String> {
        vec![
            "albedo_d".into(),
            "specular_scale".into(),
            "ln_alpha".into(),
        ]
    }
    fn bounds(&self) -> Vec<ParamBound> {
        vec![
            ParamBound::new(0.0, MAX_ALBEDO),
            ParamBound::new(0.0, MAX_KS),
            ParamBound::new(MIN_ALPHA.ln(), 0.0),
        ]
    }
    fn eval(&self, p: &[f64], g: &Geom) -> f64 {
        channel(p[0], p[1], p[2].exp(), self.ior, g, None)
    }
    fn eval_grad(&self, p: &[f64], g: &Geom, grad: &mut [f64]) -> f64 {
        channel(p[0], p[1], p[2].exp(), self.ior, g, Some(grad))
    }
    fn starting_points(&self, hint: &StartHint) -> Vec<Vec<f64>> {
        let diffuse = hint.diffuse_rho.max(1e-6);
        let spec = (hint.peak_rho - diffuse).max(1e-4 * diffuse);
        [0.02, 0.1, 0.3, 0.6]
            .iter()
            .map(|&alpha: &f64| {
                // At the specular peak near normal incidence rho_spec ~ ks / (4 pi alpha^2).
                let ks = (spec * 4.0 * std::f64::consts::PI * alpha * alpha).clamp(1e-6, MAX_KS);
                vec![
                    (0.8 * diffuse * std::f64::consts::PI).min(MAX_ALBEDO),
                    ks,
                    alpha.ln(),
                ]
            })
            .collect()
    }
    fn to_model(&self, params: &[Vec<f64>; 3]) -> Result<BrdfModel, BrdfError> {
        for p in params {
            check_len(self, p)?;
        }
        let m = BrdfModel::CookTorrance(CookTorrance {
            diffuse_albedo: std::array::from_fn(|c| params[c][0]),
            specular_scale: std::array::from_fn(|c| params[c][1]),
            roughness_alpha: std::array::from_fn(|c| params[c][2].exp()),
            ior: self.ior,
        });
        m.validate()?;
        Ok(m)
    }
    fn params_from_model(&self, model: &BrdfModel, c: usize) -> Option<Vec<f64>> {
        match model {
            BrdfModel::CookTorrance(m) => Some(vec![
                m.diffuse_albedo[c],
                m.specular_scale[c],
                m.roughness_alpha[c].ln(),
            ]),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn gradient_matches_finite_differences(
            kd in 0.0..1.0f64, ks in 0.0..5.0f64, ln_alpha in (MIN_ALPHA.ln())..0.0,
            ti in 0.0..1.5f64, te in 0.0..1.5f64, pd in 0.0..std::f64::consts::PI,
        ) {
            let m = CookTorranceFit::default();
            let g = Geom::from_angles(ti, te, pd);
            let p = [kd, ks, ln_alpha];
            let mut grad = [0.0; 3];
            let v = m.eval_grad(&p, &g, &mut grad);
            prop_assert!((v - m.eval(&p, &g)).abs() <= 1e-12 * v.abs());
            for j in 0..3 {
                let h = 1e-6 * p[j].abs().max(1e-2);
                let mut pp = p;
                pp[j] += h;
                let up = m.eval(&pp, &g);
                pp[j] -= 2.0 * h;
                let fd = (up - m.eval(&pp, &g)) / (2.0 * h);
                let scale = grad[j].abs().max(fd.abs()).max(1e-9 * v.abs());
                prop_assert!((fd - grad[j]).abs() <= 1e-4 * scale, "param {j}: {} vs {fd}", grad[j]);
            }
        }

        #[test]
        fn grazing_and_mirror_stay_finite(
            ln_alpha in (MIN_ALPHA.ln())..0.0, ti in 0.0..std::f64::consts::FRAC_PI_2,
            te in 0.0..std::f64::consts::FRAC_PI_2, pd in 0.0..std::f64::consts::PI,
        ) {
            let m = CookTorranceFit::default();
            let mut grad = [0.0; 3];
            let v = m.eval_grad(&[0.5, 1.0, ln_alpha], &Geom::from_angles(ti, te, pd), &mut grad);
            prop_assert!(v.is_finite() && v >= 0.0 && grad.iter().all(|g| g.is_finite()));
        }
    }

    #[test]
    fn fresnel_limits() {
        let f0 = fresnel_dielectric(1.0, 1.5);
        assert!((f0 - 0.04).abs() < 1e-12);
        assert!((fresnel_dielectric(0.0, 1.5) - 1.0).abs() < 1e-12);
        assert!(fresnel_dielectric(0.3, 1.5) > f0);
    }

    #[test]
    fn energy_of_the_specular_term_is_bounded() {
        // Directional albedo of the specular term at normal incidence (ks = 1, F normalised)
        // must not exceed ~1: integrate over the hemisphere with a midpoint rule.
        let m = CookTorranceFit::default();
        for alpha in [0.1f64, 0.3, 0.7] {
            let n = 400;
            let mut e = 0.0;
            for a in 0..n {
                let te = (a as f64 + 0.5) / n as f64 * std::f64::consts::FRAC_PI_2;
                let g = Geom::from_angles(0.0, te, 0.0);
                let v = m.eval(&[0.0, 1.0, alpha.ln()], &g);
                e += v
                    * te.cos()
                    * te.sin()
                    * 2.0
                    * std::f64::consts::PI
                    * std::f64::consts::FRAC_PI_2
                    / n as f64;
            }
            assert!(e > 0.3 && e < 1.2, "alpha {alpha}: albedo {e}");
        }
    }
}
