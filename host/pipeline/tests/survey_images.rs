//! Survey images on the studio's real path (scene `survey-images`: 16 measurement images and
//! survey shots taken before the subject sits, in `studio/survey/`): the ingest gives them role
//! `survey`; the placement survey with them places more reference targets than without them
//! (the same session with the survey images removed), within the issue's bound, and every
//! placed target within [`SIGMA_COVERAGE`] of its stated standard deviation. Scored against the
//! studio's truth, which the path under test never reads.
//!
//! Run with `cargo test --release` (ignored in debug builds: rendering takes minutes there).

mod common;

use std::collections::HashMap;

use glam::DVec3;
use skinbrdf_pipeline::process::ProcessConfig;
use skinbrdf_poses::{survey, Survey, SurveyConfig};
use skinbrdf_session::{ImageRole, Session, TargetGroup, Truth};
use skinbrdf_synth::studio::STUDIO_DIR;
use skinbrdf_synth::Scene;

/// Reference targets within this RMS of the truth, mm (the issue's bound).
const REFERENCE_RMS_MM: f64 = 0.3;
/// Every placed target's error within this many of its stated standard deviations (a Gaussian
/// 3-D error exceeds 4 sigma-of-the-trace with probability well under 1e-3).
const SIGMA_COVERAGE: f64 = 4.0;

/// Per surveyed target of `group` (but the flash-only ones: the flash stand's panel, held to
/// the flash's bound): its mean corner distance to the truth, mm, and its stated position
/// sigma, mm.
fn errors(sv: &Survey, truth: &Truth, group: TargetGroup) -> Vec<(u32, f64, f64)> {
    let t: HashMap<u32, [DVec3; 4]> = truth
        .placements
        .iter()
        .filter(|p| p.group == group)
        .map(|p| (p.id, p.corners_m))
        .collect();
    sv.targets
        .iter()
        .filter(|s| s.group == group && !s.flash_only)
        .filter_map(|s| {
            let c = t.get(&s.id)?;
            let e = (0..4).map(|k| c[k].distance(s.corners_m[k])).sum::<f64>() / 4.0 * 1e3;
            Some((s.id, e, s.position_sigma_mm))
        })
        .collect()
}

fn rms(v: &[(u32, f64, f64)]) -> f64 {
    (v.iter().map(|x| x.1 * x.1).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn survey_images_place_more_reference_targets() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = Scene::load("survey-images").expect("survey-images scene");
    let n = skinbrdf_synth::survey_shots::planned_count(&scene);
    assert!(n > 0, "the scene takes survey images");
    let (s, s2) = common::studio_session(dir.path(), &scene);
    let truth = Truth::load(&s.join(STUDIO_DIR).join("truth.json")).expect("truth");
    let session = Session::load(&s2).expect("session");
    let roles: Vec<ImageRole> = session.file.images.iter().map(|e| e.role).collect();
    assert_eq!(
        roles.iter().filter(|r| **r == ImageRole::Survey).count(),
        n,
        "{roles:?}"
    );
    assert!(
        roles[..n].iter().all(|r| *r == ImageRole::Survey),
        "the survey images are listed first (taken first): {roles:?}"
    );

    // With the survey images: the pipeline's survey (registered to the textured scan, so the
    // headdress is scored in the scan's frame too).
    let with = skinbrdf_pipeline::survey::survey(&s2, &ProcessConfig::new(), None, &mut |_| {})
        .expect("survey with the survey images")
        .surveyed
        .expect("surveyed")
        .survey;
    assert_eq!(with.survey_images_used, n, "every survey image posed");
    // Without them: the same session, its survey images removed.
    let mut without_session = session.clone();
    without_session
        .file
        .images
        .retain(|e| e.role != ImageRole::Survey);
    let without = survey(&without_session, &SurveyConfig::default()).expect("survey without");
    assert_eq!(without.survey_images_used, 0);

    let ref_with = errors(&with, &truth, TargetGroup::Reference);
    let ref_without = errors(&without, &truth, TargetGroup::Reference);
    let head_with = errors(&with, &truth, TargetGroup::Headdress);
    let left = |sv: &Survey| -> Vec<String> { sv.issues.iter().map(ToString::to_string).collect() };
    eprintln!(
        "without survey images: {} reference targets, rms {:.3} mm; left out {:#?}",
        ref_without.len(),
        rms(&ref_without),
        left(&without)
    );
    eprintln!(
        "with {n} survey images: {} reference targets, rms {:.3} mm; {} headdress, rms {:.3} mm; left out {:#?}",
        ref_with.len(),
        rms(&ref_with),
        head_with.len(),
        rms(&head_with),
        left(&with)
    );
    eprintln!(
        "survey time {:.2} s with, {:.2} s without",
        with.timing.total_ms / 1e3,
        without.timing.total_ms / 1e3
    );
    assert!(
        ref_with.len() > ref_without.len(),
        "{} reference targets placed with survey images, {} without",
        ref_with.len(),
        ref_without.len()
    );
    let r = rms(&ref_with);
    assert!(r < REFERENCE_RMS_MM, "reference rms {r} mm");
    let mut worst = (0, 0.0f64);
    for &(id, e, sigma) in ref_with.iter().chain(&head_with) {
        let ratio = e / sigma.max(1e-6);
        if ratio > worst.1 {
            worst = (id, ratio);
        }
    }
    eprintln!(
        "worst error over stated sigma: {:.2} (target {})",
        worst.1, worst.0
    );
    assert!(
        worst.1 < SIGMA_COVERAGE,
        "target {}: error {:.2} of its stated sigma",
        worst.0,
        worst.1
    );
}
