//! Write DNGs with every Bayer phase, bit depth and active-area offset, decode them back, and
//! check the photosites, superpixels, saturation, levels and metadata exactly; refusals name the file.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

use std::path::Path;

use proptest::prelude::*;
use skinbrdf_raw::dng::{write_dng, DngImage};
use skinbrdf_raw::{
    check_extension, decode_photosites, decode_superpixel, read_metadata, read_raw_header, sniff,
    BayerPhase, CaptureTime, FileKind, LocalDateTime, RawError, RawLayout, RawOptions,
};

/// A sensor with the given active area and margins whose width packs into whole bytes.
struct Layout {
    phase: BayerPhase,
    bits: u32,
    left: u32,
    top: u32,
    active_w: u32,
    active_h: u32,
    right: u32,
    bottom: u32,
}

impl Layout {
    fn sensor(&self) -> (u32, u32) {
        let mut w = self.left + self.active_w + self.right;
        while !(w * self.bits).is_multiple_of(8) {
            w += 1;
        }
        (w, self.top + self.active_h + self.bottom)
    }
}

fn image(l: &Layout, data: Vec<u16>, black: [u16; 4], white: u16) -> DngImage {
    let (w, h) = l.sensor();
    let mut img = DngImage::new(w, h, l.phase, l.bits, data);
    img.active_area = Some([l.top, l.left, l.top + l.active_h, l.left + l.active_w]);
    img.black_levels = black;
    img.white_level = white;
    img
}

/// The superpixel the crate documents: R, mean(G1, G2), B of the quad at (2u, 2v) of the
/// active area, each `(raw - black_c) / (white - black_c)`, computed the same way in f64.
fn expected(l: &Layout, data: &[u16], black: [f64; 4], white: f64) -> (Vec<[f32; 3]>, Vec<bool>) {
    let (sw, _) = l.sensor();
    let [pr, pg1, pg2, pb] = l.phase.positions();
    let scale = black.map(|b| 1.0 / (white - b));
    let mut rgb = Vec::new();
    let mut sat = Vec::new();
    for v in 0..l.active_h / 2 {
        for u in 0..l.active_w / 2 {
            let (x, y) = ((l.left + 2 * u) as usize, (l.top + 2 * v) as usize);
            let sw = sw as usize;
            let q = [
                data[y * sw + x],
                data[y * sw + x + 1],
                data[(y + 1) * sw + x],
                data[(y + 1) * sw + x + 1],
            ]
            .map(f64::from);
            let n = |k: usize| (q[k] - black[k]) * scale[k];
            rgb.push([n(pr) as f32, (0.5 * (n(pg1) + n(pg2))) as f32, n(pb) as f32]);
            sat.push(q.iter().any(|&r| r >= white));
        }
    }
    (rgb, sat)
}

/// The photosites the crate documents: photosite (x, y) of the even part of the active area
/// with its own channel `(raw - black_c) / (white - black_c)`, the others NaN.
fn expected_photosites(
    l: &Layout,
    data: &[u16],
    black: [f64; 4],
    white: f64,
) -> (Vec<[f32; 3]>, Vec<bool>) {
    let (sw, _) = l.sensor();
    let mut rgb = Vec::new();
    let mut sat = Vec::new();
    for y in 0..l.active_h / 2 * 2 {
        for x in 0..l.active_w / 2 * 2 {
            let raw = f64::from(data[((l.top + y) * sw + l.left + x) as usize]);
            let k = (y % 2 * 2 + x % 2) as usize;
            let mut px = [f32::NAN; 3];
            let c = usize::from(l.phase.colour_at(x as usize, y as usize).dng_code());
            px[c] = ((raw - black[k]) * (1.0 / (white - black[k]))) as f32;
            rgb.push(px);
            sat.push(raw >= white);
        }
    }
    (rgb, sat)
}

fn phase() -> impl Strategy<Value = BayerPhase> {
    prop::sample::select(BayerPhase::ALL.to_vec())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Every phase, depth and active-area offset (odd ones included) decodes exactly.
    #[test]
    fn superpixels_round_trip(
        phase in phase(),
        bits in prop::sample::select(vec![12u32, 14, 16]),
        left in 0u32..4, top in 0u32..4, right in 0u32..3, bottom in 0u32..3,
        half_w in 1u32..7, half_h in 1u32..6, odd_w in 0u32..2, odd_h in 0u32..2,
        seed in any::<u64>(),
    ) {
        let l = Layout { phase, bits, left, top, active_w: 2 * half_w + odd_w, active_h: 2 * half_h + odd_h, right, bottom };
        let (sw, sh) = l.sensor();
        let max = (1u32 << bits) - 1;
        let white = (max - (seed % 97) as u32) as u16;
        let black = [0, 1, 2, 3].map(|k| ((seed >> (8 * k)) % 600) as u16);
        // Values span below black to above white, hitting white exactly now and then.
        let mut s = seed | 1;
        let data: Vec<u16> = (0..sw * sh)
            .map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17;
                match s % 11 { 0 => white, 1 => max as u16, _ => (s % u64::from(max + 1)) as u16 }
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.dng");
        write_dng(&path, &image(&l, data.clone(), black, white)).unwrap();
        prop_assert_eq!(sniff(&path).unwrap(), FileKind::Dng);
        let f = decode_superpixel(&path, &RawOptions::default()).unwrap();
        prop_assert_eq!(f.cfa, phase);
        prop_assert_eq!((f.width_px, f.height_px), (l.active_w / 2, l.active_h / 2));
        prop_assert_eq!((f.sensor_width_px, f.sensor_height_px), (sw, sh));
        prop_assert_eq!((f.active_left_px, f.active_top_px), (left, top));
        prop_assert_eq!(f.bits_per_sample, bits);
        let hd = read_raw_header(&path).unwrap();
        prop_assert_eq!((hd.width_px, hd.height_px, hd.bits_per_sample, hd.cfa), (f.width_px, f.height_px, bits, phase));
        prop_assert_eq!(f.black_levels, black.map(f64::from));
        prop_assert_eq!(f.white_level, f64::from(white));
        let (rgb, sat) = expected(&l, &data, black.map(f64::from), f64::from(white));
        prop_assert_eq!(&f.rgb, &rgb);
        prop_assert_eq!(&f.saturated, &sat);

        // Photosites: each its own channel and level, the others NaN; the quads average them.
        let p = decode_photosites(&path, &RawOptions::default()).unwrap();
        prop_assert_eq!((p.width_px, p.height_px), (2 * f.width_px, 2 * f.height_px));
        prop_assert_eq!(p.layout, RawLayout::Photosite);
        let (rgb, sat) = expected_photosites(&l, &data, black.map(f64::from), f64::from(white));
        prop_assert_eq!(p.rgb.len(), rgb.len());
        for (got, want) in p.rgb.iter().zip(&rgb) {
            prop_assert!(got.iter().zip(want).all(|(a, b)| a == b || (a.is_nan() && b.is_nan())), "{:?} {:?}", got, want);
        }
        prop_assert_eq!(&p.saturated, &sat);
        prop_assert_eq!(hd.size_px(RawLayout::Photosite), (p.width_px, p.height_px));

        // The session's override replaces the file's levels.
        let opts = RawOptions { black_levels: Some([10.0; 4]), white_level: Some(f64::from(white) - 5.0) };
        let g = decode_superpixel(&path, &opts).unwrap();
        let (rgb, sat) = expected(&l, &data, [10.0; 4], f64::from(white) - 5.0);
        prop_assert_eq!(g.rgb, rgb);
        prop_assert_eq!(g.saturated, sat);
    }
}

fn capture_time(s: &str, subsec: Option<&str>, offset: Option<i32>) -> CaptureTime {
    CaptureTime {
        local: LocalDateTime::parse_exif(s).unwrap().unwrap(),
        subsec_digits: subsec.map(str::to_string),
        utc_offset_min: offset,
    }
}

#[test]
fn exif_round_trips_through_dng() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("SKB_0007.DNG");
    let mut img = DngImage::new(8, 6, BayerPhase::Grbg, 14, vec![100; 48]);
    img.make = "Skinbrdf".into();
    img.model = "Studio One".into();
    img.body_serial = Some("SN-004217".into());
    img.lens_make = Some("Optica".into());
    img.lens_model = Some("Macro 100mm F2.8".into());
    img.exposure_time_s = Some(1.0 / 125.0);
    img.f_number = Some(11.0);
    img.iso = Some(100);
    img.focal_length_mm = Some(100.0);
    img.capture_time = Some(capture_time("2025:06:01 14:03:27", Some("045"), Some(60)));
    img.image_number = Some(12_345);
    write_dng(&path, &img).unwrap();
    let m = read_metadata(&path).unwrap();
    assert_eq!(m.camera_make.as_deref(), Some("Skinbrdf"));
    assert_eq!(m.camera_model.as_deref(), Some("Studio One"));
    assert_eq!(m.body_serial.as_deref(), Some("SN-004217"));
    assert_eq!(m.lens_make.as_deref(), Some("Optica"));
    assert_eq!(m.lens_model.as_deref(), Some("Macro 100mm F2.8"));
    assert_eq!(m.exposure_time_s, Some(1.0 / 125.0));
    assert_eq!(m.f_number, Some(11.0));
    assert_eq!(m.iso, Some(100));
    assert_eq!(m.focal_length_mm, Some(100.0));
    assert_eq!(m.image_number, Some(12_345));
    let t = m.capture_time.unwrap();
    assert_eq!(
        t,
        capture_time("2025:06:01 14:03:27", Some("045"), Some(60))
    );
    // 2025-06-01 13:03:27.045 UTC.
    assert_eq!(t.unix_seconds(), Some(1_748_783_007.045));

    // Nothing written, nothing read: missing fields stay `None`.
    let bare = dir.path().join("bare.dng");
    write_dng(
        &bare,
        &DngImage::new(4, 4, BayerPhase::Rggb, 16, vec![0; 16]),
    )
    .unwrap();
    let m = read_metadata(&bare).unwrap();
    assert_eq!(m.exposure_time_s, None);
    assert_eq!(m.f_number, None);
    assert_eq!(m.iso, None);
    assert_eq!(m.focal_length_mm, None);
    assert_eq!(m.capture_time, None);
    assert_eq!(m.image_number, None);
    assert_eq!(m.body_serial, None);
    assert_eq!(m.lens_model, None);
}

#[test]
fn a_truncated_raw_file_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.dng");
    write_dng(
        &path,
        &DngImage::new(64, 32, BayerPhase::Rggb, 12, vec![7; 64 * 32]),
    )
    .unwrap();
    let len = std::fs::metadata(&path).unwrap().len();
    let bytes = std::fs::read(&path).unwrap();
    // The strip is the file's tail: a copy cut short anywhere loses image data or structure.
    for keep in [100, len / 2, len - 1] {
        let short = dir.path().join(format!("short{keep}.dng"));
        std::fs::write(&short, &bytes[..keep as usize]).unwrap();
        let err = decode_superpixel(&short, &RawOptions::default()).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains(&short.display().to_string()), "{msg}");
        // Cut into the image data: the strip's extent is past the end. Cut into the structure:
        // the decoder finds no image.
        if keep >= len / 2 {
            assert!(matches!(err, RawError::Truncated { .. }), "{msg}");
        } else {
            assert!(
                matches!(err, RawError::Truncated { .. } | RawError::Decode { .. }),
                "{msg}"
            );
        }
    }
}

#[test]
fn wrong_extensions_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let dng_as_png = dir.path().join("SKB_0001.PNG");
    write_dng(
        &dng_as_png,
        &DngImage::new(4, 4, BayerPhase::Rggb, 16, vec![0; 16]),
    )
    .unwrap();
    let kind = sniff(&dng_as_png).unwrap();
    assert_eq!(kind, FileKind::Dng);
    let msg = check_extension(&dng_as_png, kind).unwrap_err().to_string();
    assert!(
        msg.contains("SKB_0001.PNG") && msg.contains("is DNG") && msg.contains("says PNG"),
        "{msg}"
    );

    let png_as_dng = dir.path().join("SKB_0002.DNG");
    image::RgbImage::new(4, 4)
        .save_with_format(&png_as_dng, image::ImageFormat::Png)
        .unwrap();
    let kind = sniff(&png_as_dng).unwrap();
    assert_eq!(kind, FileKind::Png);
    let msg = check_extension(&png_as_dng, kind).unwrap_err().to_string();
    assert!(
        msg.contains("SKB_0002.DNG") && msg.contains("is PNG") && msg.contains("says DNG"),
        "{msg}"
    );
    let msg = decode_superpixel(&png_as_dng, &RawOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("SKB_0002.DNG") && msg.contains("not a camera raw file"),
        "{msg}"
    );
}

/// TIFF bytes: an 8-bit RGB image with `Make`, `Model` and an EXIF directory (with the
/// focal-plane resolution in centimetres and the 35 mm equivalent focal length).
fn exif_tiff(with_image: bool) -> Vec<u8> {
    use skinbrdf_raw::tiff::{encode, Directory, TagValue};
    let mut exif = Directory::default();
    exif.set(0x829a, TagValue::Rational(vec![(1, 60)]))
        .set(0x829d, TagValue::Rational(vec![(56, 10)]))
        .set(0x8827, TagValue::Short(vec![400]))
        .set(0x9003, TagValue::Ascii("2024:12:31 23:59:59".into()))
        .set(0x9291, TagValue::Ascii("5".into()))
        .set(0x920a, TagValue::Rational(vec![(85, 1)]))
        .set(0x9211, TagValue::Long(vec![42]))
        .set(0xa431, TagValue::Ascii("BODY-1".into()))
        .set(0xa434, TagValue::Ascii("Portrait 85".into()))
        .set(0xa20e, TagValue::Rational(vec![(16807, 10)]))
        .set(0xa20f, TagValue::Rational(vec![(16807, 10)]))
        .set(0xa210, TagValue::Short(vec![3]))
        .set(0xa405, TagValue::Short(vec![128]));
    let mut ifd = Directory::default();
    ifd.set(271, TagValue::Ascii("Maker".into()))
        .set(272, TagValue::Ascii("Body X".into()));
    if with_image {
        ifd.set(256, TagValue::Long(vec![2]))
            .set(257, TagValue::Long(vec![2]))
            .set(258, TagValue::Short(vec![8, 8, 8]))
            .set(259, TagValue::Short(vec![1]))
            .set(262, TagValue::Short(vec![2]))
            .set(277, TagValue::Short(vec![3]))
            .set(278, TagValue::Long(vec![2]));
        ifd.strip = Some(vec![128; 12]);
    }
    ifd.subs.push((0x8769, exif));
    encode(&ifd)
}

fn check_exif_fields(path: &Path) {
    let m = read_metadata(path).unwrap();
    assert_eq!(m.camera_make.as_deref(), Some("Maker"));
    assert_eq!(m.camera_model.as_deref(), Some("Body X"));
    assert_eq!(m.exposure_time_s, Some(1.0 / 60.0));
    assert_eq!(m.f_number, Some(5.6));
    assert_eq!(m.iso, Some(400));
    assert_eq!(m.focal_length_mm, Some(85.0));
    assert_eq!(m.image_number, Some(42));
    assert_eq!(m.body_serial.as_deref(), Some("BODY-1"));
    assert_eq!(m.lens_model.as_deref(), Some("Portrait 85"));
    // 1680.7 px/cm.
    assert_eq!(m.focal_plane_resolution_unit, Some(3));
    assert!((m.focal_plane_px_per_mm_x.unwrap() - 168.07).abs() < 1e-9);
    assert!((m.focal_plane_px_per_mm_y.unwrap() - 168.07).abs() < 1e-9);
    assert_eq!(m.focal_length_35mm_mm, Some(128.0));
    // Not a DNG: no raw directory's sizes.
    assert_eq!(m.sensor_size_px, None);
    let t = m.capture_time.unwrap();
    assert_eq!(t, capture_time("2024:12:31 23:59:59", Some("5"), None));
    // No offset: the naive clock.
    assert_eq!(t.unix_seconds(), None);
    assert_eq!(t.seconds(), 1_735_689_599.5);
}

#[test]
fn exif_of_tiff_and_jpeg_files() {
    let dir = tempfile::tempdir().unwrap();
    let tif = dir.path().join("plain.tif");
    std::fs::write(&tif, exif_tiff(true)).unwrap();
    assert_eq!(sniff(&tif).unwrap(), FileKind::Tiff);
    check_exif_fields(&tif);
    let err = decode_superpixel(&tif, &RawOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("plain.tif") && err.contains("not a camera raw file"),
        "{err}"
    );

    // A JPEG: the image crate's encoding with an APP1 EXIF segment after SOI.
    let mut jpeg = Vec::new();
    image::RgbImage::from_pixel(8, 8, image::Rgb([90, 120, 150]))
        .write_to(
            &mut std::io::Cursor::new(&mut jpeg),
            image::ImageFormat::Jpeg,
        )
        .unwrap();
    let tiff = exif_tiff(false);
    let mut app1 = b"Exif\0\0".to_vec();
    app1.extend_from_slice(&tiff);
    let mut file = jpeg[..2].to_vec();
    file.extend_from_slice(&[0xFF, 0xE1]);
    file.extend_from_slice(&((app1.len() + 2) as u16).to_be_bytes());
    file.extend_from_slice(&app1);
    file.extend_from_slice(&jpeg[2..]);
    let jpg = dir.path().join("photo.jpg");
    std::fs::write(&jpg, &file).unwrap();
    assert_eq!(sniff(&jpg).unwrap(), FileKind::Jpeg);
    check_exif_fields(&jpg);
    // The image itself still decodes.
    assert_eq!(image::open(&jpg).unwrap().width(), 8);
}

#[test]
fn malformed_exif_is_an_error_not_a_guess() {
    use skinbrdf_raw::tiff::{encode, Directory, TagValue};
    let mut exif = Directory::default();
    exif.set(0x9003, TagValue::Ascii("31.12.2024 23:59".into()));
    let mut ifd = Directory::default();
    ifd.set(271, TagValue::Ascii("Maker".into()));
    ifd.subs.push((0x8769, exif));
    let dir = tempfile::tempdir().unwrap();
    let tif = dir.path().join("bad-date.tif");
    std::fs::write(&tif, encode(&ifd)).unwrap();
    let err = read_metadata(&tif).unwrap_err().to_string();
    assert!(
        err.contains("bad-date.tif") && err.contains("DateTimeOriginal"),
        "{err}"
    );
}
