//! Every photosite at its own place: a noise-free synthetic studio whose raw files are formed
//! per photosite (`[studio] mosaic = "photosite"`: each rendered pixel is one photosite, as on
//! a camera's sensor) is processed two ways: the generator's PNG session (the same renders
//! at full resolution) and the raw card loaded per photosite (the default). Loaded per
//! photosite, red and blue samples are as accurate as green and as the PNGs', and the camera
//! poses meet the method's bound. (Loaded as 2x2 superpixels, the same card's red and blue
//! are 0.09 and 0.21 percentage points worse than green on the full-size studio:
//! `docs/benchmarks.md`, *Photosites*.)
//!
//! Run with `cargo test --release` (ignored in debug builds: rendering takes minutes there).

use std::path::{Path, PathBuf};

use skinbrdf_ingest::{ingest, IngestConfig};
use skinbrdf_pipeline::process::{bounds, process, ProcessConfig, ProcessOutput};
use skinbrdf_session::{RawMode, Truth};
use skinbrdf_synth::studio::{Mosaic, CAMERA_FILE, STUDIO_DIR};
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// Red's and blue's median relative error may exceed green's by at most this, percentage
/// points (the bound): with each photosite's ray through its own place, the channels
/// differ only in their values' quantisation and the BRDF's colour.
const CHANNEL_GAP_PP: f64 = 0.03;

/// The sensor's photosites: the default scene's half resolution rounded to whole quads and
/// whole bytes per 14-bit row (multiples of 4).
const HALF_RESOLUTION: (u32, u32) = (760, 504);

/// Measurement images: enough for the pose stage and a fit, few for the run time.
const MEASUREMENT_IMAGES: u32 = 10;

fn scene() -> Scene {
    let mut scene = Scene::load("default").expect("default scene");
    scene.session.measurement_images = MEASUREMENT_IMAGES;
    scene.studio.mosaic = Mosaic::Photosite;
    scene
}

/// The scene at [`HALF_RESOLUTION`] (the sensor's photosites), noise-free, with its studio.
fn synthesize(scene: &Scene, dir: &Path) -> PathBuf {
    let s = dir.join("S");
    generate(
        scene,
        &SynthOptions {
            resolution: Some(HALF_RESOLUTION),
            noise_free: true,
            studio: true,
            ..SynthOptions::default()
        },
        &s,
    )
    .expect("synthesis");
    s
}

/// The card ingested with the surveyed rig and the studio's camera calibration (both sessions
/// then rest on the same intrinsics and frames).
fn ingest_card(s: &Path, out: &Path) {
    let studio = s.join(STUDIO_DIR);
    let mut cfg = IngestConfig::new(
        studio.join("card"),
        studio.join("capture.json"),
        studio.join("rig-measured.toml"),
        studio.join("scan.ply"),
        out.to_path_buf(),
    );
    cfg.camera = Some(studio.join(CAMERA_FILE));
    ingest(&cfg).expect("ingest");
}

fn run(dir: &Path, truth: Option<&Path>, raw_mode: RawMode, out: &str) -> ProcessOutput {
    let mut cfg = ProcessConfig::new();
    cfg.fit.figures = false;
    cfg.truth_file = truth.map(Path::to_path_buf);
    cfg.raw_mode = raw_mode;
    cfg.out_dir = Some(dir.join(out));
    process(dir, &cfg, &mut |_| {}).expect("process")
}

/// Median relative error of the samples per channel, percent.
fn channel_errors_pct(out: &ProcessOutput, truth: &Truth) -> [f64; 3] {
    let (_, samples) =
        skinbrdf_samples::read_samples(out.out_dir.join("samples.skbs")).expect("samples");
    let e = skinbrdf_derender::truth_error(&samples, &truth.brdf).expect("scored");
    e.median_rel_error_rgb
        .map(|m| m.expect("every channel scored") * 100.0)
}

fn camera_error_mm(out: &ProcessOutput) -> f64 {
    out.report
        .camera_poses()
        .and_then(|c| c.camera_position_error_median_mm)
        .expect("camera poses scored")
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn photosites_make_red_and_blue_as_accurate_as_green() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = scene();
    let s = synthesize(&scene, dir.path());
    let s2 = dir.path().join("S2");
    ingest_card(&s, &s2);
    let truth = Truth::load(&s.join("truth.json")).expect("truth");

    let png = run(&s, None, RawMode::Photosite, "out");
    let studio_truth = s.join(STUDIO_DIR).join("truth.json");
    let photosite = run(
        &s2,
        Some(&studio_truth),
        RawMode::Photosite,
        "out-photosite",
    );

    let e_png = channel_errors_pct(&png, &truth);
    let e_photo = channel_errors_pct(&photosite, &truth);
    let (c_png, c_photo) = (camera_error_mm(&png), camera_error_mm(&photosite));
    let summary = format!(
        "median rel. error % (R, G, B): PNG {e_png:.4?}, photosite {e_photo:.4?}; camera mm: \
         PNG {c_png:.4}, photosite {c_photo:.4}"
    );
    eprintln!("{summary}");
    for c in 0..3 {
        assert!(
            (e_photo[c] - e_png[c]).abs() <= CHANNEL_GAP_PP,
            "channel {c}: {summary}"
        );
    }
    for c in [0, 2] {
        assert!(
            (e_photo[c] - e_photo[1]).abs() <= CHANNEL_GAP_PP,
            "channel {c}: {summary}"
        );
    }
    // The camera meets the method's bound; matching the full-resolution PNGs' accuracy at
    // this resolution is still open (docs/benchmarks.md, *Photosites*).
    assert!(c_photo < bounds::CAMERA_POSITION_MM, "{summary}");
    assert!(c_png < bounds::CAMERA_POSITION_MM, "{summary}");
}
