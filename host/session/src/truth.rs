//! `truth.json`: the ground truth a synthetic session was rendered from, so every stage can be
//! scored. Real sessions have none.

use std::path::Path;

use glam::{DVec2, DVec3};
use serde::{Deserialize, Serialize};
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::{CameraModel, Pose};

use crate::capture::ImageRole;
use crate::error::FileError;

/// Current `truth.json` format version.
pub const TRUTH_FORMAT_VERSION: u32 = 1;

/// The ground truth of a synthetic session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Format version ([`TRUTH_FORMAT_VERSION`]).
    pub format_version: u32,
    /// Scene name the session was generated from.
    pub scene: String,
    /// Random seed used.
    pub seed: u64,
    /// The true camera (intrinsics and distortion).
    pub camera: CameraModel,
    /// The true BRDF of the skin.
    pub brdf: BrdfModel,
    /// The true BRDF of the reflectance standard.
    pub standard_brdf: BrdfModel,
    /// Radiometric calibration constant C per RGB channel, sr⁻¹ m⁻² per unit linear pixel
    /// value: `rho = C D² V / cos(theta_i)` (see `docs/session-format.md`).
    pub calibration_c: [f64; 3],
    /// The flash's emitting point, world frame, metres.
    pub light_position_m: DVec3,
    /// World from flash frame.
    pub world_from_flash: Pose,
    /// World from reflectance-standard frame.
    pub world_from_standard: Pose,
    /// The exact surface the images were rendered from (the scan is a noisy, coarser copy).
    pub surface: SurfaceTruth,
    /// Per image, in session order.
    pub images: Vec<ImageTruth>,
    /// Generator settings that matter for scoring (noise levels, samples per pixel, ...).
    pub render: RenderTruth,
    /// Every target's true placement in its group's frame (scores the placement survey; older
    /// truth files have none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub placements: Vec<PlacementTruth>,
    /// The head-frame point at which head position errors are measured (the head's centre);
    /// `None`: the head frame's origin, which is the head's centre in synthetic sessions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub head_point_m: Option<DVec3>,
    /// Every printed sheet's truth (scores a survey's sheets; empty when every target is a
    /// cut-out, and in older truth files).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sheets: Vec<SheetTruth>,
}

/// A printed sheet's truth: how its layout file relates to where its targets are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SheetTruth {
    /// Its name (as in the rig file's `[[sheets]]`).
    pub name: String,
    /// Its group (the frame of `group_from_sheet`).
    pub group: crate::format::TargetGroup,
    /// The ids printed on it (its layout's, and a target printed with another's code).
    pub ids: Vec<u32>,
    /// The flat sheet's pose, tilt included (`None`: wrapped, no pose places its layout).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group_from_sheet: Option<skinbrdf_core::Pose>,
    /// Printed size over the layout's nominal size.
    pub print_scale: f64,
    /// Its tilt about its horizontal axis, degrees (included in `group_from_sheet`).
    pub tilt_deg: f64,
    /// Its fold about its vertical centre line, degrees (0: flat).
    pub bend_deg: f64,
    /// Whether the layout placed by `group_from_sheet` and `print_scale` gives the true corners
    /// (false for a folded or wrapped sheet).
    pub rigid: bool,
}

/// A target's true placement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlacementTruth {
    /// tag36h11 id.
    pub id: u32,
    /// Its group (the frame of `corners_m`).
    pub group: crate::format::TargetGroup,
    /// Corners in the group's frame, session corner order.
    pub corners_m: [DVec3; 4],
}

/// The true surface and how the scan was derived from it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurfaceTruth {
    /// Shape description (generator-specific parameters, head frame).
    pub shape: serde_json::Value,
    /// Standard deviation of the scanner's vertex noise, metres (0 when none).
    pub scan_noise_m: f64,
    /// Mean edge length of the scan mesh, metres.
    pub scan_spacing_m: f64,
    /// Number of scan vertices.
    pub scan_vertices: usize,
}

/// Render settings recorded for scoring.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderTruth {
    /// Rays per pixel (jittered, box filter over the pixel).
    pub samples_per_pixel: u32,
    /// Whether shot/read noise was added.
    pub sensor_noise: bool,
    /// Read noise standard deviation, linear units (1.0 = white).
    pub read_noise: f64,
    /// Full-well electrons at white (shot noise: variance = V / full_well_e).
    pub full_well_e: f64,
    /// Wall time of the render, seconds (informational).
    pub render_seconds: f64,
}

/// Ground truth of one image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageTruth {
    /// Image file (as in `session.toml`).
    pub file: String,
    /// Its role.
    pub role: ImageRole,
    /// Exposure time, device microseconds (from the capture record, or synthetic).
    pub exposure_us: u64,
    /// The exposure in the capture record this image was rendered for, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_index: Option<u32>,
    /// World from camera.
    pub world_from_camera: Pose,
    /// World from head.
    pub world_from_head: Pose,
    /// Pixels that see the region of interest of the skin (8-bit PNG), relative to the session.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub forehead_mask: Option<String>,
    /// Pixels that see any printed target (8-bit PNG), relative to the session.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub targets_mask: Option<String>,
    /// Pixels that see the reflectance standard's reflecting area (8-bit PNG).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub standard_mask: Option<String>,
    /// Every target whose centre projects into the image and faces the camera.
    pub targets: Vec<TargetTruth>,
}

/// Where a target truly appears in an image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TargetTruth {
    /// Which layout it belongs to: `reference`, `headdress`, `flash` or `standard`.
    pub layout: String,
    /// tag36h11 id.
    pub id: u32,
    /// The four corners in pixels (layout corner order), distortion included.
    pub corners_px: [DVec2; 4],
    /// The centre in pixels.
    pub centre_px: DVec2,
    /// Whether every corner is unoccluded and inside the image.
    pub fully_visible: bool,
}

impl Truth {
    /// Reads `truth.json`.
    pub fn load(path: &Path) -> Result<Self, FileError> {
        let bytes = std::fs::read(path).map_err(|source| FileError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let t: Self = serde_json::from_slice(&bytes).map_err(|source| FileError::Json {
            path: path.to_path_buf(),
            source,
        })?;
        if t.format_version != TRUTH_FORMAT_VERSION {
            return Err(FileError::Invalid {
                path: path.to_path_buf(),
                field: "format_version".into(),
                problem: format!(
                    "version {} is not supported (this build reads {TRUTH_FORMAT_VERSION})",
                    t.format_version
                ),
            });
        }
        Ok(t)
    }

    /// Writes `truth.json` atomically.
    pub fn write(&self, path: &Path) -> Result<(), FileError> {
        crate::write::write_json_atomic(path, self)
    }

    /// The truth of the image with this file name.
    pub fn image(&self, file: &str) -> Option<&ImageTruth> {
        self.images.iter().find(|i| i.file == file)
    }

    /// The same truth with the head frame replaced by another (a scan in its scanner's frame):
    /// `head_from_new` maps the new frame's points into the old head frame. Head poses become
    /// `world_from_head · head_from_new`, headdress placements move into the new frame.
    pub fn with_head_frame(mut self, head_from_new: &skinbrdf_core::Pose) -> Self {
        let new_from_head = head_from_new.inverse();
        self.head_point_m =
            Some(new_from_head.transform_point(self.head_point_m.unwrap_or(DVec3::ZERO)));
        for im in &mut self.images {
            im.world_from_head = im.world_from_head * *head_from_new;
        }
        for p in &mut self.placements {
            if p.group == crate::format::TargetGroup::Headdress {
                p.corners_m = p.corners_m.map(|c| new_from_head.transform_point(c));
            }
        }
        for s in &mut self.sheets {
            if s.group == crate::format::TargetGroup::Headdress {
                s.group_from_sheet = s.group_from_sheet.map(|p| new_from_head * p);
            }
        }
        self
    }

    /// This truth with its images renamed to another session's files of the same exposure:
    /// each of `images` with an `exposure_index` takes the truth of the image rendered for that
    /// exposure, and the result holds only those, in `images`' order. The other session
    /// (written by `skinbrdf ingest` from a synthetic studio) names its files as the camera
    /// did, so the file names cannot pair them. A survey image has no exposure: it takes the
    /// truth of the survey image whose file has the same name (the studio's truth names its
    /// survey images by their raw files; the session may hold them in another folder).
    /// Errors (naming `path`) when no image pairs.
    pub fn keyed_to(
        mut self,
        images: &[crate::format::ImageEntry],
        path: &Path,
    ) -> Result<Self, FileError> {
        if images.iter().all(|e| self.image(&e.file).is_some()) {
            return Ok(self);
        }
        let mut keyed = Vec::new();
        let name = |f: &str| Path::new(f).file_name().map(std::ffi::OsStr::to_os_string);
        for e in images {
            let found = match e.exposure_index {
                Some(k) => self.images.iter().find(|t| t.exposure_index == Some(k)),
                None if e.role == ImageRole::Survey => self.images.iter().find(|t| {
                    t.role == ImageRole::Survey
                        && t.exposure_index.is_none()
                        && name(&t.file).is_some()
                        && name(&t.file) == name(&e.file)
                }),
                None => None,
            };
            if let Some(t) = found {
                keyed.push(ImageTruth {
                    file: e.file.clone(),
                    ..t.clone()
                });
            }
        }
        if keyed.is_empty() {
            return Err(FileError::Invalid {
                path: path.to_path_buf(),
                field: "images".into(),
                problem: "no image of the session pairs with this truth (neither by file name \
                          nor by exposure index)"
                    .into(),
            });
        }
        self.images = keyed;
        Ok(self)
    }
}
