//! What a file is, from its content ([`sniff`]), and whether its name agrees
//! ([`check_extension`]).
//!
//! Magic numbers decide PNG, JPEG, OpenEXR and the raw formats with a container of their own
//! (RAF, CR3, CRW, MRW, X3F, ORF, RW2). A TIFF container is a raw file when it holds a
//! `DNGVersion` tag (DNG), the CR2 signature, or an image directory with a colour-filter-array
//! photometric interpretation (32803) or DNG's linear raw (34892); its format then follows the
//! `Make` tag. Any other TIFF is a plain TIFF image.

use std::io::{BufReader, Read, Seek};
use std::path::Path;

use rawler::formats::tiff::reader::TiffReader;
use rawler::formats::tiff::{GenericTiffReader, IFD};
use rawler::tags::{DngTag, TiffCommonTag};

use crate::error::RawError;
use crate::kind::FileKind;

/// How many leading bytes the magic-number checks look at.
const HEAD_LEN: usize = 64;

/// The file's kind from its content (see the module docs). A TIFF-based file's structure is
/// checked first, its image data included (see `limits`): a file this returns is safe to decode.
pub fn sniff(path: &Path) -> Result<FileKind, RawError> {
    sniff_checked(path, true)
}

/// [`sniff`] checking a TIFF-based file's directories only, not whether its image data is in
/// the file: for reading metadata, which a file stripped of its image still holds.
pub(crate) fn sniff_for_metadata(path: &Path) -> Result<FileKind, RawError> {
    sniff_checked(path, false)
}

fn sniff_checked(path: &Path, image_data: bool) -> Result<FileKind, RawError> {
    let io = |source| RawError::Io {
        path: path.to_path_buf(),
        source,
    };
    let (mut file, _) = crate::limits::open_input(path)?;
    let mut head = Vec::with_capacity(HEAD_LEN);
    file.by_ref()
        .take(HEAD_LEN as u64)
        .read_to_end(&mut head)
        .map_err(io)?;
    // A TIFF-based file's structure is checked before any decoder reads it.
    if image_data {
        crate::limits::check_tiff_structure(path)?;
    } else {
        crate::limits::check_tiff_directories(path)?;
    }
    if let Some(kind) = sniff_magic(&head) {
        return Ok(kind);
    }
    let is_tiff = head.len() >= 8 && (head.starts_with(b"II*\0") || head.starts_with(b"MM\0*"));
    if !is_tiff {
        return Err(RawError::UnrecognisedContent {
            path: path.to_path_buf(),
        });
    }
    if head.len() >= 10 && &head[8..10] == b"CR" {
        return Ok(FileKind::Cr2);
    }
    file.seek(std::io::SeekFrom::Start(0)).map_err(io)?;
    let mut reader = BufReader::new(file);
    let tiff =
        GenericTiffReader::new(&mut reader, 0, 0, None, &[]).map_err(|e| RawError::Truncated {
            path: path.to_path_buf(),
            what: format!("TIFF structure unreadable ({e})"),
        })?;
    Ok(classify_tiff(&tiff))
}

/// Kinds recognised by their leading bytes alone.
fn sniff_magic(head: &[u8]) -> Option<FileKind> {
    let at = |offset: usize, magic: &[u8]| {
        head.len() >= offset + magic.len() && &head[offset..offset + magic.len()] == magic
    };
    if at(0, b"\x89PNG\r\n\x1a\n") {
        Some(FileKind::Png)
    } else if at(0, &[0xFF, 0xD8, 0xFF]) {
        Some(FileKind::Jpeg)
    } else if at(0, &[0x76, 0x2F, 0x31, 0x01]) {
        Some(FileKind::OpenExr)
    } else if at(0, b"FUJIFILMCCD-RAW") {
        Some(FileKind::Raf)
    } else if at(4, b"ftypcrx ") {
        Some(FileKind::Cr3)
    } else if at(6, b"HEAPCCDR") {
        Some(FileKind::Crw)
    } else if at(0, b"\0MRM") {
        Some(FileKind::Mrw)
    } else if at(0, b"FOVb") {
        Some(FileKind::X3f)
    } else if at(0, b"IIRO") || at(0, b"IIRS") || at(0, b"MMOR") {
        Some(FileKind::Orf)
    } else if at(0, b"IIU\0") {
        Some(FileKind::Rw2)
    } else {
        None
    }
}

/// Photometric interpretation of a colour filter array (TIFF/EP).
const PHOTOMETRIC_CFA: u16 = 32803;
/// Photometric interpretation of DNG linear raw data.
const PHOTOMETRIC_LINEAR_RAW: u16 = 34892;

/// Raw or plain TIFF, and which raw format (see the module docs).
fn classify_tiff(tiff: &GenericTiffReader) -> FileKind {
    if tiff.has_entry(DngTag::DNGVersion) {
        return FileKind::Dng;
    }
    let raw_ifd = |ifd: &IFD| {
        ifd.get_entry(TiffCommonTag::PhotometricInt)
            .map(|e| e.force_u16(0))
            .is_some_and(|p| p == PHOTOMETRIC_CFA || p == PHOTOMETRIC_LINEAR_RAW)
    };
    let has_raw = tiff
        .chains()
        .iter()
        .any(|ifd| raw_ifd(ifd) || ifd.sub_ifds().values().flatten().any(raw_ifd));
    if !has_raw {
        return FileKind::Tiff;
    }
    let make = tiff
        .get_entry(TiffCommonTag::Make)
        .and_then(|e| e.value.as_string().map(|s| s.trim().to_ascii_uppercase()))
        .unwrap_or_default();
    let model = tiff
        .get_entry(TiffCommonTag::Model)
        .and_then(|e| e.value.as_string().map(|s| s.trim().to_ascii_uppercase()))
        .unwrap_or_default();
    if make.starts_with("NIKON") {
        // Nikon's compact cameras write NRW, whose Make is upper-case "NIKON" and whose model
        // is a Coolpix.
        if model.contains("COOLPIX") {
            FileKind::Nrw
        } else {
            FileKind::Nef
        }
    } else if make.starts_with("SONY") {
        FileKind::Arw
    } else if make.starts_with("CANON") {
        FileKind::Cr2
    } else if make.starts_with("PENTAX") || make.starts_with("RICOH") {
        FileKind::Pef
    } else if make.starts_with("SAMSUNG") {
        FileKind::Srw
    } else if make.starts_with("OLYMPUS") || make.starts_with("OM DIGITAL") {
        FileKind::Orf
    } else if make.starts_with("PANASONIC") || make.starts_with("LEICA") {
        FileKind::Rw2
    } else if make.starts_with("PHASE ONE") || make.starts_with("LEAF") {
        FileKind::Iiq
    } else {
        FileKind::OtherRaw
    }
}

/// Checks that a file's name agrees with its content `kind` (from [`sniff`]).
///
/// A raw file must carry one of its format's extensions (any raw extension for
/// [`FileKind::OtherRaw`]); a non-raw file must not carry a raw extension. Non-raw kinds among
/// themselves are not checked here (the image decoders read by content).
pub fn check_extension(path: &Path, kind: FileKind) -> Result<(), RawError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let named = FileKind::from_extension(&ext);
    let ok = match (kind.is_raw(), named) {
        (true, Some(n)) if n == kind => true,
        (true, Some(n)) => kind == FileKind::OtherRaw && n.is_raw(),
        (true, None) => false,
        (false, Some(n)) => !n.is_raw(),
        (false, None) => true,
    };
    if ok {
        return Ok(());
    }
    let named = match named {
        Some(n) => format!("{n} (extension .{ext})"),
        None if ext.is_empty() => "nothing (no extension)".to_string(),
        None => format!("an unknown kind (extension .{ext})"),
    };
    Err(RawError::WrongExtension {
        path: path.to_path_buf(),
        actual: kind,
        named,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn magic_numbers() {
        assert_eq!(sniff_magic(b"\x89PNG\r\n\x1a\n...."), Some(FileKind::Png));
        assert_eq!(sniff_magic(&[0xFF, 0xD8, 0xFF, 0xE1]), Some(FileKind::Jpeg));
        assert_eq!(
            sniff_magic(&[0x76, 0x2F, 0x31, 0x01, 2]),
            Some(FileKind::OpenExr)
        );
        assert_eq!(sniff_magic(b"FUJIFILMCCD-RAW 0201"), Some(FileKind::Raf));
        assert_eq!(
            sniff_magic(b"\0\0\0\x18ftypcrx \0\0\0\x01"),
            Some(FileKind::Cr3)
        );
        assert_eq!(sniff_magic(b"IIRO\x08\0\0\0"), Some(FileKind::Orf));
        assert_eq!(sniff_magic(b"IIU\0\x08\0\0\0"), Some(FileKind::Rw2));
        assert_eq!(sniff_magic(b"II*\0\x08\0\0\0"), None);
        assert_eq!(sniff_magic(b""), None);
    }

    #[test]
    fn extensions_checked_both_ways() {
        let ok = |p: &str, k| check_extension(Path::new(p), k).is_ok();
        assert!(ok("a/IMG_0001.DNG", FileKind::Dng));
        assert!(ok("a/x.dng", FileKind::Dng));
        assert!(ok("x.NEF", FileKind::Nef));
        assert!(ok("x.png", FileKind::Png));
        assert!(ok("x.tif", FileKind::Png));
        assert!(ok("x.weird", FileKind::Tiff));
        assert!(!ok("x.kdc", FileKind::OtherRaw));
        assert!(ok("x.dng", FileKind::OtherRaw));
        assert!(!ok("x.PNG", FileKind::Dng));
        assert!(!ok("x.DNG", FileKind::Png));
        assert!(!ok("x.cr2", FileKind::Nef));
        assert!(!ok("x", FileKind::Dng));
        let err = check_extension(Path::new("card/SKB_0001.PNG"), FileKind::Dng)
            .unwrap_err()
            .to_string();
        assert!(err.contains("card/SKB_0001.PNG"), "{err}");
        assert!(err.contains("is DNG"), "{err}");
        assert!(err.contains("says PNG"), "{err}");
    }
}
