//! `skinbrdf targets --detect`: the binary end to end on a real photo, and its error on a
//! missing image.

use std::path::{Path, PathBuf};
use std::process::Command;

fn photo_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/apriltag")
}

/// `(id, corners)` per line of a reference `.txt`, in the C library's convention.
fn reference(stem: &str) -> Vec<(u64, Vec<[f64; 2]>)> {
    let text = std::fs::read_to_string(photo_dir().join(format!("{stem}.txt"))).expect("txt");
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let n: Vec<f64> = l
                .replace(['(', ')', ','], " ")
                .split_whitespace()
                .map(|t| t.parse().expect("number"))
                .collect();
            (
                n[0] as u64,
                n[1..].chunks(2).map(|c| [c[0], c[1]]).collect(),
            )
        })
        .collect()
}

#[test]
fn reference_corners_from_the_binary_match_the_reference_library() {
    let stem = "33369213973_9d9bb4cc96_c";
    let out = Command::new(env!("CARGO_BIN_EXE_skinbrdf"))
        .args(["targets", "--corners", "reference", "--detect"])
        .arg(photo_dir().join(format!("{stem}.jpg")))
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON line");
    let dets = line["detections"].as_array().expect("detections");
    let corners = |d: &serde_json::Value| -> Vec<[f64; 2]> {
        d["corners_px"]
            .as_array()
            .expect("corners")
            .iter()
            .map(|c| {
                // Project convention -> the C library's (+0.5 px).
                [
                    c[0].as_f64().expect("x") + 0.5,
                    c[1].as_f64().expect("y") + 0.5,
                ]
            })
            .collect()
    };
    let refs = reference(stem);
    assert!(!refs.is_empty());
    for (id, rc) in &refs {
        let worst = dets
            .iter()
            .filter(|d| d["id"].as_u64() == Some(*id))
            .map(|d| {
                corners(d)
                    .iter()
                    .zip(rc)
                    .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
                    .fold(0.0, f64::max)
            })
            .fold(f64::MAX, f64::min);
        assert!(
            worst < 0.5,
            "tag {id} at {:?}: worst corner {worst} px",
            rc[0]
        );
    }
}

#[test]
fn a_missing_image_is_named_in_the_error() {
    let out = Command::new(env!("CARGO_BIN_EXE_skinbrdf"))
        .args(["targets", "--detect", "/nonexistent/photo.jpg"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/photo.jpg"), "{err}");
}
