//! The placement survey on a studio whose rig changed during the session: one reference
//! target's tape slipped half-way (scene `survey-moved`). The survey must name it
//! ([`SurveyIssue::Moved`] with its id), leave it out, and still place the other reference
//! targets within the survey test's all-target bound. Scored against the studio's truth, which
//! the path under test never reads.
//!
//! Run with `cargo test --release -- --ignored`: the survey does not yet name this move (see
//! docs/photogrammetry.md), so the test is ignored until its detector does.

use std::collections::HashMap;

use glam::DVec3;
use skinbrdf_ingest::ingest;
use skinbrdf_pipeline::demo::studio_ingest_config;
use skinbrdf_poses::{survey, SurveyConfig, SurveyIssue};
use skinbrdf_session::{Session, TargetGroup};
use skinbrdf_synth::studio::STUDIO_DIR;
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// Every other surveyed reference target within this RMS of the truth, mm: the survey test's
/// all-target bound (half-resolution images, few-view targets included).
const ALL_TARGETS_RMS_MM: f64 = 1.0;

#[test]
#[ignore = "the survey's moved-body check (corners off by more than the input gate in 20 % of \
            the views) does not yet see a 3.4 mm move over 14 views: run with --ignored"]
fn a_target_moved_mid_session_is_named_and_left_out() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = Scene::load("survey-moved").expect("survey-moved scene");
    let moved = scene
        .studio
        .moved_target
        .clone()
        .expect("the scene moves a target");
    let s = dir.path().join("S");
    let half = (scene.camera.width_px / 2, scene.camera.height_px / 2);
    generate(
        &scene,
        &SynthOptions {
            resolution: Some(half),
            capture: None,
            noise_free: false,
            samples_per_pixel: None,
            studio: true,
        },
        &s,
    )
    .expect("synthesis");
    let st = s.join(STUDIO_DIR);
    let s2 = dir.path().join("S2");
    let cfg = studio_ingest_config(&s, &scene, s2.clone());
    ingest(&cfg).expect("ingest");
    let session = Session::load(&s2).expect("session");
    let sv = survey(&session, &SurveyConfig::default()).expect("survey");
    for i in &sv.issues {
        eprintln!("  issue: {i:?}");
    }
    for t in &sv.targets {
        eprintln!(
            "  {:>3} {:?} views {:>2} rms {:.3} px",
            t.id, t.group, t.views, t.rms_px
        );
    }
    let named = sv.issues.iter().any(|i| match i {
        SurveyIssue::Moved { ids, .. } => ids.contains(&moved.id),
        _ => false,
    });
    assert!(
        named,
        "target {} moved but not named: {:?}",
        moved.id, sv.issues
    );
    assert!(
        sv.targets.iter().all(|t| t.id != moved.id),
        "the moved target was placed anyway"
    );

    let truth = skinbrdf_session::Truth::load(&st.join("truth.json")).expect("truth");
    let truth_ref: HashMap<u32, [DVec3; 4]> = truth
        .placements
        .iter()
        .filter(|p| p.group == TargetGroup::Reference)
        .map(|p| (p.id, p.corners_m))
        .collect();
    let (mut sq, mut n) = (0.0, 0usize);
    for t in sv
        .targets
        .iter()
        .filter(|t| t.group == TargetGroup::Reference)
    {
        let Some(c) = truth_ref.get(&t.id) else {
            continue;
        };
        let e_mm = (0..4).map(|k| c[k].distance(t.corners_m[k])).sum::<f64>() / 4.0 * 1e3;
        sq += e_mm * e_mm;
        n += 1;
    }
    let rms_mm = (sq / n.max(1) as f64).sqrt();
    eprintln!(
        "survey-moved: {n} reference targets, rms {rms_mm:.3} mm; {:?}",
        sv.timing
    );
    assert!(n >= 20, "{n} reference targets surveyed");
    assert!(rms_mm < ALL_TARGETS_RMS_MM, "reference rms {rms_mm} mm");
}
