//! AprilTag tag36h11 detection with sub-pixel corners and their uncertainty.
//!
//! # Method
//!
//! 1. **Adaptive threshold** (as the reference library): the image is cut into tiles of
//!    [`DetectorConfig::tile_px`]; each pixel is compared with the mid-level of the minimum and
//!    maximum over the 3 x 3 neighbouring tiles. Pixels whose neighbourhood contrast is below
//!    [`DetectorConfig::min_contrast`] (relative to the image's range) are left unclassified, so
//!    flat regions and uneven flash lighting do not produce spurious components.
//! 2. **Dark components** of plausible size (union-find): first the 4-connected ones, so that a
//!    border touching dark surroundings (a shadow, a dark band, a neighbour) only diagonally
//!    through its thin white ring stays apart from them; then the 8-connected unions of small
//!    4-connected components (at most [`MAX_JOIN_PX`] pixels each), so that the border of a
//!    small blurred tag whose pixels meet only diagonally is whole. A union is not tried when
//!    one of its parts already decoded. The outer contour of each is traced (Moore
//!    neighbourhood tracing).
//! 3. **Quad fit**: four corner candidates from the contour (the farthest point pair and the two
//!    points farthest from their chord, at least [`MIN_CHORD_OFFSET`] of it away, so strongly
//!    foreshortened tags pass), a line fitted to the middle of each side and refitted without
//!    the points beyond the side tolerance (at most [`MAX_STRAY_FRACTION`] of them: specks
//!    touching the border); rejection when more stray (not a quadrilateral), when the quad is
//!    not convex, has a corner sharper than [`MIN_CORNER_ANGLE_DEG`] or is too small. A quick
//!    test of the unrefined quad (its border cells dark against its white ring) drops most
//!    non-tags before the edge refinement.
//! 4. **Edge refinement** on the grey image (not the binary one): along each side, the edge
//!    position along the normal is the centroid of the squared positive (dark-to-light) gradient
//!    in a window, re-centred over three passes so the window is symmetric about the edge (an
//!    off-centre window biases the centroid); a weighted total-least-squares line is fitted, and
//!    the corners are the intersections of adjacent lines. This is the same edge model as the
//!    reference library's `refine_edges`.
//! 5. **Uncertainty**: the residual scatter of the edge points gives each line's offset variance
//!    at the corner (`σ²/N + σ² t²/Σt²`); a corner's 2 x 2 covariance is
//!    `σ₁²/sin²φ · u₂u₂ᵀ + σ₂²/sin²φ · u₁u₁ᵀ` for lines of directions `u₁, u₂` meeting at angle
//!    `φ`. A floor on each line's offset, [`SIGMA_FLOOR_PX`] ([`SIGMA_FLOOR_NARROW_PX`] on cells
//!    under [`SMALL_CELL_PX`]), accounts for model error the residuals cannot see: the gradient
//!    centroid's error with the edge's position between pixel centres, which a nearly
//!    axis-aligned side shares along its length. The points are fewer independent ones than
//!    they number (neighbours share pixels; slow variations along a side make runs), so each
//!    line's variance is multiplied by `(1 + ρ)/(1 - ρ)`, `ρ` the lag-one correlation of the
//!    tag's residuals (`allow_for_correlation`, within 0..[`MAX_RESIDUAL_CORRELATION`]).
//! 6. **Decoding**: the homography from the tag square to the quad samples all 10 x 10 cells;
//!    black and white levels are modelled as planes over the tag (fitted to the black border and
//!    the white outer ring), so a lighting gradient across the tag does not flip bits. The 36 data
//!    bits are matched against all 587 codes for each of the four corner orderings; the best match
//!    within [`DetectorConfig::max_hamming`] wins. Quads whose black border is not dark are
//!    rejected before decoding. A small tag whose refined quad does not decode is read a second
//!    time ([`UNREFINED_MAX_CELL_PX`]), with each cell's grey averaged over its middle, then
//!    through its contour's quad; found so, its corners are all marked occluded. Once the code is
//!    known, a tag with its smallest cell under [`INNER_EDGE_BIAS_MAX_CELL_PX`] has its sides
//!    refitted without the pull of the border's inner edge, which lies one cell behind the outer
//!    edge where the data cell there is white and, blurred, moves the outer edge's gradient
//!    centroid outward: one bias per pair of opposite sides, fitted from the white-backed edge
//!    points against the black-backed ones (`unbias_inner_edges`), taken off, its uncertainty
//!    carried into the corners' covariance.
//! 7. **Border width** (a side displaced by an occluding edge): the black border is exactly one
//!    cell wide, and the decoded code says where a data cell behind it is white, i.e. where the
//!    border's inner edge (or, behind a black data cell, the next one, two cells in) is visible.
//!    Those edges are measured with the outer edges' estimator, along each side, through the
//!    quad's homography, and compared with where the fitted outer edge puts them
//!    (`displaced_sides`). A neighbouring target's white paper over part of a side's border
//!    has an edge as straight and as contrasted as the white ring's and parallel to the side,
//!    so the contrast, bend and cell tests all pass, and it moves both corners of that side
//!    together; but it leaves the inner edge where it was, so the border measures too thin.
//!    A side displaced by more than [`BORDER_COVARIANCE_SIGMAS`] of the edge fits' own scatter
//!    has the displacement added to both its corners' variance along that side's normal, and,
//!    beyond [`BORDER_WIDTH_SIGMAS`] and [`MIN_BORDER_DISPLACEMENT_PX`], the corners marked
//!    occluded. What is common to all sides (ink spread, a bloom of the white) is taken off
//!    first. Sides whose cells are under [`MIN_WIDTH_TEST_CELL_PX`] across are not tested on
//!    their own (their edges are too close to tell a fraction of a pixel, and the inner edges'
//!    pull differs between a foreshortened tag's two pairs of sides); such a pair, down to
//!    [`MIN_PAIR_WIDTH_TEST_CELL_PX`], is compared with itself, the thinner side's border
//!    against the other's, at each corner (`thinner_of_pair`). Every side of the family has a
//!    white cell within [`MAX_INNER_EDGE_DEPTH`] cells of its border, so no side is left
//!    untested by its code.
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

pub use crate::homography::{apply_h, square_to_quad};
use crate::image::GrayF32;
use crate::tag36h11;
use glam::{DMat3, DVec2, DVec3};
use serde::{Deserialize, Serialize};

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
/// tags, against 0.02..0.04 px with [`GRADIENT_HALF_SPAN_PX`], which [`SIGMA_FLOOR_PX`]
/// matches.
pub const SIGMA_FLOOR_NARROW_PX: f64 = 0.08;

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

/// A corner whose neighbouring side quarters are less than this fraction visible (on either
/// side, [`VISIBLE_CONTRAST`]) is occluded.
pub const MIN_VISIBLE_NEAR: f64 = 0.5;

/// Standard deviation added to an occluded corner, in cells of the tag (side / 8): where the
/// corner is hidden it is the intersection of lines fitted to what remains, or the quad is
/// partly an occluder's outline.
pub const OCCLUDED_SIGMA_CELLS: f64 = 0.25;

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

/// Half the span of the central difference that measures the edge gradient, pixels (the
/// reference library uses 1; wider is less sensitive to noise and JPEG ringing, narrower
/// resolves closely spaced edges of tiny tags).
pub const GRADIENT_HALF_SPAN_PX: f64 = 1.0;

/// Cells narrower than this (pixels) use half the gradient span.
pub const SMALL_CELL_PX: f64 = 3.0;

/// Strength of the Laplacian sharpening of the sampled cell grid for small tags (the reference
/// library's default `decode_sharpening`).
pub const DECODE_SHARPENING: f64 = 0.25;

/// Half-width, in cells, of the 3 x 3 points whose grey values are averaged into a cell's: on
/// cells of [`AVERAGED_CELL_MIN_PX`] and more always, on smaller ones in the second reading of a
/// small tag (`DecodeOptions::average_cells`). Averaging over the cell's middle lowers the
/// noise of a dark or low-contrast tag; on cells of a few pixels it also takes in some of the
/// blurred neighbours, so the first reading of a small tag samples the centre only.
pub const CELL_SPREAD_CELLS: f64 = 0.2;

/// Smallest cell, pixels, whose grey value is always averaged over its middle
/// ([`CELL_SPREAD_CELLS`]).
pub const AVERAGED_CELL_MIN_PX: f64 = 4.0;

/// Detector settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DetectorConfig {
    /// Maximum number of corrected bit errors (tag36h11 has distance 11; 2 keeps the false
    /// positive rate of the reference library's default).
    pub max_hamming: u32,
    /// Tile size of the adaptive threshold, pixels.
    pub tile_px: usize,
    /// Minimum local contrast (max - min over the tile neighbourhood) as a fraction of the image
    /// range for a pixel to be classified.
    pub min_contrast: f32,
    /// Smallest tag side (black border) to look for, pixels.
    pub min_side_px: f64,
    /// Minimum decision margin: the mean distance of the white bits (and of the black bits, the
    /// smaller of the two) from the threshold, relative to the white/black difference (0..0.5).
    /// Rejects noise decoded by luck.
    pub min_margin: f64,
    /// Maximum deviation of the traced contour from the fitted side lines, as a fraction of the
    /// side length (plus one pixel for the pixel grid).
    pub max_side_deviation: f64,
    /// Which corner estimate is reported.
    #[serde(default)]
    pub corner_model: CornerModel,
    /// Refine the sides of small tags (cells up to [`crate::profile::MAX_CELL_PX`]) by fitting
    /// their edge profiles ([`crate::profile`]); only with [`CornerModel::EdgeGradient`]. Off by
    /// default: it lowers the corner error of small blurred tags on a dark or bright surround
    /// by 30..60 % and is neutral on the synthetic sessions, see the module docs.
    #[serde(default)]
    pub profile_small_tags: bool,
}

/// The corner estimator.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum CornerModel {
    /// Edge refinement on the grey image (step 4 of the method): the accurate one.
    #[default]
    EdgeGradient,
    /// The reference C library's unrefined quad (`refine_edges = 0`): lines fitted to the
    /// dark/light boundary of its adaptive threshold, gradient-weighted
    /// ([`crate::reference_quad`], the whole quad stage as that library runs it). A tag whose
    /// border that stage does not find is not reported. For comparing with that library's
    /// output only: it inherits the threshold's bias where the local maximum is not the white
    /// of the tag (a white ring darker than its surroundings pushes the boundary outward) and
    /// the half-pixel quantisation of the boundary, so it is less accurate
    /// (docs/benchmarks-poses.md). The covariance reported is the edge refinement's.
    BinaryBoundary,
}

impl DetectorConfig {
    /// Defaults that work on the real test photos and synthetic sessions.
    pub const DEFAULT: Self = Self {
        max_hamming: 2,
        tile_px: 4,
        min_contrast: 0.04,
        min_side_px: 8.0,
        min_margin: 0.1,
        max_side_deviation: 0.08,
        corner_model: CornerModel::EdgeGradient,
        profile_small_tags: false,
    };
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// One detected tag.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Detection {
    /// Tag ID in tag36h11.
    pub id: u32,
    /// Outer corners of the black border, pixel-centre convention, in the reference library's
    /// order: bottom-left, bottom-right, top-right, top-left as printed (tag frame `(-1,1)`,
    /// `(1,1)`, `(1,-1)`, `(-1,-1)`), the order of `skinbrdf_session::Target::corners_m`.
    pub corners_px: [DVec2; 4],
    /// 2 x 2 covariance of each corner, px², row-major `[xx, xy, yy]`.
    pub corner_cov_px2: [[f64; 3]; 4],
    /// Centre of the tag (image of the tag frame origin).
    pub center_px: DVec2,
    /// Number of corrected bit errors.
    pub hamming: u32,
    /// Decision margin: the smaller of the mean relative distances of white and black data bits
    /// from their threshold (0..~0.5; higher is safer).
    pub decision_margin: f64,
    /// RMS scatter of the edge points about the fitted sides, pixels.
    pub edge_rms_px: f64,
    /// Per corner (same order), whether it is partly hidden: the edge next to it lost its
    /// contrast on either side (something covers the ring or the border), a side next to it
    /// bends or is displaced against its own inner edges (an occluder's edge along the
    /// border, [`BORDER_WIDTH_SIGMAS`]), or cells of the grid near it disagree with a whole tag
    /// (a bright border cell, a dark white-ring cell, a corrected bit). Its covariance includes
    /// [`OCCLUDED_SIGMA_CELLS`] cells (and a displaced side's displacement); the pose stage
    /// does not use it.
    #[serde(default)]
    pub occluded_corners: [bool; 4],
}

impl Detection {
    /// Standard deviation of each corner along its worst direction, pixels.
    pub fn corner_sigma_px(&self) -> [f64; 4] {
        self.corner_cov_px2.map(|[a, b, c]| {
            let tr = 0.5 * (a + c);
            let disc = (0.25 * (a - c) * (a - c) + b * b).sqrt();
            (tr + disc).max(0.0).sqrt()
        })
    }

    /// Side length (mean of the four sides), pixels.
    pub fn side_px(&self) -> f64 {
        (0..4)
            .map(|i| self.corners_px[i].distance(self.corners_px[(i + 1) % 4]))
            .sum::<f64>()
            / 4.0
    }
}

/// Statistics of one detection run (cost and rejections, for reports).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct DetectStats {
    /// Dark components considered.
    pub components: usize,
    /// Components that fitted a quadrilateral.
    pub quads: usize,
    /// Quads rejected by decoding (no code within the Hamming limit, dark border or margin).
    pub rejected_decode: usize,
    /// Duplicate detections removed.
    pub duplicates: usize,
    /// Small tags decoded only on a second reading, through their refined quad with each cell
    /// averaged or through their contour's quad, after their refined quad did not decode
    /// (every corner marked occluded).
    #[serde(default, alias = "decoded_unrefined")]
    pub decoded_on_second_reading: usize,
}

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
    // 4-connected components first (a border touching dark surroundings only diagonally stays
    // apart from them), then the 8-connected groups of small ones (a small blurred border whose
    // pixels meet only diagonally).
    let singles = cc
        .stats
        .iter()
        .enumerate()
        .filter(|(_, c)| c.plausible(w, h, cfg))
        .map(|(k, c)| (*c, k as u32, false));
    let groups = cc
        .groups
        .iter()
        .filter(|c| c.plausible(w, h, cfg))
        .map(|c| (*c, cc.comp_of[c.root as usize], true));
    let candidates: Vec<(CompStats, u32, bool)> = singles.chain(groups).collect();
    // Groups holding a component that already decoded are not tried again.
    let mut decoded_groups: std::collections::HashSet<u32> = std::collections::HashSet::new();
    for (comp, k, grouped) in &candidates {
        let (comp, k) = (*comp, *k);
        if *grouped && decoded_groups.contains(&k) {
            continue;
        }
        stats.components += 1;
        let contour = if *grouped {
            trace_contour(|i| cc.in_group(i, k), w, h, &comp)
        } else {
            trace_contour(|i| cc.in_component(i, k), w, h, &comp)
        };
        let Some(quad) = fit_quad(&contour, cfg) else {
            continue;
        };
        stats.quads += 1;
        if !border_is_dark(img, &quad) {
            stats.rejected_decode += 1;
            continue;
        }
        let Some(mut refined) = refine_quad(img, quad) else {
            stats.rejected_decode += 1;
            continue;
        };
        // The inner edges' bias is taken off the edge refinement's own corners only.
        let mut unbias = cfg.corner_model == CornerModel::EdgeGradient;
        if cfg.corner_model == CornerModel::EdgeGradient && cfg.profile_small_tags {
            if let Some(c) = crate::profile::refine_small_tag(img, &refined.corners) {
                refined.corners = c;
                unbias = false;
            }
        }
        if let Some(refs) = &reference {
            // Tags whose border the reference library's quad stage does not find are not
            // reported in its model, as that library would not report them.
            let Some(b) = matching_reference_quad(refs, &refined.corners) else {
                stats.rejected_decode += 1;
                continue;
            };
            refined.corners = b;
        }
        // A small tag whose refined quad does not decode (UNREFINED_MAX_CELL_PX) is read a
        // second time: through the same quad with each cell's grey averaged over its middle
        // (a noisy, dark tag), then through its contour's quad, centre and averaged; its
        // corners are all marked occluded, their covariance the refined quad's plus
        // UNREFINED_SIGMA_CELLS. Not in the reference library's corner model, which reports
        // that library's quads only.
        let first = DecodeOptions {
            unbias_inner_edges: unbias,
            average_cells: false,
        };
        let det = decode(img, &refined, cfg, first).or_else(|| {
            let cell_px = refined.cell_px;
            if reference.is_some() || cell_px > UNREFINED_MAX_CELL_PX {
                return None;
            }
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
            stats.decoded_on_second_reading += 1;
            let extra = (UNREFINED_SIGMA_CELLS * cell_px).powi(2);
            for cov in &mut det.corner_cov_px2 {
                cov[0] += extra;
                cov[2] += extra;
            }
            det.occluded_corners = [true; 4];
            Some(det)
        });
        match det {
            Some(det) => {
                decoded_groups.insert(cc.group_of[k as usize]);
                out.push(det)
            }
            None => stats.rejected_decode += 1,
        }
    }
    // Remove duplicates: same ID with centres closer than a quarter side; keep the better margin.
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
    (kept, stats)
}

// ---------------------------------------------------------------------------------------------
// Threshold and components

/// Dark pixels of the adaptive threshold (step 1 of the method).
fn threshold(img: &GrayF32, cfg: &DetectorConfig) -> Vec<bool> {
    let (w, h) = (img.width, img.height);
    let ts = cfg.tile_px.max(2);
    let (tw, th) = (w.div_ceil(ts), h.div_ceil(ts));
    let mut tmin = vec![f32::INFINITY; tw * th];
    let mut tmax = vec![f32::NEG_INFINITY; tw * th];
    let (mut gmin, mut gmax) = (f32::INFINITY, f32::NEG_INFINITY);
    for y in 0..h {
        let row = &img.data[y * w..(y + 1) * w];
        let ty = y / ts;
        for (x, &v) in row.iter().enumerate() {
            let t = ty * tw + x / ts;
            tmin[t] = tmin[t].min(v);
            tmax[t] = tmax[t].max(v);
        }
    }
    for (&a, &b) in tmin.iter().zip(&tmax) {
        gmin = gmin.min(a);
        gmax = gmax.max(b);
    }
    let min_diff = cfg.min_contrast * (gmax - gmin).max(1e-12);
    // 3x3 tile dilation of min and max.
    let mut nmin = vec![0f32; tw * th];
    let mut nmax = vec![0f32; tw * th];
    for ty in 0..th {
        for tx in 0..tw {
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (x, y) = (tx as i64 + dx, ty as i64 + dy);
                    if x < 0 || y < 0 || x >= tw as i64 || y >= th as i64 {
                        continue;
                    }
                    let t = y as usize * tw + x as usize;
                    lo = lo.min(tmin[t]);
                    hi = hi.max(tmax[t]);
                }
            }
            nmin[ty * tw + tx] = lo;
            nmax[ty * tw + tx] = hi;
        }
    }
    let mut dark = vec![false; w * h];
    for y in 0..h {
        let ty = y / ts;
        for x in 0..w {
            let t = ty * tw + x / ts;
            let (lo, hi) = (nmin[t], nmax[t]);
            if hi - lo < min_diff {
                continue;
            }
            dark[y * w + x] = img.data[y * w + x] <= 0.5 * (lo + hi);
        }
    }
    dark
}

/// Largest 4-connected component (pixels) that is joined to its diagonal neighbours: the
/// black border of a tag with cells under 3 px (side under 24 px) holds at most
/// `7/16 · 24² ≈ 250` px, so this leaves ample room while keeping the large dark regions of a
/// scene (hair, shadow) out of the join.
pub const MAX_JOIN_PX: usize = 2048;

/// The dark pixels' components: 4-connected, and the 8-connected ones that join several of
/// them.
struct Components {
    /// Per pixel, the index of its 4-connected component in `stats` (`u32::MAX` for pixels
    /// that are not dark). Indices follow the components' first pixels in raster order.
    comp_of: Vec<u32>,
    /// Pixel count and bounding box of each 4-connected component.
    stats: Vec<CompStats>,
    /// Per 4-connected component, the first (lowest) index of the 8-connected group it is in.
    group_of: Vec<u32>,
    /// The 8-connected groups of more than one component.
    groups: Vec<CompStats>,
}

impl Components {
    /// Labels the dark pixels (union-find, 4-connected), then joins the small components that
    /// touch diagonally.
    fn new(dark: &[bool], w: usize, h: usize) -> Self {
        let mut labels: Vec<u32> = dark
            .iter()
            .enumerate()
            .map(|(i, &d)| if d { i as u32 } else { u32::MAX })
            .collect();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if labels[i] == u32::MAX {
                    continue;
                }
                if x > 0 && labels[i - 1] != u32::MAX {
                    union(&mut labels, i as u32, (i - 1) as u32);
                }
                if y > 0 && labels[i - w] != u32::MAX {
                    union(&mut labels, i as u32, (i - w) as u32);
                }
            }
        }
        for i in 0..w * h {
            if labels[i] != u32::MAX {
                labels[i] = find(&mut labels, i as u32);
            }
        }
        // Compact indices, in place: a root is its component's first pixel in raster order, so
        // the scan converts it (root pixel -> component index) before any other pixel of the
        // component reads it.
        let mut stats: Vec<CompStats> = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let r = labels[i];
                if r == u32::MAX {
                    continue;
                }
                let k = if r as usize == i {
                    stats.push(CompStats {
                        root: i as u32,
                        count: 0,
                        x0: x,
                        x1: x,
                        y0: y,
                        y1: y,
                    });
                    stats.len() - 1
                } else {
                    labels[r as usize] as usize
                };
                labels[i] = k as u32;
                let e = &mut stats[k];
                e.count += 1;
                e.x0 = e.x0.min(x);
                e.x1 = e.x1.max(x);
                e.y1 = y;
            }
        }
        let comp_of = labels;
        // Diagonal joins of small components (union-find over component indices).
        let mut group_of: Vec<u32> = (0..stats.len() as u32).collect();
        // One byte per component: the join pass reads it for every dark pixel.
        let small_flag: Vec<bool> = stats.iter().map(|c| c.count <= MAX_JOIN_PX).collect();
        let small = |k: u32| small_flag[k as usize];
        let mut any = false;
        for y in 1..h {
            for x in 0..w {
                let i = y * w + x;
                let a = comp_of[i];
                if a == u32::MAX || !small(a) {
                    continue;
                }
                for j in [x.checked_sub(1), (x + 1 < w).then_some(x + 1)]
                    .into_iter()
                    .flatten()
                    .map(|xj| i - w - x + xj)
                {
                    let c = comp_of[j];
                    if c != u32::MAX && c != a && small(c) {
                        union(&mut group_of, a, c);
                        any = true;
                    }
                }
            }
        }
        let mut groups: Vec<CompStats> = Vec::new();
        if any {
            let mut slot = vec![u32::MAX; stats.len()];
            for k in 0..stats.len() {
                let g = find(&mut group_of, k as u32) as usize;
                group_of[k] = g as u32;
                if g == k {
                    continue;
                }
                if slot[g] == u32::MAX {
                    slot[g] = groups.len() as u32;
                    groups.push(stats[g]);
                }
                groups[slot[g] as usize].join(&stats[k]);
            }
        }
        Self {
            comp_of,
            stats,
            group_of,
            groups,
        }
    }

    /// Whether pixel `i` belongs to the 4-connected component of index `k`.
    fn in_component(&self, i: usize, k: u32) -> bool {
        self.comp_of[i] == k
    }

    /// Whether pixel `i` belongs to the 8-connected group whose first component is `g`.
    fn in_group(&self, i: usize, g: u32) -> bool {
        let k = self.comp_of[i];
        k != u32::MAX && self.group_of[k as usize] == g
    }
}

/// Pixel count and bounding box of a component.
#[derive(Debug, Clone, Copy)]
struct CompStats {
    /// The first pixel in raster order (where contour tracing starts).
    root: u32,
    count: usize,
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
}

impl CompStats {
    fn join(&mut self, o: &CompStats) {
        self.count += o.count;
        self.x0 = self.x0.min(o.x0);
        self.x1 = self.x1.max(o.x1);
        self.y0 = self.y0.min(o.y0);
        self.y1 = self.y1.max(o.y1);
    }

    /// Whether the component can be a tag's black border: a fraction of the smallest tag's
    /// area (the border ring alone covers 7/16 of the square) and a bounding box that can hold a
    /// tag but not the whole image.
    fn plausible(&self, w: usize, h: usize, cfg: &DetectorConfig) -> bool {
        let min_side = cfg.min_side_px.max(4.0);
        let bw = (self.x1 - self.x0 + 1) as f64;
        let bh = (self.y1 - self.y0 + 1) as f64;
        bw.max(bh) >= min_side
            && bw.min(bh) >= 0.25 * min_side
            && self.count as f64 >= 0.3 * min_side * min_side
            && bw < w as f64
            && bh < h as f64
    }
}

fn find(p: &mut [u32], mut i: u32) -> u32 {
    let mut root = i;
    while p[root as usize] != root {
        root = p[root as usize];
    }
    while p[i as usize] != root {
        let next = p[i as usize];
        p[i as usize] = root;
        i = next;
    }
    root
}

fn union(p: &mut [u32], a: u32, b: u32) {
    let ra = find(p, a);
    let rb = find(p, b);
    if ra != rb {
        // Keep the smaller index as root: the root is then the first pixel in raster order,
        // which is where contour tracing starts.
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        p[hi as usize] = lo;
    }
}

/// Moore-neighbourhood tracing of the outer contour of the pixels for which `member` holds
/// (by pixel index), starting at their first pixel in raster order, `comp.root`.
fn trace_contour(
    member: impl Fn(usize) -> bool,
    w: usize,
    h: usize,
    comp: &CompStats,
) -> Vec<DVec2> {
    const DIRS: [(i64, i64); 8] = [
        (1, 0),
        (1, 1),
        (0, 1),
        (-1, 1),
        (-1, 0),
        (-1, -1),
        (0, -1),
        (1, -1),
    ];
    let inside = |x: i64, y: i64| -> bool {
        x >= 0
            && y >= 0
            && (x as usize) < w
            && (y as usize) < h
            && member(y as usize * w + x as usize)
    };
    let start = (
        (comp.root as usize % w) as i64,
        (comp.root as usize / w) as i64,
    );
    let dir_of = |from: (i64, i64), to: (i64, i64)| -> usize {
        let d = (to.0 - from.0, to.1 - from.1);
        DIRS.iter().position(|&e| e == d).unwrap_or(4)
    };
    let step = |p: (i64, i64), back: (i64, i64)| -> Option<((i64, i64), (i64, i64))> {
        let db = dir_of(p, back);
        for k in 1..=8 {
            let d = (db + k) % 8;
            let q = (p.0 + DIRS[d].0, p.1 + DIRS[d].1);
            if inside(q.0, q.1) {
                let pd = (d + 7) % 8;
                return Some((q, (p.0 + DIRS[pd].0, p.1 + DIRS[pd].1)));
            }
        }
        None
    };
    let mut contour = vec![DVec2::new(start.0 as f64, start.1 as f64)];
    let Some((first, mut back)) = step(start, (start.0 - 1, start.1)) else {
        return contour;
    };
    let mut p = first;
    let limit = 4 * comp.count + 16;
    while contour.len() < limit {
        if p == start {
            // Jacob's criterion variant: stop when leaving the start the same way as at first.
            if let Some((q, _)) = step(p, back) {
                if q == first {
                    break;
                }
            }
        }
        contour.push(DVec2::new(p.0 as f64, p.1 as f64));
        let Some((q, b)) = step(p, back) else { break };
        p = q;
        back = b;
    }
    contour
}

// ---------------------------------------------------------------------------------------------
// Quad fitting

/// A line `n · x = d` with unit normal `n`.
#[derive(Debug, Clone, Copy)]
struct Line {
    n: DVec2,
    d: f64,
    /// Centroid of the fitted points and their spread along the line (for the covariance).
    centroid: DVec2,
    sum_t2: f64,
    count: f64,
    /// Scatter of the fitted points about the line, pixels.
    sigma: f64,
    /// What the points' scatter is multiplied by, in variance, for the line's offset and tilt:
    /// more than 1 when neighbouring points' errors are correlated (`allow_for_correlation`).
    var_factor: f64,
    /// `[α, β, var_b]`: the line was moved by `b (α + β t)` at `t` (from the centroid, along
    /// the line) to undo the tag's inner-edge bias `b` (`unbias_inner_edges`), so its offset
    /// there is uncertain by `(α + β t)² var_b` more. Zero when not corrected.
    bias_var: [f64; 3],
}

impl Line {
    fn dir(&self) -> DVec2 {
        DVec2::new(-self.n.y, self.n.x)
    }
    fn intersect(&self, o: &Line) -> Option<DVec2> {
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
    fn offset_var_at(&self, p: DVec2) -> f64 {
        let t = (p - self.centroid).dot(self.dir());
        let s2 = self.sigma * self.sigma * self.var_factor;
        let [alpha, beta, var_b] = self.bias_var;
        s2 / self.count.max(1.0)
            + s2 * t * t / self.sum_t2.max(1e-9)
            + (alpha + beta * t).powi(2) * var_b
    }
}

/// Weighted total-least-squares line through points.
fn fit_line(pts: &[(DVec2, f64)]) -> Option<Line> {
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

fn signed_area(q: &[DVec2; 4]) -> f64 {
    let mut a = 0.0;
    for i in 0..4 {
        let (p, r) = (q[i], q[(i + 1) % 4]);
        a += p.x * r.y - r.x * p.y;
    }
    0.5 * a
}

fn is_convex(q: &[DVec2; 4]) -> bool {
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
fn fit_quad(contour: &[DVec2], cfg: &DetectorConfig) -> Option<[DVec2; 4]> {
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

/// Largest distance of a corner of the reference library's quad from ours for the two to be the
/// same tag's outer border, pixels (the two estimators differ by under a pixel on real photos;
/// the next quad of a tag, the inner edge of its border, is a cell away).
const REFERENCE_MATCH_PX: f64 = 3.0;

/// The reference library's quad (from [`crate::reference_quad::reference_quads`]) that is the
/// same outer border as `q`, its corners reordered to match `q`'s.
fn matching_reference_quad(refs: &[[DVec2; 4]], q: &[DVec2; 4]) -> Option<[DVec2; 4]> {
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

// ---------------------------------------------------------------------------------------------
// Edge refinement

/// One side's edge points (position, gradient energy, edge contrast) and its contrast samples
/// (position along the side, contrast).
type SideSamples = (Vec<(DVec2, f64, f64)>, Vec<(f64, f64)>);

struct RefinedQuad {
    corners: [DVec2; 4],
    cov: [[f64; 3]; 4],
    edge_rms_px: f64,
    /// Per corner, the smaller visible fraction of the quarters of its two sides next to it.
    visible_near: [f64; 4],
    /// Side length over 8, pixels.
    cell_px: f64,
    /// Per corner, whether a side next to it bends (see [`BEND_SIGMAS`]).
    bent: [bool; 4],
    /// The fitted sides (side `k` from corner `k` to `k + 1`).
    lines: [Line; 4],
    /// The tag's median edge contrast (Michelson, white ring against black border).
    median_contrast: f64,
    /// Per side, the edge points its line was fitted to (position, weight).
    edge_points: [Vec<(DVec2, f64)>; 4],
    /// Per side, at its start and end corner: how far the half-side's line is from the side's,
    /// and that distance's variance from noise alone.
    bend: [[(f64, f64); 2]; 4],
}

/// Refines the sides on the grey image. `q` has positive signed area (clockwise on screen with y
/// down), so the outward normal of side `a -> b` is `perp(b - a)` rotated to point out.
fn refine_quad(img: &GrayF32, q: [DVec2; 4]) -> Option<RefinedQuad> {
    let mut corners = q;
    let mut lines: Vec<Line> = Vec::new();
    let side_mean = (0..4).map(|k| q[k].distance(q[(k + 1) % 4])).sum::<f64>() / 4.0;
    let cell = side_mean / 8.0;
    // Search window half-width: the initial error is about a pixel; never wider than most of a
    // cell so the window stays inside the black border and white ring.
    let mut range = (0.8 * cell).clamp(1.0, 3.0);
    // Small cells: the border's inner edge and the white ring's outer edge are within a cell of
    // the edge we want; a narrower difference keeps their gradient lobes from biasing it.
    let gspan = if cell < SMALL_CELL_PX {
        0.5 * GRADIENT_HALF_SPAN_PX
    } else {
        GRADIENT_HALF_SPAN_PX
    };
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
        // Per side: the edge points (position, gradient energy, edge contrast) and, for every
        // sample along the side, its position along the side and its edge contrast.
        let mut sides: Vec<SideSamples> = Vec::with_capacity(4);
        for k in 0..4 {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
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
                // Michelson contrast of the white ring against the black border half a cell
                // either side of the edge: independent of the light level (a shadow), low where
                // something covers the ring or the border.
                let (inner, outer) = (
                    img.bilinear(p - outward * (0.5 * cell)),
                    img.bilinear(p + outward * (0.5 * cell)),
                );
                let m = (outer - inner) / (outer.abs() + inner.abs()).max(1e-9);
                contrast.push((t, m));
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
                    continue;
                }
                pts.push((p + outward * (mn / mw), mw, m));
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
                        let (inner, outer) = (
                            img.bilinear(p - outward * (0.5 * cell)),
                            img.bilinear(p + outward * (0.5 * cell)),
                        );
                        (outer - inner) / (outer.abs() + inner.abs()).max(1e-9)
                    } else {
                        0.0
                    };
                    contrast.push((t, m));
                }
            }
            sides.push((pts, contrast));
        }
        // A sample is visible when its contrast is at least VISIBLE_CONTRAST of the tag's
        // median; the sides are fitted to their visible edge points.
        let mut all: Vec<f64> = sides.iter().flat_map(|s| s.1.iter().map(|c| c.1)).collect();
        all.sort_by(f64::total_cmp);
        let median = all.get(all.len() / 2).copied().unwrap_or(0.0);
        if median <= 0.0 {
            return None;
        }
        median_contrast = median;
        let visible_at = VISIBLE_CONTRAST * median;
        // A sample whose contrast is more than CONTRAST_CEILING_MADS of the tag's robust
        // scatter (and at least MIN_CONTRAST_EXCESS) above the median has something brighter
        // than the ring within half a cell of the edge.
        let mut dev: Vec<f64> = all.iter().map(|m| (m - median).abs()).collect();
        dev.sort_by(f64::total_cmp);
        let mad = dev.get(dev.len() / 2).copied().unwrap_or(0.0);
        let ceiling =
            median + (CONTRAST_CEILING_MADS * MAD_TO_SIGMA * mad).max(MIN_CONTRAST_EXCESS);
        let visible = |m: f64| (visible_at..=ceiling).contains(&m);
        for k in 0..4 {
            let (pts, contrast) = &sides[k];
            let mut used: Vec<(DVec2, f64)> = pts
                .iter()
                .filter(|p| visible(p.2))
                .map(|p| (p.0, p.1))
                .collect();
            // Too little of the side visible to fit: fit all its edge points and mark both its
            // corners occluded.
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
            // Straightness: lines fitted to each half of the side, at the corner of that half,
            // against the whole side's line. A side partly replaced by another edge (an
            // occluder's outline along the border) bends; a whole side does not beyond noise.
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            let len = a.distance(b).max(1e-9);
            let half = |first: bool| -> Vec<(DVec2, f64)> {
                used.iter()
                    .copied()
                    .filter(|p| ((p.0 - a).dot(b - a) / (len * len) < 0.5) == first)
                    .collect()
            };
            if !last {
                lines.push(line);
                continue;
            }
            for (end, corner, pts_half) in [(0usize, a, half(true)), (1, b, half(false))] {
                bend[k][end] = (0.0, 0.0);
                if pts_half.len() >= 4 {
                    if let Some(hl) = fit_line(&pts_half) {
                        let d =
                            (corner.dot(hl.n) - hl.d).abs() - (corner.dot(line.n) - line.d).abs();
                        bend[k][end] = (d.abs(), hl.offset_var_at(corner));
                    }
                }
            }
            lines.push(line);
            edge_points[k] = used;
            // Visible fraction of the quarter of the side next to each of its corners.
            let near = |lo: f64, hi: f64| {
                let (n, v) = contrast
                    .iter()
                    .filter(|c| c.0 >= lo && c.0 <= hi)
                    .fold((0usize, 0usize), |(n, v), c| {
                        (n + 1, v + usize::from(visible(c.1)))
                    });
                if n == 0 {
                    0.0
                } else {
                    v as f64 / n as f64
                }
            };
            visible_near[k] = if hidden {
                [0.0; 2]
            } else {
                [near(0.0, 0.3), near(0.7, 1.0)]
            };
        }
        let mut next = [DVec2::ZERO; 4];
        for k in 0..4 {
            next[k] = lines[(k + 3) % 4].intersect(&lines[k])?;
        }
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
fn allow_for_correlation(lines: &mut [Line; 4], points: &[Vec<(DVec2, f64)>; 4]) {
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
fn corner_covariance(
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

// ---------------------------------------------------------------------------------------------
// The inner edges' pull on small tags' outer edges

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
fn unbias_inner_edges(
    rq: &RefinedQuad,
    h: &DMat3,
    white: &[[bool; 10]; 10],
) -> Option<RefinedQuad> {
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
    // The sides' lines with their normals outward (`refine_quad`'s convention: the interior
    // is to the right of corner k -> k + 1 on screen), so that `b` has one sign on every side.
    let outward_lines: [Line; 4] = std::array::from_fn(|k| {
        let mut line = rq.lines[k];
        let along = rq.corners[(k + 1) % 4] - rq.corners[k];
        if line.n.dot(DVec2::new(along.y, -along.x)) < 0.0 {
            line.n = -line.n;
            line.d = -line.d;
        }
        line
    });
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
    let mut corners = [DVec2::ZERO; 4];
    for k in 0..4 {
        corners[k] = lines[(k + 3) % 4].intersect(&lines[k])?;
    }
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

// ---------------------------------------------------------------------------------------------
// Border width: a side displaced by an occluding edge

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
/// its standard deviations from the edge fits' scatter: four, as for a bend ([`BEND_SIGMAS`]),
/// so that Gaussian noise alone flags about one side in 16 000 (the two-sided 4-sigma tail).
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

/// The tag square's corners in quad order (those of [`square_to_quad`]).
const SQUARE: [(f64, f64); 4] = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];

/// The inner edges measured along one side of the quad.
#[derive(Debug, Clone, Copy, PartialEq)]
struct InnerEdges {
    /// Mean position of the inner edges along the inward normal, relative to where the quad's
    /// homography puts them (one or two cells inside the fitted outer edge), pixels: positive
    /// when the border is thicker than the quad predicts.
    offset_px: f64,
    /// Variance of `offset_px` from noise: the samples' scatter (or the outer line's, when
    /// larger) over their independent count, plus the outer line's offset variance, px².
    var_px2: f64,
    /// The offset as a straight line along the side (least squares over the samples'
    /// positions), at the side's start and end corners, pixels: an occluder's edge at a slant
    /// to the side thins the border more towards one corner. The mean where the samples are
    /// too few, or all at one place, to give a slope.
    end_offset_px: [f64; 2],
    /// Variances of `end_offset_px` from noise: the line's residual scatter (or the outer
    /// line's, when larger) over the independent count, extrapolated to the corner, plus the
    /// outer line's offset variance there, px².
    end_var_px2: [f64; 2],
}

/// Measures the edges behind the black border along each side of the quad (`h`: the quad's
/// homography from the tag square, `white`: the decoded code's cells in the quad's frame) where the
/// code puts a white data cell within [`MAX_INNER_EDGE_DEPTH`] cells of the outer edge and the cell
/// across the edge is at least `min_cell_px`: the centroid of the squared dark-to-light gradient
/// along the edge's normal (the outer edges' estimator, step 4), in a window re-centred over three
/// passes. Samples whose contrast is below [`VISIBLE_CONTRAST`] of the tag's median are left out
/// (the white cell is hidden). `None` for a side with no sample (no white cell within reach, all
/// hidden, or cells under `min_cell_px` across it).
fn inner_edges(
    img: &GrayF32,
    h: &DMat3,
    white: &[[bool; 10]; 10],
    rq: &RefinedQuad,
    min_cell_px: f64,
) -> [Option<InnerEdges>; 4] {
    let cw = 2.0 / tag36h11::WIDTH_AT_BORDER as f64;
    let probe = EdgeProbe {
        gspan: if rq.cell_px < SMALL_CELL_PX {
            0.5 * GRADIENT_HALF_SPAN_PX
        } else {
            GRADIENT_HALF_SPAN_PX
        },
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
struct SideDisplacement {
    /// How far the fitted outer edge lies inside where the inner edges put it, pixels
    /// (negative: outside), at the side's start and end corners.
    d_px: [f64; 2],
    /// Beyond [`BORDER_WIDTH_SIGMAS`] and [`MIN_BORDER_DISPLACEMENT_PX`] at that corner: an
    /// occluder's edge, so the corner is marked occluded. Short of either, the displacement
    /// may as well be the gradient centroid's sub-pixel phase bias; the corner is uncertain by
    /// that much all the same, so it goes into its covariance without marking it.
    marked: [bool; 2],
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
fn displaced_sides(e: &[Option<InnerEdges>; 4]) -> [Option<SideDisplacement>; 4] {
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
fn thinner_of_pair(side: InnerEdges, opposite: InnerEdges) -> [Option<SideDisplacement>; 2] {
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

// ---------------------------------------------------------------------------------------------
// Decoding

/// Mean grey value of cell (row, col) of the 10 x 10 grid: the cell centre, averaged with 3 x 3
/// points in its middle when cells are large enough (`spread` in cell units, 0 = centre only).
fn sample_cell(img: &GrayF32, h: &DMat3, row: usize, col: usize, spread: f64) -> Option<f64> {
    let cw = 2.0 / tag36h11::WIDTH_AT_BORDER as f64;
    let u0 = -1.0 + (col as f64 - 0.5) * cw;
    let v0 = -1.0 + (row as f64 - 0.5) * cw;
    let offs: &[f64] = if spread > 0.0 {
        &[-1.0, 0.0, 1.0]
    } else {
        &[0.0]
    };
    let mut acc = 0.0;
    let mut n = 0.0;
    for sy in offs {
        for sx in offs {
            let p = apply_h(h, DVec2::new(u0 + sx * spread * cw, v0 + sy * spread * cw));
            if !img.contains(p, 0.0) {
                continue;
            }
            acc += img.bilinear(p);
            n += 1.0;
        }
    }
    (n > 0.0).then(|| acc / n)
}

/// Least-squares plane `a + b u + c v` through `(u, v, value)`; falls back to the mean when the
/// points do not span the plane.
fn fit_plane(pts: &[(f64, f64, f64)]) -> Option<[f64; 3]> {
    if pts.is_empty() {
        return None;
    }
    let mean = pts.iter().map(|p| p.2).sum::<f64>() / pts.len() as f64;
    let mut ata = DMat3::ZERO;
    let mut atb = DVec3::ZERO;
    for &(u, v, z) in pts {
        let r = DVec3::new(1.0, u, v);
        ata += DMat3::from_cols(r * r.x, r * r.y, r * r.z);
        atb += r * z;
    }
    if pts.len() < 6 || ata.determinant().abs() < 1e-9 {
        return Some([mean, 0.0, 0.0]);
    }
    let s = ata.inverse() * atb;
    Some([s.x, s.y, s.z])
}

fn cell_uv(row: usize, col: usize) -> (f64, f64) {
    let cw = 2.0 / tag36h11::WIDTH_AT_BORDER as f64;
    (
        -1.0 + (col as f64 - 0.5) * cw,
        -1.0 + (row as f64 - 0.5) * cw,
    )
}

/// Most border cells brighter than the midpoint of the black and white models on the
/// unrefined quad (a quick test before the edge refinement; decoding allows 3 on the refined
/// one, and the unrefined corners can be a pixel off, which puts some cell centres of a small
/// tag onto its edges).
const MAX_BRIGHT_BORDER_UNREFINED: usize = 8;

/// Whether the black border of quad `q` (unrefined) is dark against its white ring: the cell
/// centres of the two rings, each modelled as a plane over the tag.
fn border_is_dark(img: &GrayF32, q: &[DVec2; 4]) -> bool {
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

/// How a quad's code is read (`decode`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct DecodeOptions {
    /// Refit a small tag's sides without its inner edges' pull (`unbias_inner_edges`) once
    /// the code is known; off for a quad that is not the edge refinement's own.
    unbias_inner_edges: bool,
    /// Average each cell's grey over its middle ([`CELL_SPREAD_CELLS`]) whatever its size.
    average_cells: bool,
}

/// Reads the code of a refined quad (step 6 of the method), tests its border's width (step 7)
/// and reports the tag.
fn decode(
    img: &GrayF32,
    rq: &RefinedQuad,
    cfg: &DetectorConfig,
    opts: DecodeOptions,
) -> Option<Detection> {
    let q = rq.corners;
    // Sample the grid once in the quad's own order; rotations permute the grid.
    let h = square_to_quad(&q)?;
    let side_px = (0..4)
        .map(|k| q[k].distance(q[(k + 1) % 4]))
        .fold(f64::INFINITY, f64::min);
    let cell_px = side_px / tag36h11::WIDTH_AT_BORDER as f64;
    let spread = if opts.average_cells || cell_px >= AVERAGED_CELL_MIN_PX {
        CELL_SPREAD_CELLS
    } else {
        0.0
    };
    let mut raw = [[None; 10]; 10];
    for (r, row) in raw.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = sample_cell(img, &h, r, c, spread);
        }
    }
    // Sharpen the sampled grid (Laplacian, as the reference library's decode_sharpening) to
    // undo the blur that mixes neighbouring cells when cells are only a few pixels wide.
    let mut grid = raw;
    if cell_px < 6.0 {
        for r in 0..10 {
            for c in 0..10 {
                let Some(v) = raw[r][c] else { continue };
                let mut lap = 0.0;
                let mut n = 0.0;
                for (dr, dc) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                    if (0..10).contains(&rr) && (0..10).contains(&cc) {
                        if let Some(nv) = raw[rr as usize][cc as usize] {
                            lap += v - nv;
                            n += 1.0;
                        }
                    }
                }
                if n > 0.0 {
                    grid[r][c] = Some(v + DECODE_SHARPENING * lap * 4.0 / n);
                }
            }
        }
    }
    let ring = |r: usize, c: usize, k: usize| r.min(c).min(9 - r).min(9 - c) == k;
    let mut black = Vec::new();
    let mut white = Vec::new();
    for r in 0..10 {
        for c in 0..10 {
            let Some(v) = grid[r][c] else { continue };
            let (u, w) = cell_uv(r, c);
            if ring(r, c, 1) {
                black.push((u, w, v));
            } else if ring(r, c, 0) {
                white.push((u, w, v));
            }
        }
    }
    if black.len() < 20 {
        return None;
    }
    let bp = fit_plane(&black)?;
    let eval = |p: &[f64; 3], u: f64, v: f64| p[0] + p[1] * u + p[2] * v;
    // White reference: the outer ring when it is mostly visible, else the brightest data cells.
    let wp = if white.len() >= 18 {
        fit_plane(&white)?
    } else {
        let mut data: Vec<f64> = (2..8)
            .flat_map(|r| (2..8).map(move |c| (r, c)))
            .filter_map(|(r, c)| grid[r][c])
            .collect();
        data.sort_by(f64::total_cmp);
        let top = &data[data.len() * 3 / 4..];
        [top.iter().sum::<f64>() / top.len().max(1) as f64, 0.0, 0.0]
    };
    // Border must be dark against the white model.
    let mut bright_border = 0;
    for &(u, v, z) in &black {
        let (lo, hi) = (eval(&bp, u, v), eval(&wp, u, v));
        if hi - lo <= 0.0 || z > 0.5 * (lo + hi) {
            bright_border += 1;
        }
    }
    if bright_border > 3 {
        return None;
    }
    // Occlusion evidence per quad corner (the quadrant of the grid nearest to it): border cells
    // that are not dark, white-ring cells that are not light.
    let quadrant = |r: usize, c: usize| match (c >= 5, r >= 5) {
        (false, false) => 0,
        (true, false) => 1,
        (true, true) => 2,
        (false, true) => 3,
    };
    let mut evidence = [0usize; 4];
    for r in 0..10 {
        for c in 0..10 {
            let Some(z) = grid[r][c] else { continue };
            let (u, v) = cell_uv(r, c);
            let (lo, hi) = (eval(&bp, u, v), eval(&wp, u, v));
            let mid = 0.5 * (lo + hi);
            let bad = (ring(r, c, 1) && (hi - lo <= 0.0 || z > mid))
                || (ring(r, c, 0) && white.len() >= 18 && z < mid);
            if bad {
                evidence[quadrant(r, c)] += 1;
            }
        }
    }
    // Read the data bits for each of the four rotations (corner shifts).
    let mut best: Option<(u32, u32, usize, f64)> = None; // (hamming, id, shift, margin)
    for shift in 0..4 {
        let mut code = 0u64;
        let (mut white_m, mut white_n, mut black_m, mut black_n) = (0.0, 0.0, 0.0, 0.0);
        let mut ok = true;
        for i in 0..tag36h11::NBITS {
            // Cell (row, col) in the tag's own frame, mapped into the quad's frame by the shift:
            // a corner shift by one is a quarter turn of the grid.
            let (mut r, mut c) = (
                tag36h11::BIT_Y[i] as usize + 1,
                tag36h11::BIT_X[i] as usize + 1,
            );
            for _ in 0..shift {
                // Quarter turn: tag corner k sits at quad corner k + 1 ...
                let (nr, nc) = (c, 9 - r);
                r = nr;
                c = nc;
            }
            let Some(v) = grid[r][c] else {
                ok = false;
                break;
            };
            let (u, w) = cell_uv(r, c);
            let (lo, hi) = (eval(&bp, u, w), eval(&wp, u, w));
            let thr = 0.5 * (lo + hi);
            let m = (v - thr) / (hi - lo).max(1e-12);
            code <<= 1;
            if v > thr {
                code |= 1;
                white_m += m;
                white_n += 1.0;
            } else {
                black_m -= m;
                black_n += 1.0;
            }
        }
        let margin = (white_m / f64::max(white_n, 1.0)).min(black_m / f64::max(black_n, 1.0));
        if !ok {
            continue;
        }
        for (id, &cw) in tag36h11::CODES.iter().enumerate() {
            let d = (cw ^ code).count_ones();
            if d <= cfg.max_hamming && best.is_none_or(|b| d < b.0) {
                best = Some((d, id as u32, shift, margin));
            }
        }
    }
    let (hamming, id, shift, margin) = best?;
    if margin < cfg.min_margin {
        return None;
    }
    let wrong = tag36h11::CODES[id as usize];
    let mut code = 0u64;
    let mut cells = [(0usize, 0usize); tag36h11::NBITS];
    for (i, cell) in cells.iter_mut().enumerate() {
        let (mut r, mut c) = (
            tag36h11::BIT_Y[i] as usize + 1,
            tag36h11::BIT_X[i] as usize + 1,
        );
        for _ in 0..shift {
            let (nr, nc) = (c, 9 - r);
            r = nr;
            c = nc;
        }
        *cell = (r, c);
        let (u, w) = cell_uv(r, c);
        let thr = 0.5 * (eval(&bp, u, w) + eval(&wp, u, w));
        code = (code << 1) | u64::from(grid[r][c].is_some_and(|v| v > thr));
    }
    let diff = code ^ wrong;
    for (i, &(r, c)) in cells.iter().enumerate() {
        if (diff >> (tag36h11::NBITS - 1 - i)) & 1 == 1 {
            evidence[quadrant(r, c)] += 1;
        }
    }
    // The code's cells in the quad's frame: the white ring, the black border and the data.
    let mut white = [[false; 10]; 10];
    for (r, row) in white.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = ring(r, c, 0);
        }
    }
    for (i, &(r, c)) in cells.iter().enumerate() {
        white[r][c] = (wrong >> (tag36h11::NBITS - 1 - i)) & 1 == 1;
    }
    // A small tag's sides without the pull of its inner edges, now that the code says where
    // they are.
    let unbiased = if opts.unbias_inner_edges && cell_px < INNER_EDGE_BIAS_MAX_CELL_PX {
        unbias_inner_edges(rq, &h, &white)
    } else {
        None
    };
    let rq = unbiased.as_ref().unwrap_or(rq);
    // Border width: a side whose outer edge is displaced against its inner edges (an
    // occluder's edge along the border) has its displacement in both its corners' covariance
    // along that side's normal, and the corners marked occluded when it is beyond the floor.
    let edges = inner_edges(img, &h, &white, rq, MIN_WIDTH_TEST_CELL_PX);
    let mut shifted = displaced_sides(&edges);
    // A pair of sides with cells too small across them for both to be measured on their own is
    // measured down to MIN_PAIR_WIDTH_TEST_CELL_PX and its two sides compared with each other.
    let unmeasured = |k: usize| edges[k].is_none() || edges[k + 2].is_none();
    if unmeasured(0) || unmeasured(1) {
        let narrow = inner_edges(img, &h, &white, rq, MIN_PAIR_WIDTH_TEST_CELL_PX);
        for k in (0..2).filter(|&k| unmeasured(k)) {
            if let (Some(a), Some(b)) = (narrow[k], narrow[k + 2]) {
                [shifted[k], shifted[k + 2]] = thinner_of_pair(a, b);
            }
        }
    }
    // A corner is occluded when the edge next to it is hidden on either side, a side next to it
    // bends or is displaced, or the cells of its quadrant disagree with a whole tag; its
    // covariance then gets an isotropic term of OCCLUDED_SIGMA_CELLS cells.
    let occluded_q: [bool; 4] = std::array::from_fn(|j| {
        rq.visible_near[j] < MIN_VISIBLE_NEAR
            || evidence[j] > 0
            || rq.bent[j]
            || shifted[j].is_some_and(|s| s.marked[0])
            || shifted[(j + 3) % 4].is_some_and(|s| s.marked[1])
    });
    let extra = (OCCLUDED_SIGMA_CELLS * rq.cell_px).powi(2);
    // A displaced side `k` moves its corners along the other side through each: corner `k`
    // along side `k - 1`, corner `k + 1` along side `k + 1`, by the displacement over the sine
    // of their angle (floored as in the edge refinement's covariance).
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
    // Reorder corners so corner 0 is the tag's printed top-left. With the grid turned by
    // `shift` quarter turns, the tag's corner k is the quad's corner k - shift.
    let mut corners = [DVec2::ZERO; 4];
    let mut cov = [[0.0; 3]; 4];
    let mut occluded = [false; 4];
    for k in 0..4 {
        let j = (k + shift) % 4;
        corners[k] = rq.corners[j];
        cov[k] = rq_cov[j];
        occluded[k] = occluded_q[j];
        if occluded[k] {
            cov[k][0] += extra;
            cov[k][2] += extra;
        }
    }
    let ht = square_to_quad(&corners)?;
    // Output in the reference library's order (bottom-left, bottom-right, top-right, top-left).
    let rev = |a: [DVec2; 4]| [a[3], a[2], a[1], a[0]];
    let revc = |a: [[f64; 3]; 4]| [a[3], a[2], a[1], a[0]];
    let revb = |a: [bool; 4]| [a[3], a[2], a[1], a[0]];
    Some(Detection {
        id,
        corners_px: rev(corners),
        corner_cov_px2: revc(cov),
        center_px: apply_h(&ht, DVec2::ZERO),
        hamming,
        decision_margin: margin,
        edge_rms_px: rq.edge_rms_px,
        occluded_corners: revb(occluded),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::paint_tag;
    use rand::{Rng, SeedableRng};

    fn blank(w: usize, h: usize, v: f32) -> GrayF32 {
        GrayF32::new(w, h, vec![v; w * h]).expect("size matches")
    }

    /// Homography of a tag of half-size `s` px centred at `c`, turned by `angle` and with a
    /// perspective term `(g, h)`.
    fn tag_h(c: DVec2, s: f64, angle: f64, g: f64, h: f64) -> DMat3 {
        let (sn, cs) = angle.sin_cos();
        DMat3::from_cols(
            DVec3::new(s * cs + c.x * g, s * sn + c.y * g, g),
            DVec3::new(-s * sn + c.x * h, s * cs + c.y * h, h),
            DVec3::new(c.x, c.y, 1.0),
        )
    }

    fn truth_corners(h: &DMat3) -> [DVec2; 4] {
        [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)]
            .map(|(x, y)| apply_h(h, DVec2::new(x, y)))
    }

    #[test]
    fn finds_rotated_and_foreshortened_tags_with_subpixel_corners() {
        let mut img = blank(640, 480, 0.5);
        let cases = [
            (3usize, DVec2::new(120.0, 120.0), 40.0, 0.0, 0.0, 0.0),
            (42, DVec2::new(320.0, 120.0), 50.0, 1.7, 0.0005, 0.0),
            (100, DVec2::new(510.0, 130.0), 45.0, 3.0, -0.0008, 0.0004),
            (586, DVec2::new(150.0, 350.0), 30.0, 4.4, 0.0, 0.0012),
            (7, DVec2::new(420.0, 340.0), 60.0, -0.3, 0.0007, 0.0007),
        ];
        let mut truth = Vec::new();
        for &(id, c, s, a, g, h) in &cases {
            let hm = tag_h(c, s, a, g, h);
            assert!(paint_tag(&mut img, &hm, id, 0.08, 0.9, 8));
            truth.push((id as u32, truth_corners(&hm)));
        }
        let dets = detect(&img, &DetectorConfig::default());
        assert_eq!(dets.len(), cases.len(), "{dets:?}");
        for (id, corners) in truth {
            let d = dets.iter().find(|d| d.id == id).expect("tag found");
            for k in 0..4 {
                let e = d.corners_px[k].distance(corners[k]);
                assert!(e < 0.1, "tag {id} corner {k}: error {e} px");
            }
            assert_eq!(d.hamming, 0);
        }
    }

    #[test]
    fn binary_boundary_corners_are_coarser_than_edge_refined_ones() {
        let mut img = blank(640, 480, 0.5);
        let cases = [
            (3usize, DVec2::new(160.0, 140.0), 40.0, 0.3, 0.0004, 0.0),
            (42, DVec2::new(450.0, 300.0), 50.0, 1.7, 0.0, 0.0006),
        ];
        for &(id, c, s, a, g, h) in &cases {
            assert!(paint_tag(&mut img, &tag_h(c, s, a, g, h), id, 0.08, 0.9, 8));
        }
        let boundary = DetectorConfig {
            corner_model: CornerModel::BinaryBoundary,
            ..DetectorConfig::default()
        };
        let rms = |cfg: &DetectorConfig| {
            let dets = detect(&img, cfg);
            assert_eq!(dets.len(), cases.len(), "{dets:?}");
            let mut s2 = 0.0;
            for &(id, c, s, a, g, h) in &cases {
                let truth = truth_corners(&tag_h(c, s, a, g, h));
                let d = dets.iter().find(|d| d.id == id as u32).expect("tag found");
                for k in 0..4 {
                    s2 += d.corners_px[k].distance_squared(truth[k]);
                }
            }
            (s2 / (4 * cases.len()) as f64).sqrt()
        };
        let (edge, binary) = (rms(&DetectorConfig::default()), rms(&boundary));
        // The boundary of the threshold sits on the half-pixel grid: a few tenths of a pixel,
        // not the edge refinement's few hundredths.
        assert!(binary < 0.3, "binary boundary RMS {binary}");
        assert!(
            edge < 0.5 * binary,
            "edge {edge} vs binary boundary {binary}"
        );
    }

    #[test]
    fn survives_noise_blur_and_a_lighting_gradient_with_honest_sigma() {
        let (w, h) = (400usize, 300usize);
        let mut img = blank(w, h, 0.0);
        let hm = tag_h(DVec2::new(200.3, 150.7), 70.0, 0.4, 0.0003, -0.0002);
        // Paint into a white card, then apply a strong left-to-right flash falloff and noise.
        for v in img.data.iter_mut() {
            *v = 0.9;
        }
        assert!(paint_tag(&mut img, &hm, 11, 0.05, 0.9, 8));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        // 3x3 box blur.
        let src = img.clone();
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let mut s = 0.0;
                for dy in 0..3 {
                    for dx in 0..3 {
                        s += src.data[(y + dy - 1) * w + x + dx - 1];
                    }
                }
                img.data[y * w + x] = s / 9.0;
            }
        }
        for y in 0..h {
            for x in 0..w {
                let gain = 0.35 + 0.65 * x as f32 / w as f32;
                let n: f32 = rng.random_range(-0.03..0.03);
                img.data[y * w + x] = img.data[y * w + x] * gain + n;
            }
        }
        let dets = detect(&img, &DetectorConfig::default());
        assert_eq!(dets.len(), 1, "{dets:?}");
        let truth = truth_corners(&hm);
        let d = &dets[0];
        assert_eq!(d.id, 11);
        let sig = d.corner_sigma_px();
        for k in 0..4 {
            let e = d.corners_px[k].distance(truth[k]);
            assert!(e < 0.15, "corner {k}: error {e}");
            // The stated uncertainty is within a factor of a few of the actual error scale.
            assert!(sig[k] > 0.005 && sig[k] < 0.3, "sigma {}", sig[k]);
        }
    }

    #[test]
    fn rejects_plain_squares_and_noise() {
        let mut img = blank(300, 300, 0.8);
        // A black square with no code, and a square with a random (non-code) pattern.
        for y in 50..130 {
            for x in 50..130 {
                img.data[y * 300 + x] = 0.1;
            }
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for v in img.data[160 * 300..].iter_mut() {
            if rng.random_bool(0.3) {
                *v = 0.1;
            }
        }
        assert!(detect(&img, &DetectorConfig::default()).is_empty());
    }

    /// Paints white paper (level `v`, anti-aliased) over the half-plane beyond the line through
    /// `p` with outward normal `n`, within `reach` px of `p`.
    fn paper_edge(img: &mut GrayF32, p: DVec2, n: DVec2, reach: f64, v: f32) {
        let (w, h) = (img.width as i64, img.height as i64);
        for y in ((p.y - reach) as i64).max(0)..((p.y + reach) as i64).min(h) {
            for x in ((p.x - reach) as i64).max(0)..((p.x + reach) as i64).min(w) {
                let d = (DVec2::new(x as f64, y as f64) - p).dot(n);
                let f = (d + 0.5).clamp(0.0, 1.0) as f32;
                let i = (y * w + x) as usize;
                img.data[i] = img.data[i] * (1.0 - f) + v * f;
            }
        }
    }

    /// 3 x 3 binomial blur (sigma about 0.7 px) and uniform noise of +-`noise`.
    fn blur_and_noise(img: &mut GrayF32, noise: f32, seed: u64) {
        let (w, h) = (img.width, img.height);
        let src = img.data.clone();
        let k = [0.25f32, 0.5, 0.25];
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let mut acc = 0.0;
                for (dy, ky) in k.iter().enumerate() {
                    for (dx, kx) in k.iter().enumerate() {
                        acc += ky * kx * src[(y + dy - 1) * w + x + dx - 1];
                    }
                }
                img.data[y * w + x] = acc;
            }
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        for v in img.data.iter_mut() {
            *v += rng.random_range(-noise..noise);
        }
    }

    /// A neighbouring target's white paper laid over the outer 1..2 px of one side's black
    /// border, parallel to it: the paper's edge is as straight and as contrasted as the border's
    /// own, so only the border's width gives it away. Both corners of that side must be marked
    /// occluded with a sigma that covers their displacement; the other two, and every corner of
    /// the same tags uncovered, must not be marked.
    #[test]
    fn a_paper_edge_over_one_side_of_the_border_marks_both_its_corners() {
        // (id, centre, half side px, angle, perspective g, h, paper over the border px): cells
        // of 5 px (the studio's reference targets at half resolution) and of 8 px.
        let cases = [
            (21usize, DVec2::new(90.0, 90.0), 20.0, 0.3, 0.0, 0.0, 1.0),
            (52, DVec2::new(250.0, 90.0), 20.0, -0.5, 0.0008, 0.0, 1.6),
            (3, DVec2::new(90.0, 250.0), 32.0, 2.0, 0.0, -0.0006, 1.5),
            (44, DVec2::new(250.0, 250.0), 32.0, 4.0, 0.0005, 0.0005, 2.0),
        ];
        for covered in [false, true] {
            let mut img = blank(340, 340, 0.45);
            for (n, &(id, c, s, a, g, hh, over)) in cases.iter().enumerate() {
                let hm = tag_h(c, s, a, g, hh);
                assert!(paint_tag(&mut img, &hm, id, 0.06, 0.9, 8));
                if covered {
                    // Side k of the tag frame, from corner k to k + 1 (BL, BR, TR, TL).
                    let k = n % 4;
                    let t = truth_corners(&hm);
                    let (p, q) = (t[k], t[(k + 1) % 4]);
                    let centre = apply_h(&hm, DVec2::ZERO);
                    let dir = (q - p).normalize();
                    let mut out = DVec2::new(-dir.y, dir.x);
                    if out.dot(p - centre) < 0.0 {
                        out = -out;
                    }
                    paper_edge(&mut img, p - out * over, out, 2.0 * s, 0.9);
                }
            }
            blur_and_noise(&mut img, 0.03, 11);
            let dets = detect(&img, &DetectorConfig::default());
            assert_eq!(dets.len(), cases.len(), "covered {covered}: {dets:?}");
            for (n, &(id, c, s, a, g, hh, over)) in cases.iter().enumerate() {
                let truth = truth_corners(&tag_h(c, s, a, g, hh));
                let d = dets.iter().find(|d| d.id == id as u32).expect("tag found");
                let sig = d.corner_sigma_px();
                let k = n % 4;
                for j in 0..4 {
                    let e = d.corners_px[j].distance(truth[j]);
                    let on_side = covered && (j == k || j == (k + 1) % 4);
                    assert_eq!(
                        d.occluded_corners[j], on_side,
                        "tag {id} (covered {covered}, {over} px over side {k}) corner {j}: \
                         error {e:.2} px, sigma {:.2}",
                        sig[j]
                    );
                    assert!(
                        e <= 3.0 * sig[j],
                        "tag {id} (covered {covered}) corner {j}: error {e:.2} px, sigma {:.2}",
                        sig[j]
                    );
                    if on_side {
                        // The paper moved the corner by about its overlap.
                        assert!(e > 0.5 * over, "tag {id} corner {j}: error {e:.2} px");
                    }
                }
            }
        }
    }

    /// Foreshortened small tags (18..23 px wide, 40 px tall: cells of 2.2..2.9 px across the
    /// long sides, too small for each side's border to be tested on its own) with a
    /// neighbour's white paper laid obliquely over one long side's border, from 0.1 px over at
    /// one corner to 0.9 px at the other: the side stays straight and as contrasted as a whole
    /// one. Compared with the opposite side (`thinner_of_pair`), its border is thinner there,
    /// so that corner is marked occluded with a sigma that covers its error; every other
    /// corner, covered or not, stays within five sigmas.
    #[test]
    fn paper_over_a_small_cells_side_is_found_against_the_opposite_side() {
        // (id, centre, width px, turn, side covered: 1 or 3, the long ones)
        let cases = [
            (5usize, DVec2::new(70.0, 70.0), 18.0, 0.2, 1usize),
            (17, DVec2::new(190.0, 70.0), 20.0, 1.1, 3),
            (29, DVec2::new(310.0, 70.0), 23.0, -0.4, 1),
            (40, DVec2::new(70.0, 200.0), 21.0, 2.6, 3),
            (63, DVec2::new(190.0, 200.0), 19.0, -2.0, 1),
            (77, DVec2::new(310.0, 200.0), 22.0, 0.7, 3),
        ];
        let quad = |c: DVec2, w: f64, turn: f64| -> [DVec2; 4] {
            let (sn, cs) = turn.sin_cos();
            SQUARE.map(|(x, y)| {
                let (x, y) = (0.5 * w * x, 20.0 * y);
                c + DVec2::new(cs * x - sn * y, sn * x + cs * y)
            })
        };
        for covered in [false, true] {
            let mut img = blank(380, 270, 0.45);
            for &(id, c, w, turn, k) in &cases {
                let q = quad(c, w, turn);
                let hm = square_to_quad(&q).expect("homography");
                assert!(paint_tag(&mut img, &hm, id, 0.06, 0.9, 8));
                if covered {
                    let (a, b) = (q[k], q[(k + 1) % 4]);
                    let dir = (b - a).normalize();
                    let mut out = DVec2::new(-dir.y, dir.x);
                    if out.dot(a - c) < 0.0 {
                        out = -out;
                    }
                    // The paper's edge from 0.1 px inside the border at `a` to 0.9 px at `b`.
                    let (pa, pb) = (a - out * 0.1, b - out * 0.9);
                    let along = (pb - pa).normalize();
                    let mut n = DVec2::new(-along.y, along.x);
                    if n.dot(out) < 0.0 {
                        n = -n;
                    }
                    paper_edge(&mut img, (pa + pb) * 0.5, n, 26.0, 0.9);
                }
            }
            blur_and_noise(&mut img, 0.02, 5);
            let dets = detect(&img, &DetectorConfig::default());
            for &(id, c, w, turn, k) in &cases {
                let truth = truth_corners(&square_to_quad(&quad(c, w, turn)).expect("homography"));
                let d = dets
                    .iter()
                    .find(|d| d.id == id as u32)
                    .unwrap_or_else(|| panic!("covered {covered}: tag {id} not found"));
                let sig = d.corner_sigma_px();
                for j in 0..4 {
                    let e = d.corners_px[j].distance(truth[j]);
                    let msg = format!(
                        "tag {id} (covered {covered}, side {k}) corner {j}: error {e:.2} px, \
                         sigma {:.2}, occluded {}",
                        sig[j], d.occluded_corners[j]
                    );
                    // Detections list the corners in the reverse of the quad's order.
                    if covered && j == 3 - (k + 1) % 4 {
                        // Where the paper lies furthest over the border it moved the corner,
                        // and the corner is marked with a sigma that covers that.
                        assert!(e > 0.5 && d.occluded_corners[j], "{msg}");
                        assert!(e <= 3.0 * sig[j], "{msg}");
                    } else {
                        assert!(e <= 5.0 * sig[j], "{msg}");
                    }
                }
            }
        }
    }

    /// Inner edges measured along a side: mean offset and its standard deviation, the offset
    /// line's values at the two corners and their standard deviation.
    fn edges(offset_px: f64, sd: f64, end_offset_px: [f64; 2], end_sd: f64) -> InnerEdges {
        InnerEdges {
            offset_px,
            var_px2: sd * sd,
            end_offset_px,
            end_var_px2: [end_sd * end_sd; 2],
        }
    }

    #[test]
    fn a_pair_of_small_sides_flags_the_thinner_one_where_it_is_thinner() {
        let whole = edges(0.1, 0.03, [0.1; 2], 0.06);
        // Both borders alike (whatever pull or ink spread they share): nothing.
        assert_eq!(thinner_of_pair(whole, whole), [None, None]);
        // A paper over the border, 0.1 px at the start corner, 0.9 px at the end: the border
        // thins by 7/8 of that (the mean by 7/8 of 0.5 px). The mean test finds the side, the
        // end test the larger displacement at its end corner; the opposite side is left alone.
        let slanted = edges(0.1 - 0.4375, 0.03, [0.1 - 0.0875, 0.1 - 0.7875], 0.06);
        let [s, o] = thinner_of_pair(slanted, whole);
        assert_eq!(o, None);
        let s = s.expect("the thinner side is displaced");
        assert!((s.d_px[0] - 0.4375).abs() < 1e-9, "{s:?}");
        assert!((s.d_px[1] - 0.7875).abs() < 1e-9, "{s:?}");
        assert_eq!(s.marked, [true; 2]);
        // The same with the sides swapped.
        let [s2, o2] = thinner_of_pair(whole, slanted);
        assert_eq!((s2, o2), (None, Some(s)));
        // Thicker is never displaced; within two standard deviations nothing, within four
        // or under MIN_BORDER_DISPLACEMENT_PX a displacement for the covariance only.
        assert_eq!(
            thinner_of_pair(edges(0.6, 0.03, [0.6; 2], 0.06), whole)[0],
            None
        );
        let faint = edges(0.1 - 0.08, 0.04, [0.02; 2], 0.2);
        assert_eq!(thinner_of_pair(faint, whole), [None, None]);
        let slight = edges(0.1 - 0.2, 0.03, [-0.1; 2], 0.2);
        let s = thinner_of_pair(slight, whole)[0].expect("beyond two sigmas");
        assert_eq!(s.marked, [false; 2]);
        assert!((s.d_px[0] - 0.2).abs() < 1e-9 && (s.d_px[1] - 0.2).abs() < 1e-9);
    }

    #[test]
    fn border_width_flags_one_displaced_side_but_not_a_common_thickening() {
        let side = |offset_px: f64| Some(edges(offset_px, 0.03, [offset_px; 2], 0.03));
        // A side moved 1 px inward: its border is 7/8 px thinner than predicted, the opposite
        // side's 1/8 px thicker; only the moved side is displaced, by about 1 px.
        let one = displaced_sides(&[side(-0.875), side(0.0), side(0.125), side(0.0)]);
        assert!(
            one[0].is_some_and(|s| (s.d_px[0] - 1.0).abs() < 1e-9
                && s.d_px[0] == s.d_px[1]
                && s.marked == [true; 2]),
            "{one:?}"
        );
        assert_eq!(one[1..], [None, None, None]);
        // Every border 0.4 px thicker (ink spread): nothing is displaced.
        assert_eq!(displaced_sides(&[side(0.4); 4]), [None; 4]);
        // Under the floor, or beyond the floor but under four sigmas: a displacement for the
        // covariance, not an occluder; under two sigmas, nothing.
        let small = displaced_sides(&[side(-0.2), side(0.0), side(0.0), side(0.0)]);
        assert!(
            small[0].is_some_and(
                |s| s.marked == [false; 2] && (s.d_px[0] - 0.2 * 8.0 / 7.0).abs() < 0.05
            ),
            "{small:?}"
        );
        assert_eq!(small[1..], [None, None, None]);
        let noisy_side = |offset_px: f64| Some(edges(offset_px, 0.2, [offset_px; 2], 0.2));
        let noisy = displaced_sides(&[noisy_side(-0.6), side(0.0), side(0.0), side(0.0)]);
        assert!(
            noisy[0].is_some_and(|s| s.marked == [false; 2]),
            "{noisy:?}"
        );
        let quiet = [noisy_side(-0.3), side(0.0), side(0.0), side(0.0)];
        assert_eq!(displaced_sides(&quiet), [None; 4]);
        // Sides not measured are not tested.
        assert_eq!(displaced_sides(&[None; 4]), [None; 4]);
    }

    /// Small blurred tags (cells of 1.25..2.5 px, blur 0.7 px, white paper around): the border's
    /// inner edge pulls the outer edge outward where the data cell behind it is white, so
    /// uncorrected every quad is too large; and the gradient centroid's phase error is common
    /// to a side's samples. With the pull taken off (`unbias_inner_edges`) the quads' mean
    /// outward error stays under the bound (what remains is the weaker pull of edges two
    /// cells in, which every sample shares), and with the narrow difference's floor the stated
    /// sigmas cover the errors.
    #[test]
    fn small_blurred_tags_lose_the_inner_edge_bias_and_state_honest_sigmas() {
        let (mut outward, mut ratios) = (Vec::new(), Vec::new());
        for seed in 0..12 {
            let sc = crate::profile::tests::scene(seed, (10.0, 20.0), 1.0, 1.0, 0.7);
            for d in detect(&sc.img, &DetectorConfig::default()) {
                let Some((_, q)) = sc.truth.iter().find(|t| t.0 == d.id) else {
                    continue;
                };
                if d.occluded_corners.contains(&true) {
                    continue;
                }
                let centre = (q[0] + q[1] + q[2] + q[3]) * 0.25;
                let sigma = d.corner_sigma_px();
                for (c, s) in d.corners_px.iter().zip(sigma) {
                    let t = q
                        .iter()
                        .copied()
                        .min_by(|a, b| a.distance(*c).total_cmp(&b.distance(*c)))
                        .expect("four corners");
                    outward.push((*c - t).dot((t - centre).normalize()));
                    ratios.push(c.distance(t) / s);
                }
            }
        }
        assert!(outward.len() >= 150, "too few corners: {}", outward.len());
        let mean_outward = outward.iter().sum::<f64>() / outward.len() as f64;
        ratios.sort_by(f64::total_cmp);
        let (median, max) = (ratios[ratios.len() / 2], ratios[ratios.len() - 1]);
        eprintln!(
            "{} corners: mean outward error {mean_outward:+.3} px, error/sigma median {median:.2}, max {max:.2}",
            ratios.len()
        );
        assert!(mean_outward.abs() < 0.08, "{mean_outward}");
        assert!(median < 1.5 && max < 5.0, "median {median}, max {max}");
    }

    /// Small foreshortened tags (10..14 px wide, twice as tall, blur 0.7 px): the long sides,
    /// with a cell of 1.25..1.75 px across them, take several times the pull of the short
    /// ones, so each pair of opposite sides gets its own bias. A side's outward offset from the
    /// true side is the mean of its two corners' errors along its outward normal. Left in, the
    /// pull moves the long sides outward beyond the first bound; one bias for the whole tag
    /// moves the short sides inward beyond the second. What stays on the long sides is the
    /// weaker pull of edges two cells in, which every point shares.
    #[test]
    fn a_foreshortened_small_tag_has_each_pair_of_sides_unbiased() {
        let (mut long, mut short) = (Vec::new(), Vec::new());
        for seed in 0..10 {
            let sc = crate::profile::tests::stretched_scene(seed, (10.0, 14.0), 2.0, 1.0, 1.0, 0.7);
            let (img, truth) = (&sc.img, &sc.truth);
            for d in detect(img, &DetectorConfig::default()) {
                let Some((_, q)) = truth.iter().find(|t| t.0 == d.id) else {
                    continue;
                };
                if d.occluded_corners.contains(&true) {
                    continue;
                }
                // The detected corners matched to the true ones, in the true order.
                let found: Vec<DVec2> = q
                    .iter()
                    .map(|t| {
                        d.corners_px
                            .iter()
                            .copied()
                            .min_by(|a, b| a.distance(*t).total_cmp(&b.distance(*t)))
                            .expect("four corners")
                    })
                    .collect();
                let centre = (q[0] + q[1] + q[2] + q[3]) * 0.25;
                for k in 0..4 {
                    let (a, b) = (q[k], q[(k + 1) % 4]);
                    let along = (b - a).normalize();
                    let mut n = DVec2::new(-along.y, along.x);
                    if n.dot((a + b) * 0.5 - centre) < 0.0 {
                        n = -n;
                    }
                    let offset = 0.5 * ((found[k] - a).dot(n) + (found[(k + 1) % 4] - b).dot(n));
                    if a.distance(b) > 15.0 {
                        long.push(offset);
                    } else {
                        short.push(offset);
                    }
                }
            }
        }
        assert!(
            long.len() >= 60 && short.len() >= 60,
            "{} long, {} short sides",
            long.len(),
            short.len()
        );
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let (ml, ms) = (mean(&long), mean(&short));
        eprintln!(
            "{} tags: mean outward offset, long sides {ml:+.3} px, short sides {ms:+.3} px",
            long.len() / 2
        );
        assert!(ml.abs() < 0.1, "long sides {ml}");
        assert!(ms.abs() < 0.04, "short sides {ms}");
    }

    #[test]
    fn corrects_bit_errors_up_to_the_limit() {
        let mut img = blank(240, 240, 0.8);
        let hm = tag_h(DVec2::new(120.0, 120.0), 80.0, 0.0, 0.0, 0.0);
        assert!(paint_tag(&mut img, &hm, 9, 0.1, 0.9, 4));
        // Flip two data cells by painting over them (partial occlusion).
        let cell = 20.0;
        for (r, c) in [(3usize, 3usize), (5, 6)] {
            let x0 = 120.0 - 100.0 + c as f64 * cell;
            let y0 = 120.0 - 100.0 + r as f64 * cell;
            let v = img.bilinear(DVec2::new(x0 + 10.0, y0 + 10.0));
            let nv = if v > 0.5 { 0.1 } else { 0.9 };
            for y in y0 as usize + 2..(y0 + cell) as usize - 2 {
                for x in x0 as usize + 2..(x0 + cell) as usize - 2 {
                    img.data[y * 240 + x] = nv;
                }
            }
        }
        let dets = detect(&img, &DetectorConfig::default());
        assert_eq!(dets.len(), 1);
        assert_eq!((dets[0].id, dets[0].hamming), (9, 2));
        let strict = DetectorConfig {
            max_hamming: 1,
            ..DetectorConfig::default()
        };
        assert!(detect(&img, &strict).is_empty());
    }
}
