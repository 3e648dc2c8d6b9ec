//! A card ingested without the camera's calibration starts where the lens is: the focal length
//! the raw files' metadata give (focal-plane resolution, else the 35 mm equivalent), in the
//! session's superpixels, is written as `focal_guess_px` and reported with its source; it is
//! within 1 % of the synthetic scene's true focal length. With a calibration file no guess is
//! made.

use std::path::{Path, PathBuf};

use skinbrdf_core::CameraModel;
use skinbrdf_ingest::focal::{focal_guess_px, FocalGuessSource};
use skinbrdf_ingest::{ingest, IngestConfig};
use skinbrdf_raw::ExposureMeta;
use skinbrdf_session::{CameraSpec, Session};
use skinbrdf_synth::studio::{CAMERA_FILE, STUDIO_DIR};
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// The guess must be this close to the scene's focal length (relative).
const GUESS_REL_TOL: f64 = 0.01;

/// A small studio (4 measurement images: ingest needs files, not detail) of `scene` at
/// `size`; returns the studio directory and the scene camera's true focal length, pixels.
fn studio(dir: &Path, mut scene: Scene, size: (u32, u32)) -> (PathBuf, f64) {
    scene.session.measurement_images = 4;
    let s = dir.join("S");
    generate(
        &scene,
        &SynthOptions {
            resolution: Some(size),
            capture: None,
            noise_free: false,
            samples_per_pixel: Some(1),
            studio: true,
            studio_only: true,
        },
        &s,
    )
    .expect("synthesis");
    let truth = CameraModel::from_fov(size.0, size.1, scene.camera.hfov_deg.to_radians()).fx_px;
    (s.join(STUDIO_DIR), truth)
}

fn config(studio: &Path, out: PathBuf) -> IngestConfig {
    IngestConfig::new(
        studio.join("card"),
        studio.join("capture.json"),
        studio.join("rig-measured.toml"),
        studio.join("scan.ply"),
        out,
    )
}

fn rel(a: f64, b: f64) -> f64 {
    (a / b - 1.0).abs()
}

/// Ingests `studio` without and with its calibration and checks the guess against `truth`.
fn check(dir: &Path, studio: &Path, truth: f64, label: &str) {
    // Without a calibration: the guess from the focal-plane resolution.
    let out = dir.join(format!("{label}-guessed"));
    let r = ingest(&config(studio, out.clone())).expect("ingest without a calibration");
    let g = r
        .focal_guess
        .clone()
        .unwrap_or_else(|| panic!("{label}: no guess: {:?}", r.focal_guess_refused));
    eprintln!(
        "{label}: guess {g}; truth {truth:.2} px ({:+.3} %)",
        100.0 * (g.focal_px / truth - 1.0)
    );
    assert!(r.focal_guess_refused.is_empty());
    assert!(
        matches!(g.source, FocalGuessSource::FocalPlaneResolution { session_px_per_sensor_px, .. }
            if session_px_per_sensor_px == 0.5),
        "{label}: {g}"
    );
    assert!(
        rel(g.focal_px, truth) < GUESS_REL_TOL,
        "{label}: {g} vs {truth}"
    );
    assert!(g.notes.is_empty(), "{label}: the two sources disagree: {g}");
    let session = Session::load(&out).expect("the session loads");
    assert_eq!(
        session.file.camera,
        CameraSpec::ToBeCalibrated {
            width_px: r.image_size_px.0,
            height_px: r.image_size_px.1,
            focal_guess_px: Some(g.focal_px),
        }
    );
    let json = std::fs::read_to_string(out.join("ingest.json")).expect("ingest.json");
    assert!(
        json.contains("\"focal_guess\"") && json.contains("focal-plane-resolution"),
        "{json}"
    );

    // The 35 mm equivalent alone, from the same card file, within the same tolerance (EXIF
    // rounds it to whole millimetres).
    let card_file = &r.images[0].card_file;
    let meta = skinbrdf_raw::read_metadata(card_file).expect("metadata");
    let only_35 = ExposureMeta {
        focal_plane_px_per_mm_x: None,
        focal_plane_px_per_mm_y: None,
        ..meta
    };
    let size = r.image_size_px;
    let g35 = focal_guess_px(&only_35, size, (2 * size.0, 2 * size.1)).expect("35 mm guess");
    eprintln!(
        "{label}: 35 mm equivalent {g35}; truth {truth:.2} px ({:+.3} %)",
        100.0 * (g35.focal_px / truth - 1.0)
    );
    assert!(matches!(
        g35.source,
        FocalGuessSource::Equivalent35mm { .. }
    ));
    assert!(
        rel(g35.focal_px, truth) < GUESS_REL_TOL,
        "{label}: {g35} vs {truth}"
    );

    // With the calibration file: no guess, none refused.
    let mut cfg = config(studio, dir.join(format!("{label}-calibrated")));
    cfg.camera = Some(studio.join(CAMERA_FILE));
    let r = ingest(&cfg).expect("ingest with a calibration");
    assert_eq!(r.focal_guess, None);
    assert!(r.focal_guess_refused.is_empty());
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn a_synthetic_card_gives_the_scenes_focal_length() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The default scene: 16 degrees across a 23.6 mm sensor.
    let scene = Scene::load("default").expect("default scene");
    let d = dir.path().join("default");
    let (st, truth) = studio(&d, scene, (200, 133));
    check(&d, &st, truth, "default");
    // The method's long lens (10 degrees) on a full-frame sensor, another image size.
    let mut scene = Scene::load("default").expect("default scene");
    scene.camera.hfov_deg = 10.0;
    scene.studio.sensor_width_mm = 36.0;
    let d = dir.path().join("long");
    let (st, truth) = studio(&d, scene, (240, 160));
    check(&d, &st, truth, "long");
}
