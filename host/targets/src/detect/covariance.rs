//! Step 5 of the detector: the corners' uncertainty.
//!
//! The residual scatter of the edge points gives each line's offset variance at the corner
//! (`σ²/N + σ² t²/Σt²`); a corner's 2 x 2 covariance is `σ₁²/sin²φ · u₂u₂ᵀ + σ₂²/sin²φ · u₁u₁ᵀ`
//! for lines of directions `u₁, u₂` meeting at angle `φ`. A floor on each line's offset,
//! [`SIGMA_FLOOR_PX`] ([`SIGMA_FLOOR_NARROW_PX`] on cells under [`SMALL_CELL_PX`]), accounts for
//! model error the residuals cannot see: the gradient centroid's error with the edge's position
//! between pixel centres, which a nearly axis-aligned side shares along its length. The points
//! are fewer independent ones than they number (neighbours share pixels; slow variations along
//! a side make runs), so each line's variance is multiplied by `(1 + ρ)/(1 - ρ)`, `ρ` the
//! lag-one correlation of the tag's residuals (`allow_for_correlation`, within
//! 0..[`MAX_RESIDUAL_CORRELATION`]). A side that bends at a corner ([`BEND_COVARIANCE_SIGMAS`])
//! adds its bend there to the line's offset variance.

use crate::detect::edge::SMALL_CELL_PX;
use crate::detect::line::Line;
use glam::DVec2;

/// Floor of the corner standard deviation: residual model error of edge fitting (blur
/// asymmetry, pixel response, interpolation) that the fit's own scatter does not show, added in
/// quadrature. Measured on the default synthetic session against the true corners
/// (`skinbrdf poses` with `truth.json`): with a floor of 0.02 px the errors were 1.45..1.55
/// times the stated sigmas (median), where honest sigmas give at most 1.18 (Rayleigh median of
/// a per-axis sigma; the sigma reported is the worst direction's); 0.04 px brings it to ~1.1.
pub const SIGMA_FLOOR_PX: f64 = 0.04;

/// [`SIGMA_FLOOR_PX`] for tags with cells under [`SMALL_CELL_PX`], whose edges are measured with
/// the narrower gradient difference. The gradient centroid's error depends on where the edge
/// falls between pixel centres (its phase), and along a nearly axis-aligned side the phase is
/// the same for every sample, so that error moves the whole line and the residuals do not
/// show it. Over the phase, for an edge blurred by 0.3..0.7 px (a 1-D model of the estimator,
/// `scripts/edge_pull_1d.py`: box pixels, Gaussian blur, bilinear reads, the same window and
/// passes), its standard deviation is 0.04..0.11 px with the half span of [`SMALL_CELL_PX`]'s
/// tags, against 0.02..0.04 px with
/// [`GRADIENT_HALF_SPAN_PX`](crate::detect::GRADIENT_HALF_SPAN_PX), which [`SIGMA_FLOOR_PX`]
/// matches.
pub const SIGMA_FLOOR_NARROW_PX: f64 = 0.08;

/// A side bends at a corner when the line fitted to its half next to the corner is more than
/// this many of its own (noise) standard deviations, and [`MIN_BEND_PX`], from the whole side's
/// line there: part of the side is another edge (an occluder's outline). The bend is then added
/// to the corner's variance and the corner is occluded.
pub const BEND_SIGMAS: f64 = 4.0;

/// Smallest bend that counts, pixels (below it the side is straight for any use of the
/// corners).
pub const MIN_BEND_PX: f64 = 0.15;

/// A side whose half-side line is off the whole side's at a corner by more than this many of
/// its standard deviations (but not by [`BEND_SIGMAS`] and [`MIN_BEND_PX`]) adds the bend to the
/// corner's variance without marking it: a smooth curvature (lens distortion across a large
/// tag, a bent sheet) or an occluder's edge too slight to be sure of; either way the line's
/// extrapolation to the corner is uncertain by that much. Three: one whole side in 370 takes its
/// (small) bend by chance.
pub const BEND_COVARIANCE_SIGMAS: f64 = 3.0;

/// Largest lag-one correlation of a tag's edge residuals allowed for (`allow_for_correlation`):
/// at 0.3 a line's variance is at most 1.86 times its points' scatter over their count, and
/// most tags reach it (the estimate, from about a hundred points, scatters by about 0.1). A
/// higher cap inflates every sigma further without covering more of the errors, and the pose
/// stages' robust losses and accuracy targets, set in units of the stated sigmas, then let more
/// of a bad corner through (docs/benchmarks-poses.md, "Correlated edge residuals").
pub const MAX_RESIDUAL_CORRELATION: f64 = 0.3;

/// Sets the four lines' variance factor from the tag's edge residuals' pooled lag-one
/// correlation `ρ` (residuals about each side's line, neighbours along the side).
///
/// Neighbouring edge points are a pixel apart and each reads a central difference over up to
/// ±1 px through bilinear interpolation, so they share pixels and their noise; and what varies
/// slowly along a side (the pull of the code's cells behind the border, the sub-pixel phase as
/// a slightly tilted edge crosses the pixel grid, shading across the blur) makes runs of
/// residuals of one sign. Either way the points are fewer independent ones than they number.
/// For residuals correlated as a first-order autoregression the variance of their mean is
/// `(1 + ρ)/(1 - ρ)` times `σ²/N`, which each line's offset and tilt variance is multiplied by
/// (`ρ` within `0..`[`MAX_RESIDUAL_CORRELATION`]; pooled over the four sides, because the
/// image's noise and blur are the tag's).
pub(crate) fn allow_for_correlation(lines: &mut [Line; 4], points: &[Vec<(DVec2, f64)>; 4]) {
    let (mut lagged, mut squared) = (0.0, 0.0);
    for (line, pts) in lines.iter().zip(points) {
        let mut previous: Option<f64> = None;
        for (p, _) in pts {
            let r = p.dot(line.n) - line.d;
            squared += r * r;
            lagged += previous.map_or(0.0, |q| q * r);
            previous = Some(r);
        }
    }
    let rho = if squared > 0.0 {
        (lagged / squared).clamp(0.0, MAX_RESIDUAL_CORRELATION)
    } else {
        0.0
    };
    for line in lines.iter_mut() {
        line.var_factor = (1.0 + rho) / (1.0 - rho);
    }
}

/// Each corner's 2 x 2 covariance (step 5 of the method) from its two lines' offset variances
/// at it, the floor and the bends of the sides (`bend`, per side at its start and end corner),
/// and whether a side next to it bends beyond [`BEND_SIGMAS`] and [`MIN_BEND_PX`].
pub(crate) fn corner_covariance(
    lines: &[Line; 4],
    corners: &[DVec2; 4],
    bend: &[[(f64, f64); 2]; 4],
    cell_px: f64,
) -> ([[f64; 3]; 4], [bool; 4]) {
    // The floor of each line's offset at a corner: the gradient centroid's phase error, larger
    // with the narrower difference of small cells.
    let offset_floor_px = if cell_px < SMALL_CELL_PX {
        SIGMA_FLOOR_NARROW_PX
    } else {
        SIGMA_FLOOR_PX
    };
    let mut cov = [[0.0; 3]; 4];
    let mut bent = [false; 4];
    for k in 0..4 {
        let (l1, l2) = (&lines[(k + 3) % 4], &lines[k]);
        let sin = l1.n.perp_dot(l2.n).abs().max(0.05);
        let floor2 = SIGMA_FLOOR_PX * SIGMA_FLOOR_PX;
        // A side that bends beyond BEND_COVARIANCE_SIGMAS adds its bend at the corner to the
        // line's offset variance; beyond BEND_SIGMAS and MIN_BEND_PX it marks the corner.
        let bend_var = |(d, var): (f64, f64)| {
            let marked = d > MIN_BEND_PX && d * d > BEND_SIGMAS * BEND_SIGMAS * (var + floor2);
            let counted =
                marked || d * d > BEND_COVARIANCE_SIGMAS * BEND_COVARIANCE_SIGMAS * (var + floor2);
            (if counted { d * d } else { 0.0 }, marked)
        };
        let ((b1, m1), (b2, m2)) = (bend_var(bend[(k + 3) % 4][1]), bend_var(bend[k][0]));
        bent[k] = m1 || m2;
        let v1 = l1.offset_var_at(corners[k]) + offset_floor_px.powi(2) + b1;
        let v2 = l2.offset_var_at(corners[k]) + offset_floor_px.powi(2) + b2;
        let (u1, u2) = (l1.dir(), l2.dir());
        let s2 = sin * sin;
        // A shift of line 1 moves the corner along line 2's direction, and vice versa.
        cov[k] = [
            (v1 * u2.x * u2.x + v2 * u1.x * u1.x) / s2,
            (v1 * u2.x * u2.y + v2 * u1.x * u1.y) / s2,
            (v1 * u2.y * u2.y + v2 * u1.y * u1.y) / s2,
        ];
    }
    (cov, bent)
}
