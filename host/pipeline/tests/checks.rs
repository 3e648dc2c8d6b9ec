//! The pipeline knows when its answer is bad: a session whose camera is to be calibrated and
//! whose stated focal length is four times off (a start the field-of-view search never made)
//! FAILS the calibration's check, the stages after it do not run, `process` returns the
//! failed check, and the written report says FAILED; `--accept-failed-checks` goes on. With the
//! focal length stated right, every check passes.
//!
//! Run with `cargo test --release` (ignored in debug builds: rendering takes minutes there).

use std::path::{Path, PathBuf};

use skinbrdf_ingest::{ingest, IngestConfig};
use skinbrdf_pipeline::checks::Outcome;
use skinbrdf_pipeline::process::{process, ProcessConfig, ProcessError};
use skinbrdf_pipeline::Stage;
use skinbrdf_session::{CameraSpec, Session};
use skinbrdf_synth::studio::STUDIO_DIR;
use skinbrdf_synth::Scene;

mod common;

/// The studio at half resolution with few measurement images, ingested with the measured rig
/// (no survey) and no camera file: the camera is to be calibrated. Returns the session.
fn to_be_calibrated_session(dir: &Path) -> PathBuf {
    let mut scene = Scene::load("default").expect("default scene");
    scene.session.measurement_images = 12;
    let s = common::half_resolution_studio(dir, &scene);
    let studio = s.join(STUDIO_DIR);
    let s2 = dir.join("S2");
    ingest(&IngestConfig::new(
        studio.join("card"),
        studio.join("capture.json"),
        studio.join("rig-measured.toml"),
        studio.join("scan.ply"),
        s2.clone(),
    ))
    .expect("ingest");
    s2
}

/// Writes `focal_guess_px` into the session's `[camera]` table.
fn state_focal_guess(session: &Path, focal_px: f64) {
    let path = session.join("session.toml");
    let text = std::fs::read_to_string(&path).expect("session.toml");
    let mut doc: toml::Table = toml::from_str(&text).expect("toml");
    let camera = doc
        .get_mut("camera")
        .and_then(toml::Value::as_table_mut)
        .expect("[camera]");
    camera.insert("focal_guess_px".into(), toml::Value::Float(focal_px));
    std::fs::write(&path, toml::to_string(&doc).expect("toml")).expect("write");
}

fn true_focal_px(session: &Path) -> f64 {
    let loaded = Session::load(session).expect("session");
    let CameraSpec::ToBeCalibrated { width_px, .. } = loaded.camera_as_stated(&loaded.file.camera)
    else {
        panic!("the camera is to be calibrated");
    };
    let scene = Scene::load("default").expect("default scene");
    0.5 * width_px as f64 / (0.5 * scene.camera.hfov_deg.to_radians()).tan()
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn a_focal_length_four_times_off_fails_its_check_and_stops_the_run() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s2 = to_be_calibrated_session(dir.path());
    let f_true = true_focal_px(&s2);

    // Stated right: every check passes and the run goes to the end.
    state_focal_guess(&s2, f_true * 1.08);
    let mut cfg = ProcessConfig::new();
    cfg.fit.figures = false;
    cfg.out_dir = Some(dir.path().join("out-right"));
    let out = process(&s2, &cfg, &mut |_| {}).expect("a right start passes its checks");
    let checks: Vec<_> = out.report.checks().map(|(_, c)| c.clone()).collect();
    assert!(checks.len() >= 5, "{checks:?}");
    assert!(
        checks.iter().all(|c| !c.failed()),
        "{:?}",
        out.report.failed_checks()
    );
    assert!(checks
        .iter()
        .any(|c| c.name == "focal_vs_files" && c.outcome == Outcome::Passed));

    // Four times short: the calibration FAILS its check; nothing after the pose unit runs.
    state_focal_guess(&s2, f_true / 4.0);
    cfg.out_dir = Some(dir.path().join("out-wrong"));
    let err = process(&s2, &cfg, &mut |_| {}).expect_err("a 4x wrong focal length must fail");
    let ProcessError::ChecksFailed { failed, report, .. } = &err else {
        panic!("expected failed checks, got {err}");
    };
    assert!(
        failed.iter().any(|c| c.name == "focal_vs_files"),
        "{failed:?}"
    );
    assert!(err.to_string().contains("likely cause"), "{err}");
    let md = std::fs::read_to_string(report).expect("the report is written");
    assert!(md.contains("**FAILED**"), "{md}");
    assert!(
        md.contains("not run: camera calibration FAILED its checks"),
        "{md}"
    );
    let out_wrong = dir.path().join("out-wrong");
    assert!(out_wrong.join("poses.json").is_file());
    assert!(!out_wrong.join("samples.skbs").exists(), "derender ran");

    // Run again: the pose unit is reused and checked again, with the same outcome.
    let again = process(&s2, &cfg, &mut |_| {}).expect_err("reused, still failed");
    assert!(
        matches!(again, ProcessError::ChecksFailed { .. }),
        "{again}"
    );

    // An expert goes on: the run ends, and the report still says FAILED.
    cfg.accept_failed_checks = true;
    let out = process(&s2, &cfg, &mut |_| {}).expect("--accept-failed-checks goes on");
    let calib = out
        .report
        .stages
        .iter()
        .find(|r| r.stage == Stage::CameraCalibration)
        .expect("calibration report");
    assert!(calib.failed());
    assert!(out_wrong.join("samples.skbs").is_file());
}
