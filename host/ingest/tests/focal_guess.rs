//! A card ingested without the camera's calibration starts where the lens is: the focal length
//! the raw files' metadata give (focal-plane resolution, else the 35 mm equivalent), in the
//! session's superpixels, is written as `focal_guess_px` and reported with its source; it is
//! within 1 % of the synthetic scene's true focal length. With a calibration file no guess is
//! made.
//!
//! A rig that states the camera (`[camera]`): its focal length is where the calibration starts
//! (the files' own value noted where they differ), its calibration is the session's, a stated
//! image size other than the photographs' is refused by the rig's key, and a `--camera` file
//! wins over it, which the report says.

use std::path::{Path, PathBuf};

use skinbrdf_core::CameraModel;
use skinbrdf_ingest::focal::{focal_guess_px, FocalGuessSource};
use skinbrdf_ingest::ingest::CameraSource;
use skinbrdf_ingest::{ingest, IngestConfig, IngestError};
use skinbrdf_raw::ExposureMeta;
use skinbrdf_session::{CameraSpec, Rig, RigCamera, Session};
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
        session.camera_as_stated(&session.file.camera),
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

/// The studio's measured rig with `camera` stated, written beside it; returns its path.
fn rig_with_camera(studio: &Path, name: &str, camera: RigCamera) -> PathBuf {
    let mut file = Rig::load(&studio.join("rig-measured.toml"))
        .expect("measured rig")
        .file;
    file.camera = Some(camera);
    let p = studio.join(name);
    Rig::write_file(&p, &file).expect("write the rig");
    p
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn a_rig_states_the_camera_and_a_calibration_file_wins_over_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = Scene::load("default").expect("default scene");
    let (st, truth) = studio(dir.path(), scene, (200, 133));

    // A stated focal length 20 % off the files' (as a studio's note of another lens would
    // be): the calibration starts from it, and the report notes the files' value.
    let stated = 1.2 * truth;
    let rig = rig_with_camera(
        &st,
        "rig-focal.toml",
        RigCamera::ToBeCalibrated {
            width_px: None,
            height_px: None,
            focal_guess_px: Some(stated),
        },
    );
    let mut cfg = config(&st, dir.path().join("focal"));
    cfg.rig = rig.clone();
    let r = ingest(&cfg).expect("ingest with the rig's focal length");
    let g = r.focal_guess.clone().expect("a guess");
    assert_eq!(g.source, FocalGuessSource::Rig);
    assert_eq!(g.focal_px, stated);
    assert!(g.notes.iter().any(|n| n.contains("the files give")), "{g}");
    assert_eq!(r.camera, CameraSource::ToBeCalibrated);
    let session = Session::load(dir.path().join("focal")).expect("the session loads");
    assert!(matches!(
        session.camera_as_stated(&session.file.camera),
        CameraSpec::ToBeCalibrated { focal_guess_px: Some(f), .. } if f == stated
    ));

    // A calibration file wins over the rig's camera, and the report says so.
    cfg.out_dir = dir.path().join("file-wins");
    cfg.camera = Some(st.join(CAMERA_FILE));
    let r = ingest(&cfg).expect("ingest with a calibration file");
    assert!(matches!(r.camera, CameraSource::File { .. }));
    assert_eq!(r.camera_notes.len(), 1, "{:?}", r.camera_notes);
    assert!(
        r.camera_notes[0].contains("--camera") && r.camera_notes[0].contains("the rig's [camera]"),
        "{}",
        r.camera_notes[0]
    );

    // The rig's calibration: the session's camera.
    let text = std::fs::read_to_string(st.join(CAMERA_FILE)).expect("camera.toml");
    let mut table: toml::Table = toml::from_str(&text).expect("toml");
    let spec: CameraSpec = table
        .remove("camera")
        .expect("[camera]")
        .try_into()
        .expect("camera");
    let model = *spec.model().expect("calibrated");
    let rig = rig_with_camera(&st, "rig-calibrated.toml", RigCamera::Calibrated(model));
    let mut cfg = config(&st, dir.path().join("calibrated"));
    cfg.rig = rig.clone();
    let r = ingest(&cfg).expect("ingest with the rig's calibration");
    assert_eq!(r.camera, CameraSource::Rig { path: rig });
    assert_eq!(r.focal_guess, None);
    let session = Session::load(dir.path().join("calibrated")).expect("the session loads");
    // Stated in superpixel units; the session loads it on the photosite grid.
    assert_eq!(
        session.camera_as_stated(&session.file.camera),
        CameraSpec::Calibrated(model)
    );

    // A stated size that is not the photographs': refused by the rig's key.
    let rig = rig_with_camera(
        &st,
        "rig-size.toml",
        RigCamera::ToBeCalibrated {
            width_px: Some(400),
            height_px: Some(266),
            focal_guess_px: None,
        },
    );
    let mut cfg = config(&st, dir.path().join("size"));
    cfg.rig = rig.clone();
    match ingest(&cfg) {
        Err(e @ IngestError::Invalid { .. }) => {
            let text = e.to_string();
            assert!(
                text.starts_with(&format!("{}: `camera.width_px`: ", rig.display())),
                "{text}"
            );
            assert!(
                text.contains("400x266") && text.contains("200x133"),
                "{text}"
            );
        }
        other => panic!(
            "expected the rig's size refused, got {:?}",
            other.map(|_| ())
        ),
    }
    assert!(!dir.path().join("size").exists());
}
