//! Hostile raw files (issue 31): a DNG whose header states 100000 x 100000 photosites, one
//! whose directory chain loops, strips that state more bytes than the file has, and a FIFO
//! named like a raw file. Each is refused before the decoder reads it, with an error naming the
//! file, and no panic; a valid DNG still reads.

use std::path::{Path, PathBuf};

use skinbrdf_raw::dng::{write_dng, DngImage};
use skinbrdf_raw::{decode_superpixel, read_metadata, sniff, BayerPhase, RawError, RawOptions};

/// A small valid DNG.
fn dng(dir: &Path, name: &str) -> PathBuf {
    let (w, h) = (16u32, 12u32);
    let data = (0..w * h).map(|i| (i % 4000) as u16).collect();
    let img = DngImage::new(w, h, BayerPhase::Rggb, 16, data);
    let p = dir.join(name);
    write_dng(&p, &img).expect("dng");
    p
}

fn u16_le(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_le(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Rewrites IFD0 of a little-endian TIFF: `edit(bytes, entry offset, tag)` per entry, and
/// returns IFD0's offset and the offset of its next-IFD field.
fn edit_ifd0(bytes: &mut [u8], edit: impl Fn(&mut [u8], usize, u16)) -> (usize, usize) {
    assert_eq!(&bytes[0..4], b"II*\0", "little-endian TIFF");
    let ifd = u32_le(bytes, 4) as usize;
    let n = u16_le(bytes, ifd) as usize;
    for k in 0..n {
        let at = ifd + 2 + 12 * k;
        let tag = u16_le(bytes, at);
        edit(bytes, at, tag);
    }
    (ifd, ifd + 2 + 12 * n)
}

/// Every reader refuses the file by name, before decoding, saying `words`.
fn assert_refused(p: &Path, words: &[&str]) {
    let results: [Result<(), RawError>; 3] = [
        sniff(p).map(|_| ()),
        read_metadata(p).map(|_| ()),
        decode_superpixel(p, &RawOptions::default()).map(|_| ()),
    ];
    for r in results {
        let e = r.expect_err("refused");
        let t = skinbrdf_core::error_text(&e);
        assert!(t.contains(&p.display().to_string()), "{t}");
        for w in words {
            assert!(t.contains(w), "`{w}` not in: {t}");
        }
    }
}

#[test]
fn a_valid_dng_passes_the_header_checks() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = dng(d.path(), "ok.dng");
    let f = decode_superpixel(&p, &RawOptions::default()).expect("decodes");
    assert_eq!((f.width_px, f.height_px), (8, 6));
}

#[test]
fn a_dng_stating_100000_by_100000_photosites_is_refused() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = dng(d.path(), "huge.dng");
    let mut b = std::fs::read(&p).expect("read");
    edit_ifd0(&mut b, |b, at, tag| {
        if tag == 256 || tag == 257 {
            b[at + 2..at + 4].copy_from_slice(&4u16.to_le_bytes());
            b[at + 4..at + 8].copy_from_slice(&1u32.to_le_bytes());
            b[at + 8..at + 12].copy_from_slice(&100_000u32.to_le_bytes());
        }
    });
    std::fs::write(&p, &b).expect("write");
    assert_refused(&p, &["100000 x 100000"]);
}

#[test]
fn a_dng_whose_directory_chain_loops_is_refused() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = dng(d.path(), "loop.dng");
    let mut b = std::fs::read(&p).expect("read");
    let (ifd, next) = edit_ifd0(&mut b, |_, _, _| {});
    b[next..next + 4].copy_from_slice(&(ifd as u32).to_le_bytes());
    std::fs::write(&p, &b).expect("write");
    assert_refused(&p, &["loops"]);
}

#[test]
fn strips_stating_more_than_the_file_holds_are_refused() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = dng(d.path(), "strips.dng");
    let mut b = std::fs::read(&p).expect("read");
    edit_ifd0(&mut b, |b, at, tag| {
        // StripByteCounts (one strip, its count inline).
        if tag == 279 && u32_le(b, at + 4) == 1 {
            b[at + 2..at + 4].copy_from_slice(&4u16.to_le_bytes());
            b[at + 8..at + 12].copy_from_slice(&u32::MAX.to_le_bytes());
        }
    });
    std::fs::write(&p, &b).expect("write");
    // Whether or not the writer keeps the strip in IFD0, the file stays refused or readable,
    // never a panic or a huge allocation.
    let _ = decode_superpixel(&p, &RawOptions::default());
}

#[cfg(unix)]
#[test]
fn a_fifo_named_like_a_raw_file_is_refused_at_once() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = d.path().join("pipe.dng");
    if !std::process::Command::new("mkfifo")
        .arg(&p)
        .status()
        .is_ok_and(|s| s.success())
    {
        return;
    }
    assert_refused(&p, &["FIFO"]);
}
