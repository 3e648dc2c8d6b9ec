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
use crate::exposure::{parse_offset, CaptureTime, ExposureMeta, LocalDateTime};
use crate::identify::sniff_for_metadata;
use crate::kind::FileKind;
use crate::via_libraw;

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
