//! Lines fitted to edge points, and the quadrilaterals they bound (shared by the quad fit, the
//! edge refinement and the refits after decoding).

use glam::DVec2;

/// A line `n · x = d` with unit normal `n`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Line {
    pub(crate) n: DVec2,
    pub(crate) d: f64,
    /// Centroid of the fitted points and their spread along the line (for the covariance).
    pub(crate) centroid: DVec2,
    pub(crate) sum_t2: f64,
    pub(crate) count: f64,
    /// Scatter of the fitted points about the line, pixels.
    pub(crate) sigma: f64,
    /// What the points' scatter is multiplied by, in variance, for the line's offset and tilt:
    /// more than 1 when neighbouring points' errors are correlated (`allow_for_correlation`).
    pub(crate) var_factor: f64,
    /// `[α, β, var_b]`: the line was moved by `b (α + β t)` at `t` (from the centroid, along
    /// the line) to undo the tag's inner-edge bias `b` (`unbias_inner_edges`), so its offset
    /// there is uncertain by `(α + β t)² var_b` more. Zero when not corrected.
    pub(crate) bias_var: [f64; 3],
}

impl Line {
    pub(crate) fn dir(&self) -> DVec2 {
        DVec2::new(-self.n.y, self.n.x)
    }
    pub(crate) fn intersect(&self, o: &Line) -> Option<DVec2> {
        let det = self.n.x * o.n.y - self.n.y * o.n.x;
        if det.abs() < 1e-9 {
            return None;
        }
        Some(DVec2::new(
            (self.d * o.n.y - self.n.y * o.d) / det,
            (self.n.x * o.d - self.d * o.n.x) / det,
        ))
    }
    /// Variance of the line's offset along its normal at point `p`.
    pub(crate) fn offset_var_at(&self, p: DVec2) -> f64 {
        let t = (p - self.centroid).dot(self.dir());
        let s2 = self.sigma * self.sigma * self.var_factor;
        let [alpha, beta, var_b] = self.bias_var;
        s2 / self.count.max(1.0)
            + s2 * t * t / self.sum_t2.max(1e-9)
            + (alpha + beta * t).powi(2) * var_b
    }
}

/// Weighted total-least-squares line through points.
pub(crate) fn fit_line(pts: &[(DVec2, f64)]) -> Option<Line> {
    let wsum: f64 = pts.iter().map(|p| p.1).sum();
    if pts.len() < 2 || wsum <= 0.0 {
        return None;
    }
    let c = pts.iter().map(|(p, w)| *p * *w).sum::<DVec2>() / wsum;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for (p, w) in pts {
        let d = *p - c;
        sxx += w * d.x * d.x;
        sxy += w * d.x * d.y;
        syy += w * d.y * d.y;
    }
    // Direction = principal eigenvector of the scatter matrix.
    let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let dir = DVec2::new(theta.cos(), theta.sin());
    let n = DVec2::new(-dir.y, dir.x);
    let mut res2 = 0.0;
    let mut sum_t2 = 0.0;
    for (p, w) in pts {
        let r = (*p - c).dot(n);
        res2 += w * r * r;
        let t = (*p - c).dot(dir);
        sum_t2 += t * t;
    }
    let count = pts.len() as f64;
    let dof = (count - 2.0).max(1.0);
    let sigma = (res2 / wsum * count / dof).sqrt();
    Some(Line {
        n,
        d: n.dot(c),
        centroid: c,
        sum_t2,
        count,
        sigma,
        var_factor: 1.0,
        bias_var: [0.0; 3],
    })
}

pub(crate) fn signed_area(q: &[DVec2; 4]) -> f64 {
    let mut a = 0.0;
    for i in 0..4 {
        let (p, r) = (q[i], q[(i + 1) % 4]);
        a += p.x * r.y - r.x * p.y;
    }
    0.5 * a
}

pub(crate) fn is_convex(q: &[DVec2; 4]) -> bool {
    let mut sign = 0.0;
    for i in 0..4 {
        let a = q[(i + 1) % 4] - q[i];
        let b = q[(i + 2) % 4] - q[(i + 1) % 4];
        let c = a.perp_dot(b);
        if c.abs() < 1e-9 || (sign != 0.0 && c.signum() != sign) {
            return false;
        }
        sign = c.signum();
    }
    true
}

/// The corners of the quad bounded by four lines, corner `k` where side `k - 1` meets side `k`;
/// `None` when adjacent sides are parallel.
pub(crate) fn quad_corners(lines: &[Line]) -> Option<[DVec2; 4]> {
    let mut q = [DVec2::ZERO; 4];
    for k in 0..4 {
        q[k] = lines[(k + 3) % 4].intersect(&lines[k])?;
    }
    Some(q)
}
