//! `[[images]]`: each entry's file (present, not listed twice, of the camera's size, its
//! linearization fitting its format), its fields, and its exposure in the capture record.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::capture::{CaptureRecord, ImageRole};
use crate::checks::{check_image_file, check_pose, check_relative_file};
use crate::error::SessionErrors;
use crate::format::{ImageEntry, SessionFile};
use crate::linear::{raw_options, StoredFormat};

use super::duplicates::report_identical_contents;

/// The files seen so far: by name as written, and by canonical path.
#[derive(Default)]
struct Seen<'a> {
    by_name: HashMap<&'a str, usize>,
    by_path: HashMap<PathBuf, usize>,
}

/// Checks every image entry, then the images' contents against each other and that one is a
/// measurement.
pub(super) fn check(
    dir: &Path,
    s: &SessionFile,
    capture: Option<&CaptureRecord>,
    file: &Path,
    errs: &mut SessionErrors,
) {
    if s.images.is_empty() {
        errs.push(file, "images", "the session has no images");
    }
    let mut seen = Seen::default();
    let mut existing: Vec<usize> = Vec::new();
    for (i, im) in s.images.iter().enumerate() {
        let field = format!("images[{i}]");
        if image_file(dir, s, i, &mut seen, file, errs) {
            existing.push(i);
        }
        fields(dir, im, &field, file, errs);
        exposure_index(s, im, capture, &field, file, errs);
    }
    report_identical_contents(dir, s, &existing, file, errs);
    let count = |role| s.images.iter().filter(|i| i.role == role).count();
    if !s.images.is_empty() && count(ImageRole::Measurement) == 0 {
        errs.push(file, "images", "no image has role = \"measurement\"");
    }
}

/// Image `i`'s file: not listed before (by name or by canonical path), present, and readable
/// as an image of the camera's size (see [`header`]). True when the file exists and was not
/// listed before by name.
fn image_file<'a>(
    dir: &Path,
    s: &'a SessionFile,
    i: usize,
    seen: &mut Seen<'a>,
    file: &Path,
    errs: &mut SessionErrors,
) -> bool {
    let im = &s.images[i];
    let field = format!("images[{i}].file");
    if let Some(prev) = seen.by_name.insert(im.file.as_str(), i) {
        errs.push(file, field, format!("`{}` is also images[{prev}]", im.file));
        return false;
    }
    if !check_image_file(dir, &im.file, file, &field, errs) {
        return false;
    }
    let path = dir.join(&im.file);
    let same_file = std::fs::canonicalize(&path)
        .ok()
        .and_then(|c| seen.by_path.insert(c, i));
    if let Some(prev) = same_file {
        errs.push(
            file,
            &field,
            format!(
                "`{}` is the same file as images[{prev}] (`{}`)",
                im.file, s.images[prev].file
            ),
        );
    }
    header(&path, s, i, file, errs);
    true
}

/// Image `i`'s header: its size is the camera's, and the linearization that applies to it
/// (its own, else the session's; a raw file's own table only) fits its stored format.
fn header(path: &Path, s: &SessionFile, i: usize, file: &Path, errs: &mut SessionErrors) {
    let im = &s.images[i];
    let field = format!("images[{i}]");
    let (w, h) = s.camera.size_px();
    match crate::linear::read_header(path) {
        Ok(hd) if (hd.width, hd.height) != (w, h) => errs.push(
            file,
            format!("{field}.file"),
            format!(
                "`{}` is {}x{} px but the camera is {w}x{h} px",
                im.file, hd.width, hd.height
            ),
        ),
        Ok(hd) if matches!(hd.format, StoredFormat::Raw { .. }) => {
            // No session default applies to a raw file; its own table may override the levels.
            if let Some(Err((f, p))) = im.linearization.as_ref().map(raw_options) {
                errs.push(
                    file,
                    format!("{field}.linearization.{f}"),
                    format!("`{}` (camera raw): {p}", im.file),
                );
            }
        }
        Ok(hd) => {
            let (lin, lin_field) = match &im.linearization {
                Some(l) => (l, format!("{field}.linearization")),
                None => (&s.linearization, "linearization".to_string()),
            };
            for (f, p) in lin.problems_for(hd.format) {
                errs.push(
                    file,
                    format!("{lin_field}.{f}"),
                    format!("`{}` ({}): {p}", im.file, hd.format.describe()),
                );
            }
        }
        Err(e) => errs.push(
            file,
            format!("{field}.file"),
            format!(
                "`{}` is not a readable image: {}",
                im.file,
                skinbrdf_core::error_text(&e)
            ),
        ),
    }
}

/// An image entry's own fields: linearization, exposure scale, mask file, known poses.
fn fields(dir: &Path, im: &ImageEntry, field: &str, file: &Path, errs: &mut SessionErrors) {
    if let Some(l) = &im.linearization {
        for (f, p) in l.problems() {
            errs.push(file, format!("{field}.linearization.{f}"), p);
        }
    }
    if let Some(k) = im.exposure_scale {
        if !(k.is_finite() && k > 0.0) {
            errs.push(
                file,
                format!("{field}.exposure_scale"),
                format!("must be positive and finite, got {k}"),
            );
        }
    }
    if let Some(m) = &im.mask {
        check_relative_file(dir, m, file, &format!("{field}.mask"), errs);
    }
    if let Some(p) = &im.world_from_camera {
        check_pose(p, file, &format!("{field}.world_from_camera"), errs);
    }
    if let Some(p) = &im.world_from_head {
        check_pose(p, file, &format!("{field}.world_from_head"), errs);
    }
}

/// An image's `exposure_index`: only for images the controller fires, and then an exposure
/// of the capture record shot in the image's role.
fn exposure_index(
    s: &SessionFile,
    im: &ImageEntry,
    capture: Option<&CaptureRecord>,
    field: &str,
    file: &Path,
    errs: &mut SessionErrors,
) {
    match (im.exposure_index, capture) {
        (Some(x), _) if !im.role.fired_by_controller() => errs.push(
            file,
            format!("{field}.exposure_index"),
            format!(
                "is {x}, but a survey image is taken by hand, never fired by the \
                 controller: it has no exposure in the capture record"
            ),
        ),
        (Some(x), Some(c)) => match c.exposures.iter().find(|e| e.index == x) {
            None => errs.push(
                file,
                format!("{field}.exposure_index"),
                format!(
                    "exposure {x} is not in `{}`",
                    s.capture.as_deref().unwrap_or_default()
                ),
            ),
            Some(e) if e.role != im.role => errs.push(
                file,
                format!("{field}.role"),
                format!(
                    "is {} but exposure {x} was shot as {}",
                    im.role.name(),
                    e.role.name()
                ),
            ),
            Some(_) => {}
        },
        (Some(_), None) if s.capture.is_none() => errs.push(
            file,
            format!("{field}.exposure_index"),
            "given, but the session has no `capture` record",
        ),
        _ => {}
    }
}
