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
//!
//! ## Fitting parametrisation ([`LafortuneFit`])
//!
//! `(Cxy, Cz, n)` is badly conditioned for fitting: the lobe's magnitude `|C|^n` couples all
//! three. Per channel the fit uses, for each lobe `k`,
//!
//! ```text
//! lobe_k = A_k (n_k + 2) / (2 pi) * max(0, s_k u_z v_z + t_k (u_x v_x + u_y v_y)) ^ n_k
//! params: ln A_k (log lobe albedo), t_k = Cxy/|Cz| (shape), ln n_k (log exponent)
//! ```
//!
//! with `s_k = sign(Cz) = ±1` a structural choice (not fitted; `+1` unless a lobe is declared
//! `cz_negative`). `A_k` is the lobe's albedo in the normalised-Phong sense (exactly the
//! directional albedo of a lobe about the normal), so the peak height and the width are separate
//! parameters: widening a lobe does not also rescale it. `t = -1` is a mirror lobe, `t > 0`
//! retro-reflective, `|t| < 1` off-specular towards the normal, `|t| > 1` towards grazing.
//! The value is computed as `exp(ln A + ln((n+2)/2pi) + n ln b)`, so exponents in the thousands
//! neither overflow nor produce NaN (the log-value is capped at [`MAX_LOG_VALUE`]).
//! Conversion to the classic form is exact: `Cxy = t k`, `Cz = s k`,
//! `k = (A (n+2) / 2pi)^(1/n)`.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::lambertian::MAX_ALBEDO;
use crate::param::check_len;
use crate::{BrdfError, BrdfModel, ChannelModel, Geom, ParamBound, StartHint};

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

/// Cap on the natural log of a lobe value (e^80 ~ 5.5e34 1/sr): keeps every value and gradient
/// finite for any parameter inside or outside the bounds.
pub const MAX_LOG_VALUE: f64 = 80.0;
/// Largest exponent the fit explores (near-mirror lobes of glossy paints reach a few thousand).
pub const MAX_EXPONENT: f64 = 20_000.0;

/// The structure of one fitted lobe (not fitted itself).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LobeSpec {
    /// `Cz < 0` (a lobe that lives only where `t dxy` exceeds `u_z v_z`, i.e. near grazing).
    pub cz_negative: bool,
}

/// Fittable Lafortune channel: `[albedo_d, (ln A_k, t_k, ln n_k) for each lobe]`.
#[derive(Debug, Clone, PartialEq)]
pub struct LafortuneFit {
    /// The lobes' structure.
    pub lobes: Vec<LobeSpec>,
}

impl LafortuneFit {
    /// `lobes` lobes with `Cz > 0` (forward, retro or off-specular depending on the fitted `t`).
    pub fn standard(lobes: usize) -> Self {
        Self {
            lobes: vec![LobeSpec::default(); lobes],
        }
    }

    #[inline]
    fn lobe(&self, k: usize, p: &[f64], g: &Geom, grad: Option<&mut [f64]>) -> f64 {
        let s = if self.lobes[k].cz_negative { -1.0 } else { 1.0 };
        let (ln_a, t, ln_n) = (p[1 + 3 * k], p[2 + 3 * k], p[3 + 3 * k]);
        let b = s * g.dz + t * g.dxy;
        if b <= 0.0 {
            if let Some(gr) = grad {
                gr.fill(0.0);
            }
            return 0.0;
        }
        let n = ln_n.exp();
        let lb = b.ln();
        let log_norm = ln_a + ((n + 2.0) * (0.5 * std::f64::consts::FRAC_1_PI)).ln();
        let e = log_norm + n * lb;
        if e > MAX_LOG_VALUE {
            if let Some(gr) = grad {
                gr.fill(0.0);
            }
            return MAX_LOG_VALUE.exp();
        }
        let v = e.exp();
        if let Some(gr) = grad {
            gr[0] = v;
            // v n dxy / b without dividing by a tiny b: b^(n-1) with n >= 1.
            gr[1] = n * g.dxy * (log_norm + (n - 1.0) * lb).exp();
            gr[2] = v * n * (1.0 / (n + 2.0) + lb);
        }
        v
    }
}

impl ChannelModel for LafortuneFit {
    fn name(&self) -> String {
        format!("lafortune{}", self.lobes.len())
    }
    fn n_params(&self) -> usize {
        1 + 3 * self.lobes.len()
    }
    fn param_names(&self) -> Vec<String> {
        let mut v = vec!["albedo_d".to_owned()];
        for k in 0..self.lobes.len() {
            v.push(format!("ln_albedo_{k}"));
            v.push(format!("t_{k}"));
            v.push(format!("ln_exponent_{k}"));
        }
        v
    }
    fn bounds(&self) -> Vec<ParamBound> {
        let mut v = vec![ParamBound::new(0.0, MAX_ALBEDO)];
        for _ in &self.lobes {
            v.push(ParamBound::new(-18.0, 3.0));
            v.push(ParamBound::new(-3.0, 3.0));
            v.push(ParamBound::new(0.0, MAX_EXPONENT.ln()));
        }
        v
    }
    fn eval(&self, p: &[f64], g: &Geom) -> f64 {
        let mut v = p[0] * std::f64::consts::FRAC_1_PI;
        for k in 0..self.lobes.len() {
            v += self.lobe(k, p, g, None);
        }
        v
    }
    fn eval_grad(&self, p: &[f64], g: &Geom, grad: &mut [f64]) -> f64 {
        grad[0] = std::f64::consts::FRAC_1_PI;
        let mut v = p[0] * std::f64::consts::FRAC_1_PI;
        for k in 0..self.lobes.len() {
            v += self.lobe(k, p, g, Some(&mut grad[1 + 3 * k..4 + 3 * k]));
        }
        v
    }
    fn starting_points(&self, hint: &StartHint) -> Vec<Vec<f64>> {
        let diffuse = hint.diffuse_rho.max(1e-6);
        let spec = (hint.peak_rho - diffuse).max(1e-4 * diffuse);
        let ln_a = |peak: f64, n: f64| {
            (peak * 2.0 * std::f64::consts::PI / (n + 2.0))
                .ln()
                .clamp(-18.0, 3.0)
        };
        // First lobe: a forward (mirror) lobe of four widths. A second lobe starts either as a
        // broad retro-reflective lobe or as a broad lobe about the normal (t = 0) that takes over
        // the diffuse level and lets it fall off towards grazing; a third is a broad forward lobe.
        let mut starts = Vec::new();
        let variants: &[bool] = if self.lobes.len() >= 2 {
            &[false, true]
        } else {
            &[false]
        };
        for &normal_lobe in variants {
            for &n0 in &[8.0, 80.0, 800.0, 4000.0] {
                let d0 = if normal_lobe { 0.1 } else { 0.8 };
                let mut p = vec![(d0 * diffuse * std::f64::consts::PI).min(MAX_ALBEDO)];
                for k in 0..self.lobes.len() {
                    let (peak, t, n) = match k {
                        0 => (spec, -1.0, n0),
                        1 if normal_lobe => (0.9 * diffuse, 0.0, 1.5),
                        1 => (0.2 * diffuse, 1.0, 3.0),
                        _ => (0.2 * diffuse, -0.8, 2.0),
                    };
                    p.extend([ln_a(peak, n), t, n.ln()]);
                }
                starts.push(p);
            }
        }
        starts
    }
    fn to_model(&self, params: &[Vec<f64>; 3]) -> Result<BrdfModel, BrdfError> {
        for p in params {
            check_len(self, p)?;
        }
        let lobes = (0..self.lobes.len())
            .map(|k| {
                let s = if self.lobes[k].cz_negative { -1.0 } else { 1.0 };
                let mut lobe = LafortuneLobe {
                    cxy: [0.0; 3],
                    cz: [0.0; 3],
                    exponent: [0.0; 3],
                };
                for (c, pc) in params.iter().enumerate() {
                    let (ln_a, t, ln_n) = (pc[1 + 3 * k], pc[2 + 3 * k], pc[3 + 3 * k]);
                    let n = ln_n.exp();
                    let kk =
                        ((ln_a + ((n + 2.0) * 0.5 * std::f64::consts::FRAC_1_PI).ln()) / n).exp();
                    lobe.cxy[c] = t * kk;
                    lobe.cz[c] = s * kk;
                    lobe.exponent[c] = n;
                }
                lobe
            })
            .collect();
        let m = BrdfModel::Lafortune(Lafortune {
            diffuse_albedo: std::array::from_fn(|c| params[c][0]),
            lobes,
        });
        m.validate()?;
        Ok(m)
    }
    fn params_from_model(&self, model: &BrdfModel, c: usize) -> Option<Vec<f64>> {
        let BrdfModel::Lafortune(l) = model else {
            return None;
        };
        if l.lobes.len() != self.lobes.len() {
            return None;
        }
        let mut p = vec![l.diffuse_albedo[c]];
        for (lobe, spec) in l.lobes.iter().zip(&self.lobes) {
            let cz = lobe.cz[c];
            if cz == 0.0 || (cz < 0.0) != spec.cz_negative {
                return None;
            }
            let n = lobe.exponent[c];
            let ln_a = n * cz.abs().ln() + (2.0 * std::f64::consts::PI / (n + 2.0)).ln();
            p.extend([ln_a, lobe.cxy[c] / cz.abs(), n.ln()]);
        }
        Some(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use skinbrdf_core::BrdfAngles;

    fn fd_check(m: &dyn ChannelModel, p: &[f64], g: &Geom) -> Result<(), String> {
        let mut grad = vec![0.0; m.n_params()];
        let v = m.eval_grad(p, g, &mut grad);
        if (v - m.eval(p, g)).abs() > 1e-12 * v.abs().max(1e-300) {
            return Err("eval and eval_grad disagree".into());
        }
        for j in 0..p.len() {
            let h = 1e-6 * p[j].abs().max(1.0);
            let mut pp = p.to_vec();
            pp[j] += h;
            let up = m.eval(&pp, g);
            pp[j] -= 2.0 * h;
            let dn = m.eval(&pp, g);
            let fd = (up - dn) / (2.0 * h);
            // Central differences: truncation ~h^2, rounding ~eps |v| / h.
            let allowed = 1e-4 * grad[j].abs().max(fd.abs()) + 1e-7 * v.abs();
            if (fd - grad[j]).abs() > allowed {
                return Err(format!(
                    "param {j}: analytic {} vs finite difference {fd}",
                    grad[j]
                ));
            }
        }
        Ok(())
    }

    proptest! {
        #[test]
        fn lafortune_fit_gradient_matches_finite_differences(
            ad in 0.0..1.0f64, ln_a in -5.0..1.0f64, t in -2.0..2.0f64, ln_n in 0.0..8.0f64,
            ln_a2 in -5.0..1.0f64, t2 in -2.0..2.0f64, ln_n2 in 0.0..3.0f64,
            ti in 0.0..1.5f64, te in 0.0..1.5f64, pd in 0.0..std::f64::consts::PI,
        ) {
            let m = LafortuneFit::standard(2);
            let g = Geom::from_angles(ti, te, pd);
            let p = [ad, ln_a, t, ln_n, ln_a2, t2, ln_n2];
            // Skip the kink where a lobe base crosses zero (the model is only C0 there).
            prop_assume!((g.dz + t * g.dxy).abs() > 1e-3 && (g.dz + t2 * g.dxy).abs() > 1e-3);
            fd_check(&m, &p, &g).map_err(TestCaseError::fail)?;
        }

        #[test]
        fn lafortune_fit_agrees_with_the_classic_form(
            ad in 0.0..1.0f64, ln_a in -5.0..1.0f64, t in -2.0..2.0f64, ln_n in 0.0..8.0f64,
            ti in 0.0..1.5f64, te in 0.0..1.5f64, pd in 0.0..std::f64::consts::PI, neg in any::<bool>(),
        ) {
            let m = LafortuneFit { lobes: vec![LobeSpec { cz_negative: neg }] };
            let p = vec![ad, ln_a, t, ln_n];
            let model = m.to_model(&[p.clone(), p.clone(), p.clone()]).map_err(|e| TestCaseError::fail(e.to_string()))?;
            let back = m.params_from_model(&model, 1).ok_or_else(|| TestCaseError::fail("kind"))?;
            for (a, b) in p.iter().zip(&back) {
                prop_assert!((a - b).abs() < 1e-9 * a.abs().max(1.0), "{p:?} vs {back:?}");
            }
            let v = model.eval_angles(ti, te, pd)[0];
            let w = m.eval(&p, &Geom::from_angles(ti, te, pd));
            // The fitted form caps values at e^MAX_LOG_VALUE; the classic form does not.
            prop_assume!(w < 0.5 * MAX_LOG_VALUE.exp());
            prop_assert!((v - w).abs() <= 1e-9 * v.abs().max(1e-12), "{v} vs {w}");
        }

        #[test]
        fn huge_exponents_and_grazing_stay_finite(
            ln_a in -18.0..3.0f64, t in -3.0..3.0f64, ln_n in 0.0..(MAX_EXPONENT.ln()),
            ti in 0.0..std::f64::consts::FRAC_PI_2, te in 0.0..std::f64::consts::FRAC_PI_2,
            pd in 0.0..std::f64::consts::PI,
        ) {
            let m = LafortuneFit::standard(1);
            let mut grad = [0.0; 4];
            let v = m.eval_grad(&[0.3, ln_a, t, ln_n], &Geom::from_angles(ti, te, pd), &mut grad);
            prop_assert!(v.is_finite() && v >= 0.0);
            prop_assert!(grad.iter().all(|g| g.is_finite()));
        }
    }

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
