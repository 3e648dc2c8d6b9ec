//! Exposure metadata (EXIF) of raw, TIFF and JPEG files.
//!
//! A TIFF-based file's directories are checked before rawler reads them (chains, entry counts,
//! value arrays, pixel count), but not whether its image data is in the file: a file stripped
//! of its image, or cut short after its directories, still gives its metadata.
//!
//! Every field is read as the file states it; a missing field is `None`, never guessed or
//! derived from another. The capture time is kept as the camera wrote it ([`CaptureTime`]): the
//! naive local `DateTimeOriginal`, the `SubSecTimeOriginal` digits and the `OffsetTimeOriginal`
//! offset, each only if present. A field that is present but malformed (a date that is not
//! `YYYY:MM:DD HH:MM:SS`, a zero denominator) is an error ([`RawError::BadExif`]); a date of
//! blanks or zeros (the EXIF convention for "unknown") is `None`.
//!
//! ISO is `PhotographicSensitivity` (0x8827), or where that is absent or saturated at 65535,
//! `RecommendedExposureIndex`, then `ISOSpeed`. The body serial is EXIF `BodySerialNumber`
//! (0xA431), else DNG `CameraSerialNumber`. The shutter count is EXIF `ImageNumber` (0x9211).
//!
//! # What turns millimetres into pixels
//!
//! The focal length alone (`FocalLength`, mm) says nothing about pixels; a camera states the
//! scale beside it, and these fields carry it so a focal length in pixels can be guessed
//! before any calibration (`skinbrdf ingest`):
//!
//! * `FocalPlaneXResolution` / `FocalPlaneYResolution` (EXIF 0xA20E / 0xA20F; the TIFF/EP
//!   tags 0x920E / 0x920F where the EXIF ones are absent): pixels of the camera's image per
//!   `FocalPlaneResolutionUnit` (0xA210 / 0x9210) on the focal plane. The unit is, as written:
//!   2 inch (also the EXIF default when the tag is absent), 3 centimetre, and the values
//!   exiftool documents beyond the standard, 4 millimetre and 5 micrometre; 1 ("no absolute
//!   unit") is read as inch, as exiftool reads it. Any other unit leaves the resolution
//!   `None` (the unit as written stays in [`ExposureMeta::focal_plane_resolution_unit`]).
//!   They are stored converted to pixels per millimetre: `px_per_mm = value / mm_per_unit`
//!   (25.4, 10, 1 or 0.001 mm). A rational with a zero denominator is stored as the division
//!   gives it (infinite or NaN): these tags only feed a guess, which refuses such values with
//!   its reason, instead of refusing the file.
//! * `FocalLengthIn35mmFilm` (EXIF 0xA405): the focal length of the same field of view on a
//!   36 x 24 mm frame (0, "unknown", is `None`).
//! * For a DNG, the raw image's full size in photosites (`ImageWidth` x `ImageLength` of the
//!   raw directory, masked border included) and its `DefaultCropSize`.
//!
//! Formats without a TIFF structure rawler exposes (CR3, RAF, ...) give none of these.

use std::path::Path;

use rawler::decoders::{RawDecodeParams, WellKnownIFD};
use rawler::exif::Exif;
use rawler::formats::jfif::Jfif;
use rawler::formats::tiff::reader::TiffReader;
use rawler::formats::tiff::{GenericTiffReader, Rational, Value, IFD};
use rawler::rawsource::RawSource;
use rawler::tags::{DngTag, ExifTag, TiffCommonTag};

use crate::decode::loader;
use crate::error::RawError;
use crate::kind::{sniff_for_metadata, FileKind};
use crate::via_libraw;

/// A naive (zone-less) calendar date and time of day, as EXIF stores it.
#[derive(
    serde::Serialize, serde::Deserialize, Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash,
)]
pub struct LocalDateTime {
    /// Year (e.g. 2025).
    pub year: i32,
    /// Month, 1..=12.
    pub month: u8,
    /// Day of the month, 1..=31.
    pub day: u8,
    /// Hour, 0..=23.
    pub hour: u8,
    /// Minute, 0..=59.
    pub minute: u8,
    /// Second, 0..=60 (a leap second is kept as written).
    pub second: u8,
}

impl LocalDateTime {
    /// The EXIF text, `YYYY:MM:DD HH:MM:SS` (what [`LocalDateTime::parse_exif`] reads).
    pub fn exif_text(&self) -> String {
        format!(
            "{:04}:{:02}:{:02} {:02}:{:02}:{:02}",
            self.year, self.month, self.day, self.hour, self.minute, self.second
        )
    }

    /// Parses EXIF's `YYYY:MM:DD HH:MM:SS` (also accepts `-` between date fields and `T`
    /// between date and time). `Ok(None)` for the "unknown" forms (blanks, all zeros).
    pub fn parse_exif(s: &str) -> Result<Option<Self>, &'static str> {
        let s = s.trim_end_matches('\0').trim();
        if s.is_empty() || s.chars().all(|c| matches!(c, ' ' | ':' | '0' | '-')) {
            return Ok(None);
        }
        let b = s.as_bytes();
        if b.len() < 19 {
            return Err("expected `YYYY:MM:DD HH:MM:SS`");
        }
        let num = |r: std::ops::Range<usize>| -> Result<u32, &'static str> {
            let t = &s[r];
            if t.bytes().all(|c| c.is_ascii_digit()) {
                t.parse().map_err(|_| "not a number")
            } else {
                Err("expected `YYYY:MM:DD HH:MM:SS`")
            }
        };
        let sep_ok = matches!(b[4], b':' | b'-')
            && matches!(b[7], b':' | b'-')
            && matches!(b[10], b' ' | b'T')
            && b[13] == b':'
            && b[16] == b':';
        if !sep_ok {
            return Err("expected `YYYY:MM:DD HH:MM:SS`");
        }
        let (year, month, day) = (num(0..4)?, num(5..7)?, num(8..10)?);
        let (hour, minute, second) = (num(11..13)?, num(14..16)?, num(17..19)?);
        let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
        let days_in_month = match month {
            1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
            4 | 6 | 9 | 11 => 30,
            2 if leap => 29,
            2 => 28,
            _ => return Err("month out of range"),
        };
        if day == 0 || day > days_in_month || hour > 23 || minute > 59 || second > 60 {
            return Err("date or time field out of range");
        }
        // Every field was checked to fit its type above.
        Ok(Some(Self {
            year: year as i32,
            month: month as u8,
            day: day as u8,
            hour: hour as u8,
            minute: minute as u8,
            second: second as u8,
        }))
    }

    /// Seconds from 1970-01-01 00:00:00 to this date-time on the same (unspecified) clock.
    pub fn naive_seconds(&self) -> i64 {
        days_from_civil(self.year, u32::from(self.month), u32::from(self.day)) * 86_400
            + i64::from(self.hour) * 3600
            + i64::from(self.minute) * 60
            + i64::from(self.second)
    }
    /// The date-time `s` seconds after 1970-01-01 00:00:00 on the same clock: the inverse of
    /// [`Self::naive_seconds`] (proleptic Gregorian calendar, H. Hinnant's algorithm).
    pub fn from_naive_seconds(s: i64) -> Self {
        let days = s.div_euclid(86_400);
        let secs = s.rem_euclid(86_400);
        let z = days + 719_468;
        let era = z.div_euclid(146_097);
        let doe = z - era * 146_097;
        let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
        let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
        let mp = (5 * doy + 2) / 153;
        let day = (doy - (153 * mp + 2) / 5 + 1) as u8;
        let month = if mp < 10 { mp + 3 } else { mp - 9 } as u8;
        let year = (yoe + era * 400 + i64::from(month <= 2)) as i32;
        Self {
            year,
            month,
            day,
            hour: (secs / 3600) as u8,
            minute: ((secs % 3600) / 60) as u8,
            second: (secs % 60) as u8,
        }
    }
}

/// Days from 1970-01-01 to a proleptic Gregorian date (H. Hinnant's algorithm).
fn days_from_civil(y: i32, m: u32, d: u32) -> i64 {
    let y = i64::from(y) - i64::from(m <= 2);
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(m);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// When the shutter opened, as the camera's clock stated it.
#[derive(serde::Serialize, serde::Deserialize, Debug, Clone, PartialEq, Eq)]
pub struct CaptureTime {
    /// `DateTimeOriginal`: the camera's local date and time, whole seconds.
    pub local: LocalDateTime,
    /// `SubSecTimeOriginal` as written (decimal digits of the fraction of a second: "5" is
    /// 0.5 s, "050" is 0.05 s), if present.
    pub subsec_digits: Option<String>,
    /// `OffsetTimeOriginal` as minutes east of UTC (`"+01:00"` is 60), if present.
    pub utc_offset_min: Option<i32>,
}

impl CaptureTime {
    /// The sub-second fraction in seconds (0 when the file has none).
    pub fn subsec_s(&self) -> f64 {
        match &self.subsec_digits {
            Some(d) if !d.is_empty() => {
                d.parse::<f64>().unwrap_or(0.0) / 10f64.powi(d.len() as i32)
            }
            _ => 0.0,
        }
    }

    /// Seconds since the Unix epoch (UTC) when the offset is known.
    pub fn unix_seconds(&self) -> Option<f64> {
        self.utc_offset_min
            .map(|o| (self.local.naive_seconds() - i64::from(o) * 60) as f64 + self.subsec_s())
    }

    /// Seconds since the epoch on the camera's own clock, ignoring any offset.
    pub fn naive_seconds(&self) -> f64 {
        self.local.naive_seconds() as f64 + self.subsec_s()
    }

    /// [`Self::unix_seconds`] when the offset is known, else [`Self::naive_seconds`].
    pub fn seconds(&self) -> f64 {
        self.unix_seconds().unwrap_or_else(|| self.naive_seconds())
    }
}

/// What a file's metadata says about its exposure and the camera that made it.
#[derive(serde::Serialize, serde::Deserialize, Debug, Clone, PartialEq, Default)]
pub struct ExposureMeta {
    /// `ExposureTime`, seconds.
    pub exposure_time_s: Option<f64>,
    /// `FNumber`.
    pub f_number: Option<f64>,
    /// ISO sensitivity (see the module docs).
    pub iso: Option<u32>,
    /// `FocalLength`, millimetres.
    pub focal_length_mm: Option<f64>,
    /// `LensMake`.
    pub lens_make: Option<String>,
    /// `LensModel`.
    pub lens_model: Option<String>,
    /// `Make` as written (trimmed) in a file with a TIFF structure (DNG, CR2, NEF, ARW, ...);
    /// for other containers (CR3, CRW, MRW, RAF, X3F) the decoder's normalised camera make.
    pub camera_make: Option<String>,
    /// `Model` as written (trimmed) in a file with a TIFF structure; for other containers the
    /// decoder's normalised camera model (e.g. `EOS Digital Rebel` for a CRW whose `Model` is
    /// `Canon EOS DIGITAL REBEL`).
    pub camera_model: Option<String>,
    /// The body's serial number (see the module docs).
    pub body_serial: Option<String>,
    /// `DateTimeOriginal` with its sub-seconds and offset.
    pub capture_time: Option<CaptureTime>,
    /// `ImageNumber` (0x9211): the shutter count or image number where the camera writes one.
    pub image_number: Option<u32>,
    /// `FocalPlaneXResolution` in pixels (of the camera's image, photosites for a raw file) per
    /// millimetre of the focal plane, converted by its unit (see the module docs). As written:
    /// may be non-finite or not positive.
    pub focal_plane_px_per_mm_x: Option<f64>,
    /// `FocalPlaneYResolution` in pixels per millimetre, as `focal_plane_px_per_mm_x`.
    pub focal_plane_px_per_mm_y: Option<f64>,
    /// `FocalPlaneResolutionUnit` as written (2 inch, 3 cm, 4 mm, 5 um; see the module docs).
    pub focal_plane_resolution_unit: Option<u16>,
    /// `FocalLengthIn35mmFilm` (0xA405), millimetres: the focal length giving the same field
    /// of view on a 36 x 24 mm frame.
    pub focal_length_35mm_mm: Option<f64>,
    /// A DNG's raw image in photosites, `(width, height)`, masked border included.
    pub sensor_size_px: Option<(u32, u32)>,
    /// A DNG's `DefaultCropSize`, `(width, height)` in photosites: the size of its final image.
    pub default_crop_size_px: Option<(f64, f64)>,
}

/// Reads a raw, TIFF or JPEG file's exposure metadata (see the module docs).
pub fn read_metadata(path: &Path) -> Result<ExposureMeta, RawError> {
    let kind = sniff_for_metadata(path)?;
    let io = |source| RawError::Io {
        path: path.to_path_buf(),
        source,
    };
    let src = RawSource::new(path).map_err(io)?;
    let structure = |e: String| RawError::Truncated {
        path: path.to_path_buf(),
        what: format!("metadata unreadable ({e})"),
    };
    // The raw image's directory (DNG only): its size and default crop.
    let mut raw_ifd: Option<IFD> = None;
    let (exif, root): (Exif, Option<IFD>) = match kind {
        FileKind::Jpeg => {
            let jfif = Jfif::new(&src).map_err(|e| structure(e.to_string()))?;
            match jfif.exif_ifd() {
                Some(ifd) => (
                    Exif::new(ifd).map_err(|e| structure(e.to_string()))?,
                    Some(ifd.clone()),
                ),
                None => (Exif::default(), None),
            }
        }
        FileKind::Tiff => {
            let tiff = GenericTiffReader::new(&mut src.reader(), 0, 0, None, &[])
                .map_err(|e| structure(e.to_string()))?;
            let root = tiff.root_ifd().clone();
            (
                Exif::new(&root).map_err(|e| structure(e.to_string()))?,
                Some(root),
            )
        }
        FileKind::Png | FileKind::OpenExr => {
            return Err(RawError::NotRaw {
                path: path.to_path_buf(),
                actual: kind,
            })
        }
        _ => {
            let rawler =
                crate::decode::guarded(path, || loader().get_decoder(&src)).and_then(|d| {
                    let md = crate::decode::guarded(path, || {
                        d.raw_metadata(&src, &RawDecodeParams::default())
                    })?;
                    Ok((d, md))
                });
            let (decoder, md) = match rawler {
                Ok(r) => r,
                // A raw file rawler cannot read (an unsupported format or camera): LibRaw's.
                Err(e) => {
                    return via_libraw::metadata(path)
                        .map_err(|libraw| via_libraw::both_failed(e, libraw))
                }
            };
            // rawler exposes a DNG's root directory only; other TIFF-based formats' root is read
            // here, so `Make` and `Model` come as written rather than as rawler's clean names.
            let root = decoder
                .ifd(WellKnownIFD::Root)
                .ok()
                .flatten()
                .map(|r| (*r).clone())
                .or_else(|| tiff_root(&src));
            if kind == FileKind::Dng {
                raw_ifd = decoder
                    .ifd(WellKnownIFD::Raw)
                    .ok()
                    .flatten()
                    .map(|r| (*r).clone());
            }
            let mut exif = md.exif;
            if root.is_none() {
                // Formats without a TIFF root (CR3, CRW, RAF, MRW...): rawler gives its clean
                // names and no exposure for some; LibRaw gives the names as written where it
                // meets them and the exposure fields (rawler's stand where LibRaw fails).
                let mut meta = finish(
                    path,
                    exif_take(&mut exif),
                    &exif,
                    Some(md.make),
                    Some(md.model),
                )?;
                // rawler's answer stands where LibRaw cannot read the file.
                via_libraw::fill_metadata(path, &mut meta, via_libraw::Fill::Everything).ok();
                return Ok(meta);
            }
            (exif, root)
        }
    };
    let tag_str = |ifd: &IFD, tag: u16| {
        ifd.entries()
            .get(&tag)
            .and_then(|e| {
                e.value
                    .as_string()
                    .map(|s| s.trim_end_matches('\0').trim().to_string())
            })
            .filter(|s| !s.is_empty())
    };
    let make = root
        .as_ref()
        .and_then(|r| tag_str(r, TiffCommonTag::Make.into()));
    let model = root
        .as_ref()
        .and_then(|r| tag_str(r, TiffCommonTag::Model.into()));
    let mut exif = exif;
    let mut extra = exif_take(&mut exif);
    if extra.body_serial.is_none() {
        extra.body_serial = root
            .as_ref()
            .and_then(|r| tag_str(r, DngTag::CameraSerialNumber.into()));
    }
    if let Some(root) = &root {
        focal_plane_tags(&mut extra, root, raw_ifd.as_ref());
    }
    let mut meta = finish(path, extra, &exif, make, model)?;
    let exposure_missing = meta.exposure_time_s.is_none()
        || meta.f_number.is_none()
        || meta.iso.is_none()
        || meta.focal_length_mm.is_none();
    if kind.is_raw() && exposure_missing {
        // A raw file whose EXIF lacks an exposure field: LibRaw's (maker notes included),
        // where it reads the file.
        via_libraw::fill_metadata(path, &mut meta, via_libraw::Fill::Exposure).ok();
    }
    Ok(meta)
}

/// The root directory of a file with a TIFF structure (CR2, NEF, ARW, PEF, ORF, RW2, ...),
/// `None` for other containers (CR3, CRW, MRW, RAF, X3F) or an unreadable structure.
fn tiff_root(src: &RawSource) -> Option<IFD> {
    let tiff = GenericTiffReader::new(&mut src.reader(), 0, 0, None, &[]).ok()?;
    let root = tiff.root_ifd();
    root.get_entry(TiffCommonTag::Make)?;
    Some(root.clone())
}

/// The diagonal of the 36 x 24 mm frame `FocalLengthIn35mmFilm` refers to, millimetres:
/// `sqrt(36² + 24²)`. The equivalent focal length keeps the diagonal field of view, so
/// `f_35 / 43.27 mm = f / sensor diagonal`.
pub const FULL_FRAME_DIAGONAL_MM: f64 = 43.266_615_305_567_87;

/// Millimetres per `FocalPlaneResolutionUnit` (see the module docs): `None` for a unit EXIF
/// does not define. An absent unit is EXIF's default, the inch.
pub fn focal_plane_unit_mm(unit: Option<u16>) -> Option<f64> {
    match unit {
        None | Some(1 | 2) => Some(25.4),
        Some(3) => Some(10.0),
        Some(4) => Some(1.0),
        Some(5) => Some(0.001),
        Some(_) => None,
    }
}

/// The `idx`-th number of a tag's value whatever its numeric type; a rational is divided as
/// written (a zero denominator gives an infinite or NaN value, for the caller to judge).
fn number(value: &Value, idx: usize) -> Option<f64> {
    match value {
        Value::Byte(v) => v.get(idx).map(|&x| f64::from(x)),
        Value::Short(v) => v.get(idx).map(|&x| f64::from(x)),
        Value::Long(v) => v.get(idx).map(|&x| f64::from(x)),
        Value::SShort(v) => v.get(idx).map(|&x| f64::from(x)),
        Value::SLong(v) => v.get(idx).map(|&x| f64::from(x)),
        Value::Float(v) => v.get(idx).map(|&x| f64::from(x)),
        Value::Double(v) => v.get(idx).copied(),
        Value::Rational(v) => v.get(idx).map(|r| f64::from(r.n) / f64::from(r.d)),
        Value::SRational(v) => v.get(idx).map(|r| f64::from(r.n) / f64::from(r.d)),
        _ => None,
    }
}

/// The focal-plane resolution, the 35 mm equivalent focal length and a DNG's sizes (see the
/// module docs), from the root directory, its EXIF directory and a DNG's raw directory.
fn focal_plane_tags(meta: &mut ExposureMeta, root: &IFD, raw: Option<&IFD>) {
    let exif = root.get_sub_ifd(ExifTag::ExifOffset);
    // A tag from the EXIF directory, else from the root (TIFF/EP and some DNGs keep them there).
    let find = |tag: ExifTag| {
        exif.and_then(|e| e.get_entry(tag))
            .or_else(|| root.get_entry(tag))
    };
    // EXIF's tags first, TIFF/EP's where EXIF's are absent; the unit of the same family.
    let family = [
        (
            ExifTag::FocalPlaneXResolution2,
            ExifTag::FocalPlaneYResolution2,
            ExifTag::FocalPlaneResolutionUnit2,
        ),
        (
            ExifTag::FocalPlaneXResolution,
            ExifTag::FocalPlaneYResolution,
            ExifTag::FocalPlaneResolutionUnit,
        ),
    ]
    .into_iter()
    .find(|(x, _, _)| find(*x).is_some());
    if let Some((x, y, unit)) = family {
        let unit = find(unit)
            .and_then(|e| number(&e.value, 0))
            .map(|u| u16::try_from(u as i64).unwrap_or(u16::MAX));
        meta.focal_plane_resolution_unit = unit;
        if let Some(mm) = focal_plane_unit_mm(unit) {
            meta.focal_plane_px_per_mm_x =
                find(x).and_then(|e| number(&e.value, 0)).map(|v| v / mm);
            meta.focal_plane_px_per_mm_y =
                find(y).and_then(|e| number(&e.value, 0)).map(|v| v / mm);
        }
    }
    meta.focal_length_35mm_mm = find(ExifTag::FocalLengthIn35mmFormat)
        .and_then(|e| number(&e.value, 0))
        .filter(|&f| f != 0.0);
    if let Some(raw) = raw {
        let dim = |tag: TiffCommonTag| raw.get_entry(tag).and_then(|e| number(&e.value, 0));
        if let (Some(w), Some(h)) = (
            dim(TiffCommonTag::ImageWidth),
            dim(TiffCommonTag::ImageLength),
        ) {
            meta.sensor_size_px = Some((w as u32, h as u32));
        }
        meta.default_crop_size_px = raw
            .get_entry(DngTag::DefaultCropSize)
            .and_then(|e| Some((number(&e.value, 0)?, number(&e.value, 1)?)));
    }
}

/// The fields that need no validation, moved out of rawler's EXIF record.
fn exif_take(exif: &mut Exif) -> ExposureMeta {
    let clean = |s: Option<String>| {
        s.map(|s| s.trim_end_matches('\0').trim().to_string())
            .filter(|s| !s.is_empty())
    };
    ExposureMeta {
        lens_make: clean(exif.lens_make.take()),
        lens_model: clean(exif.lens_model.take()),
        body_serial: clean(exif.serial_number.take()),
        image_number: exif.image_number,
        iso: match (
            exif.iso_speed_ratings,
            exif.recommended_exposure_index,
            exif.iso_speed,
        ) {
            (Some(i), _, _) if i != u16::MAX => Some(u32::from(i)),
            (_, Some(rei), _) => Some(rei),
            (_, _, Some(s)) => Some(s),
            (Some(i), None, None) => Some(u32::from(i)),
            (None, None, None) => None,
        },
        ..ExposureMeta::default()
    }
}

/// Adds the validated fields (rationals, the capture time) and the camera names.
fn finish(
    path: &Path,
    mut meta: ExposureMeta,
    exif: &Exif,
    make: Option<String>,
    model: Option<String>,
) -> Result<ExposureMeta, RawError> {
    let bad = |tag: &'static str, value: String, problem: &'static str| RawError::BadExif {
        path: path.to_path_buf(),
        tag,
        value,
        problem,
    };
    let ratio = |tag: &'static str, r: Option<Rational>| -> Result<Option<f64>, RawError> {
        match r {
            None => Ok(None),
            Some(r) if r.d == 0 => Err(bad(tag, format!("{}/{}", r.n, r.d), "zero denominator")),
            Some(r) => Ok(Some(f64::from(r.n) / f64::from(r.d))),
        }
    };
    meta.exposure_time_s = ratio("ExposureTime", exif.exposure_time)?;
    meta.f_number = ratio("FNumber", exif.fnumber)?;
    meta.focal_length_mm = ratio("FocalLength", exif.focal_length)?;
    let nonempty = |s: Option<String>| s.filter(|s| !s.trim().is_empty());
    meta.camera_make = nonempty(make);
    meta.camera_model = nonempty(model);
    meta.capture_time = match &exif.date_time_original {
        None => None,
        Some(s) => match LocalDateTime::parse_exif(s) {
            Err(problem) => return Err(bad("DateTimeOriginal", s.clone(), problem)),
            Ok(None) => None,
            Ok(Some(local)) => {
                let subsec_digits = match &exif.sub_sec_time_original {
                    None => None,
                    Some(d) => {
                        let d = d.trim_end_matches('\0').trim();
                        if d.is_empty() {
                            None
                        } else if d.bytes().all(|c| c.is_ascii_digit()) && d.len() <= 9 {
                            Some(d.to_string())
                        } else {
                            return Err(bad(
                                "SubSecTimeOriginal",
                                d.to_string(),
                                "expected 1 to 9 decimal digits",
                            ));
                        }
                    }
                };
                let utc_offset_min = match &exif.offset_time_original {
                    None => None,
                    Some(o) => match parse_offset(o) {
                        Ok(v) => v,
                        Err(problem) => return Err(bad("OffsetTimeOriginal", o.clone(), problem)),
                    },
                };
                Some(CaptureTime {
                    local,
                    subsec_digits,
                    utc_offset_min,
                })
            }
        },
    };
    Ok(meta)
}

/// Parses EXIF's `±HH:MM` into minutes east of UTC; `Ok(None)` for blanks.
pub(crate) fn parse_offset(s: &str) -> Result<Option<i32>, &'static str> {
    let s = s.trim_end_matches('\0').trim();
    if s.is_empty() || s.chars().all(|c| matches!(c, ' ' | ':')) {
        return Ok(None);
    }
    let b = s.as_bytes();
    if b.len() != 6 || b[3] != b':' || !matches!(b[0], b'+' | b'-') {
        return Err("expected `+HH:MM` or `-HH:MM`");
    }
    let h: i32 = s[1..3].parse().map_err(|_| "expected `+HH:MM`")?;
    let m: i32 = s[4..6].parse().map_err(|_| "expected `+HH:MM`")?;
    if h > 14 || m > 59 {
        return Err("offset out of range");
    }
    let sign = if b[0] == b'-' { -1 } else { 1 };
    Ok(Some(sign * (h * 60 + m)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn dates_parse_and_reject() {
        let d = LocalDateTime::parse_exif("2025:03:04 05:06:07")
            .unwrap()
            .unwrap();
        assert_eq!(
            (d.year, d.month, d.day, d.hour, d.minute, d.second),
            (2025, 3, 4, 5, 6, 7)
        );
        assert_eq!(
            LocalDateTime::parse_exif("    :  :     :  :  ").unwrap(),
            None
        );
        assert_eq!(
            LocalDateTime::parse_exif("0000:00:00 00:00:00").unwrap(),
            None
        );
        assert!(LocalDateTime::parse_exif("2025:02:30 00:00:00").is_err());
        assert!(LocalDateTime::parse_exif("2025/03/04 05:06:07").is_err());
        assert!(LocalDateTime::parse_exif("yesterday").is_err());
        // 2000-03-01 is day 11017 after the epoch.
        let d = LocalDateTime::parse_exif("2000:03:01 00:00:00")
            .unwrap()
            .unwrap();
        assert_eq!(d.naive_seconds(), 11_017 * 86_400);
    }

    #[test]
    fn offsets_and_subseconds() {
        assert_eq!(parse_offset("+01:00"), Ok(Some(60)));
        assert_eq!(parse_offset("-05:30"), Ok(Some(-330)));
        assert_eq!(parse_offset("      "), Ok(None));
        assert!(parse_offset("01:00").is_err());
        let local = LocalDateTime::parse_exif("1970:01:01 01:00:00")
            .unwrap()
            .unwrap();
        let t = CaptureTime {
            local,
            subsec_digits: Some("045".into()),
            utc_offset_min: Some(60),
        };
        assert!((t.subsec_s() - 0.045).abs() < 1e-12);
        assert_eq!(t.unix_seconds(), Some(0.045));
        assert_eq!(t.naive_seconds(), 3600.045);
        let naive = CaptureTime {
            utc_offset_min: None,
            ..t
        };
        assert_eq!(naive.seconds(), 3600.045);
    }

    #[test]
    fn civil_dates_invert_naive_seconds() {
        for s in [0i64, 951_782_400, 1_795_168_800, 4_102_444_799, -86_401] {
            assert_eq!(
                LocalDateTime::from_naive_seconds(s).naive_seconds(),
                s,
                "{s}"
            );
        }
        let d = LocalDateTime::from_naive_seconds(951_782_400); // 2000-02-29
        assert_eq!((d.year, d.month, d.day), (2000, 2, 29));
    }

    proptest! {
        /// Consecutive days are 86400 s apart, across month, year and leap boundaries.
        #[test]
        fn days_are_contiguous(y in 1900i32..2200, m in 1u32..=12, d in 1u32..=28) {
            let a = days_from_civil(y, m, d);
            let b = days_from_civil(y, m, d + 1);
            prop_assert_eq!(b - a, 1);
            let next_month = if m == 12 { days_from_civil(y + 1, 1, 1) } else { days_from_civil(y, m + 1, 1) };
            let len = next_month - days_from_civil(y, m, 1);
            prop_assert!((28..=31).contains(&len));
        }
    }
}
