//! Tags recorded through LibRaw's EXIF callback, and their values read from the file's bytes.
//!
//! LibRaw calls the callback for every entry of every TIFF or EXIF directory it parses
//! (in any container: CR3's CMT boxes, MRW's TTW block, RAF's embedded EXIF), with the tag
//! (directory tags carry `(directory + 1) << 20` in their high bits, EXIF tags none,
//! Panasonic's raw directory `0x30000`; GPS, interoperability and Kodak tags other values),
//! the type, the count, the byte order and the stream standing at the value.

/// TIFF tag Make.
pub(crate) const TAG_MAKE: u32 = 0x010f;
/// TIFF tag Model.
pub(crate) const TAG_MODEL: u32 = 0x0110;
/// EXIF tag DateTimeOriginal.
pub(crate) const TAG_DATE_TIME_ORIGINAL: u32 = 0x9003;
/// TIFF type ASCII.
const TYPE_ASCII: i32 = 2;
/// At most this many entries are recorded (only the tags above are, a few per directory).
pub(crate) const MAX_ENTRIES: usize = 1024;
/// High bits of GPS, interoperability and Kodak tags, which are not the camera's
/// directories.
const FOREIGN_HIGH_BITS: [u32; 3] = [0x20000, 0x40000, 0x50000];

/// One recorded tag: where its value lies in the file.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TagAt {
    /// The tag as LibRaw passed it, high bits included.
    pub tag: u32,
    pub type_: i32,
    pub count: i32,
    pub offset: i64,
}

/// The tags of interest, in the order LibRaw met them.
#[derive(Debug, Default)]
pub(crate) struct ExifTags {
    pub entries: Vec<TagAt>,
}

impl ExifTags {
    /// Whether the callback records `tag` (as LibRaw passes it).
    pub(crate) fn wants(tag: u32) -> bool {
        let low = tag & 0xffff;
        let high = tag & !0xffff;
        matches!(low, TAG_MAKE | TAG_MODEL | TAG_DATE_TIME_ORIGINAL)
            && !FOREIGN_HIGH_BITS.contains(&high)
    }

    /// The first ASCII value of `tag` (low 16 bits), as written: up to its first NUL, with
    /// surrounding white space trimmed; `None` when absent or empty.
    pub(crate) fn ascii(&self, bytes: &[u8], tag: u32) -> Option<String> {
        self.entries
            .iter()
            .filter(|t| t.tag & 0xffff == tag && t.type_ == TYPE_ASCII)
            .find_map(|t| ascii_at(bytes, t.offset, t.count))
    }
}

fn ascii_at(bytes: &[u8], offset: i64, count: i32) -> Option<String> {
    let start = usize::try_from(offset).ok()?;
    let len = usize::try_from(count).ok()?;
    let value = bytes.get(start..start.checked_add(len)?)?;
    let value = value.split(|b| *b == 0).next().unwrap_or_default();
    let text = String::from_utf8_lossy(value).trim().to_string();
    (!text.is_empty()).then_some(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directory_and_exif_tags_are_wanted_gps_and_kodak_are_not() {
        assert!(ExifTags::wants(TAG_MAKE | (1 << 20)));
        assert!(ExifTags::wants(TAG_MODEL | 0x30000));
        assert!(ExifTags::wants(TAG_DATE_TIME_ORIGINAL));
        assert!(!ExifTags::wants(TAG_MAKE | 0x40000));
        assert!(!ExifTags::wants(TAG_MAKE | 0x20000));
        assert!(!ExifTags::wants(0x0111 | (1 << 20)));
    }

    #[test]
    fn ascii_values_stop_at_nul_and_out_of_range_values_are_none() {
        let bytes = b"xxCanon\0junk";
        let tags = ExifTags {
            entries: vec![TagAt {
                tag: TAG_MAKE | (1 << 20),
                type_: TYPE_ASCII,
                count: 10,
                offset: 2,
            }],
        };
        assert_eq!(tags.ascii(bytes, TAG_MAKE).as_deref(), Some("Canon"));
        assert_eq!(tags.ascii(bytes, TAG_MODEL), None);
        assert_eq!(ascii_at(bytes, 8, 100), None);
        assert_eq!(ascii_at(bytes, -1, 2), None);
    }
}
