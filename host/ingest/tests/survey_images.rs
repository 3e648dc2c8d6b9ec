//! `ingest --survey DIR`: survey images (taken by hand before the subject sits, not in the
//! controller's record) become images of role `survey` without an exposure, listed before the
//! session's own; their longer exposure is not refused; one from another camera body is refused
//! naming the file, and a card file given as a survey image is refused too.

use std::path::{Path, PathBuf};

use skinbrdf_ingest::{ingest, IngestConfig, IngestError};
use skinbrdf_session::{ImageRole, Session};
use skinbrdf_synth::studio::{STUDIO_DIR, SURVEY_DIR};
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// A small studio with survey shots (4 measurement images at 200 x 133: ingest needs files, not
/// detail); returns the studio directory and its number of survey shots.
fn studio(dir: &Path) -> (PathBuf, usize) {
    let mut scene = Scene::load("survey-images").expect("survey-images scene");
    scene.session.measurement_images = 4;
    scene.session.survey_images = 3;
    let s = dir.join("S");
    generate(
        &scene,
        &SynthOptions {
            resolution: Some((200, 133)),
            capture: None,
            noise_free: false,
            samples_per_pixel: Some(1),
            studio: true,
            studio_only: false,
        },
        &s,
    )
    .expect("synthesis");
    (
        s.join(STUDIO_DIR),
        skinbrdf_synth::survey_shots::planned_count(&scene),
    )
}

fn config(studio: &Path, survey: Option<PathBuf>, out: PathBuf) -> IngestConfig {
    let mut cfg = IngestConfig::new(
        studio.join("card"),
        studio.join("capture.json"),
        studio.join("rig-measured.toml"),
        studio.join("scan.ply"),
        out,
    );
    cfg.survey_dir = survey;
    cfg
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("folder")
        .map(|e| e.expect("entry").path())
        .collect();
    v.sort();
    v
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn survey_images_are_ingested_with_their_role_before_the_session() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (studio, n) = studio(dir.path());
    let survey_dir = studio.join(SURVEY_DIR);

    // Without --survey: the session's own images only.
    let plain = config(&studio, None, dir.path().join("plain"));
    let r0 = ingest(&plain).expect("ingest without survey images");
    assert!(r0.survey_images.is_empty());

    // With --survey, referenced in place: role survey, no exposure, listed first; the longer
    // exposure of a survey shot is neither refused nor normalised.
    let out = dir.path().join("with");
    let r = ingest(&config(&studio, Some(survey_dir.clone()), out.clone()))
        .expect("ingest with survey images");
    assert_eq!(r.survey_images.len(), n);
    assert_eq!(r.images.len(), r0.images.len());
    assert!(r.survey_images.iter().all(|s| s.before_session));
    let exposure = |s: &skinbrdf_ingest::ingest::IngestedSurveyImage| {
        s.settings.expect("settings").exposure_time_s
    };
    let flash = r.images[0].settings.expect("settings").exposure_time_s;
    assert!(r.survey_images.iter().all(|s| exposure(s) > 2.0 * flash));
    let session = Session::load(&out).expect("the session loads");
    assert_eq!(session.file.images.len(), r0.images.len() + n);
    for (k, im) in session.file.images.iter().enumerate() {
        assert_eq!(
            im.role == ImageRole::Survey,
            k < n,
            "{}: {:?}",
            im.file,
            im.role
        );
        if im.role == ImageRole::Survey {
            assert!(im.exposure_index.is_none() && im.exposure_scale.is_none());
            assert!(im.file.contains(SURVEY_DIR), "{}", im.file);
        }
    }
    let names: Vec<String> = files_in(&survey_dir)
        .iter()
        .map(|p| p.file_name().expect("name").to_string_lossy().into_owned())
        .collect();
    for (s, name) in r.survey_images.iter().zip(&names) {
        assert!(s.file.ends_with(name.as_str()), "{} against {name}", s.file);
    }
    let json = std::fs::read_to_string(out.join("ingest.json")).expect("ingest.json");
    assert!(json.contains("survey_images"), "{json}");
    // The report reads back as what the ingest returned (its times may come back one ulp off:
    // serde_json's default float parser is not exact).
    let back: skinbrdf_ingest::IngestReport = serde_json::from_str(&json).expect("a report");
    assert_eq!(back.survey_images, r.survey_images);
    assert_eq!(back.images.len(), r.images.len());
    assert_eq!(back.camera_body, r.camera_body);

    // Copied: into images/survey/ (a survey file may share a card file's name).
    let mut copied = config(&studio, Some(survey_dir.clone()), dir.path().join("copied"));
    copied.copy = true;
    let rc = ingest(&copied).expect("ingest copying");
    for s in &rc.survey_images {
        assert!(s.file.starts_with("images/survey/"), "{}", s.file);
        assert!(dir.path().join("copied").join(&s.file).is_file());
    }
    Session::load(dir.path().join("copied")).expect("the copied session loads");
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn a_survey_image_from_another_body_or_off_the_card_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (studio, _) = studio(dir.path());
    let serial = Scene::load("survey-images")
        .expect("scene")
        .studio
        .body_serial;
    // A survey folder with one file from another body (same length serial, rewritten in place).
    let other = dir.path().join("other-body");
    std::fs::create_dir_all(&other).expect("folder");
    let mut victim = None;
    for (k, p) in files_in(&studio.join(SURVEY_DIR)).iter().enumerate() {
        let to = other.join(p.file_name().expect("name"));
        let mut bytes = std::fs::read(p).expect("read");
        if k == 1 {
            let from = serial.as_bytes();
            let to_serial: Vec<u8> = from.iter().map(|_| b'7').collect();
            let mut hits = 0;
            for i in 0..bytes.len().saturating_sub(from.len()) {
                if &bytes[i..i + from.len()] == from {
                    bytes[i..i + from.len()].copy_from_slice(&to_serial);
                    hits += 1;
                }
            }
            assert!(hits > 0, "the serial is in the file");
            victim = Some(to.clone());
        }
        std::fs::write(&to, bytes).expect("write");
    }
    let victim = victim.expect("a second survey file");
    let err = ingest(&config(&studio, Some(other), dir.path().join("o")))
        .expect_err("another body is refused");
    let msg = err.to_string();
    assert!(
        matches!(&err, IngestError::SurveyFromAnotherBody { file, .. } if *file == victim),
        "{msg}"
    );
    assert!(msg.contains(&victim.display().to_string()), "{msg}");
    assert!(!dir.path().join("o").exists(), "nothing written");

    // The card itself given as the survey folder: its files are the session's.
    let err = ingest(&config(
        &studio,
        Some(studio.join("card")),
        dir.path().join("c"),
    ))
    .expect_err("a card file as a survey image is refused");
    assert!(
        matches!(err, IngestError::SurveyIsSessionFile { .. }),
        "{err}"
    );
}
