//! Damaged input through the `skinbrdf` binary: every kind of damage is a non-zero exit with a
//! message naming the file and the field, or (with `--skip-bad-images`) a skip listed in the
//! terminal summary and the report, never a silently changed result. The library-level cases
//! (each table's unknown keys, linearization, duplicates, sections a session does not need)
//! are in `host/session/tests/damaged.rs`.

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

#[test]
fn synth_values_out_of_range_are_errors_that_write_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("s");
    let o = skinbrdf(&[
        "synth",
        "--samples-per-pixel",
        "4294967295",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("sensor.samples_per_pixel"), "{t}");
    assert!(!out.exists(), "{t}");

    let scene = dir.path().join("many.toml");
    std::fs::write(&scene, "[session]\nmeasurement_images = 4294967295\n").expect("write");
    let o = skinbrdf(&[
        "synth",
        "--scene",
        scene.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("session.measurement_images"), "{t}");
    assert!(!out.exists(), "{t}");
}

/// The default scene stored as OpenEXR, processed end to end; then the same session damaged.
#[test]
fn an_exr_session_runs_end_to_end_and_damage_to_it_is_never_silent() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = dir.path().join("exr.toml");
    std::fs::write(&scene, "[sensor]\nencoding = \"exr\"\n").expect("write");
    let s = dir.path().join("s");
    let s_str = s.to_str().expect("utf-8");
    let o = skinbrdf(&[
        "synth",
        "--scene",
        scene.to_str().expect("utf-8"),
        "--out",
        s_str,
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(s.join("images/m01.exr").is_file());
    assert!(!s.join("images/m01.png").exists());

    let process = |extra: &[&str]| {
        let mut args = vec!["process", s_str, "--no-figures"];
        args.extend_from_slice(extra);
        skinbrdf(&args)
    };
    let o = process(&[]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    // Every pose stage found its targets in the float images (the light-position ones too).
    let report = std::fs::read_to_string(s.join("out/report.md")).expect("report.md");
    assert!(report.contains("flash triangulation | ran"), "{report}");
    // One file mode for every output (no temp-file default leaking through).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = |p: &str| std::fs::metadata(s.join(p)).expect(p).permissions().mode() & 0o777;
        assert_eq!(mode("scan.ply"), mode("session.toml"));
        assert_eq!(mode("out/samples.skbs"), mode("out/report.md"));
    }
    assert!(report.contains("| images_skipped | 0"), "{report}");

    // An unknown key in a core type's table is an error naming it.
    let toml_path = s.join("session.toml");
    let good = std::fs::read_to_string(&toml_path).expect("session.toml");
    std::fs::write(
        &toml_path,
        good.replace("[camera]\n", "[camera]\nk1 = 0.5\n"),
    )
    .expect("write");
    let o = process(&[]);
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(t.contains("`camera.k1`: unknown field"), "{t}");
    std::fs::write(&toml_path, &good).expect("write");

    // A truncated photograph: an error naming the file and the cause ...
    let m01 = s.join("images/m01.exr");
    let bytes = std::fs::read(&m01).expect("m01");
    std::fs::write(&m01, &bytes[..bytes.len() / 2]).expect("truncate");
    let o = process(&[]);
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(
        t.contains("images/m01.exr") && t.contains("cannot be decoded"),
        "{t}"
    );
    assert!(t.contains("--skip-bad-images"), "{t}");
    // ... and with --skip-bad-images a listed skip: terminal summary, report, first table.
    // (With -v, whose log goes to a pipe here: plain text, no colour codes.)
    let o = skinbrdf(&["-v", "process", s_str, "--no-figures", "--skip-bad-images"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("stage started"), "{t}");
    assert!(!stderr.contains('\x1b'), "colour codes in a piped log: {t}");
    assert!(t.contains("skipped image `images/m01.exr`"), "{t}");
    let report = std::fs::read_to_string(s.join("out/report.md")).expect("report.md");
    assert!(report.contains("| images_skipped | 1"), "{report}");
    assert!(report.contains("images/m01.exr"), "{report}");
}
