//! `skinbrdf process SESSION_DIR`: the planned pipeline.
//!
//! 1. Load and validate the session; derive [`SceneFacts`] from what it already has.
//! 2. Derive and announce the [`Plan`].
//! 3. Photogrammetry (camera calibration, camera poses, head tracking, flash triangulation and
//!    the standard's pose) through `skinbrdf-poses`, which itself skips every quantity the
//!    session gives.
//! 4. Derendering uses the estimated poses (`PoseChoice::Estimated`) or the session's own known
//!    poses, never the ground truth: truth is only read to score each stage.
//! 5. Scan preparation (BVH, planar-fit normals, convexity test), derendering, smoothing and
//!    fitting; then the report.
//!
//! Every stage is fingerprinted (see [`crate::ledger`]): running `process` again on unchanged
//! inputs reuses the previous results.

use std::path::{Path, PathBuf};
use std::time::Instant;

use skinbrdf_derender::{DerenderConfig, PoseChoice, SessionOptions, SessionRun};
use skinbrdf_fit::report::{fit_and_report, FitReport, Input, ReportOptions};
use skinbrdf_fit::FitConfig;
use skinbrdf_poses::{PoseConfig, SessionPoses};
use skinbrdf_samples::SampleHeader;
use skinbrdf_session::{BadImagePolicy, GeometrySpec, ImageRole, Session, Truth};

use crate::ledger::{write_atomic, FingerprintBuilder, Ledger};
use crate::plan::{Geometry, Plan, PlanOptions, SceneFacts, Stage};
use crate::report::{Metric, MetricKind, RunReport, StageReport, StageStatus};

/// Accuracy bounds the issues state for the default scene (reported, not asserted here).
pub mod bounds {
    /// Camera position, median, mm.
    pub const CAMERA_POSITION_MM: f64 = 1.0;
    /// Camera orientation, median, degrees.
    pub const CAMERA_ORIENTATION_DEG: f64 = 0.02;
    /// Head position, median, mm.
    pub const HEAD_POSITION_MM: f64 = 0.5;
    /// Flash position, mm.
    pub const FLASH_POSITION_MM: f64 = 2.0;
    /// Derendered samples' median relative error against the true BRDF, percent.
    pub const SAMPLE_MEDIAN_REL_ERROR_PCT: f64 = 3.0;
}

/// Errors of `process`.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// The session did not load.
    #[error("{dir}: the session is not valid:\n{problems}")]
    Session {
        /// Session directory.
        dir: PathBuf,
        /// Every problem, one per line.
        problems: String,
    },
    /// `truth.json` is present but unreadable.
    #[error("{0}")]
    Truth(String),
    /// Photogrammetry failed.
    #[error("photogrammetry: {0}")]
    Poses(#[from] skinbrdf_poses::PoseError),
    /// Derendering failed.
    #[error("derendering: {0}")]
    Derender(#[from] skinbrdf_derender::DerenderError),
    /// Smoothing or fitting failed.
    #[error("fitting: {0}")]
    Fit(#[from] skinbrdf_fit::report::ReportError),
    /// Sample file I/O.
    #[error(transparent)]
    Samples(#[from] skinbrdf_samples::SamplesError),
    /// Ledger or output I/O.
    #[error(transparent)]
    Ledger(#[from] crate::ledger::LedgerError),
    /// No samples survived derendering.
    #[error("no BRDF samples survived derendering ({0}); nothing to fit")]
    NoSamples(String),
}

/// Settings of `process`.
#[derive(Debug, Clone)]
pub struct ProcessConfig {
    /// What the user asked the plan for.
    pub plan: PlanOptions,
    /// Photogrammetry settings.
    pub poses: PoseConfig,
    /// Derendering settings.
    pub derender: DerenderConfig,
    /// Model and figures.
    pub fit: ReportOptions,
    /// Ignore the ledger and run every planned stage.
    pub force: bool,
    /// Output directory (default `SESSION/out`).
    pub out_dir: Option<PathBuf>,
    /// Leave unreadable or implausible images out (listed in the report) instead of failing.
    pub skip_bad_images: bool,
}

impl ProcessConfig {
    /// The defaults: a 2-lobe Lafortune fit with figures, no MERL table.
    pub fn new() -> Self {
        Self {
            plan: PlanOptions::default(),
            poses: PoseConfig::DEFAULT,
            derender: DerenderConfig::DEFAULT,
            fit: ReportOptions {
                model: skinbrdf_brdf::ModelSpec::Lafortune { lobes: 2 },
                fit: FitConfig::default(),
                merl: false,
                figures: true,
            },
            force: false,
            out_dir: None,
            skip_bad_images: false,
        }
    }
}

impl Default for ProcessConfig {
    fn default() -> Self {
        Self::new()
    }
}

/// Progress events for the caller to print.
#[derive(Debug)]
pub enum Event<'a> {
    /// The plan, before anything runs.
    Plan(&'a Plan),
    /// A stage starts.
    Started(Stage),
    /// A stage ended (ran, reused or skipped).
    Finished(&'a StageReport),
}

/// What `process` produced.
#[derive(Debug, Clone)]
pub struct ProcessOutput {
    /// The run's report.
    pub report: RunReport,
    /// Output directory.
    pub out_dir: PathBuf,
    /// The fit (with parameters, uncertainties and files).
    pub fit: Option<FitReport>,
}

/// The facts a session states about itself (convexity of a scan is measured later).
pub fn scene_facts(session: &Session) -> SceneFacts {
    let f = &session.file;
    let measurements: Vec<_> = f
        .images
        .iter()
        .filter(|i| i.role == ImageRole::Measurement)
        .collect();
    let (geometry, region_convex) = match f.geometry {
        GeometrySpec::Scan { .. } => (Geometry::Scan, None),
        GeometrySpec::Sphere { .. } => (Geometry::Sphere, Some(true)),
        GeometrySpec::Cylinder { .. } => (Geometry::Cylinder, Some(true)),
    };
    SceneFacts {
        intrinsics_known: f.camera.model().is_some(),
        camera_poses_known: !f.images.is_empty()
            && f.images.iter().all(|i| i.world_from_camera.is_some()),
        head_poses_known: !measurements.is_empty()
            && measurements.iter().all(|i| i.world_from_head.is_some()),
        stationary_sample: f.known.stationary_sample,
        light_position_known: f.known.light_position_m.is_some()
            || f.known.world_from_flash.is_some(),
        calibration_known: f.known.calibration_c.is_some(),
        geometry,
        region_convex,
    }
}

/// The images the input check left out and the defaults the session relies on: a count for the
/// report's first table and one note per finding.
fn input_findings(session: &Session) -> (Metric, Vec<String>) {
    let metric = Metric::new(
        "images_skipped",
        session.skipped_images.len() as f64,
        "",
        MetricKind::Count,
    );
    let mut notes: Vec<String> = session
        .skipped_images
        .iter()
        .map(|s| format!("skipped image `{}` ({:?}): {}", s.file, s.role, s.cause))
        .collect();
    notes.extend(session.linearization_source.note().map(str::to_string));
    (metric, notes)
}

fn session_fingerprint(session: &Session) -> Result<FingerprintBuilder, ProcessError> {
    let mut fp = FingerprintBuilder::new().file(&session.dir.join("session.toml"))?;
    for img in &session.file.images {
        fp = fp.file(&session.path(&img.file))?;
    }
    Ok(fp)
}

/// Runs the pipeline on a session directory.
pub fn process(
    dir: &Path,
    cfg: &ProcessConfig,
    on_event: &mut dyn FnMut(Event<'_>),
) -> Result<ProcessOutput, ProcessError> {
    let t0 = Instant::now();
    let mut session = Session::load(dir).map_err(|e| ProcessError::Session {
        dir: dir.to_path_buf(),
        problems: e.to_string(),
    })?;
    let policy = if cfg.skip_bad_images {
        BadImagePolicy::Skip
    } else {
        BadImagePolicy::Fail
    };
    session
        .check_images(policy)
        .map_err(|e| ProcessError::Session {
            dir: dir.to_path_buf(),
            problems: format!(
                "{e}\n(--skip-bad-images leaves unusable images out and lists them in the report)"
            ),
        })?;
    // What the input check found, on the first line of the report's first table.
    let (input_metric, input_notes) = input_findings(&session);
    let truth = match session.load_truth() {
        None => None,
        Some(r) => Some(r.map_err(|e| ProcessError::Truth(e.to_string()))?),
    };
    let out_dir = cfg.out_dir.clone().unwrap_or_else(|| dir.join("out"));
    std::fs::create_dir_all(&out_dir).map_err(|source| crate::ledger::LedgerError::Io {
        path: out_dir.clone(),
        source,
    })?;
    let mut ledger = if cfg.force {
        Ledger::default()
    } else {
        Ledger::load(&out_dir)?
    };

    let mut facts = scene_facts(&session);
    let plan = Plan::derive(&facts, &cfg.plan);
    on_event(Event::Plan(&plan));
    let mut reports: Vec<StageReport> = Vec::new();
    let emit = |mut r: StageReport,
                reports: &mut Vec<StageReport>,
                on_event: &mut dyn FnMut(Event<'_>)| {
        if reports.is_empty() {
            r.metrics.insert(0, input_metric.clone());
            r.notes.extend(input_notes.iter().cloned());
        }
        on_event(Event::Finished(&r));
        reports.push(r);
    };

    // --- photogrammetry -------------------------------------------------------------------
    let pose_stages = [
        Stage::CameraCalibration,
        Stage::CameraPoses,
        Stage::HeadTracking,
        Stage::FlashTriangulation,
        Stage::RadiometricCalibration,
    ];
    let session_fp = session_fingerprint(&session)?.finish();
    let poses_fp = FingerprintBuilder::new()
        .upstream(&session_fp)
        .value("poses", &cfg.poses)
        .finish();
    let needs_poses = pose_stages.iter().any(|&s| plan.runs(s));
    let poses_path = out_dir.join("poses.json");
    let mut estimated: Option<SessionPoses> = None;
    if needs_poses {
        on_event(Event::Started(Stage::CameraPoses));
        let reused = ledger
            .reusable(Stage::CameraPoses, &poses_fp, &out_dir)
            .and_then(|_| std::fs::read(&poses_path).ok())
            .and_then(|b| serde_json::from_slice::<SessionPoses>(&b).ok());
        let (poses, run_time_s, status) = match reused {
            Some(p) => (p, 0.0, StageStatus::Reused),
            None => {
                let t = Instant::now();
                let p = skinbrdf_poses::estimate_session(&session, &cfg.poses)?;
                let s = t.elapsed().as_secs_f64();
                let json = serde_json::to_vec_pretty(&p).unwrap_or_default();
                write_atomic(&poses_path, &json)?;
                (p, s, StageStatus::Ran)
            }
        };
        let pose_reports = pose_stage_reports(&plan, &poses, truth.as_ref(), run_time_s, &status);
        if status == StageStatus::Ran {
            if let Some(r) = pose_reports.iter().find(|r| r.stage == Stage::CameraPoses) {
                ledger.record(
                    Stage::CameraPoses,
                    poses_fp.clone(),
                    vec!["poses.json".into()],
                    r.clone(),
                );
            }
        }
        for r in pose_reports {
            emit(r, &mut reports, on_event);
        }
        estimated = Some(poses);
    } else {
        for &s in &pose_stages {
            if let Some(r) = RunReport::skipped_from_plan(&plan)
                .into_iter()
                .find(|r| r.stage == s)
            {
                emit(r, &mut reports, on_event);
            }
        }
    }

    // --- scan preparation and derendering ---------------------------------------------------
    let derender_fp = FingerprintBuilder::new()
        .upstream(&poses_fp)
        .upstream(&session_fp)
        .value("derender", &cfg.derender)
        .value("plane", &cfg.plan)
        .finish();
    let samples_path = out_dir.join("samples.skbs");
    let reuse = ledger
        .reusable(Stage::Derender, &derender_fp, &out_dir)
        .map(|e| e.report.clone());
    let samples = match reuse {
        Some(prev) => {
            let (_, samples) = skinbrdf_samples::read_samples(&samples_path)?;
            for stage in [Stage::ScanPreparation, Stage::ShadowRays, Stage::Derender] {
                if !plan.runs(stage) {
                    emit(skipped(&plan, stage), &mut reports, on_event);
                    continue;
                }
                let mut r = if stage == Stage::Derender {
                    prev.clone()
                } else {
                    StageReport::ran(stage, 0.0)
                };
                r.stage = stage;
                r.status = StageStatus::Reused;
                r.run_time_s = 0.0;
                emit(r, &mut reports, on_event);
            }
            samples
        }
        None => {
            on_event(Event::Started(Stage::Derender));
            // Shadow rays follow the plan: forced, skipped (a region known to be convex), or
            // left to scan preparation's convexity test (a scan).
            let mut dcfg = cfg.derender;
            if cfg.plan.force_shadow_rays {
                dcfg.shadows = skinbrdf_derender::ShadowMode::Always;
            } else if !plan.runs(Stage::ShadowRays) {
                dcfg.shadows = skinbrdf_derender::ShadowMode::Never;
            }
            // Estimated poses when the pose stage ran, else the session's own (all known);
            // never the ground truth.
            let opts = SessionOptions {
                poses: if estimated.is_some() {
                    PoseChoice::Estimated
                } else {
                    PoseChoice::Session
                },
                skip_target_mask: false,
                estimated: estimated.clone(),
            };
            let run = skinbrdf_derender::derender_session(&session, &opts, &dcfg)?;
            if facts.region_convex.is_none() {
                facts.region_convex = Some(!run.report.region_can_self_shadow);
            }
            let [scan, shadow, der] = derender_reports(&plan, &run);
            for r in [scan, shadow] {
                emit(r, &mut reports, on_event);
            }
            let mut samples = run.report.samples;
            if cfg.plan.incidence_plane_only {
                samples.retain(near_incidence_plane);
            }
            let mut header = SampleHeader::new("derender", &session.file.description);
            header.origin = Some(dir.display().to_string());
            header.calibration_c = Some(run.report.c);
            skinbrdf_samples::write_samples(&samples_path, &header, &samples)?;
            ledger.record(
                Stage::Derender,
                derender_fp.clone(),
                vec!["samples.skbs".into()],
                der.clone(),
            );
            emit(der, &mut reports, on_event);
            samples
        }
    };
    if samples.is_empty() {
        return Err(ProcessError::NoSamples(
            "see the derender stage's drop counts".into(),
        ));
    }

    // --- smoothing and fitting ---------------------------------------------------------------
    let fit_fp = FingerprintBuilder::new()
        .upstream(&derender_fp)
        .value("model", &format!("{:?}", cfg.fit.model))
        .value("fit", &cfg.fit.fit)
        .value("figures", &cfg.fit.figures)
        .finish();
    let fit_dir = out_dir.join("fit");
    let mut fit_out = None;
    match ledger
        .reusable(Stage::Fit, &fit_fp, &out_dir)
        .map(|e| e.report.clone())
    {
        Some(prev) => {
            for stage in [
                Stage::SmoothIncidencePlane,
                Stage::SmoothHemisphere,
                Stage::Fit,
            ] {
                let mut r = if stage == Stage::Fit {
                    prev.clone()
                } else {
                    StageReport::ran(stage, 0.0)
                };
                r.stage = stage;
                r.status = StageStatus::Reused;
                r.run_time_s = 0.0;
                if stage == Stage::SmoothHemisphere && !plan.runs(stage) {
                    r = skipped(&plan, stage);
                }
                emit(r, &mut reports, on_event);
            }
        }
        None => {
            on_event(Event::Started(Stage::Fit));
            let input = Input {
                path: dir.to_path_buf(),
                label: dir
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                samples,
                cornell: None,
                truth: truth.as_ref().map(|t| t.brdf.clone()),
            };
            let fr = fit_and_report(&input, &fit_dir, &cfg.fit)?;
            let [plane, hemi, fit] = fit_reports(&plan, &fr);
            ledger.record(
                Stage::Fit,
                fit_fp,
                vec!["fit/params.json".into()],
                fit.clone(),
            );
            for r in [plane, hemi, fit] {
                emit(r, &mut reports, on_event);
            }
            fit_out = Some(fr);
        }
    }
    ledger.save(&out_dir)?;

    // --- rendering (Figures 7 and 10): part of the report stage ----------------------------
    let t_render = Instant::now();
    let render_note = render_head(&session, &out_dir, fit_out.is_some());

    // --- report ----------------------------------------------------------------------------
    let mut final_plan = Plan::derive(&facts, &cfg.plan);
    final_plan.convexity_pending = false;
    let mut report = RunReport {
        session: dir.display().to_string(),
        plan: final_plan,
        stages: reports,
        total_time_s: 0.0,
    };
    report.total_time_s = t0.elapsed().as_secs_f64();
    let input_section = if input_notes.is_empty() {
        String::new()
    } else {
        let items: String = input_notes.iter().map(|n| format!("- {n}\n")).collect();
        format!("## Input\n\n{items}\n")
    };
    let md = format!(
        "# skinbrdf process: {}\n\n{}\n{input_section}## Stages: accuracy and run time\n\n{}\n\nFigures and the fit: `fit/report.md`, `fit/*.png`, `fit/*.svg`; the head rendering (Lambertian vs fitted): `render/head_comparison.png`; the same report with the figures inline: `report.html`.\n",
        dir.display(),
        "```text\n".to_string() + &report.plan.to_text() + "```\n",
        report.to_markdown()
    );
    write_atomic(&out_dir.join("report.md"), md.as_bytes())?;
    let mut figures: Vec<(String, String)> = png_figures(&out_dir, "fit")
        .into_iter()
        .map(|rel| (rel.clone(), rel))
        .collect();
    if out_dir.join(RENDER_FIGURE).is_file() {
        figures.insert(
            0,
            (
                "head rendered with a Lambertian BRDF (left) and the fitted one (right), the method's Figures 7 and 10".into(),
                RENDER_FIGURE.into(),
            ),
        );
    }
    let html = crate::report::html_page(
        &format!("skinbrdf process: {}", dir.display()),
        "",
        &report,
        &figures,
    );
    write_atomic(&out_dir.join("report.html"), html.as_bytes())?;
    // The report stage's time includes the head rendering.
    let mut r = StageReport::ran(Stage::Report, t_render.elapsed().as_secs_f64());
    match render_note {
        Ok(Some(stats)) => {
            r.metrics.push(Metric::new(
                "render_rays",
                stats.rays as f64,
                "",
                MetricKind::Cost,
            ));
            r.metrics.push(Metric::new(
                "render_time",
                t_render.elapsed().as_secs_f64(),
                "s",
                MetricKind::Cost,
            ));
            r.notes.push(format!(
                "{RENDER_FIGURE}: the scan rendered with a Lambertian BRDF and with the fitted model"
            ));
        }
        Ok(None) => {}
        Err(note) => r.notes.push(note),
    }
    on_event(Event::Finished(&r));
    report.stages.push(r);
    let json = serde_json::to_vec_pretty(&report).unwrap_or_default();
    write_atomic(&out_dir.join("report.json"), &json)?;
    Ok(ProcessOutput {
        report,
        out_dir,
        fit: fit_out,
    })
}

/// The head rendering (Lambertian against the fitted BRDF), relative to the output directory.
pub const RENDER_FIGURE: &str = "render/head_comparison.png";

/// Renders the scan with a Lambertian BRDF and with the fitted model side by side (the method's
/// Figures 7 and 10) into `out/render/`. `Ok(None)`: nothing to do (not a scan, or the figure
/// is current); `Err`: why it could not be drawn (reported as a note, never fatal).
fn render_head(
    session: &Session,
    out_dir: &Path,
    fit_ran: bool,
) -> Result<Option<skinbrdf_render::RenderStats>, String> {
    let GeometrySpec::Scan { file, units } = &session.file.geometry else {
        return Ok(None);
    };
    if !fit_ran && out_dir.join(RENDER_FIGURE).is_file() {
        return Ok(None);
    }
    let model = skinbrdf_render::load_model(&out_dir.join("fit/params.json"))
        .map_err(|e| format!("head rendering skipped: {e}"))?;
    let mesh = skinbrdf_mesh::load_mesh(
        &session.path(file),
        &skinbrdf_mesh::LoadOptions {
            unit: skinbrdf_mesh::LengthUnit::Custom(units.to_m()),
            ..Default::default()
        },
    )
    .map_err(|e| format!("head rendering skipped: {e}"))?;
    let cfg = skinbrdf_render::RenderConfig::default();
    let img = skinbrdf_render::render_comparison(&mesh.mesh, &model, &cfg)
        .map_err(|e| format!("head rendering failed: {e}"))?;
    let dir = out_dir.join("render");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    img.write(&dir.join("head_comparison"), &cfg.labels)
        .map_err(|e| format!("head rendering not written: {e}"))?;
    Ok(Some(img.stats))
}

/// The PNG figures in `base/sub`, as paths relative to `base` (`sub/name.png`), sorted.
pub fn png_figures(base: &Path, sub: &str) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(base.join(sub))
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".png"))
                .map(|n| format!("{sub}/{n}"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Within 5 degrees of the incidence plane (`phi_d` near 0 or pi).
fn near_incidence_plane(s: &skinbrdf_core::BrdfSample) -> bool {
    f64::from(s.phi_d_rad).sin().abs() * f64::from(s.theta_e_rad).sin() <= 5f64.to_radians().sin()
}

fn skipped(plan: &Plan, stage: Stage) -> StageReport {
    RunReport::skipped_from_plan(plan)
        .into_iter()
        .find(|r| r.stage == stage)
        .unwrap_or_else(|| StageReport::skipped(stage, "not planned"))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn pose_stage_reports(
    plan: &Plan,
    poses: &SessionPoses,
    truth: Option<&Truth>,
    run_time_s: f64,
    status: &StageStatus,
) -> Vec<StageReport> {
    let errs = truth.map(|t| skinbrdf_poses::session::compare_truth(poses, t));
    let corners = errs
        .as_ref()
        .map(|e| e.corner_summary())
        .unwrap_or_default();
    // The detector's own accuracy for a layout's targets: corners against their true positions.
    let corner_metric = |r: &mut StageReport, layout: &str| {
        if let Some(c) = corners.get(layout) {
            r.metrics.push(Metric::new(
                &format!("{layout}_corner_error_median"),
                c.corner_error_median_px,
                "px",
                MetricKind::Error,
            ));
        }
    };
    let mk = |stage: Stage, time: f64| -> StageReport {
        if !plan.runs(stage) {
            return skipped(plan, stage);
        }
        let mut r = StageReport::ran(stage, time);
        r.status = status.clone();
        r
    };
    let mut out = Vec::new();

    let mut r = mk(Stage::CameraCalibration, 0.0);
    if let Some(c) = &poses.calibration {
        r.metrics.push(Metric::new(
            "reprojection_rms",
            c.rms_px,
            "px",
            MetricKind::Quality,
        ));
    }
    if let Some(fe) = errs.as_ref().and_then(|e| e.focal_error_px) {
        r.metrics.push(Metric::new(
            "focal_length_error",
            fe,
            "px",
            MetricKind::Error,
        ));
    }
    out.push(r);

    let mut r = mk(Stage::CameraPoses, run_time_s);
    let cams: Vec<_> = poses
        .images
        .iter()
        .filter_map(|i| i.world_from_camera.as_ref())
        .collect();
    r.metrics.push(Metric::new(
        "images_with_camera_pose",
        cams.len() as f64,
        "",
        MetricKind::Count,
    ));
    r.metrics.push(Metric::new(
        "reprojection_rms_median",
        median(cams.iter().map(|p| p.rms_px).collect()),
        "px",
        MetricKind::Quality,
    ));
    r.metrics.push(Metric::new(
        "detect_plus_pose_per_image_median",
        median(
            poses
                .images
                .iter()
                .map(|i| i.detect_ms + i.pose_ms)
                .collect(),
        ),
        "ms",
        MetricKind::Cost,
    ));
    if let Some(e) = &errs {
        r.metrics.push(
            Metric::new(
                "camera_position_error_median",
                median(e.camera_position_error_m.clone()) * 1e3,
                "mm",
                MetricKind::Error,
            )
            .with_bound(bounds::CAMERA_POSITION_MM),
        );
        r.metrics.push(
            Metric::new(
                "camera_orientation_error_median",
                median(e.camera_orientation_error_deg.clone()),
                "deg",
                MetricKind::Error,
            )
            .with_bound(bounds::CAMERA_ORIENTATION_DEG),
        );
        corner_metric(&mut r, "reference");
    }
    let failures: usize = poses.images.iter().map(|i| i.errors.len()).sum();
    if failures > 0 {
        r.notes.push(format!(
            "{failures} individual pose estimates failed (see poses.json)"
        ));
    }
    out.push(r);

    let mut r = mk(Stage::HeadTracking, 0.0);
    if plan.runs(Stage::HeadTracking) {
        let heads: Vec<_> = poses
            .images
            .iter()
            .filter_map(|i| i.world_from_head.as_ref())
            .collect();
        r.metrics.push(Metric::new(
            "images_with_head_pose",
            heads.len() as f64,
            "",
            MetricKind::Count,
        ));
        if let Some(e) = &errs {
            r.metrics.push(
                Metric::new(
                    "head_position_error_median",
                    median(e.head_position_error_m.clone()) * 1e3,
                    "mm",
                    MetricKind::Error,
                )
                .with_bound(bounds::HEAD_POSITION_MM),
            );
            r.metrics.push(Metric::new(
                "head_orientation_error_median",
                median(e.head_orientation_error_deg.clone()),
                "deg",
                MetricKind::Error,
            ));
            corner_metric(&mut r, "headdress");
        }
        r.notes.push("timed together with camera poses".into());
    }
    out.push(r);

    let mut r = mk(Stage::FlashTriangulation, 0.0);
    if plan.runs(Stage::FlashTriangulation) {
        if let Some(e) = errs.as_ref().and_then(|e| e.light_position_error_m) {
            r.metrics.push(
                Metric::new("flash_position_error", e * 1e3, "mm", MetricKind::Error)
                    .with_bound(bounds::FLASH_POSITION_MM),
            );
        }
        if poses.light_position_cov_m2.len() == 9 {
            let c = &poses.light_position_cov_m2;
            r.metrics.push(Metric::new(
                "flash_position_sigma",
                (c[0] + c[4] + c[8]).max(0.0).sqrt() * 1e3,
                "mm",
                MetricKind::Quality,
            ));
        }
        r.notes.push("timed together with camera poses".into());
    }
    out.push(r);

    let mut r = mk(Stage::RadiometricCalibration, 0.0);
    if plan.runs(Stage::RadiometricCalibration) {
        if let Some(e) = errs.as_ref().and_then(|e| e.standard_position_error_m) {
            r.metrics.push(Metric::new(
                "standard_position_error",
                e * 1e3,
                "mm",
                MetricKind::Error,
            ));
        }
        r.notes
            .push("standard pose here; C itself is estimated during derendering".into());
    }
    out.push(r);
    out
}

fn derender_reports(plan: &Plan, run: &SessionRun) -> [StageReport; 3] {
    let d = &run.report;
    let t = &d.times;
    let mut scan = if plan.runs(Stage::ScanPreparation) {
        StageReport::ran(
            Stage::ScanPreparation,
            t.mesh_load_s + t.bvh_s + t.normals_s + t.convexity_s,
        )
    } else {
        let mut r = skipped(plan, Stage::ScanPreparation);
        r.notes.push(format!(
            "the ideal shape was tessellated instead ({} triangles, {:.3} s)",
            run.triangles,
            t.mesh_load_s + t.bvh_s + t.normals_s
        ));
        r
    };
    scan.metrics.push(Metric::new(
        "triangles",
        run.triangles as f64,
        "",
        MetricKind::Count,
    ));
    if let Some(m) = &run.mesh_report {
        scan.metrics.push(Metric::new(
            "scan_triangles_dropped",
            m.dropped_triangles() as f64,
            "",
            MetricKind::Count,
        ));
        if m.summary() != "no problems" {
            scan.notes.push(format!("scan repaired: {}", m.summary()));
        }
    }
    scan.metrics.push(Metric::new(
        "normal_fit_radius",
        d.normal_radius_m * 1e3,
        "mm",
        MetricKind::Quality,
    ));
    let shadow = if !plan.runs(Stage::ShadowRays) {
        let mut r = skipped(plan, Stage::ShadowRays);
        if d.region_can_self_shadow {
            r.notes.push(
                "the tessellated shape failed the convexity test within its tolerance; the plan's geometric fact wins".into(),
            );
        }
        r
    } else if d.shadow_rays {
        let mut r = StageReport::ran(Stage::ShadowRays, 0.0);
        r.metrics.push(Metric::new(
            "shadow_rays_cast",
            d.shadow_rays_cast as f64,
            "",
            MetricKind::Cost,
        ));
        r.notes.push(if d.region_can_self_shadow {
            "the convexity test found the region can shadow itself".into()
        } else {
            "forced although the region is convex".into()
        });
        r.notes.push("timed within derender".into());
        r
    } else if d.region_can_self_shadow {
        StageReport::skipped(Stage::ShadowRays, "disabled by the derender settings")
    } else {
        // The same reason the final plan gives, with where the fact came from.
        let mut r = StageReport::skipped(
            Stage::ShadowRays,
            "the region is convex: it cannot shadow itself",
        );
        r.notes
            .push("found by scan preparation's convexity test".into());
        r
    };
    let mut der = StageReport::ran(
        Stage::Derender,
        t.image_load_s + t.calibration_s + t.derender_s,
    );
    der.metrics.push(Metric::new(
        "samples_kept",
        d.counts.kept as f64,
        "",
        MetricKind::Count,
    ));
    let k = &d.counts;
    for (reason, n) in [
        ("off_mask", k.off_mask),
        ("on_target", k.on_target),
        ("no_surface", k.no_surface),
        ("back_facing", k.back_facing),
        ("off_region", k.off_region),
        ("grazing", k.grazing),
        ("shadowed", k.shadowed),
        ("saturated", k.saturated),
        ("below_noise_floor", k.below_noise_floor),
        ("no_ray", k.no_ray),
    ] {
        if n > 0 {
            der.metrics.push(Metric::new(
                &format!("dropped_{reason}"),
                n as f64,
                "",
                MetricKind::Count,
            ));
        }
    }
    der.metrics.push(Metric::new(
        "C_green",
        d.c[1],
        "sr^-1 m^-2",
        MetricKind::Quality,
    ));
    if let Some(c) = &d.calibration {
        der.metrics.push(Metric::new(
            "C_relative_spread_green",
            c.rel_spread[1] * 100.0,
            "%",
            MetricKind::Quality,
        ));
        der.metrics.push(Metric::new(
            "C_standard_pixels",
            c.pixels as f64,
            "",
            MetricKind::Count,
        ));
    }
    let secs = t.derender_s.max(1e-9);
    der.metrics.push(Metric::new(
        "primary_rays_per_s",
        d.primary_rays as f64 / secs / 1e6,
        "Mrays/s",
        MetricKind::Cost,
    ));
    if let Some(te) = &d.truth_error {
        der.metrics.push(
            Metric::new(
                "sample_median_rel_error",
                te.median_rel_error * 100.0,
                "%",
                MetricKind::Error,
            )
            .with_bound(bounds::SAMPLE_MEDIAN_REL_ERROR_PCT),
        );
        der.metrics.push(Metric::new(
            "sample_p90_rel_error",
            te.p90_rel_error * 100.0,
            "%",
            MetricKind::Error,
        ));
    }
    der.notes.push(format!(
        "camera from {}, light from {}, C from {}",
        run.camera_source, run.light_source, run.c_source
    ));
    [scan, shadow, der]
}

fn fit_reports(plan: &Plan, fr: &FitReport) -> [StageReport; 3] {
    let time_of = |name: &str| {
        fr.timings_s
            .iter()
            .filter(|(n, _)| n == name)
            .map(|(_, t)| *t)
            .sum::<f64>()
    };
    let mut plane = StageReport::ran(Stage::SmoothIncidencePlane, time_of("smooth"));
    plane.metrics.push(Metric::new(
        "loess_span",
        fr.smooth_span,
        "",
        MetricKind::Quality,
    ));
    plane.metrics.push(Metric::new(
        "loess_residual_sigma",
        fr.smooth_sigma * 100.0,
        "% (log)",
        MetricKind::Quality,
    ));
    let hemi = if plan.runs(Stage::SmoothHemisphere) {
        let mut r = StageReport::ran(Stage::SmoothHemisphere, 0.0);
        r.notes.push("the same local quadratic fit spans (theta_i, theta_e, phi_d); timed with the incidence plane".into());
        r
    } else {
        skipped(plan, Stage::SmoothHemisphere)
    };
    let mut fit = StageReport::ran(Stage::Fit, fr.fit.fit_time_s);
    fit.metrics.push(Metric::new(
        "samples_fitted",
        fr.n_samples as f64,
        "",
        MetricKind::Count,
    ));
    let g = &fr.fit.channels;
    if let Some(c) = g.get(1) {
        fit.metrics.push(Metric::new(
            "log_rmse_vs_samples_green",
            c.error.log_rmse,
            "",
            MetricKind::Quality,
        ));
    }
    if let Some(t) = &fr.truth {
        let c = &t.channels;
        fit.metrics.push(Metric::new(
            "model_log_rmse_vs_truth",
            (c.iter().map(|m| m.log_rmse * m.log_rmse).sum::<f64>() / 3.0).sqrt(),
            "",
            MetricKind::Error,
        ));
        fit.metrics.push(Metric::new(
            "model_median_rel_error_vs_truth",
            median(c.iter().map(|m| m.median_rel_err * 100.0).collect()),
            "%",
            MetricKind::Error,
        ));
    }
    for w in &fr.fit.warnings {
        fit.notes.push(w.clone());
    }
    [plane, hemi, fit]
}
