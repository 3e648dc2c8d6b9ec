//! The semantic and cross-file checks of a parsed `session.toml`, one function per section:
//! every invariant and every cross-reference (files exist, image sizes match the camera,
//! target ids are unique across layouts, exposure indices exist in `capture.json` with the
//! same role), then what the stages that have no known quantity to skip them need (targets,
//! standard, images). Every problem is reported; none stops the others.

mod capture_record;
mod duplicates;
mod images;
mod known;
mod scene;
mod stages;
mod targets;

use std::path::Path;

use crate::capture::CaptureRecord;
use crate::error::SessionErrors;
use crate::format::{CameraSpec, SessionFile, SESSION_FILE};
use crate::parse::Stated;

/// Semantic and cross-file checks of the session in `dir`. Returns the capture record if it
/// was loaded.
pub(crate) fn validate(
    dir: &Path,
    s: &SessionFile,
    stated: Stated,
    errs: &mut SessionErrors,
) -> Option<CaptureRecord> {
    let file = dir.join(SESSION_FILE);
    let file = file.as_path();
    camera(&s.camera, file, errs);
    for (f, p) in s.linearization.problems() {
        errs.push(file, format!("linearization.{f}"), p);
    }
    let capture = s
        .capture
        .as_ref()
        .and_then(|rel| capture_record::load(dir, rel, file, errs));
    images::check(dir, s, capture.as_ref(), file, errs);
    targets::check(s, file, errs);
    scene::flash_and_standard(s, stated, file, errs);
    scene::geometry(dir, s, file, errs);
    known::check(&s.known, file, errs);
    stages::check(s, stated, file, errs);
    capture
}

/// `[camera]`: a calibration's parameters, or a positive image size and focal guess.
fn camera(camera: &CameraSpec, file: &Path, errs: &mut SessionErrors) {
    let (w, h) = camera.size_px();
    match camera {
        CameraSpec::Calibrated(m) => {
            if let Err(skinbrdf_core::CameraError::InvalidParameter { field, reason }) =
                m.validate()
            {
                errs.push(file, format!("camera.{field}"), reason);
            }
        }
        CameraSpec::ToBeCalibrated { focal_guess_px, .. } => {
            if w == 0 || h == 0 {
                errs.push(
                    file,
                    "camera.width_px/height_px",
                    "image size must be positive",
                );
            }
            if let Some(f) = focal_guess_px {
                if !crate::checks::positive(*f) {
                    errs.push(file, "camera.focal_guess_px", "must be positive and finite");
                }
            }
        }
    }
}
