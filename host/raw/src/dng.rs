//! A DNG writer for mosaicked (Bayer) sensor data, built on the crate's own [`crate::tiff`]
//! writer.
//!
//! The file is a little-endian DNG 1.4 whose first directory is the raw image (uncompressed, one
//! strip, `PhotometricInterpretation` = CFA) with an EXIF directory behind it. Samples of 12 or
//! 14 bits are bit-packed most significant bit first, as the DNG specification requires for
//! depths other than 8 and 16 (whatever the file's byte order); 16-bit samples are
//! little-endian. As in the DNG specification, the CFA pattern and the black-level pattern both
//! start at the active area's top-left photosite. A fixed, plausible `ColorMatrix1` (D65) and
//! `AsShotNeutral` are written unless given, since common readers need a colour matrix; this
//! project never applies them.
//!
//! The EXIF directory carries what a camera's does to turn the focal length into pixels when
//! given: `FocalPlaneXResolution`, `FocalPlaneYResolution` and `FocalPlaneResolutionUnit`
//! (0xA20E-0xA210, photosites per unit on the focal plane) and `FocalLengthIn35mmFilm`
//! (0xA405).
//!
//! Writing is atomic ([`skinbrdf_core::fsio::write_atomic`]).

use std::path::Path;

use crate::bayer::BayerPhase;
use crate::error::RawError;
use crate::exposure::CaptureTime;
use crate::tiff::{encode, Directory, TagValue};

/// A mosaicked sensor image and the metadata a camera would store with it.
#[derive(Debug, Clone, PartialEq)]
pub struct DngImage {
    /// Full sensor width in photosites (masked areas included).
    pub width_px: u32,
    /// Full sensor height in photosites.
    pub height_px: u32,
    /// The Bayer phase at the active area's top-left photosite.
    pub cfa: BayerPhase,
    /// The active area as `[top, left, bottom, right]` (DNG `ActiveArea`, bottom and right
    /// exclusive); `None` = the whole sensor.
    pub active_area: Option<[u32; 4]>,
    /// Bits per sample: 12, 14 or 16.
    pub bits_per_sample: u32,
    /// The photosites, row-major, `width_px * height_px` values below `2^bits_per_sample`.
    pub data: Vec<u16>,
    /// Black level per CFA position of the active area's quad, reading order.
    pub black_levels: [u16; 4],
    /// White level (at most `2^bits_per_sample - 1`).
    pub white_level: u16,
    /// `Make`.
    pub make: String,
    /// `Model`.
    pub model: String,
    /// DNG `UniqueCameraModel`.
    pub unique_camera_model: String,
    /// Body serial (EXIF `BodySerialNumber` and DNG `CameraSerialNumber`).
    pub body_serial: Option<String>,
    /// `LensMake`.
    pub lens_make: Option<String>,
    /// `LensModel`.
    pub lens_model: Option<String>,
    /// `ExposureTime`, seconds.
    pub exposure_time_s: Option<f64>,
    /// `FNumber`.
    pub f_number: Option<f64>,
    /// ISO (`PhotographicSensitivity`; above 65535 also `RecommendedExposureIndex`).
    pub iso: Option<u32>,
    /// `FocalLength`, millimetres.
    pub focal_length_mm: Option<f64>,
    /// `FocalPlaneXResolution`, `FocalPlaneYResolution` and `FocalPlaneResolutionUnit`.
    pub focal_plane_resolution: Option<FocalPlaneResolution>,
    /// `FocalLengthIn35mmFilm`, whole millimetres (EXIF stores a SHORT; 0 means unknown).
    pub focal_length_35mm_mm: Option<u16>,
    /// `DateTimeOriginal`, `SubSecTimeOriginal`, `OffsetTimeOriginal`.
    pub capture_time: Option<CaptureTime>,
    /// EXIF `ImageNumber`.
    pub image_number: Option<u32>,
    /// DNG `AsShotNeutral` (camera-space neutral, each in (0, 1]).
    pub as_shot_neutral: [f64; 3],
    /// DNG `ColorMatrix1` (XYZ to camera, row-major, D65).
    pub color_matrix: [f64; 9],
}

/// The unit of EXIF's focal-plane resolution (`FocalPlaneResolutionUnit`): 2 and 3 are
/// standard EXIF, 4 and 5 the extension exiftool documents.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FocalPlaneUnit {
    /// 2: inch (EXIF's default).
    Inch,
    /// 3: centimetre.
    Centimetre,
    /// 4: millimetre.
    Millimetre,
    /// 5: micrometre.
    Micrometre,
}

impl FocalPlaneUnit {
    /// The tag's value.
    pub const fn code(self) -> u16 {
        match self {
            Self::Inch => 2,
            Self::Centimetre => 3,
            Self::Millimetre => 4,
            Self::Micrometre => 5,
        }
    }

    /// Millimetres per unit.
    pub const fn mm(self) -> f64 {
        match self {
            Self::Inch => 25.4,
            Self::Centimetre => 10.0,
            Self::Millimetre => 1.0,
            Self::Micrometre => 0.001,
        }
    }
}

/// How many pixels (photosites, for a raw file) a unit of the focal plane holds, across and
/// down: EXIF's `FocalPlaneXResolution`, `FocalPlaneYResolution`, `FocalPlaneResolutionUnit`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FocalPlaneResolution {
    /// Pixels per unit across (`FocalPlaneXResolution`).
    pub x_px_per_unit: f64,
    /// Pixels per unit down (`FocalPlaneYResolution`).
    pub y_px_per_unit: f64,
    /// The unit.
    pub unit: FocalPlaneUnit,
}

impl FocalPlaneResolution {
    /// The resolution of photosites of `pitch_mm` (square) stated in `unit`.
    pub fn from_pitch_mm(pitch_mm: f64, unit: FocalPlaneUnit) -> Self {
        let per_unit = unit.mm() / pitch_mm;
        Self {
            x_px_per_unit: per_unit,
            y_px_per_unit: per_unit,
            unit,
        }
    }
}

impl DngImage {
    /// A plausible `ColorMatrix1` (XYZ D65 to camera) of a modern CMOS sensor.
    pub const DEFAULT_COLOR_MATRIX: [f64; 9] = [
        0.6722, -0.0635, -0.0963, -0.4287, 1.2460, 0.2028, -0.0908, 0.2162, 0.5668,
    ];
    /// A plausible daylight `AsShotNeutral`.
    pub const DEFAULT_AS_SHOT_NEUTRAL: [f64; 3] = [0.4861, 1.0, 0.6636];

    /// An image with the given photosites, black 0, white at full scale, no active-area border
    /// and no metadata but a generic camera name.
    pub fn new(
        width_px: u32,
        height_px: u32,
        cfa: BayerPhase,
        bits_per_sample: u32,
        data: Vec<u16>,
    ) -> Self {
        let full = (1u32 << bits_per_sample.min(16)) - 1;
        Self {
            width_px,
            height_px,
            cfa,
            active_area: None,
            bits_per_sample,
            data,
            black_levels: [0; 4],
            white_level: u16::try_from(full).unwrap_or(u16::MAX),
            make: "skinbrdf".into(),
            model: "synthetic".into(),
            unique_camera_model: "skinbrdf synthetic".into(),
            body_serial: None,
            lens_make: None,
            lens_model: None,
            exposure_time_s: None,
            f_number: None,
            iso: None,
            focal_length_mm: None,
            focal_plane_resolution: None,
            focal_length_35mm_mm: None,
            capture_time: None,
            image_number: None,
            as_shot_neutral: Self::DEFAULT_AS_SHOT_NEUTRAL,
            color_matrix: Self::DEFAULT_COLOR_MATRIX,
        }
    }
}

/// Every problem that makes `img` unwritable, in words.
fn problems(img: &DngImage) -> Vec<String> {
    let mut out = Vec::new();
    let (w, h) = (img.width_px as usize, img.height_px as usize);
    if !matches!(img.bits_per_sample, 12 | 14 | 16) {
        out.push(format!(
            "bits_per_sample must be 12, 14 or 16, got {}",
            img.bits_per_sample
        ));
        return out;
    }
    let max = (1u32 << img.bits_per_sample) - 1;
    if w < 2 || h < 2 {
        out.push(format!("sensor {w}x{h} is smaller than one 2x2 quad"));
    }
    if !(w * img.bits_per_sample as usize).is_multiple_of(8) {
        out.push(format!(
            "a row of {w} {}-bit samples is not a whole number of bytes",
            img.bits_per_sample
        ));
    }
    if img.data.len() != w * h {
        out.push(format!(
            "data has {} samples, the sensor {w}x{h} has {}",
            img.data.len(),
            w * h
        ));
    }
    if (w * h * img.bits_per_sample as usize) / 8 > (u32::MAX as usize) - (1 << 20) {
        out.push("image data exceeds a classic TIFF's 4 GiB".into());
    }
    if let Some(i) = img.data.iter().position(|&v| u32::from(v) > max) {
        out.push(format!(
            "sample {i} = {} exceeds the {}-bit full scale {max}",
            img.data[i], img.bits_per_sample
        ));
    }
    if u32::from(img.white_level) > max {
        out.push(format!(
            "white_level {} exceeds the {}-bit full scale {max}",
            img.white_level, img.bits_per_sample
        ));
    }
    if img.black_levels.iter().any(|&b| b >= img.white_level) {
        out.push(format!(
            "black levels {} must be below the white level {}",
            list_in_words(&img.black_levels),
            img.white_level
        ));
    }
    if let Some([t, l, b, r]) = img.active_area {
        if !(t + 2 <= b && l + 2 <= r && b <= img.height_px && r <= img.width_px) {
            out.push(format!(
                "active area [top {t}, left {l}, bottom {b}, right {r}] is not a rectangle of at least 2x2 inside the {w}x{h} sensor"
            ));
        }
    }
    for (name, v) in [
        ("exposure_time_s", img.exposure_time_s),
        ("f_number", img.f_number),
        ("focal_length_mm", img.focal_length_mm),
    ] {
        if let Some(v) = v {
            if !(v.is_finite() && v > 0.0) {
                out.push(format!("{name} must be positive and finite, got {v}"));
            }
        }
    }
    if let Some(r) = &img.focal_plane_resolution {
        for (name, v) in [
            ("focal_plane_resolution.x_px_per_unit", r.x_px_per_unit),
            ("focal_plane_resolution.y_px_per_unit", r.y_px_per_unit),
        ] {
            if !(v.is_finite() && v > 0.0) {
                out.push(format!("{name} must be positive and finite, got {v}"));
            }
        }
    }
    if img.focal_length_35mm_mm == Some(0) {
        out.push(
            "focal_length_35mm_mm must be positive (EXIF's 0 means unknown: write None)".into(),
        );
    }
    if img
        .as_shot_neutral
        .iter()
        .any(|&v| !(v.is_finite() && v > 0.0 && v <= 1.0))
    {
        out.push(format!(
            "as_shot_neutral {} must be in (0, 1]",
            list_in_words(&img.as_shot_neutral)
        ));
    }
    if img.color_matrix.iter().any(|v| !v.is_finite()) {
        out.push("color_matrix must be finite".into());
    }
    if let Some(t) = &img.capture_time {
        if let Some(d) = &t.subsec_digits {
            if d.is_empty() || d.len() > 9 || !d.bytes().all(|c| c.is_ascii_digit()) {
                out.push(format!(
                    "subsec_digits \"{d}\" must be 1 to 9 decimal digits"
                ));
            }
        }
        if let Some(o) = t.utc_offset_min {
            if o.abs() > 14 * 60 {
                out.push(format!("utc_offset_min {o} is beyond +-14 h"));
            }
        }
    }
    out
}

/// The closest rational with 32-bit terms (continued fractions), for a positive finite `x`.
pub(crate) fn to_rational(x: f64) -> (u32, u32) {
    let limit = f64::from(u32::MAX);
    let (mut h0, mut h1, mut k0, mut k1) = (0.0f64, 1.0f64, 1.0f64, 0.0f64);
    let mut r = x;
    let mut best = (x.round().clamp(0.0, limit), 1.0);
    for _ in 0..40 {
        let a = r.floor();
        let h2 = a * h1 + h0;
        let k2 = a * k1 + k0;
        if h2 > limit || k2 > limit {
            break;
        }
        best = (h2, k2);
        if (h2 / k2 - x).abs() <= x * 1e-15 {
            break;
        }
        let frac = r - a;
        if frac <= 0.0 {
            break;
        }
        r = 1.0 / frac;
        (h0, h1, k0, k1) = (h1, h2, k1, k2);
    }
    (best.0 as u32, best.1 as u32)
}

fn to_srational(x: f64) -> (i32, i32) {
    const DEN: i32 = 10_000;
    ((x * f64::from(DEN)).round() as i32, DEN)
}

/// The samples as the strip stores them (see the module docs).
fn pack(data: &[u16], bits: u32) -> Vec<u8> {
    if bits == 16 {
        return data.iter().flat_map(|v| v.to_le_bytes()).collect();
    }
    let mut out = Vec::with_capacity(data.len() * bits as usize / 8 + 1);
    let (mut acc, mut n) = (0u32, 0u32);
    for &v in data {
        acc = (acc << bits) | u32::from(v);
        n += bits;
        while n >= 8 {
            n -= 8;
            out.push((acc >> n) as u8);
        }
        acc &= (1 << n) - 1;
    }
    if n > 0 {
        out.push((acc << (8 - n)) as u8);
    }
    out
}

/// The DNG's directory tree before encoding ([`crate::tiff::encode`]): tests alter it to build
/// files this writer never writes (another CFA layout, a damaged tag).
pub fn directory(path: &Path, img: &DngImage) -> Result<Directory, RawError> {
    let p = problems(img);
    if !p.is_empty() {
        return Err(RawError::BadDngImage {
            path: path.to_path_buf(),
            problem: p.join("; "),
        });
    }
    let mut exif = Directory::default();
    exif.set(0x9000, TagValue::Undefined(b"0231".to_vec()));
    if let Some(t) = img.exposure_time_s {
        exif.set(0x829a, TagValue::Rational(vec![to_rational(t)]));
    }
    if let Some(f) = img.f_number {
        exif.set(0x829d, TagValue::Rational(vec![to_rational(f)]));
    }
    if let Some(iso) = img.iso {
        match u16::try_from(iso) {
            Ok(s) if s != u16::MAX => {
                exif.set(0x8827, TagValue::Short(vec![s]));
            }
            _ => {
                exif.set(0x8827, TagValue::Short(vec![u16::MAX]));
                exif.set(0x8830, TagValue::Short(vec![2]));
                exif.set(0x8832, TagValue::Long(vec![iso]));
            }
        }
    }
    if let Some(f) = img.focal_length_mm {
        exif.set(0x920a, TagValue::Rational(vec![to_rational(f)]));
    }
    if let Some(r) = &img.focal_plane_resolution {
        exif.set(
            0xa20e,
            TagValue::Rational(vec![to_rational(r.x_px_per_unit)]),
        );
        exif.set(
            0xa20f,
            TagValue::Rational(vec![to_rational(r.y_px_per_unit)]),
        );
        exif.set(0xa210, TagValue::Short(vec![r.unit.code()]));
    }
    if let Some(f) = img.focal_length_35mm_mm {
        exif.set(0xa405, TagValue::Short(vec![f]));
    }
    if let Some(t) = &img.capture_time {
        exif.set(0x9003, TagValue::Ascii(t.local.exif_text()));
        if let Some(s) = &t.subsec_digits {
            exif.set(0x9291, TagValue::Ascii(s.clone()));
        }
        if let Some(o) = t.utc_offset_min {
            let sign = if o < 0 { '-' } else { '+' };
            exif.set(
                0x9011,
                TagValue::Ascii(format!("{sign}{:02}:{:02}", o.abs() / 60, o.abs() % 60)),
            );
        }
    }
    if let Some(n) = img.image_number {
        exif.set(0x9211, TagValue::Long(vec![n]));
    }
    if let Some(s) = &img.body_serial {
        exif.set(0xa431, TagValue::Ascii(s.clone()));
    }
    if let Some(s) = &img.lens_make {
        exif.set(0xa433, TagValue::Ascii(s.clone()));
    }
    if let Some(s) = &img.lens_model {
        exif.set(0xa434, TagValue::Ascii(s.clone()));
    }

    let mut ifd = Directory::default();
    ifd.set(254, TagValue::Long(vec![0]))
        .set(256, TagValue::Long(vec![img.width_px]))
        .set(257, TagValue::Long(vec![img.height_px]))
        .set(258, TagValue::Short(vec![img.bits_per_sample as u16]))
        .set(259, TagValue::Short(vec![1]))
        .set(262, TagValue::Short(vec![32803]))
        .set(271, TagValue::Ascii(img.make.clone()))
        .set(272, TagValue::Ascii(img.model.clone()))
        .set(274, TagValue::Short(vec![1]))
        .set(277, TagValue::Short(vec![1]))
        .set(278, TagValue::Long(vec![img.height_px]))
        .set(284, TagValue::Short(vec![1]))
        .set(305, TagValue::Ascii("skinbrdf".into()))
        .set(33421, TagValue::Short(vec![2, 2]))
        .set(33422, TagValue::Byte(img.cfa.dng_pattern().to_vec()))
        .set(50706, TagValue::Byte(vec![1, 4, 0, 0]))
        .set(50707, TagValue::Byte(vec![1, 1, 0, 0]))
        .set(50708, TagValue::Ascii(img.unique_camera_model.clone()))
        .set(50710, TagValue::Byte(vec![0, 1, 2]))
        .set(50711, TagValue::Short(vec![1]))
        .set(50713, TagValue::Short(vec![2, 2]))
        .set(50714, TagValue::Short(img.black_levels.to_vec()))
        .set(50717, TagValue::Long(vec![u32::from(img.white_level)]))
        .set(
            50721,
            TagValue::SRational(img.color_matrix.iter().map(|&v| to_srational(v)).collect()),
        )
        .set(
            50728,
            TagValue::Rational(
                img.as_shot_neutral
                    .iter()
                    .map(|&v| to_rational(v))
                    .collect(),
            ),
        )
        .set(50778, TagValue::Short(vec![21]));
    if let Some(area) = img.active_area {
        ifd.set(50829, TagValue::Long(area.to_vec()));
    }
    if let Some(s) = &img.body_serial {
        ifd.set(50735, TagValue::Ascii(s.clone()));
    }
    ifd.subs.push((0x8769, exif));
    ifd.strip = Some(pack(&img.data, img.bits_per_sample));
    Ok(ifd)
}

/// The bytes of the DNG file for `img` (`path` only names the file in errors).
pub fn encode_dng(path: &Path, img: &DngImage) -> Result<Vec<u8>, RawError> {
    Ok(encode(&directory(path, img)?))
}

/// Writes `img` as a DNG file, atomically.
pub fn write_dng(path: &Path, img: &DngImage) -> Result<(), RawError> {
    let bytes = encode_dng(path, img)?;
    skinbrdf_core::fsio::write_atomic(path, &bytes)?;
    Ok(())
}

/// Numbers in words: `1, 2, 3`.
fn list_in_words<T: std::fmt::Display>(values: &[T]) -> String {
    values
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_is_msb_first() {
        assert_eq!(pack(&[0xABC, 0xDEF], 12), vec![0xAB, 0xCD, 0xEF]);
        assert_eq!(pack(&[0x1234], 16), vec![0x34, 0x12]);
        // Four 14-bit samples are 7 bytes.
        assert_eq!(pack(&[0x3FFF, 0, 0x3FFF, 0], 14).len(), 7);
        assert_eq!(pack(&[0x3FFF, 0, 0, 0], 14)[..2], [0xFF, 0xFC]);
    }

    #[test]
    fn rationals_are_close() {
        for x in [
            1.0 / 125.0,
            1.0 / 8000.0,
            2.8,
            5.6,
            35.0,
            0.4861,
            30.0,
            1.0 / 3.0,
        ] {
            let (n, d) = to_rational(x);
            let back = f64::from(n) / f64::from(d);
            assert!((back - x).abs() <= x * 1e-12, "{x}: {n}/{d}");
        }
        assert_eq!(to_rational(1.0 / 125.0), (1, 125));
        assert_eq!(to_rational(2.8), (14, 5));
    }

    fn write_altered(
        name: &str,
        alter: impl FnOnce(&mut Directory),
    ) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(name);
        let img = DngImage::new(12, 12, BayerPhase::Rggb, 16, vec![1000; 144]);
        let mut d = directory(&path, &img).unwrap();
        alter(&mut d);
        std::fs::write(&path, encode(&d)).unwrap();
        (dir, path)
    }

    #[test]
    fn x_trans_is_refused_naming_the_file_and_layout() {
        // Fujifilm's X-Trans pattern (6x6).
        let xtrans = b"GGRGGBGGBGGRBRGRBGGGBGGRGGRGGBRBGBRG".map(|c| match c {
            b'R' => 0,
            b'G' => 1,
            _ => 2,
        });
        let (_dir, path) = write_altered("XT_0001.DNG", |d| {
            d.set(33421, TagValue::Short(vec![6, 6]));
            d.set(33422, TagValue::Byte(xtrans.to_vec()));
        });
        let err = crate::decode_superpixel(&path, &crate::RawOptions::default()).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, RawError::UnsupportedLayout { .. }), "{msg}");
        assert!(
            msg.contains("XT_0001.DNG") && msg.contains("X-Trans 6x6"),
            "{msg}"
        );
    }

    #[test]
    fn linear_three_channel_raw_is_refused() {
        let (_dir, path) = write_altered("LIN_0001.DNG", |d| {
            d.set(262, TagValue::Short(vec![34892]));
            d.set(277, TagValue::Short(vec![3]));
            d.set(258, TagValue::Short(vec![16, 16, 16]));
            d.entries.remove(&33421);
            d.entries.remove(&33422);
            d.set(50713, TagValue::Short(vec![1, 1]));
            d.set(50714, TagValue::Short(vec![0, 0, 0]));
            d.set(50717, TagValue::Long(vec![65535, 65535, 65535]));
            d.strip = Some(vec![0x10; 12 * 12 * 3 * 2]);
        });
        let err = crate::decode_superpixel(&path, &crate::RawOptions::default()).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, RawError::UnsupportedLayout { .. }), "{msg}");
        assert!(
            msg.contains("LIN_0001.DNG") && msg.contains("3 samples per pixel"),
            "{msg}"
        );
    }

    #[test]
    fn bad_images_are_refused_with_every_problem() {
        let mut img = DngImage::new(6, 4, BayerPhase::Rggb, 14, vec![0; 10]);
        img.white_level = 20000;
        img.active_area = Some([0, 0, 5, 6]);
        let err = encode_dng(Path::new("out/x.dng"), &img)
            .unwrap_err()
            .to_string();
        assert!(err.contains("out/x.dng"), "{err}");
        assert!(err.contains("not a whole number of bytes"), "{err}");
        assert!(err.contains("data has 10 samples"), "{err}");
        assert!(err.contains("white_level 20000"), "{err}");
        assert!(err.contains("active area"), "{err}");
    }
}
