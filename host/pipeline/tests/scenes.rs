//! `process` on every built-in scene, on the studio's real path: synthesize the scene with its
//! studio (the camera's card, the controller's record, a rig nobody measured and the textured
//! head scan; no calibration file, as a photographer's card comes: the session calibrates the
//! camera from its reference targets, starting from the focal length the files state; one test
//! states the calibration instead, under the same bounds), ingest them, run the planned pipeline (the placement survey and the registration
//! to the scan first), and check that it printed its plan first, followed it (every stage
//! reported once, in order, skipped exactly where the plan says with the plan's reason), wrote
//! its products, and that every figure is finite and every error within the scene's stated
//! bound, scored against the studio's truth (which the path under test never reads).
//!
//! Each test renders its scene with the scene's own camera (field of view, distortion), geometry,
//! BRDF, noise and anti-aliasing, with two stated reductions to keep CI affordable (run with
//! `cargo test --release`): [`MEASUREMENT_IMAGES`] measurement images instead of 30 (plus the 6
//! calibration images), and a sensor of half the scene's pixels per axis (762 x 506 superpixels
//! for the default 1524 x 1012; same field of view). The cards are formed per photosite
//! (`[studio] mosaic = "photosite"`): the render has the scene's pixel count, one rendered pixel
//! per photosite, as a camera's sensor records it, since `process` loads raw files per photosite
//! by default. A card formed from 2x2 quads of one rendered pixel (`mosaic = "quad"`) holds no
//! photosite's own value: loaded per photosite, its target corners carry the quads' blocks
//! (`docs/derender.md`, "Why photosites are the default"). Half the scene's pixel count in
//! photosites (the quad cards' rays) is not enough: detection then sees green interpolated at
//! red and blue on a quarter of the pixels, and three scenes miss their bounds (the same
//! document). One ray per pixel instead is not a
//! valid reduction: a real sensor integrates over each pixel, and point-sampled (aliased) target
//! edges move the detected corners (the measurement is in `docs/benchmarks-poses.md`).
//! `skinbrdf process` on the full scenes is recorded in `docs/benchmarks.md`.
//!
//! In a debug build the tests are ignored (rendering takes minutes there).
//!
//! Bounds: the issues' bounds for the default scene; the stiff scenes state their own where the
//! scene makes the default one unreachable (each with its reason).

use std::path::Path;

use skinbrdf_ingest::ingest;
use skinbrdf_pipeline::demo::studio_ingest_config;
use skinbrdf_pipeline::plan::Action;
use skinbrdf_pipeline::process::{process, Event, ProcessConfig};
use skinbrdf_pipeline::report::{MetricKind, StageStatus};
use skinbrdf_pipeline::Stage;
use skinbrdf_synth::studio::{Mosaic, STUDIO_DIR};
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// Measurement images per test session (the scenes have 30).
const MEASUREMENT_IMAGES: u32 = 12;

/// Per-scene bounds (all "at most").
#[derive(Debug, Clone, Copy)]
struct Bounds {
    /// Camera position error, median, mm.
    camera_mm: f64,
    /// Derendered samples' median relative error, percent.
    samples_pct: f64,
    /// Fitted model's median relative error against the truth, percent.
    model_pct: f64,
    /// Samples kept, at least.
    min_samples: f64,
    /// Surveyed reference targets' RMS corner error against the truth, mm.
    survey_reference_mm: f64,
    /// Head position error, median over the head-tracked images, mm.
    head_mm: f64,
    /// Flash (emitting point) position error, mm.
    flash_mm: f64,
}

/// The default scene's stated bounds (camera, samples, model, survey, flash), and head
/// tracking at twice the default scene's 0.5 mm: these sessions are rendered at half the pixels
/// per axis, so each headdress tag spans half the pixels and its corners' noise is twice as
/// large in millimetres, and the head pose of an image rests on that image's few headdress
/// tags alone.
const DEFAULT: Bounds = Bounds {
    camera_mm: 1.0,
    samples_pct: 3.0,
    model_pct: 3.0,
    min_samples: 2_000.0,
    survey_reference_mm: 0.3,
    head_mm: 1.0,
    flash_mm: 2.0,
};

/// How the camera's calibration reaches the session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Camera {
    /// Ingested with the studio's `camera.toml` (an earlier calibration).
    Stated,
    /// Ingested without it, as a photographer's card comes: the survey calibrates the camera
    /// from the reference targets, starting from the focal length the files state.
    SelfCalibrated,
}

/// How a scene's session is made and ingested.
#[derive(Debug, Clone, Copy)]
struct Run {
    /// The camera's calibration: stated or calibrated by the session.
    camera: Camera,
    /// A sensor of the scene's full size in superpixels instead of half its pixels per axis.
    full_size: bool,
}

impl Run {
    /// The photographer's path at the reduced size: no calibration file.
    const DEFAULT: Self = Self {
        camera: Camera::SelfCalibrated,
        full_size: false,
    };
}

fn run_scene(name: &str, bounds: Bounds, expect_skipped: &[Stage]) {
    run_scene_with(name, bounds, expect_skipped, Run::DEFAULT);
}

fn run_scene_with(name: &str, bounds: Bounds, expect_skipped: &[Stage], run: Run) {
    let camera = run.camera;
    let dir = tempfile::tempdir().expect("tempdir");
    let generated = dir.path().join("generated");
    let session = dir.path().join("session");
    let mut scene = Scene::load(name).expect("built-in scene");
    scene.session.measurement_images = MEASUREMENT_IMAGES;
    scene.studio.mosaic = Mosaic::Photosite;
    // One rendered pixel per photosite: the scene's pixel count is a sensor of half its size
    // in superpixels.
    let size = if run.full_size {
        (2 * scene.camera.width_px, 2 * scene.camera.height_px)
    } else {
        (scene.camera.width_px, scene.camera.height_px)
    };
    generate(
        &scene,
        &SynthOptions {
            resolution: Some(size),
            capture: None,
            noise_free: false,
            samples_per_pixel: None,
            studio: true,
            studio_only: true,
        },
        &generated,
    )
    .expect("synthesis");
    // What the studio holds, ingested as a user would.
    let mut ingest_cfg = studio_ingest_config(&generated, &scene, session.clone());
    if camera == Camera::SelfCalibrated {
        ingest_cfg.camera = None;
    }
    ingest(&ingest_cfg).unwrap_or_else(|e| panic!("{name}: ingest failed: {e}"));
    let expect_skipped: Vec<Stage> = expect_skipped
        .iter()
        .copied()
        .filter(|s| camera == Camera::Stated || *s != Stage::CameraCalibration)
        .collect();
    let mut cfg = ProcessConfig::new();
    cfg.truth_file = Some(generated.join(STUDIO_DIR).join("truth.json"));

    // Record the events: the plan must come first and every stage must end exactly once.
    let mut plan_text = None;
    let mut order: Vec<Stage> = Vec::new();
    let out = process(&session, &cfg, &mut |e| match e {
        Event::Plan(p) => {
            assert!(order.is_empty(), "{name}: the plan came after a stage");
            plan_text = Some(p.to_text());
        }
        Event::Started(_) => {}
        Event::Finished(r) => order.push(r.stage),
    })
    .unwrap_or_else(|e| panic!("{name}: process failed: {e}"));
    let plan_text = plan_text.unwrap_or_else(|| panic!("{name}: no plan was announced"));
    let report = &out.report;
    eprintln!("--- {name}\n{plan_text}{}", report.to_text());

    // Followed in order, each stage once.
    assert_eq!(order, Stage::ALL.to_vec(), "{name}: stages out of order");

    // Skipped exactly where the plan says, with its reason; the printed plan names the reason.
    for s in &report.stages {
        let planned = report
            .plan
            .stages
            .iter()
            .find(|p| p.stage == s.stage)
            .expect("every stage is planned");
        match (&planned.action, &s.status) {
            (Action::Skip { reason }, StageStatus::Skipped { reason: r }) => {
                assert_eq!(reason, r, "{name}: {:?}", s.stage);
            }
            (Action::Run, StageStatus::Ran) => {}
            (a, st) => panic!("{name}: {:?} planned {a:?} but {st:?}", s.stage),
        }
    }
    for &stage in &expect_skipped {
        assert!(
            !report.plan.runs(stage),
            "{name}: {stage:?} should be skipped\n{plan_text}"
        );
        assert!(
            plan_text.contains(&format!("skip  {}", stage.name())),
            "{name}: printed plan does not skip {stage:?}\n{plan_text}"
        );
    }
    for stage in [
        Stage::PlacementSurvey,
        Stage::CameraPoses,
        Stage::Derender,
        Stage::SmoothIncidencePlane,
        Stage::Fit,
        Stage::Report,
    ] {
        assert!(report.plan.runs(stage), "{name}: {stage:?} must run");
    }

    // Products.
    // A head's surveyed headdress is registered to its textured scan; an ideal sample's frame
    // is its rig's declared headdress targets'.
    if skinbrdf_synth::generate::analytic_geometry(&scene).is_none() {
        assert!(
            out.out_dir.join("registration.json").is_file(),
            "{name}: missing out/registration.json"
        );
    }
    for f in [
        "survey.json",
        "poses.json",
        "samples.skbs",
        "fit/params.json",
        "report.md",
        "report.html",
        "report.json",
    ] {
        assert!(out.out_dir.join(f).is_file(), "{name}: missing out/{f}");
    }
    let md = std::fs::read_to_string(out.out_dir.join("report.md")).expect("report.md");
    assert!(md.contains("## Stages: accuracy and run time"), "{name}");

    // Every figure finite; errors within the scene's bounds.
    for s in &report.stages {
        for m in &s.metrics {
            assert!(
                m.value.is_finite(),
                "{name}: {:?} {} = {}",
                s.stage,
                m.name,
                m.value
            );
            assert!(
                m.kind != MetricKind::Error || m.value >= 0.0,
                "{name}: {}",
                m.name
            );
        }
    }
    let sv = report
        .survey()
        .unwrap_or_else(|| panic!("{name}: no survey figures"));
    let ref_mm = sv
        .reference_rms_error_mm
        .unwrap_or_else(|| panic!("{name}: the survey was not scored"));
    assert!(
        ref_mm <= bounds.survey_reference_mm,
        "{name}: surveyed reference targets {ref_mm} mm"
    );
    let cam = report
        .camera_poses()
        .and_then(|c| c.camera_position_error_median_mm)
        .unwrap_or_else(|| panic!("{name}: no camera position error"));
    assert!(cam <= bounds.camera_mm, "{name}: camera position {cam} mm");
    let head = report
        .head_tracking()
        .and_then(|h| h.head_position_error_median_mm)
        .unwrap_or_else(|| panic!("{name}: no head position error"));
    assert!(head <= bounds.head_mm, "{name}: head position {head} mm");
    let flash = report
        .flash()
        .and_then(|f| f.flash_position_error_mm)
        .unwrap_or_else(|| panic!("{name}: no flash position error"));
    assert!(
        flash <= bounds.flash_mm,
        "{name}: flash position {flash} mm"
    );
    let der = report
        .derender()
        .unwrap_or_else(|| panic!("{name}: no derender figures"));
    let kept = der.samples_kept as f64;
    assert!(kept >= bounds.min_samples, "{name}: {kept} samples kept");
    let se = der
        .sample_median_rel_error_pct
        .unwrap_or_else(|| panic!("{name}: no sample error"));
    assert!(se <= bounds.samples_pct, "{name}: samples {se} %");
    let me = report
        .fit()
        .and_then(|f| f.model_median_rel_error_vs_truth_pct)
        .unwrap_or_else(|| panic!("{name}: no model error"));
    assert!(me <= bounds.model_pct, "{name}: model {me} %");
    assert!(Path::new(&report.session).ends_with("session"));
    eprintln!(
        "{name} ({run:?}): survey {ref_mm:.3} mm, camera {cam:.3} mm, head {head:.3} mm, flash {flash:.3} mm, \
         samples {se:.2} %, model {me:.2} %"
    );
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn default_scene() {
    run_scene("default", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn sphere_needs_no_scan_and_no_shadow_rays() {
    run_scene(
        "sphere",
        DEFAULT,
        &[
            Stage::CameraCalibration,
            Stage::ScanPreparation,
            Stage::ShadowRays,
        ],
    );
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn cylinder_needs_no_scan_and_no_shadow_rays() {
    run_scene(
        "cylinder",
        DEFAULT,
        &[
            Stage::CameraCalibration,
            Stage::ScanPreparation,
            Stage::ShadowRays,
        ],
    );
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn dark_skin() {
    // Dim pixels near the noise floor: shot and read noise weigh ~3x more on each sample.
    run_scene(
        "dark-skin",
        Bounds {
            samples_pct: 5.0,
            ..DEFAULT
        },
        &[Stage::CameraCalibration],
    );
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn grazing() {
    // The camera only sees the far end of the arc: reference targets at grazing angles (camera
    // poses are less certain), few forehead pixels, most near the grazing limit. The headdress
    // is seen from its side only, its tags foreshortened and fewer per image, so each image's
    // head pose is less certain too.
    run_scene(
        "grazing",
        Bounds {
            camera_mm: 4.0,
            head_mm: 2.5,
            samples_pct: 5.0,
            model_pct: 5.0,
            min_samples: 200.0,
            ..DEFAULT
        },
        &[Stage::CameraCalibration],
    );
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn head_motion() {
    run_scene("head-motion", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn near_mirror() {
    // A lobe of exponent 2000: the samples straddle a peak hundreds of times the diffuse level;
    // a pose or normal error of a fraction of a degree moves a sample across the peak.
    run_scene(
        "near-mirror",
        Bounds {
            samples_pct: 5.0,
            model_pct: 10.0,
            ..DEFAULT
        },
        &[Stage::CameraCalibration],
    );
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn oily() {
    run_scene("oily", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn strong_distortion() {
    run_scene("strong-distortion", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn studio_faults() {
    // Clock far off, 12-bit BGGR raw, test shots, a deleted file, a misfire, an ISO slip:
    // ingest leaves out what has no image and refuses the odd exposure unless normalised, so
    // the session has fewer images than the plan.
    run_scene("studio-faults", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn survey_moved() {
    // A reference target moves half-way: the survey leaves it out (survey_faults.rs asserts it
    // is named); the rest of the pipeline works on the others.
    run_scene("survey-moved", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn survey_sheets() {
    // The cage printed on tilted sheets, one printed 1.5 % large: each sheet one body with its
    // print scale (survey_faults.rs asserts the scale).
    run_scene("survey-sheets", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn survey_faults() {
    // A bent sheet, the headdress stated as one flat band although wrapped, a duplicated id:
    // the survey names them and places what it can target by target.
    run_scene("survey-faults", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn survey_images() {
    // Survey images taken before the subject sits (role survey, ingested with --survey): the
    // survey and the poses use them; derendering, the radiometric calibration and head tracking
    // never do (survey_images.rs asserts what they add to the survey).
    run_scene("survey-images", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn survey_flash() {
    // The flash stand's panel left to the survey, linked to the cage through the relay and the
    // link shots (survey_flash.rs asserts the panel's and the flash's errors).
    run_scene("survey-flash", DEFAULT, &[Stage::CameraCalibration]);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn long_lens() {
    // The method's own optics (10 degrees across), no calibration file: the focal length the
    // files state starts the survey's calibration. At the full size: at half the pixels per
    // axis the flash stand's small panel tags are placed above their accuracy target and left
    // out read as superpixels, and read per photosite the camera misses its bound
    // (docs/photogrammetry.md, "The rig follows the lens").
    run_scene_with(
        "long-lens",
        DEFAULT,
        &[],
        Run {
            full_size: true,
            ..Run::DEFAULT
        },
    );
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn default_scene_with_its_calibration_stated() {
    // The studio that calibrated its camera earlier: the same bounds as the self-calibrated
    // `default_scene`, and no calibration stage.
    run_scene_with(
        "default",
        DEFAULT,
        &[Stage::CameraCalibration],
        Run {
            camera: Camera::Stated,
            ..Run::DEFAULT
        },
    );
}
