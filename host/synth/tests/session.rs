//! `generate` writes sessions that `Session::load` accepts, with ground truth.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers

use skinbrdf_session::capture::*;
use skinbrdf_session::{GeometrySpec, ImageRole, Session};
use skinbrdf_synth::{generate, Scene, SynthOptions, BUILTIN_SCENES};

/// The brightest pixel of a measurement image is at least this (linear, 1.0 = white): lit
/// skin, not a blank image.
const MIN_PEAK: f32 = 0.1;

fn small(samples: u32) -> SynthOptions {
    SynthOptions {
        resolution: Some((381, 253)),
        capture: None,
        noise_free: false,
        samples_per_pixel: Some(samples),
        studio: false,
        studio_only: false,
    }
}

#[test]
fn default_scene_writes_a_valid_36_image_session_with_truth() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::load("default").unwrap();
    let sum = generate(&scene, &small(1), dir.path()).unwrap();
    // The capture's 36 exposures and the survey shots (the relay's link shots).
    let survey = skinbrdf_synth::survey_shots::planned_count(&scene);
    assert!(survey > 0, "the default studio's relay has link shots");
    assert_eq!(sum.images, 36 + survey);
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.file.images.len(), 36 + survey);
    assert_eq!(s.images_with_role(ImageRole::Survey).count(), survey);
    assert_eq!(s.images_with_role(ImageRole::Measurement).count(), 30);
    assert_eq!(s.images_with_role(ImageRole::LightPosition).count(), 3);
    assert_eq!(s.images_with_role(ImageRole::ReferenceStandard).count(), 1);
    assert_eq!(s.images_with_role(ImageRole::StandardPosition).count(), 2);
    assert!(matches!(s.file.geometry, GeometrySpec::Scan { .. }));
    let truth = s.load_truth().unwrap().unwrap();
    assert_eq!(truth.images.len(), 36 + survey);
    assert!(truth.surface.scan_vertices > 1000);
    for it in &truth.images {
        let visible = |layout: &str| {
            it.targets
                .iter()
                .filter(|t| t.layout == layout && t.fully_visible)
                .count()
        };
        match it.role {
            ImageRole::Measurement => {
                assert!(
                    it.forehead_mask.is_some(),
                    "{}: forehead not visible",
                    it.file
                );
                assert!(
                    visible("reference") >= 4,
                    "{}: {} reference targets",
                    it.file,
                    visible("reference")
                );
                assert!(
                    visible("headdress") >= 3,
                    "{}: {} headdress targets",
                    it.file,
                    visible("headdress")
                );
            }
            ImageRole::LightPosition => {
                assert!(
                    visible("flash") >= 4,
                    "{}: {} flash targets",
                    it.file,
                    visible("flash")
                );
                assert!(
                    visible("reference") >= 4,
                    "{}: {} reference targets",
                    it.file,
                    visible("reference")
                );
            }
            ImageRole::ReferenceStandard | ImageRole::StandardPosition => {
                assert!(
                    it.standard_mask.is_some(),
                    "{}: standard not visible",
                    it.file
                );
                assert!(
                    visible("standard") >= 4,
                    "{}: {} standard targets",
                    it.file,
                    visible("standard")
                );
            }
            // The relay's link shots: each sees at least two relay targets and two of the
            // panel or the cage (asserted in the synth crate's link-shot test).
            ImageRole::Survey => assert!(
                visible("reference") >= 4,
                "{}: {} reference targets",
                it.file,
                visible("reference")
            ),
        }
    }
    // The images are not blank and the skin is brighter than the background.
    let img = s.load_image(10).unwrap();
    let max = img.rgb.iter().map(|p| p[1]).fold(0.0f32, f32::max);
    assert!(max > MIN_PEAK, "max {max}");
}

#[test]
fn every_builtin_scene_generates_a_loadable_session() {
    for (name, _) in BUILTIN_SCENES {
        let dir = tempfile::tempdir().unwrap();
        let mut scene = Scene::load(name).unwrap();
        scene.session.measurement_images = 3;
        let opts = SynthOptions {
            resolution: Some((200, 133)),
            ..small(1)
        };
        generate(&scene, &opts, dir.path()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(
            s.file.images.len(),
            9 + skinbrdf_synth::survey_shots::planned_count(&scene),
            "{name}"
        );
    }
}

/// Paper under the room light at a survey shot's longer exposure is at least this bright
/// (linear, 1.0 = white): mid-grey, for the detector.
const MIN_SURVEY_PAPER: f32 = 0.35;

#[test]
fn survey_images_are_taken_without_the_subject_before_the_session() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = Scene::load("survey-images").unwrap();
    scene.session.measurement_images = 3;
    let n = skinbrdf_synth::survey_shots::planned_count(&scene);
    assert!(n > 0);
    // The studio's 14-bit rows need an even width of superpixels x 2 photosites.
    let opts = SynthOptions {
        studio: true,
        studio_only: false,
        resolution: Some((200, 133)),
        ..small(1)
    };
    generate(&scene, &opts, dir.path()).unwrap();
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    // Listed first (taken first), role survey, no exposure.
    for (k, im) in s.file.images.iter().enumerate() {
        assert_eq!(im.role == ImageRole::Survey, k < n, "{}", im.file);
        if im.role == ImageRole::Survey {
            assert!(im.exposure_index.is_none(), "{}", im.file);
        }
    }
    let truth = s.load_truth().unwrap().unwrap();
    for it in truth.images.iter().filter(|t| t.role == ImageRole::Survey) {
        // No subject: no skin, no headdress; the cage is seen and lit by the room light.
        assert!(it.forehead_mask.is_none(), "{}", it.file);
        assert!(
            it.targets.iter().all(|t| t.layout != "headdress"),
            "{}",
            it.file
        );
        let seen = it
            .targets
            .iter()
            .filter(|t| t.layout == "reference" && t.fully_visible)
            .count();
        assert!(seen >= 5, "{}: {seen} reference targets", it.file);
    }
    for (i, _) in s.images_with_role(ImageRole::Survey) {
        let img = s.load_image(i).unwrap();
        let mut g: Vec<f32> = img.rgb.iter().map(|p| p[1]).collect();
        g.sort_by(f32::total_cmp);
        let p999 = g[g.len() * 999 / 1000];
        assert!(
            p999 > MIN_SURVEY_PAPER,
            "{}: paper at {p999}",
            s.file.images[i].file
        );
    }
    // The studio's survey files: before the card's first file, the same body, a longer
    // exposure; the studio's truth names them by their raw files.
    let studio = dir.path().join("studio");
    let card_first = std::fs::read_dir(studio.join("card/DCIM/100SKBRF"))
        .unwrap()
        .map(|e| skinbrdf_raw::read_metadata(&e.unwrap().path()).unwrap())
        .map(|m| m.capture_time.unwrap().seconds())
        .fold(f64::INFINITY, f64::min);
    let mut survey: Vec<_> = std::fs::read_dir(studio.join("survey"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    survey.sort();
    assert_eq!(survey.len(), n);
    for p in &survey {
        let m = skinbrdf_raw::read_metadata(p).unwrap();
        assert!(
            m.capture_time.unwrap().seconds() < card_first,
            "{}",
            p.display()
        );
        assert_eq!(
            m.body_serial.as_deref(),
            Some(scene.studio.body_serial.as_str())
        );
        let t = m.exposure_time_s.unwrap();
        assert!(
            t > scene.studio.exposure_time_s * 2.0,
            "{}: {t} s",
            p.display()
        );
    }
    let studio_truth = skinbrdf_session::Truth::load(&studio.join("truth.json")).unwrap();
    let names: Vec<String> = studio_truth
        .images
        .iter()
        .filter(|t| t.role == ImageRole::Survey)
        .map(|t| t.file.clone())
        .collect();
    assert_eq!(names.len(), n);
    for p in &survey {
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        assert!(
            names.iter().any(|f| f == &format!("survey/{name}")),
            "{name} not in {names:?}"
        );
    }
}

#[test]
fn a_capture_record_drives_the_session() {
    let group = |label: &str, role| ShotGroup {
        label: label.into(),
        role,
        count: 1,
        min_interval_us: 2_000_000,
        pre_focus_us: 100_000,
        shutter_pulse_us: 50_000,
        xsync_timeout_us: 500_000,
        flash_ready_timeout_us: 5_000_000,
        flash_mode: FlashMode::CameraHotShoe,
    };
    let exp = |index: u32, role, t: u64, outcome| Exposure {
        index,
        group: 0,
        role,
        shutter_command_us: t,
        xsync_us: Some(t + 80_000),
        flash_fired_us: Some(t + 80_100),
        recycle_us: None,
        outcome,
        host_time_us: 0.0,
        image: None,
    };
    let rec = CaptureRecord {
        format_version: CAPTURE_FORMAT_VERSION,
        plan: CapturePlan {
            groups: vec![group("measurement", ImageRole::Measurement)],
            max_retries: 1,
        },
        device: DeviceIdentity {
            protocol_version: 1,
            firmware_version: "test".into(),
            serial: "T".into(),
            kind: "simulator".into(),
        },
        clock: ClockModel {
            device_ref_us: 0,
            host_ref_us: 0.0,
            drift_ppm: 0.0,
            residual_rms_us: 0.0,
            samples: 1,
        },
        exposures: vec![
            exp(0, ImageRole::Measurement, 1_000_000, ShotOutcome::Ok),
            exp(
                1,
                ImageRole::Measurement,
                3_000_000,
                ShotOutcome::MissingXsync,
            ),
            exp(2, ImageRole::Measurement, 5_000_000, ShotOutcome::Ok),
            exp(3, ImageRole::LightPosition, 7_000_000, ShotOutcome::Ok),
            exp(4, ImageRole::ReferenceStandard, 9_000_000, ShotOutcome::Ok),
        ],
        complete: true,
    };
    let dir = tempfile::tempdir().unwrap();
    let opts = SynthOptions {
        capture: Some(rec),
        resolution: Some((200, 133)),
        ..small(1)
    };
    let scene = Scene::load("default").unwrap();
    let sum = generate(&scene, &opts, dir.path()).unwrap();
    assert_eq!(
        sum.images,
        4 + skinbrdf_synth::survey_shots::planned_count(&scene),
        "the exposure whose camera did not fire has no image (the survey shots are not in the record)"
    );
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    let cap = s.capture.as_ref().unwrap();
    assert_eq!(cap.exposures[2].image.as_deref(), Some("images/m01.png"));
    assert_eq!(cap.exposures[1].image, None);
    // The exposures' images follow the survey shots, which come first (taken before).
    let first = s
        .file
        .images
        .iter()
        .position(|e| e.role != ImageRole::Survey)
        .expect("the exposures' images");
    assert_eq!(s.file.images[first + 1].exposure_index, Some(2));
    let truth = s.load_truth().unwrap().unwrap();
    assert_eq!(truth.images[first + 1].exposure_us, 5_080_000);
    // Head motion is keyed to exposure time: different shots, different head poses.
    assert!(truth.images[first].world_from_head != truth.images[first + 1].world_from_head);
}
