//! What a single derendering (`skinbrdf derender`) asks for, resolved the way `process` resolves
//! it: the shadow-ray setting the plan implies, and where the poses come from.
//!
//! The pose source: an explicit pose-stage file means [`PoseChoice::Estimated`]; otherwise the
//! requested [`PoseChoice`], with the pose stage's default output `SESSION/out/poses.json`
//! ([`crate::stages::POSES_FILE`]). Leaving the printed targets unmasked is a check of the mask
//! itself, so it is refused with any poses but the truth's.

use std::path::PathBuf;

use skinbrdf_derender::DerenderConfig;
use skinbrdf_session::Session;

use crate::pose_inputs::PoseChoice;
use crate::process::{scene_facts, ProcessError};
use crate::stages::{choose_pose_source, planned_derender_config, PoseSourceChoice, POSES_FILE};
use crate::{Plan, PlanOptions};

/// The pose request of one derendering.
#[derive(Debug, Clone, Default)]
pub struct PoseRequest {
    /// Which poses (`Estimated` when `poses_file` is given).
    pub choice: PoseChoice,
    /// The pose stage's output; `None`: `SESSION/out/poses.json`.
    pub poses_file: Option<PathBuf>,
    /// Leave the projected printed targets unmasked (only with [`PoseChoice::Truth`]).
    pub skip_target_mask: bool,
}

/// Why a pose request cannot be served.
#[derive(Debug, thiserror::Error)]
pub enum PoseRequestError {
    /// Unmasked targets asked for with poses other than the truth's.
    #[error("--no-target-mask is only for --poses truth (a check of the mask itself)")]
    UnmaskedWithoutTruth,
    /// The chosen source is not there (no pose-stage output).
    #[error(transparent)]
    Process(#[from] ProcessError),
}

/// The derender settings as `process` would plan them for `session`: shadow rays forced,
/// skipped for a region known to be convex, or left to the convexity test.
pub fn planned_config(
    session: &Session,
    cfg: &DerenderConfig,
    opts: &PlanOptions,
) -> DerenderConfig {
    let plan = Plan::derive(&scene_facts(session), opts);
    planned_derender_config(cfg, &plan, opts)
}

/// The pose source `request` names for `session` (see the module docs).
pub fn derender_pose_source(
    session: &Session,
    request: &PoseRequest,
) -> Result<PoseSourceChoice, PoseRequestError> {
    let choice = if request.poses_file.is_some() {
        PoseChoice::Estimated
    } else {
        request.choice
    };
    if request.skip_target_mask && choice != PoseChoice::Truth {
        return Err(PoseRequestError::UnmaskedWithoutTruth);
    }
    let poses_file = request
        .poses_file
        .clone()
        .unwrap_or_else(|| session.dir.join("out").join(POSES_FILE));
    Ok(choose_pose_source(session, choice, &poses_file)?)
}

#[cfg(test)]
mod tests {
    use skinbrdf_session::KnownQuantities;

    use super::*;
    use crate::pose_inputs::tests::session;

    /// A session without poses of its own, in `dir`.
    fn unposed_session_in(dir: &std::path::Path) -> Session {
        let mut s = session(KnownQuantities::default());
        s.dir = dir.to_path_buf();
        s
    }

    #[test]
    fn the_default_poses_file_is_the_pose_stages_output_in_the_session() {
        let dir = tempfile::tempdir().expect("tempdir");
        let s = unposed_session_in(dir.path());
        let request = PoseRequest::default();
        match derender_pose_source(&s, &request) {
            Err(PoseRequestError::Process(ProcessError::NoPoses { poses, .. })) => {
                assert_eq!(poses, dir.path().join("out").join(POSES_FILE));
            }
            other => panic!("expected NoPoses, got {other:?}"),
        }
        let file = dir.path().join("out").join(POSES_FILE);
        std::fs::create_dir_all(dir.path().join("out")).expect("mkdir");
        std::fs::write(&file, "{}").expect("write");
        assert_eq!(
            derender_pose_source(&s, &request).expect("a source"),
            PoseSourceChoice::Estimated(file)
        );
    }

    #[test]
    fn a_given_poses_file_means_the_estimated_poses() {
        let dir = tempfile::tempdir().expect("tempdir");
        let s = unposed_session_in(dir.path());
        let file = dir.path().join("elsewhere.json");
        std::fs::write(&file, "{}").expect("write");
        for choice in [PoseChoice::Session, PoseChoice::Truth] {
            let request = PoseRequest {
                choice,
                poses_file: Some(file.clone()),
                skip_target_mask: false,
            };
            assert_eq!(
                derender_pose_source(&s, &request).expect("a source"),
                PoseSourceChoice::Estimated(file.clone())
            );
        }
    }

    #[test]
    fn unmasked_targets_only_with_the_truths_poses() {
        let dir = tempfile::tempdir().expect("tempdir");
        let s = unposed_session_in(dir.path());
        let request = |choice| PoseRequest {
            choice,
            poses_file: None,
            skip_target_mask: true,
        };
        assert_eq!(
            derender_pose_source(&s, &request(PoseChoice::Truth)).expect("a source"),
            PoseSourceChoice::Truth
        );
        for choice in [PoseChoice::Auto, PoseChoice::Session, PoseChoice::Estimated] {
            assert!(matches!(
                derender_pose_source(&s, &request(choice)),
                Err(PoseRequestError::UnmaskedWithoutTruth)
            ));
        }
    }
}
