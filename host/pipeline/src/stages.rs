//! The pipeline's typed units of work, each a [`StageUnit`]: its inputs (a [`Fingerprint`] of
//! every file and option it reads), `run` (which writes its outputs and returns its stages'
//! reports with typed figures) and `load` (which reads a previous run's outputs back when the
//! ledger says they are current).
//!
//! | unit | stages | reads | writes |
//! |---|---|---|---|
//! | [`SurveyUnit`] | placement survey | session files | `survey.json` |
//! | [`PoseUnit`] | calibration, camera poses, head tracking, flash, standard | session files | `poses.json` |
//! | [`DerenderUnit`] | scan preparation, shadow rays, derender | session files, `poses.json` | `samples.skbs` |
//! | [`FitUnit`] | smoothing (plane, hemisphere), fit | `samples.skbs`, truth | `fit/*` |
//! | [`RenderUnit`] | report (the head rendering) | `fit/params.json`, scan | `render/*` |
//!
//! Truth (`truth.json`) is read only to score: it enters each unit's fingerprint because the
//! figures depend on it, never its results.

use std::path::{Path, PathBuf};
use std::time::Instant;

use skinbrdf_core::stats::median_finite;
use skinbrdf_derender::{DerenderConfig, SessionRun};

use crate::pose_inputs::{PoseChoice, SessionOptions};
use skinbrdf_fit::report::{fit_and_report, FitReport, Input};
use skinbrdf_poses::SessionPoses;
use skinbrdf_samples::SampleHeader;
use skinbrdf_session::{GeometrySpec, RegistrationFit, Session, Truth};

use crate::ledger::{write_atomic, Fingerprint, FingerprintBuilder, Unit};
use crate::metrics::{
    CalibrationMetrics, CameraPoseMetrics, DerenderMetrics, DropCounts, FitMetrics, FlashMetrics,
    HeadTrackingMetrics, ReportMetrics, ScanMetrics, ShadowMetrics, SmoothMetrics, StageMetrics,
    StandardMetrics, SurveyMetrics,
};
use crate::plan::{Plan, PlanOptions, SceneFacts, Stage};
use crate::process::{ProcessConfig, ProcessError};
use crate::report::{RunReport, StageReport, StageStatus};

/// The pose stage's output file, relative to the output directory.
pub const POSES_FILE: &str = "poses.json";
/// The placement survey's output file, relative to the output directory.
pub const SURVEY_FILE: &str = "survey.json";
/// The derender stage's output file, relative to the output directory.
pub const SAMPLES_FILE: &str = "samples.skbs";
/// The fit's parameter file, relative to the output directory.
pub const PARAMS_FILE: &str = "fit/params.json";
/// The fit's own report, relative to the output directory.
pub const FIT_REPORT_FILE: &str = "fit/report.md";
/// The head rendering (Lambertian against the fitted BRDF), relative to the output directory.
pub const RENDER_FIGURE: &str = "render/head_comparison.png";

/// What the units share while a run goes through the plan.
#[derive(Debug)]
pub struct Ctx<'a> {
    /// The session.
    pub session: &'a Session,
    /// Ground truth, for scoring only.
    pub truth: Option<&'a Truth>,
    /// The run's settings.
    pub cfg: &'a ProcessConfig,
    /// Output directory.
    pub out_dir: PathBuf,
    /// What the scene has (the convexity fact is filled in by scan preparation).
    pub facts: SceneFacts,
    /// The plan.
    pub plan: Plan,
    /// The placement survey's result, when it ran or was reused.
    pub survey: Option<skinbrdf_poses::Survey>,
    /// The tags the survey found in the session's images, when it ran in this run (the pose
    /// stage uses them instead of detecting again when they fit its session and detector).
    pub detections: Option<std::sync::Arc<skinbrdf_poses::SessionDetections>>,
    /// The camera as the session states it before the survey (the survey writes its own
    /// focal length in as the pose stage's guess; the checks compare with the files').
    pub stated_camera: skinbrdf_session::CameraSpec,
    /// The pose stage's result, when it ran or was reused.
    pub poses: Option<SessionPoses>,
    /// The derendered samples.
    pub samples: Option<Vec<skinbrdf_core::BrdfSample>>,
    /// The fit, when it ran in this run.
    pub fit: Option<FitReport>,
}

/// One unit of work (see the module docs).
pub trait StageUnit {
    /// The ledger's name for it.
    fn unit(&self) -> Unit;
    /// The stage announced when it starts.
    fn first_stage(&self) -> Stage;
    /// Whether the plan runs any of its stages; by default a unit always runs.
    fn planned(&self, _ctx: &Ctx<'_>) -> bool {
        true
    }
    /// The reports of its stages when none runs; by default none (a unit that always runs).
    fn skipped(&self, _ctx: &Ctx<'_>) -> Vec<StageReport> {
        Vec::new()
    }
    /// The fingerprint of everything it reads.
    fn fingerprint(&self, ctx: &Ctx<'_>) -> Result<Fingerprint, ProcessError>;
    /// Runs: writes its outputs and returns its stages' reports and the files it wrote
    /// (relative to the output directory).
    fn run(&self, ctx: &mut Ctx<'_>) -> Result<(Vec<StageReport>, Vec<String>), ProcessError>;
    /// Reads a previous run's outputs back into the context (`recorded`: that run's reports).
    fn load(&self, ctx: &mut Ctx<'_>, recorded: &[StageReport]) -> Result<(), ProcessError>;
    /// Its self-checks ([`crate::checks`]) on what it ran or reused, by stage; by default none.
    fn checks(
        &self,
        _ctx: &Ctx<'_>,
        _reports: &[StageReport],
    ) -> Vec<(Stage, crate::checks::Check)> {
        Vec::new()
    }
}

/// Every file a session's stages read: `session.toml`, the images and their masks, the scan
/// and the capture record; `truth.json` when present (scoring).
pub fn session_input_files(session: &Session) -> Vec<PathBuf> {
    let f = &session.file;
    let mut v = vec![session.dir.join("session.toml")];
    for img in &f.images {
        v.push(session.path(&img.file));
        if let Some(m) = &img.mask {
            v.push(session.path(m));
        }
    }
    if let GeometrySpec::Scan { file, .. } = &f.geometry {
        v.push(session.path(file));
    }
    if let Some(c) = &f.capture {
        v.push(session.path(c));
    }
    let truth = session.truth_path();
    if truth.is_file() {
        v.push(truth);
    }
    v
}

fn session_fingerprint(session: &Session) -> Result<FingerprintBuilder, ProcessError> {
    let mut fp = FingerprintBuilder::new();
    for p in session_input_files(session) {
        fp = fp.file(&p)?;
    }
    Ok(fp)
}

/// The skipped report of a stage, with the plan's reason.
pub fn skipped(plan: &Plan, stage: Stage) -> StageReport {
    RunReport::skipped_from_plan(plan)
        .into_iter()
        .find(|r| r.stage == stage)
        .unwrap_or_else(|| StageReport::skipped(stage, "not planned"))
}

fn json_bytes<T: serde::Serialize>(path: &Path, v: &T) -> Result<Vec<u8>, ProcessError> {
    Ok(skinbrdf_core::json::to_vec_pretty(path, v)?)
}

// --- placement survey ------------------------------------------------------------------------

/// The placement survey (see [`skinbrdf_poses::survey()`]).
#[derive(Debug)]
pub struct SurveyUnit;

impl StageUnit for SurveyUnit {
    fn unit(&self) -> Unit {
        Unit::Survey
    }
    fn first_stage(&self) -> Stage {
        Stage::PlacementSurvey
    }
    fn planned(&self, ctx: &Ctx<'_>) -> bool {
        ctx.plan.runs(Stage::PlacementSurvey)
    }
    fn skipped(&self, ctx: &Ctx<'_>) -> Vec<StageReport> {
        vec![skipped(&ctx.plan, Stage::PlacementSurvey)]
    }
    fn fingerprint(&self, ctx: &Ctx<'_>) -> Result<Fingerprint, ProcessError> {
        Ok(session_fingerprint(ctx.session)?
            .value("survey", &ctx.cfg.survey)
            .finish())
    }
    fn run(&self, ctx: &mut Ctx<'_>) -> Result<(Vec<StageReport>, Vec<String>), ProcessError> {
        let t = Instant::now();
        let (mut survey, detections) =
            skinbrdf_poses::survey_detected(ctx.session, &ctx.cfg.survey)?;
        ctx.detections = Some(std::sync::Arc::new(detections));
        let mut files = vec![SURVEY_FILE.to_string()];
        let registration = register_to_scan(ctx.session, &mut survey)?;
        if let Some(reg) = &registration {
            let path = ctx.out_dir.join(REGISTRATION_FILE);
            write_atomic(&path, &json_bytes(&path, reg)?)?;
            files.push(REGISTRATION_FILE.into());
        }
        let run_time_s = t.elapsed().as_secs_f64();
        let path = ctx.out_dir.join(SURVEY_FILE);
        write_atomic(&path, &json_bytes(&path, &survey)?)?;
        let mut report = survey_report(&survey, ctx.truth, run_time_s);
        if let Some(reg) = &registration {
            let a = &reg.alignment;
            report.notes.push(format!(
                "scan registration ({}): {} targets, rms {:.3} mm, rotation sd {:.4} deg, {} left out",
                reg.method,
                a.residuals.len(),
                a.rms_mm,
                a.rotation_sd_deg,
                a.dropped.len()
            ));
        }
        ctx.survey = Some(survey);
        Ok((vec![report], files))
    }
    fn load(&self, ctx: &mut Ctx<'_>, _recorded: &[StageReport]) -> Result<(), ProcessError> {
        let path = ctx.out_dir.join(SURVEY_FILE);
        let bytes = std::fs::read(&path).map_err(|source| ProcessError::Read {
            path: path.clone(),
            source,
        })?;
        ctx.survey = Some(
            serde_json::from_slice(&bytes).map_err(|source| ProcessError::Json { path, source })?,
        );
        Ok(())
    }
    fn checks(
        &self,
        ctx: &Ctx<'_>,
        _reports: &[StageReport],
    ) -> Vec<(Stage, crate::checks::Check)> {
        ctx.survey
            .as_ref()
            .map_or_else(Vec::new, crate::checks::survey_checks)
    }
}

/// The scan registration's report, relative to the output directory.
pub const REGISTRATION_FILE: &str = "registration.json";

/// When the survey's head frame is provisional and the scan carries a texture: finds the
/// headdress targets on the scan and moves the surveyed headdress into the scan's frame (a
/// rigid fit over all their corners; a badly scanned target is left out and named).
fn register_to_scan(
    session: &Session,
    survey: &mut skinbrdf_poses::Survey,
) -> Result<Option<skinbrdf_register::RegistrationReport>, ProcessError> {
    if survey.head_frame_fixed() {
        return Ok(None);
    }
    let GeometrySpec::Scan {
        file,
        units,
        accept_repair_loss,
    } = &session.file.geometry
    else {
        return Ok(None);
    };
    let spec = session.file.registration.clone().unwrap_or_default();
    let kind = match spec.fit {
        RegistrationFit::Rigid => skinbrdf_register::AlignKind::Rigid,
        RegistrationFit::Similarity => skinbrdf_register::AlignKind::Similarity,
    };
    let corners = survey.headdress_corners();
    // Picked points, when the session gives them, else the scan's texture.
    if let Some(points) = &spec.points {
        let reg = skinbrdf_register::register_by_points(
            &corners,
            &session.path(points),
            kind,
            &skinbrdf_register::AlignConfig::default(),
        )
        .map_err(|source| ProcessError::Registration { source })?;
        transform_head(survey, &reg, "points");
        return Ok(Some(reg));
    }
    let path = session.path(file);
    let scan = skinbrdf_mesh::load_textured(
        &path,
        &skinbrdf_mesh::LoadOptions {
            unit: skinbrdf_mesh::LengthUnit::Custom(units.to_m()),
            policy: skinbrdf_derender::from_session::scan_repair_policy(*accept_repair_loss),
        },
    )
    .map_err(|source| ProcessError::RegistrationScan { source })?;
    if matches!(scan.appearance, skinbrdf_mesh::Appearance::None) {
        return Ok(None);
    }
    let sizes: Vec<(u32, f64)> = survey
        .targets
        .iter()
        .filter(|t| t.group == skinbrdf_session::TargetGroup::Headdress)
        .map(|t| (t.id, t.size_m))
        .collect();
    let reg = skinbrdf_register::register_by_texture(
        &corners,
        &sizes,
        &scan,
        kind,
        &skinbrdf_register::ScanTargetConfig::default(),
        &skinbrdf_register::AlignConfig::default(),
    )
    .map_err(|source| ProcessError::Registration { source })?;
    transform_head(survey, &reg, "texture");
    Ok(Some(reg))
}

/// Moves the surveyed headdress into the scan's frame by a registration, with its uncertainty.
fn transform_head(
    survey: &mut skinbrdf_poses::Survey,
    reg: &skinbrdf_register::RegistrationReport,
    method: &str,
) {
    let a = &reg.alignment;
    survey.transform_head(
        &a.scan_from_survey,
        a.scale,
        method,
        &skinbrdf_poses::FrameUncertainty {
            centroid_sd_mm: a.centroid_sd_mm,
            rotation_sd_deg: a.rotation_sd_deg,
        },
    );
}

/// RMS over a group's surveyed targets of the mean corner distance to the truth, mm (`None`
/// without truth placements).
pub fn survey_rms_error_mm(
    survey: &skinbrdf_poses::Survey,
    truth: &Truth,
    group: skinbrdf_session::TargetGroup,
    flash_only: bool,
) -> Option<f64> {
    let errs: Vec<f64> = survey
        .targets
        .iter()
        .filter(|t| t.group == group && t.flash_only == flash_only)
        .filter_map(|t| {
            let p = truth
                .placements
                .iter()
                .find(|p| p.id == t.id && p.group == group)?;
            Some(
                (0..4)
                    .map(|k| t.corners_m[k].distance(p.corners_m[k]))
                    .sum::<f64>()
                    * 250.0,
            )
        })
        .collect();
    (!errs.is_empty()).then(|| (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt())
}

/// The survey's report: typed figures and, with truth placements, its errors.
pub fn survey_report(
    survey: &skinbrdf_poses::Survey,
    truth: Option<&Truth>,
    run_time_s: f64,
) -> StageReport {
    use skinbrdf_session::TargetGroup;
    let err = |g| truth.and_then(|t| survey_rms_error_mm(survey, t, g, false));
    let mut r = StageReport::ran(Stage::PlacementSurvey, run_time_s).with_figures(
        StageMetrics::Survey(SurveyMetrics {
            targets_surveyed: survey.targets.len(),
            targets_left_out: survey.issues.iter().filter(|i| !i.is_warning()).count(),
            position_sigma_median_mm: median_finite(
                &survey
                    .targets
                    .iter()
                    .map(|t| t.position_sigma_mm)
                    .collect::<Vec<_>>(),
            ),
            reprojection_rms_px: survey.bundle.final_rms_px,
            parameters: survey.bundle.parameters,
            images_used: survey.images_used,
            survey_images: survey.survey_images_used,
            reference_rms_error_mm: err(TargetGroup::Reference),
            headdress_rms_error_mm: err(TargetGroup::Headdress),
            flash_only_rms_error_mm: truth
                .and_then(|t| survey_rms_error_mm(survey, t, TargetGroup::Reference, true)),
        }),
    );
    r.notes.push(format!("head frame: {}", survey.head_gauge));
    if survey.intrinsics_restart {
        r.notes.push(
            "camera to be calibrated: surveyed twice, the second time starting from the \
             intrinsics the first refined (timings are the second's, the total both)"
                .into(),
        );
    }
    let helped = survey
        .issues
        .iter()
        .filter(|i| i.survey_images_would_help())
        .count();
    if helped > 0 {
        r.notes.push(format!(
            "{helped} target(s) seen too rarely or placed too uncertainly: survey images that \
             see them from other directions would place them (`skinbrdf ingest --survey`; {} \
             survey image(s) used)",
            survey.survey_images_used
        ));
    }
    for i in &survey.issues {
        r.notes.push(format!("{}: {i}", i.label()));
    }
    r
}

// --- photogrammetry --------------------------------------------------------------------------

/// Photogrammetry (see the module docs).
#[derive(Debug)]
pub struct PoseUnit;

/// The pose stages in order.
pub const POSE_STAGES: [Stage; 5] = [
    Stage::CameraCalibration,
    Stage::CameraPoses,
    Stage::HeadTracking,
    Stage::FlashTriangulation,
    Stage::RadiometricCalibration,
];

impl StageUnit for PoseUnit {
    fn unit(&self) -> Unit {
        Unit::Poses
    }
    fn first_stage(&self) -> Stage {
        Stage::CameraPoses
    }
    fn planned(&self, ctx: &Ctx<'_>) -> bool {
        POSE_STAGES.iter().any(|&s| ctx.plan.runs(s))
    }
    fn skipped(&self, ctx: &Ctx<'_>) -> Vec<StageReport> {
        POSE_STAGES.iter().map(|&s| skipped(&ctx.plan, s)).collect()
    }
    fn fingerprint(&self, ctx: &Ctx<'_>) -> Result<Fingerprint, ProcessError> {
        Ok(session_fingerprint(ctx.session)?
            .value("poses", &ctx.cfg.poses)
            .value("skip_bad_images", &ctx.cfg.skip_bad_images)
            .value("start_camera", &ctx.session.file.camera)
            .finish())
    }
    fn run(&self, ctx: &mut Ctx<'_>) -> Result<(Vec<StageReport>, Vec<String>), ProcessError> {
        let t = Instant::now();
        let poses = match &ctx.detections {
            Some(d) => skinbrdf_poses::estimate_session_detected(ctx.session, &ctx.cfg.poses, d)?,
            None => skinbrdf_poses::estimate_session(ctx.session, &ctx.cfg.poses)?,
        };
        let run_time_s = t.elapsed().as_secs_f64();
        let path = ctx.out_dir.join(POSES_FILE);
        write_atomic(&path, &json_bytes(&path, &poses)?)?;
        let panel_sd_mm = ctx.survey.as_ref().and_then(flash_panel_sigma_mm);
        let reports = pose_stage_reports(&ctx.plan, &poses, ctx.truth, run_time_s, panel_sd_mm);
        ctx.poses = Some(poses);
        Ok((reports, vec![POSES_FILE.into()]))
    }
    fn load(&self, ctx: &mut Ctx<'_>, _recorded: &[StageReport]) -> Result<(), ProcessError> {
        ctx.poses = Some(read_poses(&ctx.out_dir.join(POSES_FILE))?);
        Ok(())
    }
    fn checks(
        &self,
        ctx: &Ctx<'_>,
        _reports: &[StageReport],
    ) -> Vec<(Stage, crate::checks::Check)> {
        ctx.poses.as_ref().map_or_else(Vec::new, |p| {
            crate::checks::pose_checks(
                p,
                crate::checks::PoseCheckInputs {
                    stated_camera: &ctx.stated_camera,
                },
            )
        })
    }
}

/// Reads the pose stage's `poses.json`.
pub fn read_poses(path: &Path) -> Result<SessionPoses, ProcessError> {
    let bytes = std::fs::read(path).map_err(|source| ProcessError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_slice(&bytes).map_err(|source| ProcessError::Json {
        path: path.to_path_buf(),
        source,
    })
}

/// The surveyed flash stand panel's placement sd, mm: the mean position sd of the surveyed
/// targets that serve the flash alone and that the light-position images see
/// (`SurveyedTarget::flash_only` and `light_position`; a relay's targets, placed far better,
/// would understate it); `None` when the survey placed none (the rig stated the panel).
///
/// The light-position cameras are posed against the panel held fixed, so the flash triangulated
/// from them moves with the panel. The panel's errors are nearly one common shift (they come
/// from the chain of survey shots that places it as a whole), so the mean of its targets' sds
/// stands for the shift's.
pub fn flash_panel_sigma_mm(survey: &skinbrdf_poses::Survey) -> Option<f64> {
    let sd: Vec<f64> = survey
        .targets
        .iter()
        .filter(|t| t.flash_only && t.light_position)
        .map(|t| t.position_sigma_mm)
        .collect();
    (!sd.is_empty()).then(|| sd.iter().sum::<f64>() / sd.len() as f64)
}

/// Says that the truth's head frame is not the session's, so that a frame difference is not
/// read as a measurement error.
fn head_frame_offset_note(o: &skinbrdf_poses::session::HeadFrameOffset) -> String {
    format!(
        "the truth's head frame is not this session's: every estimated head pose differs from \
         the truth by the same rigid transform ({:.1} mm, {:.2} degrees, over {} images), so \
         the head errors measure the two frames' difference, not the measurement; score with a \
         truth stated in the frame of the session's scan",
        o.distance_mm, o.angle_deg, o.images
    )
}

/// The pose stages' reports: typed figures from the poses and, with truth, their errors.
/// `panel_sd_mm` ([`flash_panel_sigma_mm`]) is added in quadrature to the flash's sd.
pub fn pose_stage_reports(
    plan: &Plan,
    poses: &SessionPoses,
    truth: Option<&Truth>,
    run_time_s: f64,
    panel_sd_mm: Option<f64>,
) -> Vec<StageReport> {
    let errs = truth.map(|t| skinbrdf_poses::session::compare_truth(poses, t));
    let corners = errs
        .as_ref()
        .map(|e| e.corner_summary())
        .unwrap_or_default();
    let corner = |layout: &str| corners.get(layout).and_then(|c| c.corner_error_median_px);
    let mk = |stage: Stage, time: f64, figures: StageMetrics| -> StageReport {
        if !plan.runs(stage) {
            return skipped(plan, stage);
        }
        StageReport::ran(stage, time).with_figures(figures)
    };
    let mut out = Vec::new();

    out.push(mk(
        Stage::CameraCalibration,
        0.0,
        StageMetrics::Calibration(CalibrationMetrics {
            reprojection_rms_px: poses.calibration.as_ref().map(|c| c.rms_px),
            focal_length_error_px: errs.as_ref().and_then(|e| e.focal_error_px),
        }),
    ));

    let cams: Vec<_> = poses
        .images
        .iter()
        .filter_map(|i| i.world_from_camera.as_ref())
        .collect();
    let failed_estimates: usize = poses.images.iter().map(|i| i.errors.len()).sum();
    let mut r = mk(
        Stage::CameraPoses,
        run_time_s,
        StageMetrics::CameraPoses(CameraPoseMetrics {
            images_with_camera_pose: cams.len(),
            reprojection_rms_median_px: median_finite(
                &cams.iter().map(|p| p.rms_px).collect::<Vec<_>>(),
            ),
            detect_plus_pose_per_image_median_ms: median_finite(
                &poses
                    .images
                    .iter()
                    .map(|i| i.detect_ms + i.pose_ms)
                    .collect::<Vec<_>>(),
            ),
            failed_estimates,
            camera_position_error_median_mm: errs
                .as_ref()
                .and_then(|e| median_finite(&e.camera_position_error_m))
                .map(|m| m * 1e3),
            camera_orientation_error_median_deg: errs
                .as_ref()
                .and_then(|e| median_finite(&e.camera_orientation_error_deg)),
            reference_corner_error_median_px: corner("reference"),
        }),
    );
    if failed_estimates > 0 {
        r.notes.push(format!(
            "{failed_estimates} individual pose estimates failed (see poses.json)"
        ));
    }
    out.push(r);

    let mut r = mk(
        Stage::HeadTracking,
        0.0,
        StageMetrics::HeadTracking(HeadTrackingMetrics {
            images_with_head_pose: poses
                .images
                .iter()
                .filter(|i| i.world_from_head.is_some())
                .count(),
            head_position_error_median_mm: errs
                .as_ref()
                .and_then(|e| median_finite(&e.head_position_error_m))
                .map(|m| m * 1e3),
            head_orientation_error_median_deg: errs
                .as_ref()
                .and_then(|e| median_finite(&e.head_orientation_error_deg)),
            headdress_corner_error_median_px: corner("headdress"),
        }),
    );
    if plan.runs(Stage::HeadTracking) {
        r.notes.push("timed together with camera poses".into());
        if let Some(o) = truth.and_then(|t| skinbrdf_poses::session::head_frame_offset(poses, t)) {
            r.notes.push(head_frame_offset_note(&o));
        }
    }
    out.push(r);

    let c = &poses.light_position_cov_m2;
    let mut r = mk(
        Stage::FlashTriangulation,
        0.0,
        StageMetrics::Flash(FlashMetrics {
            flash_position_error_mm: errs
                .as_ref()
                .and_then(|e| e.light_position_error_m)
                .map(|e| e * 1e3),
            flash_position_sigma_mm: (c.len() == 9).then(|| {
                let own_mm2 = (c[0] + c[4] + c[8]).max(0.0) * 1e6;
                (own_mm2 + panel_sd_mm.unwrap_or(0.0).powi(2)).sqrt()
            }),
        }),
    );
    if plan.runs(Stage::FlashTriangulation) {
        r.notes.push("timed together with camera poses".into());
    }
    if let Some(sd) = panel_sd_mm {
        r.notes.push(format!(
            "flash sd includes the surveyed panel's placement sd {sd:.3} mm"
        ));
    }
    out.push(r);

    let mut r = mk(
        Stage::RadiometricCalibration,
        0.0,
        StageMetrics::Standard(StandardMetrics {
            standard_position_error_mm: errs
                .as_ref()
                .and_then(|e| e.standard_position_error_m)
                .map(|e| e * 1e3),
        }),
    );
    if plan.runs(Stage::RadiometricCalibration) {
        r.notes
            .push("standard pose here; C itself is estimated during derendering".into());
    }
    out.push(r);
    out
}

// --- derendering ------------------------------------------------------------------------------

/// What [`estimate_and_write_poses`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PoseFiles {
    /// The pose stage's result.
    pub poses: PathBuf,
    /// The camera calibration as a `[camera]` table, when the pose stage calibrated.
    pub camera: Option<PathBuf>,
}

/// `skinbrdf poses`: estimates the session's poses and writes them to `poses_file`, and, when
/// the stage calibrated the camera, `camera.toml` beside it (the file `skinbrdf ingest --camera`
/// reads).
pub fn estimate_and_write_poses(
    session: &Session,
    cfg: &skinbrdf_poses::PoseConfig,
    poses_file: &Path,
) -> Result<(SessionPoses, PoseFiles), ProcessError> {
    let est = skinbrdf_poses::estimate_session(session, cfg)?;
    if let Some(dir) = poses_file.parent() {
        std::fs::create_dir_all(dir).map_err(|source| ProcessError::Read {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    skinbrdf_session::write_json_atomic(poses_file, &est)?;
    let camera = match &est.calibration {
        Some(cal) => {
            let path = poses_file.with_file_name("camera.toml");
            write_camera_file(&path, cal, session)?;
            Some(path)
        }
        None => None,
    };
    Ok((
        est,
        PoseFiles {
            poses: poses_file.to_path_buf(),
            camera,
        },
    ))
}

/// Writes a calibration as a `[camera]` table (the `session.toml` format: a raw session's
/// camera in superpixel units whatever the raw mode, see `skinbrdf_session::linear`).
fn write_camera_file(
    path: &Path,
    cal: &skinbrdf_poses::calib::Calibration,
    session: &Session,
) -> Result<(), ProcessError> {
    #[derive(serde::Serialize)]
    struct CameraFile {
        camera: skinbrdf_session::CameraSpec,
    }
    let body = toml::to_string(&CameraFile {
        camera: session.camera_as_stated(&skinbrdf_session::CameraSpec::Calibrated(cal.camera)),
    })
    .map_err(|source| ProcessError::CameraFile {
        path: path.to_path_buf(),
        source,
    })?;
    let text = format!(
        "# Camera calibration from the reference targets of {} ({} points, reprojection RMS {:.3} px, raw images loaded per {}).\n# The image size is the session's: the images' as loaded, 2x2 superpixels for raw files (as session.toml states a raw camera).\n{body}",
        session.dir.display(),
        cal.points,
        cal.rms_px,
        session.raw_mode(),
    );
    write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// Scan preparation, shadow rays and derendering (see the module docs).
#[derive(Debug)]
pub struct DerenderUnit;

/// The derender settings the plan implies: shadow rays forced, skipped (a region known to be
/// convex) or left to scan preparation's convexity test.
pub fn planned_derender_config(
    cfg: &DerenderConfig,
    plan: &Plan,
    opts: &PlanOptions,
) -> DerenderConfig {
    let mut d = *cfg;
    if opts.force_shadow_rays {
        d.shadows = skinbrdf_derender::ShadowMode::Always;
    } else if !plan.runs(Stage::ShadowRays) {
        d.shadows = skinbrdf_derender::ShadowMode::Never;
    }
    d
}

/// Derenders a session the way `process` does: with the pose stage's poses when given (the
/// session's own known quantities still take precedence inside), else the session's poses;
/// never the ground truth. `skinbrdf derender` calls this too, so that running the stages one
/// at a time gives what `process` gives.
pub fn derender_stage(
    session: &Session,
    poses: Option<&SessionPoses>,
    dcfg: &DerenderConfig,
    opts: &PlanOptions,
) -> Result<(SessionRun, Vec<skinbrdf_core::BrdfSample>), ProcessError> {
    let session_opts = SessionOptions {
        poses: if poses.is_some() {
            PoseChoice::Estimated
        } else {
            PoseChoice::Session
        },
        skip_target_mask: false,
        estimated: poses.cloned(),
    };
    let mut run = crate::pose_inputs::derender_session(session, &session_opts, dcfg)?;
    let mut samples = std::mem::take(&mut run.report.samples);
    if opts.incidence_plane_only {
        samples.retain(near_incidence_plane);
    }
    Ok((run, samples))
}

/// Where derendering takes its poses from, once chosen.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PoseSourceChoice {
    /// The poses `session.toml` gives.
    Session,
    /// The pose stage's output file.
    Estimated(PathBuf),
    /// `truth.json` (marked as such in the samples' header).
    Truth,
}

/// Chooses the pose source for `skinbrdf derender --poses`: `Auto` takes the session's poses when it gives every
/// one (camera poses, and head poses or a stationary sample), else the pose stage's
/// `poses_file`; `Estimated` needs `poses_file`. A missing pose-stage file is
/// [`ProcessError::NoPoses`], which says which command to run.
pub fn choose_pose_source(
    session: &Session,
    request: PoseChoice,
    poses_file: &Path,
) -> Result<PoseSourceChoice, ProcessError> {
    let facts = crate::process::scene_facts(session);
    let session_has_poses =
        facts.camera_poses_known && (facts.head_poses_known || facts.stationary_sample);
    match request {
        PoseChoice::Truth => Ok(PoseSourceChoice::Truth),
        PoseChoice::Session => Ok(PoseSourceChoice::Session),
        PoseChoice::Auto if session_has_poses => Ok(PoseSourceChoice::Session),
        PoseChoice::Auto | PoseChoice::Estimated => {
            if poses_file.is_file() {
                Ok(PoseSourceChoice::Estimated(poses_file.to_path_buf()))
            } else {
                Err(ProcessError::NoPoses {
                    dir: session.dir.clone(),
                    poses: poses_file.to_path_buf(),
                })
            }
        }
    }
}

/// What [`derender_chosen`] wrote.
#[derive(Debug)]
pub struct DerenderOutput {
    /// The run, its report holding the samples written.
    pub run: SessionRun,
    /// `samples.skbs`.
    pub samples_file: PathBuf,
    /// `derender.json`.
    pub report_file: PathBuf,
}

/// Options of [`derender_chosen`] beyond the derender settings.
#[derive(Debug, Clone, Default)]
pub struct DerenderOutputOptions {
    /// Leave the projected printed targets unmasked (only with [`PoseSourceChoice::Truth`]).
    pub skip_target_mask: bool,
    /// Also write `samples.csv`.
    pub csv: bool,
    /// Write the coverage figures into `OUT/figures` at this incident angle and tolerance
    /// (degrees).
    pub figures: Option<(f64, f64)>,
}

/// Derenders with the chosen poses (as [`derender_stage`] does for the session's and the pose
/// stage's) and writes `samples.skbs`, `derender.json` and what `opts` asks for into `out_dir`.
/// Samples from the truth's poses say so in their header.
pub fn derender_chosen(
    session: &Session,
    source: &PoseSourceChoice,
    dcfg: &DerenderConfig,
    plan_opts: &PlanOptions,
    out_dir: &Path,
    opts: &DerenderOutputOptions,
) -> Result<DerenderOutput, ProcessError> {
    let (mut run, samples) = match source {
        PoseSourceChoice::Truth => {
            let session_opts = SessionOptions {
                poses: PoseChoice::Truth,
                skip_target_mask: opts.skip_target_mask,
                estimated: None,
            };
            let mut run = crate::pose_inputs::derender_session(session, &session_opts, dcfg)?;
            let samples = std::mem::take(&mut run.report.samples);
            (run, samples)
        }
        PoseSourceChoice::Session => derender_stage(session, None, dcfg, plan_opts)?,
        PoseSourceChoice::Estimated(file) => {
            let poses = read_poses(file)?;
            derender_stage(session, Some(&poses), dcfg, plan_opts)?
        }
    };
    let mut header = samples_header(session, &run);
    if *source == PoseSourceChoice::Truth {
        header.description = format!("{} (poses from truth.json)", header.description);
    }
    let samples_file = out_dir.join(SAMPLES_FILE);
    skinbrdf_samples::write_samples(&samples_file, &header, &samples)?;
    if opts.csv {
        skinbrdf_samples::write_csv(out_dir.join("samples.csv"), &samples)?;
    }
    run.report.samples = samples;
    if let Some((theta_i_deg, tol_deg)) = opts.figures {
        write_derender_figures(
            &out_dir.join("figures"),
            session,
            &run,
            theta_i_deg,
            tol_deg,
        )?;
    }
    let report_file = out_dir.join("derender.json");
    write_atomic(&report_file, &json_bytes(&report_file, &run)?)?;
    Ok(DerenderOutput {
        run,
        samples_file,
        report_file,
    })
}

/// The derender coverage figures: pixels used per image (PNG) and the exitant hemisphere at
/// `theta_i_deg` +- `tol_deg` (PNG and SVG).
fn write_derender_figures(
    dir: &Path,
    session: &Session,
    run: &SessionRun,
    theta_i_deg: f64,
    tol_deg: f64,
) -> Result<(), ProcessError> {
    use skinbrdf_derender::figures;
    std::fs::create_dir_all(dir).map_err(|source| ProcessError::Read {
        path: dir.to_path_buf(),
        source,
    })?;
    let samples = &run.report.samples;
    for im in &run.report.images {
        let img = session.load_image(im.image_index)?;
        let view = skinbrdf_derender::ImageView {
            width: img.width,
            height: img.height,
            rgb: &img.rgb,
            saturated: None,
            cfa: img.cfa,
        };
        let index = u16::try_from(im.image_index).map_err(|_| {
            skinbrdf_derender::DerenderError::ImageIndex {
                index: im.image_index,
            }
        })?;
        let rgb = figures::pixels_used_rgb8(&view, samples, index);
        let p = dir.join(format!("pixels_used_{:03}.png", im.image_index));
        skinbrdf_session::write::write_png_rgb8(&p, img.width, img.height, &rgb)?;
    }
    let svg = figures::hemisphere_svg(samples, theta_i_deg, tol_deg);
    write_atomic(
        &dir.join(format!("hemisphere_theta_i_{theta_i_deg}.svg")),
        svg.as_bytes(),
    )?;
    let size = 600;
    let png = figures::hemisphere_rgb8(samples, theta_i_deg, tol_deg, size);
    skinbrdf_session::write::write_png_rgb8(
        &dir.join(format!("hemisphere_theta_i_{theta_i_deg}.png")),
        size,
        size,
        &png,
    )?;
    Ok(())
}

/// The header `process` writes into `samples.skbs`.
pub fn samples_header(session: &Session, run: &SessionRun) -> SampleHeader {
    let mut header = SampleHeader::new("derender", &session.file.description);
    header.origin = Some(session.dir.display().to_string());
    header.calibration_c = Some(run.report.c);
    // What the samples' surface points refer to: the session's geometry as loaded.
    header.extra = serde_json::json!({
        "surface_points": {
            "triangles": run.triangles,
            "texture_coordinates": run.texture_coordinates,
        }
    });
    header
}

impl StageUnit for DerenderUnit {
    fn unit(&self) -> Unit {
        Unit::Derender
    }
    fn first_stage(&self) -> Stage {
        Stage::Derender
    }
    fn fingerprint(&self, ctx: &Ctx<'_>) -> Result<Fingerprint, ProcessError> {
        let mut fp = session_fingerprint(ctx.session)?;
        if ctx.poses.is_some() {
            fp = fp.file(&ctx.out_dir.join(POSES_FILE))?;
        }
        Ok(fp
            .value("derender", &ctx.cfg.derender)
            .value("plan", &ctx.cfg.plan)
            .value("skip_bad_images", &ctx.cfg.skip_bad_images)
            .finish())
    }
    fn run(&self, ctx: &mut Ctx<'_>) -> Result<(Vec<StageReport>, Vec<String>), ProcessError> {
        let dcfg = planned_derender_config(&ctx.cfg.derender, &ctx.plan, &ctx.cfg.plan);
        let (run, samples) = derender_stage(ctx.session, ctx.poses.as_ref(), &dcfg, &ctx.cfg.plan)?;
        if ctx.facts.region_convex.is_none() {
            ctx.facts.region_convex = Some(!run.report.region_can_self_shadow);
        }
        let path = ctx.out_dir.join(SAMPLES_FILE);
        skinbrdf_samples::write_samples(&path, &samples_header(ctx.session, &run), &samples)?;
        let reports = derender_reports(&ctx.plan, &run, samples.len() as u64).to_vec();
        ctx.samples = Some(samples);
        Ok((reports, vec![SAMPLES_FILE.into()]))
    }
    fn load(&self, ctx: &mut Ctx<'_>, recorded: &[StageReport]) -> Result<(), ProcessError> {
        let (_, samples) = skinbrdf_samples::read_samples(ctx.out_dir.join(SAMPLES_FILE))?;
        if ctx.facts.region_convex.is_none() {
            ctx.facts.region_convex = recorded.iter().find_map(|r| match &r.figures {
                StageMetrics::Scan(s) => s.region_can_self_shadow.map(|c| !c),
                _ => None,
            });
        }
        ctx.samples = Some(samples);
        Ok(())
    }
    fn checks(
        &self,
        _ctx: &Ctx<'_>,
        reports: &[StageReport],
    ) -> Vec<(Stage, crate::checks::Check)> {
        crate::checks::derender_checks(reports)
    }
}

/// Within 5 degrees of the incidence plane (`phi_d` near 0 or pi).
fn near_incidence_plane(s: &skinbrdf_core::BrdfSample) -> bool {
    f64::from(s.phi_d_rad).sin().abs() * f64::from(s.theta_e_rad).sin() <= 5f64.to_radians().sin()
}

/// The reports of scan preparation, shadow rays and derendering.
pub fn derender_reports(plan: &Plan, run: &SessionRun, samples_kept: u64) -> [StageReport; 3] {
    let d = &run.report;
    let t = &d.times;
    let scan_figures = StageMetrics::Scan(ScanMetrics {
        triangles: run.triangles,
        normal_fit_radius_mm: d.normal_radius_m * 1e3,
        triangles_dropped: run
            .mesh_report
            .as_ref()
            .map_or(0, |m| m.dropped_triangles()),
        region_can_self_shadow: Some(d.region_can_self_shadow),
    });
    let mut scan = if plan.runs(Stage::ScanPreparation) {
        StageReport::ran(
            Stage::ScanPreparation,
            t.mesh_load_s + t.bvh_s + t.normals_s + t.convexity_s,
        )
        .with_figures(scan_figures)
    } else {
        let mut r = skipped(plan, Stage::ScanPreparation).with_figures(scan_figures);
        r.notes.push(format!(
            "the ideal shape was tessellated instead ({} triangles, {:.3} s)",
            run.triangles,
            t.mesh_load_s + t.bvh_s + t.normals_s
        ));
        r
    };
    if let Some(m) = &run.mesh_report {
        if !m.is_clean() {
            scan.notes.push(format!("scan repaired: {}", m.summary()));
        }
    }
    let shadow = if !plan.runs(Stage::ShadowRays) {
        let mut r = skipped(plan, Stage::ShadowRays);
        if d.region_can_self_shadow {
            r.notes.push(
                "the tessellated shape failed the convexity test within its tolerance; the plan's geometric fact wins".into(),
            );
        }
        r
    } else if d.shadow_rays {
        let mut r = StageReport::ran(Stage::ShadowRays, 0.0).with_figures(StageMetrics::Shadow(
            ShadowMetrics {
                shadow_rays_cast: d.shadow_rays_cast,
            },
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
        let mut r = StageReport::skipped(
            Stage::ShadowRays,
            "the region is convex: it cannot shadow itself",
        );
        r.notes
            .push("found by scan preparation's convexity test".into());
        r
    };
    let k = &d.counts;
    let secs = t.derender_s.max(1e-9);
    let mut der = StageReport::ran(
        Stage::Derender,
        t.image_load_s + t.calibration_s + t.derender_s,
    )
    .with_figures(StageMetrics::Derender(DerenderMetrics {
        samples_kept,
        dropped: DropCounts {
            off_mask: k.off_mask,
            on_target: k.on_target,
            no_surface: k.no_surface,
            back_facing: k.back_facing,
            off_region: k.off_region,
            grazing: k.grazing,
            shadowed: k.shadowed,
            saturated: k.saturated,
            below_noise_floor: k.below_noise_floor,
            non_finite: k.non_finite,
            no_ray: k.no_ray,
        },
        c_green: d.c[1],
        c_relative_spread_green_pct: d.calibration.as_ref().map(|c| c.rel_spread[1] * 100.0),
        c_standard_pixels: d.calibration.as_ref().map(|c| c.pixels as u64),
        primary_rays_per_s_m: d.primary_rays as f64 / secs / 1e6,
        sample_median_rel_error_pct: d.truth_error.as_ref().map(|e| e.median_rel_error * 100.0),
        sample_p90_rel_error_pct: d.truth_error.as_ref().map(|e| e.p90_rel_error * 100.0),
        sample_median_rel_error_green_pct: d
            .truth_error
            .as_ref()
            .and_then(|e| e.median_rel_error_rgb[1])
            .map(|e| e * 100.0),
    }));
    der.notes.push(format!(
        "camera from {}, light from {}, C from {}",
        run.camera_source, run.light_source, run.c_source
    ));
    [scan, shadow, der]
}

// --- smoothing and fitting -------------------------------------------------------------------

/// Smoothing and the model fit (see the module docs).
#[derive(Debug)]
pub struct FitUnit;

impl StageUnit for FitUnit {
    fn unit(&self) -> Unit {
        Unit::Fit
    }
    fn first_stage(&self) -> Stage {
        Stage::Fit
    }
    fn fingerprint(&self, ctx: &Ctx<'_>) -> Result<Fingerprint, ProcessError> {
        let mut fp = FingerprintBuilder::new()
            .file(&ctx.out_dir.join(SAMPLES_FILE))?
            .value("model", &format!("{:?}", ctx.cfg.fit.model))
            .value("fit", &ctx.cfg.fit.fit)
            .value("figures", &ctx.cfg.fit.figures)
            .value("merl", &ctx.cfg.fit.merl)
            .value("plan", &ctx.cfg.plan);
        let truth = ctx.session.truth_path();
        if truth.is_file() {
            fp = fp.file(&truth)?;
        }
        Ok(fp.finish())
    }
    fn run(&self, ctx: &mut Ctx<'_>) -> Result<(Vec<StageReport>, Vec<String>), ProcessError> {
        let samples = ctx.samples.take().unwrap_or_default();
        if samples.is_empty() {
            return Err(ProcessError::NoSamples);
        }
        let dir = &ctx.session.dir;
        let input = Input {
            path: dir.clone(),
            label: dir
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            samples,
            cornell: None,
            truth: ctx.truth.map(|t| t.brdf.clone()),
        };
        let fit_dir = ctx.out_dir.join("fit");
        let fr = fit_and_report(&input, &fit_dir, &ctx.cfg.fit)?;
        ctx.samples = Some(input.samples);
        let mut outputs: Vec<String> = fr
            .files
            .iter()
            .filter_map(|f| {
                Path::new(f)
                    .strip_prefix(&ctx.out_dir)
                    .ok()
                    .map(|p| p.to_string_lossy().into_owned())
            })
            .collect();
        // The parameters and the fit's own report are outputs too (the head rendering reads
        // the parameters).
        for f in [PARAMS_FILE, FIT_REPORT_FILE] {
            if ctx.out_dir.join(f).is_file() && !outputs.iter().any(|o| o == f) {
                outputs.push(f.to_string());
            }
        }
        let reports = fit_reports(&ctx.plan, &fr).to_vec();
        ctx.fit = Some(fr);
        Ok((reports, outputs))
    }
    fn load(&self, _ctx: &mut Ctx<'_>, _recorded: &[StageReport]) -> Result<(), ProcessError> {
        Ok(())
    }
    fn checks(&self, ctx: &Ctx<'_>, reports: &[StageReport]) -> Vec<(Stage, crate::checks::Check)> {
        let files: Vec<&str> = ctx
            .session
            .file
            .images
            .iter()
            .map(|i| i.file.as_str())
            .collect();
        crate::checks::fit_checks(reports, &files)
    }
}

/// The reports of smoothing (plane, hemisphere) and the fit.
pub fn fit_reports(plan: &Plan, fr: &FitReport) -> [StageReport; 3] {
    let plane = StageReport::ran(Stage::SmoothIncidencePlane, fr.smooth.run_time_s).with_figures(
        StageMetrics::Smooth(SmoothMetrics {
            loess_span: fr.smooth.span,
            loess_residual_sigma_pct: fr.smooth.residual_sigma_log * 100.0,
            worst_image_offset_pct: fr.smooth.worst_image_offset.map(|o| o.offset_log * 100.0),
            worst_image_index: fr.smooth.worst_image_offset.map(|o| o.image_index),
        }),
    );
    let hemi = if plan.runs(Stage::SmoothHemisphere) {
        let mut r = StageReport::ran(Stage::SmoothHemisphere, 0.0);
        r.notes.push("the same local quadratic fit spans (theta_i, theta_e, phi_d); timed with the incidence plane".into());
        r
    } else {
        skipped(plan, Stage::SmoothHemisphere)
    };
    let mut fit = StageReport::ran(Stage::Fit, fr.timings.fit_s).with_figures(StageMetrics::Fit(
        FitMetrics {
            samples_fitted: fr.n_samples as u64,
            log_rmse_vs_samples_green: fr.fit.channels.get(1).map(|c| c.error.log_rmse),
            model_log_rmse_vs_truth: fr.truth.as_ref().map(|t| {
                let c = &t.channels;
                (c.iter().map(|m| m.log_rmse * m.log_rmse).sum::<f64>() / c.len().max(1) as f64)
                    .sqrt()
            }),
            model_median_rel_error_vs_truth_pct: fr.truth.as_ref().and_then(|t| {
                median_finite(
                    &t.channels
                        .iter()
                        .map(|m| m.median_rel_err * 100.0)
                        .collect::<Vec<_>>(),
                )
            }),
        },
    ));
    for w in &fr.fit.warnings {
        fit.notes.push(w.clone());
    }
    [plane, hemi, fit]
}

// --- the head rendering ---------------------------------------------------------------------

/// The head rendering of the report (see the module docs).
#[derive(Debug)]
pub struct RenderUnit;

impl StageUnit for RenderUnit {
    fn unit(&self) -> Unit {
        Unit::Render
    }
    fn first_stage(&self) -> Stage {
        Stage::Report
    }
    fn planned(&self, ctx: &Ctx<'_>) -> bool {
        matches!(ctx.session.file.geometry, GeometrySpec::Scan { .. })
    }
    fn skipped(&self, _ctx: &Ctx<'_>) -> Vec<StageReport> {
        let mut r = StageReport::ran(Stage::Report, 0.0);
        r.notes
            .push("no head rendering: the sample is an ideal shape, not a scan".into());
        vec![r]
    }
    fn fingerprint(&self, ctx: &Ctx<'_>) -> Result<Fingerprint, ProcessError> {
        let mut fp = FingerprintBuilder::new().file(&ctx.out_dir.join(PARAMS_FILE))?;
        if let GeometrySpec::Scan {
            file,
            units,
            accept_repair_loss,
        } = &ctx.session.file.geometry
        {
            fp = fp
                .file(&ctx.session.path(file))?
                .value("units", units)
                .value("accept_repair_loss", accept_repair_loss);
        }
        Ok(fp.finish())
    }
    fn run(&self, ctx: &mut Ctx<'_>) -> Result<(Vec<StageReport>, Vec<String>), ProcessError> {
        let t = Instant::now();
        let result = render_head(ctx.session, &ctx.out_dir);
        let render_time_s = t.elapsed().as_secs_f64();
        let mut r = StageReport::ran(Stage::Report, render_time_s);
        let outputs = match result {
            Ok((stats, files)) => {
                r = r.with_figures(StageMetrics::Report(ReportMetrics {
                    render_rays: Some(stats.rays),
                    render_time_s: Some(render_time_s),
                }));
                r.notes.push(format!(
                    "{RENDER_FIGURE}: the scan rendered with a Lambertian BRDF and with the fitted model"
                ));
                files
                    .iter()
                    .filter_map(|f| f.strip_prefix(&ctx.out_dir).ok())
                    .map(|p| p.to_string_lossy().into_owned())
                    .collect()
            }
            Err(note) => {
                r.notes.push(note);
                Vec::new()
            }
        };
        Ok((vec![r], outputs))
    }
    fn load(&self, _ctx: &mut Ctx<'_>, _recorded: &[StageReport]) -> Result<(), ProcessError> {
        Ok(())
    }
}

/// Renders the scan with a Lambertian BRDF and with the fitted model side by side (the method's
/// Figures 7 and 10) into `out/render/`. `Err`: why it could not be drawn (reported as a note,
/// never fatal).
fn render_head(
    session: &Session,
    out_dir: &Path,
) -> Result<(skinbrdf_render::RenderStats, Vec<PathBuf>), String> {
    let GeometrySpec::Scan {
        file,
        units,
        accept_repair_loss,
    } = &session.file.geometry
    else {
        return Err("no scan to render".into());
    };
    let model = skinbrdf_render::load_model(&out_dir.join(PARAMS_FILE))
        .map_err(|e| format!("head rendering skipped: {}", skinbrdf_core::error_text(&e)))?;
    let mesh = skinbrdf_mesh::load_mesh(
        &session.path(file),
        &skinbrdf_mesh::LoadOptions {
            unit: skinbrdf_mesh::LengthUnit::Custom(units.to_m()),
            policy: skinbrdf_derender::from_session::scan_repair_policy(*accept_repair_loss),
        },
    )
    .map_err(|e| format!("head rendering skipped: {}", skinbrdf_core::error_text(&e)))?;
    let cfg = skinbrdf_render::RenderConfig::default();
    let img = skinbrdf_render::render_comparison(&mesh.mesh, &model, &cfg)
        .map_err(|e| format!("head rendering failed: {}", skinbrdf_core::error_text(&e)))?;
    let dir = out_dir.join("render");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let files = img
        .write(&dir.join("head_comparison"), &cfg.labels)
        .map_err(|e| {
            format!(
                "head rendering not written: {}",
                skinbrdf_core::error_text(&e)
            )
        })?;
    Ok((img.stats, files))
}

/// Marks recorded reports as reused (their figures and run times are the recorded run's).
pub fn as_reused(recorded: &[StageReport]) -> Vec<StageReport> {
    recorded
        .iter()
        .cloned()
        .map(|mut r| {
            if r.status == StageStatus::Ran {
                r.status = StageStatus::Reused;
            }
            r
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use skinbrdf_session::KnownQuantities;

    use super::*;
    use crate::pose_inputs::tests::{camera_pose, session};

    /// A session that states every camera pose of a stationary sample: it needs no pose stage.
    fn posed_session() -> Session {
        let mut s = session(KnownQuantities {
            stationary_sample: true,
            ..Default::default()
        });
        for (i, im) in s.file.images.iter_mut().enumerate() {
            im.world_from_camera = Some(camera_pose(i));
        }
        s
    }

    #[test]
    fn auto_takes_the_pose_stages_file_when_the_session_gives_no_poses() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join(POSES_FILE);
        let s = session(KnownQuantities::default());
        match choose_pose_source(&s, PoseChoice::Auto, &file) {
            Err(ProcessError::NoPoses { dir, poses }) => {
                assert_eq!(dir, s.dir);
                assert_eq!(poses, file);
            }
            other => panic!("expected NoPoses, got {other:?}"),
        }
        std::fs::write(&file, "{}").expect("write");
        for request in [PoseChoice::Auto, PoseChoice::Estimated] {
            assert_eq!(
                choose_pose_source(&s, request, &file).expect("a source"),
                PoseSourceChoice::Estimated(file.clone())
            );
        }
    }

    #[test]
    fn auto_prefers_the_sessions_poses_and_truth_only_when_asked() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join(POSES_FILE);
        std::fs::write(&file, "{}").expect("write");
        let s = posed_session();
        let choose = |r| choose_pose_source(&s, r, &file).expect("a source");
        assert_eq!(choose(PoseChoice::Auto), PoseSourceChoice::Session);
        assert_eq!(choose(PoseChoice::Session), PoseSourceChoice::Session);
        assert_eq!(
            choose(PoseChoice::Estimated),
            PoseSourceChoice::Estimated(file.clone())
        );
        assert_eq!(choose(PoseChoice::Truth), PoseSourceChoice::Truth);
    }

    #[test]
    fn an_unreadable_pose_file_is_an_error_naming_it_and_writes_nothing() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join(POSES_FILE);
        std::fs::write(&file, "not json").expect("write");
        let s = session(KnownQuantities::default());
        let out = dir.path().join("out");
        let err = derender_chosen(
            &s,
            &PoseSourceChoice::Estimated(file.clone()),
            &DerenderConfig::DEFAULT,
            &PlanOptions::default(),
            &out,
            &DerenderOutputOptions::default(),
        )
        .expect_err("garbage poses");
        assert!(
            skinbrdf_core::error_text(&err).contains(POSES_FILE),
            "{err:?}"
        );
        assert!(!out.join(SAMPLES_FILE).exists());
    }
}
