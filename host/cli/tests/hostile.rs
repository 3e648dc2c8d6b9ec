//! The raw decoder in a child process (issue 31): `ingest` decodes each raw file in
//! `skinbrdf internal-decode` under memory and time limits, so a file that makes the decoder
//! abort (an allocation failure cannot be caught) or hang fails only itself, as an error naming
//! the file, and the calling process goes on.

use std::path::{Path, PathBuf};
use std::time::Duration;

use skinbrdf_raw::dng::{write_dng, DngImage};
use skinbrdf_raw::{decoded_size_with, read_metadata_with, BayerPhase, Isolation, RawError};

fn isolation() -> Isolation {
    Isolation::new(
        PathBuf::from(env!("CARGO_BIN_EXE_skinbrdf")),
        vec!["internal-decode".into()],
    )
}

fn dng(dir: &Path) -> PathBuf {
    let (w, h) = (64u32, 48u32);
    let data = (0..w * h).map(|i| (i % 4000) as u16).collect();
    let p = dir.join("SKB_0001.DNG");
    write_dng(&p, &DngImage::new(w, h, BayerPhase::Rggb, 16, data)).expect("dng");
    p
}

#[test]
fn a_child_decodes_what_the_process_would() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = dng(d.path());
    let iso = isolation();
    assert_eq!(
        decoded_size_with(Some(&iso), &p).expect("size"),
        decoded_size_with(None, &p).expect("size")
    );
    assert_eq!(
        read_metadata_with(Some(&iso), &p).expect("meta"),
        read_metadata_with(None, &p).expect("meta")
    );
    // A refusal inside the child comes back as one error naming the file.
    let bad = d.path().join("cut.dng");
    std::fs::write(&bad, &std::fs::read(&p).expect("read")[..100]).expect("write");
    let e = decoded_size_with(Some(&iso), &bad).expect_err("refused");
    let t = skinbrdf_core::error_text(&e);
    assert!(t.contains("cut.dng") && !t.contains('\n'), "{t}");
}

#[test]
fn a_child_out_of_memory_fails_only_its_file() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = dng(d.path());
    // An address-space limit below what the program has already mapped: the decoder's first
    // allocation fails and the child aborts, as it would on a header asking for 34 GB.
    let iso = Isolation {
        max_memory_bytes: 1 << 20,
        ..isolation()
    };
    let e = decoded_size_with(Some(&iso), &p).expect_err("fails");
    let t = skinbrdf_core::error_text(&e);
    assert!(matches!(e, RawError::Decode { .. }), "{t}");
    assert!(t.contains("SKB_0001.DNG"), "{t}");
    // This process is still here, and the file decodes with the default limits.
    assert!(decoded_size_with(Some(&isolation()), &p).is_ok());
}

#[cfg(unix)]
#[test]
fn a_child_that_hangs_is_stopped_after_its_time() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = dng(d.path());
    // A program that never answers in time stands for a decoder caught in a loop.
    let iso = Isolation {
        program: PathBuf::from("sh"),
        args: vec!["-c".into(), "sleep 30".into()],
        max_memory_bytes: 1 << 30,
        timeout: Duration::from_millis(300),
    };
    let e = decoded_size_with(Some(&iso), &p).expect_err("stopped");
    let t = skinbrdf_core::error_text(&e);
    assert!(
        t.contains("SKB_0001.DNG") && t.contains("longer than"),
        "{t}"
    );
}
