//! Every reader accepts what every writer writes: each JSON file the pipeline writes is written
//! with the writer the pipeline uses and read back with the reader the next stage or command
//! uses. JSON has no NaN: a quantity that was not estimated is written as `null` from an
//! `Option` and read back as `None`, and a NaN is refused by the writer with its field's path
//! (`skinbrdf_core::json`), never written as a `null` that a reader then refuses.
//!
//! The files of a `process` run are read back from one small synthetic session (the sphere
//! scene at a quarter of the pixels per axis, as in `resume.rs`); in a debug build that case is
//! ignored (rendering takes minutes there).

use std::collections::HashMap;
use std::path::Path;

use glam::{DQuat, DVec2, DVec3};
use skinbrdf_core::json::JsonError;
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_pipeline::ledger::{FingerprintBuilder, Ledger, Unit};
use skinbrdf_pipeline::process::{process, ProcessConfig, ProcessError};
use skinbrdf_pipeline::report::{RunReport, StageReport};
use skinbrdf_pipeline::stages::{
    derender_chosen, read_poses, DerenderOutputOptions, PoseSourceChoice, POSES_FILE,
};
use skinbrdf_pipeline::Stage;
use skinbrdf_poses::calib::{Calibration, PARAM_NAMES};
use skinbrdf_poses::session::{DetectedTag, ImagePoses, PoseWithCov};
use skinbrdf_poses::{BundleReport, HeadGauge, SessionPoses, Survey};
use skinbrdf_register::{AlignConfig, AlignKind, RegistrationMethod, RegistrationReport};
use skinbrdf_session::ImageRole;
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// Whether two JSON values are the same, numbers within a relative 1e-15: serde_json's default
/// float parser may read a number back one ulp off the one it wrote (its `float_roundtrip`
/// feature is exact), so a value read back is compared through its JSON form.
fn same_json(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => match (x.as_f64(), y.as_f64()) {
            (Some(x), Some(y)) => (x - y).abs() <= 1e-15 * x.abs().max(y.abs()),
            _ => x == y,
        },
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(x, y)| same_json(x, y))
        }
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len()
                && x.iter()
                    .all(|(k, v)| y.get(k).is_some_and(|w| same_json(v, w)))
        }
        _ => a == b,
    }
}

/// Asserts that `back` (read from a file) is `written`, up to the last bit of a float.
fn assert_reads_back<T: serde::Serialize + std::fmt::Debug>(back: &T, written: &T) {
    let json = |v: &T| serde_json::to_value(v).expect("JSON");
    assert!(
        same_json(&json(back), &json(written)),
        "read back {back:#?}\nwritten {written:#?}"
    );
}

fn estimated(pose: Pose, rms_px: f64) -> PoseWithCov {
    PoseWithCov {
        pose,
        covariance: (0..36)
            .map(|i| if i % 7 == 0 { 1e-8 } else { 0.0 })
            .collect(),
        rms_px,
        targets_used: 5,
        source: "estimated".into(),
    }
}

/// The pose stage's result for a camera it calibrated: k3 and the tangential terms were held
/// fixed (no sigma), the rest estimated.
fn calibrated_poses() -> SessionPoses {
    let camera = CameraModel::from_fov(1524, 1012, 48f64.to_radians());
    let mut sigma = [None; 9];
    for (i, name) in PARAM_NAMES.iter().enumerate() {
        if !matches!(*name, "p1" | "p2" | "k3") {
            sigma[i] = Some(0.01 * (i + 1) as f64);
        }
    }
    let image = |i: usize| ImagePoses {
        file: format!("images/m{i:02}.png"),
        role: ImageRole::Measurement,
        targets_found: HashMap::from([("reference".to_string(), 6), ("headdress".into(), 4)]),
        world_from_camera: Some(estimated(
            Pose::new(
                DQuat::from_rotation_y(0.1 * i as f64),
                DVec3::new(0.0, 0.0, 2.0),
            ),
            0.21,
        )),
        world_from_head: Some(estimated(Pose::IDENTITY, 0.3)),
        world_from_flash: None,
        world_from_standard: None,
        detect_ms: 12.5,
        pose_ms: 3.25,
        diagnostics: Vec::new(),
        errors: Vec::new(),
        detections: vec![DetectedTag {
            id: 7,
            layout: "reference".into(),
            corners_px: [
                DVec2::new(10.0, 10.0),
                DVec2::new(20.0, 10.0),
                DVec2::new(20.0, 20.0),
                DVec2::new(10.0, 20.0),
            ],
            corner_sigma_px: [0.05; 4],
            occluded_corners: [false; 4],
        }],
    };
    SessionPoses {
        camera,
        calibration: Some(Calibration {
            camera,
            sigma,
            rms_px: 0.08,
            views: vec![Pose::IDENTITY],
            points: 480,
            condition_number: 3.5e9,
        }),
        images: (0..4).map(image).collect(),
        light_position_m: Some(DVec3::new(0.5, -0.2, 1.5)),
        light_position_cov_m2: vec![1e-8, 0.0, 0.0, 0.0, 1e-8, 0.0, 0.0, 0.0, 1e-8],
        light_agreement: Some(skinbrdf_poses::LightAgreement {
            images: 3,
            reduced_chi2: 1.2,
            farthest_image: "img_032.dng".into(),
            farthest_offset_mm: 0.8,
        }),
        world_from_flash: None,
        world_from_standard: Some(PoseWithCov {
            pose: Pose::IDENTITY,
            covariance: Vec::new(),
            rms_px: 0.0,
            targets_used: 0,
            source: "known".into(),
        }),
        skipped: vec!["flash triangulation".into()],
        total_ms: 812.0,
        bundle: Some(BundleReport {
            initial_cost: 10.0,
            final_cost: 8.0,
            relative_improvement: 0.2,
            initial_rms_px: 0.3,
            final_rms_px: 0.2,
            observations: 96,
            parameters: 30,
            iterations: 4,
            variance_factor: 1.1,
            intrinsics_refined: true,
            time_ms: 40.0,
            ..BundleReport::default()
        }),
    }
}

#[test]
fn a_calibrated_cameras_poses_json_reads_back_as_derender_reads_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let poses = calibrated_poses();
    // `skinbrdf poses` writes through the session's writer, `process` through the checked
    // writer directly; `skinbrdf derender` and a resumed `process` read with `read_poses`.
    let by_command = dir.path().join("command").join(POSES_FILE);
    skinbrdf_session::write_json_atomic(&by_command, &poses).expect("written");
    let by_process = dir.path().join("process").join(POSES_FILE);
    skinbrdf_core::json::write_pretty(&by_process, &poses).expect("written");
    for file in [&by_command, &by_process] {
        let text = std::fs::read_to_string(file).expect("read");
        assert!(text.contains("null"), "held-fixed sigmas are null: {text}");
        let back = read_poses(file).expect("derender reads what the pose stage wrote");
        assert_eq!(back, poses);
        let cal = back.calibration.expect("calibration");
        assert_eq!(cal.sigma[8], None, "k3 was held fixed");
        assert!(cal.sigma[0].is_some());
    }
}

#[test]
fn a_nan_in_poses_is_refused_with_its_fields_path_and_the_old_file_stays() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join(POSES_FILE);
    let good = calibrated_poses();
    skinbrdf_session::write_json_atomic(&file, &good).expect("written");

    let mut bad = calibrated_poses();
    if let Some(c) = bad.images[3].world_from_camera.as_mut() {
        c.rms_px = f64::NAN;
    }
    match skinbrdf_session::write_json_atomic(&file, &bad) {
        Err(skinbrdf_session::FileError::JsonOut(JsonError::NonFinite {
            file: f, field, ..
        })) => {
            assert_eq!(f, file);
            assert_eq!(field, "images[3].world_from_camera.rms_px");
        }
        other => panic!("expected a refusal naming the field, got {other:?}"),
    }
    let mut bad = calibrated_poses();
    if let Some(c) = bad.calibration.as_mut() {
        c.sigma[2] = Some(f64::INFINITY);
    }
    let err = skinbrdf_core::json::write_pretty(&file, &bad).expect_err("infinite sigma");
    let text = skinbrdf_core::error_text(&err);
    assert!(text.contains(&*file.to_string_lossy()), "{text}");
    assert!(text.contains("calibration.sigma[2]"), "{text}");
    assert!(text.contains("inf"), "{text}");
    assert_eq!(read_poses(&file).expect("the old file"), good);
}

#[test]
fn survey_and_registration_json_read_back() {
    let dir = tempfile::tempdir().expect("tempdir");
    let camera = CameraModel::from_fov(1524, 1012, 48f64.to_radians());
    let survey = Survey {
        targets: Vec::new(),
        sheets: Vec::new(),
        issues: Vec::new(),
        head_gauge: HeadGauge::Provisional { anchor: 3 },
        camera,
        bundle: BundleReport::default(),
        bodies: 0,
        images_used: 0,
        survey_images_used: 0,
        timing: Default::default(),
        intrinsics_restart: false,
    };
    let file = dir.path().join("survey.json");
    skinbrdf_core::json::write_pretty(&file, &survey).expect("written");
    // The survey unit's `load` reads it with serde_json into a `Survey`.
    let back: Survey =
        serde_json::from_slice(&std::fs::read(&file).expect("read")).expect("a survey");
    assert_eq!(back, survey);

    // A registration's alignment states the threshold and robust median it used (once NaN
    // placeholders).
    let square = |id: u32, at: DVec3| -> (u32, [DVec3; 4]) {
        let h = 0.01;
        (
            id,
            [
                at + DVec3::new(-h, h, 0.0),
                at + DVec3::new(h, h, 0.0),
                at + DVec3::new(h, -h, 0.0),
                at + DVec3::new(-h, -h, 0.0),
            ],
        )
    };
    let survey_corners: Vec<_> = (0..4)
        .map(|i| {
            square(
                i,
                DVec3::new(0.05 * i as f64, 0.03 * (i % 2) as f64, 0.01 * i as f64),
            )
        })
        .collect();
    let shift = DVec3::new(0.1, 0.0, -0.02);
    let scan_corners: Vec<_> = survey_corners
        .iter()
        .map(|(id, c)| (*id, c.map(|p| p + shift)))
        .collect();
    let alignment = skinbrdf_register::align(
        &survey_corners,
        &scan_corners,
        AlignKind::Rigid,
        &AlignConfig::default(),
    )
    .expect("aligned");
    assert!(alignment.threshold_mm.is_finite() && alignment.robust_median_mm.is_finite());
    let reg = RegistrationReport {
        method: RegistrationMethod::Points,
        alignment,
        scan_targets: None,
        points_file: Some("points.csv".into()),
    };
    let file = dir.path().join("registration.json");
    skinbrdf_core::json::write_pretty(&file, &reg).expect("written");
    let back: RegistrationReport =
        serde_json::from_slice(&std::fs::read(&file).expect("read")).expect("a registration");
    assert_eq!(back, reg);
}

#[test]
fn a_ledger_reads_back_and_a_nan_figure_is_refused_by_name() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(dir.path().join("poses.json"), "{}").expect("write");
    let mut ledger = Ledger::default();
    let fp = FingerprintBuilder::new().bytes("x", b"1").finish();
    let report = StageReport::ran(Stage::CameraPoses, 1.5);
    ledger
        .record(
            Unit::Poses,
            fp.clone(),
            &["poses.json".to_string()],
            vec![report],
            dir.path(),
        )
        .expect("recorded");
    ledger.save(dir.path()).expect("saved");
    assert_eq!(Ledger::load(dir.path()).expect("loads"), ledger);

    let mut bad = ledger.clone();
    bad.record(
        Unit::Poses,
        fp,
        &["poses.json".to_string()],
        vec![StageReport::ran(Stage::CameraPoses, f64::NAN)],
        dir.path(),
    )
    .expect("recorded");
    let err = bad.save(dir.path()).expect_err("a NaN run time");
    let text = skinbrdf_core::error_text(&err);
    assert!(text.contains("ledger.json"), "{text}");
    assert!(text.contains("units.poses.reports[0]"), "{text}");
    assert_eq!(Ledger::load(dir.path()).expect("the old ledger"), ledger);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn every_file_a_process_run_writes_reads_back() {
    let dir = tempfile::tempdir().expect("tempdir");
    let session_dir = dir.path().join("session");
    let mut scene = Scene::load("sphere").expect("built-in scene");
    scene.session.measurement_images = 4;
    let quarter = (scene.camera.width_px / 4, scene.camera.height_px / 4);
    generate(
        &scene,
        &SynthOptions {
            resolution: Some(quarter),
            capture: None,
            noise_free: false,
            samples_per_pixel: None,
            studio: false,
            studio_only: false,
        },
        &session_dir,
    )
    .expect("synthesis");
    // truth.json: written by the generator, read by scoring.
    let truth = skinbrdf_session::Truth::load(&session_dir.join("truth.json")).expect("truth");
    assert!(!truth.images.is_empty());

    let out = process(&session_dir, &ProcessConfig::new(), &mut |_| {}).expect("process");
    let o = &out.out_dir;
    // poses.json, as `skinbrdf derender` and a resumed run read it.
    let poses = read_poses(&o.join(POSES_FILE)).expect("poses.json");
    assert_eq!(poses.images.len(), truth.images.len());
    // samples.skbs: its header's JSON (with the derender report) reads back.
    let (header, samples) =
        skinbrdf_samples::read_samples(o.join("samples.skbs")).expect("samples.skbs");
    assert!(!samples.is_empty());
    assert!(header.calibration_c.is_some());
    // fit/params.json: the head rendering's reader, and the whole fit report.
    let params = o.join("fit/params.json");
    skinbrdf_render::load_model(&params).expect("the rendering reads the fitted model");
    let fit: skinbrdf_fit::report::FitReport =
        serde_json::from_slice(&std::fs::read(&params).expect("read")).expect("a fit report");
    assert_reads_back(&fit, out.fit.as_ref().expect("a fit"));
    // report.json and the ledger.
    let report: RunReport =
        serde_json::from_slice(&std::fs::read(o.join("report.json")).expect("read"))
            .expect("a run report");
    assert_reads_back(&report, &out.report);
    let ledger = Ledger::load(o).expect("ledger.json");
    assert!(ledger.units.contains_key(&Unit::Poses));

    // `skinbrdf derender` from the pose stage's file: derender.json and the samples again.
    let session = skinbrdf_session::Session::load(&session_dir).expect("session");
    let again = dir.path().join("derender-out");
    let written = derender_chosen(
        &session,
        &PoseSourceChoice::Estimated(o.join(POSES_FILE)),
        &skinbrdf_derender::DerenderConfig::DEFAULT,
        &skinbrdf_pipeline::plan::PlanOptions::default(),
        &again,
        &DerenderOutputOptions::default(),
    )
    .expect("derender from poses.json");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&written.report_file).expect("read"))
            .expect("derender.json is JSON");
    assert!(report.get("report").is_some(), "{report}");
    skinbrdf_samples::read_samples(&written.samples_file).expect("samples");
}

#[test]
fn a_process_error_from_the_writer_names_file_and_field() {
    // The pipeline maps the checked writer's error into its own, keeping the message.
    let err: ProcessError = JsonError::NonFinite {
        file: Path::new("out/poses.json").to_path_buf(),
        field: "images[3].world_from_camera.rms_px".into(),
        value: f64::NAN,
    }
    .into();
    assert_eq!(
        err.to_string(),
        "out/poses.json: field images[3].world_from_camera.rms_px is NaN, which JSON cannot hold"
    );
}
