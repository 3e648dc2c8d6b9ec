//! A rig that states what the studio knows without targets: the flash's measured light
//! position instead of its ring of targets, the standard's fixed pose instead of its frame, and
//! the camera's calibration instead of `ingest --camera`. Ingest carries them into the
//! session's `[known]` and `[camera]`, and `process` runs on them: the flash triangulation is
//! skipped and the samples meet the default bounds.
//!
//! The stated positions come from the generator's design of the scene
//! (`skinbrdf_synth::layout::build_rig`), as a studio would measure them, never from the truth.
//! The same rig without the light position is refused, naming the rig file and its key.
//!
//! Run with `cargo test --release` (ignored in debug builds: rendering takes minutes there).

mod common;

use std::path::{Path, PathBuf};

use skinbrdf_ingest::ingest::CameraSource;
use skinbrdf_ingest::{ingest, IngestConfig, IngestError};
use skinbrdf_pipeline::plan::Stage;
use skinbrdf_pipeline::process::{bounds, process, ProcessConfig};
use skinbrdf_session::rig::RigFile;
use skinbrdf_session::{CameraSpec, Rig, RigCamera, Session, TargetGroup};
use skinbrdf_synth::studio::{CAMERA_FILE, STUDIO_DIR};
use skinbrdf_synth::Scene;

/// Measurement images: enough for the default bounds on the samples, few for the test's time.
const MEASUREMENT_IMAGES: u32 = 16;

/// The measured rig (every placement given) without the flash's and the standard's targets,
/// stating instead the light position and the standard's pose from the scene's design, and the
/// camera's calibration from the studio's calibration file.
fn rig_that_knows(studio: &Path, scene: &Scene) -> RigFile {
    let measured = Rig::load(&studio.join("rig-measured.toml")).expect("measured rig");
    let mut file = measured.file;
    let kept = |g: TargetGroup| !matches!(g, TargetGroup::Flash | TargetGroup::Standard);
    file.sheets.retain(|s| kept(s.group));
    file.targets.retain(|t| kept(t.group));
    let design = skinbrdf_synth::layout::build_rig(scene);
    // The emitting point is the flash frame's origin in the generator's design.
    file.flash.light_position_m = Some(design.light_position_m());
    file.standard
        .as_mut()
        .expect("the studio's standard")
        .world_from_standard = Some(design.world_from_standard);
    let text = std::fs::read_to_string(studio.join(CAMERA_FILE)).expect("camera.toml");
    let mut table: toml::Table = toml::from_str(&text).expect("camera toml");
    let spec: CameraSpec = table
        .remove("camera")
        .expect("[camera]")
        .try_into()
        .expect("camera");
    file.camera = Some(RigCamera::Calibrated(*spec.model().expect("calibrated")));
    file
}

fn config(s: &Path, rig: PathBuf, out: &Path) -> IngestConfig {
    let studio = s.join(STUDIO_DIR);
    IngestConfig::new(
        studio.join("card"),
        studio.join("capture.json"),
        rig,
        studio.join("scan.ply"),
        out.to_path_buf(),
    )
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn a_rig_stating_the_light_position_and_the_standard_pose_runs_without_their_targets() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut scene = Scene::load("default").expect("default scene");
    scene.session.measurement_images = MEASUREMENT_IMAGES;
    let s = common::half_resolution_studio(dir.path(), &scene);
    let studio = s.join(STUDIO_DIR);
    let rig = rig_that_knows(&studio, &scene);
    let rig_path = studio.join("rig-known.toml");
    Rig::write_file(&rig_path, &rig).expect("write the rig");

    // Without the light position the same rig is refused by its file and key, before
    // anything is written.
    let mut no_light = rig.clone();
    no_light.flash.light_position_m = None;
    let no_light_path = studio.join("rig-no-light.toml");
    Rig::write_file(&no_light_path, &no_light).expect("write the rig");
    let refused_out = dir.path().join("refused");
    match ingest(&config(&s, no_light_path.clone(), &refused_out)) {
        Err(IngestError::Rig { path, source }) => {
            assert_eq!(path, no_light_path);
            assert!(source.has_field("flash"), "{source}");
            let text = source.to_string();
            assert!(text.contains("rig-no-light.toml: `flash`"), "{text}");
            assert!(text.contains("light_position_m"), "{text}");
            assert!(!text.contains(".ingest-"), "{text}");
            assert!(!text.contains("known."), "{text}");
        }
        other => panic!("expected the rig's refusal, got {:?}", other.map(|_| ())),
    }
    assert!(!refused_out.exists());

    // Stated, the session knows them.
    let s2 = dir.path().join("S2");
    let report = ingest(&config(&s, rig_path.clone(), &s2)).expect("ingest");
    assert_eq!(report.camera, CameraSource::Rig { path: rig_path });
    assert_eq!(
        report.known_from_rig.len(),
        2,
        "{:?}",
        report.known_from_rig
    );
    let session = Session::load(&s2).expect("the ingested session loads");
    let known = &session.file.known;
    let design = skinbrdf_synth::layout::build_rig(&scene);
    assert_eq!(known.light_position_m, Some(design.light_position_m()));
    assert_eq!(known.world_from_standard, Some(design.world_from_standard));
    assert!(session.file.flash.targets.is_empty());
    assert!(session
        .file
        .standard
        .as_ref()
        .is_some_and(|s| s.targets.is_empty()));
    assert!(session.file.camera.model().is_some());

    // And `process` uses them: no flash triangulation, no camera calibration, the samples and
    // the camera within the default bounds.
    let mut cfg = ProcessConfig::new();
    cfg.fit.figures = false;
    cfg.truth_file = Some(s.join("truth.json"));
    let out = process(&s2, &cfg, &mut |_| {}).expect("process");
    let plan = &out.report.plan;
    assert!(!plan.runs(Stage::FlashTriangulation), "{}", plan.to_text());
    assert!(!plan.runs(Stage::CameraCalibration), "{}", plan.to_text());
    assert!(
        plan.runs(Stage::RadiometricCalibration),
        "{}",
        plan.to_text()
    );
    let cam = out.report.camera_poses().expect("camera poses ran");
    let cam_mm = cam.camera_position_error_median_mm.expect("scored");
    assert!(cam_mm < bounds::CAMERA_POSITION_MM, "camera {cam_mm} mm");
    let e = out
        .report
        .derender()
        .and_then(|d| d.sample_median_rel_error_pct)
        .expect("scored");
    assert!(e < bounds::SAMPLE_MEDIAN_REL_ERROR_PCT, "samples {e} %");
    println!("rig_known: camera {cam_mm:.3} mm, samples {e:.3} % (median relative error)");
}
