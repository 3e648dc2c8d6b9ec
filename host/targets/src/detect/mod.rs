//! AprilTag tag36h11 detection with sub-pixel corners and their uncertainty.
//!
//! # Method
//!
//! [`detect_with_stats`] runs the steps in order, one module each (their module docs hold the
//! details and the math):
//!
//! 1. **Adaptive threshold** (`threshold`): dark pixels against the mid-level of the local
//!    minimum and maximum over tiles of [`DetectorConfig::tile_px`]; flat regions are left
//!    unclassified.
//! 2. **Dark components** (`components`): the 4-connected components of plausible size, then
//!    the 8-connected unions of small ones (at most [`MAX_JOIN_PX`] pixels each), a union not
//!    tried when one of its parts already decoded; the outer contour of each.
//! 3. **Quad fit** (`quad`): four corners from the contour and a line fitted to each side,
//!    rejected when not a convex quadrilateral of plausible size and angles, or when its border
//!    is not dark against its white ring.
//! 4. **Edge refinement** (`refine`): each side's edge on the grey image, the centroid of the
//!    squared dark-to-light gradient along its normal, a weighted line through the points, the
//!    corners where adjacent lines meet; hidden and bent parts of the sides are found there.
//! 5. **Uncertainty** (`covariance`): each corner's 2 x 2 covariance from its two lines' offset
//!    variances, with a floor ([`SIGMA_FLOOR_PX`]), the sides' bends and the correlation of the
//!    edge residuals.
//! 6. **Decoding** (`decode`): the 10 x 10 cells through the quad's homography against black
//!    and white planes over the tag, the 36 data bits matched against the code table in the four
//!    orderings. A small tag whose refined quad does not decode is read a second time
//!    ([`UNREFINED_MAX_CELL_PX`], below). Once the code is known, a tag with its smallest cell
//!    under [`INNER_EDGE_BIAS_MAX_CELL_PX`] has its sides refitted without the pull of the
//!    border's inner edge (`inner_bias`).
//! 7. **Border width** (`border_width`): the border's inner edges, where the code puts a white
//!    cell behind it, measured against where the fitted outer edge puts them; a side displaced
//!    by an occluding edge has its corners' covariance widened and, beyond
//!    [`BORDER_WIDTH_SIGMAS`] and [`MIN_BORDER_DISPLACEMENT_PX`], its corners marked occluded.
//!
//! A small tag whose refined quad does not decode (cells up to [`UNREFINED_MAX_CELL_PX`]) is
//! read a second time, with each cell's grey averaged over its middle, then through its
//! contour's quad; found so, its corners are all marked occluded and their covariance widened
//! by [`UNREFINED_SIGMA_CELLS`].
//!
//! The steps' modules are layered: the public types (`types`) and the shared geometry (`line`,
//! `edge`, `cells`) at the bottom, the steps above them, this orchestrator on top; no step
//! imports one above it.
//!
//! [`DetectorConfig::corner_model`] can instead report the reference library's unrefined quad
//! ([`CornerModel::BinaryBoundary`]: that library's quad stage, reimplemented in
//! [`crate::reference_quad`], matched to each tag we find), for comparing with that library's
//! `refine_edges = 0` output, which it reproduces to a median of 0.001 px on the real test
//! photos; it is less accurate than the edge refinement.
//!
//! # Output convention
//!
//! Corners are in the project's pixel convention (integer = pixel centre), in the reference
//! library's order: the printed tag's bottom-left, bottom-right, top-right, top-left (tag frame
//! `(-1,1)`, `(1,1)`, `(1,-1)`, `(-1,-1)`, see [`crate::tag36h11`]), each the outer corner of the
//! black border. The reference C library puts pixel centres at half-integers, so its
//! coordinates are ours + 0.5: `c_lib.p[i] = ours[i] + (0.5, 0.5)`.

// Grid and corner loops index several parallel arrays; iterators would obscure the geometry.
#![allow(clippy::needless_range_loop)]

mod border_width;
mod cells;
mod components;
mod covariance;
mod decode;
mod edge;
mod inner_bias;
mod line;
mod quad;
mod refine;
mod threshold;
mod types;

#[cfg(test)]
mod tests;

pub use crate::homography::{apply_h, square_to_quad};
pub use border_width::{
    BORDER_COVARIANCE_SIGMAS, BORDER_WIDTH_SIGMAS, MAX_INNER_EDGE_DEPTH,
    MIN_BORDER_DISPLACEMENT_PX, MIN_PAIR_WIDTH_TEST_CELL_PX, MIN_WIDTH_TEST_CELL_PX,
};
pub use components::MAX_JOIN_PX;
pub use covariance::{
    BEND_COVARIANCE_SIGMAS, BEND_SIGMAS, MAX_RESIDUAL_CORRELATION, MIN_BEND_PX,
    SIGMA_FLOOR_NARROW_PX, SIGMA_FLOOR_PX,
};
pub use decode::{
    AVERAGED_CELL_MIN_PX, CELL_SPREAD_CELLS, DECODE_SHARPENING, MIN_VISIBLE_NEAR,
    OCCLUDED_SIGMA_CELLS,
};
pub use edge::{GRADIENT_HALF_SPAN_PX, SMALL_CELL_PX};
pub use inner_bias::INNER_EDGE_BIAS_MAX_CELL_PX;
pub use quad::{CONTOUR_INSET_PX, MAX_STRAY_FRACTION, MIN_CHORD_OFFSET, MIN_CORNER_ANGLE_DEG};
pub use refine::{CONTRAST_CEILING_MADS, MIN_CONTRAST_EXCESS, VISIBLE_CONTRAST};
pub use types::{CornerModel, DetectStats, Detection, DetectorConfig};

use crate::detect::components::{CompStats, Components};
use crate::detect::decode::{decode, DecodeOptions};
use crate::detect::quad::{border_is_dark, fit_quad, matching_reference_quad};
use crate::detect::refine::{refine_quad, RefinedQuad};
use crate::detect::threshold::threshold;
use crate::image::GrayF32;
use glam::DVec2;

/// Largest cell, pixels, of a tag read a second time when its refined quad does not decode
/// (the same quad with each cell averaged over its middle, [`CELL_SPREAD_CELLS`], then its
/// contour's quad): on cells of a few pixels the noise of a dark tag is as large as the
/// contrast at a single sample, and a neighbour's edge or the surround's within the
/// gradient window can pull a refined side by a cell, so the grid is sampled off by a cell
/// while the binary contour is still right. On larger tags a refined quad that does not
/// decode is mostly an occluded one, whose contour follows the occluder's outline.
pub const UNREFINED_MAX_CELL_PX: f64 = 4.0;

/// Standard deviation added to every corner of a small tag read only on a second reading
/// (through its refined quad with each cell averaged, or through its contour's quad), in
/// cells: the contour's corners are only as good as the binary threshold's pixel grid, and the
/// refined sides that disagree with them do not say which is right; a refined quad whose cells
/// read right only when averaged is as noisy, or as hidden, as its code.
pub const UNREFINED_SIGMA_CELLS: f64 = 1.0;

/// Detects tag36h11 tags.
pub fn detect(img: &GrayF32, cfg: &DetectorConfig) -> Vec<Detection> {
    detect_with_stats(img, cfg).0
}

/// Detects tag36h11 tags and returns the run's statistics.
pub fn detect_with_stats(img: &GrayF32, cfg: &DetectorConfig) -> (Vec<Detection>, DetectStats) {
    let mut stats = DetectStats::default();
    if img.width < 16 || img.height < 16 {
        return (Vec::new(), stats);
    }
    let dark = threshold(img, cfg);
    let reference = (cfg.corner_model == CornerModel::BinaryBoundary)
        .then(|| crate::reference_quad::reference_quads(img));
    let mut out: Vec<Detection> = Vec::new();
    let (w, h) = (img.width, img.height);
    let cc = Components::new(&dark, w, h);
    let candidates: Vec<(CompStats, u32, bool)> = cc.candidates(w, h, cfg);
    // Groups holding a component that already decoded are not tried again.
    let mut decoded_groups: std::collections::HashSet<u32> = std::collections::HashSet::new();
    for (comp, k, grouped) in &candidates {
        let (comp, k) = (*comp, *k);
        if *grouped && decoded_groups.contains(&k) {
            continue;
        }
        stats.components += 1;
        let contour = cc.contour(&comp, k, *grouped, w, h);
        if let Some(det) = tag_of_contour(img, &contour, cfg, reference.as_deref(), &mut stats) {
            decoded_groups.insert(cc.group_of[k as usize]);
            out.push(det);
        }
    }
    let kept = remove_duplicates(out, &mut stats);
    (kept, stats)
}

/// The tag whose black border is the traced `contour`, if any (steps 3 to 7), counting in
/// `stats` what became of it: a quad, a rejection, a second reading. `reference`: the
/// reference library's quads when its corner model is reported.
fn tag_of_contour(
    img: &GrayF32,
    contour: &[DVec2],
    cfg: &DetectorConfig,
    reference: Option<&[[DVec2; 4]]>,
    stats: &mut DetectStats,
) -> Option<Detection> {
    let quad = fit_quad(contour, cfg)?;
    stats.quads += 1;
    let det = refined_quad(img, quad, cfg, reference).and_then(|(refined, unbias)| {
        read_tag(img, quad, refined, cfg, unbias, reference.is_some(), stats)
    });
    if det.is_none() {
        stats.rejected_decode += 1;
    }
    det
}

/// The contour's quad refined on the grey image (step 4) with the configured corner model's
/// corners, and whether the inner edges' bias may be taken off them; `None` when the quad's
/// border is not dark, the refinement fails, or the reference library's quad stage does not
/// find the border.
fn refined_quad(
    img: &GrayF32,
    quad: [DVec2; 4],
    cfg: &DetectorConfig,
    reference: Option<&[[DVec2; 4]]>,
) -> Option<(RefinedQuad, bool)> {
    if !border_is_dark(img, &quad) {
        return None;
    }
    let mut refined = refine_quad(img, quad)?;
    // The inner edges' bias is taken off the edge refinement's own corners only.
    let mut unbias = cfg.corner_model == CornerModel::EdgeGradient;
    if cfg.corner_model == CornerModel::EdgeGradient && cfg.profile_small_tags {
        if let Some(c) = crate::profile::refine_small_tag(img, &refined.corners) {
            refined.corners = c;
            unbias = false;
        }
    }
    if let Some(refs) = reference {
        // Tags whose border the reference library's quad stage does not find are not
        // reported in its model, as that library would not report them.
        refined.corners = matching_reference_quad(refs, &refined.corners)?;
    }
    Some((refined, unbias))
}

/// Reads the tag of a refined quad (steps 6 and 7), a small one a second time when its refined
/// quad does not decode ([`UNREFINED_MAX_CELL_PX`]); not in the reference library's corner
/// model (`reference_model`), which reports that library's quads only.
fn read_tag(
    img: &GrayF32,
    quad: [DVec2; 4],
    refined: RefinedQuad,
    cfg: &DetectorConfig,
    unbias: bool,
    reference_model: bool,
    stats: &mut DetectStats,
) -> Option<Detection> {
    let first = DecodeOptions {
        unbias_inner_edges: unbias,
        average_cells: false,
    };
    decode(img, &refined, cfg, first).or_else(|| {
        if reference_model || refined.cell_px > UNREFINED_MAX_CELL_PX {
            return None;
        }
        let det = second_reading(img, quad, refined, cfg, first)?;
        stats.decoded_on_second_reading += 1;
        Some(det)
    })
}

/// The second reading of a small tag whose refined quad does not decode: through the same quad
/// with each cell's grey averaged over its middle (a noisy, dark tag), then through its
/// contour's quad `quad`, centre and averaged. Its corners are all marked occluded, their
/// covariance the refined quad's plus [`UNREFINED_SIGMA_CELLS`].
fn second_reading(
    img: &GrayF32,
    quad: [DVec2; 4],
    refined: RefinedQuad,
    cfg: &DetectorConfig,
    first: DecodeOptions,
) -> Option<Detection> {
    let cell_px = refined.cell_px;
    let averaged = DecodeOptions {
        average_cells: true,
        ..first
    };
    let mut det = decode(img, &refined, cfg, averaged).or_else(|| {
        let contour = RefinedQuad {
            corners: quad,
            ..refined
        };
        [false, true].into_iter().find_map(|average_cells| {
            let opts = DecodeOptions {
                unbias_inner_edges: false,
                average_cells,
            };
            decode(img, &contour, cfg, opts)
        })
    })?;
    let extra = (UNREFINED_SIGMA_CELLS * cell_px).powi(2);
    for cov in &mut det.corner_cov_px2 {
        cov[0] += extra;
        cov[2] += extra;
    }
    det.occluded_corners = [true; 4];
    Some(det)
}

/// Removes duplicates (same ID with centres closer than a quarter side), keeping the better
/// margin, counted in `stats`; the rest sorted by ID.
fn remove_duplicates(mut out: Vec<Detection>, stats: &mut DetectStats) -> Vec<Detection> {
    out.sort_by(|a, b| {
        b.decision_margin
            .partial_cmp(&a.decision_margin)
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let mut kept: Vec<Detection> = Vec::new();
    for d in out {
        if kept
            .iter()
            .any(|k| k.id == d.id && k.center_px.distance(d.center_px) < 0.25 * k.side_px())
        {
            stats.duplicates += 1;
        } else {
            kept.push(d);
        }
    }
    kept.sort_by_key(|d| d.id);
    kept
}
