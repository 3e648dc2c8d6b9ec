//! End to end: the demo on the built-in default scene (simulator capture, synthesis of the
//! studio's files, ingest, survey and registration to the textured scan, photogrammetry,
//! derendering, smoothing, fitting, report), then `process` again on the same session, which
//! must reuse every stage. Run in release (`cargo test --release`): the
//! full-size render takes seconds there and minutes in a debug build.

use skinbrdf_pipeline::demo::{run_demo, DemoConfig};
use skinbrdf_pipeline::process::bounds;

/// The fitted model against the true BRDF, median relative error, percent: the fit of samples
/// within the derender bound cannot be held to a tighter one.
const MODEL_MEDIAN_REL_ERROR_PCT: f64 = bounds::SAMPLE_MEDIAN_REL_ERROR_PCT;
use skinbrdf_pipeline::process::{process, ProcessConfig};
use skinbrdf_pipeline::report::StageStatus;
use skinbrdf_pipeline::Stage;

#[test]
fn demo_runs_end_to_end_and_process_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = DemoConfig::new(dir.path().to_path_buf());
    let out = run_demo(&cfg, &mut |_| {}).expect("demo");

    // The capture ran the method's plan on the simulator.
    assert_eq!(out.capture.exposures.len(), 36);
    assert!(out.capture.complete);
    // The exposures' images and the relay's link shots (survey shots, not in the record).
    let scene = skinbrdf_synth::Scene::load("default").expect("default scene");
    let survey = skinbrdf_synth::survey_shots::planned_count(&scene);
    assert!(survey > 0, "the default studio's relay has link shots");
    assert_eq!(out.synth.images, 36 + survey);
    // The real path: the session came from the studio's files, with placements to survey.
    let ingest = out.ingest.as_ref().expect("the demo ingests the studio");
    assert_eq!(ingest.images.len(), 36);
    assert_eq!(ingest.survey_images.len(), survey);
    assert!(ingest.unplaced_targets > 40, "{}", ingest.unplaced_targets);
    let session_toml =
        std::fs::read_to_string(dir.path().join("session/session.toml")).expect("session.toml");
    assert!(
        !session_toml.contains("truth"),
        "the ingested session does not point at the truth"
    );

    // Every stage reported, with its accuracy against truth within the stated bounds.
    let r = &out.process.report;
    let survey = r.survey().expect("the survey ran");
    let ref_mm = survey.reference_rms_error_mm.expect("scored against truth");
    let head_mm = survey.headdress_rms_error_mm.expect("scored against truth");
    // The flash stand's panel was surveyed through the relay, not stated.
    let panel_mm = survey
        .flash_only_rms_error_mm
        .expect("the panel surveyed and scored");
    assert!(
        panel_mm < bounds::SURVEY_FLASH_ONLY_RMS_MM,
        "panel survey {panel_mm} mm"
    );
    assert!(
        ref_mm < bounds::SURVEY_REFERENCE_RMS_MM,
        "reference survey {ref_mm} mm"
    );
    assert!(
        head_mm < bounds::SURVEY_HEADDRESS_RMS_MM,
        "headdress survey {head_mm} mm"
    );
    let head = r.head_tracking().expect("head tracking ran");
    assert!(head.head_position_error_median_mm.expect("truth") < bounds::HEAD_POSITION_MM);
    let cam = r.camera_poses().expect("camera poses ran");
    let derender = r.derender().expect("derender ran");
    let fit = r.fit().expect("fit ran");
    assert!(cam.camera_position_error_median_mm.expect("truth") < bounds::CAMERA_POSITION_MM);
    assert!(
        cam.camera_orientation_error_median_deg.expect("truth") < bounds::CAMERA_ORIENTATION_DEG
    );
    let flash = r.flash().and_then(|f| f.flash_position_error_mm);
    assert!(flash.expect("flash ran") < bounds::FLASH_POSITION_MM);
    assert!(
        derender.sample_median_rel_error_pct.expect("truth") < bounds::SAMPLE_MEDIAN_REL_ERROR_PCT
    );
    assert!(derender.samples_kept > 10_000);
    assert!(fit.model_median_rel_error_vs_truth_pct.expect("truth") < MODEL_MEDIAN_REL_ERROR_PCT);
    let md = std::fs::read_to_string(&out.report_path).unwrap();
    assert!(md.contains("## Stages: accuracy against ground truth and run time"));
    assert!(md.contains("camera_position_error_median"));
    assert!(md.contains("## Ingest"), "the report gives the ingest");
    assert!(
        md.contains("reference_rms_error"),
        "the report gives the survey's error against truth"
    );
    let html = std::fs::read_to_string(dir.path().join("report.html")).expect("report.html");
    assert!(html.contains("<h2>Stages: accuracy and run time</h2>"));
    assert!(
        html.contains("<img src=\"session/out/fit/"),
        "figures inline"
    );
    assert!(
        html.contains("<img src=\"session/out/render/head_comparison.png\""),
        "the head rendering is in the report"
    );
    for fig in html.split("<img src=\"").skip(1) {
        let rel = fig.split('"').next().unwrap();
        assert!(
            dir.path().join(rel).is_file(),
            "{rel} is referenced but missing"
        );
    }

    // Unchanged inputs: everything is reused, nothing recomputed.
    let session = dir.path().join("session");
    let mut pcfg = ProcessConfig::new();
    pcfg.truth_file = Some(dir.path().join("generated/studio/truth.json"));
    let again = process(&session, &pcfg, &mut |_| {}).expect("process again");
    for stage in [
        Stage::PlacementSurvey,
        Stage::CameraPoses,
        Stage::Derender,
        Stage::Fit,
    ] {
        let s = again
            .report
            .stages
            .iter()
            .find(|s| s.stage == stage)
            .unwrap();
        assert_eq!(s.status, StageStatus::Reused, "{stage:?}");
    }
    // A fully reused run reports the figures of the run it reuses.
    assert_eq!(again.report.derender(), out.process.report.derender());
    assert_eq!(again.report.fit(), out.process.report.fit());
}

#[test]
fn a_broken_session_is_a_precise_error() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("session.toml"),
        "format_version = 1\n[camera\n",
    )
    .unwrap();
    let err = process(dir.path(), &ProcessConfig::new(), &mut |_| {}).unwrap_err();
    let err = skinbrdf_core::error_text(&err);
    assert!(err.contains("session.toml"), "{err}");
}
