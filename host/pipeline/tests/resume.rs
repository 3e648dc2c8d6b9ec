//! Resume never lies: `process` reuses a unit only when every input it reads and every output
//! it wrote are what the ledger recorded; otherwise it runs the unit again, and the report's
//! figures always describe the files on disk.
//!
//! One small synthetic session (the sphere scene: 4 measurement images at a quarter of the
//! pixels per axis) is processed once; each case then damages or changes one thing and checks
//! what the next run did. In a debug build the test is ignored (rendering takes minutes there).

use std::path::Path;

use skinbrdf_pipeline::ledger::{Ledger, RunLock, Unit};
use skinbrdf_pipeline::process::{process, ProcessConfig, ProcessOutput};
use skinbrdf_pipeline::report::StageStatus;
use skinbrdf_pipeline::Stage;
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// `process` going on after failed self-checks: these sessions are a few images at a quarter
/// of the pixels, and one case masks out every skin pixel of ten images; what is tested here
/// is the ledger, not the measurement (the checks have their own test, `tests/checks.rs`).
fn run(session: &Path) -> ProcessOutput {
    let cfg = ProcessConfig {
        accept_failed_checks: true,
        ..ProcessConfig::new()
    };
    process(session, &cfg, &mut |_| {}).expect("process")
}

fn status(out: &ProcessOutput, stage: Stage) -> StageStatus {
    out.report
        .stages
        .iter()
        .find(|s| s.stage == stage)
        .map(|s| s.status.clone())
        .unwrap_or_else(|| panic!("{stage:?} not reported"))
}

fn samples_in_file(out: &ProcessOutput) -> u64 {
    let (_, s) = skinbrdf_samples::read_samples(out.out_dir.join("samples.skbs")).expect("read");
    s.len() as u64
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn resume_reuses_only_what_is_intact() {
    let dir = tempfile::tempdir().expect("tempdir");
    let session = dir.path().join("session");
    let mut scene = Scene::load("sphere").expect("built-in scene");
    scene.session.measurement_images = 4;
    let quarter = (scene.camera.width_px / 4, scene.camera.height_px / 4);
    generate(
        &scene,
        &SynthOptions {
            resolution: Some(quarter),
            capture: None,
            noise_free: false,
            samples_per_pixel: None,
            studio: false,
            studio_only: false,
        },
        &session,
    )
    .expect("synthesis");

    let first = run(&session);
    let out = first.out_dir.clone();
    let kept = first.report.derender().expect("derender").samples_kept;
    assert_eq!(kept, samples_in_file(&first));

    // Unchanged: everything reused, with the first run's figures.
    let again = run(&session);
    for s in [Stage::CameraPoses, Stage::Derender, Stage::Fit] {
        assert_eq!(status(&again, s), StageStatus::Reused, "{s:?}");
    }
    assert_eq!(again.report.derender(), first.report.derender());
    assert_eq!(again.report.fit(), first.report.fit());
    let md = |o: &ProcessOutput| {
        std::fs::read_to_string(o.out_dir.join("report.md")).expect("report.md")
    };
    let strip = |s: String| {
        // The run's own total time differs; everything else is the same report.
        s.lines()
            .filter(|l| !l.contains("total"))
            .map(|l| l.replace("reused", "ran"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(strip(md(&again)), strip(md(&first)));

    // Samples replaced behind the ledger's back (a hand-run derender with another stride, or a
    // run interrupted after writing them): derender runs again and the report counts what the
    // file holds. The rerun restores the very samples the fit was made from, so the fit (whose
    // fingerprint covers the samples' digest) is rightly reused.
    let (h, s) = skinbrdf_samples::read_samples(out.join("samples.skbs")).expect("read");
    let half: Vec<_> = s.iter().step_by(2).copied().collect();
    skinbrdf_samples::write_samples(out.join("samples.skbs"), &h, &half).expect("write");
    let after = run(&session);
    assert_eq!(status(&after, Stage::CameraPoses), StageStatus::Reused);
    assert_eq!(status(&after, Stage::Derender), StageStatus::Ran);
    assert_eq!(status(&after, Stage::Fit), StageStatus::Reused);
    assert_eq!(
        after.report.derender().expect("derender").samples_kept,
        samples_in_file(&after)
    );
    assert_eq!(
        after.report.fit().expect("fit").samples_fitted,
        samples_in_file(&after)
    );

    // The fit's input changed (another derender setting): the fit runs again.
    let mut cfg = ProcessConfig {
        accept_failed_checks: true,
        ..ProcessConfig::new()
    };
    cfg.derender.stride = 2;
    let strided = process(&session, &cfg, &mut |_| {}).expect("process --stride 2");
    assert_eq!(status(&strided, Stage::Derender), StageStatus::Ran);
    assert_eq!(status(&strided, Stage::Fit), StageStatus::Ran);
    assert_eq!(
        strided.report.fit().expect("fit").samples_fitted,
        samples_in_file(&strided)
    );
    run(&session);
    assert_eq!(samples_in_file(&after), kept);

    // A deleted fit product is written again; so is a figure; a garbage params.json is not
    // reused.
    for victim in ["fit/model.brdf", "fit/params.json"] {
        let p = out.join(victim);
        if victim.ends_with(".json") {
            std::fs::write(&p, b"{garbage").expect("write");
        } else {
            std::fs::remove_file(&p).expect("remove");
        }
        let r = run(&session);
        assert_eq!(status(&r, Stage::Fit), StageStatus::Ran, "{victim}");
        assert_eq!(status(&r, Stage::Derender), StageStatus::Reused, "{victim}");
        assert!(p.is_file(), "{victim} written again");
        assert!(
            !std::fs::read(&p).expect("read").starts_with(b"{garbage"),
            "{victim}"
        );
    }
    let figure = std::fs::read_dir(out.join("fit"))
        .expect("fit dir")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "png"))
        .expect("a figure");
    std::fs::remove_file(&figure).expect("remove");
    let r = run(&session);
    assert_eq!(status(&r, Stage::Fit), StageStatus::Ran);
    assert!(figure.is_file(), "{} written again", figure.display());

    // A changed input (session.toml) reruns everything downstream of it.
    let toml = session.join("session.toml");
    let mut text = std::fs::read_to_string(&toml).expect("session.toml");
    text.push_str("\n# edited\n");
    std::fs::write(&toml, text).expect("write");
    let r = run(&session);
    assert_eq!(status(&r, Stage::CameraPoses), StageStatus::Ran);
    assert_eq!(status(&r, Stage::Derender), StageStatus::Ran);

    // The ledger is written after each unit: a run that died after derendering resumes at the
    // fit.
    let mut ledger = Ledger::load(&out).expect("ledger");
    ledger.forget(Unit::Fit);
    ledger.save(&out).expect("save");
    std::fs::remove_dir_all(out.join("fit")).expect("remove fit");
    let r = run(&session);
    assert_eq!(status(&r, Stage::CameraPoses), StageStatus::Reused);
    assert_eq!(status(&r, Stage::Derender), StageStatus::Reused);
    assert_eq!(status(&r, Stage::Fit), StageStatus::Ran);

    // Temporary files of a dead run are removed.
    let stray = out.join(".poses.json.4294967295.tmp");
    std::fs::write(&stray, b"partial").expect("write");
    let r = run(&session);
    assert!(!stray.exists(), "stray temp file removed");
    assert_eq!(status(&r, Stage::Derender), StageStatus::Reused);

    // A second run on the same output directory is refused while the first holds it.
    let lock = RunLock::acquire(&out).expect("lock");
    let err = process(&session, &ProcessConfig::new(), &mut |_| {})
        .expect_err("a second run must be refused")
        .to_string();
    assert!(err.contains("another run"), "{err}");
    drop(lock);
    run(&session);
}

/// The default scene (a scan, targets, a standard) at a fifth of the pixels per axis and one
/// ray per pixel: small enough to process several times.
fn small_scan_session(dir: &Path) -> std::path::PathBuf {
    let session = dir.join("session");
    let scene = Scene::load("default").expect("built-in scene");
    let small = (scene.camera.width_px / 5, scene.camera.height_px / 5);
    generate(
        &scene,
        &SynthOptions {
            resolution: Some(small),
            capture: None,
            noise_free: false,
            samples_per_pixel: Some(1),
            studio: false,
            studio_only: false,
        },
        &session,
    )
    .expect("synthesis");
    session
}

/// The report's derender and fit figures describe the samples file on disk.
fn assert_report_matches_files(out: &ProcessOutput) {
    let on_disk = samples_in_file(out);
    assert_eq!(
        out.report.derender().expect("derender").samples_kept,
        on_disk
    );
    assert_eq!(out.report.fit().expect("fit").samples_fitted, on_disk);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn resume_sees_the_scan_a_mask_and_a_hand_run_derender() {
    use skinbrdf_pipeline::pose_inputs::PoseChoice;
    use skinbrdf_pipeline::stages::{self, DerenderOutputOptions};
    use skinbrdf_pipeline::{Plan, PlanOptions};

    let dir = tempfile::tempdir().expect("tempdir");
    let session = small_scan_session(dir.path());

    // The first ten measurement images get masks (the truth masks of the forehead).
    std::fs::create_dir_all(session.join("masks")).expect("masks dir");
    let toml = session.join("session.toml");
    let mut text = std::fs::read_to_string(&toml).expect("session.toml");
    for i in 0..10 {
        std::fs::copy(
            session.join(format!("truth/m{i:02}_forehead.png")),
            session.join(format!("masks/m{i:02}.png")),
        )
        .expect("copy mask");
        let entry = format!("file = \"images/m{i:02}.png\"\n");
        assert!(text.contains(&entry), "{text}");
        text = text.replacen(&entry, &format!("{entry}mask = \"masks/m{i:02}.png\"\n"), 1);
    }
    std::fs::write(&toml, text).expect("write");

    let first = run(&session);
    assert_report_matches_files(&first);
    let out = first.out_dir.clone();
    assert_eq!(status(&run(&session), Stage::Derender), StageStatus::Reused);

    // Changed masks (the targets' pixels only, so these images give no skin sample): derender
    // and the fit of its changed samples run again.
    for i in 0..10 {
        std::fs::copy(
            session.join(format!("truth/m{i:02}_targets.png")),
            session.join(format!("masks/m{i:02}.png")),
        )
        .expect("change mask");
    }
    let masked = run(&session);
    assert_eq!(status(&masked, Stage::Derender), StageStatus::Ran);
    assert_eq!(status(&masked, Stage::Fit), StageStatus::Ran);
    assert_report_matches_files(&masked);
    let masked_kept = samples_in_file(&masked);

    // `skinbrdf derender S --stride 4` by hand (the command's own pipeline calls): the next
    // `process` derenders again at its own stride and reports what the file holds.
    let loaded = skinbrdf_session::Session::load(&session).expect("session");
    let plan_opts = PlanOptions::default();
    let plan = Plan::derive(
        &skinbrdf_pipeline::process::scene_facts(&loaded),
        &plan_opts,
    );
    let mut dcfg = ProcessConfig::new().derender;
    dcfg.stride = 4;
    let dcfg = stages::planned_derender_config(&dcfg, &plan, &plan_opts);
    let source =
        stages::choose_pose_source(&loaded, PoseChoice::Auto, &out.join(stages::POSES_FILE))
            .expect("the pose stage's poses");
    let by_hand = stages::derender_chosen(
        &loaded,
        &source,
        &dcfg,
        &plan_opts,
        &out,
        &DerenderOutputOptions::default(),
    )
    .expect("derender --stride 4");
    let strided = by_hand.run.report.samples.len() as u64;
    assert!(
        strided < masked_kept,
        "stride 4 keeps fewer samples: {strided} of {masked_kept}"
    );
    assert_eq!(samples_in_file(&masked), strided);
    let after = run(&session);
    assert_eq!(status(&after, Stage::CameraPoses), StageStatus::Reused);
    assert_eq!(status(&after, Stage::Derender), StageStatus::Ran);
    assert_report_matches_files(&after);
    assert_eq!(samples_in_file(&after), masked_kept);

    // scan.ply replaced by an empty mesh: no stage that reads it is reused; the run fails
    // naming the scan.
    let scan = session.join("scan.ply");
    let good_scan = std::fs::read(&scan).expect("scan.ply");
    std::fs::write(
        &scan,
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
         property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
    )
    .expect("empty scan");
    let err = process(&session, &ProcessConfig::new(), &mut |_| {})
        .expect_err("an empty scan cannot be derendered");
    let text = skinbrdf_core::error_text(&err);
    assert!(text.contains("scan.ply"), "{text}");
    // Restored: the run matches the files again.
    std::fs::write(&scan, good_scan).expect("restore scan");
    let restored = run(&session);
    assert_report_matches_files(&restored);
}
