//! The surveyed headdress registered to a head scan WITHOUT texture, by corners an operator
//! picked on the scan (`ingest --scan-points`): the synthetic studio's textured scan with its
//! material removed (the same mesh, untextured, in its scanner's frame), and a points file of
//! the true corners of the headdress targets as printed on the scan plus a picking error.
//! `process` must register by the points (and say so), and meet the head bounds; without the
//! points it must refuse, saying what would relate the headdress to the scan; a similarity fit
//! finds the scale 1.
//!
//! Run with `cargo test --release` (ignored in debug builds: rendering takes minutes there).

mod common;

use std::path::Path;

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use skinbrdf_ingest::ingest;
use skinbrdf_pipeline::demo::studio_ingest_config;
use skinbrdf_pipeline::process::{bounds, process, ProcessConfig};
use skinbrdf_register::{RegistrationMethod, RegistrationReport};
use skinbrdf_session::RegistrationFit;
use skinbrdf_synth::studio::STUDIO_DIR;
use skinbrdf_synth::Scene;

/// Measurement images (the default scene has 30).
const MEASUREMENT_IMAGES: u32 = 12;
/// An operator's picking error on the scan, per coordinate, metres: a fifth of a millimetre
/// (the scan's texel pitch is about 0.2 mm).
const PICK_SIGMA_M: f64 = 0.0002;
/// A similarity fit to points picked on a scan of the right unit finds a scale within this of
/// 1 (a 0.2 mm picking error over a band about 0.15 m across).
const SCALE_TOL: f64 = 0.005;

/// The points file: every corner of every headdress target painted on the scan, with a
/// picking error.
fn points_file(studio: &Path, out: &Path) {
    let truth: serde_json::Value = serde_json::from_slice(
        &std::fs::read(studio.join("scan").join("scan-truth.json")).expect("scan truth"),
    )
    .expect("json");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let n = Normal::new(0.0, PICK_SIGMA_M).expect("normal");
    let mut text = String::from("# corners picked on the scan, metres, scan frame\n");
    for t in truth["targets"].as_array().expect("targets") {
        let id = t["id"].as_u64().expect("id");
        for (k, c) in t["corners_m"]
            .as_array()
            .expect("corners")
            .iter()
            .enumerate()
        {
            let xyz: Vec<f64> = (0..3)
                .map(|i| c[i].as_f64().expect("coordinate") + n.sample(&mut rng))
                .collect();
            text.push_str(&format!(
                "[[points]]\ntarget = {id}\ncorner = {k}\nscan_m = [{}, {}, {}]\n",
                xyz[0], xyz[1], xyz[2]
            ));
        }
    }
    std::fs::write(out, text).expect("points file");
}

/// The textured scan's mesh as a PLY without colours (metres): the same surface, no texture.
fn untextured(studio: &Path, out: &Path) {
    let loaded = skinbrdf_mesh::load_mesh(
        &studio.join("scan").join("head.obj"),
        &skinbrdf_mesh::LoadOptions {
            unit: skinbrdf_mesh::LengthUnit::Custom(1e-3),
            ..Default::default()
        },
    )
    .expect("the textured scan loads");
    skinbrdf_mesh::write_ply_binary_in(out, &loaded.mesh, "metres").expect("untextured ply");
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn an_untextured_scan_is_registered_by_picked_points() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut scene = Scene::load("default").expect("default scene");
    scene.session.measurement_images = MEASUREMENT_IMAGES;
    let s = common::half_resolution_studio(dir.path(), &scene);
    let st = s.join(STUDIO_DIR);
    let plain = dir.path().join("head-plain.ply");
    untextured(&st, &plain);
    let points = dir.path().join("picked.toml");
    points_file(&st, &points);
    let mut pcfg = ProcessConfig::new();
    pcfg.fit.figures = false;
    pcfg.truth_file = Some(st.join("truth.json"));

    // Without the points nothing relates the surveyed headdress to the untextured scan.
    let bare = dir.path().join("bare");
    let mut cfg = studio_ingest_config(&s, &scene, bare.clone());
    cfg.scan = Some(plain.clone());
    cfg.scan_units = Some(skinbrdf_session::LengthUnit::M);
    ingest(&cfg).expect("ingest");
    let e = process(&bare, &pcfg, &mut |_| {}).expect_err("no registration");
    let text = skinbrdf_core::error_text(&e);
    assert!(text.contains("points file"), "{text}");

    // With them: registered by the points, and the head poses within their bound.
    let picked = dir.path().join("picked");
    cfg.out_dir = picked.clone();
    cfg.scan_points = Some(points.clone());
    ingest(&cfg).expect("ingest with points");
    let out = process(&picked, &pcfg, &mut |_| {}).expect("process");
    let reg: RegistrationReport = serde_json::from_slice(
        &std::fs::read(out.out_dir.join("registration.json")).expect("registration.json"),
    )
    .expect("registration");
    assert_eq!(reg.method, RegistrationMethod::Points);
    let sv = out.report.survey().expect("survey ran");
    let head_mm = sv.headdress_rms_error_mm.expect("scored");
    let head = out
        .report
        .head_tracking()
        .and_then(|h| h.head_position_error_median_mm)
        .expect("head scored");
    eprintln!(
        "points: {} targets, rms {:.3} mm; headdress {head_mm:.3} mm, head {head:.3} mm",
        reg.alignment.residuals.len(),
        reg.alignment.rms_mm
    );
    assert!(
        head_mm < bounds::SURVEY_HEADDRESS_RMS_MM,
        "headdress {head_mm} mm"
    );
    assert!(head < bounds::HEAD_POSITION_MM, "head {head} mm");

    // A similarity, asked for: the scale comes out 1.
    let sim = dir.path().join("similarity");
    cfg.out_dir = sim.clone();
    cfg.registration_fit = RegistrationFit::Similarity;
    ingest(&cfg).expect("ingest, similarity");
    let out = process(&sim, &pcfg, &mut |_| {}).expect("process, similarity");
    let reg: RegistrationReport = serde_json::from_slice(
        &std::fs::read(out.out_dir.join("registration.json")).expect("registration.json"),
    )
    .expect("registration");
    eprintln!(
        "similarity: scale {:.5} ± {:.5}",
        reg.alignment.scale, reg.alignment.scale_sd
    );
    assert!(
        (reg.alignment.scale - 1.0).abs() < SCALE_TOL,
        "scale {}",
        reg.alignment.scale
    );
}
