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
use skinbrdf_brdf::lafortune::MAX_LOG_VALUE;
use skinbrdf_brdf::{BrdfModel, ChannelModel, Geom, Lafortune, LafortuneLobe, ParamBound};

/// Samples per parallel work item.
const CHUNK: usize = 8192;
/// Diagonal floor relative to the largest diagonal entry (keeps the damped system positive
/// definite when a parameter has no influence, e.g. a lobe whose base is negative everywhere).
const DIAG_FLOOR_REL: f64 = 1e-12;

/// Gain ratio (actual / predicted decrease) above which the last step shows the quadratic model
/// to be accurate (Nielsen's damping update treats `rho > 0.5` as a good step).
const TRUSTED_GAIN_RATIO: f64 = 0.5;
/// Damping below which a step is close to the Gauss-Newton step (so its predicted decrease bounds
/// what any step can gain).
const TRUSTED_MU: f64 = 1e-2;

/// The predicted-decrease stop demands a predicted decrease this much below `ftol` (the confirmed
/// stop uses `ftol` itself): the final cost then matches a fully confirmed solve to ~1e-12
/// relative while saving the confirming pass over the data.
const PREDICTED_STOP_REL: f64 = 1e-4;

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
        ResidualKind::Log { floor_rho } => y
            .par_iter()
            .map(|&v| (v.max(0.0) + floor_rho).ln())
            .collect(),
        ResidualKind::CosineWeighted => geom.par_iter().zip(y).map(|(g, &v)| g.cos_i * v).collect(),
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

impl std::fmt::Display for LmStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::CostConverged => "cost converged",
            Self::GradientConverged => "gradient converged",
            Self::StepConverged => "step converged",
            Self::MaxIterations => "iteration limit",
        })
    }
}

impl std::fmt::Display for ResidualKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Log { floor_rho } => write!(f, "log, floor {floor_rho} 1/sr"),
            Self::CosineWeighted => f.write_str("cosine-weighted"),
        }
    }
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

/// The model evaluator of one solve: a specialised kernel for the Lafortune model (its
/// per-lobe constants `n`, `ln((n+2)/2pi) + ln A` hoisted out of the sample loop, so a lobe
/// costs one `ln` and one `exp` per sample instead of three `exp` and two `ln`), or the model's
/// own [`ChannelModel::eval_grad`] for every other model.
#[derive(Debug, Clone)]
pub(crate) enum Kernel<'m> {
    /// [`skinbrdf_brdf::LafortuneFit`] with the given lobe signs `s_k = sign(Cz_k)`.
    Lafortune {
        /// The model (for bounds and names).
        model: &'m dyn ChannelModel,
        /// `s_k` per lobe.
        signs: Vec<f64>,
    },
    /// Any model, through the trait.
    Generic(&'m dyn ChannelModel),
}

/// Relative tolerance of the kernel self-check against the model's own evaluation (both compute
/// the same expression in a different order: a few ulps, amplified by `n ln b` for large `n`).
const KERNEL_CHECK_REL: f64 = 1e-9;

impl<'m> Kernel<'m> {
    /// Detects the Lafortune structure (`lafortuneK`, `1 + 3K` parameters, lobe signs found
    /// through [`ChannelModel::params_from_model`], which accepts only the model's own signs)
    /// and checks the specialised kernel against the model at `p` on a few geometries; falls
    /// back to the generic path on any mismatch.
    pub(crate) fn new(model: &'m dyn ChannelModel, p: &[f64]) -> Self {
        Self::detect_lafortune(model, p).unwrap_or(Self::Generic(model))
    }

    fn detect_lafortune(model: &'m dyn ChannelModel, p: &[f64]) -> Option<Self> {
        let k: usize = model.name().strip_prefix("lafortune")?.parse().ok()?;
        if k == 0 || k > 3 || model.n_params() != 1 + 3 * k || p.len() != 1 + 3 * k {
            return None;
        }
        let signs = (0..1u32 << k).find_map(|mask| {
            let signs: Vec<f64> = (0..k)
                .map(|j| if mask >> j & 1 == 1 { -1.0 } else { 1.0 })
                .collect();
            let probe = BrdfModel::Lafortune(Lafortune {
                diffuse_albedo: [0.5; 3],
                lobes: signs
                    .iter()
                    .map(|&s| LafortuneLobe {
                        cxy: [0.0; 3],
                        cz: [s; 3],
                        exponent: [2.0; 3],
                    })
                    .collect(),
            });
            model.params_from_model(&probe, 0).map(|_| signs)
        })?;
        let kernel = Self::Lafortune { model, signs };
        let prep = kernel.prepare(p);
        let n = model.n_params();
        let (mut ga, mut gb) = (vec![0.0; n], vec![0.0; n]);
        for (ti, te, pd) in [
            (0.3, 0.35, 3.0),
            (0.9, 0.2, 0.4),
            (1.2, 1.3, 2.9),
            (0.0, 0.6, 1.0),
        ] {
            let g = Geom::from_angles(ti, te, pd);
            let a = prep.eval_grad(&g, &mut ga);
            let b = model.eval_grad(p, &g, &mut gb);
            let close =
                |x: f64, y: f64| (x - y).abs() <= KERNEL_CHECK_REL * x.abs().max(y.abs()) + 1e-300;
            if !close(a, b) || !ga.iter().zip(&gb).all(|(x, y)| close(*x, *y)) {
                return None;
            }
        }
        Some(kernel)
    }

    fn model(&self) -> &'m dyn ChannelModel {
        match self {
            Self::Lafortune { model, .. } | Self::Generic(model) => *model,
        }
    }

    fn prepare<'p>(&self, p: &'p [f64]) -> Prepared<'m, 'p> {
        match self {
            Self::Lafortune { signs, .. } => Prepared::Lafortune(LafortuneKernel {
                albedo_term: p[0] * std::f64::consts::FRAC_1_PI,
                lobes: signs
                    .iter()
                    .enumerate()
                    .map(|(k, &s)| {
                        let (ln_a, t, ln_n) = (p[1 + 3 * k], p[2 + 3 * k], p[3 + 3 * k]);
                        let n = ln_n.exp();
                        LobeConst {
                            s,
                            t,
                            n,
                            log_norm: ln_a + ((n + 2.0) * (0.5 * std::f64::consts::FRAC_1_PI)).ln(),
                            n_over_n2: n / (n + 2.0),
                        }
                    })
                    .collect(),
            }),
            Self::Generic(model) => Prepared::Generic(*model, p),
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct LobeConst {
    s: f64,
    t: f64,
    n: f64,
    log_norm: f64,
    n_over_n2: f64,
}

#[derive(Debug, Clone)]
struct LafortuneKernel {
    albedo_term: f64,
    lobes: Vec<LobeConst>,
}

impl LafortuneKernel {
    /// The same expression as `LafortuneFit::eval_grad` (see its docs), per-lobe constants
    /// precomputed.
    #[inline]
    fn eval_grad(&self, g: &Geom, grad: &mut [f64]) -> f64 {
        grad[0] = std::f64::consts::FRAC_1_PI;
        let mut v_sum = self.albedo_term;
        for (l, gr) in self.lobes.iter().zip(grad[1..].chunks_exact_mut(3)) {
            let b = l.s * g.dz + l.t * g.dxy;
            if b <= 0.0 {
                gr.fill(0.0);
                continue;
            }
            let lb = b.ln();
            let e = l.log_norm + l.n * lb;
            if e > MAX_LOG_VALUE {
                gr.fill(0.0);
                v_sum += MAX_LOG_VALUE.exp();
                continue;
            }
            let v = e.exp();
            gr[0] = v;
            // v n dxy / b; for a subnormal v fall back to b^(n-1) without the division.
            gr[1] = if v > f64::MIN_POSITIVE {
                l.n * g.dxy * (v / b)
            } else {
                l.n * g.dxy * (l.log_norm + (l.n - 1.0) * lb).exp()
            };
            gr[2] = v * (l.n_over_n2 + l.n * lb);
            v_sum += v;
        }
        v_sum
    }

    #[inline]
    fn eval(&self, g: &Geom) -> f64 {
        let mut v_sum = self.albedo_term;
        for l in &self.lobes {
            let b = l.s * g.dz + l.t * g.dxy;
            if b > 0.0 {
                v_sum += (l.log_norm + l.n * b.ln()).min(MAX_LOG_VALUE).exp();
            }
        }
        v_sum
    }
}

enum Prepared<'m, 'p> {
    Lafortune(LafortuneKernel),
    Generic(&'m dyn ChannelModel, &'p [f64]),
}

impl Prepared<'_, '_> {
    #[inline]
    fn eval_grad(&self, g: &Geom, grad: &mut [f64]) -> f64 {
        match self {
            Self::Lafortune(k) => k.eval_grad(g, grad),
            Self::Generic(m, p) => m.eval_grad(p, g, grad),
        }
    }
}

/// Cost, `J^T J` (full symmetric) and `J^T r` at `p`. Returns `None` if any residual is not finite.
pub fn accumulate(
    model: &dyn ChannelModel,
    p: &[f64],
    data: &ChannelData<'_>,
) -> Option<(f64, DMatrix<f64>, DVector<f64>)> {
    accumulate_with(&Kernel::new(model, p), p, data)
}

/// Per-chunk partial sums: cost, upper triangle of `J^T J` (row-major n x n), `J^T r`.
struct Partial {
    cost: f64,
    jtj: Vec<f64>,
    jtr: Vec<f64>,
}

fn accumulate_chunk(
    eval_grad: impl Fn(&Geom, &mut [f64]) -> f64,
    n: usize,
    data: &ChannelData<'_>,
    lo: usize,
    hi: usize,
) -> Partial {
    let mut jtj = vec![0.0; n * n];
    let mut jtr = vec![0.0; n];
    let mut grad = vec![0.0; n];
    let mut cost = 0.0;
    for i in lo..hi {
        let g = &data.geom[i];
        let f = eval_grad(g, &mut grad);
        let sw = data.sqrt_w[i];
        let (r, scale) = match data.residual {
            ResidualKind::Log { floor_rho } => {
                let fp = f.max(0.0) + floor_rho;
                (sw * (fp.ln() - data.target[i]), sw / fp)
            }
            ResidualKind::CosineWeighted => (sw * (g.cos_i * f - data.target[i]), sw * g.cos_i),
        };
        cost += r * r;
        for v in grad.iter_mut() {
            *v *= scale;
        }
        for a in 0..n {
            let ja = grad[a];
            jtr[a] += ja * r;
            let row = &mut jtj[a * n..a * n + n];
            for b in a..n {
                row[b] += ja * grad[b];
            }
        }
    }
    Partial { cost, jtj, jtr }
}

/// [`accumulate`] with a prepared kernel. Chunks are summed in a fixed order, so the result
/// does not depend on the thread schedule.
pub(crate) fn accumulate_with(
    kernel: &Kernel<'_>,
    p: &[f64],
    data: &ChannelData<'_>,
) -> Option<(f64, DMatrix<f64>, DVector<f64>)> {
    let n = kernel.model().n_params();
    let m = data.len();
    let prep = kernel.prepare(p);
    let parts: Vec<Partial> = (0..m.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let (lo, hi) = (c * CHUNK, ((c + 1) * CHUNK).min(m));
            match &prep {
                Prepared::Lafortune(k) => {
                    accumulate_chunk(|g, gr| k.eval_grad(g, gr), n, data, lo, hi)
                }
                Prepared::Generic(model, p) => {
                    accumulate_chunk(|g, gr| model.eval_grad(p, g, gr), n, data, lo, hi)
                }
            }
        })
        .collect();
    let mut cost = 0.0;
    let mut jtj = vec![0.0; n * n];
    let mut jtr = vec![0.0; n];
    for part in &parts {
        cost += part.cost;
        jtj.iter_mut().zip(&part.jtj).for_each(|(a, b)| *a += b);
        jtr.iter_mut().zip(&part.jtr).for_each(|(a, b)| *a += b);
    }
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

/// Model values at every sample for parameters `p` (the specialised kernel where it applies),
/// in parallel.
pub fn eval_all(model: &dyn ChannelModel, p: &[f64], geom: &[Geom]) -> Vec<f64> {
    let kernel = Kernel::new(model, p);
    let prep = kernel.prepare(p);
    match &prep {
        Prepared::Lafortune(k) => geom.par_iter().map(|g| k.eval(g)).collect(),
        Prepared::Generic(m, p) => geom.par_iter().map(|g| m.eval(p, g)).collect(),
    }
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
    let kernel = Kernel::new(model, &p);
    let (mut f, mut a, mut g) = accumulate_with(&kernel, &p, data)?;
    let mut evaluations = 1;
    // Damping is relative to diag(J^T J) (Marquardt scaling), so mu is dimensionless.
    let mut mu = 1e-3;
    let mut nu = 2.0;
    // Gain ratio of the last accepted step (0 = none yet): the quadratic model is trusted for
    // the predicted-decrease stop only after a step it predicted well.
    let mut last_rho = 0.0;
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
        // MINPACK-style predicted-reduction test: when the last step was predicted well, the
        // damping is small and this step cannot lower the cost by more than ftol relative, stop
        // without paying a pass over the data to confirm it.
        if last_rho > TRUSTED_GAIN_RATIO
            && mu <= TRUSTED_MU
            && predicted <= PREDICTED_STOP_REL * cfg.ftol * f.max(1e-300)
        {
            status = LmStatus::CostConverged;
            break;
        }
        let trial = accumulate_with(&kernel, &p_new, data);
        evaluations += 1;
        match trial {
            Some((f_new, a_new, g_new)) if f_new < f && predicted > 0.0 => {
                let rho = (f - f_new) / predicted;
                last_rho = rho;
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use skinbrdf_brdf::{CookTorranceFit, LafortuneFit, LobeSpec};

    fn lafortune_with(signs: &[bool]) -> LafortuneFit {
        LafortuneFit {
            lobes: signs
                .iter()
                .map(|&cz_negative| LobeSpec { cz_negative })
                .collect(),
        }
    }

    #[test]
    fn the_lafortune_kernel_is_chosen_only_for_lafortune_models() {
        for signs in [&[false][..], &[true], &[false, true], &[true, false, true]] {
            let m = lafortune_with(signs);
            let p: Vec<f64> = std::iter::once(0.3)
                .chain(signs.iter().flat_map(|_| [-1.0, -0.7, 2.0]))
                .collect();
            match Kernel::new(&m, &p) {
                Kernel::Lafortune { signs: s, .. } => {
                    let want: Vec<f64> =
                        signs.iter().map(|&n| if n { -1.0 } else { 1.0 }).collect();
                    assert_eq!(s, want);
                }
                Kernel::Generic(_) => panic!("{signs:?}: not detected"),
            }
        }
        let ct = CookTorranceFit::default();
        assert!(matches!(
            Kernel::new(&ct, &[0.3, 0.5, -1.0]),
            Kernel::Generic(_)
        ));
    }

    proptest! {
        #[test]
        fn the_lafortune_kernel_matches_the_model(
            ad in 0.0..1.0f64, ln_a in -18.0..3.0f64, t in -3.0..3.0f64, ln_n in 0.0..9.9f64,
            ln_a2 in -18.0..3.0f64, t2 in -3.0..3.0f64, ln_n2 in 0.0..9.9f64, neg in any::<bool>(),
            ti in 0.0..1.57f64, te in 0.0..1.57f64, pd in 0.0..std::f64::consts::PI,
        ) {
            let m = lafortune_with(&[false, neg]);
            let p = [ad, ln_a, t, ln_n, ln_a2, t2, ln_n2];
            let kernel = Kernel::new(&m, &p);
            let specialised = matches!(kernel, Kernel::Lafortune { .. });
            prop_assert!(specialised);
            let prep = kernel.prepare(&p);
            let Prepared::Lafortune(k) = &prep else {
                return Err(TestCaseError::fail("generic"));
            };
            let g = Geom::from_angles(ti, te, pd);
            let (mut ga, mut gb) = ([0.0; 7], [0.0; 7]);
            let a = k.eval_grad(&g, &mut ga);
            let b = m.eval_grad(&p, &g, &mut gb);
            let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * x.abs().max(y.abs()) + 1e-300;
            prop_assert!(close(a, b), "value {a} vs {b}");
            prop_assert!(close(k.eval(&g), m.eval(&p, &g)));
            for j in 0..7 {
                prop_assert!(close(ga[j], gb[j]), "grad {j}: {} vs {}", ga[j], gb[j]);
            }
        }
    }

    #[test]
    fn chunk_sums_do_not_depend_on_the_thread_schedule() {
        let (_, samples) = crate::synthetic::lafortune2_samples(50_000, 0.05, 3);
        let data = crate::FitData::from_samples(&samples).expect("data");
        let residual = ResidualKind::Log { floor_rho: 1e-3 };
        let target = transform_target(residual, &data.geom, &data.y[1]);
        let cd = ChannelData {
            geom: &data.geom,
            target: &target,
            sqrt_w: &data.sqrt_w,
            residual,
        };
        let m = LafortuneFit::standard(2);
        let p = crate::synthetic::bench_truth_params()[1].clone();
        let a = accumulate(&m, &p, &cd).expect("finite");
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool");
        let b = pool.install(|| accumulate(&m, &p, &cd)).expect("finite");
        assert_eq!(a.0.to_bits(), b.0.to_bits());
        assert_eq!(a.1, b.1);
        assert_eq!(a.2, b.2);
        // And the generic path (through the trait) agrees with the kernel.
        let generic = accumulate_with(&Kernel::Generic(&m), &p, &cd).expect("finite");
        assert!((generic.0 - a.0).abs() <= 1e-10 * a.0);
    }
}
