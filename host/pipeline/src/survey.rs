//! `skinbrdf survey SESSION`: the placement survey on its own.
//!
//! The same unit `process` plans first ([`crate::stages::SurveyUnit`]), under the same ledger:
//! a survey run here is reused by the next `process` (and by `skinbrdf poses`) while the
//! session's files are unchanged, and a survey `process` ran is reused here. When every
//! placement is given the plan skips the survey and the report says why.
//!
//! With a rig file, the surveyed placements are also written back into a copy of it
//! ([`skinbrdf_poses::Survey::placed_rig`]): a rig surveyed once is loaded fixed next time
//! (`skinbrdf ingest --rig` with the written file leaves nothing to survey).

use std::path::{Path, PathBuf};

use skinbrdf_session::{Rig, Session};

use crate::plan::{Plan, Stage};
use crate::process::{
    open, scene_facts, survey_step, Event, ProcessConfig, ProcessError, Surveyed,
};
use crate::report::{StageReport, StageStatus};

/// Writing back the surveyed rig: the rig file the session came from and where to write.
#[derive(Debug, Clone)]
pub struct RigWriteBack {
    /// The rig file without (some) placements.
    pub rig: PathBuf,
    /// Where the rig with the surveyed placements goes.
    pub out: PathBuf,
}

/// What `skinbrdf survey` produced.
#[derive(Debug)]
pub struct SurveyOutput {
    /// The survey stage's report (ran, reused or skipped with its reason).
    pub report: StageReport,
    /// The survey and the surveyed session (`None` when the plan skips the survey).
    pub surveyed: Option<Surveyed>,
    /// The output directory (`survey.json`, `registration.json`).
    pub out_dir: PathBuf,
    /// The rig file written with the surveyed placements.
    pub rig_written: Option<PathBuf>,
}

/// Errors of the survey command beyond those of the pipeline.
#[derive(Debug, thiserror::Error)]
pub enum SurveyRunError {
    /// The pipeline's error (session, survey, registration, output).
    #[error(transparent)]
    Process(#[from] ProcessError),
    /// The rig file to write back did not load.
    #[error("rig file {}", path.display())]
    Rig {
        /// The rig file.
        path: PathBuf,
        /// Every problem.
        #[source]
        source: skinbrdf_session::SessionErrors,
    },
    /// Writing the surveyed rig failed.
    #[error("writing the surveyed rig {}", path.display())]
    WriteRig {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: skinbrdf_session::FileError,
    },
    /// A rig was asked for but the plan skipped the survey.
    #[error("no surveyed rig to write: the plan skips the placement survey ({reason})")]
    NothingSurveyed {
        /// Why the plan skips it.
        reason: String,
    },
}

/// Runs (or reuses) the placement survey of the session in `dir`, writes `survey.json` (and
/// `registration.json` when the headdress was registered to a textured scan) and, with
/// `rig`, the surveyed rig.
pub fn survey(
    dir: &Path,
    cfg: &ProcessConfig,
    rig: Option<&RigWriteBack>,
    on_event: &mut dyn FnMut(Event<'_>),
) -> Result<SurveyOutput, SurveyRunError> {
    let mut opened = open(dir, cfg)?;
    let facts = scene_facts(&opened.session);
    let plan = Plan::derive(&facts, &cfg.plan);
    on_event(Event::Plan(&plan));
    let (mut reports, surveyed, _) = survey_step(
        &opened.session,
        opened.truth.as_ref(),
        cfg,
        &opened.out_dir,
        facts,
        &plan,
        &mut opened.ledger,
        on_event,
    )?;
    let report = match reports.pop() {
        Some(r) => r,
        None => StageReport::skipped(Stage::PlacementSurvey, "not planned"),
    };
    on_event(Event::Finished(&report));
    let rig_written = match rig {
        None => None,
        Some(w) => {
            let Some(s) = &surveyed else {
                let reason = match &report.status {
                    StageStatus::Skipped { reason } => reason.clone(),
                    _ => "it placed nothing".to_string(),
                };
                return Err(SurveyRunError::NothingSurveyed { reason });
            };
            let loaded = Rig::load(&w.rig).map_err(|source| SurveyRunError::Rig {
                path: w.rig.clone(),
                source,
            })?;
            let dir_of = |p: &Path| {
                p.parent()
                    .filter(|d| !d.as_os_str().is_empty())
                    .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
            };
            let placed = s
                .survey
                .placed_rig(&loaded.file)
                .moved(&dir_of(&w.rig), &dir_of(&w.out));
            Rig::write_file(&w.out, &placed).map_err(|source| SurveyRunError::WriteRig {
                path: w.out.clone(),
                source,
            })?;
            Some(w.out.clone())
        }
    };
    Ok(SurveyOutput {
        report,
        surveyed,
        out_dir: opened.out_dir,
        rig_written,
    })
}

/// The session in `dir` ready for the pose stage run by hand (`skinbrdf poses`): as it is when
/// every placement is given, else with the placements of the survey, which runs now unless the
/// ledger holds a current one.
pub fn surveyed_session(
    dir: &Path,
    cfg: &ProcessConfig,
    on_event: &mut dyn FnMut(Event<'_>),
) -> Result<(Session, Option<StageReport>), SurveyRunError> {
    let mut session = Session::load(dir).map_err(|source| ProcessError::Session {
        dir: dir.to_path_buf(),
        source,
    })?;
    session.set_raw_mode(cfg.raw_mode);
    if session.file.targets.unplaced.is_empty() {
        return Ok((session, None));
    }
    let out = survey(dir, cfg, None, on_event)?;
    match out.surveyed {
        Some(s) => Ok((s.session, Some(out.report))),
        None => Ok((session, None)),
    }
}
