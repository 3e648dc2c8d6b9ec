//! Sizes, CFA and levels of a raw file as LibRaw identified it.

use crate::exif::{ExifTags, TAG_MAKE, TAG_MODEL};
use crate::handle::State;

/// Below this, LibRaw's `filters` is a code (Leaf, X-Trans), not a pattern.
const FILTERS_PATTERN_MIN: u32 = 1000;

/// What LibRaw says about a file's sensor before reading its image data.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// The make as LibRaw normalises it (e.g. `Nikon`).
    pub make: String,
    /// The model as LibRaw normalises it (the make cut from its front).
    pub model: String,
    /// The full sensor width, masked columns included.
    pub raw_width_px: u32,
    /// The full sensor height, masked rows included.
    pub raw_height_px: u32,
    /// The visible area's width.
    pub width_px: u32,
    /// The visible area's height.
    pub height_px: u32,
    /// The visible area's first column on the sensor.
    pub left_margin_px: u32,
    /// The visible area's first row on the sensor.
    pub top_margin_px: u32,
    /// The 2x2 colour pattern at the visible area's origin, row-major (e.g. `RGGB`); `None`
    /// for X-Trans, Foveon, linear and other layouts that are not a 2x2 mosaic.
    pub cfa: Option<String>,
    /// LibRaw's `filters` (0 for linear data, 9 for X-Trans, a 2-bit code per position else).
    pub filters: u32,
    /// The number of colours LibRaw sees (3 for RGB, 4 for CMYG).
    pub colors: i32,
    /// Whether the sensor is a Foveon (three layers, no mosaic).
    pub is_foveon: bool,
    /// Black level per CFA position (row-major 2x2 at the visible origin); for a file
    /// without a 2x2 pattern, LibRaw's common black level four times.
    pub black_levels: [f64; 4],
    /// White level (LibRaw's `maximum`).
    pub white_level: f64,
    /// The TIFF Make tag as written, where LibRaw met TIFF directories.
    pub make_as_written: Option<String>,
    /// The TIFF Model tag as written, where LibRaw met TIFF directories.
    pub model_as_written: Option<String>,
}

/// The colour index of photosite `(row, col)` of the visible area (LibRaw's `FC`).
pub(crate) fn colour_index(filters: u32, row: u32, col: u32) -> usize {
    ((filters >> ((((row << 1) & 14) | (col & 1)) << 1)) & 3) as usize
}

/// Whether `filters` is a 2x2 pattern (its eight row pairs all alike).
fn is_two_by_two(filters: u32) -> bool {
    filters >= FILTERS_PATTERN_MIN
        && (0..8).all(|row| {
            (0..2).all(|col| colour_index(filters, row, col) == colour_index(filters, row % 2, col))
        })
}

impl Header {
    pub(crate) fn from_state(s: &State, exif: &ExifTags, bytes: &[u8]) -> Self {
        let mosaic = is_two_by_two(s.filters) && !s.is_foveon;
        let cfa = mosaic.then(|| {
            (0..4)
                .map(|k| match s.cdesc[colour_index(s.filters, k / 2, k % 2)] {
                    0 => '?',
                    c => char::from(c),
                })
                .collect::<String>()
        });
        let mut black_levels = [f64::from(s.black); 4];
        if mosaic {
            for (k, level) in black_levels.iter_mut().enumerate() {
                let (row, col) = (k as u32 / 2, k as u32 % 2);
                *level += f64::from(black_offset(s, row, col));
            }
        }
        Header {
            make: s.make.clone(),
            model: s.model.clone(),
            raw_width_px: s.raw_width,
            raw_height_px: s.raw_height,
            width_px: s.width,
            height_px: s.height,
            left_margin_px: s.left_margin,
            top_margin_px: s.top_margin,
            cfa,
            filters: s.filters,
            colors: s.colors,
            is_foveon: s.is_foveon,
            black_levels,
            white_level: f64::from(s.maximum),
            make_as_written: exif.ascii(bytes, TAG_MAKE),
            model_as_written: exif.ascii(bytes, TAG_MODEL),
        }
    }

    /// The CFA as LibRaw's colour letters, only when it is an RGB Bayer pattern.
    pub fn bayer(&self) -> Option<&str> {
        self.cfa.as_deref().filter(|c| {
            let mut letters: Vec<char> = c.chars().collect();
            letters.sort_unstable();
            letters == ['B', 'G', 'G', 'R']
        })
    }
}

/// LibRaw's per-colour and per-position black offsets for photosite `(row, col)`.
fn black_offset(s: &State, row: u32, col: u32) -> u32 {
    let c = colour_index(s.filters, row, col);
    let per_colour = s.cblack.get(c).copied().unwrap_or(0);
    let (rows, cols) = (
        s.cblack.get(4).copied().unwrap_or(0),
        s.cblack.get(5).copied().unwrap_or(0),
    );
    let per_position = if rows > 0 && cols > 0 {
        let i = 6 + (row % rows) as usize * cols as usize + (col % cols) as usize;
        s.cblack.get(i).copied().unwrap_or(0)
    } else {
        0
    };
    per_colour.saturating_add(per_position)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// LibRaw's `filters` for RGGB at the origin (dcraw's 0x94949494).
    const RGGB: u32 = 0x9494_9494;

    #[test]
    fn rggb_filters_read_as_rggb_positions() {
        let idx: Vec<usize> = (0..4).map(|k| colour_index(RGGB, k / 2, k % 2)).collect();
        assert_eq!(idx, [0, 1, 1, 2]);
        assert!(is_two_by_two(RGGB));
        assert!(!is_two_by_two(9));
        assert!(!is_two_by_two(0));
    }
}
