//! What a session's planned stages need from `session.toml` ([`SectionNeeds`]), from the
//! quantities it already knows, and what kind of file an image is by its name.

use std::path::Path;

use crate::capture::ImageRole;
use crate::format::{CameraSpec, ImageEntry, KnownQuantities};

/// Which optional parts of a session its planned stages need, from the quantities it already
/// knows (the facts that plan `skinbrdf process`'s stages): `Some(reason)` = needed, `None` =
/// every stage that would use it is skipped.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SectionNeeds {
    /// `[[targets.reference]]`: camera calibration (unknown intrinsics) or camera poses (an
    /// image without `world_from_camera`).
    pub reference_targets: Option<String>,
    /// `[[targets.headdress]]`: head tracking (a measurement image without `world_from_head`,
    /// and the sample not stationary).
    pub headdress_targets: Option<String>,
    /// `[flash]` and its targets: flash triangulation (no known light position).
    pub flash_targets: Option<String>,
    /// `[standard]` and a reference-standard image: radiometric calibration (no known C).
    pub standard: Option<String>,
    /// `[linearization]`: an integer (PNG/TIFF/JPEG) image without its own linearization.
    pub linearization: Option<String>,
}

impl SectionNeeds {
    /// The needs of a session with these images, known quantities and camera (`None`: not
    /// known, e.g. because it did not parse).
    pub fn of(images: &[ImageEntry], known: &KnownQuantities, camera: Option<&CameraSpec>) -> Self {
        let no_cam: Vec<usize> = (0..images.len())
            .filter(|&i| images[i].world_from_camera.is_none())
            .collect();
        let reference_targets = if let Some(&first) = no_cam.first() {
            Some(format!(
                "{} image(s) have no known world_from_camera (first: images[{first}])",
                no_cam.len()
            ))
        } else if images.is_empty() {
            Some("no image has a known world_from_camera".to_string())
        } else if matches!(camera, Some(CameraSpec::ToBeCalibrated { .. })) {
            Some("the camera is to be calibrated (from the reference targets)".to_string())
        } else {
            None
        };
        let no_head = images
            .iter()
            .position(|i| i.role == ImageRole::Measurement && i.world_from_head.is_none());
        let headdress_targets = match (no_head, known.stationary_sample) {
            (_, true) => None,
            (Some(i), false) => Some(format!(
                "images[{i}] has no known world_from_head and the sample is not stationary"
            )),
            (None, false) if images.is_empty() => {
                Some("no image has a known world_from_head and the sample is not stationary".into())
            }
            (None, false) => None,
        };
        let flash_targets = (known.light_position_m.is_none() && known.world_from_flash.is_none())
            .then(|| "neither known.light_position_m nor known.world_from_flash is given".into());
        let standard = known
            .calibration_c
            .is_none()
            .then(|| "known.calibration_c is not given".to_string());
        let linearization = images
            .iter()
            .enumerate()
            .find(|(_, im)| {
                im.linearization.is_none() && !is_float_file(&im.file) && !is_raw_file(&im.file)
            })
            .map(|(i, im)| {
                format!(
                    "images[{i}] (`{}`) is an integer image without a linearization of its own",
                    im.file
                )
            });
        Self {
            reference_targets,
            headdress_targets,
            flash_targets,
            standard,
            linearization,
        }
    }
}

/// True for a camera raw file, by its extension (a content that disagrees with the name is
/// refused when the image is read).
pub(crate) fn is_raw_file(name: &str) -> bool {
    Path::new(name)
        .extension()
        .and_then(|e| skinbrdf_raw::FileKind::from_extension(&e.to_string_lossy()))
        .is_some_and(|k| k.is_raw())
}

/// True for an OpenEXR file (float values), by its extension.
pub(crate) fn is_float_file(name: &str) -> bool {
    Path::new(name)
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}
