//! Edge-profile refinement of small tags: each side's grey profile across the black border, the
//! one-cell white ring and what lies beyond, fitted as blurred steps.
//!
//! # Why
//!
//! The gradient-centroid edge of [`crate::detect`](mod@crate::detect) assumes the edge's
//! gradient lobe stands alone. On a tag whose cells are only 1.5..4 px wide, blur of a pixel or
//! more merges it with the lobes of the neighbouring edges a cell away: the inner edge of the
//! black border (towards white data cells) and the outer edge of the white ring (towards
//! whatever surrounds the tag).
//! A surround darker than the ring pulls the centroid inward (-0.15..-0.28 px at blur 1..1.5
//! px), a surround brighter than the ring pushes it outward (+0.3..+0.67 px), as measured in
//! docs/benchmarks-poses.md. Modelling the neighbours removes that.
//!
//! # Model
//!
//! Along the outward normal `s` of a side, at each of up to 16 positions along it, the grey
//! level is four plateaus separated by three edges blurred by one Gaussian of width `σ` (optics,
//! pixel area and interpolation together):
//!
//! ```text
//! I(s) = L_in (1 - Φ(z₁)) + L_b (Φ(z₁) - Φ(z₂)) + L_r (Φ(z₂) - Φ(z₃)) + L_o Φ(z₃)
//! z₁ = (s - e + c_in) / σ,   z₂ = (s - e) / σ,   z₃ = (s - e - m c_out) / σ
//! ```
//!
//! with `c_in`, `c_out` the widths of one cell inward and outward at that position (through the
//! tag's homography, so perspective is allowed for; the black border is exactly one cell), `m`
//! the width of the light margin in cells, `e` the edge we want (one offset for the whole side
//! from the gradient-centroid line) and four levels per position: the data cell inside (which
//! may be black too), the border, the ring and the surround (which may be white too: its step
//! is then zero). The levels enter linearly, so they are solved in closed form for any
//! `(e, σ)` (variable projection, Kaufman's Jacobian) and Levenberg-Marquardt runs on those two
//! only, from the gradient-centroid edge and a pixel of blur. The margin is a tag36h11 print's
//! one-cell ring, often widened by the paper around it: `m` = 1, 2 and 3 cells are each fitted
//! and the lowest cost wins. The samples reach 1.75 cells inward and 3.25 cells + 1 px outward,
//! every 0.5 px.
//!
//! Tried and dropped, each measured: a free margin width (under blur a wider, dimmer ring looks
//! like a narrower, brighter one and the edge traded off against it: the gains on dark
//! surrounds halved); a tilt of the edge along the side (on oblique headdress tags it took
//! tilts of over a pixel from the surround's variation: a corner 0.8 px off where the centroid
//! was 0.12 px off).
//!
//! # Effect (unit test `detect::tests::profile_fit_removes_the_neighbouring_edges_bias`)
//!
//! Tags of 12..32 px at random rotations, 4 x 4 supersampled, Gaussian blur, ±0.01 noise;
//! corner RMS against truth, gradient centroid -> profile fit, px:
//!
//! | surround beyond the one-cell ring | blur 0.6 | blur 1.0 | blur 1.5 |
//! |---|---|---|---|
//! | dark (0.2) | 0.113 -> 0.066 | 0.249 -> 0.132 | 0.441 -> 0.255 |
//! | grey (0.55) | 0.077 -> 0.067 | 0.157 -> 0.152 | 0.288 -> 0.269 |
//! | bright (1.0), ring 0.7 | 0.172 -> 0.082 | 0.370 -> 0.148 | 0.809 -> 0.400 |
//!
//! The gradient centroid's figures include its small tags' refit without the border's
//! inner-edge pull ([`crate::detect`](mod@crate::detect), step 6), which takes off an outward
//! pull: on a dark surround that pull had partly cancelled the surround's inward one.
//!
//! # Why it is off by default
//!
//! [`crate::DetectorConfig::profile_small_tags`] is `false`: the gains above need blur of half a
//! pixel or more and a surround unlike the ring, and the pipeline's synthetic sessions have
//! neither (box-filtered pixels, two cells of white paper around each tag). There it is neutral
//! within the noise of the head poses: at half resolution (`cargo test -p skinbrdf-pipeline
//! --test scenes`, 12..14 head images per scene) the median head position error went from
//! 0.48 to 0.40 mm on `grazing`, 0.29 to 0.23 on `dark-skin`, 0.18 to 0.16 on
//! `strong-distortion`, but 0.14 to 0.25 on `head-motion`, 0.20 to 0.28 on `cylinder` and 0.29
//! to 0.33 on `default`; on the whole half-resolution `grazing` session (36 images) the
//! headdress corners' error against truth went from median 0.094 / p90 0.173 px to 0.091 /
//! 0.185 px (`skinbrdf poses` prints these). On the real test photos, where there is no truth,
//! it moves the corners by about a tenth of a pixel. So it is an option for images like the
//! unit test's (small tags, real blur, a dark or bright surround): `skinbrdf targets --detect
//! IMAGE --profile-small-tags`.
//!
//! # Guarantees
//!
//! The result replaces the gradient-centroid side only when the fit converged to a plausible
//! profile (edge moved less than [`MAX_SHIFT_PX`] and half a cell, its standard deviation under
//! [`MAX_EDGE_SD_PX`], blur within bounds); otherwise the side is left as it was.

// Small dense matrices are indexed by row and column; iterators would obscure the algebra.
#![allow(clippy::needless_range_loop)]

use crate::image::GrayF32;
use glam::DVec2;

/// Cells wider than this (pixels) are left to the gradient centroid: their edge lobes no longer
/// overlap at the blurs the detector meets, and it is already within hundredths of a pixel.
pub const MAX_CELL_PX: f64 = 4.0;

/// Largest accepted move of a side's edge from the gradient centroid, pixels (the biases this
/// removes are under 0.7 px).
pub const MAX_SHIFT_PX: f64 = 1.0;

/// Widths of the light margin around the black border tried, cells: the tag's own one-cell
/// ring, and paper extending it by one or two cells.
const RING_HYPOTHESES_CELLS: [f64; 3] = [1.0, 2.0, 3.0];

/// Largest accepted standard deviation of the fitted edge offset, pixels: a side whose profile
/// pins its edge less well than this (tiny cells, heavy blur, noise) keeps the gradient
/// centroid.
pub const MAX_EDGE_SD_PX: f64 = 0.05;

/// Sample spacing along the normal, pixels (half a pixel: the bilinear samples in between carry
/// little more).
const STEP_PX: f64 = 0.5;

/// Most positions sampled along a side.
const MAX_POSITIONS: usize = 16;

/// Accepted range of the fitted blur, pixels.
const SIGMA_RANGE_PX: (f64, f64) = (0.15, 4.0);

/// Standard normal cumulative distribution.
fn phi(z: f64) -> f64 {
    0.5 * libm::erfc(-z * std::f64::consts::FRAC_1_SQRT_2)
}

/// The profile across a side at one position.
struct Row {
    /// Width of the black border here (one cell inward, through the tag's homography), pixels.
    inner: f64,
    /// Width of the white ring here (one cell outward), pixels.
    outer: f64,
    /// Grey levels at the side's offsets.
    ys: Vec<f64>,
}

/// One side's sampled profiles.
struct Side {
    rows: Vec<Row>,
    /// Offsets along the outward normal, pixels.
    offsets: Vec<f64>,
    /// Width of the light margin (ring plus paper) in cells, for the hypothesis being fitted.
    ring_cells: f64,
}

impl Side {
    /// Residuals of the profile model with the levels solved per position, and (if `jac` is
    /// given) their Jacobian with respect to `(e, ln σ)` in Kaufman's variable
    /// projection form, `∂r/∂θ ≈ -(I - A A⁺) (∂A/∂θ) L`. `None` when a position's levels
    /// cannot be solved.
    fn evaluate(
        &self,
        p: &[f64; NP],
        res: &mut Vec<f64>,
        mut jac: Option<&mut Vec<[f64; NP]>>,
    ) -> Option<f64> {
        res.clear();
        if let Some(j) = jac.as_deref_mut() {
            j.clear();
        }
        let (e, sigma) = (p[0], p[1].exp());
        let n = self.offsets.len();
        let mut basis = vec![[0.0; 4]; n];
        // Per sample: the three edges' CDF derivatives wrt z (the normal densities) and z.
        let mut dens = vec![[0.0; 6]; n];
        let mut cost = 0.0;
        for row in &self.rows {
            let ys = &row.ys;
            for (i, &s) in self.offsets.iter().enumerate() {
                let z = [
                    (s - e + row.inner) / sigma,
                    (s - e) / sigma,
                    (s - e - self.ring_cells * row.outer) / sigma,
                ];
                let f = z.map(phi);
                basis[i] = [1.0 - f[0], f[0] - f[1], f[1] - f[2], f[2]];
                if jac.is_some() {
                    let g = z.map(|zz| (-0.5 * zz * zz).exp() * FRAC_1_SQRT_2PI);
                    dens[i] = [g[0], g[1], g[2], z[0], z[1], z[2]];
                }
            }
            let normal = Normal4::new(&basis)?;
            let levels = normal.solve(&basis, ys)?;
            let start = res.len();
            for (b, y) in basis.iter().zip(ys) {
                let r = y - dot4(b, &levels);
                cost += r * r;
                res.push(r);
            }
            let Some(j) = jac.as_deref_mut() else {
                continue;
            };
            // Step heights of the three edges.
            let h = [
                levels[1] - levels[0],
                levels[2] - levels[1],
                levels[3] - levels[2],
            ];
            // dm/dθ per sample, θ = (e, ln σ).
            let mut v = vec![[0.0; NP]; n];
            for (vi, d) in v.iter_mut().zip(&dens) {
                let de = -(h[0] * d[0] + h[1] * d[1] + h[2] * d[2]) / sigma;
                *vi = [
                    de,
                    -(h[0] * d[3] * d[0] + h[1] * d[4] * d[1] + h[2] * d[5] * d[2]),
                ];
            }
            j.resize(start + n, [0.0; NP]);
            for k in 0..NP {
                let col: Vec<f64> = v.iter().map(|vi| vi[k]).collect();
                let proj = normal.solve(&basis, &col)?;
                for i in 0..n {
                    j[start + i][k] = -(col[i] - dot4(&basis[i], &proj));
                }
            }
        }
        Some(cost)
    }
}

/// Number of nonlinear parameters: the edge offset `e` and `ln σ`.
const NP: usize = 2;

const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

fn dot4(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

/// The 4 x 4 normal matrix `AᵀA` of one position's basis, with a tiny ridge so that a level
/// with no support (a black data cell next to the black border) stays finite.
struct Normal4([[f64; 4]; 4]);

impl Normal4 {
    fn new(basis: &[[f64; 4]]) -> Option<Self> {
        let mut a = [[0.0; 4]; 4];
        for row in basis {
            for i in 0..4 {
                for j in 0..4 {
                    a[i][j] += row[i] * row[j];
                }
            }
        }
        let scale = (0..4).map(|i| a[i][i]).fold(0.0, f64::max);
        if scale.is_nan() || scale <= 0.0 {
            return None;
        }
        for (i, row) in a.iter_mut().enumerate() {
            row[i] += 1e-9 * scale;
        }
        Some(Self(a))
    }

    /// Least-squares coefficients of `ys` on the basis.
    fn solve(&self, basis: &[[f64; 4]], ys: &[f64]) -> Option<[f64; 4]> {
        let mut b = [0.0; 4];
        for (row, &y) in basis.iter().zip(ys) {
            for i in 0..4 {
                b[i] += row[i] * y;
            }
        }
        solve(self.0, b)
    }
}

/// Gaussian elimination with partial pivoting.
fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let piv = (col..N).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[piv][col].abs() < 1e-300 {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..N {
            let f = a[r][col] / a[col][col];
            for c in col..N {
                a[r][c] -= f * a[col][c];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0; N];
    for r in (0..N).rev() {
        let s: f64 = (r + 1..N).map(|c| a[r][c] * x[c]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// A converged profile fit: `(e, ln σ)`, the edge offset's standard deviation and the cost.
struct Fit {
    p: [f64; NP],
    edge_sd: f64,
    cost: f64,
}

fn normal_equations(jac: &[[f64; NP]], r: &[f64]) -> ([[f64; NP]; NP], [f64; NP]) {
    let mut jtj = [[0.0; NP]; NP];
    let mut jtr = [0.0; NP];
    for (row, &ri) in jac.iter().zip(r) {
        for i in 0..NP {
            jtr[i] -= row[i] * ri;
            for j in 0..NP {
                jtj[i][j] += row[i] * row[j];
            }
        }
    }
    (jtj, jtr)
}

/// Levenberg-Marquardt on the two nonlinear parameters; stops when a step changes the cost by
/// less than [`COST_TOL`] relative or no damping lowers it. The edge offset's standard
/// deviation is `√((JᵀJ)⁻¹)₀₀ · s` with `s²` the residual variance over the degrees of freedom
/// left by the two parameters and the four levels per position.
fn fit(side: &Side, start: [f64; NP]) -> Option<Fit> {
    let mut p = start;
    let (mut r, mut jac) = (Vec::new(), Vec::new());
    let mut cost = side.evaluate(&p, &mut r, Some(&mut jac))?;
    let mut lambda = 1e-3;
    let mut rt = Vec::new();
    for _ in 0..MAX_ITERATIONS {
        let (jtj, jtr) = normal_equations(&jac, &r);
        let mut accepted = None;
        while lambda < 1e8 {
            let mut a = jtj;
            for (i, row) in a.iter_mut().enumerate() {
                row[i] += lambda * jtj[i][i].max(1e-12);
            }
            if let Some(step) = solve(a, jtr) {
                let trial: [f64; NP] = std::array::from_fn(|i| p[i] + step[i]);
                if let Some(c) = side.evaluate(&trial, &mut rt, None) {
                    if c < cost {
                        accepted = Some((trial, c));
                        break;
                    }
                }
            }
            lambda *= 10.0;
        }
        // No step lowers the cost: at a minimum to the damping's resolution.
        let Some((trial, c)) = accepted else {
            break;
        };
        let converged = cost - c <= COST_TOL * cost;
        p = trial;
        cost = side.evaluate(&p, &mut r, Some(&mut jac))?;
        lambda = (lambda * 0.3).max(1e-9);
        if converged {
            break;
        }
    }
    let (jtj, _) = normal_equations(&jac, &r);
    let dof = r.len().saturating_sub(NP + 4 * side.rows.len()).max(1) as f64;
    let s2 = cost / dof;
    let mut unit = [0.0; NP];
    unit[0] = 1.0;
    let edge_sd = (solve(jtj, unit)?[0] * s2).max(0.0).sqrt();
    Some(Fit { p, edge_sd, cost })
}

/// Relative cost decrease below which the fit has converged.
const COST_TOL: f64 = 1e-7;

/// Iteration limit (the fits converge in 4..10 from the gradient-centroid start).
const MAX_ITERATIONS: usize = 30;

/// Refines the sides of a quad (positive signed area, corners on the gradient-centroid edges)
/// whose cells are at most [`MAX_CELL_PX`] wide by fitting the edge profile model; sides whose
/// fit is not plausible keep their line. Returns the new corners, or `None` when nothing
/// changed (large cells, or no side accepted).
pub fn refine_small_tag(img: &GrayF32, q: &[DVec2; 4]) -> Option<[DVec2; 4]> {
    let lens: [f64; 4] = std::array::from_fn(|k| q[k].distance(q[(k + 1) % 4]));
    if lens.iter().sum::<f64>() / 32.0 > MAX_CELL_PX {
        return None;
    }
    // Each side as a point and a direction, moved along its outward normal when accepted.
    let mut lines: [(DVec2, DVec2); 4] = std::array::from_fn(|k| {
        let (a, b) = (q[k], q[(k + 1) % 4]);
        (a, (b - a) / lens[k])
    });
    // The tag's homography gives the border's and the ring's widths at each position, which
    // differ along a side seen in perspective.
    let h = crate::homography::square_to_quad(q)?;
    let h_inv = h.inverse();
    const SQUARE: [DVec2; 4] = [
        DVec2::new(-1.0, -1.0),
        DVec2::new(1.0, -1.0),
        DVec2::new(1.0, 1.0),
        DVec2::new(-1.0, 1.0),
    ];
    let mut any = false;
    for k in 0..4 {
        // Outward normal of side k in the tag square; a cell is 2/8 of the square.
        let out_sq = (SQUARE[k] + SQUARE[(k + 1) % 4]).normalize() * 0.25;
        let (a, dir) = lines[k];
        let len = lens[k];
        let outward = DVec2::new(dir.y, -dir.x);
        // The cell across this side: an eighth of the two sides that cross it.
        let cell = 0.5 * (lens[(k + 1) % 4] + lens[(k + 3) % 4]) / 8.0;
        let offsets: Vec<f64> = {
            let (lo, hi) = (-1.75 * cell, 3.25 * cell + 1.0);
            let n = ((hi - lo) / STEP_PX).floor() as usize;
            (0..=n).map(|i| lo + i as f64 * STEP_PX).collect()
        };
        let reach = offsets.iter().fold(0.0f64, |m, s| m.max(s.abs())) + 1.0;
        // Half a cell from the corners: nearer, the crossing side's own edge is in the profile.
        let margin = 0.5 * len / 8.0;
        let npos = ((len - 2.0 * margin).round().max(4.0) as usize).min(MAX_POSITIONS);
        let mut rows = Vec::with_capacity(npos);
        for j in 0..npos {
            let t = margin + (len - 2.0 * margin) * (j as f64 + 0.5) / npos as f64;
            let p = a + dir * t;
            if !img.contains(p, reach) {
                continue;
            }
            let sq = crate::homography::apply_h(&h_inv, p);
            let inner = (p - crate::homography::apply_h(&h, sq - out_sq)).dot(outward);
            let outer = (crate::homography::apply_h(&h, sq + out_sq) - p).dot(outward);
            if !(inner > 0.25 * cell
                && inner < 4.0 * cell
                && outer > 0.25 * cell
                && outer < 4.0 * cell)
            {
                continue;
            }
            let ys = offsets
                .iter()
                .map(|&s| img.bilinear(p + outward * s))
                .collect();
            rows.push(Row { inner, outer, ys });
        }
        if rows.len() < 4 {
            continue;
        }
        let mut side = Side {
            rows,
            offsets,
            ring_cells: 1.0,
        };
        // The light margin is one cell on the tag itself, often more with the paper around it:
        // each hypothesis is fitted and the one that explains the profile best is kept (a
        // continuous width cannot be told from the ring's brightness under blur).
        let mut best: Option<Fit> = None;
        for ring_cells in RING_HYPOTHESES_CELLS {
            side.ring_cells = ring_cells;
            if let Some(f) = fit(&side, [0.0, 1.0f64.ln()]) {
                if best.as_ref().is_none_or(|b| f.cost < b.cost) {
                    best = Some(f);
                }
            }
        }
        let Some(Fit { p, edge_sd, .. }) = best else {
            continue;
        };
        let (e, sigma) = (p[0], p[1].exp());
        // The edge's move: within a pixel, and within half a cell (a larger move means the fit
        // took a neighbouring edge for this one).
        let plausible = e.abs() < MAX_SHIFT_PX.min(0.5 * cell)
            && edge_sd < MAX_EDGE_SD_PX
            && (SIGMA_RANGE_PX.0..=SIGMA_RANGE_PX.1).contains(&sigma);
        if !plausible {
            continue;
        }
        // The side moves parallel to itself.
        lines[k] = (a + outward * e, dir);
        any = true;
    }
    if !any {
        return None;
    }
    let mut out = [DVec2::ZERO; 4];
    for k in 0..4 {
        let (p1, d1) = lines[(k + 3) % 4];
        let (p2, d2) = lines[k];
        let den = d1.perp_dot(d2);
        if den.abs() < 1e-9 {
            return None;
        }
        out[k] = p1 + d1 * ((p2 - p1).perp_dot(d2) / den);
    }
    Some(out)
}
