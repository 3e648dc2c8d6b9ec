//! Step 6 of the detector: reading a refined quad's code, then the tag reported.
//!
//! The homography from the tag square to the quad samples all 10 x 10 cells (sharpened on
//! small cells, [`DECODE_SHARPENING`]); black and white levels are modelled as planes over the
//! tag (fitted to the black border and the white outer ring), so a lighting gradient across the
//! tag does not flip bits. The 36 data bits are matched against all 587 codes for each of the
//! four corner orderings; the best match within [`DetectorConfig::max_hamming`] wins. Quads
//! whose black border is not dark are rejected. Once the code is known, a small tag's sides
//! are refitted without the inner edges' pull (`inner_bias`) and its border's width tested
//! (`border_width`, step 7).
//!
//! A corner is occluded when the edge next to it is hidden on either side
//! ([`MIN_VISIBLE_NEAR`]), a side next to it bends or is displaced, or the cells of the grid
//! nearest to it disagree with a whole tag (a bright border cell, a dark white-ring cell, a
//! corrected bit); its covariance then gets an isotropic term of [`OCCLUDED_SIGMA_CELLS`] cells.

use crate::detect::border_width::{side_displacements, widened_covariance};
use crate::detect::cells::{cell_uv, fit_plane, sample_cell};
use crate::detect::inner_bias::{unbias_inner_edges, INNER_EDGE_BIAS_MAX_CELL_PX};
use crate::detect::refine::RefinedQuad;
use crate::detect::types::{Detection, DetectorConfig};
use crate::homography::{apply_h, square_to_quad};
use crate::image::GrayF32;
use crate::tag36h11;
use glam::{DMat3, DVec2};

/// A corner whose neighbouring side quarters are less than this fraction visible (on either
/// side, [`VISIBLE_CONTRAST`](crate::detect::VISIBLE_CONTRAST)) is occluded.
pub const MIN_VISIBLE_NEAR: f64 = 0.5;

/// Standard deviation added to an occluded corner, in cells of the tag (side / 8): where the
/// corner is hidden it is the intersection of lines fitted to what remains, or the quad is
/// partly an occluder's outline.
pub const OCCLUDED_SIGMA_CELLS: f64 = 0.25;

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

/// How a quad's code is read (`decode`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct DecodeOptions {
    /// Refit a small tag's sides without its inner edges' pull (`unbias_inner_edges`) once
    /// the code is known; off for a quad that is not the edge refinement's own.
    pub(crate) unbias_inner_edges: bool,
    /// Average each cell's grey over its middle ([`CELL_SPREAD_CELLS`]) whatever its size.
    pub(crate) average_cells: bool,
}

/// The grey levels of the 10 x 10 cells in the quad's frame (`None`: outside the image).
type Grid = [[Option<f64>; 10]; 10];

/// The code found on a quad's grid.
#[derive(Debug, Clone, Copy)]
struct Code {
    /// Tag ID in tag36h11.
    id: u32,
    /// Number of corrected bit errors.
    hamming: u32,
    /// Quarter turns of the grid from the tag's frame to the quad's.
    shift: usize,
    /// Decision margin (see [`Detection::decision_margin`]).
    margin: f64,
}

/// Reads the code of a refined quad (step 6 of the method), tests its border's width (step 7)
/// and reports the tag.
pub(crate) fn decode(
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
    let grid = sample_grid(img, &h, cell_px, opts.average_cells);
    let levels = Levels::fit(&grid)?;
    // Border must be dark against the white model.
    if levels.bright_border_cells() > 3 {
        return None;
    }
    let mut evidence = levels.occlusion_evidence(&grid);
    let code = best_code(&grid, &levels, cfg)?;
    if code.margin < cfg.min_margin {
        return None;
    }
    let codeword = tag36h11::CODES[code.id as usize];
    let cells = code_cells(code.shift);
    // The corrected bits are occlusion evidence too.
    let diff = read_code(&grid, &levels, &cells) ^ codeword;
    for (i, &(r, c)) in cells.iter().enumerate() {
        if (diff >> (tag36h11::NBITS - 1 - i)) & 1 == 1 {
            evidence[quadrant(r, c)] += 1;
        }
    }
    let white = code_pattern(codeword, &cells);
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
    let shifted = side_displacements(img, &h, &white, rq);
    // A corner is occluded when the edge next to it is hidden on either side, a side next to it
    // bends or is displaced, or the cells of its quadrant disagree with a whole tag.
    let occluded_q: [bool; 4] = std::array::from_fn(|j| {
        rq.visible_near[j] < MIN_VISIBLE_NEAR
            || evidence[j] > 0
            || rq.bent[j]
            || shifted[j].is_some_and(|s| s.marked[0])
            || shifted[(j + 3) % 4].is_some_and(|s| s.marked[1])
    });
    let rq_cov = widened_covariance(rq, &shifted);
    tag_detection(rq, &rq_cov, &occluded_q, code)
}

/// Samples the grid through `h` (each cell's grey averaged over its middle on cells of
/// [`AVERAGED_CELL_MIN_PX`] and more, or with `average_cells`), sharpened when cells are only a
/// few pixels wide.
fn sample_grid(img: &GrayF32, h: &DMat3, cell_px: f64, average_cells: bool) -> Grid {
    let spread = if average_cells || cell_px >= AVERAGED_CELL_MIN_PX {
        CELL_SPREAD_CELLS
    } else {
        0.0
    };
    let mut raw = [[None; 10]; 10];
    for (r, row) in raw.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = sample_cell(img, h, r, c, spread);
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
    grid
}

/// Whether cell (row, col) is on ring `k` of the grid (0: the white outer ring, 1: the black
/// border).
fn ring(r: usize, c: usize, k: usize) -> bool {
    r.min(c).min(9 - r).min(9 - c) == k
}

/// The quadrant of the grid nearest to each quad corner, of cell (row, col).
fn quadrant(r: usize, c: usize) -> usize {
    match (c >= 5, r >= 5) {
        (false, false) => 0,
        (true, false) => 1,
        (true, true) => 2,
        (false, true) => 3,
    }
}

/// The plane `a + b u + c v` at `(u, v)`.
fn eval(p: &[f64; 3], u: f64, v: f64) -> f64 {
    p[0] + p[1] * u + p[2] * v
}

/// The black and white levels over the tag, as planes in the tag frame.
struct Levels {
    /// The black border's cells `(u, v, grey)`.
    black: Vec<(f64, f64, f64)>,
    black_plane: [f64; 3],
    white_plane: [f64; 3],
    /// Whether the white plane was fitted to the white outer ring (mostly visible), not to the
    /// brightest data cells.
    white_ring: bool,
}

impl Levels {
    /// The planes fitted to the black border and the white outer ring (the brightest data cells
    /// when the ring is mostly hidden); `None` when too little of the border is seen.
    fn fit(grid: &Grid) -> Option<Self> {
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
        let black_plane = fit_plane(&black)?;
        // White reference: the outer ring when it is mostly visible, else the brightest data
        // cells.
        let white_ring = white.len() >= 18;
        let white_plane = if white_ring {
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
        Some(Self {
            black,
            black_plane,
            white_plane,
            white_ring,
        })
    }

    /// The black and white levels at `(u, v)`.
    fn at(&self, u: f64, v: f64) -> (f64, f64) {
        (eval(&self.black_plane, u, v), eval(&self.white_plane, u, v))
    }

    /// Border cells not dark against the white model.
    fn bright_border_cells(&self) -> usize {
        let mut bright_border = 0;
        for &(u, v, z) in &self.black {
            let (lo, hi) = self.at(u, v);
            if hi - lo <= 0.0 || z > 0.5 * (lo + hi) {
                bright_border += 1;
            }
        }
        bright_border
    }

    /// Occlusion evidence per quad corner (the quadrant of the grid nearest to it): border cells
    /// that are not dark, white-ring cells that are not light.
    fn occlusion_evidence(&self, grid: &Grid) -> [usize; 4] {
        let mut evidence = [0usize; 4];
        for r in 0..10 {
            for c in 0..10 {
                let Some(z) = grid[r][c] else { continue };
                let (u, v) = cell_uv(r, c);
                let (lo, hi) = self.at(u, v);
                let mid = 0.5 * (lo + hi);
                let bad = (ring(r, c, 1) && (hi - lo <= 0.0 || z > mid))
                    || (ring(r, c, 0) && self.white_ring && z < mid);
                if bad {
                    evidence[quadrant(r, c)] += 1;
                }
            }
        }
        evidence
    }
}

/// The cells of the data bits in the quad's frame, for the grid turned by `shift` quarter turns
/// from the tag's frame (a corner shift by one is a quarter turn of the grid: tag corner `k`
/// sits at quad corner `k + 1`).
fn code_cells(shift: usize) -> [(usize, usize); tag36h11::NBITS] {
    std::array::from_fn(|i| {
        let (mut r, mut c) = (
            tag36h11::BIT_Y[i] as usize + 1,
            tag36h11::BIT_X[i] as usize + 1,
        );
        for _ in 0..shift {
            let (nr, nc) = (c, 9 - r);
            r = nr;
            c = nc;
        }
        (r, c)
    })
}

/// The data bits of `cells` read against the levels' mid-level (a missing cell reads black),
/// and the decision margin; `None` when a cell is missing.
fn read_bits(
    grid: &Grid,
    levels: &Levels,
    cells: &[(usize, usize); tag36h11::NBITS],
) -> Option<(u64, f64)> {
    let mut code = 0u64;
    let (mut white_m, mut white_n, mut black_m, mut black_n) = (0.0, 0.0, 0.0, 0.0);
    for &(r, c) in cells {
        let v = grid[r][c]?;
        let (u, w) = cell_uv(r, c);
        let (lo, hi) = levels.at(u, w);
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
    Some((code, margin))
}

/// The data bits of `cells` (a missing cell reads black).
fn read_code(grid: &Grid, levels: &Levels, cells: &[(usize, usize); tag36h11::NBITS]) -> u64 {
    let mut code = 0u64;
    for &(r, c) in cells {
        let (u, w) = cell_uv(r, c);
        let (lo, hi) = levels.at(u, w);
        let thr = 0.5 * (lo + hi);
        code = (code << 1) | u64::from(grid[r][c].is_some_and(|v| v > thr));
    }
    code
}

/// The code nearest to the grid's bits over the four rotations (corner shifts), within
/// [`DetectorConfig::max_hamming`].
fn best_code(grid: &Grid, levels: &Levels, cfg: &DetectorConfig) -> Option<Code> {
    let mut best: Option<Code> = None;
    for shift in 0..4 {
        let Some((code, margin)) = read_bits(grid, levels, &code_cells(shift)) else {
            continue;
        };
        for (id, &cw) in tag36h11::CODES.iter().enumerate() {
            let d = (cw ^ code).count_ones();
            if d <= cfg.max_hamming && best.is_none_or(|b| d < b.hamming) {
                best = Some(Code {
                    id: id as u32,
                    hamming: d,
                    shift,
                    margin,
                });
            }
        }
    }
    best
}

/// The code's cells in the quad's frame: the white ring, the black border and the data.
fn code_pattern(codeword: u64, cells: &[(usize, usize); tag36h11::NBITS]) -> [[bool; 10]; 10] {
    let mut white = [[false; 10]; 10];
    for (r, row) in white.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = ring(r, c, 0);
        }
    }
    for (i, &(r, c)) in cells.iter().enumerate() {
        white[r][c] = (codeword >> (tag36h11::NBITS - 1 - i)) & 1 == 1;
    }
    white
}

/// The tag reported from its quad `rq`, its corners' covariance `rq_cov` and occlusion
/// `occluded_q` in the quad's order, and its `code`.
fn tag_detection(
    rq: &RefinedQuad,
    rq_cov: &[[f64; 3]; 4],
    occluded_q: &[bool; 4],
    code: Code,
) -> Option<Detection> {
    let extra = (OCCLUDED_SIGMA_CELLS * rq.cell_px).powi(2);
    // Reorder corners so corner 0 is the tag's printed top-left. With the grid turned by
    // `shift` quarter turns, the tag's corner k is the quad's corner k - shift.
    let mut corners = [DVec2::ZERO; 4];
    let mut cov = [[0.0; 3]; 4];
    let mut occluded = [false; 4];
    for k in 0..4 {
        let j = (k + code.shift) % 4;
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
        id: code.id,
        corners_px: rev(corners),
        corner_cov_px2: revc(cov),
        center_px: apply_h(&ht, DVec2::ZERO),
        hamming: code.hamming,
        decision_margin: code.margin,
        edge_rms_px: rq.edge_rms_px,
        occluded_corners: revb(occluded),
    })
}
