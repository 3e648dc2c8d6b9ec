//! Part of step 6 of the detector: a decoded small tag's sides refitted without the pull of
//! the border's inner edge.
//!
//! Once the code is known, a tag with its smallest cell under [`INNER_EDGE_BIAS_MAX_CELL_PX`]
//! has its sides refitted without the pull of the border's inner edge, which lies one cell
//! behind the outer edge where the data cell there is white and, blurred, moves the outer
//! edge's gradient centroid outward: one bias per pair of opposite sides, fitted from the
//! white-backed edge points against the black-backed ones (`unbias_inner_edges`, which gives
//! the model), taken off, its uncertainty carried into the corners' covariance.

use crate::detect::cells::SQUARE;
use crate::detect::covariance::{allow_for_correlation, corner_covariance};
use crate::detect::edge::SMALL_CELL_PX;
use crate::detect::line::{fit_line, is_convex, quad_corners, Line};
use crate::detect::refine::RefinedQuad;
use crate::homography::apply_h;
use crate::tag36h11;
use glam::{DMat3, DVec2};

/// Tags whose smallest cell (shortest side over 8: across a foreshortened tag's long sides) is
/// under this many pixels have their sides refitted once decoded, with the inner edges' bias
/// estimated and taken off (`unbias_inner_edges`): below it the border's inner edge, one cell
/// behind the outer edge where the data cell there is white, is within the blur's reach of the
/// gradient window. In a 1-D model of the estimator (`scripts/edge_pull_1d.py`) the edge
/// reads outward by 0.08..0.29 px more where the cell behind is white than where it is black at
/// 2 px cells, 0.05..0.21 px at 3 px, 0.01..0.13 px at 3.5 px, under blur of 0.5..1 px. The
/// same size as [`SMALL_CELL_PX`] (docs/benchmarks-poses.md, "Small tags").
pub const INNER_EDGE_BIAS_MAX_CELL_PX: f64 = SMALL_CELL_PX;

/// Fraction of a pair of sides' edge points that must see a white data cell behind the border,
/// and of those that must not, for the pair's own bias to be estimated: with fewer, the bias is
/// confounded with the sides' offsets.
const MIN_BIAS_CONTRAST_FRACTION: f64 = 0.1;

/// Largest ratio of the cells across a tag's two pairs of opposite sides for a pair whose own
/// edge points do not separate white- from black-backed ones to take the other pair's bias: the
/// pull falls steeply with the cell across the side (in the 1-D model of the estimator, by
/// about half for each half pixel at 2..3.5 px), so a foreshortened tag's pairs differ.
const MAX_POOLED_CELL_RATIO: f64 = 1.25;

/// Refits the sides of a decoded small tag without its inner edges' pull.
///
/// Where the data cell behind the black border is white, the border's inner edge lies one cell
/// behind the outer edge, and on cells of a few pixels its blurred lobe of the opposite
/// gradient sign eats into the inner flank of the outer edge's lobe: the gradient centroid
/// moves outward by `b`, a fraction of a pixel that depends on the blur over the cell. Where
/// the cell behind is black the next edge is two cells in and the pull is much weaker. As the
/// code runs along a side the edge points step between the two, and a side's line moves by `b`
/// times its share of white cells, with a tilt where they bunch at one end; the edge points'
/// scatter shows only the steps, not the common move, so the corners' stated sigmas miss it.
///
/// With the code known, each edge point gets `w` = the fraction of white data cell behind it
/// (sampled at its position and ±half a pixel along the side, so a point at a cell's end counts
/// half), and the edge offsets `s` of the four sides are fitted jointly as
/// `s = a_k + m_k t + b_j w` (per side an offset and a tilt; one `b_j` per pair `j` of opposite
/// sides, which share the cell across them and the blur: on a foreshortened tag the pull on the
/// long sides, a narrow cell across, is several times that on the short ones). By Frisch-Waugh,
/// `b_j = Σ ω w̃ s̃ / Σ ω w̃²` over the pair's points, with `w̃, s̃` the residuals of `w` and `s`
/// after each side's own straight-line fit, and `var b_j = σ² / Σ ω w̃²` with `σ²` the model's
/// residual variance. A pair whose own points do not separate the two kinds
/// ([`MIN_BIAS_CONTRAST_FRACTION`]) takes the tag's pooled `b` when the two pairs' cells across
/// are alike ([`MAX_POOLED_CELL_RATIO`]), else is left as it was. Each side's edge points are
/// moved back by `b_j w` along its normal and its line refitted; the line's offset at `t`
/// depends on `b_j` through the side's own straight-line fit of `w`, `ŵ(t)`, so
/// `ŵ(t)² var b_j` joins its offset variance.
///
/// `h`: the quad's homography from the tag square; `white`: the decoded code's cells in the
/// quad's frame. `None` when neither pair can be corrected or the refitted quad is not a quad.
///
/// The cost is a pass over the tag's edge points and up to four line fits, only for tags under
/// [`INNER_EDGE_BIAS_MAX_CELL_PX`].
pub(crate) fn unbias_inner_edges(
    rq: &RefinedQuad,
    h: &DMat3,
    white: &[[bool; 10]; 10],
) -> Option<RefinedQuad> {
    let outward_lines = outward_lines(rq);
    let sides = bias_samples(rq, h, white, &outward_lines);
    let PairBiases { bias, fits, sigma2 } = pair_biases(rq, &sides)?;
    let mut lines = rq.lines;
    let mut points = rq.edge_points.clone();
    for k in 0..4 {
        let Some((b, sww_b)) = bias[k % 2] else {
            continue;
        };
        let old = &outward_lines[k];
        let moved: Vec<(DVec2, f64)> = rq.edge_points[k]
            .iter()
            .zip(&sides[k])
            .map(|(&(p, wgt), sp)| (p - old.n * (b * sp.white), wgt))
            .collect();
        let mut line = fit_line(&moved)?;
        // Keep the normal outward, so the position along the line is measured as in `fits`.
        if line.n.dot(old.n) < 0.0 {
            line.n = -line.n;
            line.d = -line.d;
        }
        // The side's straight-line fit of `w`, re-centred on the new line's centroid.
        let (_, _, wa, wm) = fits[k];
        let shift = (line.centroid - old.centroid).dot(old.dir());
        line.bias_var = [wa + wm * shift, wm, sigma2 / sww_b];
        lines[k] = line;
        points[k] = moved;
    }
    allow_for_correlation(&mut lines, &points);
    let corners = quad_corners(&lines)?;
    let moved = (0..4)
        .map(|k| corners[k].distance(rq.corners[k]))
        .fold(0.0, f64::max);
    if !is_convex(&corners) || moved > 0.5 * rq.cell_px {
        return None;
    }
    let (cov, bent) = corner_covariance(&lines, &corners, &rq.bend, rq.cell_px);
    Some(RefinedQuad {
        corners,
        cov,
        bent,
        lines,
        edge_points: points,
        ..*rq
    })
}

/// The sides' lines with their normals outward (`refine_quad`'s convention: the interior is to
/// the right of corner k -> k + 1 on screen), so that `b` has one sign on every side.
fn outward_lines(rq: &RefinedQuad) -> [Line; 4] {
    std::array::from_fn(|k| {
        let mut line = rq.lines[k];
        let along = rq.corners[(k + 1) % 4] - rq.corners[k];
        if line.n.dot(DVec2::new(along.y, -along.x)) < 0.0 {
            line.n = -line.n;
            line.d = -line.d;
        }
        line
    })
}

/// Per side, its edge points as [`BiasSample`]s about its outward line, each with the fraction
/// of white data cell behind the border there (sampled at its position and half a pixel either
/// way along the side).
fn bias_samples(
    rq: &RefinedQuad,
    h: &DMat3,
    white: &[[bool; 10]; 10],
    outward_lines: &[Line; 4],
) -> Vec<Vec<BiasSample>> {
    let cw = 2.0 / tag36h11::WIDTH_AT_BORDER as f64;
    let tag_from_image = h.inverse();
    // Half a pixel along the side, in tag units.
    let half_px = 0.5 * cw / rq.cell_px.max(1e-9);
    let is_white = |p: DVec2| {
        let col = ((p.x + 1.0) / cw + 1.0).floor();
        let row = ((p.y + 1.0) / cw + 1.0).floor();
        (0.0..10.0).contains(&col)
            && (0.0..10.0).contains(&row)
            && white[row as usize][col as usize]
    };
    let mut sides: Vec<Vec<BiasSample>> = Vec::with_capacity(4);
    for k in 0..4 {
        let (s, e) = (DVec2::from(SQUARE[k]), DVec2::from(SQUARE[(k + 1) % 4]));
        let (along, inward) = ((e - s) * 0.5, -(s + e) * 0.5);
        let line = &outward_lines[k];
        let pts = rq.edge_points[k]
            .iter()
            .map(|&(p, wgt)| {
                let u = apply_h(&tag_from_image, p) + inward * (1.5 * cw);
                let w = [-half_px, 0.0, half_px]
                    .iter()
                    .filter(|&&o| is_white(u + along * o))
                    .count() as f64
                    / 3.0;
                BiasSample {
                    t_px: (p - line.centroid).dot(line.dir()),
                    s_px: p.dot(line.n) - line.d,
                    weight: wgt,
                    white: w,
                }
            })
            .collect();
        sides.push(pts);
    }
    sides
}

/// The inner edges' bias fitted per pair of opposite sides.
struct PairBiases {
    /// Per pair (sides 0 and 2, sides 1 and 3), the bias `b_j` and its `Σ ω w̃²`; `None` for a
    /// pair left as it was.
    bias: [Option<(f64, f64)>; 2],
    /// Per side, its straight-line fits of the offsets and of the white fractions,
    /// `(a_s, m_s, a_w, m_w)`.
    fits: Vec<(f64, f64, f64, f64)>,
    /// The model's residual variance `σ²`.
    sigma2: f64,
}

/// Fits the bias of each pair of opposite sides (Frisch-Waugh, see `unbias_inner_edges`), or
/// takes the tag's pooled one; `None` when neither pair can be corrected.
fn pair_biases(rq: &RefinedQuad, sides: &[Vec<BiasSample>]) -> Option<PairBiases> {
    // Per pair of opposite sides (0 and 2, 1 and 3), which share the cell across them: the
    // Frisch-Waugh sums, and the counts of white- and black-backed points.
    let mut fits = Vec::with_capacity(4);
    let (mut sww, mut sws) = ([0.0f64; 2], [0.0f64; 2]);
    let mut kinds = [(0usize, 0usize); 2];
    for (k, pts) in sides.iter().enumerate() {
        let (sa, sm) = straight_fit(pts, |p| p.s_px);
        let (wa, wm) = straight_fit(pts, |p| p.white);
        for p in pts {
            let (rs, rw) = (p.s_px - sa - sm * p.t_px, p.white - wa - wm * p.t_px);
            sww[k % 2] += p.weight * rw * rw;
            sws[k % 2] += p.weight * rw * rs;
            if p.white > 0.5 {
                kinds[k % 2].0 += 1;
            } else {
                kinds[k % 2].1 += 1;
            }
        }
        fits.push((sa, sm, wa, wm));
    }
    let separates = |(white, black): (usize, usize)| {
        let n = (white + black) as f64;
        white + black >= 6
            && white as f64 >= MIN_BIAS_CONTRAST_FRACTION * n
            && black as f64 >= MIN_BIAS_CONTRAST_FRACTION * n
    };
    // The cell across each pair: pair 0 (sides 0 and 2) is crossed by sides 1 and 3.
    let side_len = |k: usize| rq.corners[k].distance(rq.corners[(k + 1) % 4]);
    let across = [
        (side_len(1) + side_len(3)) / 16.0,
        (side_len(0) + side_len(2)) / 16.0,
    ];
    let similar = across[0].max(across[1]) <= MAX_POOLED_CELL_RATIO * across[0].min(across[1]);
    let both = (kinds[0].0 + kinds[1].0, kinds[0].1 + kinds[1].1);
    // Each pair's own bias where its points separate the two kinds; else the tag's pooled one
    // when the cells across the pairs are alike; else none (the pair is left as it was).
    let own = |j: usize| (separates(kinds[j]) && sww[j] > 1e-9).then(|| (sws[j] / sww[j], sww[j]));
    let pooled = (similar && separates(both) && sww[0] + sww[1] > 1e-9)
        .then(|| ((sws[0] + sws[1]) / (sww[0] + sww[1]), sww[0] + sww[1]));
    let bias: [Option<(f64, f64)>; 2] = std::array::from_fn(|j| own(j).or(pooled));
    if bias.iter().all(Option::is_none) {
        return None;
    }
    let mut res2 = 0.0;
    for (k, (pts, &(sa, sm, wa, wm))) in sides.iter().zip(&fits).enumerate() {
        let b = bias[k % 2].map_or(0.0, |b| b.0);
        for p in pts {
            let r = (p.s_px - sa - sm * p.t_px) - b * (p.white - wa - wm * p.t_px);
            res2 += p.weight * r * r;
        }
    }
    let n = sides.iter().map(Vec::len).sum::<usize>() as f64;
    let fitted = bias.iter().flatten().count() as f64;
    let sigma2 = res2 / (n - 8.0 - fitted).max(1.0);
    Some(PairBiases { bias, fits, sigma2 })
}

/// One edge point of a side, for `unbias_inner_edges`.
struct BiasSample {
    /// Position along the side's line from its centroid, pixels.
    t_px: f64,
    /// Offset from the side's line, outward, pixels.
    s_px: f64,
    /// The line fit's weight of the point.
    weight: f64,
    /// Fraction of white data cell behind the border there (0..1).
    white: f64,
}

/// Weighted least-squares straight line `v = a + m t` through a side's samples, `(a, m)`; the
/// weighted mean and no tilt when the positions do not spread.
fn straight_fit(pts: &[BiasSample], value: impl Fn(&BiasSample) -> f64) -> (f64, f64) {
    let (mut sw, mut st, mut stt, mut sv, mut stv) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in pts {
        let v = value(p);
        sw += p.weight;
        st += p.weight * p.t_px;
        stt += p.weight * p.t_px * p.t_px;
        sv += p.weight * v;
        stv += p.weight * p.t_px * v;
    }
    let det = sw * stt - st * st;
    if det.abs() > 1e-12 {
        ((stt * sv - st * stv) / det, (sw * stv - st * sv) / det)
    } else {
        (sv / sw.max(1e-12), 0.0)
    }
}
