//! Local quadratic regression (loess) of scattered BRDF samples, with pointwise confidence bands.
//!
//! At a query point `x0` the smoother fits, by weighted least squares, a full quadratic in the
//! `d <= 3` predictors (intercept, linear, squares and cross products: `1 + d + d(d+1)/2` terms)
//! to the neighbours of `x0`, with tricube weights `w = (1 - (r/h)^3)^3` for `r < h`, and returns
//! the fitted value at `x0`. This is Cleveland's loess with `degree = 2`, `family = "gaussian"`,
//! `surface = "direct"`, as R's `loess` and netlib's `dloess` compute it:
//!
//! * **Normalisation** (R's `normalize = TRUE`): with two or more predictors each one is divided
//!   by its 10%-trimmed standard deviation before distances are taken.
//! * **Bandwidth**: [`Bandwidth::Span`] `alpha <= 1` takes `h` as the distance to the
//!   `q = floor(alpha n)`-th nearest sample (R's `span`); [`Bandwidth::Radius`] is a fixed `h`
//!   in normalised units, for millions of samples (no sort of `q` neighbours); `h` may be chosen
//!   by generalized cross-validation ([`choose_span_gcv`]).
//! * **Neighbourhoods** come from a k-d tree (kiddo's `ImmutableKdTree`), built once.
//! * **Linear-smoother algebra.** The fit is `yhat(x0) = sum_j l_j(x0) y_j`. The residual scale is
//!   `s^2 = RSS / delta1`, `delta1 = tr((I-L)^T (I-L)) = n - 2 tr L + sum_i |L_i|^2`, evaluated
//!   exactly from the rows `L_i` at the samples (on an evenly strided subset of at most
//!   [`LoessConfig::max_sigma_points`] samples for large sets: the ratio RSS/delta1 is then an
//!   estimate). The standard error at `x0` is `s |l(x0)|`; the band is `yhat +- z s |l(x0)|` with
//!   the normal quantile `z` (R uses a t quantile with `delta1^2/delta2` degrees of freedom, which
//!   is the same to three digits once that exceeds ~1000).
//! * The local system is solved through the eigen-decomposition of the scaled `X^T W X` with a
//!   relative cut-off, so a degenerate neighbourhood (all samples on a line) still gives a value.
//!
//! Parity with the original Fortran (through scikit-misc) is tested on a committed fixture:
//! fitted values agree to [`PARITY_REL_TOL`] and standard errors to [`PARITY_SE_REL_TOL`].

use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Relative agreement of fitted values with netlib loess (scikit-misc) on the test fixture.
pub const PARITY_REL_TOL: f64 = 1e-6;
/// Relative agreement of standard errors with netlib loess (exact statistics).
pub const PARITY_SE_REL_TOL: f64 = 1e-3;
/// Terms of the local quadratic in three predictors (`n_terms(3)`), the most there are.
const MAX_TERMS: usize = 10;
/// Eigenvalue cut-off of the local normal equations, relative to the largest.
const LOCAL_RCOND: f64 = 1e-10;

/// Errors of the smoother.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LoessError {
    /// Too few samples for a local quadratic.
    #[error(
        "{found} samples are too few for a local quadratic in {dims} predictors (need {needed})"
    )]
    TooFewSamples {
        /// Needed.
        needed: usize,
        /// Present.
        found: usize,
        /// Predictors.
        dims: usize,
    },
    /// A bandwidth outside its domain.
    #[error("bandwidth {0} is invalid (span in (0, 1], radius > 0)")]
    BadBandwidth(f64),
    /// A non-finite predictor or response.
    #[error("sample {0} has a non-finite predictor or response")]
    NonFinite(usize),
    /// Wrong number of predictors.
    #[error("{0} predictors given; 1 to 3 are supported")]
    Dims(usize),
}

/// How wide the neighbourhoods are.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", content = "value", rename_all = "snake_case")]
pub enum Bandwidth {
    /// Fraction of the samples in each neighbourhood (R's `span`), in `(0, 1]`.
    Span(f64),
    /// Fixed radius in normalised predictor units.
    Radius(f64),
}

/// Smoother settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LoessConfig {
    /// Neighbourhood size.
    pub bandwidth: Bandwidth,
    /// Divide predictors by their 10%-trimmed standard deviations (R's default for d >= 2).
    pub normalize: bool,
    /// Two-sided confidence level of the bands.
    pub confidence: f64,
    /// Samples at which the residual scale is computed (all when fewer).
    pub max_sigma_points: usize,
}

impl Default for LoessConfig {
    fn default() -> Self {
        Self {
            bandwidth: Bandwidth::Span(0.3),
            normalize: true,
            confidence: 0.95,
            max_sigma_points: 20_000,
        }
    }
}

/// A value of the smooth with its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LoessPoint {
    /// Fitted value.
    pub value: f64,
    /// Standard error of the fitted value.
    pub std_error: f64,
    /// Lower end of the confidence band.
    pub lower: f64,
    /// Upper end of the confidence band.
    pub upper: f64,
}

/// A fitted smoother, ready to evaluate anywhere.
#[derive(Debug)]
pub struct Loess {
    dims: usize,
    scale: [f64; 3],
    points: Vec<[f64; 3]>,
    y: Vec<f64>,
    tree: ImmutableKdTree<f64, u64, 3, 32>,
    cfg: LoessConfig,
    /// Residual standard error `s`.
    pub sigma: f64,
    /// Trace of the operator, `tr L` (estimated on the sigma subset, scaled to n).
    pub trace_hat: f64,
    /// Equivalent number of parameters as netlib loess reports it, `delta1 + 2 tr L - n`
    /// (`= tr L^T L`).
    pub enp: f64,
    /// `delta1 / n` (see the module docs).
    pub delta1_per_sample: f64,
    /// Generalized cross-validation score `n RSS / (n - tr L)^2` (per-sample form).
    pub gcv: f64,
    /// The residuals `y_i - fit(x_i)` at the samples the residual scale was computed on, as
    /// `(index of the sample in the input, residual)`.
    pub sigma_residuals: Vec<(usize, f64)>,
    z: f64,
}

/// Standard normal quantile by Acklam's rational approximation (relative error < 1.2e-9).
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.38357751867269e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let pl = 0.02425;
    if p < pl {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - pl {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -normal_quantile(1.0 - p)
    }
}

fn trimmed_sd(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    let trim = (0.1 * n as f64).ceil() as usize;
    let kept = if n > 2 * trim + 1 {
        &s[trim..n - trim]
    } else {
        &s[..]
    };
    let m = kept.iter().sum::<f64>() / kept.len() as f64;
    let var = kept.iter().map(|x| (x - m) * (x - m)).sum::<f64>()
        / (kept.len().saturating_sub(1).max(1)) as f64;
    var.sqrt()
}

fn n_terms(d: usize) -> usize {
    1 + d + d * (d + 1) / 2
}

/// Quadratic basis of a centred, scaled offset.
fn basis(d: usize, u: &[f64; 3], out: &mut [f64]) {
    out[0] = 1.0;
    let mut k = 1;
    for ua in u.iter().take(d) {
        out[k] = *ua;
        k += 1;
    }
    for a in 0..d {
        for b in a..d {
            out[k] = u[a] * u[b];
            k += 1;
        }
    }
}

impl Loess {
    /// Fits the smoother to `x` (each row `d` predictors, `d` = 1..=3) and `y`.
    pub fn fit(x: &[Vec<f64>], y: &[f64], cfg: LoessConfig) -> Result<Self, LoessError> {
        let n = y.len();
        let dims = x.first().map_or(1, Vec::len);
        if !(1..=3).contains(&dims) || x.iter().any(|r| r.len() != dims) {
            return Err(LoessError::Dims(dims));
        }
        let p = n_terms(dims);
        if n < p + 1 || x.len() != n {
            return Err(LoessError::TooFewSamples {
                needed: p + 1,
                found: n.min(x.len()),
                dims,
            });
        }
        match cfg.bandwidth {
            Bandwidth::Span(a) if !(a > 0.0 && a <= 1.0) => {
                return Err(LoessError::BadBandwidth(a))
            }
            Bandwidth::Radius(r) if !(r > 0.0 && r.is_finite()) => {
                return Err(LoessError::BadBandwidth(r))
            }
            _ => {}
        }
        if let Some(i) = (0..n).find(|&i| !y[i].is_finite() || x[i].iter().any(|v| !v.is_finite()))
        {
            return Err(LoessError::NonFinite(i));
        }
        let mut scale = [1.0; 3];
        if cfg.normalize && dims >= 2 {
            for (a, s) in scale.iter_mut().enumerate().take(dims) {
                let col: Vec<f64> = x.iter().map(|r| r[a]).collect();
                let sd = trimmed_sd(&col);
                *s = if sd > 0.0 { sd } else { 1.0 };
            }
        }
        let points: Vec<[f64; 3]> = x
            .iter()
            .map(|r| std::array::from_fn(|a| if a < dims { r[a] / scale[a] } else { 0.0 }))
            .collect();
        let tree = ImmutableKdTree::<f64, u64, 3, 32>::new_from_slice(&points);
        let z = normal_quantile(0.5 + 0.5 * cfg.confidence);
        let mut me = Self {
            dims,
            scale,
            points,
            y: y.to_vec(),
            tree,
            cfg,
            sigma: f64::NAN,
            enp: f64::NAN,
            trace_hat: f64::NAN,
            delta1_per_sample: f64::NAN,
            gcv: f64::NAN,
            sigma_residuals: Vec::new(),
            z,
        };
        // Residual scale from the operator rows at (a strided subset of) the samples.
        let m = n.min(cfg.max_sigma_points.max(p + 1));
        let idx: Vec<usize> = (0..m)
            .map(|k| ((k as u128 * n as u128) / m as u128) as usize)
            .collect();
        let stats: Vec<(usize, f64, f64, f64)> = idx
            .par_iter()
            .filter_map(|&i| {
                let (val, l_self, l_norm2) = me.local(&me.points[i], Some(i))?;
                Some((i, me.y[i] - val, l_self, l_norm2))
            })
            .collect();
        let k = stats.len().max(1) as f64;
        let rss = stats.iter().map(|s| s.1 * s.1).sum::<f64>() / k;
        let tr = stats.iter().map(|s| s.2).sum::<f64>() / k;
        let nrm = stats.iter().map(|s| s.3).sum::<f64>() / k;
        let delta1 = (1.0 - 2.0 * tr + nrm).max(1e-12);
        me.sigma = (rss / delta1).sqrt();
        me.trace_hat = tr * n as f64;
        me.enp = (delta1 + 2.0 * tr - 1.0) * n as f64;
        me.delta1_per_sample = delta1;
        me.gcv = rss / ((1.0 - tr) * (1.0 - tr)).max(1e-300);
        me.sigma_residuals = stats.iter().map(|s| (s.0, s.1)).collect();
        Ok(me)
    }

    /// Number of predictors.
    pub fn dims(&self) -> usize {
        self.dims
    }

    /// Local fit at a normalised point: `(value, l_self, |l|^2)` where `l_self` is the weight of
    /// sample `self_index` (if given). `None` when the neighbourhood is empty.
    fn local(&self, q: &[f64; 3], self_index: Option<usize>) -> Option<(f64, f64, f64)> {
        let (idx, d2, h) = self.neighbours(q)?;
        let d = self.dims;
        let p = n_terms(d);
        // Upper triangle of X^T W X, and each neighbour's weight and basis row, on the stack
        // (no allocation per neighbour: a span of 0.2 of 20k samples is 4,000 neighbours).
        let mut acc = [[0.0f64; MAX_TERMS]; MAX_TERMS];
        let mut rows: Vec<(usize, f64, [f64; MAX_TERMS])> = Vec::with_capacity(idx.len());
        for (&j, &dd) in idx.iter().zip(&d2) {
            let r = dd.sqrt() / h;
            if r >= 1.0 {
                continue;
            }
            let t = 1.0 - r * r * r;
            let w = t * t * t;
            let pj = &self.points[j];
            let u: [f64; 3] = std::array::from_fn(|a| (pj[a] - q[a]) / h);
            let mut b = [0.0; MAX_TERMS];
            basis(d, &u, &mut b);
            for a in 0..p {
                let wb = w * b[a];
                for c in a..p {
                    acc[a][c] += wb * b[c];
                }
            }
            rows.push((j, w, b));
        }
        if rows.len() < p {
            return None;
        }
        let xtwx = DMatrix::<f64>::from_fn(p, p, |a, c| acc[a.min(c)][a.max(c)]);
        // Solve X^T W X a = e1 by a truncated eigen-decomposition.
        let eig = xtwx.symmetric_eigen();
        let lmax = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
        if lmax <= 0.0 {
            return None;
        }
        let mut a_vec = DVector::<f64>::zeros(p);
        for k in 0..p {
            let l = eig.eigenvalues[k];
            if l > LOCAL_RCOND * lmax {
                let v = eig.eigenvectors.column(k);
                a_vec += v * (v[0] / l);
            }
        }
        let mut val = 0.0;
        let mut l_self = 0.0;
        let mut l_norm2 = 0.0;
        for (j, w, bj) in &rows {
            let lj = w * bj[..p]
                .iter()
                .zip(a_vec.iter())
                .map(|(x, y)| x * y)
                .sum::<f64>();
            val += lj * self.y[*j];
            l_norm2 += lj * lj;
            if Some(*j) == self_index {
                l_self = lj;
            }
        }
        Some((val, l_self, l_norm2))
    }

    /// Neighbour indices, squared distances and the bandwidth at `q`.
    fn neighbours(&self, q: &[f64; 3]) -> Option<(Vec<usize>, Vec<f64>, f64)> {
        let n = self.points.len();
        match self.cfg.bandwidth {
            Bandwidth::Span(alpha) => {
                let k = ((alpha * n as f64).floor() as usize).clamp(1, n);
                let nn = self
                    .tree
                    .nearest_n::<SquaredEuclidean>(q, std::num::NonZero::new(k)?);
                let h2 = nn.iter().map(|m| m.distance).fold(0.0, f64::max);
                let mut h = h2.sqrt();
                if h <= 0.0 {
                    return None;
                }
                // netlib enlarges h by a hair so the q-th neighbour gets a (tiny) positive weight.
                h *= 1.0 + 1e-12;
                Some((
                    nn.iter().map(|m| m.item as usize).collect(),
                    nn.iter().map(|m| m.distance).collect(),
                    h,
                ))
            }
            Bandwidth::Radius(h) => {
                let nn = self.tree.within_unsorted::<SquaredEuclidean>(q, h * h);
                Some((
                    nn.iter().map(|m| m.item as usize).collect(),
                    nn.iter().map(|m| m.distance).collect(),
                    h,
                ))
            }
        }
    }

    fn normalise(&self, x: &[f64]) -> [f64; 3] {
        std::array::from_fn(|a| {
            if a < self.dims {
                x.get(a).copied().unwrap_or(0.0) / self.scale[a]
            } else {
                0.0
            }
        })
    }

    /// The smooth and its band at one point (`None` where no neighbourhood supports a fit).
    pub fn predict(&self, x: &[f64]) -> Option<LoessPoint> {
        let q = self.normalise(x);
        let (value, _, l2) = self.local(&q, None)?;
        let se = self.sigma * l2.sqrt();
        Some(LoessPoint {
            value,
            std_error: se,
            lower: value - self.z * se,
            upper: value + self.z * se,
        })
    }

    /// The smooth at many points, in parallel.
    pub fn predict_many(&self, xs: &[Vec<f64>]) -> Vec<Option<LoessPoint>> {
        xs.par_iter().map(|x| self.predict(x)).collect()
    }
}

/// Chooses a span from `candidates` by generalized cross-validation (smallest GCV score).
/// Returns the span and every candidate's score.
pub fn choose_span_gcv(
    x: &[Vec<f64>],
    y: &[f64],
    candidates: &[f64],
    base: LoessConfig,
) -> Result<(f64, Vec<(f64, f64)>), LoessError> {
    let mut scores = Vec::new();
    for &a in candidates {
        let l = Loess::fit(
            x,
            y,
            LoessConfig {
                bandwidth: Bandwidth::Span(a),
                ..base
            },
        )?;
        scores.push((a, l.gcv));
    }
    let best = scores
        .iter()
        .filter(|s| s.1.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|s| s.0)
        .ok_or(LoessError::BadBandwidth(f64::NAN))?;
    Ok((best, scores))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproduces_a_quadratic_exactly() {
        let x: Vec<Vec<f64>> = (0..200)
            .map(|i| vec![(i % 20) as f64 * 0.1, (i / 20) as f64 * 0.2])
            .collect();
        let y: Vec<f64> = x
            .iter()
            .map(|r| 1.0 + 2.0 * r[0] - r[1] + 0.5 * r[0] * r[1] + r[1] * r[1])
            .collect();
        let l = Loess::fit(
            &x,
            &y,
            LoessConfig {
                bandwidth: Bandwidth::Span(0.3),
                ..LoessConfig::default()
            },
        )
        .expect("fit");
        for q in [[0.55, 0.7], [1.0, 1.3]] {
            let p = l.predict(&q).expect("pred");
            let truth = 1.0 + 2.0 * q[0] - q[1] + 0.5 * q[0] * q[1] + q[1] * q[1];
            assert!((p.value - truth).abs() < 1e-9, "{} vs {truth}", p.value);
        }
        assert!(l.sigma < 1e-8);
    }

    #[test]
    fn parity_with_netlib_loess() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/loess_reference.json");
        let text = std::fs::read_to_string(&path).expect("fixture");
        let v: serde_json::Value = serde_json::from_str(&text).expect("json");
        let cases = v["cases"].as_array().expect("cases");
        for c in cases {
            let name = c["name"].as_str().expect("name");
            let rows = |key: &str| -> Vec<Vec<f64>> {
                c[key]
                    .as_array()
                    .expect(key)
                    .iter()
                    .map(|r| {
                        r.as_array()
                            .expect("row")
                            .iter()
                            .map(|x| x.as_f64().expect("num"))
                            .collect()
                    })
                    .collect()
            };
            let flat = |key: &str| -> Vec<f64> {
                c[key]
                    .as_array()
                    .expect(key)
                    .iter()
                    .map(|x| x.as_f64().expect("num"))
                    .collect()
            };
            let (x, q) = (rows("x"), rows("query"));
            let (y, want) = (flat("y"), flat("value"));
            let want_se = if c["stderr"].is_null() {
                vec![f64::NAN; want.len()]
            } else {
                flat("stderr")
            };
            let cfg = LoessConfig {
                bandwidth: Bandwidth::Span(c["span"].as_f64().expect("span")),
                normalize: c["normalize"].as_bool().expect("normalize"),
                ..LoessConfig::default()
            };
            let l = Loess::fit(&x, &y, cfg).expect("fit");
            let rs = c["residual_scale"].as_f64().expect("rs");
            assert!(
                (l.sigma / rs - 1.0).abs() < PARITY_SE_REL_TOL,
                "{name}: sigma {} vs {rs}",
                l.sigma
            );
            let enp = c["enp"].as_f64().expect("enp");
            assert!(
                (l.enp / enp - 1.0).abs() < PARITY_SE_REL_TOL,
                "{name}: enp {} vs {enp}",
                l.enp
            );
            for ((qi, w), wse) in q.iter().zip(&want).zip(&want_se) {
                let p = l.predict(qi).expect("pred");
                assert!(
                    (p.value - w).abs() <= PARITY_REL_TOL * w.abs().max(1e-3),
                    "{name} at {qi:?}: {} vs {w}",
                    p.value
                );
                if wse.is_finite() {
                    assert!(
                        (p.std_error / wse - 1.0).abs() < PARITY_SE_REL_TOL,
                        "{name} at {qi:?}: se {} vs {wse}",
                        p.std_error
                    );
                }
            }
        }
    }

    #[test]
    fn normal_quantile_is_accurate() {
        assert!((normal_quantile(0.975) - 1.959963984540054).abs() < 1e-8);
        assert!((normal_quantile(0.5)).abs() < 1e-12);
    }

    #[test]
    fn bad_input_is_rejected() {
        let x = vec![vec![0.0]; 3];
        assert!(matches!(
            Loess::fit(&x, &[1.0; 3], LoessConfig::default()),
            Err(LoessError::TooFewSamples { .. })
        ));
        let x: Vec<Vec<f64>> = (0..10).map(|i| vec![i as f64]).collect();
        let mut y = vec![1.0; 10];
        y[4] = f64::NAN;
        assert!(matches!(
            Loess::fit(&x, &y, LoessConfig::default()),
            Err(LoessError::NonFinite(4))
        ));
        assert!(matches!(
            Loess::fit(
                &x,
                &[1.0; 10],
                LoessConfig {
                    bandwidth: Bandwidth::Span(1.5),
                    ..LoessConfig::default()
                }
            ),
            Err(LoessError::BadBandwidth(_))
        ));
    }
}
