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
    }
}

#[test]
fn default_scene_writes_a_valid_36_image_session_with_truth() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::load("default").unwrap();
    let sum = generate(&scene, &small(1), dir.path()).unwrap();
    assert_eq!(sum.images, 36);
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.file.images.len(), 36);
    assert_eq!(s.images_with_role(ImageRole::Measurement).count(), 30);
    assert_eq!(s.images_with_role(ImageRole::LightPosition).count(), 3);
    assert_eq!(s.images_with_role(ImageRole::ReferenceStandard).count(), 1);
    assert_eq!(s.images_with_role(ImageRole::StandardPosition).count(), 2);
    assert!(matches!(s.file.geometry, GeometrySpec::Scan { .. }));
    let truth = s.load_truth().unwrap().unwrap();
    assert_eq!(truth.images.len(), 36);
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
        assert_eq!(s.file.images.len(), 9, "{name}");
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
    let sum = generate(&Scene::load("default").unwrap(), &opts, dir.path()).unwrap();
    assert_eq!(
        sum.images, 4,
        "the exposure whose camera did not fire has no image"
    );
    let s = Session::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
    let cap = s.capture.as_ref().unwrap();
    assert_eq!(cap.exposures[2].image.as_deref(), Some("images/m01.png"));
    assert_eq!(cap.exposures[1].image, None);
    assert_eq!(s.file.images[1].exposure_index, Some(2));
    let truth = s.load_truth().unwrap().unwrap();
    assert_eq!(truth.images[1].exposure_us, 5_080_000);
    // Head motion is keyed to exposure time: different shots, different head poses.
    assert!(truth.images[0].world_from_head != truth.images[1].world_from_head);
}
