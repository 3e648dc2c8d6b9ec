//! Self-checks: each unit of the pipeline asks of its own result, without the ground truth,
//! whether it is plausible, so a wrong answer is never a silent one.
//!
//! A check compares one figure the run can compute from its own data with a bound; every
//! bound is a named constant below with its reason. A check that fails marks its stage FAILED
//! in the report; `process` then stops the stages that depend on it and exits non-zero with the
//! check, its figure and the likely cause (`--accept-failed-checks` goes on, the report still
//! says FAILED). A check that cannot apply to a scene (no focal length in the files, no
//! light-position images) is listed as not checked, with why.
//!
//! | stage | check | figure | fails when |
//! |---|---|---|---|
//! | camera calibration | `focal_vs_files` | calibrated fx against the focal length the files state | more than [`FOCAL_VS_FILES_MAX_REL`] apart |
//! | camera poses | `reprojection_chi2` | median over images of `(rms / sigma)²`, the per-image reprojection RMS against the median stated corner sigma | above [`REPROJECTION_CHI2_MAX`] |
//! | placement survey | `survey_chi2` | the survey adjustment's reduced chi-square (variance factor) | above [`REPROJECTION_CHI2_MAX`] |
//! | camera poses | `bundle_chi2` | the joint pose adjustment's reduced chi-square over all images | above [`REPROJECTION_CHI2_MAX`] |
//! | camera poses | `camera_distance_spread` | relative sd of the measurement cameras' distances to the point their optical axes meet | above [`CAMERA_DISTANCE_SPREAD_MAX`] |
//! | flash triangulation | `flash_sigma` | the flash position's stated sd | above [`FLASH_SIGMA_MAX_MM`] |
//! | radiometric calibration (in derender) | `c_spread` | C's relative spread over the standard | above [`C_SPREAD_MAX_PCT`] |
//! | fit | `fit_vs_smoother` | the model's log residual against the samples over the smoother's | above [`FIT_VS_SMOOTHER_MAX`] |

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};
use skinbrdf_core::stats::median;
use skinbrdf_poses::SessionPoses;
use skinbrdf_session::{CameraSpec, ImageRole};

use crate::metrics::StageMetrics;
use crate::plan::Stage;
use crate::report::StageReport;

/// Calibrated focal length against the one the files state, relative. The files state the
/// lens's nominal focal length: focused at 2 m a 200 mm lens images at `f (1 + f / (d - f))`,
/// 11 % further, and zoom markings are rounded. A start from the wrong lens is off by a factor.
pub const FOCAL_VS_FILES_MAX_REL: f64 = 0.25;

/// Median over images of `(reprojection rms / stated corner sigma)²`. The detector's corner
/// sigmas are its own estimate from the edge fit; a camera model that fits the reference
/// field leaves residuals at that scale (a reduced chi-square near 1), a wrong one a
/// systematic residual many times larger.
pub const REPROJECTION_CHI2_MAX: f64 = 25.0;

/// Relative standard deviation of the measurement cameras' distances to the point their
/// optical axes meet. The method places the camera on one circle around the subject, aimed at
/// the forehead; an operator's aim and position vary by centimetres at 2 m.
pub const CAMERA_DISTANCE_SPREAD_MAX: f64 = 0.15;

/// The flash position's stated sd, mm: beyond this the incident direction at the forehead is
/// uncertain by more than a third of a degree at 1.5 m.
pub const FLASH_SIGMA_MAX_MM: f64 = 10.0;

/// C's relative spread over the standard's pixels, percent: a uniform Lambertian standard
/// under one flash gives one C up to noise and the standard's falloff model; a misplaced
/// standard or flash spreads it.
pub const C_SPREAD_MAX_PCT: f64 = 5.0;

/// The fitted model's log residual against the samples, over the smoother's residual (the
/// samples' own scatter about a smooth BRDF). A model that describes the data leaves about
/// the same; twice as much is a misfit or samples that are not one BRDF.
pub const FIT_VS_SMOOTHER_MAX: f64 = 2.0;

/// What became of one check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "outcome", rename_all = "kebab-case")]
pub enum Outcome {
    /// The figure is within its bound.
    Passed,
    /// The figure is beyond its bound, or could not be computed.
    Failed {
        /// The likely cause, in words.
        likely_cause: String,
    },
    /// The check does not apply to this scene.
    NotChecked {
        /// Why.
        why: String,
    },
}

/// One self-check of a stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// Its name (see the module docs' table).
    pub name: String,
    /// What the figure is, in words.
    pub what: String,
    /// The figure (`None` when not checked, or not computable).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub figure: Option<f64>,
    /// The figure's unit.
    pub unit: String,
    /// The bound the figure must stay at or below.
    pub bound: f64,
    /// Passed, failed or not checked.
    #[serde(flatten)]
    pub outcome: Outcome,
}

impl Check {
    /// A check of `figure` against `bound` (at most); a figure that is not finite fails.
    fn at_most(
        name: &str,
        what: &str,
        figure: f64,
        unit: &str,
        bound: f64,
        likely_cause: &str,
    ) -> Self {
        let outcome = if figure.is_finite() && figure <= bound {
            Outcome::Passed
        } else {
            Outcome::Failed {
                likely_cause: likely_cause.to_string(),
            }
        };
        Self {
            name: name.to_string(),
            what: what.to_string(),
            figure: figure.is_finite().then_some(figure),
            unit: unit.to_string(),
            bound,
            outcome,
        }
    }

    /// A check that does not apply, with why.
    fn not_checked(name: &str, what: &str, unit: &str, bound: f64, why: &str) -> Self {
        Self {
            name: name.to_string(),
            what: what.to_string(),
            figure: None,
            unit: unit.to_string(),
            bound,
            outcome: Outcome::NotChecked {
                why: why.to_string(),
            },
        }
    }

    /// Whether it failed.
    pub fn failed(&self) -> bool {
        matches!(self.outcome, Outcome::Failed { .. })
    }

    /// One line for a terminal or an error: name, figure, bound and the likely cause.
    pub fn to_line(&self) -> String {
        let figure = self
            .figure
            .map_or_else(|| "not computable".to_string(), |f| format!("{f:.4}"));
        match &self.outcome {
            Outcome::Passed => format!(
                "{}: {figure}{} <= {}{} (passed)",
                self.name,
                unit_suffix(&self.unit),
                self.bound,
                unit_suffix(&self.unit)
            ),
            Outcome::Failed { likely_cause } => format!(
                "{}: {} is {figure}{}, above the bound {}{}; likely cause: {likely_cause}",
                self.name,
                self.what,
                unit_suffix(&self.unit),
                self.bound,
                unit_suffix(&self.unit)
            ),
            Outcome::NotChecked { why } => format!("{}: not checked ({why})", self.name),
        }
    }
}

/// ` unit`, or nothing for a unitless figure.
fn unit_suffix(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    }
}

/// What the pose checks read besides the poses.
#[derive(Debug, Clone, Copy)]
pub struct PoseCheckInputs<'a> {
    /// The camera as the session states it before any survey (the focal length from the files
    /// is its `focal_guess_px`).
    pub stated_camera: &'a CameraSpec,
}

/// The survey unit's checks, by stage.
pub fn survey_checks(survey: &skinbrdf_poses::Survey) -> Vec<(Stage, Check)> {
    vec![(
        Stage::PlacementSurvey,
        adjustment_chi2(
            "survey_chi2",
            Some(survey.bundle.variance_factor),
            "the survey's adjustment does not fit the photographs: a target that moved, a sheet \
             that is not flat, or a camera model that does not fit",
        ),
    )]
}

/// The pose unit's checks, by stage.
pub fn pose_checks(poses: &SessionPoses, inputs: PoseCheckInputs<'_>) -> Vec<(Stage, Check)> {
    vec![
        (Stage::CameraCalibration, focal_vs_files(poses, inputs)),
        (Stage::CameraPoses, reprojection_chi2(poses)),
        (
            Stage::CameraPoses,
            adjustment_chi2(
                "bundle_chi2",
                poses.bundle.as_ref().map(|b| b.variance_factor),
                "the joint adjustment of every pose does not fit the photographs: a target \
                 that moved since the survey, a head that moved against its headdress, or a \
                 camera model that does not fit",
            ),
        ),
        (Stage::CameraPoses, camera_distance_spread(poses)),
        (Stage::FlashTriangulation, flash_sigma(poses)),
    ]
}

fn focal_vs_files(poses: &SessionPoses, inputs: PoseCheckInputs<'_>) -> Check {
    const NAME: &str = "focal_vs_files";
    const WHAT: &str =
        "the calibrated focal length against the one the session states from the files (relative)";
    match inputs.stated_camera {
        CameraSpec::Calibrated(_) => Check::not_checked(
            NAME,
            WHAT,
            "",
            FOCAL_VS_FILES_MAX_REL,
            "the camera is calibrated in session.toml",
        ),
        CameraSpec::ToBeCalibrated {
            focal_guess_px: None,
            ..
        } => Check::not_checked(
            NAME,
            WHAT,
            "",
            FOCAL_VS_FILES_MAX_REL,
            "the session states no focal length for the camera",
        ),
        CameraSpec::ToBeCalibrated {
            focal_guess_px: Some(f),
            ..
        } => Check::at_most(
            NAME,
            WHAT,
            (poses.camera.fx_px / f - 1.0).abs(),
            "",
            FOCAL_VS_FILES_MAX_REL,
            "the calibration converged to another lens than the files state: a wrong start \
             (state `focal_guess_px`), or the wrong files' focal length",
        ),
    }
}

fn reprojection_chi2(poses: &SessionPoses) -> Check {
    const NAME: &str = "reprojection_chi2";
    const WHAT: &str = "the median over images of (reprojection rms / stated corner sigma)²";
    let per_image: Vec<f64> = poses
        .images
        .iter()
        .filter_map(|img| {
            let cam = img.world_from_camera.as_ref()?;
            if cam.source != "estimated" || cam.targets_used == 0 {
                return None;
            }
            let sigmas: Vec<f64> = img
                .detections
                .iter()
                .filter(|d| d.layout == "reference")
                .flat_map(|d| d.corner_sigma_px)
                .filter(|s| s.is_finite() && *s > 0.0)
                .collect();
            (!sigmas.is_empty()).then(|| (cam.rms_px / median(&sigmas)).powi(2))
        })
        .collect();
    if per_image.is_empty() {
        return Check::not_checked(
            NAME,
            WHAT,
            "",
            REPROJECTION_CHI2_MAX,
            "no camera pose was estimated from the images",
        );
    }
    Check::at_most(
        NAME,
        WHAT,
        median(&per_image),
        "",
        REPROJECTION_CHI2_MAX,
        "the camera model does not fit the reference field: wrong intrinsics or distortion, or \
         reference targets placed wrongly (moved since the survey)",
    )
}

/// An adjustment's reduced chi-square (its a-posteriori variance factor: the robustly
/// weighted squared residuals over their stated corner sigmas, per degree of freedom) against
/// [`REPROJECTION_CHI2_MAX`].
fn adjustment_chi2(name: &str, variance_factor: Option<f64>, likely_cause: &str) -> Check {
    const WHAT: &str =
        "the adjustment's reduced chi-square over all images (residuals over stated corner sigmas)";
    match variance_factor {
        Some(v) => Check::at_most(name, WHAT, v, "", REPROJECTION_CHI2_MAX, likely_cause),
        None => Check::not_checked(
            name,
            WHAT,
            "",
            REPROJECTION_CHI2_MAX,
            "no joint adjustment ran",
        ),
    }
}

fn camera_distance_spread(poses: &SessionPoses) -> Check {
    const NAME: &str = "camera_distance_spread";
    const WHAT: &str =
        "the relative sd of the measurement cameras' distances to their common aim point";
    let axes: Vec<(DVec3, DVec3)> = poses
        .images
        .iter()
        .filter(|i| i.role == ImageRole::Measurement)
        .filter_map(|i| {
            let p = &i.world_from_camera.as_ref()?.pose;
            Some((p.translation_m, p.rotation * DVec3::Z))
        })
        .collect();
    let aim = if axes.len() >= 3 {
        aim_point(&axes)
    } else {
        None
    };
    let Some(aim) = aim else {
        return Check::not_checked(
            NAME,
            WHAT,
            "",
            CAMERA_DISTANCE_SPREAD_MAX,
            "fewer than three measurement images have camera poses, or their axes are parallel",
        );
    };
    let d: Vec<f64> = axes.iter().map(|(c, _)| c.distance(aim)).collect();
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (d.len() - 1) as f64).sqrt();
    Check::at_most(
        NAME,
        WHAT,
        sd / mean,
        "",
        CAMERA_DISTANCE_SPREAD_MAX,
        "the cameras are not on one circle around the forehead they aim at: wrong intrinsics \
         scale each image's distance by how much of the reference field it sees",
    )
}

/// The point closest, in least squares, to every camera's optical axis (`(centre, direction)`,
/// unit directions): `Σ (I - d dᵀ) p = Σ (I - d dᵀ) c`; `None` when the axes are (nearly)
/// parallel.
fn aim_point(axes: &[(DVec3, DVec3)]) -> Option<DVec3> {
    let mut a = DMat3::ZERO;
    let mut b = DVec3::ZERO;
    for (c, d) in axes {
        let m = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += m;
        b += m * *c;
    }
    (a.determinant().abs() > 1e-9).then(|| a.inverse() * b)
}

fn flash_sigma(poses: &SessionPoses) -> Check {
    const NAME: &str = "flash_sigma";
    const WHAT: &str = "the flash position's stated sd";
    let c = &poses.light_position_cov_m2;
    if poses.light_position_m.is_none() || c.len() != 9 {
        return Check::not_checked(
            NAME,
            WHAT,
            "mm",
            FLASH_SIGMA_MAX_MM,
            "the flash position was not triangulated (given, or no light-position images)",
        );
    }
    if c.iter().all(|v| *v == 0.0) {
        return Check::not_checked(
            NAME,
            WHAT,
            "mm",
            FLASH_SIGMA_MAX_MM,
            "the flash position is given, not triangulated",
        );
    }
    Check::at_most(
        NAME,
        WHAT,
        (c[0] + c[4] + c[8]).max(0.0).sqrt() * 1e3,
        "mm",
        FLASH_SIGMA_MAX_MM,
        "the light-position images do not agree on the flash: too few of them, too close in \
         direction, or their camera poses are wrong",
    )
}

/// The derender unit's checks, by stage, from its report's figures.
pub fn derender_checks(reports: &[StageReport]) -> Vec<(Stage, Check)> {
    const NAME: &str = "c_spread";
    const WHAT: &str = "C's relative spread over the standard (green)";
    let spread = reports.iter().find_map(|r| match &r.figures {
        StageMetrics::Derender(m) => Some(m.c_relative_spread_green_pct),
        _ => None,
    });
    let check = match spread {
        Some(Some(pct)) => Check::at_most(
            NAME,
            WHAT,
            pct,
            "%",
            C_SPREAD_MAX_PCT,
            "the standard's pixels do not give one C: the standard or the flash is misplaced, \
             the standard is shadowed or saturated, or its image is not the one under the flash",
        ),
        _ => Check::not_checked(
            NAME,
            WHAT,
            "%",
            C_SPREAD_MAX_PCT,
            "C is given, or was not estimated from a standard",
        ),
    };
    vec![(Stage::Derender, check)]
}

/// The fit unit's checks, by stage, from its reports' figures.
pub fn fit_checks(reports: &[StageReport]) -> Vec<(Stage, Check)> {
    const NAME: &str = "fit_vs_smoother";
    const WHAT: &str = "the model's log residual against the samples over the smoother's";
    let smoother_pct = reports.iter().find_map(|r| match &r.figures {
        StageMetrics::Smooth(m) if m.loess_residual_sigma_pct > 0.0 => {
            Some(m.loess_residual_sigma_pct)
        }
        _ => None,
    });
    let model = reports.iter().find_map(|r| match &r.figures {
        StageMetrics::Fit(m) => m.log_rmse_vs_samples_green,
        _ => None,
    });
    let check = match (model, smoother_pct) {
        (Some(m), Some(s)) => Check::at_most(
            NAME,
            WHAT,
            m / (s / 100.0),
            "",
            FIT_VS_SMOOTHER_MAX,
            "the model does not describe the samples: too few lobes, or samples that are not \
             one BRDF (a patch that is not uniform, wrong poses or C)",
        ),
        _ => Check::not_checked(
            NAME,
            WHAT,
            "",
            FIT_VS_SMOOTHER_MAX,
            "the fit or the smoother gave no residual",
        ),
    };
    vec![(Stage::Fit, check)]
}

/// Attaches each check to its stage's report (a check whose stage has no report goes to the
/// last one); returns the checks that failed.
pub fn attach(reports: &mut [StageReport], checks: Vec<(Stage, Check)>) -> Vec<Check> {
    let mut failed = Vec::new();
    for (stage, check) in checks {
        if check.failed() {
            failed.push(check.clone());
        }
        let at = reports
            .iter()
            .position(|r| r.stage == stage)
            .or(reports.len().checked_sub(1));
        if let Some(i) = at {
            reports[i].checks.retain(|c| c.name != check.name);
            reports[i].checks.push(check);
        }
    }
    failed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_figure_beyond_its_bound_or_not_finite_fails() {
        let ok = Check::at_most("x", "x", 1.0, "", 2.0, "cause");
        assert_eq!(ok.outcome, Outcome::Passed);
        let bad = Check::at_most("x", "x", 3.0, "", 2.0, "cause");
        assert!(bad.failed());
        assert!(
            bad.to_line().contains("likely cause: cause"),
            "{}",
            bad.to_line()
        );
        let nan = Check::at_most("x", "x", f64::NAN, "", 2.0, "cause");
        assert!(nan.failed());
        assert_eq!(nan.figure, None);
    }

    #[test]
    fn an_adjustment_that_does_not_fit_fails_and_none_is_not_checked() {
        let fits = adjustment_chi2("survey_chi2", Some(0.7), "cause");
        assert_eq!(fits.outcome, Outcome::Passed);
        assert!(adjustment_chi2("survey_chi2", Some(40.0), "cause").failed());
        assert!(adjustment_chi2("survey_chi2", Some(f64::NAN), "cause").failed());
        assert!(matches!(
            adjustment_chi2("bundle_chi2", None, "cause").outcome,
            Outcome::NotChecked { .. }
        ));
    }

    #[test]
    fn a_check_round_trips_through_json() {
        for c in [
            Check::at_most("x", "x", 3.0, "mm", 2.0, "cause"),
            Check::at_most("x", "x", 1.0, "mm", 2.0, "cause"),
            Check::not_checked("x", "x", "mm", 2.0, "why"),
        ] {
            let json = serde_json::to_string(&c).expect("serialises");
            let back: Check = serde_json::from_str(&json).expect("reads back");
            assert_eq!(back, c);
        }
    }

    #[test]
    fn attach_marks_the_stage_and_returns_the_failures() {
        let mut reports = vec![
            StageReport::ran(Stage::CameraCalibration, 0.0),
            StageReport::ran(Stage::CameraPoses, 0.0),
        ];
        let failed = attach(
            &mut reports,
            vec![
                (
                    Stage::CameraPoses,
                    Check::at_most("a", "a", 3.0, "", 2.0, "c"),
                ),
                (
                    Stage::CameraCalibration,
                    Check::at_most("b", "b", 1.0, "", 2.0, "c"),
                ),
            ],
        );
        assert_eq!(failed.len(), 1);
        assert!(reports[1].failed());
        assert!(!reports[0].failed());
    }
}
