//! The binary sample file (`.skbs`), version 2 (version 1 still reads).
//!
//! Layout (all integers and floats little-endian):
//!
//! | offset | size | field |
//! |-------:|-----:|-------|
//! | 0  | 8  | magic `b"SKBRDFS\0"` |
//! | 8  | 4  | `u32` format version (1 or 2; this build writes [`FORMAT_VERSION`] = 2) |
//! | 12 | 4  | `u32` record size in bytes (version 1: [`RECORD_SIZE_V1`] = 46; version 2: [`RECORD_SIZE`] = 66) |
//! | 16 | 8  | `u64` record count |
//! | 24 | 4  | `u32` provenance header length `H` in bytes |
//! | 28 | H  | provenance header: UTF-8 JSON of [`SampleHeader`] |
//! | 28+H | count x record size | records |
//!
//! One record:
//!
//! | offset | size | field | versions |
//! |-------:|-----:|-------|----------|
//! | 0  | 24 | `theta_i_rad, theta_e_rad, phi_d_rad, theta_h_rad, theta_diff_rad, phi_diff_rad` (6 x `f32`) | 1, 2 |
//! | 24 | 12 | `rho_r, rho_g, rho_b` (3 x `f32`, 1/sr) | 1, 2 |
//! | 36 | 4  | `weight` (`f32`) | 1, 2 |
//! | 40 | 2  | `image_index` (`u16`, `u16::MAX` = not from an image) | 1, 2 |
//! | 42 | 4  | `pixel_x, pixel_y` (2 x `u16`) | 1, 2 |
//! | 46 | 4  | `triangle` (`u32`, `u32::MAX` = no surface point) | 2 |
//! | 50 | 8  | `b1, b2` (2 x `f32`): barycentric weights of the triangle's second and third corner | 2 |
//! | 58 | 8  | `u, v` (2 x `f32`): the scan's texture coordinates at the point (NaN: none) | 2 |
//!
//! Angles follow [`skinbrdf_core::angles`]. A channel a partial sample did not measure (a
//! camera raw photosite measures one) is a NaN `rho` (bits kept as written). The surface point
//! is [`skinbrdf_core::SurfacePoint`] (triangle of the scan's loaded and repaired mesh, see
//! `docs/derender.md`); a version-1 record has none ([`skinbrdf_core::SurfacePoint::NONE`]).
//!
//! A reader rejects a wrong magic, an unknown version, a record size other than its version's,
//! a file shorter than its count and one with data past its count, each with an error naming
//! the file. The writer streams records through a temporary file in the target directory,
//! patches the count at the end and renames the file into place, so a reader never sees a
//! partial file.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use skinbrdf_core::{BrdfSample, SurfacePoint};

use crate::SamplesError;

/// First eight bytes of every sample file.
pub const MAGIC: [u8; 8] = *b"SKBRDFS\0";
/// The format version this build writes (it reads this and every version back to
/// [`OLDEST_FORMAT_VERSION`]).
pub const FORMAT_VERSION: u32 = 2;
/// The oldest format version this build reads.
pub const OLDEST_FORMAT_VERSION: u32 = 1;
/// Bytes per record of the version this build writes.
pub const RECORD_SIZE: usize = 66;
/// Bytes per record of version 1 (no surface point).
pub const RECORD_SIZE_V1: usize = 46;
/// Bytes before the provenance header.
const FIXED_HEADER: usize = 28;
/// Upper bound on the provenance header (a sanity check against corrupt length fields).
const MAX_HEADER_BYTES: u32 = 16 << 20;

/// Provenance of a sample file. Every field is optional on read so that later writers can add
/// fields without breaking older readers.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct SampleHeader {
    /// Where the samples come from: `derender`, `cornell`, `synth`, ...
    pub source: String,
    /// Free text (material, subject, treatment).
    pub description: String,
    /// The session directory or input file the samples were made from.
    pub origin: Option<String>,
    /// Program and version that wrote the file.
    pub created_by: String,
    /// Colour space of `rho` (e.g. `linear sRGB (D65)`).
    pub color_space: String,
    /// Number of source images, if any.
    pub image_count: Option<u32>,
    /// Calibration constant C per channel (method eq. 3), if derendered.
    pub calibration_c: Option<[f64; 3]>,
    /// Anything else a stage wants to record.
    pub extra: serde_json::Value,
}

impl SampleHeader {
    /// A header with a source and description; `created_by` names this crate.
    pub fn new(source: &str, description: &str) -> Self {
        Self {
            source: source.to_owned(),
            description: description.to_owned(),
            created_by: format!("skinbrdf-samples {}", env!("CARGO_PKG_VERSION")),
            color_space: "linear sRGB".to_owned(),
            ..Self::default()
        }
    }
}

/// Bytes per record of a format version, `None` for a version this build does not read.
pub fn record_size(version: u32) -> Option<usize> {
    match version {
        1 => Some(RECORD_SIZE_V1),
        2 => Some(RECORD_SIZE),
        _ => None,
    }
}

fn encode(s: &BrdfSample, out: &mut [u8; RECORD_SIZE]) {
    let floats = [
        s.theta_i_rad,
        s.theta_e_rad,
        s.phi_d_rad,
        s.theta_h_rad,
        s.theta_diff_rad,
        s.phi_diff_rad,
        s.rho[0],
        s.rho[1],
        s.rho[2],
        s.weight,
    ];
    for (i, f) in floats.iter().enumerate() {
        out[4 * i..4 * i + 4].copy_from_slice(&f.to_le_bytes());
    }
    out[40..42].copy_from_slice(&s.image_index.to_le_bytes());
    out[42..44].copy_from_slice(&s.pixel[0].to_le_bytes());
    out[44..46].copy_from_slice(&s.pixel[1].to_le_bytes());
    let p = &s.surface;
    out[46..50].copy_from_slice(&p.triangle.to_le_bytes());
    let floats = [p.barycentric[0], p.barycentric[1], p.uv[0], p.uv[1]];
    for (i, f) in floats.iter().enumerate() {
        out[50 + 4 * i..54 + 4 * i].copy_from_slice(&f.to_le_bytes());
    }
}

/// Decodes one record of a version-1 (`b.len() == 46`) or version-2 (`66`) file; the reader
/// hands only whole records of the file's own size.
fn decode(b: &[u8]) -> BrdfSample {
    let at4 = |o: usize| [b[o], b[o + 1], b[o + 2], b[o + 3]];
    let f = |i: usize| f32::from_le_bytes(at4(4 * i));
    let u = |o: usize| u16::from_le_bytes([b[o], b[o + 1]]);
    let surface = if b.len() >= RECORD_SIZE {
        let g = |o: usize| f32::from_le_bytes(at4(o));
        SurfacePoint {
            triangle: u32::from_le_bytes(at4(46)),
            barycentric: [g(50), g(54)],
            uv: [g(58), g(62)],
        }
    } else {
        SurfacePoint::NONE
    };
    BrdfSample {
        theta_i_rad: f(0),
        theta_e_rad: f(1),
        phi_d_rad: f(2),
        theta_h_rad: f(3),
        theta_diff_rad: f(4),
        phi_diff_rad: f(5),
        rho: [f(6), f(7), f(8)],
        weight: f(9),
        image_index: u(40),
        pixel: [u(42), u(44)],
        surface,
    }
}

/// Streaming writer. Records go to a temporary file next to the target; [`SampleWriter::finish`]
/// writes the count and renames the file into place. Dropping without `finish` leaves no file.
#[derive(Debug)]
pub struct SampleWriter {
    path: PathBuf,
    out: BufWriter<skinbrdf_core::fsio::AtomicFile>,
    count: u64,
    count_offset: u64,
}

impl SampleWriter {
    /// Starts a sample file at `path` (created atomically on [`finish`](Self::finish)).
    pub fn create(path: impl AsRef<Path>, header: &SampleHeader) -> Result<Self, SamplesError> {
        let path = path.as_ref().to_path_buf();
        let io_err = |source| SamplesError::Io {
            path: path.clone(),
            source,
        };
        let tmp = skinbrdf_core::fsio::AtomicFile::create(&path).map_err(|e| SamplesError::Io {
            path: e.path,
            source: e.source,
        })?;
        let mut out = BufWriter::with_capacity(1 << 20, tmp);
        let json =
            skinbrdf_core::json::to_vec(&path, header).map_err(|e| SamplesError::BadHeader {
                path: path.clone(),
                problem: format!("cannot serialise the provenance header: {}", e.problem()),
            })?;
        let header_len = u32::try_from(json.len())
            .ok()
            .filter(|&n| n <= MAX_HEADER_BYTES)
            .ok_or_else(|| SamplesError::BadHeader {
                path: path.clone(),
                problem: format!("provenance header of {} bytes is too large", json.len()),
            })?;
        let mut fixed = Vec::with_capacity(FIXED_HEADER);
        fixed.extend_from_slice(&MAGIC);
        fixed.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        fixed.extend_from_slice(&(RECORD_SIZE as u32).to_le_bytes());
        fixed.extend_from_slice(&0u64.to_le_bytes());
        fixed.extend_from_slice(&header_len.to_le_bytes());
        out.write_all(&fixed).map_err(io_err)?;
        out.write_all(&json).map_err(io_err)?;
        Ok(Self {
            path,
            out,
            count: 0,
            count_offset: 16,
        })
    }

    /// Appends one record.
    pub fn write(&mut self, sample: &BrdfSample) -> Result<(), SamplesError> {
        let mut rec = [0u8; RECORD_SIZE];
        encode(sample, &mut rec);
        self.out
            .write_all(&rec)
            .map_err(|source| SamplesError::Io {
                path: self.path.clone(),
                source,
            })?;
        self.count += 1;
        Ok(())
    }

    /// Appends many records.
    pub fn write_all(&mut self, samples: &[BrdfSample]) -> Result<(), SamplesError> {
        samples.iter().try_for_each(|s| self.write(s))
    }

    /// Records written so far.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Writes the record count, syncs and renames the file into place. Returns the count.
    pub fn finish(self) -> Result<u64, SamplesError> {
        let path = self.path;
        let io_err = |source| SamplesError::Io {
            path: path.clone(),
            source,
        };
        let mut tmp = self.out.into_inner().map_err(|e| io_err(e.into_error()))?;
        tmp.seek(SeekFrom::Start(self.count_offset))
            .map_err(io_err)?;
        tmp.write_all(&self.count.to_le_bytes()).map_err(io_err)?;
        tmp.commit().map_err(|e| SamplesError::Io {
            path: e.path,
            source: e.source,
        })?;
        Ok(self.count)
    }
}

/// Writes a whole sample file atomically.
pub fn write_samples(
    path: impl AsRef<Path>,
    header: &SampleHeader,
    samples: &[BrdfSample],
) -> Result<(), SamplesError> {
    let mut w = SampleWriter::create(path, header)?;
    w.write_all(samples)?;
    w.finish()?;
    Ok(())
}

/// Streaming reader: an iterator over records after a validated header.
#[derive(Debug)]
pub struct SampleReader {
    path: PathBuf,
    input: BufReader<File>,
    header: SampleHeader,
    version: u32,
    record_size: usize,
    count: u64,
    read: u64,
}

impl SampleReader {
    /// Opens and validates a sample file (magic, version, record size, length).
    pub fn open(path: impl AsRef<Path>) -> Result<Self, SamplesError> {
        let path = path.as_ref().to_path_buf();
        let io_err = |source| SamplesError::Io {
            path: path.clone(),
            source,
        };
        let file = File::open(&path).map_err(io_err)?;
        let file_len = file.metadata().map_err(io_err)?.len();
        let mut input = BufReader::with_capacity(1 << 20, file);
        let mut fixed = [0u8; FIXED_HEADER];
        if file_len < FIXED_HEADER as u64 {
            let mut found = [0u8; 8];
            let n = (file_len as usize).min(8);
            input.read_exact(&mut found[..n]).map_err(io_err)?;
            if found != MAGIC {
                return Err(SamplesError::BadMagic {
                    path,
                    found,
                    expected: MAGIC,
                });
            }
            return Err(SamplesError::BadHeader {
                path,
                problem: format!(
                    "file is {file_len} bytes, shorter than the {FIXED_HEADER}-byte header"
                ),
            });
        }
        input.read_exact(&mut fixed).map_err(io_err)?;
        let mut magic = [0u8; 8];
        magic.copy_from_slice(&fixed[0..8]);
        if magic != MAGIC {
            return Err(SamplesError::BadMagic {
                path,
                found: magic,
                expected: MAGIC,
            });
        }
        let u32_at =
            |o: usize| u32::from_le_bytes([fixed[o], fixed[o + 1], fixed[o + 2], fixed[o + 3]]);
        let version = u32_at(8);
        let Some(record_size) = record_size(version) else {
            return Err(SamplesError::UnsupportedVersion {
                path,
                found: version,
                supported: FORMAT_VERSION,
            });
        };
        let stated_size = u32_at(12);
        if stated_size as usize != record_size {
            return Err(SamplesError::BadHeader {
                path,
                problem: format!(
                    "record size {stated_size} bytes, expected {record_size} for version {version}"
                ),
            });
        }
        let mut count_bytes = [0u8; 8];
        count_bytes.copy_from_slice(&fixed[16..24]);
        let count = u64::from_le_bytes(count_bytes);
        let header_len = u32_at(24);
        if header_len > MAX_HEADER_BYTES || u64::from(header_len) + FIXED_HEADER as u64 > file_len {
            return Err(SamplesError::BadHeader {
                path,
                problem: format!(
                    "provenance header length {header_len} exceeds the file ({file_len} bytes)"
                ),
            });
        }
        let mut json = vec![0u8; header_len as usize];
        input.read_exact(&mut json).map_err(io_err)?;
        let header: SampleHeader =
            serde_json::from_slice(&json).map_err(|e| SamplesError::BadHeader {
                path: path.clone(),
                problem: format!("provenance header is not valid JSON: {e}"),
            })?;
        let body = file_len - FIXED_HEADER as u64 - u64::from(header_len);
        let found = body / record_size as u64;
        if found < count {
            return Err(SamplesError::Truncated {
                path,
                expected: count,
                found,
            });
        }
        let extra_bytes = body - count * record_size as u64;
        if extra_bytes > 0 {
            return Err(SamplesError::TrailingData {
                path,
                count,
                extra_bytes,
                extra_records: extra_bytes / record_size as u64,
            });
        }
        Ok(Self {
            path,
            input,
            header,
            version,
            record_size,
            count,
            read: 0,
        })
    }

    /// The file's format version (1 or 2; version-1 samples have no surface point).
    pub fn version(&self) -> u32 {
        self.version
    }

    /// The provenance header.
    pub fn header(&self) -> &SampleHeader {
        &self.header
    }

    /// Records announced by the header.
    pub fn record_count(&self) -> u64 {
        self.count
    }

    /// Reads up to `max` records into `out` (cleared first); returns how many were read.
    pub fn read_chunk(
        &mut self,
        out: &mut Vec<BrdfSample>,
        max: usize,
    ) -> Result<usize, SamplesError> {
        out.clear();
        let n = ((self.count - self.read) as usize).min(max);
        let mut buf = vec![0u8; n * self.record_size];
        self.input
            .read_exact(&mut buf)
            .map_err(|source| SamplesError::Io {
                path: self.path.clone(),
                source,
            })?;
        out.extend(buf.chunks_exact(self.record_size).map(decode));
        self.read += n as u64;
        Ok(n)
    }
}

impl Iterator for SampleReader {
    type Item = Result<BrdfSample, SamplesError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.read >= self.count {
            return None;
        }
        let mut rec = [0u8; RECORD_SIZE];
        let rec = &mut rec[..self.record_size];
        if let Err(source) = self.input.read_exact(rec) {
            self.read = self.count;
            return Some(Err(SamplesError::Io {
                path: self.path.clone(),
                source,
            }));
        }
        self.read += 1;
        Some(Ok(decode(rec)))
    }
}

/// Reads a whole sample file.
pub fn read_samples(
    path: impl AsRef<Path>,
) -> Result<(SampleHeader, Vec<BrdfSample>), SamplesError> {
    let mut r = SampleReader::open(path)?;
    let mut all = Vec::new();
    let n = usize::try_from(r.record_count()).unwrap_or(usize::MAX);
    r.read_chunk(&mut all, n)?;
    Ok((r.header, all))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sample(i: u32) -> BrdfSample {
        let a = skinbrdf_core::BrdfAngles::from_local(
            skinbrdf_core::BrdfAngles::canonical_directions(0.1 + 0.001 * i as f64, 0.7, 2.0).0,
            skinbrdf_core::BrdfAngles::canonical_directions(0.1, 0.7, 2.0).1,
        );
        let mut s = BrdfSample::from_angles(&a, [0.1 * i as f32, 0.2, 0.3]);
        s.image_index = (i % 7) as u16;
        s.pixel = [i as u16, (i * 3) as u16];
        s.weight = 0.5;
        s.surface = SurfacePoint {
            triangle: i * 11,
            barycentric: [0.001 * i as f32, 0.25],
            // Every third sample from a triangle without texture coordinates.
            uv: if i.is_multiple_of(3) {
                [f32::NAN; 2]
            } else {
                [0.5, 0.001 * i as f32]
            },
        };
        s
    }

    #[test]
    fn round_trip_streaming_and_whole() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("s.skbs");
        let mut h = SampleHeader::new("test", "round trip");
        h.calibration_c = Some([1.0, 2.0, 3.0]);
        let samples: Vec<_> = (0..1000).map(sample).collect();
        write_samples(&path, &h, &samples).expect("write");
        let (h2, back) = read_samples(&path).expect("read");
        assert_eq!(h, h2);
        assert_eq!(samples, back);
        let streamed: Vec<_> = SampleReader::open(&path)
            .expect("open")
            .collect::<Result<_, _>>()
            .expect("stream");
        assert_eq!(samples, streamed);
        let len = std::fs::metadata(&path).expect("meta").len();
        let hl = serde_json::to_vec(&h).expect("json").len() as u64;
        assert_eq!(len, 28 + hl + 1000 * RECORD_SIZE as u64);
    }

    #[test]
    fn partial_samples_round_trip() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("p.skbs");
        let samples: Vec<_> = (0..3)
            .map(|c| {
                let mut s = sample(c);
                s.rho = std::array::from_fn(|k| if k == c as usize { 0.4 } else { f32::NAN });
                s
            })
            .collect();
        write_samples(&path, &SampleHeader::new("test", "partial"), &samples).expect("write");
        let (_, back) = read_samples(&path).expect("read");
        for (a, b) in samples.iter().zip(&back) {
            assert_eq!(a.measured(), b.measured());
            assert_eq!(a.rho.map(f32::to_bits), b.rho.map(f32::to_bits));
        }
    }

    #[test]
    fn dropped_writer_leaves_no_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("s.skbs");
        let mut w = SampleWriter::create(&path, &SampleHeader::default()).expect("create");
        w.write(&sample(1)).expect("write");
        drop(w);
        assert!(!path.exists());
        assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 0);
    }

    #[test]
    fn bad_files_give_named_errors() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("bad.skbs");
        std::fs::write(&path, b"PNG\x89not a sample file at all, really not").expect("write");
        let e = SampleReader::open(&path).expect_err("bad magic");
        assert!(matches!(e, SamplesError::BadMagic { .. }));
        assert!(e.to_string().contains("bad.skbs"));

        let good = dir.path().join("good.skbs");
        write_samples(&good, &SampleHeader::default(), &[sample(1), sample(2)]).expect("write");
        let mut bytes = std::fs::read(&good).expect("read");
        bytes.truncate(bytes.len() - 10);
        std::fs::write(&path, &bytes).expect("write");
        let e = SampleReader::open(&path).expect_err("truncated");
        assert!(
            matches!(
                e,
                SamplesError::Truncated {
                    expected: 2,
                    found: 1,
                    ..
                }
            ),
            "{e}"
        );

        // Records past the header's count (a count never patched, or an append).
        let mut bytes = std::fs::read(&good).expect("read");
        let n = bytes.len();
        bytes.extend_from_within(n - 2 * RECORD_SIZE..n);
        bytes.push(0);
        std::fs::write(&path, &bytes).expect("write");
        let e = SampleReader::open(&path).expect_err("trailing data");
        assert!(
            matches!(
                e,
                SamplesError::TrailingData {
                    count: 2,
                    extra_records: 2,
                    extra_bytes: 133, // two 66-byte records and one byte
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("bad.skbs"), "{e}");

        let mut bytes = std::fs::read(&good).expect("read");
        bytes[8] = 9;
        std::fs::write(&path, &bytes).expect("write");
        let e = SampleReader::open(&path).expect_err("version");
        assert!(matches!(
            e,
            SamplesError::UnsupportedVersion { found: 9, .. }
        ));

        // A version-2 file claiming version 1's record size (and the other way round).
        let mut bytes = std::fs::read(&good).expect("read");
        bytes[12..16].copy_from_slice(&(RECORD_SIZE_V1 as u32).to_le_bytes());
        std::fs::write(&path, &bytes).expect("write");
        let e = SampleReader::open(&path).expect_err("record size");
        assert!(matches!(e, SamplesError::BadHeader { .. }), "{e}");
        assert!(e.to_string().contains("version 2"), "{e}");
        bytes[8..12].copy_from_slice(&1u32.to_le_bytes());
        bytes[12..16].copy_from_slice(&(RECORD_SIZE as u32).to_le_bytes());
        std::fs::write(&path, &bytes).expect("write");
        let e = SampleReader::open(&path).expect_err("record size");
        assert!(matches!(e, SamplesError::BadHeader { .. }), "{e}");
    }

    /// A version-1 file as the previous writer made it, byte by byte: two records after a
    /// `{}` provenance header.
    fn version_1_golden() -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(b"SKBRDFS\0");
        b.extend_from_slice(&[1, 0, 0, 0]); // version 1
        b.extend_from_slice(&[46, 0, 0, 0]); // record size
        b.extend_from_slice(&[2, 0, 0, 0, 0, 0, 0, 0]); // two records
        b.extend_from_slice(&[2, 0, 0, 0]); // header length
        b.extend_from_slice(b"{}");
        // Record 0: angles 0.5, 0.25, 1.0, 0.125, 0.375, 2.0; rho 0.1 (f32 bits 0x3dcccccd),
        // NaN, 0.3 (0x3e99999a); weight 1.0; image 3; pixel (640, 480).
        for f in [
            0x3f00_0000u32,
            0x3e80_0000,
            0x3f80_0000,
            0x3e00_0000,
            0x3ec0_0000,
            0x4000_0000,
            0x3dcc_cccd,
            0x7fc0_0000,
            0x3e99_999a,
            0x3f80_0000,
        ] {
            b.extend_from_slice(&f.to_le_bytes());
        }
        b.extend_from_slice(&[3, 0, 0x80, 0x02, 0xe0, 0x01]);
        // Record 1: all zero but image u16::MAX (not from an image) and weight 0.5.
        b.extend_from_slice(&[0; 36]);
        b.extend_from_slice(&0x3f00_0000u32.to_le_bytes());
        b.extend_from_slice(&[0xff, 0xff, 0, 0, 0, 0]);
        assert_eq!(b.len(), 28 + 2 + 2 * 46);
        b
    }

    #[test]
    fn version_1_files_still_read_without_a_surface_point() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("v1.skbs");
        std::fs::write(&path, version_1_golden()).expect("write");
        let r = SampleReader::open(&path).expect("open v1");
        assert_eq!(r.version(), 1);
        assert_eq!(r.record_count(), 2);
        let (header, back) = read_samples(&path).expect("read v1");
        assert_eq!(header, SampleHeader::default());
        let s = back[0];
        assert_eq!(
            [
                s.theta_i_rad,
                s.theta_e_rad,
                s.phi_d_rad,
                s.theta_h_rad,
                s.theta_diff_rad,
                s.phi_diff_rad
            ],
            [0.5, 0.25, 1.0, 0.125, 0.375, 2.0]
        );
        assert_eq!(s.rho[0], 0.1);
        assert!(s.rho[1].is_nan());
        assert_eq!(s.rho[2], 0.3);
        assert_eq!((s.weight, s.image_index, s.pixel), (1.0, 3, [640, 480]));
        assert_eq!(s.surface, SurfacePoint::NONE);
        assert_eq!(back[1].image_index, u16::MAX);
        assert_eq!(back[1].weight, 0.5);
        assert!(!back[1].surface.is_known());
        // Streaming gives the same (compared as text: the partial sample's NaN is not equal).
        let streamed: Vec<_> = SampleReader::open(&path)
            .expect("open")
            .collect::<Result<_, _>>()
            .expect("stream");
        assert_eq!(format!("{back:?}"), format!("{streamed:?}"));
        // A third record's worth of bytes past the count is trailing data at 46 bytes a record.
        let mut bytes = version_1_golden();
        bytes.extend_from_slice(&[0; 46]);
        std::fs::write(&path, &bytes).expect("write");
        let e = SampleReader::open(&path).expect_err("trailing");
        assert!(
            matches!(
                e,
                SamplesError::TrailingData {
                    extra_records: 1,
                    extra_bytes: 46,
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn version_2_records_keep_the_surface_point() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("v2.skbs");
        let mut s = sample(4);
        s.surface = SurfacePoint {
            triangle: 0x0102_0304,
            barycentric: [0.5, 0.25],
            uv: [1.0, 0.125],
        };
        write_samples(&path, &SampleHeader::default(), &[s, sample(3)]).expect("write");
        let bytes = std::fs::read(&path).expect("read");
        assert_eq!(&bytes[8..16], &[2, 0, 0, 0, 66, 0, 0, 0]);
        let hl = u32::from_le_bytes([bytes[24], bytes[25], bytes[26], bytes[27]]) as usize;
        let rec = &bytes[28 + hl..28 + hl + RECORD_SIZE];
        assert_eq!(&rec[46..50], &[4, 3, 2, 1]);
        assert_eq!(&rec[50..54], &0.5f32.to_le_bytes());
        assert_eq!(&rec[54..58], &0.25f32.to_le_bytes());
        assert_eq!(&rec[58..62], &1.0f32.to_le_bytes());
        assert_eq!(&rec[62..66], &0.125f32.to_le_bytes());
        let r = SampleReader::open(&path).expect("open");
        assert_eq!(r.version(), FORMAT_VERSION);
        let (_, back) = read_samples(&path).expect("read");
        assert_eq!(back, [s, sample(3)]);
        assert_eq!(back[1].surface.texture_uv(), None);
        assert!(back[1].surface.is_known());
    }

    proptest! {
        #[test]
        fn records_round_trip_bit_exactly(vals in proptest::collection::vec(any::<(f32, f32, u16, u16, u16)>(), 0..50)) {
            let samples: Vec<BrdfSample> = vals.iter().map(|&(a, b, i, x, y)| BrdfSample {
                theta_i_rad: a, theta_e_rad: b, phi_d_rad: a, theta_h_rad: b, theta_diff_rad: a,
                phi_diff_rad: b, rho: [a, b, a], image_index: i, pixel: [x, y], weight: b,
                surface: SurfacePoint {
                    triangle: u32::from(x) << 16 | u32::from(y),
                    barycentric: [b, a],
                    uv: [a, b],
                },
            }).collect();
            let mut rec = [0u8; RECORD_SIZE];
            for s in &samples {
                encode(s, &mut rec);
                let d = decode(&rec);
                prop_assert_eq!(d.theta_i_rad.to_bits(), s.theta_i_rad.to_bits());
                prop_assert_eq!(d.weight.to_bits(), s.weight.to_bits());
                prop_assert_eq!(d.pixel, s.pixel);
                prop_assert_eq!(d.image_index, s.image_index);
                prop_assert_eq!(d.surface.triangle, s.surface.triangle);
                prop_assert_eq!(d.surface.barycentric.map(f32::to_bits), s.surface.barycentric.map(f32::to_bits));
                prop_assert_eq!(d.surface.uv.map(f32::to_bits), s.surface.uv.map(f32::to_bits));
            }
        }

        /// Hostile bytes: a valid file (version 1 or 2) with bytes overwritten, or cut short,
        /// reads or is refused with an error, never a panic, and a file that opens reads every
        /// record it announces.
        #[test]
        fn damaged_files_never_panic(
            v1 in any::<bool>(),
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..8),
            cut in proptest::option::of(any::<prop::sample::Index>()),
        ) {
            let mut bytes = if v1 {
                version_1_golden()
            } else {
                let dir = tempfile::tempdir().expect("tempdir");
                let p = dir.path().join("g.skbs");
                write_samples(&p, &SampleHeader::new("t", "d"), &[sample(1), sample(2)]).expect("write");
                std::fs::read(&p).expect("read")
            };
            for (at, value) in edits {
                let i = at.index(bytes.len());
                bytes[i] = value;
            }
            if let Some(c) = cut {
                let n = c.index(bytes.len());
                bytes.truncate(n);
            }
            let dir = tempfile::tempdir().expect("tempdir");
            let path = dir.path().join("hostile.skbs");
            std::fs::write(&path, &bytes).expect("write");
            if let Ok(r) = SampleReader::open(&path) {
                let announced = r.record_count();
                let read: Vec<_> = r.collect::<Result<_, _>>().expect("an opened file reads");
                prop_assert_eq!(read.len() as u64, announced);
                let (_, all) = read_samples(&path).expect("an opened file reads whole");
                prop_assert_eq!(all.len() as u64, announced);
            }
        }
    }
}
