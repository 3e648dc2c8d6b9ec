//! Checks of single values of `session.toml` (and `rig.toml`): poses, files, target ids and
//! sizes, placed targets, shapes, BRDFs. Each reports its problems by field and returns.

use std::path::Path;

use glam::DVec3;
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::Pose;

use crate::error::SessionErrors;
use crate::format::{GeometrySpec, Target};

/// Number of codes in the tag36h11 family.
pub const TAG36H11_CODES: u32 = 587;

/// Relative tolerance on a target's edge lengths against `size_m` (printing and measuring a
/// layout is good to well under 1%; more means a wrong corner order or unit).
pub const TARGET_SIZE_REL_TOL: f64 = 0.01;

/// Positive and finite.
pub(crate) fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

/// A pose: finite, its rotation a unit quaternion.
pub(crate) fn check_pose(p: &Pose, file: &Path, field: &str, errs: &mut SessionErrors) {
    if !p.is_finite() {
        errs.push(file, field, "pose has a non-finite component");
    } else if (p.rotation.length() - 1.0).abs() > 1e-6 {
        errs.push(
            file,
            format!("{field}.rotation"),
            format!(
                "quaternion must be unit length, has length {}",
                p.rotation.length()
            ),
        );
    }
}

/// False (with the error) when a file key of `session.toml` names no file.
fn is_named(rel: &str, file: &Path, field: &str, errs: &mut SessionErrors) -> bool {
    if rel.is_empty() {
        errs.push(file, field, "empty file name");
    }
    !rel.is_empty()
}

/// Checks that a photograph named in `session.toml` exists. Unlike the session's other files,
/// a photograph may live outside the session directory (`skinbrdf ingest` references the
/// camera card's files in place unless asked to copy them): a relative path is taken from the
/// session directory, an absolute one as it is.
pub(crate) fn check_image_file(
    dir: &Path,
    rel: &str,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> bool {
    if !is_named(rel, file, field, errs) {
        return false;
    }
    if !dir.join(rel).is_file() {
        errs.push(file, field, format!("file `{rel}` does not exist"));
        return false;
    }
    true
}

/// Checks that a file named in `session.toml` is a regular file inside the session directory.
pub(crate) fn check_relative_file(
    dir: &Path,
    rel: &str,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> bool {
    if !is_named(rel, file, field, errs) {
        return false;
    }
    // Inside the session directory (no absolute path, `..` or link out), a regular file.
    match skinbrdf_core::untrusted::confine(dir, rel) {
        Ok(_) => true,
        Err(skinbrdf_core::untrusted::ConfineError::Missing { .. }) => {
            errs.push(file, field, format!("file `{rel}` does not exist"));
            false
        }
        Err(e) => {
            errs.push(
                file,
                field,
                format!("must be a regular file inside the session directory: {e}"),
            );
            false
        }
    }
}

/// A target's id (a tag36h11 code) and printed size (positive); false when the size is not
/// (nothing geometric can be checked then).
pub(crate) fn check_id_and_size(
    id: u32,
    size_m: f64,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> bool {
    if id >= TAG36H11_CODES {
        errs.push(
            file,
            format!("{field}.id"),
            format!("{id} is not a tag36h11 id (0..{TAG36H11_CODES})"),
        );
    }
    if !positive(size_m) {
        errs.push(
            file,
            format!("{field}.size_m"),
            format!("must be positive, got {size_m}"),
        );
        return false;
    }
    true
}

/// Checks an analytic shape (sphere, cylinder): finite centre and axis, positive sizes. A scan
/// is checked where its file is resolved.
pub(crate) fn check_shape(g: &GeometrySpec, file: &Path, errs: &mut SessionErrors) {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    match g {
        GeometrySpec::Scan { .. } => {}
        GeometrySpec::Sphere { centre_m, radius_m } => {
            if !centre_m.is_finite() {
                errs.push(file, "geometry.centre_m", "non-finite coordinate");
            }
            if !positive(*radius_m) {
                errs.push(
                    file,
                    "geometry.radius_m",
                    format!("must be positive, got {radius_m}"),
                );
            }
        }
        GeometrySpec::Cylinder {
            centre_m,
            axis,
            radius_m,
            length_m,
        } => {
            if !centre_m.is_finite() {
                errs.push(file, "geometry.centre_m", "non-finite coordinate");
            }
            if !axis.is_finite() || axis.length() < 1e-12 {
                errs.push(file, "geometry.axis", "must be a finite non-zero vector");
            }
            if !positive(*radius_m) {
                errs.push(
                    file,
                    "geometry.radius_m",
                    format!("must be positive, got {radius_m}"),
                );
            }
            if !positive(*length_m) {
                errs.push(
                    file,
                    "geometry.length_m",
                    format!("must be positive, got {length_m}"),
                );
            }
        }
    }
}

/// A placed target: id, size, finite corners forming a square of its size (edges within
/// [`TARGET_SIZE_REL_TOL`]), coplanar, its centre at their mean.
pub(crate) fn check_target(t: &Target, file: &Path, field: &str, errs: &mut SessionErrors) {
    if !check_id_and_size(t.id, t.size_m, file, field, errs) {
        return;
    }
    if !t.corners_m.iter().all(|c| c.is_finite()) || !t.centre_m.is_none_or(|c| c.is_finite()) {
        errs.push(file, format!("{field}.corners_m"), "non-finite coordinate");
        return;
    }
    let c = t.corners_m;
    let tol = TARGET_SIZE_REL_TOL * t.size_m;
    for i in 0..4 {
        let e = c[(i + 1) % 4].distance(c[i]);
        if (e - t.size_m).abs() > tol {
            errs.push(
                file,
                format!("{field}.corners_m"),
                format!(
                    "edge {i}->{} is {e:.5} m, but size_m is {} m",
                    (i + 1) % 4,
                    t.size_m
                ),
            );
            return;
        }
    }
    let d = c[2].distance(c[0]);
    if (d - t.size_m * std::f64::consts::SQRT_2).abs() > 2.0 * tol {
        errs.push(
            file,
            format!("{field}.corners_m"),
            "corners do not form a square",
        );
        return;
    }
    let n = (c[1] - c[0]).cross(c[3] - c[0]).normalize_or_zero();
    if (c[2] - c[0]).dot(n).abs() > tol {
        errs.push(
            file,
            format!("{field}.corners_m"),
            "corners are not coplanar",
        );
    }
    if let Some(centre) = t.centre_m {
        let mean = c.iter().copied().sum::<DVec3>() * 0.25;
        if centre.distance(mean) > tol {
            errs.push(
                file,
                format!("{field}.centre_m"),
                "is not the centre of the corners",
            );
        }
    }
}

/// A BRDF's parameters, each problem named by its field.
pub(crate) fn check_brdf(b: &BrdfModel, file: &Path, field: &str, errs: &mut SessionErrors) {
    if let Err(e) = b.validate() {
        match e {
            skinbrdf_brdf::BrdfError::InvalidParameter { field: f, reason } => {
                errs.push(file, format!("{field}.{f}"), reason)
            }
            other => errs.push(file, field, other.to_string()),
        }
    }
}
