//! Loading and validating session directories: a valid one loads; bad ones report every
//! problem with file and field.
#![allow(clippy::unwrap_used)] // test helpers

use std::path::Path;

use glam::DVec3;
use skinbrdf_core::Pose;
use skinbrdf_session::write::write_png_rgb16;
use skinbrdf_session::*;

mod common;

/// A 16-bit code decoded to `f32` in [0, 1] equals the exact quotient within `f32` rounding.
const F32_DECODE_TOL: f32 = 1e-7;

const W: u32 = 8;
const H: u32 = 6;

/// The valid session the tests start from: four PNG images of a W x H camera, two reference
/// targets, a region of interest and the standard's pose known.
fn valid_file() -> SessionFile {
    let mut f = common::session_file(W, H, "png");
    f.targets
        .reference
        .push(common::target(1, DVec3::new(0.1, 0.0, 2.0)));
    f.roi = Some(RegionOfInterest {
        centre_m: DVec3::new(0.0, 0.0, 0.08),
        radius_m: 0.03,
    });
    f.known.world_from_standard = Some(Pose::IDENTITY);
    f
}

fn write_dir(dir: &Path, f: &SessionFile) {
    common::write_dir(dir, f, W, H);
}

#[test]
fn a_valid_session_loads_and_its_images_linearize() {
    let dir = tempfile::tempdir().unwrap();
    let f = valid_file();
    write_dir(dir.path(), &f);
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.file, f);
    assert_eq!(s.images_with_role(ImageRole::Measurement).count(), 2);
    let img = s.load_image(0).unwrap();
    assert_eq!((img.width, img.height), (W, H));
    assert!((img.rgb[7][1] - 1000.0 / 65535.0).abs() < F32_DECODE_TOL);
    assert!(s.load_truth().is_none());
}

#[test]
fn a_session_with_survey_images_loads_and_a_survey_image_has_no_exposure() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = valid_file();
    let mut survey = f.images[0].clone();
    survey.file = "images/survey0.png".into();
    survey.role = ImageRole::Survey;
    f.images.insert(0, survey);
    write_dir(dir.path(), &f);
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.images_with_role(ImageRole::Survey).count(), 1);
    assert_eq!(s.images_with_role(ImageRole::Measurement).count(), 2);
    let text = std::fs::read_to_string(dir.path().join("session.toml")).unwrap();
    assert!(text.contains("role = \"survey\""), "{text}");
    // A survey image is never fired by the controller: an exposure index is refused.
    f.images[0].exposure_index = Some(3);
    Session::write_file(dir.path(), &f).unwrap();
    let errs = Session::load(dir.path()).unwrap_err();
    assert!(errs.has_field("images[0].exposure_index"), "{errs}");
    assert!(errs.to_string().contains("survey image"), "{errs}");
}

#[test]
fn every_semantic_problem_is_reported_with_its_field() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = valid_file();
    write_dir(dir.path(), &f);
    f.images[1].file = "images/missing.png".into();
    f.images[2].linearization = Some(Linearization {
        curve: ToneCurve::Gamma,
        ..Linearization::LINEAR
    });
    f.targets.headdress[0].id = 1; // duplicate of a reference id
    f.targets.reference[1].size_m = 0.05; // corners no longer match
    f.flash.diameter_m = -1.0;
    f.geometry = GeometrySpec::Sphere {
        centre_m: DVec3::ZERO,
        radius_m: 0.0,
    };
    f.known.calibration_c = Some([1.0, f64::NAN, 1.0]);
    Session::write_file(dir.path(), &f).unwrap();
    let errs = Session::load(dir.path()).unwrap_err();
    let text = errs.to_string();
    for field in [
        "images[1].file",
        "images[2].linearization.gamma",
        "targets.headdress[0].id",
        "targets.reference[1].corners_m",
        "flash.diameter_m",
        "geometry.radius_m",
        "known.calibration_c",
    ] {
        assert!(errs.has_field(field), "missing `{field}` in:\n{text}");
    }
    assert!(errs
        .problems
        .iter()
        .all(|p| p.file.ends_with("session.toml")));
}

#[test]
fn every_parse_problem_is_reported_at_once() {
    let text = toml::to_string(&valid_file()).unwrap();
    let bad = text
        .replace("role = \"light-position\"", "role = \"light-posiiton\"")
        .replace("diameter_m = 0.082", "diameter_m = \"big\"")
        .replace("format_version = 1", "format_version = 1\nbogus = 3");
    // Drop one required field of a target.
    let bad = bad.replacen("size_m = 0.04\n", "", 1);
    let errs = Session::parse_toml(&bad, Path::new("x/session.toml")).unwrap_err();
    let text = errs.to_string();
    assert!(errs.has_field("images[2].role"), "{text}");
    assert!(errs.has_field("flash.diameter_m"), "{text}");
    assert!(errs.has_field("bogus"), "{text}");
    assert!(
        errs.problems
            .iter()
            .any(|p| p.field.starts_with("targets.reference[0]")),
        "{text}"
    );
    assert!(text.contains("light-posiiton"), "{text}");
    assert!(errs.len() >= 4, "{text}");
}

#[test]
fn missing_sections_and_needs_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = valid_file();
    write_dir(dir.path(), &f);
    f.targets.reference.clear();
    f.standard = None;
    Session::write_file(dir.path(), &f).unwrap();
    let errs = Session::load(dir.path()).unwrap_err();
    assert!(errs.has_field("targets.reference"), "{errs}");
    assert!(errs.has_field("standard"), "{errs}");

    let errs = Session::parse_toml("format_version = 2\n", Path::new("session.toml")).unwrap_err();
    for field in [
        "format_version",
        "camera",
        "images",
        "targets",
        "flash",
        "geometry",
    ] {
        assert!(errs.has_field(field), "missing `{field}` in {errs}");
    }
    let errs = Session::parse_toml("format_version = [", Path::new("session.toml")).unwrap_err();
    assert!(errs.to_string().contains("line 1"), "{errs}");
}

#[test]
fn image_size_mismatch_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let f = valid_file();
    write_dir(dir.path(), &f);
    write_png_rgb16(
        &dir.path().join("images/m1.png"),
        W + 1,
        H,
        &vec![0u16; (3 * (W + 1) * H) as usize],
    )
    .unwrap();
    let errs = Session::load(dir.path()).unwrap_err();
    assert_eq!(errs.len(), 1, "{errs}");
    assert!(errs.has_field("images[1].file"));
    assert!(errs.to_string().contains("9x6"), "{errs}");
}
