//! Step 3 of the detector: the quadrilateral of a traced contour.
//!
//! Four corner candidates from the contour (the farthest point pair and the two points
//! farthest from their chord, at least [`MIN_CHORD_OFFSET`] of it away, so strongly
//! foreshortened tags pass), a line fitted to the middle of each side and refitted without the
//! points beyond the side tolerance (at most [`MAX_STRAY_FRACTION`] of them: specks touching
//! the border); rejection when more stray (not a quadrilateral), when the quad is not convex,
//! has a corner sharper than [`MIN_CORNER_ANGLE_DEG`] or is too small. A quick test of the
//! unrefined quad (its border cells dark against its white ring, `border_is_dark`) drops most
//! non-tags before the edge refinement.
//!
//! In the reference library's corner model
//! ([`CornerModel::BinaryBoundary`](crate::detect::CornerModel::BinaryBoundary)) the quad
//! reported is that library's own, matched to ours (`matching_reference_quad`).

use crate::detect::cells::{cell_uv, fit_plane, sample_cell};
use crate::detect::line::{fit_line, is_convex, signed_area};
use crate::detect::types::DetectorConfig;
use crate::homography::square_to_quad;
use crate::image::GrayF32;
use glam::DVec2;

/// Smallest angle between adjacent sides of a quad, degrees (the reference library's
/// `cos_critical_rad`): a square seen at 80° from its normal along a diagonal still has 20°
/// corners; sharper ones are slivers of other shapes.
pub const MIN_CORNER_ANGLE_DEG: f64 = 10.0;

/// Smallest distance of the two side corners from the diagonal between the two farthest
/// contour points, as a fraction of that diagonal: a square foreshortened to a rhombus whose
/// short diagonal is 8 % of the long one (10° corners, [`MIN_CORNER_ANGLE_DEG`]) passes.
pub const MIN_CHORD_OFFSET: f64 = 0.04;

/// How much shorter a side of the traced contour's quad can be than the tag's border, pixels:
/// the contour runs through the centres of the outermost dark pixels, half a pixel or more
/// (with blur) inside the edge at each end.
pub const CONTOUR_INSET_PX: f64 = 2.0;

/// Largest fraction of a side's traced contour that may lie beyond the side tolerance
/// ([`DetectorConfig::max_side_deviation`]): specks of noise or shadow that touch the border.
pub const MAX_STRAY_FRACTION: f64 = 0.2;

/// Fits a quadrilateral to a closed contour. The result is ordered with positive signed area in
/// image coordinates (clockwise on screen).
pub(crate) fn fit_quad(contour: &[DVec2], cfg: &DetectorConfig) -> Option<[DVec2; 4]> {
    let n = contour.len();
    if (n as f64) < 3.0 * cfg.min_side_px {
        return None;
    }
    let c = contour.iter().copied().sum::<DVec2>() / n as f64;
    let far = |from: DVec2| -> usize {
        (0..n)
            .max_by(|&a, &b| {
                contour[a]
                    .distance_squared(from)
                    .total_cmp(&contour[b].distance_squared(from))
            })
            .unwrap_or(0)
    };
    let i0 = far(c);
    let i2 = far(contour[i0]);
    let (a, b) = (contour[i0], contour[i2]);
    let chord = (b - a).normalize_or_zero();
    let dist = |i: usize| (contour[i] - a).perp_dot(chord);
    let arc = |from: usize, to: usize| -> Vec<usize> {
        let mut v = Vec::new();
        let mut i = (from + 1) % n;
        while i != to {
            v.push(i);
            i = (i + 1) % n;
        }
        v
    };
    let arc1 = arc(i0, i2);
    let arc2 = arc(i2, i0);
    let i1 = *arc1
        .iter()
        .max_by(|&&x, &&y| dist(x).abs().total_cmp(&dist(y).abs()))?;
    let i3 = *arc2
        .iter()
        .max_by(|&&x, &&y| dist(x).abs().total_cmp(&dist(y).abs()))?;
    let diag = a.distance(b);
    if dist(i1).abs() < MIN_CHORD_OFFSET * diag || dist(i3).abs() < MIN_CHORD_OFFSET * diag {
        return None;
    }
    let idx = [i0, i1, i2, i3];
    let mut lines = Vec::with_capacity(4);
    for k in 0..4 {
        let (s, e) = (idx[k], idx[(k + 1) % 4]);
        let seg = arc(s, e);
        let len = seg.len();
        if len < 3 {
            return None;
        }
        // Middle 70 % of the side: the traced corners are rounded by the pixel grid and blur.
        let lo = (len as f64 * 0.15) as usize;
        let hi = (len as f64 * 0.85).ceil() as usize;
        let pts: Vec<(DVec2, f64)> = seg[lo..hi.min(len)]
            .iter()
            .map(|&i| (contour[i], 1.0))
            .collect();
        let side = contour[s].distance(contour[e]);
        let tol = 1.0 + cfg.max_side_deviation * side;
        // A few contour points may stray (a dark speck of noise or shadow touching the border):
        // refit on the points within the tolerance, and require most of the side to be there.
        let mut line = fit_line(&pts)?;
        for _ in 0..2 {
            let inliers: Vec<(DVec2, f64)> = pts
                .iter()
                .copied()
                .filter(|(p, _)| (p.dot(line.n) - line.d).abs() <= tol)
                .collect();
            if (inliers.len() as f64) < (1.0 - MAX_STRAY_FRACTION) * pts.len() as f64 {
                return None;
            }
            if inliers.len() == pts.len() {
                break;
            }
            line = fit_line(&inliers)?;
        }
        lines.push(line);
    }
    let mut q = [DVec2::ZERO; 4];
    for k in 0..4 {
        q[k] = lines[(k + 3) % 4].intersect(&lines[k])?;
    }
    if !is_convex(&q) {
        return None;
    }
    for k in 0..4 {
        let side = q[k].distance(q[(k + 1) % 4]);
        let (u, v) = (
            (q[(k + 1) % 4] - q[k]).normalize_or_zero(),
            (q[(k + 3) % 4] - q[k]).normalize_or_zero(),
        );
        if side < cfg.min_side_px - CONTOUR_INSET_PX
            || q[k].distance(c) > 2.0 * diag
            || u.dot(v).abs() > MIN_CORNER_ANGLE_DEG.to_radians().cos()
        {
            return None;
        }
    }
    if signed_area(&q) < 0.0 {
        q.reverse();
    }
    Some(q)
}

/// Most border cells brighter than the midpoint of the black and white models on the
/// unrefined quad (a quick test before the edge refinement; decoding allows 3 on the refined
/// one, and the unrefined corners can be a pixel off, which puts some cell centres of a small
/// tag onto its edges).
const MAX_BRIGHT_BORDER_UNREFINED: usize = 8;

/// Whether the black border of quad `q` (unrefined) is dark against its white ring: the cell
/// centres of the two rings, each modelled as a plane over the tag.
pub(crate) fn border_is_dark(img: &GrayF32, q: &[DVec2; 4]) -> bool {
    let Some(h) = square_to_quad(q) else {
        return false;
    };
    let mut black = Vec::with_capacity(28);
    let mut white = Vec::with_capacity(36);
    for r in 0..10 {
        for c in 0..10 {
            let ring = r.min(c).min(9 - r).min(9 - c);
            if ring > 1 {
                continue;
            }
            let Some(v) = sample_cell(img, &h, r, c, 0.0) else {
                continue;
            };
            let (u, w) = cell_uv(r, c);
            if ring == 1 {
                black.push((u, w, v));
            } else {
                white.push((u, w, v));
            }
        }
    }
    if black.len() < 20 || white.len() < 18 {
        // Too little visible to tell: leave it to the full decode.
        return true;
    }
    let (Some(bp), Some(wp)) = (fit_plane(&black), fit_plane(&white)) else {
        return false;
    };
    let eval = |p: &[f64; 3], u: f64, v: f64| p[0] + p[1] * u + p[2] * v;
    let bright = black
        .iter()
        .filter(|&&(u, v, z)| {
            let (lo, hi) = (eval(&bp, u, v), eval(&wp, u, v));
            hi - lo <= 0.0 || z > 0.5 * (lo + hi)
        })
        .count();
    bright <= MAX_BRIGHT_BORDER_UNREFINED
}

/// Largest distance of a corner of the reference library's quad from ours for the two to be the
/// same tag's outer border, pixels (the two estimators differ by under a pixel on real photos;
/// the next quad of a tag, the inner edge of its border, is a cell away).
const REFERENCE_MATCH_PX: f64 = 3.0;

/// The reference library's quad (from [`crate::reference_quad::reference_quads`]) that is the
/// same outer border as `q`, its corners reordered to match `q`'s.
pub(crate) fn matching_reference_quad(refs: &[[DVec2; 4]], q: &[DVec2; 4]) -> Option<[DVec2; 4]> {
    refs.iter()
        .filter_map(|r| {
            let mut out = [DVec2::ZERO; 4];
            let mut total = 0.0;
            for k in 0..4 {
                let (j, d) = (0..4)
                    .map(|j| (j, r[j].distance(q[k])))
                    .min_by(|a, b| a.1.total_cmp(&b.1))?;
                if d > REFERENCE_MATCH_PX {
                    return None;
                }
                out[k] = r[j];
                total += d;
            }
            let distinct = (0..4).all(|a| (a + 1..4).all(|b| out[a] != out[b]));
            distinct.then_some((total, out))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, out)| out)
}
