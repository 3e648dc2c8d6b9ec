//! LibRaw ([`skinbrdf_libraw`]) where rawler does not read a file.
//!
//! rawler stays the first reader: it decodes every file the synthetic studio writes and the
//! formats it supports, bit for bit as before. LibRaw reads:
//!
//! * the **header** (sizes, CFA) of a file rawler cannot decode or that is stripped or cut
//!   short: LibRaw identifies a file from its structure alone;
//! * the **photosites** of a file rawler cannot decode (an unsupported format or camera). A
//!   file refused before decoding (truncated, implausible, not raw) stays refused, and so does
//!   one whose image data LibRaw reports corrupt or short;
//! * the **metadata** of a file rawler cannot read, and what rawler leaves out: the make and
//!   model as written in containers without a TIFF root (CR3's CMT1 box, RAF's EXIF, MRW's TTW
//!   block), and the exposure fields of CRW, MRW and X3F.
//!
//! Levels read by LibRaw follow LibRaw: the black level of each CFA position (its common,
//! per-colour and per-position parts) and `maximum` as the white level; the bit depth is the
//! white level's (`floor(log2(white)) + 1`). A sensor that is not a 2x2 Bayer mosaic (Foveon,
//! X-Trans, linear, CMYG) is refused with [`RawError::UnsupportedLayout`] as rawler's are.

use std::path::Path;

use skinbrdf_libraw::{Header, LibRawError, RawFile};

use crate::assemble::{check_levels, crop, Geometry, Sensor};
use crate::bayer::{BayerPhase, CfaColour};
use crate::error::RawError;
use crate::exposure::{CaptureTime, ExposureMeta, LocalDateTime};
use crate::frame::{RawHeader, RawOptions};
use crate::identify::sniff_for_metadata;
use crate::kind::FileKind;
use crate::mosaic::{MosaicSamples, RawMosaic};

/// Why LibRaw gave no answer where rawler gave none either.
#[derive(Debug)]
pub(crate) enum Fallback {
    /// Our own checks refuse the file as LibRaw reads it (e.g. not a Bayer mosaic): final.
    Refused(RawError),
    /// LibRaw itself failed, in these words.
    LibRaw(String),
}

impl From<LibRawError> for Fallback {
    fn from(e: LibRawError) -> Self {
        Fallback::LibRaw(e.reason())
    }
}

/// The error when rawler failed (`rawler`) and LibRaw did too.
pub(crate) fn both_failed(rawler: RawError, libraw: Fallback) -> RawError {
    match (rawler, libraw) {
        (_, Fallback::Refused(e)) => e,
        (RawError::Decode { path, reason }, Fallback::LibRaw(words)) => RawError::Decode {
            path,
            reason: format!("{reason}; LibRaw: {words}"),
        },
        (RawError::Truncated { path, what }, Fallback::LibRaw(words)) => RawError::Truncated {
            path,
            what: format!("{what}; LibRaw: {words}"),
        },
        (other, Fallback::LibRaw(_)) => other,
    }
}

/// The Bayer phase of a LibRaw header, or the layout refused in words.
fn bayer_phase(path: &Path, h: &Header) -> Result<BayerPhase, RawError> {
    let refuse = |layout: String| RawError::UnsupportedLayout {
        path: path.to_path_buf(),
        layout,
    };
    let Some(cfa) = h.cfa.as_deref() else {
        return Err(refuse(if h.is_foveon {
            "Foveon (three layers, no CFA)".to_string()
        } else if h.filters == 9 {
            "X-Trans 6x6 CFA".to_string()
        } else if h.filters == 0 {
            "linear (no CFA)".to_string()
        } else {
            format!("a CFA LibRaw describes as {:#010x}", h.filters)
        }));
    };
    let colour = |c: char| match c {
        'R' => Some(CfaColour::Red),
        'G' => Some(CfaColour::Green),
        'B' => Some(CfaColour::Blue),
        _ => None,
    };
    let quad: Option<Vec<CfaColour>> = cfa.chars().map(colour).collect();
    quad.and_then(|q| BayerPhase::from_quad([*q.first()?, *q.get(1)?, *q.get(2)?, *q.get(3)?]))
        .ok_or_else(|| refuse(format!("2x2 CFA {cfa}")))
}

/// The active (visible) area of a LibRaw header, checked to lie on the sensor.
fn geometry(path: &Path, h: &Header) -> Result<Geometry, RawError> {
    let phase = bayer_phase(path, h)?;
    if h.width_px > h.raw_width_px || h.height_px > h.raw_height_px {
        // LibRaw's visible area of a Fujifilm SuperCCD is the sensor turned 45 degrees.
        return Err(RawError::UnsupportedLayout {
            path: path.to_path_buf(),
            layout: format!(
                "a rotated sensor (Fujifilm SuperCCD): a {}x{} visible area from a {}x{} mosaic",
                h.width_px, h.height_px, h.raw_width_px, h.raw_height_px
            ),
        });
    }
    let fits = h
        .left_margin_px
        .checked_add(h.width_px)
        .is_some_and(|r| r <= h.raw_width_px)
        && h.top_margin_px
            .checked_add(h.height_px)
            .is_some_and(|b| b <= h.raw_height_px);
    if !fits || h.width_px < 2 || h.height_px < 2 {
        return Err(RawError::Decode {
            path: path.to_path_buf(),
            reason: format!(
                "LibRaw's visible area {}x{} at ({}, {}) does not fit the {}x{} sensor",
                h.width_px,
                h.height_px,
                h.left_margin_px,
                h.top_margin_px,
                h.raw_width_px,
                h.raw_height_px
            ),
        });
    }
    Ok(Geometry {
        left: h.left_margin_px as usize,
        top: h.top_margin_px as usize,
        aw: h.width_px as usize,
        ah: h.height_px as usize,
        phase,
    })
}

/// Bits per sample of a white level (`floor(log2(white)) + 1`; 0 for none).
fn bits_of(white_level: f64) -> u32 {
    if white_level >= 1.0 && white_level.is_finite() {
        32 - (white_level.min(f64::from(u32::MAX)) as u32).leading_zeros()
    } else {
        0
    }
}

/// [`crate::read_raw_header`] by LibRaw.
pub(crate) fn header(path: &Path) -> Result<RawHeader, Fallback> {
    let kind = sniff_for_metadata(path).map_err(Fallback::Refused)?;
    let h = RawFile::open(path)?.header();
    let g = geometry(path, &h).map_err(Fallback::Refused)?;
    let to_u32 = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
    Ok(RawHeader {
        kind,
        width_px: to_u32(g.aw / 2),
        height_px: to_u32(g.ah / 2),
        bits_per_sample: bits_of(h.white_level),
        cfa: g.phase,
    })
}

/// [`crate::decode_mosaic`] by LibRaw, for a file of `kind` rawler could not decode.
pub(crate) fn decode(
    path: &Path,
    kind: FileKind,
    opts: &RawOptions,
) -> Result<RawMosaic, Fallback> {
    let p = RawFile::open(path)?.photosites()?;
    let h = &p.header;
    let g = geometry(path, h).map_err(Fallback::Refused)?;
    let black_levels = opts.black_levels.unwrap_or(h.black_levels);
    let white_level = opts.white_level.unwrap_or(h.white_level);
    check_levels(path, black_levels, white_level).map_err(Fallback::Refused)?;
    let sensor = Sensor {
        kind,
        width: h.raw_width_px as usize,
        height: h.raw_height_px as usize,
        bits_per_sample: bits_of(h.white_level) as usize,
    };
    Ok(crop(
        &p.values,
        &sensor,
        &g,
        black_levels,
        white_level,
        MosaicSamples::U16,
    ))
}

/// [`crate::read_metadata`] by LibRaw alone, for a raw file rawler cannot read.
pub(crate) fn metadata(path: &Path) -> Result<ExposureMeta, Fallback> {
    let mut meta = ExposureMeta::default();
    fill_metadata(path, &mut meta, Fill::Everything)?;
    Ok(meta)
}

/// Which fields [`fill_metadata`] may fill.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Fill {
    /// Every field rawler left empty, and the make and model as written where LibRaw met
    /// them (rawler gave its clean names: a container without a TIFF root).
    Everything,
    /// Only the exposure fields rawler left empty (a TIFF-rooted file: rawler read its make,
    /// model and capture time as written).
    Exposure,
}

/// Fills what rawler left out of `meta` with what LibRaw reads (see the module docs).
pub(crate) fn fill_metadata(
    path: &Path,
    meta: &mut ExposureMeta,
    fill: Fill,
) -> Result<(), Fallback> {
    let m = RawFile::open(path)?.metadata();
    meta.exposure_time_s = meta.exposure_time_s.or(m.exposure_time_s);
    meta.f_number = meta.f_number.or(m.f_number);
    meta.focal_length_mm = meta.focal_length_mm.or(m.focal_length_mm);
    meta.iso = meta.iso.or(m.iso.map(|i| i.round() as u32));
    if fill == Fill::Everything {
        if m.make_as_written.is_some() || meta.camera_make.is_none() {
            meta.camera_make = m.make_as_written.or(Some(m.make).filter(|s| !s.is_empty()));
        }
        if m.model_as_written.is_some() || meta.camera_model.is_none() {
            meta.camera_model = m
                .model_as_written
                .or(Some(m.model).filter(|s| !s.is_empty()));
        }
        if meta.capture_time.is_none() {
            meta.capture_time = m.capture_time.as_deref().and_then(capture_time);
        }
    }
    Ok(())
}

/// LibRaw's `YYYY:MM:DD HH:MM:SS` as a capture time (no sub-seconds, no offset); `None` for
/// a blank, zero or malformed value.
fn capture_time(text: &str) -> Option<CaptureTime> {
    LocalDateTime::parse_exif(text)
        .ok()
        .flatten()
        .map(|local| CaptureTime {
            local,
            subsec_digits: None,
            utc_offset_min: None,
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dng::{write_dng, DngImage};
    use crate::{decode_raw, BayerPhase, RawLayout};

    /// A DNG with a masked border, per-position black levels and a ramp of values.
    fn test_dng(dir: &Path, phase: BayerPhase, border: u32) -> std::path::PathBuf {
        let (w, h) = (48 + 2 * border, 36 + 2 * border);
        let data = (0..w * h).map(|i| (600 + (i * 37) % 3000) as u16).collect();
        let mut img = DngImage::new(w, h, phase, 12, data);
        img.black_levels = [256, 260, 250, 254];
        img.white_level = 4000;
        if border > 0 {
            img.active_area = Some([border, border, h - border, w - border]);
        }
        let path = dir.join(format!("{}-{border}.dng", phase.name()));
        write_dng(&path, &img).expect("write");
        path
    }

    /// Even active-area origins: LibRaw moves an odd origin to the next even photosite
    /// (`libraw_moves_an_odd_active_area_to_even`).
    #[test]
    fn libraw_decodes_our_dngs_as_rawler_does() {
        let dir = tempfile::tempdir().expect("tempdir");
        for (phase, border) in [
            (BayerPhase::Rggb, 0),
            (BayerPhase::Gbrg, 4),
            (BayerPhase::Bggr, 2),
        ] {
            let path = test_dng(dir.path(), phase, border);
            for layout in [RawLayout::Photosite, RawLayout::Superpixel] {
                let ours = decode_raw(&path, &RawOptions::default(), layout).expect("rawler");
                let Ok(theirs) =
                    decode(&path, FileKind::Dng, &RawOptions::default()).map(|m| m.frame(layout))
                else {
                    panic!("LibRaw decodes {}", path.display());
                };
                let what = format!("{} {layout:?}", path.display());
                assert_eq!(
                    (theirs.width_px, theirs.height_px),
                    (ours.width_px, ours.height_px),
                    "{what}"
                );
                assert_eq!(theirs.cfa, ours.cfa, "{what}");
                assert_eq!(theirs.black_levels, ours.black_levels, "{what}");
                assert_eq!(theirs.white_level, ours.white_level, "{what}");
                assert_eq!(
                    (
                        theirs.sensor_width_px,
                        theirs.sensor_height_px,
                        theirs.active_left_px,
                        theirs.active_top_px
                    ),
                    (
                        ours.sensor_width_px,
                        ours.sensor_height_px,
                        ours.active_left_px,
                        ours.active_top_px
                    ),
                    "{what}"
                );
                let same = theirs
                    .rgb
                    .iter()
                    .zip(&ours.rgb)
                    .all(|(a, b)| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()));
                assert!(
                    same && theirs.saturated == ours.saturated,
                    "{what}: values differ"
                );
            }
            let h = header(&path).expect("LibRaw header");
            let r = crate::read_raw_header(&path).expect("header");
            assert_eq!(
                (h.width_px, h.height_px, h.cfa),
                (r.width_px, r.height_px, r.cfa)
            );
        }
    }

    #[test]
    fn bit_depth_follows_the_white_level() {
        assert_eq!(bits_of(4095.0), 12);
        assert_eq!(bits_of(3983.0), 12);
        assert_eq!(bits_of(16383.0), 14);
        assert_eq!(bits_of(15872.0), 14);
        assert_eq!(bits_of(65535.0), 16);
        assert_eq!(bits_of(0.0), 0);
    }

    #[test]
    fn libraw_moves_an_odd_active_area_to_even() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = test_dng(dir.path(), BayerPhase::Gbrg, 3);
        let h = RawFile::open(&path).expect("LibRaw reads it").header();
        assert_eq!(
            (h.left_margin_px, h.top_margin_px, h.width_px, h.height_px),
            (4, 4, 47, 35)
        );
        assert_eq!(h.cfa.as_deref(), Some("GRBG"));
    }
}
