//! `skinbrdf process SESSION_DIR`: the planned pipeline as a loop over its units.
//!
//! 1. Load and validate the session; derive [`SceneFacts`] from what it already has, and the
//!    [`Plan`] from them.
//! 2. Take the output directory's lock (a second run on it is refused), remove temporary files
//!    that dead runs left, and load the ledger.
//! 3. For each unit of [`crate::stages`] in order (photogrammetry, derendering, smoothing and
//!    fitting, the head rendering): skip it when the plan runs none of its stages; reuse it when
//!    the fingerprint of every input it reads *and* the digests of every output it wrote match
//!    the ledger; otherwise run it, and record it in the ledger (written atomically) before the
//!    next unit starts, so an interrupted run resumes after the last finished unit.
//! 4. Write `report.md`, `report.html` and `report.json`: the same figures whether a stage ran
//!    now or was reused.
//!
//! Derendering uses the pose stage's poses when it ran, else the session's own known poses,
//! never the ground truth: truth is only read to score each stage.

use std::path::{Path, PathBuf};
use std::time::Instant;

use skinbrdf_derender::DerenderConfig;
use skinbrdf_fit::report::{FitReport, ReportOptions};
use skinbrdf_fit::FitConfig;
use skinbrdf_poses::PoseConfig;
use skinbrdf_session::{
    BadImagePolicy, DecodeCache, GeometrySpec, ImageRole, RawMode, Session, TargetGroup,
};

/// The directory of the output directory where a run keeps the raw files it decoded (its
/// [`DecodeCache`]; removed when the run ends).
pub const DECODED_DIR: &str = "decoded";

use crate::ledger::{write_atomic, Ledger, RunLock};
use crate::plan::{Geometry, Plan, PlanOptions, SceneFacts, Stage};
use crate::report::{Metric, MetricKind, RunReport, StageReport};
use crate::stages::{Ctx, DerenderUnit, FitUnit, PoseUnit, RenderUnit, StageUnit, SurveyUnit};

pub use crate::metrics::bounds;
pub use crate::stages::RENDER_FIGURE;

/// Errors of `process`.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// The session did not load.
    #[error("{dir}: the session is not valid")]
    Session {
        /// Session directory.
        dir: PathBuf,
        /// Every problem.
        source: skinbrdf_session::SessionErrors,
    },
    /// `truth.json` is present but unreadable.
    #[error(transparent)]
    Truth {
        /// Why it did not load (names the file).
        source: skinbrdf_session::FileError,
    },
    /// An image is unreadable or implausible.
    #[error(
        "{dir}: unusable images (--skip-bad-images leaves them out and lists them in the report)"
    )]
    Images {
        /// Session directory.
        dir: PathBuf,
        /// Each image and its cause.
        source: skinbrdf_session::SessionErrors,
    },
    /// Photogrammetry failed.
    #[error("photogrammetry")]
    Poses(#[from] skinbrdf_poses::PoseError),
    /// Derendering failed.
    #[error("derendering")]
    Derender(#[from] skinbrdf_derender::DerenderError),
    /// The poses for derendering could not be resolved, or derendering failed.
    #[error(transparent)]
    DerenderSession(#[from] crate::pose_inputs::DerenderSessionError),
    /// Smoothing or fitting failed.
    #[error("fitting")]
    Fit(#[from] skinbrdf_fit::report::ReportError),
    /// Sample file I/O.
    #[error(transparent)]
    Samples(#[from] skinbrdf_samples::SamplesError),
    /// Ledger, lock or output I/O.
    #[error(transparent)]
    Ledger(#[from] crate::ledger::LedgerError),
    /// An image could not be read, or a figure not written.
    #[error(transparent)]
    File(#[from] skinbrdf_session::FileError),
    /// A calibration could not be serialised as a `[camera]` table.
    #[error("{path}: cannot serialise the calibration")]
    CameraFile {
        /// The camera file.
        path: PathBuf,
        /// The serialiser's error.
        source: toml::ser::Error,
    },
    /// An output or stage file could not be read, or its directory not created.
    #[error("{path}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A stage file could not be parsed.
    #[error("{path}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The serde error.
        source: serde_json::Error,
    },
    /// An output could not be written as JSON: a NaN or infinity (named by its field's path),
    /// or a value serde_json refuses. The message names the file.
    #[error(transparent)]
    JsonOut(#[from] skinbrdf_core::json::JsonError),
    /// A stage needs poses that no earlier stage produced.
    #[error("{dir}: no poses: the session gives none and {poses} does not exist; run `skinbrdf poses {dir}` (or `skinbrdf process {dir}`) first")]
    NoPoses {
        /// Session directory.
        dir: PathBuf,
        /// The pose stage's output it looked for.
        poses: PathBuf,
    },
    /// The surveyed headdress is in a provisional frame and nothing relates it to the scan.
    #[error(
        "the placement survey placed the headdress in the frame of target {anchor}, but nothing \
         relates it to the head scan: state one headdress target's corners (scan frame) in the \
         rig, or give a textured scan or a points file to register it"
    )]
    HeadFrame {
        /// The survey's anchor target.
        anchor: u32,
    },
    /// The survey could not be registered to the head scan.
    #[error("scan registration")]
    Registration {
        /// Why.
        source: skinbrdf_register::RegisterError,
    },
    /// The scan could not be loaded for the registration.
    #[error("scan registration")]
    RegistrationScan {
        /// Why (names the file).
        source: skinbrdf_mesh::MeshError,
    },
    /// No samples survived derendering.
    #[error("no BRDF samples survived derendering (see the derender stage's drop counts); nothing to fit")]
    NoSamples,
    /// A stage's self-checks failed: the stages after it did not run (the report, written,
    /// says so).
    #[error(
        "{stage} FAILED its checks, so the stages that depend on it did not run (report: {}; \
         `--accept-failed-checks` goes on):\n{}",
        report.display(),
        failed.iter().map(|c| format!("  - {}", c.to_line())).collect::<Vec<_>>().join("\n")
    )]
    ChecksFailed {
        /// The stage whose checks failed first.
        stage: &'static str,
        /// Every check that failed.
        failed: Vec<crate::checks::Check>,
        /// The report written.
        report: PathBuf,
    },
}

/// Settings of `process`.
#[derive(Debug, Clone)]
pub struct ProcessConfig {
    /// What the user asked the plan for.
    pub plan: PlanOptions,
    /// Placement survey settings.
    pub survey: skinbrdf_poses::SurveyConfig,
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
    /// Score against this ground truth instead of the session's own `truth.json` (keyed to the
    /// session's images by exposure index; see [`skinbrdf_session::Truth::keyed_to`]).
    pub truth_file: Option<PathBuf>,
    /// Go on after a stage FAILED its self-checks ([`crate::checks`]); the report still says
    /// FAILED.
    pub accept_failed_checks: bool,
    /// How camera raw images load: per photosite (default, full resolution, each photosite
    /// its own sample) or as 2x2 superpixels (faster); see `skinbrdf_session::linear`.
    pub raw_mode: RawMode,
}

impl ProcessConfig {
    /// The defaults: a 2-lobe Lafortune fit with figures, no MERL table.
    pub fn new() -> Self {
        Self {
            plan: PlanOptions::default(),
            survey: skinbrdf_poses::SurveyConfig::DEFAULT,
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
            truth_file: None,
            accept_failed_checks: false,
            raw_mode: RawMode::Photosite,
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
        placements_known: !f
            .targets
            .unplaced
            .iter()
            .any(|t| matches!(t.group, TargetGroup::Reference | TargetGroup::Headdress)),
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

/// Runs the pipeline on a session directory.
pub fn process(
    dir: &Path,
    cfg: &ProcessConfig,
    on_event: &mut dyn FnMut(Event<'_>),
) -> Result<ProcessOutput, ProcessError> {
    let t0 = Instant::now();
    let Opened {
        session,
        truth,
        out_dir,
        lock: _lock,
        stale,
        mut ledger,
    } = open(dir, cfg)?;
    let (input_metric, input_notes) = input_findings(&session);

    let facts = scene_facts(&session);
    let plan = Plan::derive(&facts, &cfg.plan);
    on_event(Event::Plan(&plan));
    // The placement survey first: the other units work on the surveyed session.
    let mut reports: Vec<StageReport> = Vec::new();
    let (survey_reports, surveyed, facts) = survey_step(
        &session,
        truth.as_ref(),
        cfg,
        &out_dir,
        facts,
        &plan,
        &mut ledger,
        on_event,
    )?;
    let mut ctx = Ctx {
        session: surveyed.as_ref().map_or(&session, |s| &s.session),
        truth: truth.as_ref(),
        cfg,
        out_dir: out_dir.clone(),
        facts,
        plan,
        // The survey's placements are in the session; the pose stage reads its sds.
        survey: surveyed.as_ref().map(|s| s.survey.clone()),
        detections: surveyed.as_ref().and_then(|s| s.detections.clone()),
        stated_camera: session.file.camera,
        poses: None,
        samples: None,
        fit: None,
    };
    let mut survey_reports = survey_reports;
    let mut failed: Option<(Stage, Vec<crate::checks::Check>)> = None;
    if ctx.survey.is_some() {
        let checks = SurveyUnit.checks(&ctx, &survey_reports);
        let failures = crate::checks::attach(&mut survey_reports, checks);
        if !failures.is_empty() && !cfg.accept_failed_checks {
            failed = Some((Stage::PlacementSurvey, failures));
        }
    }
    for mut r in survey_reports {
        r.metrics.insert(0, input_metric.clone());
        r.notes.extend(input_notes.iter().cloned());
        on_event(Event::Finished(&r));
        reports.push(r);
    }
    let units: [&dyn StageUnit; 4] = [&PoseUnit, &DerenderUnit, &FitUnit, &RenderUnit];
    for unit in units {
        if let Some((stage, _)) = &failed {
            reports.extend(not_run_after(&ctx.plan, &reports, *stage));
            break;
        }
        let planned = unit.planned(&ctx);
        let mut unit_reports = run_unit(unit, &mut ctx, &mut ledger, cfg.force, on_event)?;
        if planned {
            let checks = unit.checks(&ctx, &unit_reports);
            let failures = crate::checks::attach(&mut unit_reports, checks);
            if !failures.is_empty() && !cfg.accept_failed_checks {
                let stage = unit_reports
                    .iter()
                    .find(|r| r.failed())
                    .map_or(unit.first_stage(), |r| r.stage);
                failed = Some((stage, failures));
            }
        }
        for mut r in unit_reports {
            if reports.is_empty() {
                r.metrics.insert(0, input_metric.clone());
                r.notes.extend(input_notes.iter().cloned());
            }
            on_event(Event::Finished(&r));
            reports.push(r);
        }
    }
    if let Some(r) = reports.iter_mut().find(|r| r.stage == Stage::Report) {
        if !stale.is_empty() {
            r.notes.push(format!(
                "removed {} temporary file(s) left by an interrupted run",
                stale.len()
            ));
        }
    }

    let mut final_plan = Plan::derive(&ctx.facts, &cfg.plan);
    final_plan.convexity_pending = false;
    let mut report = RunReport {
        session: dir.display().to_string(),
        plan: final_plan,
        stages: reports,
        total_time_s: 0.0,
    };
    report.total_time_s = t0.elapsed().as_secs_f64();
    write_reports(dir, &out_dir, &report, &input_notes)?;
    if let Some((stage, failed)) = failed {
        return Err(ProcessError::ChecksFailed {
            stage: stage.name(),
            failed,
            report: out_dir.join("report.md"),
        });
    }
    Ok(ProcessOutput {
        report,
        out_dir,
        fit: ctx.fit,
    })
}

/// The reports of the planned stages after `failed` that have none yet: skipped, because
/// `failed` FAILED its checks.
fn not_run_after(plan: &Plan, reports: &[StageReport], failed: Stage) -> Vec<StageReport> {
    let reason = format!("not run: {} FAILED its checks", failed.name());
    Stage::ALL
        .iter()
        .skip_while(|&&s| s != failed)
        .filter(|&&s| plan.runs(s) && !reports.iter().any(|r| r.stage == s))
        .map(|&s| StageReport::skipped(s, &reason))
        .collect()
}

/// Runs (or reuses) the placement survey unit: its reports, the session with the surveyed
/// placements written in (`None` when the plan skips the survey) and the facts as the unit left
/// them.
#[allow(clippy::too_many_arguments)]
pub(crate) fn survey_step(
    session: &Session,
    truth: Option<&skinbrdf_session::Truth>,
    cfg: &ProcessConfig,
    out_dir: &Path,
    facts: SceneFacts,
    plan: &Plan,
    ledger: &mut Ledger,
    on_event: &mut dyn FnMut(Event<'_>),
) -> Result<(Vec<StageReport>, Option<Surveyed>, SceneFacts), ProcessError> {
    let mut ctx = Ctx {
        session,
        truth,
        cfg,
        out_dir: out_dir.to_path_buf(),
        facts,
        plan: plan.clone(),
        survey: None,
        detections: None,
        stated_camera: session.file.camera,
        poses: None,
        samples: None,
        fit: None,
    };
    let reports = run_unit(&SurveyUnit, &mut ctx, ledger, cfg.force, on_event)?;
    let surveyed = match ctx.survey.take() {
        Some(s) => {
            if let skinbrdf_poses::HeadGauge::Provisional { anchor } = s.head_gauge {
                return Err(ProcessError::HeadFrame { anchor });
            }
            let mut surveyed = session.clone();
            s.apply_to(&mut surveyed.file);
            Some(Surveyed {
                survey: s,
                session: surveyed,
                detections: ctx.detections.take(),
            })
        }
        None => None,
    };
    Ok((reports, surveyed, ctx.facts))
}

/// The placement survey's result and the session with its placements written in.
#[derive(Debug, Clone)]
pub struct Surveyed {
    /// The survey.
    pub survey: skinbrdf_poses::Survey,
    /// The session, every placement given.
    pub session: Session,
    /// The tags found in the session's images, when the survey ran in this run.
    pub detections: Option<std::sync::Arc<skinbrdf_poses::SessionDetections>>,
}

/// A run's session, truth, output directory, lock and ledger.
pub(crate) struct Opened {
    pub(crate) session: Session,
    pub(crate) truth: Option<skinbrdf_session::Truth>,
    pub(crate) out_dir: PathBuf,
    pub(crate) lock: RunLock,
    pub(crate) stale: Vec<PathBuf>,
    pub(crate) ledger: Ledger,
}

/// Loads and checks the session and its truth, takes the output directory's lock, removes the
/// temporary files of dead runs and loads the ledger (steps 1 and 2 of the module docs).
pub(crate) fn open(dir: &Path, cfg: &ProcessConfig) -> Result<Opened, ProcessError> {
    let mut session = Session::load(dir).map_err(|source| ProcessError::Session {
        dir: dir.to_path_buf(),
        source,
    })?;
    session.truth_file = cfg.truth_file.clone();
    session.set_raw_mode(cfg.raw_mode);
    let out_dir = cfg.out_dir.clone().unwrap_or_else(|| dir.join("out"));
    // The input check decodes every raw file once; the stages read the decoded files back.
    session.keep_decoded(DecodeCache::new(out_dir.join(DECODED_DIR)));
    let policy = if cfg.skip_bad_images {
        BadImagePolicy::Skip
    } else {
        BadImagePolicy::Fail
    };
    session
        .check_images(policy)
        .map_err(|source| ProcessError::Images {
            dir: dir.to_path_buf(),
            source,
        })?;
    let truth = match session.load_truth() {
        None => None,
        Some(r) => Some(r.map_err(|source| ProcessError::Truth { source })?),
    };
    std::fs::create_dir_all(&out_dir).map_err(|source| crate::ledger::LedgerError::Io {
        path: out_dir.clone(),
        source,
    })?;
    let lock = RunLock::acquire(&out_dir)?;
    let stale = skinbrdf_core::fsio::remove_stale_temp_files(&out_dir);
    let ledger = if cfg.force {
        Ledger::default()
    } else {
        Ledger::load(&out_dir)?
    };
    Ok(Opened {
        session,
        truth,
        out_dir,
        lock,
        stale,
        ledger,
    })
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
        .map(|s| {
            format!(
                "skipped image `{}` ({}): {}",
                s.file,
                s.role.name(),
                s.cause
            )
        })
        .collect();
    notes.extend(session.linearization_source.note().map(str::to_string));
    (metric, notes)
}

/// Runs one unit under the ledger's contract (see the module docs); returns its stages'
/// reports.
pub(crate) fn run_unit(
    unit: &dyn StageUnit,
    ctx: &mut Ctx<'_>,
    ledger: &mut Ledger,
    force: bool,
    on_event: &mut dyn FnMut(Event<'_>),
) -> Result<Vec<StageReport>, ProcessError> {
    if !unit.planned(ctx) {
        return Ok(unit.skipped(ctx));
    }
    let fp = unit.fingerprint(ctx)?;
    let mut note = None;
    if !force {
        if let Some(entry) = ledger.reusable(unit.unit(), &fp, &ctx.out_dir).cloned() {
            match unit.load(ctx, &entry.reports) {
                Ok(()) => return Ok(crate::stages::as_reused(&entry.reports)),
                Err(e) => {
                    note = Some(format!(
                        "the recorded outputs did not load ({}): ran again",
                        skinbrdf_core::error_text(&e)
                    ))
                }
            }
        }
    }
    // Forget the old entry before touching its outputs: a run that dies midway reruns it.
    if ledger.units.contains_key(&unit.unit()) {
        ledger.forget(unit.unit());
        ledger.save(&ctx.out_dir)?;
    }
    on_event(Event::Started(unit.first_stage()));
    let (mut reports, outputs) = unit.run(ctx)?;
    if let (Some(n), Some(r)) = (note, reports.last_mut()) {
        r.notes.push(n);
    }
    ledger.record(unit.unit(), fp, &outputs, reports.clone(), &ctx.out_dir)?;
    ledger.save(&ctx.out_dir)?;
    Ok(reports)
}

/// Writes `report.md`, `report.html` and `report.json` into the output directory.
fn write_reports(
    dir: &Path,
    out_dir: &Path,
    report: &RunReport,
    input_notes: &[String],
) -> Result<(), ProcessError> {
    let input_section = if input_notes.is_empty() {
        String::new()
    } else {
        let items: String = input_notes.iter().map(|n| format!("- {n}\n")).collect();
        format!("## Input\n\n{items}\n")
    };
    let checks = report.checks_markdown();
    let checks_section = if checks.is_empty() {
        String::new()
    } else {
        format!("## Self-checks\n\n{checks}\n")
    };
    let md = format!(
        "# skinbrdf process: {}\n\n{}\n{input_section}## Stages: accuracy and run time\n\n{}\n\n{checks_section}Figures and the fit: `fit/report.md`, `fit/*.png`, `fit/*.svg`; the head rendering (Lambertian vs fitted): `render/head_comparison.png`; the same report with the figures inline: `report.html`.\n",
        dir.display(),
        "```text\n".to_string() + &report.plan.to_text() + "```\n",
        report.to_markdown()
    );
    write_atomic(&out_dir.join("report.md"), md.as_bytes())?;
    let mut figures: Vec<(String, String)> = png_figures(out_dir, "fit")
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
        report,
        &figures,
    );
    write_atomic(&out_dir.join("report.html"), html.as_bytes())?;
    let path = out_dir.join("report.json");
    write_atomic(&path, &skinbrdf_core::json::to_vec_pretty(&path, report)?)?;
    Ok(())
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
