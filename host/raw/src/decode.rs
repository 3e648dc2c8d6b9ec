//! Decoding of Bayer raw files to linear values, per photosite or per 2x2 superpixel (see the
//! crate docs for the formula and the coordinate convention).
//!
//! # Levels
//!
//! The black level of each CFA position comes, in this order of precedence, from
//! [`RawOptions::black_levels`], else from the level `rawler` reports for the file: its camera
//! table's level where it has one for that camera, else the file's own black-level tags (DNG
//! `BlackLevel` with `BlackLevelRepeatDim`, the maker's tags for other formats), else the mean of
//! the sensor's masked (optically black) area where the format describes one, else zero. The
//! white level comes from [`RawOptions::white_level`], else from the file (DNG `WhiteLevel`,
//! else `2^BitsPerSample - 1`). DNG's black pattern is anchored at the active area's top-left
//! photosite (the DNG specification); other formats' patterns at the sensor's top-left.
//!
//! # Guarantees
//!
//! * `value = (raw - black_c) / (white - black_c)` exactly (computed in `f64`, stored as `f32`),
//!   with no clamping: noise below black stays negative, highlights above white exceed 1.
//! * A truncated file is refused ([`RawError::Truncated`]) rather than decoded with missing
//!   data: every strip or tile of a TIFF-based raw image must lie inside the file.
//! * Non-Bayer data is refused ([`RawError::UnsupportedLayout`]).

use std::io::{Read, Seek};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

use rawler::decoders::{RawDecodeParams, RawLoader};
use rawler::formats::tiff::reader::TiffReader;
use rawler::formats::tiff::{GenericTiffReader, IFD};
use rawler::rawimage::{RawImage, RawImageData, RawPhotometricInterpretation};
use rawler::rawsource::RawSource;
use rawler::tags::TiffCommonTag;

use crate::assemble::{assemble, check_levels, crop, Geometry, Sensor};
use crate::bayer::{BayerPhase, CfaColour};
use crate::error::RawError;
use crate::frame::{RawFrame, RawHeader, RawLayout, RawOptions};
use crate::identify::sniff;
use crate::kind::FileKind;
use crate::mosaic::{MosaicSamples, RawMosaic};

/// Raw images unpacked by this process so far (see [`decodes_started`]).
static DECODES: AtomicUsize = AtomicUsize::new(0);

/// How many times this process has started unpacking a raw file's image data: every
/// [`decode_raw`] and [`decode_mosaic`], and every [`read_raw_header`] that needs the decoder
/// (a file other than a DNG whose tags give the header). A measure of the work done, for tests
/// and benchmarks.
pub fn decodes_started() -> usize {
    DECODES.load(Ordering::Relaxed)
}

fn count_decode() {
    DECODES.fetch_add(1, Ordering::Relaxed);
}

/// The shared camera table (parsed once).
pub(crate) fn loader() -> &'static RawLoader {
    static LOADER: OnceLock<RawLoader> = OnceLock::new();
    LOADER.get_or_init(RawLoader::new)
}

/// Runs rawler on a file and turns a panic inside it into [`RawError::Decode`]: rawler reaches
/// `todo!()` and `expect` on some malformed or unusual files (an unknown photometric
/// interpretation in a DNG, a missing compression tag), and one bad photograph must be an
/// error naming the file, not the end of the program.
pub(crate) fn guarded<T>(
    path: &Path,
    f: impl FnOnce() -> Result<T, rawler::RawlerError>,
) -> Result<T, RawError> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r.map_err(|e| RawError::Decode {
            path: path.to_path_buf(),
            reason: e.to_string(),
        }),
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unsupported structure".into());
            Err(RawError::Decode {
                path: path.to_path_buf(),
                reason: format!("the raw decoder gave up ({what})"),
            })
        }
    }
}

/// Photometric interpretation of a colour filter array (TIFF/EP).
const PHOTOMETRIC_CFA: u16 = 32803;
/// Photometric interpretation of DNG linear raw data.
const PHOTOMETRIC_LINEAR_RAW: u16 = 34892;

/// Checks that every strip and tile of a TIFF-based file's raw images lies inside the file.
/// Every directory of a TIFF file: each of the chain and their sub-directories.
fn all_ifds(tiff: &GenericTiffReader) -> Vec<&IFD> {
    let mut ifds: Vec<&IFD> = Vec::new();
    for ifd in tiff.chains() {
        ifds.push(ifd);
        ifds.extend(ifd.sub_ifds().values().flatten());
    }
    ifds
}

fn check_tiff_extents(path: &Path, file_len: u64) -> Result<(), RawError> {
    let io = |source| RawError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut reader = std::io::BufReader::new(std::fs::File::open(path).map_err(io)?);
    let mut magic = [0u8; 4];
    if reader.read_exact(&mut magic).is_err() || !(&magic == b"II*\0" || &magic == b"MM\0*") {
        // Not a standard TIFF container (ORF, RW2, CR3, RAF...): the decoder checks.
        return Ok(());
    }
    reader.rewind().map_err(io)?;
    let tiff =
        GenericTiffReader::new(&mut reader, 0, 0, None, &[]).map_err(|e| RawError::Truncated {
            path: path.to_path_buf(),
            what: format!("TIFF structure unreadable ({e})"),
        })?;
    let is_raw = |ifd: &IFD| {
        ifd.get_entry(TiffCommonTag::PhotometricInt)
            .map(|e| e.force_u16(0))
            .is_some_and(|p| p == PHOTOMETRIC_CFA || p == PHOTOMETRIC_LINEAR_RAW)
    };
    for ifd in all_ifds(&tiff).into_iter().filter(|i| is_raw(i)) {
        for (offsets, counts, what) in [
            (
                TiffCommonTag::StripOffsets,
                TiffCommonTag::StripByteCounts,
                "strip",
            ),
            (
                TiffCommonTag::TileOffsets,
                TiffCommonTag::TileByteCounts,
                "tile",
            ),
        ] {
            let (Some(off), Some(cnt)) = (ifd.get_entry(offsets), ifd.get_entry(counts)) else {
                continue;
            };
            for i in 0..off.count().min(cnt.count()) as usize {
                let end = u64::from(off.force_u32(i)) + u64::from(cnt.force_u32(i));
                if end > file_len {
                    return Err(RawError::Truncated {
                        path: path.to_path_buf(),
                        what: format!(
                            "raw image {what} {i} ends at byte {end} but the file has {file_len} bytes"
                        ),
                    });
                }
            }
        }
    }
    Ok(())
}

/// Sniffs, checks the file's extents and maps it.
fn open_raw(path: &Path) -> Result<(FileKind, RawSource), RawError> {
    let kind = sniff(path)?;
    if !kind.is_raw() {
        return Err(RawError::NotRaw {
            path: path.to_path_buf(),
            actual: kind,
        });
    }
    let io = |source| RawError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file_len = std::fs::metadata(path).map_err(io)?.len();
    check_tiff_extents(path, file_len)?;
    Ok((kind, RawSource::new(path).map_err(io)?))
}

/// Decodes a Bayer raw file to superpixels (see the module and crate docs).
pub fn decode_superpixel(path: &Path, opts: &RawOptions) -> Result<RawFrame, RawError> {
    decode_raw(path, opts, RawLayout::Superpixel)
}

/// Decodes a Bayer raw file to one pixel per photosite, each with its own channel only (see
/// the crate docs).
pub fn decode_photosites(path: &Path, opts: &RawOptions) -> Result<RawFrame, RawError> {
    decode_raw(path, opts, RawLayout::Photosite)
}

/// Decodes a Bayer raw file in either layout.
/// A file rawler cannot decode (an unsupported format or camera, a panic inside it) is
/// decoded by LibRaw ([`crate::via_libraw`]); a file refused before decoding (truncated,
/// implausible, not raw) is not.
pub fn decode_raw(path: &Path, opts: &RawOptions, layout: RawLayout) -> Result<RawFrame, RawError> {
    let (kind, src) = open_raw(path)?;
    count_decode();
    match guarded(path, || {
        loader().decode(&src, &RawDecodeParams::default(), false)
    }) {
        Ok(image) => normalise(path, kind, &image, opts, layout),
        Err(rawler) => crate::via_libraw::decode(path, kind, opts)
            .map(|m| m.frame(layout))
            .map_err(|libraw| crate::via_libraw::both_failed(rawler, libraw)),
    }
}

/// Decodes a Bayer raw file to its compact [`RawMosaic`], with the same checks, levels and
/// fallback to LibRaw as [`decode_raw`]: `decode_mosaic(p, o)?.frame(layout)` is
/// `decode_raw(p, o, layout)`.
pub fn decode_mosaic(path: &Path, opts: &RawOptions) -> Result<RawMosaic, RawError> {
    let (kind, src) = open_raw(path)?;
    count_decode();
    match guarded(path, || {
        loader().decode(&src, &RawDecodeParams::default(), false)
    }) {
        Ok(image) => {
            let (g, sensor, black, white) = prepare(path, kind, &image, opts)?;
            Ok(match &image.data {
                RawImageData::Integer(d) => crop(d, &sensor, &g, black, white, MosaicSamples::U16),
                RawImageData::Float(d) => crop(d, &sensor, &g, black, white, MosaicSamples::F32),
            })
        }
        Err(rawler) => crate::via_libraw::decode(path, kind, opts)
            .map_err(|libraw| crate::via_libraw::both_failed(rawler, libraw)),
    }
}

/// The size of the image [`decode_superpixel`] would give, its bit depth and phase, with the
/// same layout checks (non-Bayer data is refused here too).
///
/// Where rawler cannot read it (an unsupported format, a file whose image data is stripped
/// or cut short), LibRaw reads the header from the file's structure ([`crate::via_libraw`]),
/// once the file's directories pass the same checks as for metadata: a header is then given
/// for a file that no decode will accept.
pub fn read_raw_header(path: &Path) -> Result<RawHeader, RawError> {
    match rawler_header(path) {
        Ok(h) => Ok(h),
        Err(
            rawler @ (RawError::Decode { .. }
            | RawError::Truncated { .. }
            | RawError::Implausible { .. }),
        ) => crate::via_libraw::header(path)
            .map_err(|libraw| crate::via_libraw::both_failed(rawler, libraw)),
        Err(e) => Err(e),
    }
}

/// [`read_raw_header`] by rawler alone.
fn rawler_header(path: &Path) -> Result<RawHeader, RawError> {
    let (kind, src) = open_raw(path)?;
    if kind == FileKind::Dng {
        if let Some(h) = dng_header(path) {
            return Ok(h);
        }
    }
    count_decode();
    let image = guarded(path, || {
        loader().decode(&src, &RawDecodeParams::default(), true)
    })?;
    let g = geometry(path, &image)?;
    let to_u32 = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
    Ok(RawHeader {
        kind,
        width_px: to_u32(g.aw / 2),
        height_px: to_u32(g.ah / 2),
        bits_per_sample: to_u32(image.bps),
        cfa: g.phase,
    })
}

/// A DNG's header from its tags alone, without unpacking the image (rawler's decoder unpacks
/// every photosite even when asked for the header only): the raw IFD (photometric CFA, full
/// resolution), its size, bit depth, active area and 2x2 `CFAPattern`, which the DNG
/// specification anchors at the active area's top-left photosite. `None` when any of it is
/// missing or not a one-sample 2x2 Bayer layout: the full decoder then checks and reports.
fn dng_header(path: &Path) -> Option<RawHeader> {
    let mut reader = std::io::BufReader::new(std::fs::File::open(path).ok()?);
    let tiff = GenericTiffReader::new(&mut reader, 0, 0, None, &[]).ok()?;
    let raw = all_ifds(&tiff).into_iter().find(|ifd| {
        let cfa = ifd
            .get_entry(TiffCommonTag::PhotometricInt)
            .is_some_and(|e| e.force_u16(0) == PHOTOMETRIC_CFA);
        let reduced = ifd
            .get_entry(TiffCommonTag::NewSubFileType)
            .is_some_and(|e| e.force_u32(0) & 1 != 0);
        cfa && !reduced
    })?;
    let get = |tag: TiffCommonTag| raw.get_entry(tag);
    let width = get(TiffCommonTag::ImageWidth)?.force_u32(0);
    let height = get(TiffCommonTag::ImageLength)?.force_u32(0);
    let bits = get(TiffCommonTag::BitsPerSample)?.force_u32(0);
    let spp = get(TiffCommonTag::SamplesPerPixel).map_or(1, |e| e.force_u32(0));
    if spp != 1 {
        return None;
    }
    let dim = get(TiffCommonTag::CFARepeatPatternDim)?;
    if dim.count() != 2 || dim.force_u32(0) != 2 || dim.force_u32(1) != 2 {
        return None;
    }
    let pattern = get(TiffCommonTag::CFAPattern)?;
    if pattern.count() != 4 {
        return None;
    }
    let colour = |i: usize| match pattern.force_u32(i) {
        0 => Some(CfaColour::Red),
        1 => Some(CfaColour::Green),
        2 => Some(CfaColour::Blue),
        _ => None,
    };
    let cfa = BayerPhase::from_quad([colour(0)?, colour(1)?, colour(2)?, colour(3)?])?;
    let (top, left, bottom, right) = match get(TiffCommonTag::ActiveArea) {
        Some(a) if a.count() == 4 => (
            a.force_u32(0),
            a.force_u32(1),
            a.force_u32(2),
            a.force_u32(3),
        ),
        Some(_) => return None,
        None => (0, 0, height, width),
    };
    if !(top < bottom && left < right && bottom <= height && right <= width) {
        return None;
    }
    Some(RawHeader {
        kind: FileKind::Dng,
        width_px: (right - left) / 2,
        height_px: (bottom - top) / 2,
        bits_per_sample: bits,
        cfa,
    })
}

/// The layout checks (Bayer, one sample per pixel, active area inside the sensor).
fn geometry(path: &Path, image: &RawImage) -> Result<Geometry, RawError> {
    let layout_err = |layout: String| RawError::UnsupportedLayout {
        path: path.to_path_buf(),
        layout,
    };
    if image.cpp != 1 {
        return Err(layout_err(format!(
            "linear (demosaiced or Foveon) data, {} samples per pixel",
            image.cpp
        )));
    }
    match &image.photometric {
        RawPhotometricInterpretation::Cfa(_) => {}
        RawPhotometricInterpretation::LinearRaw => {
            return Err(layout_err("linear raw, 1 sample per pixel (no CFA)".into()))
        }
        RawPhotometricInterpretation::BlackIsZero => {
            return Err(layout_err("monochrome (no CFA)".into()))
        }
    }
    let cfa = &image.camera.cfa;
    let (sw, sh) = (image.width, image.height);
    let (left, top, aw, ah) = match &image.active_area {
        Some(r) => (r.p.x, r.p.y, r.d.w, r.d.h),
        None => (0, 0, sw, sh),
    };
    if left + aw > sw || top + ah > sh || aw < 2 || ah < 2 {
        return Err(RawError::Decode {
            path: path.to_path_buf(),
            reason: format!(
                "active area {aw}x{ah} at ({left}, {top}) does not fit the {sw}x{sh} sensor"
            ),
        });
    }
    let describe_cfa = || {
        let name = if cfa.width == 6 && cfa.height == 6 {
            "X-Trans "
        } else {
            ""
        };
        format!("{name}{}x{} CFA {}", cfa.width, cfa.height, cfa.name)
    };
    if cfa.width == 0 || !cfa.width.is_multiple_of(2) || !cfa.height.is_multiple_of(2) {
        return Err(layout_err(describe_cfa()));
    }
    let colour = |c: usize| match c {
        0 => Some(CfaColour::Red),
        1 => Some(CfaColour::Green),
        2 => Some(CfaColour::Blue),
        _ => None,
    };
    // Colours of the active area's first quad, and a check that the pattern repeats every 2.
    let mut quad = [CfaColour::Green; 4];
    for (k, q) in quad.iter_mut().enumerate() {
        let (x, y) = (left + k % 2, top + k / 2);
        *q = colour(cfa.color_at(y, x)).ok_or_else(|| layout_err(describe_cfa()))?;
    }
    let periodic = (0..cfa.height)
        .all(|r| (0..cfa.width).all(|c| cfa.color_at(r, c) == cfa.color_at(r % 2, c % 2)));
    let phase = BayerPhase::from_quad(quad)
        .filter(|_| periodic)
        .ok_or_else(|| layout_err(describe_cfa()))?;
    Ok(Geometry {
        left,
        top,
        aw,
        ah,
        phase,
    })
}

/// The levels a decode uses: the overrides, else the file's (see the module docs).
fn levels(
    path: &Path,
    kind: FileKind,
    image: &RawImage,
    g: &Geometry,
    opts: &RawOptions,
) -> Result<([f64; 4], f64), RawError> {
    let black_levels = match opts.black_levels {
        Some(b) => b,
        None => file_black_levels(path, kind, image, g.left, g.top)?,
    };
    let white_level = match opts.white_level {
        Some(w) => w,
        None => match image.whitelevel.0.first() {
            Some(&w) => f64::from(w),
            None => {
                return Err(RawError::BadLevels {
                    path: path.to_path_buf(),
                    problem: "the file states no white level".into(),
                })
            }
        },
    };
    check_levels(path, black_levels, white_level)?;
    Ok((black_levels, white_level))
}

/// The superpixel or photosite computation on a decoded image.
fn normalise(
    path: &Path,
    kind: FileKind,
    image: &RawImage,
    opts: &RawOptions,
    layout: RawLayout,
) -> Result<RawFrame, RawError> {
    let (g, sensor, black, white) = prepare(path, kind, image, opts)?;
    Ok(match &image.data {
        RawImageData::Integer(d) => assemble(d, &sensor, &g, black, white, layout),
        RawImageData::Float(d) => assemble(d, &sensor, &g, black, white, layout),
    })
}

/// The checks of a decoded image (layout, levels, enough data for its sensor), giving its
/// active area, sensor and levels.
fn prepare(
    path: &Path,
    kind: FileKind,
    image: &RawImage,
    opts: &RawOptions,
) -> Result<(Geometry, Sensor, [f64; 4], f64), RawError> {
    let g = geometry(path, image)?;
    let (black_levels, white_level) = levels(path, kind, image, &g, opts)?;
    let sensor = Sensor {
        kind,
        width: image.width,
        height: image.height,
        bits_per_sample: image.bps,
    };
    let expected = sensor.width * sensor.height;
    let got = match &image.data {
        RawImageData::Integer(d) => d.len(),
        RawImageData::Float(d) => d.len(),
    };
    if got < expected {
        return Err(short_data(path, got, expected));
    }
    Ok((g, sensor, black_levels, white_level))
}

fn short_data(path: &Path, got: usize, expected: usize) -> RawError {
    RawError::Truncated {
        path: path.to_path_buf(),
        what: format!("the decoder gave {got} samples, the sensor has {expected}"),
    }
}

/// The file's black level per CFA position of the active quad (see the module docs).
fn file_black_levels(
    path: &Path,
    kind: FileKind,
    image: &RawImage,
    left: usize,
    top: usize,
) -> Result<[f64; 4], RawError> {
    let bl = &image.blacklevel;
    let levels = bl.as_vec();
    let (bw, bh) = (bl.width.max(1), bl.height.max(1));
    if levels.len() < bw * bh {
        return Err(RawError::BadLevels {
            path: path.to_path_buf(),
            problem: format!(
                "black level pattern {bw}x{bh} has only {} values",
                levels.len()
            ),
        });
    }
    // The pattern's origin relative to the active area's top-left photosite.
    let (ox, oy) = if kind == FileKind::Dng {
        (0, 0)
    } else {
        (left, top)
    };
    let at = |x: usize, y: usize| f64::from(levels[((y + oy) % bh) * bw + (x + ox) % bw]);
    let out = [at(0, 0), at(1, 0), at(0, 1), at(1, 1)];
    let periodic =
        (0..bh.max(2)).all(|y| (0..bw.max(2)).all(|x| at(x, y) == out[(y % 2) * 2 + x % 2]));
    if !periodic {
        return Err(RawError::BadLevels {
            path: path.to_path_buf(),
            problem: format!("black level pattern {bw}x{bh} does not repeat every 2 photosites"),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dng::{write_dng, DngImage};

    #[test]
    fn a_dng_header_is_read_from_its_tags_and_agrees_with_the_decoder() {
        let dir = tempfile::tempdir().expect("tempdir");
        for (phase, border) in [(BayerPhase::Rggb, 0u32), (BayerPhase::Gbrg, 3)] {
            let (w, h) = (40 + 2 * border, 30 + 2 * border);
            let mut img = DngImage::new(w, h, phase, 16, vec![1000; (w * h) as usize]);
            if border > 0 {
                img.active_area = Some([border, border, h - border, w - border]);
            }
            let path = dir.path().join(format!("b{border}.dng"));
            write_dng(&path, &img).expect("write");
            let fast = dng_header(&path).expect("the tags give the header");
            let full = decode_superpixel(&path, &RawOptions::default()).expect("decode");
            assert_eq!(
                (
                    fast.width_px,
                    fast.height_px,
                    fast.cfa,
                    fast.bits_per_sample
                ),
                (
                    full.width_px,
                    full.height_px,
                    full.cfa,
                    full.bits_per_sample
                )
            );
        }
    }

    #[test]
    fn a_panic_inside_the_decoder_is_an_error_naming_the_file() {
        let path = Path::new("card/SKB_0001.DNG");
        let err = guarded::<()>(path, || panic!("not yet implemented")).expect_err("caught");
        let msg = err.to_string();
        assert!(matches!(err, RawError::Decode { .. }), "{msg}");
        assert!(
            msg.contains("SKB_0001.DNG") && msg.contains("gave up"),
            "{msg}"
        );
    }
}
