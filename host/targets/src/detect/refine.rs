//! Step 4 of the detector: the edge refinement, on the grey image (not the binary one).
//!
//! Along each side, the edge position along the normal is the centroid of the squared positive
//! (dark-to-light) gradient in a window, re-centred over three passes so the window is
//! symmetric about the edge (an off-centre window biases the centroid); a weighted
//! total-least-squares line is fitted, and the corners are the intersections of adjacent
//! lines. This is the same edge model as the reference library's `refine_edges`.
//!
//! Each edge sample also measures the Michelson contrast of the white ring against the black
//! border half a cell either side of the edge; samples below [`VISIBLE_CONTRAST`] of the tag's
//! median, or above it by [`CONTRAST_CEILING_MADS`] of its robust scatter, are hidden and not
//! fitted. On the last pass the corner zones' contrast and each side's straightness (a line
//! fitted to each half against the whole side's) are kept as occlusion evidence.

use crate::detect::covariance::{allow_for_correlation, corner_covariance};
use crate::detect::edge::gradient_half_span_px;
use crate::detect::line::{fit_line, is_convex, quad_corners, Line};
use crate::image::GrayF32;
use glam::DVec2;

/// Edge samples whose contrast (Michelson, white ring against black border) is below this
/// fraction of the tag's median are hidden (something covers the ring or the border there) and
/// are not fitted. A shadow edge across the tag keeps the contrast (it scales both levels); the
/// blur of small tags lowers it everywhere alike.
pub const VISIBLE_CONTRAST: f64 = 0.5;

/// A sample of an outer edge whose contrast (as for [`VISIBLE_CONTRAST`]) exceeds the tag's
/// median by more than this many of the tag's robust contrast scatter, and by at least
/// [`MIN_CONTRAST_EXCESS`], is hidden too: something brighter than the white ring stands over the
/// ring within half a cell of the edge (a white standard, a sheet nearer the flash). Its edge,
/// when it is within the gradient window's reach, makes the edge a double step whose gradient
/// centroid lies outward of the border's, by up to half a pixel over a one-pixel sliver of ring,
/// and the side's line pivots towards it. A shadow scales both levels and keeps the contrast;
/// glare and flare lower it. Five robust sigmas leave whole tags' samples alone (noise and the
/// code's pull on a blurred border sample stay within it).
pub const CONTRAST_CEILING_MADS: f64 = 5.0;

/// Smallest contrast excess that hides a sample (Michelson units): what the code's pull on the
/// border sample and noise reach on whole tags whose contrast scatter is very small.
pub const MIN_CONTRAST_EXCESS: f64 = 0.05;

/// Median absolute deviation to standard deviation for Gaussian data.
const MAD_TO_SIGMA: f64 = 1.4826;

/// Contrast samples in each corner zone of a side (the last 0.75 cell before the corner, where
/// no edge points are fitted).
const CORNER_ZONE_SAMPLES: usize = 3;

/// One side's edge points (position, gradient energy, edge contrast) and its contrast samples
/// (position along the side, contrast).
type SideSamples = (Vec<(DVec2, f64, f64)>, Vec<(f64, f64)>);

/// A quad whose sides were refined on the grey image, with what the later steps need of the
/// fit.
pub(crate) struct RefinedQuad {
    pub(crate) corners: [DVec2; 4],
    pub(crate) cov: [[f64; 3]; 4],
    pub(crate) edge_rms_px: f64,
    /// Per corner, the smaller visible fraction of the quarters of its two sides next to it.
    pub(crate) visible_near: [f64; 4],
    /// Side length over 8, pixels.
    pub(crate) cell_px: f64,
    /// Per corner, whether a side next to it bends (see
    /// [`BEND_SIGMAS`](crate::detect::BEND_SIGMAS)).
    pub(crate) bent: [bool; 4],
    /// The fitted sides (side `k` from corner `k` to `k + 1`).
    pub(crate) lines: [Line; 4],
    /// The tag's median edge contrast (Michelson, white ring against black border).
    pub(crate) median_contrast: f64,
    /// Per side, the edge points its line was fitted to (position, weight).
    pub(crate) edge_points: [Vec<(DVec2, f64)>; 4],
    /// Per side, at its start and end corner: how far the half-side's line is from the side's,
    /// and that distance's variance from noise alone.
    pub(crate) bend: [[(f64, f64); 2]; 4],
}

/// Refines the sides on the grey image. `q` has positive signed area (clockwise on screen with y
/// down), so the outward normal of side `a -> b` is `perp(b - a)` rotated to point out.
pub(crate) fn refine_quad(img: &GrayF32, q: [DVec2; 4]) -> Option<RefinedQuad> {
    let mut corners = q;
    let mut lines: Vec<Line> = Vec::new();
    let side_mean = (0..4).map(|k| q[k].distance(q[(k + 1) % 4])).sum::<f64>() / 4.0;
    let cell = side_mean / 8.0;
    // Search window half-width: the initial error is about a pixel; never wider than most of a
    // cell so the window stays inside the black border and white ring.
    let mut range = (0.8 * cell).clamp(1.0, 3.0);
    let gspan = gradient_half_span_px(cell);
    // Per side, at its start and end corner: how far the half-side's line is from the side's,
    // and that distance's variance from noise alone.
    let mut bend = [[(0.0f64, 0.0f64); 2]; 4];
    // Per side, the visible fraction next to its start and end corner.
    let mut visible_near = [[1.0f64; 2]; 4];
    let mut median_contrast = 0.0;
    let mut edge_points: [Vec<(DVec2, f64)>; 4] = Default::default();
    for pass in 0..3 {
        // The occlusion evidence (corner zones, bends) is gathered on the last pass.
        let last = pass == 2;
        lines.clear();
        let sides: Vec<SideSamples> = (0..4)
            .map(|k| {
                let (a, b) = (corners[k], corners[(k + 1) % 4]);
                sample_side(img, a, b, cell, range, gspan, last)
            })
            .collect();
        let band = ContrastBand::of(&sides)?;
        median_contrast = band.median;
        for (k, (pts, contrast)) in sides.iter().enumerate() {
            let SideFit { line, used, hidden } = fit_side(pts, &band)?;
            lines.push(line);
            if last {
                bend[k] = side_bend(&used, corners[k], corners[(k + 1) % 4], &line);
                visible_near[k] = if hidden {
                    [0.0; 2]
                } else {
                    near_corners_visible(contrast, &band)
                };
                edge_points[k] = used;
            }
        }
        let next = quad_corners(&lines)?;
        let moved = (0..4)
            .map(|k| next[k].distance(corners[k]))
            .fold(0.0, f64::max);
        if !is_convex(&next) || moved > 3.0 * cell.max(2.0) {
            return None;
        }
        corners = next;
        range = if pass == 0 {
            (0.5 * cell).clamp(1.0, 2.0)
        } else {
            (0.4 * cell).clamp(0.75, 2.0)
        };
    }
    let mut lines: [Line; 4] = lines.try_into().ok()?;
    allow_for_correlation(&mut lines, &edge_points);
    let (cov, bent) = corner_covariance(&lines, &corners, &bend, cell);
    let edge_rms_px = (lines.iter().map(|l| l.sigma * l.sigma).sum::<f64>() / 4.0).sqrt();
    // Corner k ends side k - 1 and starts side k.
    let visible_near =
        std::array::from_fn(|k| visible_near[(k + 3) % 4][1].min(visible_near[k][0]));
    Some(RefinedQuad {
        corners,
        cov,
        edge_rms_px,
        visible_near,
        cell_px: cell,
        bent,
        lines,
        median_contrast,
        edge_points,
        bend,
    })
}

/// Samples side `a -> b` of a quad with cells of `cell` px: per sample along the side, the
/// edge point (the gradient centroid within `range` px of the side, gradient half span
/// `gspan`) and the edge contrast; on the `last` pass also the contrast in the corner zones,
/// which the edge points leave out.
fn sample_side(
    img: &GrayF32,
    a: DVec2,
    b: DVec2,
    cell: f64,
    range: f64,
    gspan: f64,
    last: bool,
) -> SideSamples {
    let len = a.distance(b);
    let dir = (b - a) / len;
    // With positive signed area in y-down coordinates the interior is to the right of
    // a -> b, i.e. along (-dir.y, dir.x)... outward is the opposite.
    let outward = DVec2::new(dir.y, -dir.x);
    let nsamp = (len.round() as usize).clamp(6, 400);
    let mut pts = Vec::with_capacity(nsamp);
    let mut contrast = Vec::with_capacity(nsamp);
    for s in 0..nsamp {
        // Stay a cell away from the corners, where the other side's edge interferes.
        let margin = (cell * 0.75).min(0.25 * len) / len;
        let t = margin + (1.0 - 2.0 * margin) * (s as f64 + 0.5) / nsamp as f64;
        let p = a + (b - a) * t;
        if !img.contains(p, range + 2.0) {
            contrast.push((t, 0.0));
            continue;
        }
        let m = edge_contrast(img, p, outward, cell);
        contrast.push((t, m));
        let Some((offset, energy)) = gradient_centroid(img, p, outward, range, gspan) else {
            continue;
        };
        pts.push((p + outward * offset, energy, m));
    }
    // The corner zones, which the edge points leave out: contrast only, so a hidden
    // corner tip is seen.
    let margin = (cell * 0.75).min(0.25 * len) / len;
    let zone_samples = if last { CORNER_ZONE_SAMPLES } else { 0 };
    for j in 0..zone_samples {
        let f = margin * (j as f64 + 0.5) / CORNER_ZONE_SAMPLES as f64;
        for t in [f, 1.0 - f] {
            let p = a + (b - a) * t;
            let m = if img.contains(p, cell + 1.0) {
                edge_contrast(img, p, outward, cell)
            } else {
                0.0
            };
            contrast.push((t, m));
        }
    }
    (pts, contrast)
}

/// Michelson contrast of the white ring against the black border half a cell either side of
/// the edge at `p`: independent of the light level (a shadow), low where something covers the
/// ring or the border.
fn edge_contrast(img: &GrayF32, p: DVec2, outward: DVec2, cell: f64) -> f64 {
    let (inner, outer) = (
        img.bilinear(p - outward * (0.5 * cell)),
        img.bilinear(p + outward * (0.5 * cell)),
    );
    (outer - inner) / (outer.abs() + inner.abs()).max(1e-9)
}

/// The edge's offset from `p` along `outward` (the centroid of the squared dark-to-light
/// central difference of half span `gspan`, over offsets within `range` px in quarter-pixel
/// steps) and the window's gradient energy; `None` with no dark-to-light gradient.
fn gradient_centroid(
    img: &GrayF32,
    p: DVec2,
    outward: DVec2,
    range: f64,
    gspan: f64,
) -> Option<(f64, f64)> {
    let (mut mw, mut mn) = (0.0, 0.0);
    let step = 0.25;
    let mut off = -range;
    while off <= range + 1e-9 {
        let g1 = img.bilinear(p + outward * (off + gspan));
        let g2 = img.bilinear(p + outward * (off - gspan));
        let g = g1 - g2;
        if g > 0.0 {
            let wgt = g * g;
            mw += wgt;
            mn += wgt * off;
        }
        off += step;
    }
    if mw <= 0.0 {
        return None;
    }
    Some((mn / mw, mw))
}

/// The contrasts of a tag's edge samples that count as visible: at least [`VISIBLE_CONTRAST`]
/// of the tag's median, and not more than [`CONTRAST_CEILING_MADS`] of the tag's robust
/// scatter (and at least [`MIN_CONTRAST_EXCESS`]) above it, where something brighter than the
/// ring stands within half a cell of the edge.
struct ContrastBand {
    median: f64,
    visible_at: f64,
    ceiling: f64,
}

impl ContrastBand {
    /// The band of the four sides' samples; `None` when their median contrast is not positive.
    fn of(sides: &[SideSamples]) -> Option<Self> {
        let mut all: Vec<f64> = sides.iter().flat_map(|s| s.1.iter().map(|c| c.1)).collect();
        all.sort_by(f64::total_cmp);
        let median = all.get(all.len() / 2).copied().unwrap_or(0.0);
        if median <= 0.0 {
            return None;
        }
        let visible_at = VISIBLE_CONTRAST * median;
        let mut dev: Vec<f64> = all.iter().map(|m| (m - median).abs()).collect();
        dev.sort_by(f64::total_cmp);
        let mad = dev.get(dev.len() / 2).copied().unwrap_or(0.0);
        let ceiling =
            median + (CONTRAST_CEILING_MADS * MAD_TO_SIGMA * mad).max(MIN_CONTRAST_EXCESS);
        Some(Self {
            median,
            visible_at,
            ceiling,
        })
    }

    fn visible(&self, m: f64) -> bool {
        (self.visible_at..=self.ceiling).contains(&m)
    }
}

/// A side's line fitted to its edge points.
struct SideFit {
    line: Line,
    /// The points fitted (position, normalised weight).
    used: Vec<(DVec2, f64)>,
    /// Too little of the side visible to fit: all its edge points are fitted and both its
    /// corners are marked occluded.
    hidden: bool,
}

/// The line of a side fitted to its visible edge points (see [`SideFit`]).
fn fit_side(pts: &[(DVec2, f64, f64)], band: &ContrastBand) -> Option<SideFit> {
    let mut used: Vec<(DVec2, f64)> = pts
        .iter()
        .filter(|p| band.visible(p.2))
        .map(|p| (p.0, p.1))
        .collect();
    let hidden = used.len() < 4;
    if hidden {
        used = pts.iter().map(|p| (p.0, p.1)).collect();
    }
    if used.len() < 4 {
        return None;
    }
    // Weights by gradient energy, normalised so the covariance uses the point count.
    let wmax = used.iter().map(|p| p.1).fold(0.0, f64::max);
    for p in &mut used {
        p.1 = (p.1 / wmax).sqrt();
    }
    let line = fit_line(&used)?;
    Some(SideFit { line, used, hidden })
}

/// Straightness of side `a -> b`: lines fitted to each half of the side's points `used`, at the
/// corner of that half, against the whole side's `line`; per end, the distance and its variance
/// from noise alone (zero when the half has too few points). A side partly replaced by another
/// edge (an occluder's outline along the border) bends; a whole side does not beyond noise.
fn side_bend(used: &[(DVec2, f64)], a: DVec2, b: DVec2, line: &Line) -> [(f64, f64); 2] {
    let len = a.distance(b).max(1e-9);
    let half = |first: bool| -> Vec<(DVec2, f64)> {
        used.iter()
            .copied()
            .filter(|p| ((p.0 - a).dot(b - a) / (len * len) < 0.5) == first)
            .collect()
    };
    let mut bend = [(0.0, 0.0); 2];
    for (end, corner, pts_half) in [(0usize, a, half(true)), (1, b, half(false))] {
        if pts_half.len() >= 4 {
            if let Some(hl) = fit_line(&pts_half) {
                let d = (corner.dot(hl.n) - hl.d).abs() - (corner.dot(line.n) - line.d).abs();
                bend[end] = (d.abs(), hl.offset_var_at(corner));
            }
        }
    }
    bend
}

/// Visible fraction of the quarter of a side next to each of its corners, from its contrast
/// samples (position along the side, contrast).
fn near_corners_visible(contrast: &[(f64, f64)], band: &ContrastBand) -> [f64; 2] {
    let near = |lo: f64, hi: f64| {
        let (n, v) = contrast
            .iter()
            .filter(|c| c.0 >= lo && c.0 <= hi)
            .fold((0usize, 0usize), |(n, v), c| {
                (n + 1, v + usize::from(band.visible(c.1)))
            });
        if n == 0 {
            0.0
        } else {
            v as f64 / n as f64
        }
    };
    [near(0.0, 0.3), near(0.7, 1.0)]
}
