//! Coded targets: AprilTag tag36h11 detection with sub-pixel corners, and printable target sheets.
//!
//! * [`tag36h11`]: the code table and bit layout ([`tag36h11::tag_bits`] renders a tag's cells).
//! * [`detect`](mod@detect): the detector ([`detect::detect`]), corners in the project's pixel
//!   convention.
//! * [`profile`]: edge-profile refinement of small tags (cells of a few pixels).
//! * [`reference_quad`]: the reference C library's quad stage, for like-for-like comparisons.
//! * [`render`]: painting tags into images through a homography (tests, synthetic images).
//! * [`sheet`]: printable sheets (SVG, PDF) at true scale.

pub mod detect;
pub mod homography;
pub mod image;
pub mod profile;
pub mod reference_quad;
pub mod render;
pub mod sheet;
pub mod tag36h11;
#[cfg(test)]
mod test_scenes;

pub use detect::{detect, CornerModel, DetectStats, Detection, DetectorConfig};
pub use image::{GrayF32, ImageError};
