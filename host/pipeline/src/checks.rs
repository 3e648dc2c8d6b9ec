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
//! | camera calibration | `principal_point_offset` | the calibrated principal point's distance from the image centre over the half-diagonal | above [`PRINCIPAL_POINT_OFFSET_MAX`] |
//! | camera poses | `reprojection_chi2` | median over images of `(rms / sigma)²`, the per-image reprojection RMS against the median stated corner sigma | above [`REPROJECTION_CHI2_MAX`] |
//! | camera poses | `worst_image_chi2` | the largest over images of the same figure (the failure names the image) | above [`WORST_IMAGE_CHI2_MAX`] |
//! | placement survey | `survey_chi2` | the survey adjustment's reduced chi-square (variance factor) | above [`REPROJECTION_CHI2_MAX`] |
//! | camera poses | `bundle_chi2` | the joint pose adjustment's reduced chi-square over all images | above [`REPROJECTION_CHI2_MAX`] |
//! | camera poses | `camera_arc_steps` | the largest angle between neighbouring measurement cameras round their aim point, over the median one | above [`CAMERA_ARC_STEP_RATIO_MAX`] |
//! | camera poses | `camera_distance_spread` | relative sd of the measurement cameras' distances to the point their optical axes meet | above [`CAMERA_DISTANCE_SPREAD_MAX`] |
//! | flash triangulation | `light_images_agree` | the light-position images' single-view flash positions' reduced chi-square about their combined position (the farthest image named) | above [`LIGHT_IMAGES_CHI2_MAX`] |
//! | flash triangulation | `flash_sigma` | the flash position's stated sd | above [`FLASH_SIGMA_MAX_MM`] |
//! | radiometric calibration (in derender) | `c_spread` | C's relative spread over the standard | above [`C_SPREAD_MAX_PCT`] |
//! | smoothing | `image_offset` | the largest image's median log residual about the smoother, over the samples' scatter about it (at least [`IMAGE_OFFSET_SCATTER_FLOOR_PCT`]) | above [`IMAGE_OFFSET_MAX`] |
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

/// The calibrated principal point's distance from the image centre, over the image's
/// half-diagonal. A lens is centred on its sensor to a few percent of the frame (sensor-shift
/// stabilisation moves it by a few more); a calibration that puts the principal point further
/// out is trading it against the camera's orientation or the distortion, which the images do
/// not tell apart (too few views, or all from one roll angle).
pub const PRINCIPAL_POINT_OFFSET_MAX: f64 = 0.1;

/// Median over images of `(reprojection rms / stated corner sigma)²`. The detector's corner
/// sigmas are its own estimate from the edge fit; a camera model that fits the reference
/// field leaves residuals at that scale (a reduced chi-square near 1), a wrong one a
/// systematic residual many times larger.
pub const REPROJECTION_CHI2_MAX: f64 = 25.0;

/// The largest over images of `(reprojection rms / stated corner sigma)²`. Where the camera
/// model fits, every image's figure is near 1 (the worst of forty a little above 2); one image
/// whose pose rests on a misread or moved target, or on a blurred or partly hidden one, stands
/// out by an order of magnitude. A bound four times the median's lets an image with an
/// optimistic detector sigma pass.
pub const WORST_IMAGE_CHI2_MAX: f64 = 4.0 * REPROJECTION_CHI2_MAX;

/// Relative standard deviation of the measurement cameras' distances to the point their
/// optical axes meet. The method places the camera on one circle around the subject, aimed at
/// the forehead; an operator's aim and position vary by centimetres at 2 m.
pub const CAMERA_DISTANCE_SPREAD_MAX: f64 = 0.15;

/// The largest angle between neighbouring measurement cameras round their common aim point,
/// over the median angle. The method moves the camera in even steps along one arc, placed by
/// eye (a step varies by about a third); one or two missed positions make a step two or three
/// times the median. A larger gap leaves a band of angles unmeasured, or comes from poses that
/// are wrong.
pub const CAMERA_ARC_STEP_RATIO_MAX: f64 = 3.5;

/// The flash position's stated sd, mm: beyond this the incident direction at the forehead is
/// uncertain by more than a third of a degree at 1.5 m.
pub const FLASH_SIGMA_MAX_MM: f64 = 10.0;

/// The light-position images' single-view flash positions' reduced chi-square about their
/// combined position, each with its pose's stated covariance. Views that see one fixed flash
/// agree to about 1; one whose flash or camera moved, or whose pose is wrong, by many times.
/// The single-view covariances come from the detector's corner sigmas, which are
/// optimistic for small, far targets, hence the same margin as the reprojection checks.
pub const LIGHT_IMAGES_CHI2_MAX: f64 = REPROJECTION_CHI2_MAX;

/// C's relative spread over the standard's pixels, percent: a uniform Lambertian standard
/// under one flash gives one C up to noise and the standard's falloff model; a misplaced
/// standard or flash spreads it.
pub const C_SPREAD_MAX_PCT: f64 = 5.0;

/// The fitted model's log residual against the samples, over the smoother's residual (the
/// samples' own scatter about a smooth BRDF). A model that describes the data leaves about
/// the same; twice as much is a misfit or samples that are not one BRDF.
pub const FIT_VS_SMOOTHER_MAX: f64 = 2.0;

/// One image's samples' median log residual about the smoother, over the samples' scatter
/// about it (the smoother's residual sd, at least [`IMAGE_OFFSET_SCATTER_FLOOR_PCT`]). The
/// smoother is the BRDF all images agree on: an image's noise and the smoother's bias scatter
/// about it, so its median sits well inside the scatter, while an image whose exposure, flash,
/// pose or standard is wrong sits off by a relative error of its own.
pub const IMAGE_OFFSET_MAX: f64 = 2.0;

/// The least scatter, percent (log), an image's offset is compared with: noise-free samples
/// scatter by the smoother's bias alone, and an offset of a percent is within what the flash's
/// own energy varies from one firing to the next.
pub const IMAGE_OFFSET_SCATTER_FLOOR_PCT: f64 = 1.0;

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
        (
            Stage::CameraCalibration,
            principal_point_offset(poses, inputs),
        ),
        (Stage::CameraPoses, reprojection_chi2(poses)),
        (Stage::CameraPoses, worst_image_chi2(poses)),
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
        (Stage::CameraPoses, camera_arc_steps(poses)),
        (Stage::FlashTriangulation, flash_sigma(poses)),
        (Stage::FlashTriangulation, light_images_agree(poses)),
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

fn principal_point_offset(poses: &SessionPoses, inputs: PoseCheckInputs<'_>) -> Check {
    const NAME: &str = "principal_point_offset";
    const WHAT: &str =
        "the calibrated principal point's distance from the image centre over the half-diagonal";
    if let CameraSpec::Calibrated(_) = inputs.stated_camera {
        return Check::not_checked(
            NAME,
            WHAT,
            "",
            PRINCIPAL_POINT_OFFSET_MAX,
            "the camera is calibrated in session.toml",
        );
    }
    Check::at_most(
        NAME,
        WHAT,
        principal_point_offset_rel(&poses.camera),
        "",
        PRINCIPAL_POINT_OFFSET_MAX,
        "the calibration traded the principal point against the camera's orientation or \
         distortion: survey images from more directions, some with the camera turned 90 degrees \
         about its axis, separate them",
    )
}

/// `|c - centre| / (diagonal / 2)` for a camera's principal point `c`.
fn principal_point_offset_rel(camera: &skinbrdf_core::CameraModel) -> f64 {
    let (w, h) = (f64::from(camera.width_px), f64::from(camera.height_px));
    let offset_px = (camera.cx_px - 0.5 * w).hypot(camera.cy_px - 0.5 * h);
    offset_px / (0.5 * w.hypot(h))
}

/// Each image with an estimated camera pose: its file and `(reprojection rms / median stated
/// corner sigma)²` over its reference targets.
fn per_image_chi2(poses: &SessionPoses) -> Vec<(&str, f64)> {
    poses
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
            (!sigmas.is_empty())
                .then(|| (img.file.as_str(), (cam.rms_px / median(&sigmas)).powi(2)))
        })
        .collect()
}

fn reprojection_chi2(poses: &SessionPoses) -> Check {
    const NAME: &str = "reprojection_chi2";
    const WHAT: &str = "the median over images of (reprojection rms / stated corner sigma)²";
    let per_image: Vec<f64> = per_image_chi2(poses).into_iter().map(|(_, c)| c).collect();
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

fn worst_image_chi2(poses: &SessionPoses) -> Check {
    const NAME: &str = "worst_image_chi2";
    const WHAT: &str = "the largest over images of (reprojection rms / stated corner sigma)²";
    let per_image = per_image_chi2(poses);
    let Some((file, worst)) = per_image.iter().max_by(|a, b| a.1.total_cmp(&b.1)) else {
        return Check::not_checked(
            NAME,
            WHAT,
            "",
            WORST_IMAGE_CHI2_MAX,
            "no camera pose was estimated from the images",
        );
    };
    Check::at_most(
        NAME,
        WHAT,
        *worst,
        "",
        WORST_IMAGE_CHI2_MAX,
        &format!(
            "the camera pose of {file} does not fit its targets: a target misread or moved in \
             that image, motion blur, or a target that is partly hidden"
        ),
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

/// The measurement cameras' optical axes, `(centre, unit direction)`.
fn measurement_axes(poses: &SessionPoses) -> Vec<(DVec3, DVec3)> {
    poses
        .images
        .iter()
        .filter(|i| i.role == ImageRole::Measurement)
        .filter_map(|i| {
            let p = &i.world_from_camera.as_ref()?.pose;
            Some((p.translation_m, p.rotation * DVec3::Z))
        })
        .collect()
}

fn camera_distance_spread(poses: &SessionPoses) -> Check {
    const NAME: &str = "camera_distance_spread";
    const WHAT: &str =
        "the relative sd of the measurement cameras' distances to their common aim point";
    let axes = measurement_axes(poses);
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

fn camera_arc_steps(poses: &SessionPoses) -> Check {
    const NAME: &str = "camera_arc_steps";
    const WHAT: &str = "the largest angle between neighbouring measurement cameras round their \
                        aim point, over the median angle";
    let axes = measurement_axes(poses);
    let figure = if axes.len() >= 4 {
        aim_point(&axes).and_then(|aim| {
            let directions: Vec<DVec3> = axes
                .iter()
                .filter_map(|(c, _)| (*c - aim).try_normalize())
                .collect();
            arc_step_ratio(&directions)
        })
    } else {
        None
    };
    let Some(ratio) = figure else {
        return Check::not_checked(
            NAME,
            WHAT,
            "",
            CAMERA_ARC_STEP_RATIO_MAX,
            "fewer than four measurement images have camera poses, or they do not span an arc",
        );
    };
    Check::at_most(
        NAME,
        WHAT,
        ratio,
        "",
        CAMERA_ARC_STEP_RATIO_MAX,
        "the arc has a gap: positions missed or skipped, or camera poses that are wrong",
    )
}

/// For unit directions from an aim point to cameras on one arc: the largest angle between
/// neighbours along the arc over the median angle. The arc's plane is the one through the aim
/// point that the directions lie closest to (normal `n`: the eigenvector of `Σ u uᵀ` with the
/// smallest eigenvalue); each direction's azimuth in that plane is sorted, and the cyclic
/// steps between neighbours lose their largest one (the open side of the arc). `None` when the
/// directions do not determine a plane or coincide.
fn arc_step_ratio(directions: &[DVec3]) -> Option<f64> {
    let n = least_direction(directions)?;
    let e1 = directions
        .first()?
        .reject_from_normalized(n)
        .try_normalize()?;
    let e2 = n.cross(e1);
    let mut azimuth_rad: Vec<f64> = directions
        .iter()
        .map(|u| u.dot(e2).atan2(u.dot(e1)))
        .collect();
    azimuth_rad.sort_by(f64::total_cmp);
    let mut steps_rad: Vec<f64> = azimuth_rad.windows(2).map(|w| w[1] - w[0]).collect();
    steps_rad.push(std::f64::consts::TAU - (azimuth_rad.last()? - azimuth_rad.first()?));
    steps_rad.sort_by(f64::total_cmp);
    steps_rad.pop();
    let largest_step_rad = *steps_rad.last()?;
    let median_step_rad = median(&steps_rad);
    (median_step_rad > 1e-9).then(|| largest_step_rad / median_step_rad)
}

/// The unit vector `n` minimising `Σ (u·n)²`: the eigenvector of `M = Σ u uᵀ` with the
/// smallest eigenvalue. `None` when that eigenvalue is not clearly below the middle one (the
/// directions do not lie near one plane through the aim point) or the middle one is zero (they
/// lie on a line).
fn least_direction(directions: &[DVec3]) -> Option<DVec3> {
    /// The smallest eigenvalue must be below this fraction of the middle one: directions on
    /// an arc placed by eye lie within a few degrees of their plane.
    const PLANARITY_MAX: f64 = 0.25;
    let m = directions
        .iter()
        .fold(nalgebra::Matrix3::<f64>::zeros(), |acc, u| {
            let v = nalgebra::Vector3::new(u.x, u.y, u.z);
            acc + v * v.transpose()
        });
    let eigen = nalgebra::SymmetricEigen::new(m);
    let mut order = [0usize, 1, 2];
    order.sort_by(|a, b| eigen.eigenvalues[*a].total_cmp(&eigen.eigenvalues[*b]));
    let (smallest, middle) = (eigen.eigenvalues[order[0]], eigen.eigenvalues[order[1]]);
    if !(middle > 0.0 && smallest < PLANARITY_MAX * middle) {
        return None;
    }
    let n = eigen.eigenvectors.column(order[0]);
    DVec3::new(n[0], n[1], n[2]).try_normalize()
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

fn light_images_agree(poses: &SessionPoses) -> Check {
    const NAME: &str = "light_images_agree";
    const WHAT: &str = "the light-position images' single-view flash positions' reduced \
                        chi-square about their combined position";
    let Some(a) = &poses.light_agreement else {
        return Check::not_checked(
            NAME,
            WHAT,
            "",
            LIGHT_IMAGES_CHI2_MAX,
            "fewer than two light-position images placed the flash (or its position is given)",
        );
    };
    Check::at_most(
        NAME,
        WHAT,
        a.reduced_chi2,
        "",
        LIGHT_IMAGES_CHI2_MAX,
        &format!(
            "the light-position images place the flash in different places ({} is {:.1} mm \
             from their combined position): the flash stand moved between them, or a \
             light-position image's camera pose is wrong",
            a.farthest_image, a.farthest_offset_mm
        ),
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

/// The fit unit's checks, by stage, from its reports' figures (`image_files`: the session's
/// image files, to name an image).
pub fn fit_checks(reports: &[StageReport], image_files: &[&str]) -> Vec<(Stage, Check)> {
    vec![
        (
            Stage::SmoothIncidencePlane,
            image_offset(reports, image_files),
        ),
        (Stage::Fit, fit_vs_smoother(reports)),
    ]
}

fn image_offset(reports: &[StageReport], image_files: &[&str]) -> Check {
    const NAME: &str = "image_offset";
    const WHAT: &str = "the largest image's median log residual about the smoother over the \
                        samples' scatter about it";
    let smooth = reports.iter().find_map(|r| match &r.figures {
        StageMetrics::Smooth(m) => Some(m),
        _ => None,
    });
    let Some((offset_pct, index, sigma_pct)) = smooth.and_then(|m| {
        Some((
            m.worst_image_offset_pct?,
            m.worst_image_index?,
            m.loess_residual_sigma_pct,
        ))
    }) else {
        return Check::not_checked(
            NAME,
            WHAT,
            "",
            IMAGE_OFFSET_MAX,
            "no image has enough samples among the smoother's residuals",
        );
    };
    let file = image_files
        .get(usize::from(index))
        .map_or_else(|| format!("image {index}"), |f| (*f).to_string());
    Check::at_most(
        NAME,
        WHAT,
        offset_pct.abs() / sigma_pct.max(IMAGE_OFFSET_SCATTER_FLOOR_PCT),
        "",
        IMAGE_OFFSET_MAX,
        &format!(
            "the samples of {file} sit {offset_pct:+.2} % off the BRDF the other images agree \
             on: its flash did not fire fully, its exposure or camera pose is wrong, or the \
             patch moved in it"
        ),
    )
}

fn fit_vs_smoother(reports: &[StageReport]) -> Check {
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
    match (model, smoother_pct) {
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
    }
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

    /// Unit directions at these azimuths (degrees) in a plane tilted off the axes.
    fn arc(azimuths_deg: &[f64]) -> Vec<DVec3> {
        let tilt = glam::DQuat::from_axis_angle(DVec3::new(1.0, 0.3, 0.0).normalize(), 0.4);
        azimuths_deg
            .iter()
            .map(|a| tilt * DVec3::new(a.to_radians().cos(), 0.0, a.to_radians().sin()))
            .collect()
    }

    #[test]
    fn an_even_arc_has_step_ratio_one_and_a_gap_shows() {
        let even: Vec<f64> = (0..30).map(|i| -30.0 + 3.7 * f64::from(i)).collect();
        let ratio = arc_step_ratio(&arc(&even)).expect("an arc");
        assert!((ratio - 1.0).abs() < 1e-6, "{ratio}");
        let mut gap = even.clone();
        gap.drain(10..15);
        let ratio = arc_step_ratio(&arc(&gap)).expect("an arc");
        assert!((ratio - 6.0).abs() < 1e-6, "{ratio}");
        assert!(ratio > CAMERA_ARC_STEP_RATIO_MAX);
        let around: Vec<f64> = (0..12).map(|i| 170.0 + 30.0 * f64::from(i)).collect();
        let ratio = arc_step_ratio(&arc(&around)).expect("a full circle");
        assert!((ratio - 1.0).abs() < 1e-6, "{ratio}");
    }

    #[test]
    fn directions_off_any_plane_have_no_arc() {
        let spread = [
            DVec3::X,
            DVec3::Y,
            DVec3::Z,
            DVec3::NEG_X,
            DVec3::NEG_Y,
            DVec3::NEG_Z,
        ];
        assert_eq!(arc_step_ratio(&spread), None);
    }

    #[test]
    fn a_principal_point_at_the_centre_is_offset_zero_and_one_at_the_corner_is_one() {
        let mut cam = skinbrdf_core::CameraModel::from_fov(400, 300, 0.3);
        cam.cx_px = 200.0;
        cam.cy_px = 150.0;
        assert!(principal_point_offset_rel(&cam).abs() < 1e-12);
        cam.cx_px = 400.0;
        cam.cy_px = 300.0;
        assert!((principal_point_offset_rel(&cam) - 1.0).abs() < 1e-12);
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

    fn smooth_report(offset_pct: Option<f64>, sigma_pct: f64) -> StageReport {
        StageReport::ran(Stage::SmoothIncidencePlane, 0.0).with_figures(StageMetrics::Smooth(
            crate::metrics::SmoothMetrics {
                loess_span: 0.1,
                loess_residual_sigma_pct: sigma_pct,
                worst_image_offset_pct: offset_pct,
                worst_image_index: offset_pct.map(|_| 1),
            },
        ))
    }

    #[test]
    fn an_image_off_the_smoother_fails_by_name_and_the_floor_keeps_noise_free_runs() {
        let files = ["a.dng", "b.dng"];
        let noisy_ok = image_offset(&[smooth_report(Some(-3.0), 6.0)], &files);
        assert_eq!(noisy_ok.outcome, Outcome::Passed, "{}", noisy_ok.to_line());
        let dim = image_offset(&[smooth_report(Some(-20.0), 6.0)], &files);
        assert!(dim.failed());
        assert!(dim.to_line().contains("b.dng"), "{}", dim.to_line());
        // Noise-free: a scatter of 0.2 % is floored at a percent.
        let noise_free = image_offset(&[smooth_report(Some(0.5), 0.2)], &files);
        assert_eq!(noise_free.figure, Some(0.5));
        assert_eq!(noise_free.outcome, Outcome::Passed);
        assert!(matches!(
            image_offset(&[smooth_report(None, 6.0)], &files).outcome,
            Outcome::NotChecked { .. }
        ));
        let stages: Vec<Stage> = fit_checks(&[], &files).iter().map(|c| c.0).collect();
        assert_eq!(stages, [Stage::SmoothIncidencePlane, Stage::Fit]);
    }
}
