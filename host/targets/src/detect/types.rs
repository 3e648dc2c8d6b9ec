//! The detector's public types: its settings, one detected tag, a run's statistics.

use glam::DVec2;
use serde::{Deserialize, Serialize};

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
    /// border, [`BORDER_WIDTH_SIGMAS`](crate::detect::BORDER_WIDTH_SIGMAS)), or cells of the
    /// grid near it disagree with a whole tag (a bright border cell, a dark white-ring cell, a
    /// corrected bit). Its covariance includes
    /// [`OCCLUDED_SIGMA_CELLS`](crate::detect::OCCLUDED_SIGMA_CELLS) cells (and a displaced
    /// side's displacement); the pose stage does not use it.
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
