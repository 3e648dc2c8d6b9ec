//! What turns millimetres into pixels: the focal-plane resolution (each unit), the 35 mm
//! equivalent focal length and a DNG's sizes, written by our DNG writer and read back by our
//! reader; the TIFF/EP spelling of the tags; values read as written, never refusing the file;
//! and exiftool reading the same tags from our DNG (when exiftool is installed; under `CI` it
//! must be).
#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

use std::path::Path;
use std::process::Command;

use skinbrdf_raw::dng::{directory, write_dng, DngImage, FocalPlaneResolution, FocalPlaneUnit};
use skinbrdf_raw::tiff::{encode, Directory, TagValue};
use skinbrdf_raw::{focal_plane_unit_mm, read_metadata, BayerPhase, ExposureMeta};

/// Relative agreement of a value and its rational's quotient (32-bit continued fractions).
const RATIONAL_REL: f64 = 1e-9;

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= RATIONAL_REL * a.abs().max(b.abs())
}

/// A 16 x 12 sensor (active area 12 x 8 inside a 2-photosite border) of 5.95 um photosites
/// behind an 84 mm lens, as the synthetic studio writes it.
fn studio_like(unit: FocalPlaneUnit) -> DngImage {
    let mut img = DngImage::new(16, 12, BayerPhase::Rggb, 16, vec![512; 16 * 12]);
    img.active_area = Some([2, 2, 10, 14]);
    img.focal_length_mm = Some(84.0);
    img.focal_plane_resolution = Some(FocalPlaneResolution::from_pitch_mm(0.00595, unit));
    img.focal_length_35mm_mm = Some(128);
    img
}

#[test]
fn the_unit_table_is_exifs() {
    assert_eq!(focal_plane_unit_mm(None), Some(25.4)); // EXIF's default: inch
    assert_eq!(focal_plane_unit_mm(Some(1)), Some(25.4)); // "no unit": inch, as exiftool
    assert_eq!(focal_plane_unit_mm(Some(2)), Some(25.4));
    assert_eq!(focal_plane_unit_mm(Some(3)), Some(10.0));
    assert_eq!(focal_plane_unit_mm(Some(4)), Some(1.0));
    assert_eq!(focal_plane_unit_mm(Some(5)), Some(0.001));
    for u in [0, 6, 65535] {
        assert_eq!(focal_plane_unit_mm(Some(u)), None, "{u}");
    }
    for unit in [
        FocalPlaneUnit::Inch,
        FocalPlaneUnit::Centimetre,
        FocalPlaneUnit::Millimetre,
        FocalPlaneUnit::Micrometre,
    ] {
        assert_eq!(focal_plane_unit_mm(Some(unit.code())), Some(unit.mm()));
    }
}

#[test]
fn focal_plane_tags_round_trip_through_our_dng_in_every_unit() {
    let dir = tempfile::tempdir().unwrap();
    let px_per_mm = 1.0 / 0.00595;
    for unit in [
        FocalPlaneUnit::Inch,
        FocalPlaneUnit::Centimetre,
        FocalPlaneUnit::Millimetre,
        FocalPlaneUnit::Micrometre,
    ] {
        let path = dir.path().join(format!("unit{}.dng", unit.code()));
        let img = studio_like(unit);
        write_dng(&path, &img).unwrap();
        let m = read_metadata(&path).unwrap();
        let r = img.focal_plane_resolution.unwrap();
        // Each unit's number is its own: 4268.9 px/in, 1680.7 px/cm, 168.07 px/mm, 0.168 px/um.
        assert!(
            close(r.x_px_per_unit * unit.mm().recip(), px_per_mm),
            "{unit:?}"
        );
        assert_eq!(m.focal_plane_resolution_unit, Some(unit.code()));
        let x = m.focal_plane_px_per_mm_x.unwrap();
        let y = m.focal_plane_px_per_mm_y.unwrap();
        assert!(close(x, px_per_mm), "{unit:?}: {x} px/mm");
        assert!(close(y, px_per_mm), "{unit:?}: {y} px/mm");
        assert_eq!(m.focal_length_35mm_mm, Some(128.0));
        assert_eq!(m.focal_length_mm, Some(84.0));
        // The raw directory's full size, masked border included.
        assert_eq!(m.sensor_size_px, Some((16, 12)));
        assert_eq!(m.default_crop_size_px, None);
    }
    // Nothing written, nothing read.
    let bare = dir.path().join("bare.dng");
    write_dng(
        &bare,
        &DngImage::new(4, 4, BayerPhase::Rggb, 16, vec![0; 16]),
    )
    .unwrap();
    let m = read_metadata(&bare).unwrap();
    assert_eq!(m.focal_plane_px_per_mm_x, None);
    assert_eq!(m.focal_plane_px_per_mm_y, None);
    assert_eq!(m.focal_plane_resolution_unit, None);
    assert_eq!(m.focal_length_35mm_mm, None);
    assert_eq!(m.sensor_size_px, Some((4, 4)));
}

/// Our DNG with its directory altered (tags only a real camera's files have).
fn altered(path: &Path, img: &DngImage, alter: impl FnOnce(&mut Directory)) -> ExposureMeta {
    let mut d = directory(path, img).unwrap();
    alter(&mut d);
    std::fs::write(path, encode(&d)).unwrap();
    read_metadata(path).unwrap()
}

fn exif(d: &mut Directory) -> &mut Directory {
    &mut d.subs.iter_mut().find(|(t, _)| *t == 0x8769).unwrap().1
}

#[test]
fn dng_crop_tiff_ep_tags_and_odd_values_are_read_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.dng");
    let img = DngImage::new(16, 12, BayerPhase::Rggb, 16, vec![512; 16 * 12]);

    // DNG `DefaultCropSize` as RATIONAL and as LONG.
    let m = altered(&path, &img, |d| {
        d.set(50720, TagValue::Rational(vec![(23, 2), (8, 1)]));
    });
    assert_eq!(m.default_crop_size_px, Some((11.5, 8.0)));
    let m = altered(&path, &img, |d| {
        d.set(50720, TagValue::Long(vec![12, 8]));
    });
    assert_eq!(m.default_crop_size_px, Some((12.0, 8.0)));

    // TIFF/EP's tags in the root directory (0x920E-0x9210), centimetres; no unit: inches.
    let m = altered(&path, &img, |d| {
        d.set(0x920e, TagValue::Rational(vec![(16807, 10)]));
        d.set(0x920f, TagValue::Rational(vec![(16807, 10)]));
        d.set(0x9210, TagValue::Short(vec![3]));
    });
    assert_eq!(m.focal_plane_resolution_unit, Some(3));
    assert!(close(m.focal_plane_px_per_mm_x.unwrap(), 168.07));
    let m = altered(&path, &img, |d| {
        exif(d).set(0xa20e, TagValue::Rational(vec![(254, 1)]));
    });
    assert_eq!(m.focal_plane_resolution_unit, None);
    assert!(close(m.focal_plane_px_per_mm_x.unwrap(), 10.0));
    assert_eq!(m.focal_plane_px_per_mm_y, None);
    // EXIF's tags win over TIFF/EP's, each with its own unit.
    let m = altered(&path, &img, |d| {
        d.set(0x920e, TagValue::Rational(vec![(1, 1)]));
        d.set(0x9210, TagValue::Short(vec![4]));
        exif(d).set(0xa20e, TagValue::Rational(vec![(50, 1)]));
        exif(d).set(0xa210, TagValue::Short(vec![3]));
    });
    assert_eq!(m.focal_plane_resolution_unit, Some(3));
    assert!(close(m.focal_plane_px_per_mm_x.unwrap(), 5.0));

    // A unit EXIF does not define: no resolution, the unit kept for the reason.
    let m = altered(&path, &img, |d| {
        exif(d).set(0xa20e, TagValue::Rational(vec![(50, 1)]));
        exif(d).set(0xa210, TagValue::Short(vec![9]));
    });
    assert_eq!(m.focal_plane_resolution_unit, Some(9));
    assert_eq!(m.focal_plane_px_per_mm_x, None);
    // A zero denominator is kept as the division gives it (the guess refuses it; the file is
    // not refused for a tag that only feeds a guess).
    let m = altered(&path, &img, |d| {
        exif(d).set(0xa20e, TagValue::Rational(vec![(50, 0)]));
        exif(d).set(0xa20f, TagValue::Rational(vec![(0, 0)]));
        exif(d).set(0xa210, TagValue::Short(vec![4]));
    });
    assert_eq!(m.focal_plane_px_per_mm_x, Some(f64::INFINITY));
    assert!(m.focal_plane_px_per_mm_y.unwrap().is_nan());
    // `FocalLengthIn35mmFilm` 0 is EXIF's "unknown".
    let m = altered(&path, &img, |d| {
        exif(d).set(0xa405, TagValue::Short(vec![0]));
    });
    assert_eq!(m.focal_length_35mm_mm, None);
}

#[test]
fn the_writer_refuses_nonsense_focal_plane_values() {
    let mut img = studio_like(FocalPlaneUnit::Inch);
    img.focal_plane_resolution = Some(FocalPlaneResolution {
        x_px_per_unit: f64::NAN,
        y_px_per_unit: -1.0,
        unit: FocalPlaneUnit::Inch,
    });
    img.focal_length_35mm_mm = Some(0);
    let err = skinbrdf_raw::dng::encode_dng(Path::new("f.dng"), &img)
        .unwrap_err()
        .to_string();
    for w in ["x_px_per_unit", "y_px_per_unit", "focal_length_35mm_mm"] {
        assert!(err.contains(w), "{w}: {err}");
    }
}

/// exiftool's `-s -n` lines (`Name: value`) for `tags` of `path`; `None` without exiftool.
fn exiftool(path: &Path, tags: &[&str]) -> Option<Vec<(String, String)>> {
    let mut cmd = Command::new("exiftool");
    cmd.args(["-s", "-n"]);
    for t in tags {
        cmd.arg(format!("-{t}"));
    }
    let out = cmd.arg(path).output().ok()?;
    assert!(
        out.status.success(),
        "exiftool failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| {
                let (k, v) = l.split_once(':')?;
                Some((k.trim().to_string(), v.trim().to_string()))
            })
            .collect(),
    )
}

#[test]
fn exiftool_reads_the_focal_plane_tags_we_write() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("SKB_0001.DNG");
    let img = studio_like(FocalPlaneUnit::Inch);
    write_dng(&path, &img).unwrap();
    let tags = [
        "FocalPlaneXResolution",
        "FocalPlaneYResolution",
        "FocalPlaneResolutionUnit",
        "FocalLengthIn35mmFormat",
        "FocalLength",
    ];
    let Some(lines) = exiftool(&path, &tags) else {
        if std::env::var_os("CI").is_some() {
            panic!(
                "exiftool is not installed and CI is set: the parity test must run in CI \
                 (apt-get install libimage-exiftool-perl)"
            );
        }
        eprintln!(
            "SKIPPED exiftool_reads_the_focal_plane_tags_we_write: exiftool is not installed \
             (apt-get install libimage-exiftool-perl); set CI to make this a failure"
        );
        return;
    };
    let value = |name: &str| -> f64 {
        let v = lines
            .iter()
            .find(|(k, _)| k == name)
            .unwrap_or_else(|| panic!("exiftool gives no {name}: {lines:?}"));
        v.1.parse()
            .unwrap_or_else(|_| panic!("{name} = {:?} is not a number", v.1))
    };
    let ours = read_metadata(&path).unwrap();
    // exiftool prints rationals to about 10 significant digits.
    let near = |a: f64, b: f64| (a - b).abs() <= 1e-8 * a.abs().max(b.abs());
    let unit = value("FocalPlaneResolutionUnit");
    assert_eq!(unit, 2.0);
    assert_eq!(Some(unit as u16), ours.focal_plane_resolution_unit);
    let mm = focal_plane_unit_mm(Some(unit as u16)).unwrap();
    let x = value("FocalPlaneXResolution");
    let y = value("FocalPlaneYResolution");
    assert!(
        near(x / mm, ours.focal_plane_px_per_mm_x.unwrap()),
        "{x} px/in"
    );
    assert!(
        near(y / mm, ours.focal_plane_px_per_mm_y.unwrap()),
        "{y} px/in"
    );
    assert!(
        near(x, img.focal_plane_resolution.unwrap().x_px_per_unit),
        "{x}"
    );
    assert_eq!(
        Some(value("FocalLengthIn35mmFormat")),
        ours.focal_length_35mm_mm
    );
    assert_eq!(Some(value("FocalLength")), ours.focal_length_mm);
}
