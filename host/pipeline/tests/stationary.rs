//! A stationary sample (`known.stationary_sample`, no per-image `world_from_head`): the pose
//! stage skips head tracking, and derendering with its estimated poses takes the head frame
//! from the session (the world frame), so every measurement image is derendered.
//!
//! The scene is the default one with the head held still, rendered at half the pixels per
//! axis with 6 measurement images (plus the calibration images) to keep CI affordable; in a
//! debug build the test is ignored.

use skinbrdf_derender::{DerenderConfig, PoseSource};
use skinbrdf_pipeline::pose_inputs::{derender_session, PoseChoice, SessionOptions};
use skinbrdf_poses::{estimate_session, PoseConfig};
use skinbrdf_session::Session;
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// Median relative error of the samples against the true BRDF, at most: the default scene's
/// bound (`tests/scenes.rs`), which a still head can only make easier.
const SAMPLES_MEDIAN_REL_ERROR_MAX: f64 = 0.03;
/// Samples kept, at least: the default scene's bound for 12 images, halved for 6.
const MIN_SAMPLES: u64 = 1_000;

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn a_stationary_sample_derenders_with_estimated_poses() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut scene = Scene::load("default").expect("default scene");
    scene.session.measurement_images = 6;
    scene.session.head_motion_m = 0.0;
    scene.session.head_motion_deg = 0.0;
    let half = (scene.camera.width_px / 2, scene.camera.height_px / 2);
    generate(
        &scene,
        &SynthOptions {
            resolution: Some(half),
            capture: None,
            noise_free: false,
            samples_per_pixel: None,
            studio: false,
            studio_only: false,
        },
        dir.path(),
    )
    .expect("synthesis");
    // State the sample stationary and give no head pose at all.
    let mut file = Session::load(dir.path()).expect("session").file;
    file.known.stationary_sample = true;
    for e in &mut file.images {
        e.world_from_head = None;
    }
    Session::write_file(dir.path(), &file).expect("write session.toml");
    let session = Session::load(dir.path()).expect("stationary session");

    let est = estimate_session(&session, &PoseConfig::default()).expect("pose stage");
    assert!(
        est.images.iter().all(|p| p.world_from_head.is_none()),
        "the pose stage tracks no head on a stationary sample"
    );
    let measured = session
        .images_with_role(skinbrdf_session::ImageRole::Measurement)
        .count();
    let with_camera = est
        .images
        .iter()
        .filter(|p| {
            p.role == skinbrdf_session::ImageRole::Measurement && p.world_from_camera.is_some()
        })
        .count();
    assert_eq!(with_camera, measured, "every camera pose is found");

    let run = derender_session(
        &session,
        &SessionOptions {
            poses: PoseChoice::Estimated,
            skip_target_mask: false,
            estimated: Some(est),
        },
        &DerenderConfig::DEFAULT,
    )
    .unwrap_or_else(|e| panic!("derender: {e}"));
    let r = &run.report;
    assert!(run.unposed.is_empty(), "unposed: {:?}", run.unposed);
    assert_eq!(r.images.len(), measured);
    assert_eq!(r.pose_source, PoseSource::Estimated);
    assert!(r.counts.kept >= MIN_SAMPLES, "{:?}", r.counts);
    let e = r.truth_error.expect("truth.json scores the samples");
    eprintln!(
        "stationary sample: {} images, {} samples kept, median relative error {:.3} %",
        r.images.len(),
        r.counts.kept,
        e.median_rel_error * 100.0
    );
    assert!(
        e.median_rel_error <= SAMPLES_MEDIAN_REL_ERROR_MAX,
        "median relative error {:.2} %",
        e.median_rel_error * 100.0
    );
}
