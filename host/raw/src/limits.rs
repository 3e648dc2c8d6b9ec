//! Header checks made before a third-party decoder sees a file: a TIFF-based file's directory
//! structure is walked here, within the file's real length, and what it states is checked
//! against what the file can hold.
//!
//! The raw decoder (`rawler`) trusts a header's sizes and chains: a directory chain that loops
//! makes it run forever, and a header stating 100000 x 100000 photosites makes it ask for
//! 20 GB, which aborts the process (an allocation failure cannot be caught). So, for a TIFF
//! structure (DNG, CR2, NEF, ARW, PEF, ORF, RW2, plain TIFF):
//!
//! * the directory chain (`IFD0 -> next`, `SubIFDs`, the EXIF directory) is followed with a set
//!   of visited offsets: a loop, more than [`MAX_IFDS`] directories, or more than
//!   [`MAX_IFD_ENTRIES`] entries in one is refused;
//! * every directory and every value array lies inside the file (else the file is truncated);
//! * an image of more than [`MAX_PIXELS`] is refused;
//! * an image's strip or tile byte counts together fit in the file, and they hold the image:
//!   uncompressed data all its bits, lossless JPEG (compression 7) at least a bit per sample;
//! * Panasonic's RW2 states its sensor in tags 2 and 3: at least a bit per photosite must be
//!   in the file.
//!
//! Reading metadata only (`read_metadata`) skips the checks that the image data is in the file
//! (the last two), as it reads no image.
//!
//! Only a regular file is opened (a FIFO or device is refused at once, naming it).

use std::collections::HashSet;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use crate::RawError;

/// The most directories (IFDs) a file may have, all chains together.
pub const MAX_IFDS: usize = 256;
/// The most entries one directory may have.
pub const MAX_IFD_ENTRIES: u64 = 4096;
/// The largest image a header may state, pixels (the largest camera sensors have a few hundred
/// million photosites).
pub const MAX_PIXELS: u64 = 1 << 30;
/// How many bytes the values of all directories' entries may state together, per byte of the
/// file (plus [`VALUE_BYTES_SLACK`]): the raw decoder allocates every entry's values before
/// reading them, so entries pointing many times at the same bytes multiply what it allocates.
pub const VALUE_BYTES_PER_FILE_BYTE: u64 = 4;
/// Value bytes allowed beyond [`VALUE_BYTES_PER_FILE_BYTE`] times the file's length.
const VALUE_BYTES_SLACK: u64 = 1 << 20;
/// The most strips or tiles whose byte counts are read.
const MAX_STRIPS: u64 = 1 << 20;

const TAG_WIDTH: u16 = 256;
const TAG_HEIGHT: u16 = 257;
const TAG_BITS_PER_SAMPLE: u16 = 258;
const TAG_COMPRESSION: u16 = 259;
const TAG_SAMPLES_PER_PIXEL: u16 = 277;
const TAG_STRIP_BYTE_COUNTS: u16 = 279;
const TAG_TILE_BYTE_COUNTS: u16 = 325;
const TAG_SUB_IFDS: u16 = 330;
const TAG_EXIF_IFD: u16 = 34665;
const TAG_RW2_SENSOR_WIDTH: u16 = 2;
const TAG_RW2_SENSOR_HEIGHT: u16 = 3;
const COMPRESSION_NONE: u64 = 1;
const COMPRESSION_LOSSLESS_JPEG: u64 = 7;
/// TIFF's magic number; RW2's and ORF's variants.
const MAGIC_TIFF: u16 = 42;
const MAGIC_RW2: u16 = 0x55;
const MAGIC_ORF: [u16; 2] = [0x4F52, 0x5352];

/// Opens a file that a decoder will read: a regular file (a FIFO or device is refused by
/// name). Returns it and its length.
pub(crate) fn open_input(path: &Path) -> Result<(File, u64), RawError> {
    skinbrdf_core::untrusted::open_regular(path).map_err(|e| match e {
        skinbrdf_core::untrusted::ReadError::Io { path, source } => RawError::Io { path, source },
        other => RawError::Implausible {
            path: path.to_path_buf(),
            problem: other.reason(),
        },
    })
}

/// A TIFF structure's byte order.
#[derive(Clone, Copy)]
struct Order {
    little: bool,
}

impl Order {
    fn u16(self, b: &[u8]) -> u16 {
        let a = [b[0], b[1]];
        if self.little {
            u16::from_le_bytes(a)
        } else {
            u16::from_be_bytes(a)
        }
    }

    fn u32(self, b: &[u8]) -> u32 {
        let a = [b[0], b[1], b[2], b[3]];
        if self.little {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        }
    }
}

/// Bytes of one value of a TIFF field type (0: unknown type).
fn type_size(ty: u16) -> u64 {
    match ty {
        1 | 2 | 6 | 7 => 1,
        3 | 8 => 2,
        4 | 9 | 11 | 13 => 4,
        5 | 10 | 12 => 8,
        _ => 0,
    }
}

/// What one directory states about its image.
#[derive(Default)]
struct ImageTags {
    width: Option<u64>,
    height: Option<u64>,
    bits_per_sample: Option<u64>,
    samples_per_pixel: Option<u64>,
    compression: Option<u64>,
    data_bytes: Option<u64>,
    rw2_width: Option<u64>,
    rw2_height: Option<u64>,
}

struct Walker<'a> {
    file: &'a mut File,
    len: u64,
    order: Order,
    path: &'a Path,
    /// The bytes the entries' values read so far state, together.
    value_bytes: u64,
}

impl Walker<'_> {
    fn bad(&self, problem: String) -> RawError {
        RawError::Implausible {
            path: self.path.to_path_buf(),
            problem,
        }
    }

    /// `n` bytes at `offset`, which must lie inside the file.
    fn read_at(&mut self, offset: u64, n: u64, what: &str) -> Result<Vec<u8>, RawError> {
        if offset.checked_add(n).is_none_or(|end| end > self.len) {
            return Err(RawError::Truncated {
                path: self.path.to_path_buf(),
                what: format!(
                    "{what} at byte {offset} ({n} bytes) lies past the end of the file ({} bytes)",
                    self.len
                ),
            });
        }
        let io = |source| RawError::Io {
            path: self.path.to_path_buf(),
            source,
        };
        self.file.seek(SeekFrom::Start(offset)).map_err(io)?;
        let mut buf = vec![0u8; usize::try_from(n).unwrap_or(0)];
        self.file.read_exact(&mut buf).map_err(io)?;
        Ok(buf)
    }

    /// The values of an entry as integers (at most `max` of them are read).
    fn values(&mut self, entry: &[u8], max: u64) -> Result<Vec<u64>, RawError> {
        let o = self.order;
        let ty = o.u16(&entry[2..4]);
        let count = u64::from(o.u32(&entry[4..8]));
        let size = type_size(ty);
        if size == 0 || !matches!(ty, 1 | 3 | 4 | 13) {
            return Ok(Vec::new());
        }
        let total = count.saturating_mul(size);
        let bytes = if total <= 4 {
            entry[8..8 + usize::try_from(total).unwrap_or(0)].to_vec()
        } else {
            let tag = o.u16(&entry[0..2]);
            let at = u64::from(o.u32(&entry[8..12]));
            self.read_at(at, total, &format!("tag {tag}'s {count} values"))?
        };
        Ok(bytes
            .chunks_exact(usize::try_from(size).unwrap_or(1))
            .take(usize::try_from(max).unwrap_or(usize::MAX))
            .map(|c| match c.len() {
                1 => u64::from(c[0]),
                2 => u64::from(o.u16(c)),
                _ => u64::from(o.u32(c)),
            })
            .collect())
    }

    /// Reads the directory at `offset`: its image tags, the directories it points to, and the
    /// next directory's offset.
    fn directory(&mut self, offset: u64) -> Result<(ImageTags, Vec<u64>, u64), RawError> {
        let o = self.order;
        let head = self.read_at(offset, 2, "a directory")?;
        let n = u64::from(o.u16(&head));
        if n > MAX_IFD_ENTRIES {
            return Err(self.bad(format!(
                "the directory at byte {offset} states {n} entries, more than {MAX_IFD_ENTRIES}"
            )));
        }
        let body = self.read_at(offset + 2, 12 * n + 4, "a directory's entries")?;
        let mut tags = ImageTags::default();
        let mut children = Vec::new();
        for e in body.chunks_exact(12).take(usize::try_from(n).unwrap_or(0)) {
            let e = e.to_vec();
            self.check_value_bytes(&e)?;
            let first = |w: &mut Self| -> Result<Option<u64>, RawError> {
                Ok(w.values(&e, 1)?.first().copied())
            };
            match o.u16(&e[0..2]) {
                TAG_WIDTH => tags.width = first(self)?,
                TAG_HEIGHT => tags.height = first(self)?,
                TAG_BITS_PER_SAMPLE => tags.bits_per_sample = first(self)?,
                TAG_SAMPLES_PER_PIXEL => tags.samples_per_pixel = first(self)?,
                TAG_COMPRESSION => tags.compression = first(self)?,
                TAG_RW2_SENSOR_WIDTH => tags.rw2_width = first(self)?,
                TAG_RW2_SENSOR_HEIGHT => tags.rw2_height = first(self)?,
                TAG_STRIP_BYTE_COUNTS | TAG_TILE_BYTE_COUNTS => {
                    let counts = self.values(&e, MAX_STRIPS)?;
                    tags.data_bytes = Some(counts.iter().fold(0u64, |a, &c| a.saturating_add(c)));
                }
                TAG_SUB_IFDS | TAG_EXIF_IFD => {
                    children.extend(self.values(&e, MAX_IFDS as u64)?);
                }
                _ => {}
            }
        }
        let next = u64::from(o.u32(&body[body.len() - 4..]));
        Ok((tags, children, next))
    }

    /// Checks the bytes an entry's values state (a value of an unknown type counts one byte, as
    /// the decoder reads it): no array larger than the file, and all arrays together within
    /// [`VALUE_BYTES_PER_FILE_BYTE`] times the file's length.
    fn check_value_bytes(&mut self, entry: &[u8]) -> Result<(), RawError> {
        let o = self.order;
        let tag = o.u16(&entry[0..2]);
        let count = u64::from(o.u32(&entry[4..8]));
        let bytes = count.saturating_mul(type_size(o.u16(&entry[2..4])).max(1));
        if bytes <= 4 {
            return Ok(());
        }
        if bytes > self.len {
            return Err(RawError::Truncated {
                path: self.path.to_path_buf(),
                what: format!(
                    "tag {tag} states {count} values ({bytes} bytes), more than the file's {} \
                     bytes",
                    self.len
                ),
            });
        }
        self.value_bytes = self.value_bytes.saturating_add(bytes);
        let max = self
            .len
            .saturating_mul(VALUE_BYTES_PER_FILE_BYTE)
            .saturating_add(VALUE_BYTES_SLACK);
        if self.value_bytes > max {
            return Err(self.bad(format!(
                "its directories' values state more than {max} bytes together, \
                 {VALUE_BYTES_PER_FILE_BYTE} times the file's length"
            )));
        }
        Ok(())
    }

    /// Checks what one directory states against the file.
    /// With `image_data` false, only what bounds a reader of the directories themselves (the
    /// pixel count) is checked, not whether the image data is in the file.
    fn check_image(
        &self,
        at: u64,
        t: &ImageTags,
        rw2: bool,
        image_data: bool,
    ) -> Result<(), RawError> {
        if rw2 && image_data {
            if let (Some(w), Some(h)) = (t.rw2_width, t.rw2_height) {
                let px = w.saturating_mul(h);
                if px > MAX_PIXELS || px > self.len.saturating_mul(8) {
                    return Err(self.bad(format!(
                        "the header states a {w} x {h} sensor, which the file's {} bytes cannot \
                         hold",
                        self.len
                    )));
                }
            }
        }
        let (Some(w), Some(h)) = (t.width, t.height) else {
            return Ok(());
        };
        let px = w.saturating_mul(h);
        if px > MAX_PIXELS {
            return Err(self.bad(format!(
                "the directory at byte {at} states a {w} x {h} image, more than the {MAX_PIXELS} \
                 pixels any camera takes"
            )));
        }
        let Some(data) = t.data_bytes.filter(|_| image_data) else {
            return Ok(());
        };
        if data > self.len {
            return Err(RawError::Truncated {
                path: self.path.to_path_buf(),
                what: format!(
                    "the {w} x {h} image's strips or tiles state {data} bytes, more than the \
                     file's {}",
                    self.len
                ),
            });
        }
        let samples = px.saturating_mul(t.samples_per_pixel.unwrap_or(1).max(1));
        let need_bits = match t.compression.unwrap_or(COMPRESSION_NONE) {
            COMPRESSION_NONE => samples.saturating_mul(t.bits_per_sample.unwrap_or(1).max(1)),
            COMPRESSION_LOSSLESS_JPEG => samples,
            _ => 0,
        };
        if need_bits > data.saturating_mul(8) {
            return Err(self.bad(format!(
                "the {w} x {h} image needs at least {} bytes, its strips or tiles hold {data}",
                need_bits.div_ceil(8)
            )));
        }
        Ok(())
    }
}

/// Checks a TIFF-based file's structure (see the module docs); a file that is not TIFF-based
/// passes untouched.
pub(crate) fn check_tiff_structure(path: &Path) -> Result<(), RawError> {
    walk_tiff(path, true)
}

/// Checks a TIFF-based file's directories (chains, entry counts, value arrays, pixel count) but
/// not whether its image data is in the file: enough before reading its metadata, which a file
/// stripped of its image data (or cut short) still holds.
pub(crate) fn check_tiff_directories(path: &Path) -> Result<(), RawError> {
    walk_tiff(path, false)
}

fn walk_tiff(path: &Path, image_data: bool) -> Result<(), RawError> {
    let (mut file, len) = open_input(path)?;
    let mut head = [0u8; 8];
    if len < 8 || file.read_exact(&mut head).is_err() {
        return Ok(());
    }
    let order = match &head[0..2] {
        b"II" => Order { little: true },
        b"MM" => Order { little: false },
        _ => return Ok(()),
    };
    let magic = order.u16(&head[2..4]);
    if magic != MAGIC_TIFF && magic != MAGIC_RW2 && !MAGIC_ORF.contains(&magic) {
        return Ok(());
    }
    let mut w = Walker {
        file: &mut file,
        len,
        order,
        path,
        value_bytes: 0,
    };
    let mut visited: HashSet<u64> = HashSet::new();
    let mut pending = vec![u64::from(order.u32(&head[4..8]))];
    while let Some(at) = pending.pop() {
        if at == 0 {
            continue;
        }
        if !visited.insert(at) {
            return Err(w.bad(format!(
                "its directory chain loops (the directory at byte {at} is reached twice)"
            )));
        }
        if visited.len() > MAX_IFDS {
            return Err(w.bad(format!("more than {MAX_IFDS} directories")));
        }
        let (tags, children, next) = w.directory(at)?;
        w.check_image(at, &tags, magic == MAGIC_RW2, image_data)?;
        pending.push(next);
        pending.extend(children);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A directory entry `(tag, type, count, inline value)`.
    type Entry = (u16, u16, u32, u32);

    /// A little-endian TIFF: header, then one directory per `(entries, next)`.
    fn tiff(dirs: &[(Vec<Entry>, u32)]) -> Vec<u8> {
        let mut b = b"II*\0".to_vec();
        b.extend(8u32.to_le_bytes());
        for (entries, next) in dirs {
            b.extend((entries.len() as u16).to_le_bytes());
            for (tag, ty, count, value) in entries {
                b.extend(tag.to_le_bytes());
                b.extend(ty.to_le_bytes());
                b.extend(count.to_le_bytes());
                b.extend(value.to_le_bytes());
            }
            b.extend(next.to_le_bytes());
        }
        b
    }

    fn check(bytes: &[u8]) -> Result<(), RawError> {
        let d = tempfile::tempdir().expect("tempdir");
        let p = d.path().join("x.dng");
        std::fs::write(&p, bytes).expect("write");
        check_tiff_structure(&p)
    }

    #[test]
    fn a_small_honest_image_passes() {
        let entries = vec![
            (TAG_WIDTH, 3, 1, 2),
            (TAG_HEIGHT, 3, 1, 2),
            (TAG_BITS_PER_SAMPLE, 3, 1, 8),
            (TAG_STRIP_BYTE_COUNTS, 4, 1, 4),
        ];
        let mut b = tiff(&[(entries, 0)]);
        b.extend([0u8; 4]);
        check(&b).expect("passes");
    }

    #[test]
    fn a_huge_image_a_loop_and_a_short_strip_are_refused() {
        let huge = vec![(TAG_WIDTH, 4, 1, 100_000), (TAG_HEIGHT, 4, 1, 100_000)];
        let e = check(&tiff(&[(huge, 0)])).expect_err("refused");
        assert!(e.to_string().contains("100000 x 100000"), "{e}");
        // IFD0 at byte 8 points back at itself.
        let e = check(&tiff(&[(vec![(TAG_WIDTH, 3, 1, 2)], 8)])).expect_err("refused");
        assert!(e.to_string().contains("loops"), "{e}");
        let short = vec![
            (TAG_WIDTH, 3, 1, 64),
            (TAG_HEIGHT, 3, 1, 64),
            (TAG_BITS_PER_SAMPLE, 3, 1, 16),
            (TAG_STRIP_BYTE_COUNTS, 4, 1, 40),
        ];
        let mut b = tiff(&[(short, 0)]);
        b.extend([0u8; 40]);
        let e = check(&b).expect_err("refused");
        assert!(e.to_string().contains("8192 bytes"), "{e}");
    }

    #[test]
    fn values_stating_more_than_the_file_holds_are_refused() {
        // One entry stating 4 GiB of values (the decoder would allocate them before reading).
        let big = vec![(TAG_WIDTH, 3, 1, 2), (36864, 7, u32::MAX, 8)];
        let e = check(&tiff(&[(big, 0)])).expect_err("refused");
        assert!(e.to_string().contains("4294967295 values"), "{e}");
        // Many entries each stating the whole file: together more than the budget.
        let mut b = tiff(&[((0..4000).map(|_| (700u16, 7u16, 0, 8u32)).collect(), 0)]);
        let len = b.len() as u32 + 1000;
        b = tiff(&[(
            (0..4000).map(|_| (700u16, 7u16, len - 8, 8u32)).collect(),
            0,
        )]);
        b.extend(vec![0u8; 1000]);
        let e = check(&b).expect_err("refused");
        assert!(e.to_string().contains("together"), "{e}");
    }
}
