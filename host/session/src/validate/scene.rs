//! The physical setup: `[flash]`, `[standard]`, `[registration]`, `[geometry]` and `[roi]`.

use std::path::Path;

use crate::checks::{check_brdf, check_relative_file, check_shape, positive};
use crate::error::SessionErrors;
use crate::format::{GeometrySpec, SessionFile};
use crate::parse::Stated;

/// `[flash]` (a stated diameter positive, the emitting point finite) and `[standard]` (its
/// BRDF, a positive size).
pub(super) fn flash_and_standard(
    s: &SessionFile,
    stated: Stated,
    file: &Path,
    errs: &mut SessionErrors,
) {
    if stated.flash && !positive(s.flash.diameter_m) {
        errs.push(
            file,
            "flash.diameter_m",
            format!("must be positive, got {}", s.flash.diameter_m),
        );
    }
    if !s.flash.light_centre_m.is_finite() {
        errs.push(file, "flash.light_centre_m", "non-finite coordinate");
    }
    if let Some(st) = &s.standard {
        check_brdf(&st.brdf, file, "standard.brdf", errs);
        if !st.size_m.iter().all(|&v| positive(v)) {
            errs.push(
                file,
                "standard.size_m",
                format!(
                    "must be positive, got {} x {} m",
                    st.size_m[0], st.size_m[1]
                ),
            );
        }
    }
}

/// `[registration]`'s points file, `[geometry]` (a scan file of a known format inside the
/// session, or an analytic shape) and `[roi]`.
pub(super) fn geometry(dir: &Path, s: &SessionFile, file: &Path, errs: &mut SessionErrors) {
    if let Some(points) = s.registration.as_ref().and_then(|r| r.points.as_ref()) {
        check_relative_file(dir, points, file, "registration.points", errs);
    }
    match &s.geometry {
        GeometrySpec::Scan {
            file: scan,
            accept_repair_loss,
            ..
        } => scan_file(dir, scan, *accept_repair_loss, file, errs),
        shape => check_shape(shape, file, errs),
    }
    if let Some(r) = &s.roi {
        if !r.centre_m.is_finite() {
            errs.push(file, "roi.centre_m", "non-finite coordinate");
        }
        if !positive(r.radius_m) {
            errs.push(
                file,
                "roi.radius_m",
                format!("must be positive, got {}", r.radius_m),
            );
        }
    }
}

/// A scan geometry: the accepted repair loss a fraction, the file inside the session and of
/// a format the loader reads.
fn scan_file(
    dir: &Path,
    scan: &str,
    accept_repair_loss: Option<f64>,
    file: &Path,
    errs: &mut SessionErrors,
) {
    if let Some(f) = accept_repair_loss {
        if !(0.0..=1.0).contains(&f) {
            errs.push(
                file,
                "geometry.accept_repair_loss",
                format!("{f}: a fraction of the triangles, in [0, 1]"),
            );
        }
    }
    if check_relative_file(dir, scan, file, "geometry.file", errs) {
        let ext = Path::new(scan)
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if !matches!(ext.as_str(), "ply" | "obj" | "glb" | "gltf") {
            errs.push(
                file,
                "geometry.file",
                format!("`{scan}`: scans must be .ply, .obj, .glb or .gltf"),
            );
        }
    }
}
