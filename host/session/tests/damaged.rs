//! Damaged or incomplete sessions: every kind of damage is an error naming the file and the
//! field (or, for unusable photographs under `BadImagePolicy::Skip`, a listed skip), never a
//! silently changed result.
#![allow(clippy::unwrap_used)] // test helpers

use std::path::Path;

use glam::DVec3;
use skinbrdf_core::Pose;
use skinbrdf_session::write::{write_exr_rgb32f, write_png_rgb16, write_png_rgb8};
use skinbrdf_session::*;

mod common;

const W: u32 = 8;
const H: u32 = 6;

/// The valid session every test damages: four PNG images of a W x H camera.
fn valid_file() -> SessionFile {
    common::session_file(W, H, "png")
}

fn write_dir(dir: &Path, f: &SessionFile) {
    common::write_dir(dir, f, W, H);
}

/// `session.toml` of `f` as a TOML table, to damage.
fn table(f: &SessionFile) -> toml::Table {
    toml::Value::try_from(f)
        .unwrap()
        .as_table()
        .unwrap()
        .clone()
}

fn sub<'a>(t: &'a mut toml::Table, path: &[&str]) -> &'a mut toml::Table {
    path.iter()
        .fold(t, |t, k| t.get_mut(*k).unwrap().as_table_mut().unwrap())
}

fn parse(t: &toml::Table) -> Result<SessionFile, SessionErrors> {
    Session::parse_toml(&toml::to_string(t).unwrap(), Path::new("session.toml"))
}

fn load_text(dir: &Path, t: &toml::Table) -> Result<Session, SessionErrors> {
    std::fs::write(dir.join("session.toml"), toml::to_string(t).unwrap()).unwrap();
    Session::load(dir)
}

#[test]
fn unknown_keys_are_errors_in_every_table_with_their_path() {
    let base = table(&valid_file());
    assert!(parse(&base).is_ok());
    let cases: [(&[&str], &str, toml::Value, &str); 7] = [
        (&["camera"], "k1", 0.5.into(), "camera.k1"),
        (
            &["camera", "distortion"],
            "k4",
            0.1.into(),
            "camera.distortion.k4",
        ),
        (
            &["standard", "brdf"],
            "albdo",
            0.5.into(),
            "standard.brdf.albdo",
        ),
        (&["linearization"], "gama", 2.2.into(), "linearization.gama"),
        (&["geometry"], "radius", 0.1.into(), "geometry.radius"),
        (
            &["known"],
            "light_positon_m",
            0.1.into(),
            "known.light_positon_m",
        ),
        (&["flash"], "diametre_m", 0.1.into(), "flash.diametre_m"),
    ];
    for (table_path, key, value, field) in cases {
        let mut t = base.clone();
        sub(&mut t, table_path).insert(key.into(), value);
        let errs = parse(&t).expect_err(field);
        assert!(errs.has_field(field), "`{field}` not reported: {errs}");
        assert!(errs.to_string().contains("unknown field"), "{errs}");
    }
    // Inside an item of an array of tables, and inside a pose (a core type).
    let mut f = valid_file();
    f.images[0].world_from_camera = Some(Pose::IDENTITY);
    let mut t = table(&f);
    let im0 = t["images"].as_array_mut().unwrap()[0]
        .as_table_mut()
        .unwrap();
    im0.get_mut("world_from_camera")
        .unwrap()
        .as_table_mut()
        .unwrap()
        .insert("scale".into(), 1.0.into());
    let errs = parse(&t).unwrap_err();
    assert!(
        errs.has_field("images[0].world_from_camera.scale"),
        "{errs}"
    );
}

#[test]
fn type_errors_name_the_field_inside_tagged_tables() {
    let base = table(&valid_file());
    let cases: [(&[&str], &str, &str); 5] = [
        (&["camera"], "fx_px", "camera.fx_px"),
        (&["camera", "distortion"], "k2", "camera.distortion.k2"),
        (&["standard", "brdf"], "albedo", "standard.brdf.albedo"),
        (&["geometry"], "radius_m", "geometry.radius_m"),
        (&["standard"], "size_m", "standard.size_m"),
    ];
    for (table_path, key, field) in cases {
        let mut t = base.clone();
        sub(&mut t, table_path).insert(key.into(), "oops".into());
        let errs = parse(&t).expect_err(field);
        assert!(errs.has_field(field), "`{field}` not named: {errs}");
        assert!(errs.to_string().contains("invalid type"), "{errs}");
    }
    // A missing field is named with its full path, a bad tag at the tag.
    let mut t = base.clone();
    sub(&mut t, &["camera", "distortion"]).remove("k3");
    assert!(parse(&t).unwrap_err().has_field("camera.distortion.k3"));
    let mut t = base.clone();
    sub(&mut t, &["camera"]).insert("status".into(), "calibratd".into());
    let errs = parse(&t).unwrap_err();
    assert!(errs.has_field("camera.status"), "{errs}");
    assert!(errs.to_string().contains("to-be-calibrated"), "{errs}");
}

#[test]
fn linearization_is_required_for_integer_images_and_stated_for_float_ones() {
    let dir = tempfile::tempdir().unwrap();
    let f = valid_file();
    write_dir(dir.path(), &f);
    let mut t = table(&f);
    t.remove("linearization");
    let errs = load_text(dir.path(), &t).unwrap_err();
    assert!(errs.has_field("linearization"), "{errs}");
    assert!(errs.to_string().contains("images/m0.png"), "{errs}");

    // Every image a float file: the default (linear, black 0, white 1) applies and says so.
    let mut f = valid_file();
    for (i, im) in f.images.iter_mut().enumerate() {
        im.file = im.file.replace(".png", ".exr");
        let mut px = vec![0.25f32; (3 * W * H) as usize];
        px[0] = i as f32;
        write_exr_rgb32f(&dir.path().join(&im.file), W, H, &px).unwrap();
    }
    let mut t = table(&f);
    t.remove("linearization");
    let s = load_text(dir.path(), &t).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.linearization_source, LinearizationSource::FloatDefault);
    assert!(s.linearization_source.note().unwrap().contains("black 0"));
    let s = load_text(dir.path(), &table(&f)).unwrap();
    assert_eq!(s.linearization_source, LinearizationSource::Stated);
    assert!(s.linearization_source.note().is_none());
}

#[test]
fn an_8_bit_image_under_a_16_bit_black_level_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = valid_file();
    f.linearization.black_level = 4096.0;
    write_dir(dir.path(), &f);
    write_png_rgb8(
        &dir.path().join("images/m1.png"),
        W,
        H,
        &vec![200u8; (3 * W * H) as usize],
    )
    .unwrap();
    let errs = Session::load(dir.path()).unwrap_err();
    assert_eq!(errs.len(), 1, "{errs}");
    assert!(errs.has_field("linearization.black_level"), "{errs}");
    let text = errs.to_string();
    assert!(
        text.contains("images/m1.png") && text.contains("8-bit"),
        "{text}"
    );
}

#[test]
fn the_same_photograph_twice_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = valid_file();
    write_dir(dir.path(), &f);
    // The same file under another spelling of its path.
    f.images[1].file = "./images/m0.png".into();
    Session::write_file(dir.path(), &f).unwrap();
    let errs = Session::load(dir.path()).unwrap_err();
    assert!(errs.has_field("images[1].file"), "{errs}");
    assert!(
        errs.to_string().contains("same file as images[0]"),
        "{errs}"
    );
    // A copy under another name.
    f.images[1].file = "images/m0-copy.png".into();
    std::fs::copy(
        dir.path().join("images/m0.png"),
        dir.path().join("images/m0-copy.png"),
    )
    .unwrap();
    Session::write_file(dir.path(), &f).unwrap();
    let errs = Session::load(dir.path()).unwrap_err();
    assert!(errs.has_field("images[1].file"), "{errs}");
    assert!(
        errs.to_string().contains("same contents as images[0]"),
        "{errs}"
    );
}

#[test]
fn targets_and_flash_are_needed_only_when_a_stage_needs_them() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = valid_file();
    for im in &mut f.images {
        im.world_from_camera = Some(Pose::IDENTITY);
    }
    f.known.light_position_m = Some(DVec3::new(0.0, -1.0, 0.5));
    f.known.stationary_sample = true;
    f.targets = TargetLayouts::default();
    f.flash = FlashSpec::default();
    write_dir(dir.path(), &f);
    let text = std::fs::read_to_string(dir.path().join("session.toml")).unwrap();
    assert!(
        !text.contains("[targets]") && !text.contains("[flash]"),
        "{text}"
    );
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.file, f);

    // Without the light position, [flash] is needed again, with the reason.
    let mut t = table(&f);
    sub(&mut t, &["known"]).remove("light_position_m");
    let errs = load_text(dir.path(), &t).unwrap_err();
    assert!(errs.has_field("flash"), "{errs}");
    assert!(errs.to_string().contains("light_position_m"), "{errs}");
    // One camera pose unknown: [targets] is needed.
    let mut g = f.clone();
    g.images[2].world_from_camera = None;
    let errs = load_text(dir.path(), &table(&g)).unwrap_err();
    assert!(errs.has_field("targets"), "{errs}");
    assert!(errs.to_string().contains("images[2]"), "{errs}");
}

#[test]
fn unusable_photographs_are_errors_or_listed_skips() {
    let dir = tempfile::tempdir().unwrap();
    let f = valid_file();
    write_dir(dir.path(), &f);
    // A truncated PNG: the header still reads, the pixel data ends early.
    let mut big = vec![0u16; (3 * W * H) as usize];
    for (i, v) in big.iter_mut().enumerate() {
        *v = (i as u16).wrapping_mul(7919);
    }
    let m1 = dir.path().join("images/m1.png");
    write_png_rgb16(&m1, W, H, &big).unwrap();
    let bytes = std::fs::read(&m1).unwrap();
    std::fs::write(&m1, &bytes[..bytes.len() / 2]).unwrap();

    let mut s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    let errs = s.check_images(BadImagePolicy::Fail).unwrap_err();
    assert_eq!(errs.len(), 1, "{errs}");
    assert!(errs.problems[0].file.ends_with("images/m1.png"), "{errs}");
    assert!(errs.to_string().contains("cannot be decoded"), "{errs}");
    assert_eq!(s.file.images.len(), 4, "Fail leaves the session as it was");

    s.check_images(BadImagePolicy::Skip).unwrap();
    assert_eq!(s.file.images.len(), 3);
    assert_eq!(s.skipped_images.len(), 1);
    let skip = &s.skipped_images[0];
    assert_eq!((skip.index, skip.file.as_str()), (1, "images/m1.png"));
    assert!(skip.cause.contains("cannot be decoded"), "{}", skip.cause);

    // Skipping the only reference-standard image leaves the session without what it needs.
    std::fs::write(dir.path().join("images/s0.png"), &bytes[..bytes.len() / 3]).unwrap();
    let mut s = Session::load(dir.path()).unwrap();
    let errs = s.check_images(BadImagePolicy::Skip).unwrap_err();
    assert!(errs.to_string().contains("reference-standard"), "{errs}");
}

#[test]
fn a_float_image_with_an_inf_patch_is_implausible() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = valid_file();
    for (i, im) in f.images.iter_mut().enumerate() {
        im.file = im.file.replace(".png", ".exr");
        let mut px = vec![0.25f32; (3 * W * H) as usize];
        px[0] = i as f32;
        if i == 2 {
            for v in &mut px[30..42] {
                *v = f32::INFINITY;
            }
        }
        write_exr_rgb32f(&dir.path().join(&im.file), W, H, &px).unwrap();
    }
    Session::write_file(dir.path(), &f).unwrap();
    let mut s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    let errs = s.check_images(BadImagePolicy::Fail).unwrap_err();
    assert!(errs.problems[0].file.ends_with("images/l0.exr"), "{errs}");
    assert!(errs.to_string().contains("non-finite"), "{errs}");
}

#[test]
fn a_capture_record_larger_than_its_limit_is_refused_unread() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = valid_file();
    f.capture = Some("capture.json".into());
    write_dir(dir.path(), &f);
    // A sparse file one byte above the limit: refused by its length, never read into memory.
    let big = std::fs::File::create(dir.path().join("capture.json")).unwrap();
    big.set_len(skinbrdf_core::untrusted::CAPTURE_RECORD.max_bytes + 1)
        .unwrap();
    let errs = Session::load(dir.path()).unwrap_err();
    let t = errs.to_string();
    assert!(
        t.contains("capture.json") && t.contains("capture record"),
        "{t}"
    );
}
