//! Each raw file is decoded once per command: a small synthetic studio (raw files formed per
//! photosite, loaded per photosite: the defaults) is ingested and processed, and the raw
//! decoder's own count of the images it unpacked ([`skinbrdf_raw::decodes_started`]) is read
//! after each. `ingest` decodes each matched file once (its integrity check); `process` decodes
//! each once, in its input check, and its stages (poses, derender, figures) read the decoded
//! mosaics back from the run's cache, which is gone when the run ends.
//!
//! Its own test binary: the count is the process's, and no other test may decode meanwhile.
//! Run with `cargo test --release` (ignored in debug builds: rendering takes minutes there).

use std::path::Path;

use skinbrdf_ingest::{ingest, IngestConfig};
use skinbrdf_pipeline::process::{process, ProcessConfig, DECODED_DIR};
use skinbrdf_session::Session;
use skinbrdf_synth::studio::{Mosaic, CAMERA_FILE, STUDIO_DIR};
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// The sensor's photosites: the default scene's half resolution rounded to whole quads and
/// whole bytes per 14-bit row (as `photosites.rs`).
const HALF_RESOLUTION: (u32, u32) = (760, 504);

/// Measurement images: enough for the pose stage and a fit, few for the run time.
const MEASUREMENT_IMAGES: u32 = 8;

/// Decodes per raw file `process` may make: its input check's.
const PROCESS_DECODES_PER_FILE: usize = 1;

/// Decodes per matched raw file `ingest` may make: its integrity check's.
const INGEST_DECODES_PER_FILE: usize = 1;

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn each_raw_file_is_decoded_once_by_ingest_and_once_by_process() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut scene = Scene::load("default").expect("default scene");
    scene.session.measurement_images = MEASUREMENT_IMAGES;
    scene.studio.mosaic = Mosaic::Photosite;
    let s = dir.path().join("S");
    generate(
        &scene,
        &SynthOptions {
            resolution: Some(HALF_RESOLUTION),
            studio: true,
            studio_only: true,
            ..SynthOptions::default()
        },
        &s,
    )
    .expect("synthesis");
    let studio = s.join(STUDIO_DIR);
    let s2 = dir.path().join("S2");
    let mut cfg = IngestConfig::new(
        studio.join("card"),
        studio.join("capture.json"),
        studio.join("rig-measured.toml"),
        studio.join("scan.ply"),
        s2.clone(),
    );
    cfg.camera = Some(studio.join(CAMERA_FILE));

    let before = skinbrdf_raw::decodes_started();
    let report = ingest(&cfg).expect("ingest");
    let ingest_decodes = skinbrdf_raw::decodes_started() - before;
    let files = Session::load(&s2).expect("session").file.images.len();
    assert!(files > MEASUREMENT_IMAGES as usize, "{files} images");
    assert!(
        ingest_decodes <= INGEST_DECODES_PER_FILE * report.images.len(),
        "ingest decoded {ingest_decodes} times for {} images",
        report.images.len()
    );

    let mut pcfg = ProcessConfig::new();
    pcfg.truth_file = Some(studio.join("truth.json"));
    let out = s2.join("out");
    pcfg.out_dir = Some(out.clone());
    let before = skinbrdf_raw::decodes_started();
    process(&s2, &pcfg, &mut |_| {}).expect("process");
    let process_decodes = skinbrdf_raw::decodes_started() - before;
    assert!(
        process_decodes <= PROCESS_DECODES_PER_FILE * files,
        "process decoded {process_decodes} times for {files} raw files"
    );
    assert!(
        !out.join(DECODED_DIR).exists(),
        "the run's decoded files are removed when it ends"
    );
    assert_no_temp_files(&out);
}

fn assert_no_temp_files(out: &Path) {
    for e in std::fs::read_dir(out).expect("out") {
        let name = e.expect("entry").file_name().to_string_lossy().into_owned();
        assert!(!name.ends_with(".tmp"), "{name} left behind");
    }
}
