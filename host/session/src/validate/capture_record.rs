//! `capture`: the trigger controller's record, read and its version checked.

use std::path::Path;

use crate::capture::{CaptureRecord, CAPTURE_FORMAT_VERSION};
use crate::checks::check_relative_file;
use crate::error::SessionErrors;

/// Reads the capture record `rel` (relative to `dir`), or reports why it cannot be used.
pub(super) fn load(
    dir: &Path,
    rel: &str,
    file: &Path,
    errs: &mut SessionErrors,
) -> Option<CaptureRecord> {
    if !check_relative_file(dir, rel, file, "capture", errs) {
        return None;
    }
    let path = dir.join(rel);
    let bytes = match skinbrdf_core::untrusted::read_bounded(
        &path,
        skinbrdf_core::untrusted::CAPTURE_RECORD,
    ) {
        Ok(b) => b,
        Err(e) => {
            errs.push(&path, "", e.reason());
            return None;
        }
    };
    match serde_json::from_slice::<CaptureRecord>(&bytes) {
        Ok(c) if c.format_version == CAPTURE_FORMAT_VERSION => Some(c),
        Ok(c) => {
            errs.push(
                &path,
                "format_version",
                format!(
                    "version {} is not supported (this build reads {CAPTURE_FORMAT_VERSION})",
                    c.format_version
                ),
            );
            None
        }
        Err(e) => {
            errs.push(&path, "", format!("not a valid capture record: {e}"));
            None
        }
    }
}
