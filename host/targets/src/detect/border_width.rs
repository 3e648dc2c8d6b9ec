//! Step 7 of the detector: the border's width, which shows a side displaced by an occluding
//! edge.
//!
//! The black border is exactly one cell wide, and the decoded code says where a data cell
//! behind it is white, i.e. where the border's inner edge (or, behind a black data cell, the
//! next one, two cells in) is visible. Those edges are measured with the outer edges'
//! estimator, along each side, through the quad's homography, and compared with where the
//! fitted outer edge puts them (`displaced_sides`). A neighbouring target's white paper over
//! part of a side's border has an edge as straight and as contrasted as the white ring's and
//! parallel to the side, so the contrast, bend and cell tests all pass, and it moves both
//! corners of that side together; but it leaves the inner edge where it was, so the border
//! measures too thin. A side displaced by more than [`BORDER_COVARIANCE_SIGMAS`] of the edge
//! fits' own scatter has the displacement added to both its corners' variance along that
//! side's normal, and, beyond [`BORDER_WIDTH_SIGMAS`] and [`MIN_BORDER_DISPLACEMENT_PX`], the
//! corners marked occluded. What is common to all sides (ink spread, a bloom of the white) is
//! taken off first. Sides whose cells are under [`MIN_WIDTH_TEST_CELL_PX`] across are not
//! tested on their own (their edges are too close to tell a fraction of a pixel, and the inner
//! edges' pull differs between a foreshortened tag's two pairs of sides); such a pair, down to
//! [`MIN_PAIR_WIDTH_TEST_CELL_PX`], is compared with itself, the thinner side's border against
//! the other's, at each corner (`thinner_of_pair`). Every side of the family has a white cell
//! within [`MAX_INNER_EDGE_DEPTH`] cells of its border, so no side is left untested by its
//! code.

use crate::detect::cells::SQUARE;
use crate::detect::edge::{gradient_half_span_px, SMALL_CELL_PX};
use crate::detect::refine::{RefinedQuad, VISIBLE_CONTRAST};
use crate::homography::apply_h;
use crate::image::GrayF32;
use crate::tag36h11;
use glam::{DMat3, DVec2};

/// Deepest edge measured by the border-width test, in cells from the outer edge: the border's
/// inner edge (1) where the data cell next to the border is white, else the edge of the first
/// white data cell behind a black one (2), so that a side whose first data row is all black
/// (24 of the family's 2348 sides) is still measured. Deeper edges are not used: they depend
/// more on the far side's corners through the homography.
pub const MAX_INNER_EDGE_DEPTH: usize = 2;

/// Inner-edge samples stay this far from the ends of a run of equal edges, pixels, where the
/// edge turns round a white cell's corner (the blur and the gradient's span reach about this
/// far); bounded in cells by [`RUN_END_MARGIN_CELLS`].
const RUN_END_MARGIN_PX: f64 = 1.5;

/// Bounds of the run-end margin in cells: at least a quarter cell however sharp the image, and
/// never more than 0.45 cell so a single cell keeps its middle.
const RUN_END_MARGIN_CELLS: (f64, f64) = (0.25, 0.45);

/// Smallest cell across a side, pixels, for its border width to be tested: below it the
/// border's two edges, the white cell's far edge and the white ring's are all within the blur's
/// reach, and their pull on the gradient centroid depends on the code around each sample (it
/// is not common to the tag's sides), as large as the displacements to find. The same size as
/// [`SMALL_CELL_PX`], below which the outer edges also need a narrower gradient.
pub const MIN_WIDTH_TEST_CELL_PX: f64 = SMALL_CELL_PX;

/// Smallest cell across a pair of opposite sides, pixels, for the pair to be compared with each
/// other where [`MIN_WIDTH_TEST_CELL_PX`] leaves one of them unmeasured (`thinner_of_pair`).
/// The inner edges' pull that keeps such sides from being tested on their own depends on the
/// cell across the side and on the code behind it; two opposite sides share the first and
/// differ in the second, so their difference leaves only the code's share, small against the
/// displacements to find down to this size on whole tags of the synthetic sessions (figures:
/// docs/benchmarks-poses.md, "Small cells"). Under it (a square under 12 px) the border's two edges are within
/// the gradient's reach of each other and a side yields too few samples.
pub const MIN_PAIR_WIDTH_TEST_CELL_PX: f64 = 1.5;

/// Edge samples per independent one: the inner-edge samples are a pixel apart and each reads a
/// central difference over up to ±1 px through bilinear interpolation, so neighbours share
/// pixels and their noise; the scatter over the count is multiplied by this.
const SAMPLES_PER_INDEPENDENT: f64 = 2.0;

/// A side's outer edge is displaced (an occluder's edge along the border, see
/// `displaced_sides`) when the displacement measured by its inner edges exceeds this many of
/// its standard deviations from the edge fits' scatter: four, as for a bend
/// ([`BEND_SIGMAS`](crate::detect::BEND_SIGMAS)), so that Gaussian noise alone flags about one
/// side in 16 000 (the two-sided 4-sigma tail).
pub const BORDER_WIDTH_SIGMAS: f64 = 4.0;

/// A side's displacement goes into its corners' covariance (without marking them) when it
/// exceeds this many of its standard deviations: under [`MIN_BORDER_DISPLACEMENT_PX`] it may be
/// the centroid's phase bias as well as an occluder, and either way the corners are uncertain by
/// that much. Two: about one whole side in 20 takes its (small) displacement by chance.
pub const BORDER_COVARIANCE_SIGMAS: f64 = 2.0;

/// Smallest displacement of a side that counts, pixels: model error of comparing two edges that
/// the scatter does not show. A gradient centroid sampled on the pixel grid is biased by a
/// fraction of a pixel depending on the edge's sub-pixel phase, which is the same along a
/// nearly axis-aligned edge (it does not average out over the samples) and independent between
/// the outer edge and the inner ones; the displacement combines both and scales them by 8/7.
/// Set just above what whole tags of the synthetic sessions reach, so that they are not marked
/// while a paper over a third of a pixel of the border is (docs/benchmarks-poses.md).
pub const MIN_BORDER_DISPLACEMENT_PX: f64 = 0.3;

/// Step of the grey profile read across an inner edge, pixels (that of the outer edges'
/// gradient window).
const PROFILE_STEP_PX: f64 = 0.25;

/// The inner edges measured along one side of the quad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct InnerEdges {
    /// Mean position of the inner edges along the inward normal, relative to where the quad's
    /// homography puts them (one or two cells inside the fitted outer edge), pixels: positive
    /// when the border is thicker than the quad predicts.
    pub(crate) offset_px: f64,
    /// Variance of `offset_px` from noise: the samples' scatter (or the outer line's, when
    /// larger) over their independent count, plus the outer line's offset variance, px².
    pub(crate) var_px2: f64,
    /// The offset as a straight line along the side (least squares over the samples'
    /// positions), at the side's start and end corners, pixels: an occluder's edge at a slant
    /// to the side thins the border more towards one corner. The mean where the samples are
    /// too few, or all at one place, to give a slope.
    pub(crate) end_offset_px: [f64; 2],
    /// Variances of `end_offset_px` from noise: the line's residual scatter (or the outer
    /// line's, when larger) over the independent count, extrapolated to the corner, plus the
    /// outer line's offset variance there, px².
    pub(crate) end_var_px2: [f64; 2],
}

/// Measures the edges behind the black border along each side of the quad (`h`: the quad's
/// homography from the tag square, `white`: the decoded code's cells in the quad's frame) where the
/// code puts a white data cell within [`MAX_INNER_EDGE_DEPTH`] cells of the outer edge and the cell
/// across the edge is at least `min_cell_px`: the centroid of the squared dark-to-light gradient
/// along the edge's normal (the outer edges' estimator, step 4), in a window re-centred over three
/// passes. Samples whose contrast is below [`VISIBLE_CONTRAST`] of the tag's median are left out
/// (the white cell is hidden). `None` for a side with no sample (no white cell within reach, all
/// hidden, or cells under `min_cell_px` across it).
pub(crate) fn inner_edges(
    img: &GrayF32,
    h: &DMat3,
    white: &[[bool; 10]; 10],
    rq: &RefinedQuad,
    min_cell_px: f64,
) -> [Option<InnerEdges>; 4] {
    let cw = 2.0 / tag36h11::WIDTH_AT_BORDER as f64;
    let probe = EdgeProbe {
        gspan: gradient_half_span_px(rq.cell_px),
        visible_at: VISIBLE_CONTRAST * rq.median_contrast,
        min_cell_px,
    };
    std::array::from_fn(|k| {
        let s = DVec2::from(SQUARE[k]);
        let e = DVec2::from(SQUARE[(k + 1) % 4]);
        let along = (e - s) * 0.5;
        let inward = -(s + e) * 0.5;
        // The tag-frame point `t` cells along the side from its start, `d` cells inward.
        let at = |t: f64, d: f64| s + along * (t * cw) + inward * (d * cw);
        let is_white = |t: f64, d: f64| {
            let p = at(t, d);
            let col = ((p.x + 1.0) / cw + 1.0).floor();
            let row = ((p.y + 1.0) / cw + 1.0).floor();
            (0.0..10.0).contains(&col)
                && (0.0..10.0).contains(&row)
                && white[row as usize][col as usize]
        };
        // Per data column along the side, the depth of its first white cell.
        let depth: [Option<usize>; 6] = std::array::from_fn(|j| {
            (1..=MAX_INNER_EDGE_DEPTH).find(|&m| is_white(j as f64 + 1.5, m as f64 + 0.5))
        });
        // (position along the side in cells, offset px)
        let mut samples: Vec<(f64, f64)> = Vec::new();
        let mut j = 0;
        while j < 6 {
            let Some(m) = depth[j] else {
                j += 1;
                continue;
            };
            // A run of columns with the same edge depth is one straight edge.
            let mut j1 = j;
            while j1 + 1 < 6 && depth[j1 + 1] == Some(m) {
                j1 += 1;
            }
            let (t0, t1, d) = (j as f64 + 1.0, j1 as f64 + 2.0, m as f64);
            j = j1 + 1;
            let cell_along = apply_h(h, at(t1, d)).distance(apply_h(h, at(t0, d))) / (t1 - t0);
            let margin = (RUN_END_MARGIN_PX / cell_along.max(1e-9))
                .clamp(RUN_END_MARGIN_CELLS.0, RUN_END_MARGIN_CELLS.1);
            let usable = (t1 - t0 - 2.0 * margin).max(0.0);
            let n = ((usable * cell_along).round() as usize).max(1);
            for i in 0..n {
                let t = t0 + margin + usable * (i as f64 + 0.5) / n as f64;
                if let Some(o) = probe.offset(img, h, &at, t, d) {
                    samples.push((t, o));
                }
            }
        }
        if samples.is_empty() {
            return None;
        }
        let n = samples.len() as f64;
        let mean = samples.iter().map(|s| s.1).sum::<f64>() / n;
        let scatter2 = if samples.len() >= 4 {
            samples.iter().map(|s| (s.1 - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        let line = &rq.lines[k];
        let noise2 = line.sigma * line.sigma;
        let mid = apply_h(h, at(4.0, 0.0));
        let var_px2 = scatter2.max(noise2) * SAMPLES_PER_INDEPENDENT / n + line.offset_var_at(mid);
        // The offset's line along the side, through the samples' centroid.
        let t_mean = samples.iter().map(|s| s.0).sum::<f64>() / n;
        let stt: f64 = samples.iter().map(|s| (s.0 - t_mean).powi(2)).sum();
        let (mut end_offset_px, mut end_var_px2) = ([mean; 2], [var_px2; 2]);
        if samples.len() >= 4 && stt > 1e-9 {
            let slope = samples
                .iter()
                .map(|s| (s.0 - t_mean) * (s.1 - mean))
                .sum::<f64>()
                / stt;
            let residual2 = samples
                .iter()
                .map(|s| (s.1 - mean - slope * (s.0 - t_mean)).powi(2))
                .sum::<f64>()
                / (n - 2.0);
            let s2 = residual2.max(noise2) * SAMPLES_PER_INDEPENDENT;
            for (e, t_end) in [0.0, 8.0].into_iter().enumerate() {
                let dt = t_end - t_mean;
                end_offset_px[e] = mean + slope * dt;
                end_var_px2[e] =
                    s2 * (1.0 / n + dt * dt / stt) + line.offset_var_at(apply_h(h, at(t_end, 0.0)));
            }
        }
        Some(InnerEdges {
            offset_px: mean,
            var_px2,
            end_offset_px,
            end_var_px2,
        })
    })
}

/// How an inner edge is sampled: the gradient's half span, the least visible contrast and the
/// smallest cell across the edge.
struct EdgeProbe {
    gspan: f64,
    visible_at: f64,
    min_cell_px: f64,
}

impl EdgeProbe {
    /// One sample of an inner edge at tag-frame point `at(t, d)` (`d` cells behind the outer
    /// edge, dark in front, light behind): the offset of the edge from that point along the
    /// inward normal, pixels; `None` when the edge is not there to see (out of the image, cells
    /// under `min_cell_px` across it, no dark-to-light gradient, too little contrast).
    fn offset(
        &self,
        img: &GrayF32,
        h: &DMat3,
        at: &impl Fn(f64, f64) -> DVec2,
        t: f64,
        d: f64,
    ) -> Option<f64> {
        let p0 = apply_h(h, at(t, d));
        let (front, behind) = (apply_h(h, at(t, d - 0.5)), apply_h(h, at(t, d + 0.5)));
        let tangent = apply_h(h, at(t + 0.1, d)) - apply_h(h, at(t - 0.1, d));
        let mut n = tangent.perp().normalize_or_zero();
        if n.dot(behind - front) < 0.0 {
            n = -n;
        }
        // The local cell across the edge, pixels.
        let cell = (behind - front).dot(n);
        if cell < self.min_cell_px || !img.contains(front, 2.0) || !img.contains(behind, 2.0) {
            return None;
        }
        // The window covers most of a cell: a displaced outer edge moves the prediction by up
        // to about half a cell, and the neighbouring edges (the outer one in front, the white
        // cell's far one behind) have the opposite gradient sign.
        let range = (0.4 * cell).clamp(0.75, 2.5);
        // The grey profile along the normal on a grid of PROFILE_STEP_PX, read once and shared by
        // the three passes and by the two ends of each difference (the gradient's half span is
        // a whole number of steps); each pass's window starts on the grid.
        let max_centre = 0.75 * cell;
        let half = ((max_centre + range + self.gspan) / PROFILE_STEP_PX).ceil() as i64 + 1;
        let mut profile = vec![f64::NAN; (2 * half + 1) as usize];
        let mut grey = |i: i64| -> f64 {
            let slot = &mut profile[(i + half).clamp(0, 2 * half) as usize];
            if slot.is_nan() {
                *slot = img.bilinear(p0 + n * (i as f64 * PROFILE_STEP_PX));
            }
            *slot
        };
        let span = (self.gspan / PROFILE_STEP_PX).round() as i64;
        let steps = (range / PROFILE_STEP_PX).floor() as i64;
        let mut centre = 0.0;
        for _ in 0..3 {
            let c = (centre / PROFILE_STEP_PX).round() as i64;
            let (mut mw, mut mn) = (0.0, 0.0);
            for i in c - steps..=c + steps {
                let g = grey(i + span) - grey(i - span);
                if g > 0.0 {
                    mw += g * g;
                    mn += g * g * i as f64 * PROFILE_STEP_PX;
                }
            }
            if mw <= 0.0 {
                return None;
            }
            centre = mn / mw;
            if centre.abs() > max_centre {
                return None;
            }
        }
        // Contrast across the edge found: the dark border in front, the white cell behind.
        let (dark, light) = (
            img.bilinear(p0 + n * (centre - 0.4 * cell)),
            img.bilinear(p0 + n * (centre + 0.4 * cell)),
        );
        let m = (light - dark) / (light.abs() + dark.abs()).max(1e-9);
        (m >= self.visible_at).then_some(centre)
    }
}

/// A side's outer edge measured off where its inner edges put it (`displaced_sides`,
/// `thinner_of_pair`), at its start and end corners.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SideDisplacement {
    /// How far the fitted outer edge lies inside where the inner edges put it, pixels
    /// (negative: outside), at the side's start and end corners.
    pub(crate) d_px: [f64; 2],
    /// Beyond [`BORDER_WIDTH_SIGMAS`] and [`MIN_BORDER_DISPLACEMENT_PX`] at that corner: an
    /// occluder's edge, so the corner is marked occluded. Short of either, the displacement
    /// may as well be the gradient centroid's sub-pixel phase bias; the corner is uncertain by
    /// that much all the same, so it goes into its covariance without marking it.
    pub(crate) marked: [bool; 2],
}

/// Per side of the quad, its displacement (see [`SideDisplacement`]) when that is more than
/// [`BORDER_COVARIANCE_SIGMAS`] of the edge fits' scatter, else `None`; it is marked beyond
/// [`BORDER_WIDTH_SIGMAS`] and [`MIN_BORDER_DISPLACEMENT_PX`].
///
/// An occluder's edge along side `k` moves that side inward by `δ` while its inner edges stay:
/// the homography then shrinks the cell by `δ/8` across the tag, so side `k`'s border measures
/// `7δ/8` thinner than predicted and the opposite side's `δ/8` thicker. With both measured,
/// `δₖ = -(7 oₖ + oₒₚₚ)/6` undoes that coupling (a displaced side does not flag the opposite
/// one); with one, `δₖ = -8 oₖ/7`. What all sides share is not an occluder's: a printer's ink
/// spread, a bloom of the white or a blur that moves every edge alike make every border
/// thicker or thinner, so with three or four sides measured their median displacement is taken
/// off each before the test.
pub(crate) fn displaced_sides(e: &[Option<InnerEdges>; 4]) -> [Option<SideDisplacement>; 4] {
    let est: [Option<(f64, f64)>; 4] = std::array::from_fn(|k| {
        let ek = e[k]?;
        Some(match e[(k + 2) % 4] {
            Some(eo) => (
                -(7.0 * ek.offset_px + eo.offset_px) / 6.0,
                (49.0 * ek.var_px2 + eo.var_px2).sqrt() / 6.0,
            ),
            None => (-8.0 * ek.offset_px / 7.0, 8.0 * ek.var_px2.sqrt() / 7.0),
        })
    });
    let mut ds: Vec<f64> = est.iter().flatten().map(|d| d.0).collect();
    ds.sort_by(f64::total_cmp);
    let common = match ds.len() {
        3 => ds[1],
        4 => 0.5 * (ds[1] + ds[2]),
        _ => 0.0,
    };
    est.map(|d| {
        let (d, sd) = d?;
        let d_px = d - common;
        let marked = d_px.abs() > (BORDER_WIDTH_SIGMAS * sd).max(MIN_BORDER_DISPLACEMENT_PX);
        (d_px.abs() > BORDER_COVARIANCE_SIGMAS * sd).then_some(SideDisplacement {
            d_px: [d_px; 2],
            marked: [marked; 2],
        })
    })
}

/// A pair of opposite sides whose cells are too small for each to be tested on its own
/// (`displaced_sides`) compared with each other: per side, `[side, opposite]`, where its
/// border is thinner than the other's, as [`SideDisplacement`] with the same thresholds.
///
/// An occluder's edge along side `k` moving it inward by `δ` makes its border `7δ/8` thinner
/// than the quad's homography predicts and the opposite side's `δ/8` thicker, so the difference
/// of the two offsets is `δ` itself. Whatever the two sides share cancels: the inner edges'
/// pull at the cell across them (the same for both, which it is not for the other pair of a
/// foreshortened tag), a printer's ink spread, the blur. Only a thinner border counts: white
/// paper over it makes it thinner, while anything dark over the white ring takes away the
/// outer edge's contrast, which the visibility test sees.
///
/// Two tests per corner, the larger displacement found being kept: the side's mean offset
/// against the other's (the most samples), and its offset line at that corner against the
/// other's mean (an occluder's edge at a slant to the side, over the border more at one
/// corner than at the other, which the mean halves).
pub(crate) fn thinner_of_pair(
    side: InnerEdges,
    opposite: InnerEdges,
) -> [Option<SideDisplacement>; 2] {
    let thinner = |x: InnerEdges, other: InnerEdges| {
        let mean = (other.offset_px - x.offset_px, other.var_px2 + x.var_px2);
        let (mut d_px, mut marked) = ([0.0; 2], [false; 2]);
        for e in 0..2 {
            let end = (
                other.offset_px - x.end_offset_px[e],
                other.var_px2 + x.end_var_px2[e],
            );
            for (d, var) in [mean, end] {
                let sd = var.sqrt();
                if d > BORDER_COVARIANCE_SIGMAS * sd {
                    d_px[e] = f64::max(d_px[e], d);
                    marked[e] |= d > (BORDER_WIDTH_SIGMAS * sd).max(MIN_BORDER_DISPLACEMENT_PX);
                }
            }
        }
        (d_px != [0.0; 2]).then_some(SideDisplacement { d_px, marked })
    };
    [thinner(side, opposite), thinner(opposite, side)]
}

/// Per side of the quad `rq` (`h`: its homography from the tag square, `white`: the decoded
/// code's cells in its frame), its displacement against its inner edges, when there is one
/// (see [`SideDisplacement`]): the sides measured on their own where their cells are at least
/// [`MIN_WIDTH_TEST_CELL_PX`] across, and a pair of sides with cells too small across them for
/// both to be measured on their own measured down to [`MIN_PAIR_WIDTH_TEST_CELL_PX`] and its
/// two sides compared with each other.
pub(crate) fn side_displacements(
    img: &GrayF32,
    h: &DMat3,
    white: &[[bool; 10]; 10],
    rq: &RefinedQuad,
) -> [Option<SideDisplacement>; 4] {
    let edges = inner_edges(img, h, white, rq, MIN_WIDTH_TEST_CELL_PX);
    let mut shifted = displaced_sides(&edges);
    let unmeasured = |k: usize| edges[k].is_none() || edges[k + 2].is_none();
    if unmeasured(0) || unmeasured(1) {
        let narrow = inner_edges(img, h, white, rq, MIN_PAIR_WIDTH_TEST_CELL_PX);
        for k in (0..2).filter(|&k| unmeasured(k)) {
            if let (Some(a), Some(b)) = (narrow[k], narrow[k + 2]) {
                [shifted[k], shifted[k + 2]] = thinner_of_pair(a, b);
            }
        }
    }
    shifted
}

/// The corners' covariance of `rq` with the displaced sides' displacements added: a displaced
/// side `k` moves its corners along the other side through each, corner `k` along side
/// `k - 1`, corner `k + 1` along side `k + 1`, by the displacement over the sine of their angle
/// (floored as in the edge refinement's covariance).
pub(crate) fn widened_covariance(
    rq: &RefinedQuad,
    shifted: &[Option<SideDisplacement>; 4],
) -> [[f64; 3]; 4] {
    let mut rq_cov = rq.cov;
    for (k, s) in shifted.iter().enumerate() {
        let Some(SideDisplacement { d_px, .. }) = *s else {
            continue;
        };
        for (d, j, other) in [
            (d_px[0], k, (k + 3) % 4),
            (d_px[1], (k + 1) % 4, (k + 1) % 4),
        ] {
            let (u, n) = (rq.lines[other].dir(), rq.lines[k].n);
            let sin2 = n.dot(u).powi(2).max(0.05 * 0.05);
            let v = d * d / sin2;
            rq_cov[j][0] += v * u.x * u.x;
            rq_cov[j][1] += v * u.x * u.y;
            rq_cov[j][2] += v * u.y * u.y;
        }
    }
    rq_cov
}
