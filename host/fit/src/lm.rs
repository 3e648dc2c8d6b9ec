//! A bounded Levenberg-Marquardt solver specialised for BRDF channel fits.
//!
//! The residuals are `r_i = sqrt(w_i) (T(f(p; g_i)) - T(y_i))` with `T = ln(. + floor)` (log
//! space, the default: the data span several decades between the diffuse level and a specular
//! peak) or `r_i = sqrt(w_i) cos(theta_i) (f - y)` (cosine-weighted, i.e. a radiance error).
//! The cost is `0.5 sum r_i^2`.
//!
//! Each iteration forms `J^T J` and `J^T r` directly, in parallel over chunks of samples
//! (rayon), never storing `J`: memory is `O(n_params^2)` per thread, time `O(m n^2)`.
//! Steps solve `(J^T J + mu diag(J^T J)) d = -J^T r` (Marquardt scaling, Nielsen's damping
//! update); bounds are handled by projection plus an active set (parameters at a bound whose
//! gradient points outwards are frozen for the step). A trial point is evaluated together with
//! its Jacobian, so every iteration costs one pass over the data.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use skinbrdf_brdf::{ChannelModel, Geom, ParamBound};

/// Samples per parallel work item.
const CHUNK: usize = 8192;
/// Diagonal floor relative to the largest diagonal entry (keeps the damped system positive
/// definite when a parameter has no influence, e.g. a lobe whose base is negative everywhere).
const DIAG_FLOOR_REL: f64 = 1e-12;

/// How residuals are formed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ResidualKind {
    /// `ln(f + floor) - ln(max(y, 0) + floor)`: relative error, for data over many decades.
    Log {
        /// Additive floor in 1/sr (values far below it are not resolved).
        floor_rho: f64,
    },
    /// `cos(theta_i) (f - y)`: absolute error in reflected radiance per unit irradiance.
    CosineWeighted,
}

/// One channel's data, with the target already transformed.
#[derive(Debug, Clone, Copy)]
pub struct ChannelData<'a> {
    /// Geometry per sample.
    pub geom: &'a [Geom],
    /// Transformed target per sample (`ln(max(y,0) + floor)` or `cos_i * y`).
    pub target: &'a [f64],
    /// `sqrt(weight)` per sample.
    pub sqrt_w: &'a [f64],
    /// The residual form.
    pub residual: ResidualKind,
}

impl ChannelData<'_> {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.geom.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.geom.is_empty()
    }
}

/// Transforms raw values into the target of a residual kind.
pub fn transform_target(residual: ResidualKind, geom: &[Geom], y: &[f64]) -> Vec<f64> {
    match residual {
        ResidualKind::Log { floor_rho } => {
            y.iter().map(|&v| (v.max(0.0) + floor_rho).ln()).collect()
        }
        ResidualKind::CosineWeighted => geom.iter().zip(y).map(|(g, &v)| g.cos_i * v).collect(),
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LmStatus {
    /// The relative cost decrease fell below `ftol`.
    CostConverged,
    /// The projected gradient fell below `gtol`.
    GradientConverged,
    /// The step fell below `xtol`.
    StepConverged,
    /// The iteration limit was reached first.
    MaxIterations,
}

impl LmStatus {
    /// True for the converged states.
    pub fn converged(self) -> bool {
        self != Self::MaxIterations
    }
}

/// Solver settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LmConfig {
    /// Iteration limit.
    pub max_iterations: usize,
    /// Relative cost decrease that counts as converged.
    pub ftol: f64,
    /// Projected-gradient infinity norm (relative to `1 + cost`) that counts as converged.
    pub gtol: f64,
    /// Relative step that counts as converged.
    pub xtol: f64,
}

impl Default for LmConfig {
    fn default() -> Self {
        Self {
            max_iterations: 200,
            ftol: 1e-8,
            gtol: 1e-10,
            xtol: 1e-8,
        }
    }
}

/// The result of one solve.
#[derive(Debug, Clone)]
pub struct LmOutcome {
    /// Final parameters.
    pub params: Vec<f64>,
    /// Final cost `0.5 sum r^2`.
    pub cost: f64,
    /// Iterations taken.
    pub iterations: usize,
    /// Passes over the data.
    pub evaluations: usize,
    /// Why it stopped.
    pub status: LmStatus,
    /// `J^T J` at the solution (for uncertainties).
    pub jtj: DMatrix<f64>,
}

/// Cost, `J^T J` (full symmetric) and `J^T r` at `p`. Returns `None` if any residual is not finite.
pub fn accumulate(
    model: &dyn ChannelModel,
    p: &[f64],
    data: &ChannelData<'_>,
) -> Option<(f64, DMatrix<f64>, DVector<f64>)> {
    let n = model.n_params();
    let m = data.len();
    let n_chunks = m.div_ceil(CHUNK);
    let (cost, jtj, jtr) = (0..n_chunks)
        .into_par_iter()
        .map(|c| {
            let lo = c * CHUNK;
            let hi = (lo + CHUNK).min(m);
            let mut jtj = vec![0.0; n * n];
            let mut jtr = vec![0.0; n];
            let mut grad = vec![0.0; n];
            let mut cost = 0.0;
            for i in lo..hi {
                let g = &data.geom[i];
                let f = model.eval_grad(p, g, &mut grad);
                let sw = data.sqrt_w[i];
                let (r, scale) = match data.residual {
                    ResidualKind::Log { floor_rho } => {
                        let fp = f.max(0.0) + floor_rho;
                        (sw * (fp.ln() - data.target[i]), sw / fp)
                    }
                    ResidualKind::CosineWeighted => {
                        (sw * (g.cos_i * f - data.target[i]), sw * g.cos_i)
                    }
                };
                cost += r * r;
                for a in 0..n {
                    let ja = grad[a] * scale;
                    jtr[a] += ja * r;
                    let row = &mut jtj[a * n..a * n + n];
                    for b in a..n {
                        row[b] += ja * grad[b] * scale;
                    }
                }
            }
            (cost, jtj, jtr)
        })
        .reduce(
            || (0.0, vec![0.0; n * n], vec![0.0; n]),
            |mut x, y| {
                x.0 += y.0;
                x.1.iter_mut().zip(&y.1).for_each(|(a, b)| *a += b);
                x.2.iter_mut().zip(&y.2).for_each(|(a, b)| *a += b);
                x
            },
        );
    if !cost.is_finite() || !jtr.iter().all(|v| v.is_finite()) || !jtj.iter().all(|v| v.is_finite())
    {
        return None;
    }
    let mut a = DMatrix::from_row_slice(n, n, &jtj);
    for r in 0..n {
        for c in 0..r {
            a[(r, c)] = a[(c, r)];
        }
    }
    Some((0.5 * cost, a, DVector::from_vec(jtr)))
}

/// Cost only (no Jacobian), in parallel.
pub fn cost(model: &dyn ChannelModel, p: &[f64], data: &ChannelData<'_>) -> f64 {
    let m = data.len();
    0.5 * (0..m.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let (lo, hi) = (c * CHUNK, ((c + 1) * CHUNK).min(m));
            (lo..hi)
                .map(|i| {
                    let g = &data.geom[i];
                    let f = model.eval(p, g);
                    let r = match data.residual {
                        ResidualKind::Log { floor_rho } => {
                            (f.max(0.0) + floor_rho).ln() - data.target[i]
                        }
                        ResidualKind::CosineWeighted => g.cos_i * f - data.target[i],
                    } * data.sqrt_w[i];
                    r * r
                })
                .sum::<f64>()
        })
        .sum::<f64>()
}

/// Parameters frozen for a step: at a bound with the descent direction pointing outwards.
fn active_set(p: &[f64], g: &DVector<f64>, bounds: &[ParamBound]) -> Vec<bool> {
    p.iter()
        .zip(bounds)
        .enumerate()
        .map(|(j, (&v, b))| (v <= b.lo && g[j] > 0.0) || (v >= b.hi && g[j] < 0.0))
        .collect()
}

/// Minimises the cost from `p0` within the model's bounds. Returns `None` when the cost is not
/// finite at the (clamped) start.
pub fn solve(
    model: &dyn ChannelModel,
    p0: &[f64],
    data: &ChannelData<'_>,
    cfg: &LmConfig,
) -> Option<LmOutcome> {
    let bounds = model.bounds();
    let n = model.n_params();
    let mut p: Vec<f64> = p0.iter().zip(&bounds).map(|(v, b)| b.clamp(*v)).collect();
    let (mut f, mut a, mut g) = accumulate(model, &p, data)?;
    let mut evaluations = 1;
    // Damping is relative to diag(J^T J) (Marquardt scaling), so mu is dimensionless.
    let mut mu = 1e-3;
    let mut nu = 2.0;
    let mut status = LmStatus::MaxIterations;
    let mut iterations = 0;
    while iterations < cfg.max_iterations {
        iterations += 1;
        let frozen = active_set(&p, &g, &bounds);
        let pg = (0..n)
            .filter(|&j| !frozen[j])
            .map(|j| g[j].abs())
            .fold(0.0, f64::max);
        if pg <= cfg.gtol * (1.0 + f) {
            status = LmStatus::GradientConverged;
            break;
        }
        let max_diag = (0..n).map(|j| a[(j, j)]).fold(0.0f64, f64::max).max(1e-300);
        let mut sys = a.clone();
        let mut rhs = -g.clone();
        for j in 0..n {
            let d = a[(j, j)].max(DIAG_FLOOR_REL * max_diag);
            sys[(j, j)] += mu * d;
            if frozen[j] {
                for k in 0..n {
                    sys[(j, k)] = 0.0;
                    sys[(k, j)] = 0.0;
                }
                sys[(j, j)] = 1.0;
                rhs[j] = 0.0;
            }
        }
        let Some(chol) = sys.cholesky() else {
            mu *= nu;
            nu *= 2.0;
            continue;
        };
        let step = chol.solve(&rhs);
        let p_new: Vec<f64> = (0..n).map(|j| bounds[j].clamp(p[j] + step[j])).collect();
        let d = DVector::from_iterator(n, (0..n).map(|j| p_new[j] - p[j]));
        let p_norm = p.iter().map(|v| v * v).sum::<f64>().sqrt();
        if d.norm() <= cfg.xtol * (p_norm + cfg.xtol) {
            status = LmStatus::StepConverged;
            break;
        }
        let predicted = -(d.dot(&g) + 0.5 * d.dot(&(&a * &d)));
        let trial = accumulate(model, &p_new, data);
        evaluations += 1;
        match trial {
            Some((f_new, a_new, g_new)) if f_new < f && predicted > 0.0 => {
                let rho = (f - f_new) / predicted;
                let decrease = f - f_new;
                p = p_new;
                f = f_new;
                a = a_new;
                g = g_new;
                mu *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
                nu = 2.0;
                if decrease <= cfg.ftol * f.max(1e-300) {
                    status = LmStatus::CostConverged;
                    break;
                }
            }
            _ => {
                mu *= nu;
                nu *= 2.0;
                if !mu.is_finite() || mu > 1e30 {
                    // The damped step is vanishingly small: no descent is possible from here.
                    status = LmStatus::StepConverged;
                    break;
                }
            }
        }
    }
    Some(LmOutcome {
        params: p,
        cost: f,
        iterations,
        evaluations,
        status,
        jtj: a,
    })
}
