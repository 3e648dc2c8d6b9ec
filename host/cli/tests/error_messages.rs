//! Error messages through the `skinbrdf` binary: bad input is a non-zero exit whose message names
//! the file at fault and prints each cause once (every error either names its cause or exposes it
//! as its source, and `main` joins the chain with `{:#}`).

use std::path::Path;
use std::process::{Command, Output};

fn skinbrdf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_skinbrdf"))
        .args(args)
        .output()
        .expect("run skinbrdf")
}

fn text(o: &Output) -> String {
    format!(
        "exit {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A small synthetic session (fast to write and to process).
fn small_session(dir: &Path) -> String {
    let s = dir.join("s");
    let s_str = s.to_str().expect("utf-8").to_owned();
    let o = skinbrdf(&[
        "synth",
        "--resolution",
        "320x212",
        "--samples-per-pixel",
        "1",
        "--out",
        &s_str,
    ]);
    assert!(o.status.success(), "{}", text(&o));
    s_str
}

/// Runs `args`, expects a failure whose stderr names `file` and repeats no cause.
fn assert_fails_naming(args: &[&str], file: &str) {
    let o = skinbrdf(args);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        stderr.contains(file),
        "the message does not name {file}: {t}"
    );
    assert_each_cause_once(&stderr);
}

/// No cause (a `: `-separated part of the error line that is a phrase, not a bare path or a
/// number) occurs twice in stderr.
fn assert_each_cause_once(stderr: &str) {
    let line = stderr
        .lines()
        .find_map(|l| l.strip_prefix("error: "))
        .unwrap_or_else(|| panic!("no `error:` line in {stderr}"));
    for part in line.split(": ") {
        let part = part.trim();
        if !part.contains(' ') {
            continue;
        }
        assert_eq!(
            stderr.matches(part).count(),
            1,
            "`{part}` is printed more than once:\n{stderr}"
        );
    }
}

#[test]
fn a_malformed_session_file_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = small_session(dir.path());
    let toml = Path::new(&s).join("session.toml");
    let mut good = std::fs::read_to_string(&toml).expect("session.toml");
    good.push_str("\n[[images]\nfile = 3\n");
    std::fs::write(&toml, good).expect("write");
    assert_fails_naming(&["process", &s, "--no-figures"], "session.toml");
    assert_fails_naming(&["poses", &s], "session.toml");
}

#[test]
fn a_missing_image_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = small_session(dir.path());
    std::fs::remove_file(Path::new(&s).join("images/m03.png")).expect("remove");
    assert_fails_naming(&["process", &s, "--no-figures"], "images/m03.png");
    assert_fails_naming(&["derender", &s, "--poses", "truth"], "images/m03.png");
}

#[test]
fn a_scan_of_non_finite_vertices_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = small_session(dir.path());
    let ply = Path::new(&s).join("scan.ply");
    let mut bytes = std::fs::read(&ply).expect("scan.ply");
    let marker = b"end_header\n";
    let start = bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .expect("a PLY header")
        + marker.len();
    // Binary little-endian x, y, z floats per vertex: every x becomes NaN.
    let header = String::from_utf8_lossy(&bytes[..start]).into_owned();
    let vertices: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .and_then(|n| n.trim().parse().ok())
        .expect("a vertex count");
    for v in 0..vertices {
        let at = start + 12 * v;
        bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    }
    std::fs::write(&ply, bytes).expect("write");
    assert_fails_naming(&["derender", &s, "--poses", "truth"], "scan.ply");
    assert_fails_naming(&["process", &s, "--no-figures"], "scan.ply");
}

#[test]
fn a_file_that_is_not_a_session_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = small_session(dir.path());
    let root = Path::new(&s);
    // A session directory given as a file ...
    let scan = root.join("scan.ply");
    assert_fails_naming(
        &["process", scan.to_str().expect("utf-8"), "--no-figures"],
        "scan.ply",
    );
    // ... and a session.toml that holds another file's content.
    std::fs::copy(root.join("truth.json"), root.join("session.toml")).expect("copy");
    assert_fails_naming(&["process", &s, "--no-figures"], "session.toml");
    assert_fails_naming(&["poses", &s], "session.toml");
}
