//! The unpacked photosite mosaic.

use std::path::Path;

use crate::error::LibRawError;
use crate::header::Header;

/// A file's photosites as LibRaw unpacked them, with the header as it stood after unpacking.
#[derive(Debug, Clone)]
pub struct Photosites {
    /// Sizes, CFA and levels after unpacking.
    pub header: Header,
    /// `raw_width_px * raw_height_px` raw values, row by row over the full sensor.
    pub values: Vec<u16>,
}

impl Photosites {
    pub(crate) fn new(path: &Path, header: Header, values: Vec<u16>) -> Result<Self, LibRawError> {
        let want = header.raw_width_px as usize * header.raw_height_px as usize;
        let fits = header.left_margin_px + header.width_px <= header.raw_width_px
            && header.top_margin_px + header.height_px <= header.raw_height_px;
        if values.len() != want || !fits {
            return Err(LibRawError::Sizes {
                path: path.to_path_buf(),
                detail: format!(
                    "{} values for a {} x {} sensor with a {} x {} visible area at ({}, {})",
                    values.len(),
                    header.raw_width_px,
                    header.raw_height_px,
                    header.width_px,
                    header.height_px,
                    header.left_margin_px,
                    header.top_margin_px
                ),
            });
        }
        Ok(Photosites { header, values })
    }

    /// The raw value of sensor photosite `(x, y)` (full-sensor coordinates).
    pub fn get(&self, x: u32, y: u32) -> Option<u16> {
        if x >= self.header.raw_width_px || y >= self.header.raw_height_px {
            return None;
        }
        self.values
            .get(y as usize * self.header.raw_width_px as usize + x as usize)
            .copied()
    }
}
