//! What a decode gives ([`RawFrame`], [`RawHeader`]), what it is asked for ([`RawOptions`],
//! [`RawLayout`]), and the conversions between the superpixel and the photosite image.

use skinbrdf_core::CameraModel;

use crate::bayer::BayerPhase;
use crate::kind::FileKind;

/// Overrides of the file's levels (the session's per-image `linearization`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RawOptions {
    /// Black level per CFA position of the active area's quad, in reading order (top-left,
    /// top-right, bottom-left, bottom-right), in raw units.
    pub black_levels: Option<[f64; 4]>,
    /// White level in raw units.
    pub white_level: Option<f64>,
}

/// A decoded raw image, at superpixel (half) or photosite (full) resolution.
#[derive(Debug, Clone, PartialEq)]
pub struct RawFrame {
    /// What the file is.
    pub kind: FileKind,
    /// Superpixels or photosites.
    pub layout: RawLayout,
    /// Width of the image as loaded: half the active area's width, rounded down (superpixels),
    /// or twice that (photosites: an odd last column is dropped in both layouts).
    pub width_px: u32,
    /// Height of the image as loaded.
    pub height_px: u32,
    /// Normalised linear values per pixel, row-major. Superpixels: R, mean(G1, G2), B.
    /// Photosites: the photosite's own channel, the other two NaN.
    pub rgb: Vec<[f32; 3]>,
    /// True where any photosite of the quad (superpixels), or the photosite itself, is at or
    /// above the white level.
    pub saturated: Vec<bool>,
    /// The Bayer phase at the active area's top-left photosite.
    pub cfa: BayerPhase,
    /// Black level per CFA position of the active quad, reading order (as used).
    pub black_levels: [f64; 4],
    /// White level (as used).
    pub white_level: f64,
    /// Bits per stored sample the file declares.
    pub bits_per_sample: u32,
    /// Full sensor width in photosites (masked areas included).
    pub sensor_width_px: u32,
    /// Full sensor height in photosites.
    pub sensor_height_px: u32,
    /// Left edge of the active area in sensor photosites.
    pub active_left_px: u32,
    /// Top edge of the active area in sensor photosites.
    pub active_top_px: u32,
}

impl RawFrame {
    /// The pixel at column `u`, row `v`.
    pub fn get(&self, u: u32, v: u32) -> Option<[f32; 3]> {
        (u < self.width_px && v < self.height_px)
            .then(|| self.rgb[(v * self.width_px + u) as usize])
    }
}

/// A focal length in active-area photosites as a focal length in superpixels: `f / 2`.
pub const fn sensor_to_superpixel_focal(f_px: f64) -> f64 {
    f_px / 2.0
}

/// A coordinate (principal point, detection) in active-area photosites as a coordinate in
/// superpixels, both with pixel centres at integers: `(c - 0.5) / 2`.
pub const fn sensor_to_superpixel_centre(c_px: f64) -> f64 {
    (c_px - 0.5) / 2.0
}

/// A focal length in superpixels as a focal length in active-area photosites: `2 f`.
pub const fn superpixel_to_sensor_focal(f_px: f64) -> f64 {
    2.0 * f_px
}

/// A coordinate in superpixels as a coordinate in active-area photosites: `2 c + 0.5`
/// (the inverse of [`sensor_to_superpixel_centre`]).
pub const fn superpixel_to_sensor_centre(c_px: f64) -> f64 {
    2.0 * c_px + 0.5
}

/// A calibration of the superpixel image converted to the photosite image (the even part of
/// the active area: size doubled, focal lengths and principal point as above, distortion
/// unchanged); the inverse of [`sensor_camera_to_superpixel`] on an even-sized active area.
pub fn superpixel_camera_to_sensor(cam: &CameraModel) -> CameraModel {
    CameraModel {
        width_px: cam.width_px.saturating_mul(2),
        height_px: cam.height_px.saturating_mul(2),
        fx_px: superpixel_to_sensor_focal(cam.fx_px),
        fy_px: superpixel_to_sensor_focal(cam.fy_px),
        cx_px: superpixel_to_sensor_centre(cam.cx_px),
        cy_px: superpixel_to_sensor_centre(cam.cy_px),
        distortion: cam.distortion,
    }
}

/// A calibration made on the full-resolution active area, converted to the superpixel image
/// (size halved, rounded down; focal lengths and principal point as above; distortion
/// coefficients unchanged, as they act on normalised coordinates).
pub fn sensor_camera_to_superpixel(cam: &CameraModel) -> CameraModel {
    CameraModel {
        width_px: cam.width_px / 2,
        height_px: cam.height_px / 2,
        fx_px: sensor_to_superpixel_focal(cam.fx_px),
        fy_px: sensor_to_superpixel_focal(cam.fy_px),
        cx_px: sensor_to_superpixel_centre(cam.cx_px),
        cy_px: sensor_to_superpixel_centre(cam.cy_px),
        distortion: cam.distortion,
    }
}

/// What [`crate::read_raw_header`] tells without computing superpixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawHeader {
    /// What the file is.
    pub kind: FileKind,
    /// Width of the image as loaded (superpixels).
    pub width_px: u32,
    /// Height of the image as loaded (superpixels).
    pub height_px: u32,
    /// Bits per stored sample.
    pub bits_per_sample: u32,
    /// The Bayer phase at the active area's top-left photosite.
    pub cfa: BayerPhase,
}

impl RawHeader {
    /// The size of the image as a decode in `layout` gives it.
    pub const fn size_px(&self, layout: RawLayout) -> (u32, u32) {
        match layout {
            RawLayout::Superpixel => (self.width_px, self.height_px),
            RawLayout::Photosite => (
                self.width_px.saturating_mul(2),
                self.height_px.saturating_mul(2),
            ),
        }
    }
}

/// How a decode lays the photosites out in the image it returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RawLayout {
    /// One pixel per photosite of the active area (full resolution); each pixel holds its own
    /// channel, the other two NaN ([`crate::decode_photosites`]).
    Photosite,
    /// One RGB pixel per 2x2 quad (half resolution; [`crate::decode_superpixel`]).
    Superpixel,
}
