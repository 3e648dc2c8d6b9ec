//! Running the stages one at a time gives what `process` gives: `skinbrdf poses S` then
//! `skinbrdf derender S` derender with the pose stage's poses (not the truth's), into the same
//! samples `skinbrdf process S` writes; `derender` before any pose stage is an error that says
//! which command to run; `--poses truth` is marked as such; `survey` on a session with every
//! placement given says so and writes nothing.
//!
//! One small sphere session (4 measurement images at 381 x 253). Ignored in debug builds
//! (rendering takes minutes there).

use std::path::Path;
use std::process::Command;

fn skinbrdf(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_skinbrdf"))
        .args(args)
        .output()
        .expect("run skinbrdf")
}

fn ok(args: &[&str]) -> String {
    let out = skinbrdf(args);
    assert!(
        out.status.success(),
        "skinbrdf {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn samples(path: &Path) -> Vec<[f32; 4]> {
    let bytes = std::fs::read(path).expect("samples file");
    // Compare the decoded samples' angles and values through the CSV the CLI can write would be
    // slower; the binary records after the header are the samples themselves.
    let n = u64::from_le_bytes(bytes[16..24].try_into().expect("count"));
    let header_len = u32::from_le_bytes(bytes[24..28].try_into().expect("len")) as usize;
    let record = u32::from_le_bytes(bytes[12..16].try_into().expect("record")) as usize;
    let start = 28 + header_len;
    (0..n as usize)
        .map(|i| {
            let r = &bytes[start + i * record..start + (i + 1) * record];
            let f = |k: usize| f32::from_le_bytes(r[4 * k..4 * k + 4].try_into().expect("f32"));
            [f(0), f(1), f(2), f(3)]
        })
        .collect()
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn poses_then_derender_equals_process() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = dir.path().join("small-sphere.toml");
    std::fs::write(
        &scene,
        "name = \"small-sphere\"\ndescription = \"test\"\n[geometry]\nkind = \"sphere\"\nroi_elevation_deg = 0.0\n[session]\nmeasurement_images = 4\n",
    )
    .expect("scene");
    let s = dir.path().join("s");
    let s_str = s.to_str().expect("utf-8 path");
    ok(&[
        "synth",
        "--scene",
        scene.to_str().expect("utf-8"),
        "--resolution",
        "381x253",
        "--out",
        s_str,
    ]);

    // Before any pose stage: an error naming the command to run.
    let early = skinbrdf(&["derender", s_str]);
    assert!(!early.status.success());
    let msg = String::from_utf8_lossy(&early.stderr);
    assert!(msg.contains("skinbrdf poses"), "{msg}");

    // Every placement is given: the survey has nothing to do and says so; a rig to write back
    // is refused with the plan's reason, and nothing is written.
    let text = ok(&["survey", s_str]);
    assert!(text.contains("nothing to survey"), "{text}");
    let rig_out = dir.path().join("rig-surveyed.toml");
    let refused = skinbrdf(&[
        "survey",
        s_str,
        "--rig",
        "rig.toml",
        "--write-rig",
        rig_out.to_str().expect("utf-8"),
    ]);
    assert!(!refused.status.success());
    let msg = String::from_utf8_lossy(&refused.stderr);
    assert!(msg.contains("no surveyed rig to write"), "{msg}");
    assert!(!rig_out.exists());

    ok(&["poses", s_str]);
    let text = ok(&["derender", s_str]);
    assert!(
        text.contains("poses from the pose stage"),
        "derender used the pose stage's poses:\n{text}"
    );
    let by_stage = samples(&s.join("out/samples.skbs"));

    let p = dir.path().join("p");
    ok(&[
        "process",
        s_str,
        "--out",
        p.to_str().expect("utf-8"),
        "--no-figures",
    ]);
    let by_process = samples(&p.join("samples.skbs"));
    assert!(!by_process.is_empty());
    assert_eq!(by_stage.len(), by_process.len(), "same number of samples");
    assert!(by_stage == by_process, "the same samples");

    // Truth only when asked, and said.
    let truth = skinbrdf(&[
        "derender",
        s_str,
        "--poses",
        "truth",
        "--out",
        dir.path().join("t").to_str().expect("utf-8"),
    ]);
    assert!(truth.status.success());
    assert!(String::from_utf8_lossy(&truth.stderr).contains("TRUE poses"));
}
