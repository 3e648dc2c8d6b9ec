//! A small little-endian TIFF writer: directories of tagged values, sub-directories behind
//! pointer tags (e.g. the EXIF IFD) and one uncompressed strip of image data per directory.
//!
//! Layout: the 8-byte header, then for each directory its sub-directories (depth first), the
//! directory itself, the values that do not fit an entry's 4 bytes, and last its strip (so a
//! file cut short loses image data, which a reader can detect, rather than metadata). Every
//! directory and value starts at an even offset (TIFF's word alignment). Entries are written in
//! ascending tag order, as TIFF requires.

use std::collections::BTreeMap;

/// A tag's value (TIFF 6 field types).
#[derive(Debug, Clone, PartialEq)]
pub enum TagValue {
    /// BYTE (1).
    Byte(Vec<u8>),
    /// ASCII (2); the writer adds the terminating NUL.
    Ascii(String),
    /// SHORT (3).
    Short(Vec<u16>),
    /// LONG (4).
    Long(Vec<u32>),
    /// RATIONAL (5), numerator and denominator.
    Rational(Vec<(u32, u32)>),
    /// UNDEFINED (7).
    Undefined(Vec<u8>),
    /// SRATIONAL (10).
    SRational(Vec<(i32, i32)>),
}

impl TagValue {
    /// The TIFF field type code.
    pub const fn type_code(&self) -> u16 {
        match self {
            Self::Byte(_) => 1,
            Self::Ascii(_) => 2,
            Self::Short(_) => 3,
            Self::Long(_) => 4,
            Self::Rational(_) => 5,
            Self::Undefined(_) => 7,
            Self::SRational(_) => 10,
        }
    }

    /// The number of values (for ASCII: bytes including the NUL).
    pub fn count(&self) -> usize {
        match self {
            Self::Byte(v) | Self::Undefined(v) => v.len(),
            Self::Ascii(s) => s.len() + 1,
            Self::Short(v) => v.len(),
            Self::Long(v) => v.len(),
            Self::Rational(v) => v.len(),
            Self::SRational(v) => v.len(),
        }
    }

    /// The value's bytes, little-endian.
    pub fn bytes(&self) -> Vec<u8> {
        match self {
            Self::Byte(v) | Self::Undefined(v) => v.clone(),
            Self::Ascii(s) => {
                let mut b = s.as_bytes().to_vec();
                b.push(0);
                b
            }
            Self::Short(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Self::Long(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Self::Rational(v) => v
                .iter()
                .flat_map(|(n, d)| n.to_le_bytes().into_iter().chain(d.to_le_bytes()))
                .collect(),
            Self::SRational(v) => v
                .iter()
                .flat_map(|(n, d)| n.to_le_bytes().into_iter().chain(d.to_le_bytes()))
                .collect(),
        }
    }
}

/// One image file directory.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Directory {
    /// The entries by tag.
    pub entries: BTreeMap<u16, TagValue>,
    /// Sub-directories, each written behind a LONG pointer under its tag.
    pub subs: Vec<(u16, Directory)>,
    /// One uncompressed strip; the writer sets `StripOffsets` (273) and `StripByteCounts` (279).
    pub strip: Option<Vec<u8>>,
}

/// `StripOffsets`.
pub const TAG_STRIP_OFFSETS: u16 = 273;
/// `StripByteCounts`.
pub const TAG_STRIP_BYTE_COUNTS: u16 = 279;

impl Directory {
    /// Sets a tag (replacing any earlier value).
    pub fn set(&mut self, tag: u16, value: TagValue) -> &mut Self {
        self.entries.insert(tag, value);
        self
    }
}

fn align(buf: &mut Vec<u8>) {
    if buf.len() % 2 == 1 {
        buf.push(0);
    }
}

/// Offsets in a classic TIFF are 32-bit; larger files are refused by the caller.
fn offset32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// Appends `dir` (and what it points to) to `buf`; returns the directory's offset.
fn write_directory(buf: &mut Vec<u8>, dir: &Directory) -> u32 {
    let mut entries = dir.entries.clone();
    for (tag, sub) in &dir.subs {
        let off = write_directory(buf, sub);
        entries.insert(*tag, TagValue::Long(vec![off]));
    }
    if let Some(strip) = &dir.strip {
        // Patched once the strip's offset is known.
        entries.insert(TAG_STRIP_OFFSETS, TagValue::Long(vec![0]));
        entries.insert(
            TAG_STRIP_BYTE_COUNTS,
            TagValue::Long(vec![offset32(strip.len())]),
        );
    }
    align(buf);
    let start = buf.len();
    let dir_len = 2 + 12 * entries.len() + 4;
    let mut extra: Vec<u8> = Vec::new();
    let mut strip_offset_field = None;
    buf.extend_from_slice(&(entries.len().min(usize::from(u16::MAX)) as u16).to_le_bytes());
    for (tag, value) in &entries {
        let bytes = value.bytes();
        buf.extend_from_slice(&tag.to_le_bytes());
        buf.extend_from_slice(&value.type_code().to_le_bytes());
        buf.extend_from_slice(&offset32(value.count()).to_le_bytes());
        if *tag == TAG_STRIP_OFFSETS && dir.strip.is_some() {
            strip_offset_field = Some(buf.len());
        }
        if bytes.len() <= 4 {
            let mut field = [0u8; 4];
            field[..bytes.len()].copy_from_slice(&bytes);
            buf.extend_from_slice(&field);
        } else {
            align(&mut extra);
            let off = offset32(start + dir_len + extra.len());
            buf.extend_from_slice(&off.to_le_bytes());
            extra.extend_from_slice(&bytes);
        }
    }
    buf.extend_from_slice(&0u32.to_le_bytes());
    buf.extend_from_slice(&extra);
    if let (Some(strip), Some(field)) = (&dir.strip, strip_offset_field) {
        align(buf);
        let off = offset32(buf.len());
        buf[field..field + 4].copy_from_slice(&off.to_le_bytes());
        buf.extend_from_slice(strip);
    }
    offset32(start)
}

/// The bytes of a little-endian TIFF file whose first (only) directory is `ifd0`.
pub fn encode(ifd0: &Directory) -> Vec<u8> {
    let mut buf = b"II*\0\0\0\0\0".to_vec();
    let off = write_directory(&mut buf, ifd0);
    buf[4..8].copy_from_slice(&off.to_le_bytes());
    buf
}

#[cfg(test)]
mod tests {
    use super::*;
    use rawler::formats::tiff::reader::TiffReader;
    use rawler::formats::tiff::GenericTiffReader;

    #[test]
    fn rawler_reads_what_we_write() {
        let mut exif = Directory::default();
        exif.set(0x9003, TagValue::Ascii("2025:01:02 03:04:05".into()));
        exif.set(0x829a, TagValue::Rational(vec![(1, 125)]));
        let mut ifd0 = Directory::default();
        ifd0.set(256, TagValue::Long(vec![3]));
        ifd0.set(271, TagValue::Ascii("Maker".into()));
        ifd0.set(0xC621, TagValue::SRational(vec![(-1, 3); 9]));
        ifd0.set(0x828E, TagValue::Byte(vec![0, 1, 1, 2]));
        ifd0.subs.push((0x8769, exif));
        ifd0.strip = Some(vec![1, 2, 3]);
        let bytes = encode(&ifd0);
        let tiff =
            GenericTiffReader::new(&mut std::io::Cursor::new(&bytes), 0, 0, None, &[]).unwrap();
        let root = tiff.root_ifd();
        assert_eq!(
            root.get_entry(rawler::tags::TiffCommonTag::Make)
                .unwrap()
                .value
                .as_string()
                .unwrap(),
            "Maker"
        );
        let cm = root.entries().get(&0xC621).unwrap();
        assert_eq!(cm.count(), 9);
        let off = root
            .entries()
            .get(&TAG_STRIP_OFFSETS)
            .unwrap()
            .value
            .force_usize(0);
        assert_eq!(&bytes[off..off + 3], &[1, 2, 3]);
        let e = root.get_sub_ifd(rawler::tags::ExifTag::ExifOffset).unwrap();
        assert_eq!(
            e.entries().get(&0x9003).unwrap().value.as_string().unwrap(),
            "2025:01:02 03:04:05"
        );
    }
}
