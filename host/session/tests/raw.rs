//! Sessions whose images are camera raw files (DNG): they load without `[linearization]`, pass
//! the image check, and give the same values as 16-bit PNGs of the same linear data.
#![allow(clippy::unwrap_used)] // test helpers

use std::path::Path;

use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_raw::dng::{write_dng, DngImage};
use skinbrdf_raw::BayerPhase;
use skinbrdf_session::write::write_png_rgb16;
use skinbrdf_session::*;

mod common;

/// The decoder's `f32` value against the same black/white scaling done in `f64`.
const F32_DECODE_TOL: f64 = 1e-6;

/// Superpixel image size.
const W: u32 = 10;
const H: u32 = 8;
const BLACK: u16 = 512;
const WHITE: u16 = 16_383;
/// A DNG and a PNG of the same value differ by at most half a 14-bit step (over the range
/// `WHITE - BLACK`) plus half a 16-bit step, plus the f32 rounding of both.
const QUANT_TOL: f32 = 0.5 / (WHITE - BLACK) as f32 + 0.5 / 65_535.0 + 1e-6;

/// The session of four `ext` images of a W x H (superpixel) camera, the standard's pose known.
fn session_file(ext: &str) -> SessionFile {
    let mut f = common::session_file(W, H, ext);
    f.description = "raw test".into();
    f.known.world_from_standard = Some(Pose::IDENTITY);
    f
}

/// Linear RGB of image `i` at superpixel (u, v), in [0, 1].
fn value(i: usize, u: u32, v: u32) -> [f64; 3] {
    let t = (u as f64 + 0.37 * v as f64 + 0.11 * i as f64) / 14.0;
    [0.05 + 0.8 * t, 0.02 + 0.5 * t * t, 0.9 - 0.6 * t]
}

/// Writes the session with DNG images (phase GBRG at an odd active-area offset) or PNGs.
fn write_session(dir: &Path, ext: &str, edit: impl FnOnce(&mut SessionFile)) -> SessionFile {
    let mut f = session_file(ext);
    edit(&mut f);
    let (left, top) = (1u32, 3u32);
    let (sw, sh) = (2 * W + left + 3, 2 * H + top + 1);
    let phase = BayerPhase::Gbrg;
    for (i, im) in f.images.iter().enumerate() {
        let path = dir.join(&im.file);
        if ext == "png" {
            let px: Vec<u16> = (0..H)
                .flat_map(|v| (0..W).flat_map(move |u| value(i, u, v)))
                .map(|c| (c * 65_535.0).round() as u16)
                .collect();
            write_png_rgb16(&path, W, H, &px).unwrap();
            continue;
        }
        let mut data = vec![BLACK; (sw * sh) as usize];
        for v in 0..H {
            for u in 0..W {
                let rgb = value(i, u, v);
                for k in 0..4 {
                    let (x, y) = (left + 2 * u + k % 2, top + 2 * v + k / 2);
                    let c = match phase.colour_at(k as usize % 2, k as usize / 2) {
                        skinbrdf_raw::CfaColour::Red => rgb[0],
                        skinbrdf_raw::CfaColour::Green => rgb[1],
                        skinbrdf_raw::CfaColour::Blue => rgb[2],
                    };
                    data[(y * sw + x) as usize] =
                        (f64::from(BLACK) + c * f64::from(WHITE - BLACK)).round() as u16;
                }
            }
        }
        let mut img = DngImage::new(sw, sh, phase, 14, data);
        img.active_area = Some([top, left, top + 2 * H, left + 2 * W]);
        img.black_levels = [BLACK; 4];
        img.white_level = WHITE;
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        write_dng(&path, &img).unwrap();
    }
    Session::write_file(dir, &f).unwrap();
    // A raw session needs no [linearization]: take it out of the file.
    let toml_path = dir.join(SESSION_FILE);
    let mut table: toml::Table = std::fs::read_to_string(&toml_path)
        .unwrap()
        .parse()
        .unwrap();
    if ext != "png" {
        table.remove("linearization");
    }
    std::fs::write(&toml_path, toml::to_string(&table).unwrap()).unwrap();
    f
}

#[test]
fn a_dng_session_loads_and_matches_its_png_twin() {
    let raw_dir = tempfile::tempdir().unwrap();
    let png_dir = tempfile::tempdir().unwrap();
    write_session(raw_dir.path(), "dng", |_| {});
    write_session(png_dir.path(), "png", |_| {});
    let mut raw = Session::load(raw_dir.path()).unwrap_or_else(|e| panic!("{e}"));
    let png = Session::load(png_dir.path()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(raw.linearization_source, LinearizationSource::Unused);
    let needs = SectionNeeds::of(&raw.file.images, &raw.file.known, Some(&raw.file.camera));
    assert_eq!(needs.linearization, None);
    raw.check_images(BadImagePolicy::Fail)
        .unwrap_or_else(|e| panic!("{e}"));
    let hd = read_header(&raw.path(&raw.file.images[0].file)).unwrap();
    assert_eq!(
        (hd.width, hd.height, hd.format),
        (W, H, StoredFormat::Raw { bits: 14 })
    );
    // Photosites (the default): each its own channel, the camera the photosite image's.
    assert_eq!(raw.raw_mode(), RawMode::Photosite);
    assert_eq!(raw.file.camera.size_px(), (2 * W, 2 * H));
    let stated = CameraModel::from_fov(W, H, 0.8);
    let model = *raw.file.camera.model().unwrap();
    assert_eq!(
        (model.fx_px, model.cx_px, model.cy_px),
        (
            2.0 * stated.fx_px,
            2.0 * stated.cx_px + 0.5,
            2.0 * stated.cy_px + 0.5
        )
    );
    for i in 0..4 {
        let a = raw.load_image(i).unwrap();
        let b = png.load_image(i).unwrap();
        assert_eq!(
            (a.width, a.height, a.cfa),
            (2 * W, 2 * H, Some(BayerPhase::Gbrg))
        );
        for y in 0..2 * H {
            for x in 0..2 * W {
                let p = a.rgb[(y * 2 * W + x) as usize];
                let q = b.rgb[(y / 2 * W + x / 2) as usize];
                let measured = a.measured_channels(x, y);
                assert_eq!(measured.iter().filter(|m| **m).count(), 1);
                for c in 0..3 {
                    if measured[c] {
                        assert!(
                            (p[c] - q[c]).abs() <= QUANT_TOL,
                            "image {i}: {p:?} vs {q:?}"
                        );
                    } else {
                        assert!(p[c].is_nan(), "image {i}: {p:?}");
                    }
                }
            }
        }
        // Detection's image: green, here the same in every photosite of a quad.
        let grey = a.geometry_grey();
        for (k, g) in grey.iter().enumerate() {
            let (x, y) = (k as u32 % (2 * W), k as u32 / (2 * W));
            let q = b.rgb[(y / 2 * W + x / 2) as usize][1];
            // Interpolated at red and blue from the neighbouring quads' greens.
            let neighbours_tol = 0.5 / 14.0 * 0.5 * 2.0 + QUANT_TOL;
            assert!((g - q).abs() <= neighbours_tol, "({x}, {y}): {g} vs {q}");
        }
        assert!(a.saturated.iter().all(|s| !s));
    }
    // Superpixels: the PNG twin's values and size; the camera as stated.
    raw.set_raw_mode(RawMode::Superpixel);
    assert_eq!(*raw.file.camera.model().unwrap(), stated);
    for i in 0..4 {
        let a = raw.load_image(i).unwrap();
        let b = png.load_image(i).unwrap();
        assert_eq!((a.width, a.height, a.cfa), (W, H, None));
        assert_eq!(a.format, StoredFormat::Raw { bits: 14 });
        for (p, q) in a.rgb.iter().zip(&b.rgb) {
            for c in 0..3 {
                assert!(
                    (p[c] - q[c]).abs() <= QUANT_TOL,
                    "image {i}: {p:?} vs {q:?}"
                );
            }
        }
        assert!(a.saturated.iter().all(|s| !s));
    }
}

#[test]
fn exposure_scale_multiplies_v_and_is_validated() {
    let dir = tempfile::tempdir().unwrap();
    write_session(dir.path(), "dng", |f| {
        f.images[1].exposure_scale = Some(2.0)
    });
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    let a = s.load_image(1).unwrap();
    let plain = load_linear_image(
        &s.path(&s.file.images[1].file),
        s.linearization(1),
        s.raw_mode(),
    )
    .unwrap();
    for (p, q) in a.rgb.iter().zip(&plain.rgb) {
        for c in 0..3 {
            assert!(p[c] == 2.0 * q[c] || (p[c].is_nan() && q[c].is_nan()));
        }
    }
    let bad = tempfile::tempdir().unwrap();
    write_session(bad.path(), "dng", |f| {
        f.images[0].exposure_scale = Some(-1.0);
        f.images[2].exposure_scale = Some(f64::INFINITY);
    });
    let errs = Session::load(bad.path()).unwrap_err();
    assert!(errs.has_field("images[0].exposure_scale"), "{errs}");
    assert!(errs.has_field("images[2].exposure_scale"), "{errs}");
}

#[test]
fn raw_level_overrides_and_their_refusals() {
    // An override with white_level replaces the file's levels.
    let dir = tempfile::tempdir().unwrap();
    write_session(dir.path(), "dng", |f| {
        f.images[0].linearization = Some(Linearization {
            black_level: 0.0,
            white_level: Some(f64::from(WHITE)),
            ..Linearization::LINEAR
        });
    });
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    let img = s.load_image(0).unwrap();
    let rgb = value(0, 0, 0);
    let g = (f64::from(BLACK) + rgb[1] * f64::from(WHITE - BLACK)).round() / f64::from(WHITE);
    assert!(
        (f64::from(img.rgb[0][1]) - g).abs() < F32_DECODE_TOL,
        "{:?}",
        img.rgb[0]
    );

    // Other curves, saturation levels and a lone black level are refused, naming the field.
    let bad = tempfile::tempdir().unwrap();
    write_session(bad.path(), "dng", |f| {
        f.images[0].linearization = Some(Linearization {
            curve: ToneCurve::Srgb,
            ..Linearization::LINEAR
        });
        f.images[1].linearization = Some(Linearization {
            black_level: 100.0,
            ..Linearization::LINEAR
        });
        f.images[2].linearization = Some(Linearization {
            white_level: Some(9000.0),
            saturation_level: Some(8000.0),
            ..Linearization::LINEAR
        });
    });
    let errs = Session::load(bad.path()).unwrap_err();
    assert!(errs.has_field("images[0].linearization.curve"), "{errs}");
    assert!(
        errs.has_field("images[1].linearization.black_level"),
        "{errs}"
    );
    assert!(
        errs.has_field("images[2].linearization.saturation_level"),
        "{errs}"
    );
}

#[test]
fn size_and_extension_problems_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    write_session(dir.path(), "dng", |f| {
        f.camera = CameraSpec::Calibrated(CameraModel::from_fov(2 * W, 2 * H, 0.8));
    });
    let errs = Session::load(dir.path()).unwrap_err().to_string();
    assert!(
        errs.contains("images/m0.dng") && errs.contains("is 10x8 px but the camera is 20x16 px"),
        "{errs}"
    );

    // A DNG named .png, a PNG named .dng.
    let dir = tempfile::tempdir().unwrap();
    write_session(dir.path(), "dng", |_| {});
    let images = dir.path().join("images");
    std::fs::rename(images.join("m0.dng"), images.join("m0x.png")).unwrap();
    write_png_rgb16(
        &images.join("m1x.dng"),
        W,
        H,
        &vec![1000; (3 * W * H) as usize],
    )
    .unwrap();
    let text = std::fs::read_to_string(dir.path().join(SESSION_FILE))
        .unwrap()
        .replace("images/m0.dng", "images/m0x.png")
        .replace("images/m1.dng", "images/m1x.dng")
        // The .png name asks for a [linearization].
        + "\n[linearization]\ncurve = \"linear\"\n";
    std::fs::write(dir.path().join(SESSION_FILE), text).unwrap();
    let errs = Session::load(dir.path()).unwrap_err().to_string();
    assert!(
        errs.contains("m0x.png: the file is DNG but its name says PNG"),
        "{errs}"
    );
    assert!(
        errs.contains("m1x.dng: the file is PNG but its name says DNG"),
        "{errs}"
    );
}

/// Bits of an image's values and saturation, NaN-aware, for exact comparisons.
fn bits(img: &LinearImage) -> (Vec<[u32; 3]>, Vec<bool>) {
    (
        img.rgb.iter().map(|p| p.map(f32::to_bits)).collect(),
        img.saturated.clone(),
    )
}

#[test]
fn a_session_keeping_decoded_files_gives_the_same_values_and_decodes_each_once() {
    let dir = tempfile::tempdir().unwrap();
    write_session(dir.path(), "dng", |f| {
        f.images[1].exposure_scale = Some(2.0);
        f.images[2].linearization = Some(Linearization {
            black_level: 0.0,
            white_level: Some(f64::from(WHITE)),
            ..Linearization::LINEAR
        });
    });
    let out = tempfile::tempdir().unwrap();
    for mode in RawMode::ALL {
        let mut plain = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
        plain.set_raw_mode(mode);
        let mut kept = plain.clone();
        let cache_dir = out.path().join(mode.name()).join("decoded");
        kept.keep_decoded(DecodeCache::new(&cache_dir));
        kept.check_images(BadImagePolicy::Fail)
            .unwrap_or_else(|e| panic!("{e}"));
        let n = kept.file.images.len();
        let cache = kept.decode_cache().expect("kept");
        assert_eq!(cache.len(), n, "the input check decoded every file");
        for i in 0..n {
            let a = plain.load_image(i).unwrap();
            let b = kept.load_image(i).unwrap();
            assert_eq!(bits(&a), bits(&b), "{mode} image {i}");
            let grey = a.geometry_grey();
            for g in [
                plain.load_geometry_grey(i).unwrap(),
                kept.load_geometry_grey(i).unwrap(),
            ] {
                assert_eq!((g.width, g.height), (a.width, a.height));
                let same = g
                    .data
                    .iter()
                    .zip(&grey)
                    .all(|(x, y)| x.to_bits() == y.to_bits());
                assert!(same, "{mode} image {i}: the grey image differs");
            }
        }
        assert_eq!(
            cache.len(),
            n,
            "the later loads read the decoded files back"
        );
        drop(kept);
        assert!(!cache_dir.exists(), "the cache's files go with it");
    }
}

#[test]
fn the_input_check_refuses_a_black_raw_file_per_photosite_and_per_superpixel() {
    let dir = tempfile::tempdir().unwrap();
    write_session(dir.path(), "dng", |_| {});
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    // Image 1 black: every photosite at the black level.
    let path = s.path(&s.file.images[1].file);
    let (sw, sh) = (2 * W + 4, 2 * H + 4);
    let mut img = DngImage::new(
        sw,
        sh,
        BayerPhase::Gbrg,
        14,
        vec![BLACK; (sw * sh) as usize],
    );
    img.active_area = Some([3, 1, 3 + 2 * H, 1 + 2 * W]);
    img.black_levels = [BLACK; 4];
    img.white_level = WHITE;
    write_dng(&path, &img).unwrap();
    let out = tempfile::tempdir().unwrap();
    for (mode, cached) in RawMode::ALL
        .into_iter()
        .flat_map(|m| [(m, false), (m, true)])
    {
        let mut s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
        s.set_raw_mode(mode);
        if cached {
            s.keep_decoded(DecodeCache::new(out.path().join("decoded")));
        }
        let msg = s
            .check_images(BadImagePolicy::Fail)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains(&s.file.images[1].file)
                && msg.contains("no stored value is above the black level (0)"),
            "{mode}, cached {cached}: {msg}"
        );
    }
}
