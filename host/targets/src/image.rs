//! A single-channel floating-point image with bilinear sampling in the project's pixel
//! convention (integer coordinates are pixel centres).

use glam::DVec2;
use std::path::Path;

/// Errors of image loading.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The file could not be read or decoded.
    #[error("cannot read image {path}")]
    Read {
        /// The file.
        path: String,
        /// The decoder's error.
        #[source]
        source: image::ImageError,
    },
    /// The pixel buffer does not match the stated size.
    #[error("image buffer has {len} values, expected {width} x {height}")]
    Size {
        /// Buffer length.
        len: usize,
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
    },
}

/// A grey image, row-major, values in arbitrary linear or gamma units (detection is invariant to
/// affine intensity changes).
#[derive(Debug, Clone, PartialEq)]
pub struct GrayF32 {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major values.
    pub data: Vec<f32>,
}

impl GrayF32 {
    /// Wraps a buffer.
    pub fn new(width: usize, height: usize, data: Vec<f32>) -> Result<Self, ImageError> {
        if data.len() != width * height {
            return Err(ImageError::Size {
                len: data.len(),
                width,
                height,
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Converts any decoded image to grey (luma of the stored values, scaled to 0..1).
    pub fn from_dynamic(img: &image::DynamicImage) -> Self {
        let g = img.to_luma32f();
        let (w, h) = g.dimensions();
        Self {
            width: w as usize,
            height: h as usize,
            data: g.into_raw(),
        }
    }

    /// Loads an image file (PNG, JPEG, TIFF, EXR) as grey.
    pub fn load(path: &Path) -> Result<Self, ImageError> {
        let img = image::open(path).map_err(|source| ImageError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Ok(Self::from_dynamic(&img))
    }

    /// The value at an integer pixel (clamped to the image).
    #[inline]
    pub fn at(&self, x: isize, y: isize) -> f32 {
        let xc = x.clamp(0, self.width as isize - 1) as usize;
        let yc = y.clamp(0, self.height as isize - 1) as usize;
        self.data[yc * self.width + xc]
    }

    /// True when `p` lies inside the image with `margin_px` to spare.
    pub fn contains(&self, p: DVec2, margin_px: f64) -> bool {
        p.x >= margin_px
            && p.y >= margin_px
            && p.x <= self.width as f64 - 1.0 - margin_px
            && p.y <= self.height as f64 - 1.0 - margin_px
    }

    /// Bilinear interpolation at `p` (pixel-centre convention, clamped at the border).
    #[inline]
    pub fn bilinear(&self, p: DVec2) -> f64 {
        let x0 = p.x.floor();
        let y0 = p.y.floor();
        let fx = p.x - x0;
        let fy = p.y - y0;
        let (xi, yi) = (x0 as isize, y0 as isize);
        let a = self.at(xi, yi) as f64;
        let b = self.at(xi + 1, yi) as f64;
        let c = self.at(xi, yi + 1) as f64;
        let d = self.at(xi + 1, yi + 1) as f64;
        (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_hits_pixel_centres_and_interpolates() {
        let img = GrayF32::new(2, 2, vec![0.0, 1.0, 2.0, 3.0]).expect("size matches");
        assert_eq!(img.bilinear(DVec2::new(1.0, 1.0)), 3.0);
        assert!((img.bilinear(DVec2::new(0.5, 0.5)) - 1.5).abs() < 1e-12);
        assert!(GrayF32::new(3, 2, vec![0.0; 5]).is_err());
    }
}
