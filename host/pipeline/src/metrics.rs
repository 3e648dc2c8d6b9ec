//! Typed figures of every stage: what each stage measured of its accuracy and its cost.
//!
//! Each stage fills one struct of named, unit-suffixed fields; code reads those fields (a test
//! asserts `derender.sample_median_rel_error_pct < 3.0`), never a figure looked up by name.
//! [`StageMetrics::rows`] renders them as the report's rows ([`Metric`]), with the bounds the
//! method's default scene must meet. A figure that needs the ground truth is `None` when the
//! session has none.

use serde::{Deserialize, Serialize};

use crate::report::{Metric, MetricKind};

/// Accuracy bounds stated for the default scene (reported, not asserted, by the pipeline).
pub mod bounds {
    /// Surveyed reference targets against their true corners, RMS over targets, mm.
    pub const SURVEY_REFERENCE_RMS_MM: f64 = 0.3;
    /// Surveyed headdress targets, RMS over targets, mm.
    pub const SURVEY_HEADDRESS_RMS_MM: f64 = 0.5;
    /// Surveyed reference targets that light-position images see and no measurement or
    /// standard image does (the flash stand's panel: they place the flash and nothing else),
    /// RMS over targets, mm.
    pub const SURVEY_FLASH_ONLY_RMS_MM: f64 = 1.5;
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

/// The placement survey.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SurveyMetrics {
    /// Targets surveyed.
    pub targets_surveyed: usize,
    /// Targets the survey could not place or left out (moved, duplicated, unseen).
    pub targets_left_out: usize,
    /// Median of the surveyed targets' centre sigmas, mm.
    pub position_sigma_median_mm: Option<f64>,
    /// RMS reprojection error of the adjustment, px.
    pub reprojection_rms_px: f64,
    /// Parameters of the adjustment.
    pub parameters: usize,
    /// Images the adjustment used.
    #[serde(default)]
    pub images_used: usize,
    /// Of those, survey images (role `survey`: taken before the subject sits).
    #[serde(default)]
    pub survey_images: usize,
    /// Reference targets against their true corners, RMS over targets, mm (those held to the
    /// reference structure's bound: not the flash-only ones).
    pub reference_rms_error_mm: Option<f64>,
    /// Reference targets that light-position images see and no measurement or standard image
    /// does, RMS over targets, mm.
    #[serde(default)]
    pub flash_only_rms_error_mm: Option<f64>,
    /// Headdress targets against their true corners, RMS over targets, mm.
    pub headdress_rms_error_mm: Option<f64>,
}

/// Camera calibration.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CalibrationMetrics {
    /// Reprojection RMS of the calibration, px.
    pub reprojection_rms_px: Option<f64>,
    /// Focal length against the truth, px.
    pub focal_length_error_px: Option<f64>,
}

/// Camera poses.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraPoseMetrics {
    /// Images with a camera pose.
    pub images_with_camera_pose: usize,
    /// Median of the per-image reprojection RMS, px.
    pub reprojection_rms_median_px: Option<f64>,
    /// Median per-image detection plus pose time, ms.
    pub detect_plus_pose_per_image_median_ms: Option<f64>,
    /// Individual pose estimates that failed (listed in `poses.json`).
    pub failed_estimates: usize,
    /// Camera position error against the truth, median, mm.
    pub camera_position_error_median_mm: Option<f64>,
    /// Camera orientation error against the truth, median, degrees.
    pub camera_orientation_error_median_deg: Option<f64>,
    /// Reference targets' detected corners against their true image positions, median, px.
    pub reference_corner_error_median_px: Option<f64>,
}

/// Head tracking.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct HeadTrackingMetrics {
    /// Measurement images with a head pose.
    pub images_with_head_pose: usize,
    /// Head position error against the truth, median, mm.
    pub head_position_error_median_mm: Option<f64>,
    /// Head orientation error against the truth, median, degrees.
    pub head_orientation_error_median_deg: Option<f64>,
    /// Headdress targets' corners against their true image positions, median, px.
    pub headdress_corner_error_median_px: Option<f64>,
}

/// Flash triangulation.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FlashMetrics {
    /// Flash position error against the truth, mm.
    pub flash_position_error_mm: Option<f64>,
    /// Flash position standard deviation (root of the covariance's trace), mm.
    pub flash_position_sigma_mm: Option<f64>,
}

/// The reference standard's pose (C itself comes out of derendering).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StandardMetrics {
    /// Standard position error against the truth, mm.
    pub standard_position_error_mm: Option<f64>,
}

/// Scan preparation.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ScanMetrics {
    /// Triangles of the geometry.
    pub triangles: usize,
    /// Planar-fit normal radius, mm.
    pub normal_fit_radius_mm: f64,
    /// Triangles dropped by the scan's repair.
    pub triangles_dropped: usize,
    /// What the convexity test found: the region can shadow itself (`None`: not tested).
    pub region_can_self_shadow: Option<bool>,
}

/// Shadow rays.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ShadowMetrics {
    /// Shadow rays cast.
    pub shadow_rays_cast: u64,
}

/// Why pixels gave no sample, each pixel counted once by its first reason.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DropCounts {
    /// Outside the user mask.
    pub off_mask: u64,
    /// On a printed target in front of the surface.
    pub on_target: u64,
    /// The ray misses the geometry.
    pub no_surface: u64,
    /// The surface faces away from the camera.
    pub back_facing: u64,
    /// Outside the region of interest.
    pub off_region: u64,
    /// Beyond the grazing limit.
    pub grazing: u64,
    /// In shadow.
    pub shadowed: u64,
    /// A saturated channel.
    pub saturated: u64,
    /// Below the noise floor.
    pub below_noise_floor: u64,
    /// A channel is not a finite number (a broken value, not a dark one).
    #[serde(default)]
    pub non_finite: u64,
    /// No ray (outside the camera model's valid field).
    pub no_ray: u64,
}

/// Derendering.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DerenderMetrics {
    /// Samples kept.
    pub samples_kept: u64,
    /// Pixels dropped, by reason.
    pub dropped: DropCounts,
    /// C of the green channel, sr^-1 m^-2.
    pub c_green: f64,
    /// Relative spread of C over the standard (green), percent.
    pub c_relative_spread_green_pct: Option<f64>,
    /// Pixels of the standard C was averaged over.
    pub c_standard_pixels: Option<u64>,
    /// Primary rays per second, millions.
    pub primary_rays_per_s_m: f64,
    /// Samples' median relative error against the true BRDF, percent.
    pub sample_median_rel_error_pct: Option<f64>,
    /// Samples' 90th-percentile relative error against the true BRDF, percent.
    pub sample_p90_rel_error_pct: Option<f64>,
    /// Green samples' median relative error against the true BRDF, percent: the channel
    /// whose noise a raw card and the PNG images of the same renders share (unit gain).
    #[serde(default)]
    pub sample_median_rel_error_green_pct: Option<f64>,
}

/// Smoothing (local quadratic regression).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SmoothMetrics {
    /// The chosen span (fraction of the samples in each local fit).
    pub loess_span: f64,
    /// Residual sigma of the smoother in log space, percent.
    pub loess_residual_sigma_pct: f64,
    /// The image whose samples sit furthest off the smoother: its samples' median log
    /// residual, percent (`skinbrdf_fit::smooth::ImageOffset`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_image_offset_pct: Option<f64>,
    /// That image's index in the session.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_image_index: Option<u16>,
}

/// The model fit.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FitMetrics {
    /// Samples fitted.
    pub samples_fitted: u64,
    /// Log RMSE of the green channel against the samples.
    pub log_rmse_vs_samples_green: Option<f64>,
    /// Log RMSE against the true BRDF (RMS over the channels).
    pub model_log_rmse_vs_truth: Option<f64>,
    /// Median relative error against the true BRDF (median over the channels), percent.
    pub model_median_rel_error_vs_truth_pct: Option<f64>,
}

/// The report (the head rendering is its cost).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ReportMetrics {
    /// Rays of the head rendering.
    pub render_rays: Option<u64>,
    /// Time of the head rendering, s.
    pub render_time_s: Option<f64>,
}

/// One stage's typed figures.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum StageMetrics {
    /// A stage with no figures (skipped).
    #[default]
    None,
    /// The placement survey.
    Survey(SurveyMetrics),
    /// Camera calibration.
    Calibration(CalibrationMetrics),
    /// Camera poses.
    CameraPoses(CameraPoseMetrics),
    /// Head tracking.
    HeadTracking(HeadTrackingMetrics),
    /// Flash triangulation.
    Flash(FlashMetrics),
    /// The standard's pose.
    Standard(StandardMetrics),
    /// Scan preparation.
    Scan(ScanMetrics),
    /// Shadow rays.
    Shadow(ShadowMetrics),
    /// Derendering.
    Derender(DerenderMetrics),
    /// Smoothing.
    Smooth(SmoothMetrics),
    /// Model fit.
    Fit(FitMetrics),
    /// Report.
    Report(ReportMetrics),
}

/// Pushes a metric when the value is present.
fn opt(rows: &mut Vec<Metric>, name: &str, v: Option<f64>, unit: &str, kind: MetricKind) {
    if let Some(v) = v {
        rows.push(Metric::new(name, v, unit, kind));
    }
}

/// Pushes a bounded metric when the value is present.
fn bounded(rows: &mut Vec<Metric>, name: &str, v: Option<f64>, unit: &str, bound: f64) {
    if let Some(v) = v {
        rows.push(Metric::new(name, v, unit, MetricKind::Error).with_bound(bound));
    }
}

impl StageMetrics {
    /// The figures as report rows (name, value, unit, kind, bound).
    pub fn rows(&self) -> Vec<Metric> {
        use MetricKind::{Cost, Count, Error, Quality};
        let mut r = Vec::new();
        match self {
            StageMetrics::None => {}
            StageMetrics::Survey(m) => {
                r.push(Metric::new(
                    "targets_surveyed",
                    m.targets_surveyed as f64,
                    "",
                    Count,
                ));
                r.push(Metric::new(
                    "targets_left_out",
                    m.targets_left_out as f64,
                    "",
                    Count,
                ));
                opt(
                    &mut r,
                    "position_sigma_median",
                    m.position_sigma_median_mm,
                    "mm",
                    Quality,
                );
                r.push(Metric::new(
                    "reprojection_rms",
                    m.reprojection_rms_px,
                    "px",
                    Quality,
                ));
                r.push(Metric::new("parameters", m.parameters as f64, "", Count));
                r.push(Metric::new("images_used", m.images_used as f64, "", Count));
                r.push(Metric::new(
                    "survey_images",
                    m.survey_images as f64,
                    "",
                    Count,
                ));
                bounded(
                    &mut r,
                    "reference_rms_error",
                    m.reference_rms_error_mm,
                    "mm",
                    bounds::SURVEY_REFERENCE_RMS_MM,
                );
                bounded(
                    &mut r,
                    "headdress_rms_error",
                    m.headdress_rms_error_mm,
                    "mm",
                    bounds::SURVEY_HEADDRESS_RMS_MM,
                );
                if m.flash_only_rms_error_mm.is_some() {
                    bounded(
                        &mut r,
                        "flash_only_rms_error",
                        m.flash_only_rms_error_mm,
                        "mm",
                        bounds::SURVEY_FLASH_ONLY_RMS_MM,
                    );
                }
            }
            StageMetrics::Calibration(m) => {
                opt(
                    &mut r,
                    "reprojection_rms",
                    m.reprojection_rms_px,
                    "px",
                    Quality,
                );
                opt(
                    &mut r,
                    "focal_length_error",
                    m.focal_length_error_px,
                    "px",
                    Error,
                );
            }
            StageMetrics::CameraPoses(m) => {
                r.push(Metric::new(
                    "images_with_camera_pose",
                    m.images_with_camera_pose as f64,
                    "",
                    Count,
                ));
                opt(
                    &mut r,
                    "reprojection_rms_median",
                    m.reprojection_rms_median_px,
                    "px",
                    Quality,
                );
                opt(
                    &mut r,
                    "detect_plus_pose_per_image_median",
                    m.detect_plus_pose_per_image_median_ms,
                    "ms",
                    Cost,
                );
                bounded(
                    &mut r,
                    "camera_position_error_median",
                    m.camera_position_error_median_mm,
                    "mm",
                    bounds::CAMERA_POSITION_MM,
                );
                bounded(
                    &mut r,
                    "camera_orientation_error_median",
                    m.camera_orientation_error_median_deg,
                    "deg",
                    bounds::CAMERA_ORIENTATION_DEG,
                );
                opt(
                    &mut r,
                    "reference_corner_error_median",
                    m.reference_corner_error_median_px,
                    "px",
                    Error,
                );
            }
            StageMetrics::HeadTracking(m) => {
                r.push(Metric::new(
                    "images_with_head_pose",
                    m.images_with_head_pose as f64,
                    "",
                    Count,
                ));
                bounded(
                    &mut r,
                    "head_position_error_median",
                    m.head_position_error_median_mm,
                    "mm",
                    bounds::HEAD_POSITION_MM,
                );
                opt(
                    &mut r,
                    "head_orientation_error_median",
                    m.head_orientation_error_median_deg,
                    "deg",
                    Error,
                );
                opt(
                    &mut r,
                    "headdress_corner_error_median",
                    m.headdress_corner_error_median_px,
                    "px",
                    Error,
                );
            }
            StageMetrics::Flash(m) => {
                bounded(
                    &mut r,
                    "flash_position_error",
                    m.flash_position_error_mm,
                    "mm",
                    bounds::FLASH_POSITION_MM,
                );
                opt(
                    &mut r,
                    "flash_position_sigma",
                    m.flash_position_sigma_mm,
                    "mm",
                    Quality,
                );
            }
            StageMetrics::Standard(m) => {
                opt(
                    &mut r,
                    "standard_position_error",
                    m.standard_position_error_mm,
                    "mm",
                    Error,
                );
            }
            StageMetrics::Scan(m) => {
                r.push(Metric::new("triangles", m.triangles as f64, "", Count));
                r.push(Metric::new(
                    "normal_fit_radius",
                    m.normal_fit_radius_mm,
                    "mm",
                    Quality,
                ));
                if m.triangles_dropped > 0 {
                    r.push(Metric::new(
                        "triangles_dropped_by_repair",
                        m.triangles_dropped as f64,
                        "",
                        Count,
                    ));
                }
            }
            StageMetrics::Shadow(m) => {
                r.push(Metric::new(
                    "shadow_rays_cast",
                    m.shadow_rays_cast as f64,
                    "",
                    Cost,
                ));
            }
            StageMetrics::Derender(m) => {
                r.push(Metric::new(
                    "samples_kept",
                    m.samples_kept as f64,
                    "",
                    Count,
                ));
                let d = &m.dropped;
                for (reason, n) in [
                    ("off_mask", d.off_mask),
                    ("on_target", d.on_target),
                    ("no_surface", d.no_surface),
                    ("back_facing", d.back_facing),
                    ("off_region", d.off_region),
                    ("grazing", d.grazing),
                    ("shadowed", d.shadowed),
                    ("saturated", d.saturated),
                    ("below_noise_floor", d.below_noise_floor),
                    ("non_finite", d.non_finite),
                    ("no_ray", d.no_ray),
                ] {
                    if n > 0 {
                        r.push(Metric::new(
                            &format!("dropped_{reason}"),
                            n as f64,
                            "",
                            Count,
                        ));
                    }
                }
                r.push(Metric::new("C_green", m.c_green, "sr^-1 m^-2", Quality));
                opt(
                    &mut r,
                    "C_relative_spread_green",
                    m.c_relative_spread_green_pct,
                    "%",
                    Quality,
                );
                opt(
                    &mut r,
                    "C_standard_pixels",
                    m.c_standard_pixels.map(|n| n as f64),
                    "",
                    Count,
                );
                r.push(Metric::new(
                    "primary_rays_per_s",
                    m.primary_rays_per_s_m,
                    "Mrays/s",
                    Cost,
                ));
                bounded(
                    &mut r,
                    "sample_median_rel_error",
                    m.sample_median_rel_error_pct,
                    "%",
                    bounds::SAMPLE_MEDIAN_REL_ERROR_PCT,
                );
                opt(
                    &mut r,
                    "sample_p90_rel_error",
                    m.sample_p90_rel_error_pct,
                    "%",
                    Error,
                );
                opt(
                    &mut r,
                    "sample_median_rel_error_green",
                    m.sample_median_rel_error_green_pct,
                    "%",
                    Error,
                );
            }
            StageMetrics::Smooth(m) => {
                r.push(Metric::new("loess_span", m.loess_span, "", Quality));
                r.push(Metric::new(
                    "loess_residual_sigma",
                    m.loess_residual_sigma_pct,
                    "% (log)",
                    Quality,
                ));
                opt(
                    &mut r,
                    "worst_image_offset",
                    m.worst_image_offset_pct,
                    "% (log)",
                    Quality,
                );
            }
            StageMetrics::Fit(m) => {
                r.push(Metric::new(
                    "samples_fitted",
                    m.samples_fitted as f64,
                    "",
                    Count,
                ));
                opt(
                    &mut r,
                    "log_rmse_vs_samples_green",
                    m.log_rmse_vs_samples_green,
                    "",
                    Quality,
                );
                opt(
                    &mut r,
                    "model_log_rmse_vs_truth",
                    m.model_log_rmse_vs_truth,
                    "",
                    Error,
                );
                opt(
                    &mut r,
                    "model_median_rel_error_vs_truth",
                    m.model_median_rel_error_vs_truth_pct,
                    "%",
                    Error,
                );
            }
            StageMetrics::Report(m) => {
                opt(
                    &mut r,
                    "render_rays",
                    m.render_rays.map(|n| n as f64),
                    "",
                    Cost,
                );
                opt(&mut r, "render_time", m.render_time_s, "s", Cost);
            }
        }
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_carry_the_bounds_and_omit_missing_truth() {
        let m = StageMetrics::CameraPoses(CameraPoseMetrics {
            images_with_camera_pose: 3,
            camera_position_error_median_mm: Some(2.0),
            ..Default::default()
        });
        let rows = m.rows();
        let pos = rows
            .iter()
            .find(|r| r.name == "camera_position_error_median")
            .map(|r| (r.value, r.bound, r.within_bound()));
        assert_eq!(pos, Some((2.0, Some(bounds::CAMERA_POSITION_MM), false)));
        assert!(!rows
            .iter()
            .any(|r| r.name == "camera_orientation_error_median"));
    }

    #[test]
    fn metrics_round_trip_through_json() {
        let m = StageMetrics::Derender(DerenderMetrics {
            samples_kept: 7,
            sample_median_rel_error_pct: Some(1.2),
            ..Default::default()
        });
        let back: StageMetrics =
            serde_json::from_str(&serde_json::to_string(&m).unwrap_or_default())
                .unwrap_or_default();
        assert_eq!(back, m);
    }
}
