//! A small dense Levenberg-Marquardt solver with a robust (Huber) loss and covariance.
//!
//! Residuals come in pairs (the x and y reprojection error of one image point, already divided by
//! the point's standard deviation). The Huber loss acts on the pair's norm `s`:
//! `ρ(s) = s²` for `s ≤ k`, `2ks − k²` beyond, applied by iteratively reweighted least squares
//! (weight `k/s` outside the core). Steps are accepted only when the robust cost decreases, so
//! the result is never worse than the input. The Jacobian is taken by central differences
//! (problems here have at most a few hundred parameters).
//!
//! Covariance: `Σ = (JᵀWJ)⁻¹ σ̂²` with the a-posteriori variance factor
//! `σ̂² = Σ w r² / (m − n)`, so the stated uncertainty follows the actual residual scatter even
//! when the per-point sigmas are mis-stated. The condition number of the column-scaled normal
//! matrix is reported for the degeneracy checks.

use nalgebra::{DMatrix, DVector};

/// Solver settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmConfig {
    /// Maximum number of accepted iterations.
    pub max_iterations: usize,
    /// Huber threshold in whitened units (standard deviations); `None` = plain least squares.
    pub huber_k: Option<f64>,
    /// Relative cost decrease below which the solver stops.
    pub cost_tolerance: f64,
}

impl LmConfig {
    /// Defaults for pose problems.
    pub const DEFAULT: Self = Self {
        max_iterations: 100,
        huber_k: Some(3.0),
        cost_tolerance: 1e-12,
    };
}

impl Default for LmConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The solver's result.
#[derive(Debug, Clone)]
pub struct LmResult {
    /// The best parameters found (the input if no step improved it).
    pub x: DVector<f64>,
    /// Robust cost at `x` (sum of ρ over pairs).
    pub cost: f64,
    /// Robust cost at the input.
    pub initial_cost: f64,
    /// Residuals at `x` (whitened).
    pub residuals: DVector<f64>,
    /// Accepted iterations.
    pub iterations: usize,
    /// Covariance of the parameters (`None` when the normal matrix is singular).
    pub covariance: Option<DMatrix<f64>>,
    /// Condition number of the column-scaled normal matrix.
    pub condition_number: f64,
    /// A-posteriori variance factor σ̂² (1 when the sigmas are right).
    pub variance_factor: f64,
}

fn pair_weights(r: &DVector<f64>, k: Option<f64>) -> (Vec<f64>, f64) {
    let mut w = Vec::with_capacity(r.len() / 2 + 1);
    let mut cost = 0.0;
    let mut i = 0;
    while i < r.len() {
        let s2 = if i + 1 < r.len() {
            r[i] * r[i] + r[i + 1] * r[i + 1]
        } else {
            r[i] * r[i]
        };
        let s = s2.sqrt();
        match k {
            Some(k) if s > k => {
                w.push(k / s);
                cost += 2.0 * k * s - k * k;
            }
            _ => {
                w.push(1.0);
                cost += s2;
            }
        }
        i += 2;
    }
    (w, cost)
}

fn numeric_jacobian<F>(f: &F, x: &DVector<f64>, m: usize) -> Option<DMatrix<f64>>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>>,
{
    let n = x.len();
    let mut j = DMatrix::zeros(m, n);
    let mut xp = x.clone();
    for c in 0..n {
        let h = 1e-6 * x[c].abs().max(1e-2);
        xp[c] = x[c] + h;
        let rp = f(&xp)?;
        xp[c] = x[c] - h;
        let rm = f(&xp)?;
        xp[c] = x[c];
        if rp.len() != m || rm.len() != m {
            return None;
        }
        let col = (rp - rm) / (2.0 * h);
        j.set_column(c, &col);
    }
    Some(j)
}

/// Minimises `Σ ρ(‖r_pair‖)` for the residual function `f` starting at `x0`. Returns `None` when
/// `f` fails at `x0`.
pub fn minimize<F>(f: F, x0: DVector<f64>, cfg: &LmConfig) -> Option<LmResult>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>>,
{
    let n = x0.len();
    let mut x = x0;
    let mut r = f(&x)?;
    let m = r.len();
    let (mut w, mut cost) = pair_weights(&r, cfg.huber_k);
    let initial_cost = cost;
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let weighted = |j: &DMatrix<f64>, r: &DVector<f64>, w: &[f64]| {
        let mut jw = j.clone();
        let mut rw = r.clone();
        for i in 0..m {
            let s = w[i / 2].sqrt();
            rw[i] *= s;
            for c in 0..n {
                jw[(i, c)] *= s;
            }
        }
        (jw, rw)
    };
    for _ in 0..cfg.max_iterations {
        let Some(j) = numeric_jacobian(&f, &x, m) else {
            break;
        };
        let (jw, rw) = weighted(&j, &r, &w);
        let a = jw.transpose() * &jw;
        let g = jw.transpose() * &rw;
        let mut accepted = false;
        for _ in 0..12 {
            let mut ad = a.clone();
            for c in 0..n {
                ad[(c, c)] += lambda * a[(c, c)].max(1e-12);
            }
            let Some(chol) = ad.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let delta = chol.solve(&(-&g));
            let xn = &x + &delta;
            if let Some(rn) = f(&xn) {
                let (wn, cn) = pair_weights(&rn, cfg.huber_k);
                if cn.is_finite() && cn < cost {
                    let rel = (cost - cn) / cost.max(1e-300);
                    x = xn;
                    r = rn;
                    w = wn;
                    cost = cn;
                    lambda = (lambda / 3.0).max(1e-12);
                    accepted = true;
                    iterations += 1;
                    if rel < cfg.cost_tolerance {
                        return Some(finish(&f, x, r, w, cost, initial_cost, iterations));
                    }
                    break;
                }
            }
            lambda *= 4.0;
        }
        if !accepted {
            break;
        }
    }
    Some(finish(&f, x, r, w, cost, initial_cost, iterations))
}

fn finish<F>(
    f: &F,
    x: DVector<f64>,
    r: DVector<f64>,
    w: Vec<f64>,
    cost: f64,
    initial_cost: f64,
    iterations: usize,
) -> LmResult
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>>,
{
    let m = r.len();
    let n = x.len();
    let mut covariance = None;
    let mut condition_number = f64::INFINITY;
    let mut variance_factor = 1.0;
    if let Some(j) = numeric_jacobian(f, &x, m) {
        let mut jw = j;
        let mut wr2 = 0.0;
        for i in 0..m {
            let s = w[i / 2].sqrt();
            wr2 += w[i / 2] * r[i] * r[i];
            for c in 0..n {
                jw[(i, c)] *= s;
            }
        }
        let a = jw.transpose() * &jw;
        // Column scaling makes the condition number unit-free.
        let d: Vec<f64> = (0..n).map(|c| a[(c, c)].max(1e-300).sqrt()).collect();
        let mut s = a.clone();
        for i in 0..n {
            for k in 0..n {
                s[(i, k)] /= d[i] * d[k];
            }
        }
        let eig = s.symmetric_eigenvalues();
        let (lo, hi) = eig.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &e| {
            (lo.min(e), hi.max(e))
        });
        condition_number = if lo > 0.0 { hi / lo } else { f64::INFINITY };
        if m > n {
            variance_factor = wr2 / (m - n) as f64;
        }
        if condition_number < 1e15 {
            if let Some(inv) = a.try_inverse() {
                covariance = Some(inv * variance_factor);
            }
        }
    }
    LmResult {
        x,
        cost,
        initial_cost,
        residuals: r,
        iterations,
        covariance,
        condition_number,
        variance_factor,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_a_line_and_ignores_an_outlier_with_huber() {
        // y = 2x + 1 sampled at 20 points, one gross outlier; residual pairs (r, 0).
        let xs: Vec<f64> = (0..20).map(|i| i as f64 * 0.1).collect();
        let mut ys: Vec<f64> = xs.iter().map(|x| 2.0 * x + 1.0).collect();
        ys[7] += 50.0;
        let f = |p: &DVector<f64>| {
            let mut r = DVector::zeros(xs.len() * 2);
            for (i, (x, y)) in xs.iter().zip(&ys).enumerate() {
                r[2 * i] = (p[0] * x + p[1] - y) / 0.01;
            }
            Some(r)
        };
        let res = minimize(f, DVector::from_vec(vec![0.0, 0.0]), &LmConfig::DEFAULT)
            .expect("residuals evaluate");
        assert!((res.x[0] - 2.0).abs() < 5e-3, "{}", res.x);
        assert!((res.x[1] - 1.0).abs() < 5e-3);
        assert!(res.cost <= res.initial_cost);
        assert!(res.covariance.is_some());
    }

    #[test]
    fn never_returns_worse_than_the_input() {
        // Start at the optimum: the result must be the input.
        let f = |p: &DVector<f64>| Some(DVector::from_vec(vec![p[0] - 3.0, 0.0]));
        let res = minimize(f, DVector::from_vec(vec![3.0]), &LmConfig::DEFAULT).expect("ok");
        assert_eq!(res.x[0], 3.0);
        assert!(res.cost <= res.initial_cost);
    }
}
