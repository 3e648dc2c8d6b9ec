//! Derendering: images, poses and the head scan to calibrated BRDF samples.
//!
//! Every pixel of the region of interest in every measurement image becomes one sample
//!
//! ```text
//! rho_c(w_i, w_e) = C_c · D² · V_c / cos θ_i          (the method's equation 2)
//! ```
//!
//! with `V` the linearized pixel value, `D` the distance from the surface point to the light,
//! and `C` from the reference standard (equation 3, [`calibrate`]).
//!
//! * [`geometry`]: the scan prepared once — BVH, planar-fit normals, region of interest, and
//!   the convexity test that decides whether shadow rays are needed at all.
//! * [`image`]: one image to samples ([`derender_image`]), every dropped pixel counted by reason.
//! * [`calibrate`]: C from the standard's pixels, robust average with its spread.
//! * [`session`]: the whole derender from plain data ([`derender_with_loader`]: poses per
//!   image, light, C or the standard, images loaded one at a time), timings per stage.
//! * [`from_session`]: the same from a `skinbrdf-session` directory ([`derender_session`]),
//!   with, when `truth.json` is present, the samples' error against the true BRDF.
//! * [`figures`]: coverage figures (pixels used per image; the exitant hemisphere for one θ_i
//!   with the reciprocal samples in another colour), PNG and SVG.
//!
//! The API takes poses as plain data (`world_from_camera`, `world_from_head` per image, the
//! light position in the world), so it works from known poses before pose estimation exists.

pub mod calibrate;
pub mod figures;
pub mod from_session;
pub mod geometry;
pub mod image;
pub mod session;
pub mod stats;

pub use calibrate::{calibrate_c, CEstimator, Calibration, StandardImage};
pub use from_session::{derender_session, PoseChoice, SessionOptions, SessionRun};
pub use geometry::{Geometry, Roi};
pub use image::{
    derender_image, derender_image_with_rays, region_pixels, FilterCounts, ImageSamples, ImageView,
    Measurement, RegionPixels,
};
pub use session::{
    derender_with_loader, CalibrationInput, DerenderInputs, DerenderReport, ImagePoses, OwnedImage,
    PoseSource, StageTimes,
};
pub use stats::RobustStats;

use serde::Serialize;
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::BrdfSample;
use skinbrdf_mesh::{BuildQuality, NormalMethod};

/// Errors of derendering.
#[derive(Debug, thiserror::Error)]
pub enum DerenderError {
    /// The mesh could not be used.
    #[error(transparent)]
    Mesh(#[from] skinbrdf_mesh::MeshError),
    /// No scan vertex lies in the region of interest.
    #[error("the region of interest contains no vertex of the scan")]
    EmptyRegion,
    /// C could not be estimated.
    #[error("calibration: {0}")]
    Calibration(String),
    /// A session input is missing or unusable.
    #[error("{0}")]
    Input(String),
    /// Writing an output failed.
    #[error("{path}: {reason}")]
    Output {
        /// The file.
        path: std::path::PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// When to cast shadow rays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum ShadowMode {
    /// Only when the geometry can shadow the region (not convex; see [`geometry`]).
    #[default]
    Auto,
    /// For every sample.
    Always,
    /// Never.
    Never,
}

impl ShadowMode {
    /// Whether rays are cast given the convexity test's verdict.
    pub fn needs_rays(self, can_self_shadow: bool) -> bool {
        match self {
            Self::Auto => can_self_shadow,
            Self::Always => true,
            Self::Never => false,
        }
    }
}

/// Settings of derendering.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DerenderConfig {
    /// Use every `stride`-th pixel in x and y (1 = every pixel).
    pub stride: u32,
    /// Samples with θ_i or θ_e beyond this are dropped (degrees, < 90).
    pub grazing_limit_deg: f64,
    /// Samples with any channel's linear value below this are dropped.
    pub noise_floor: f64,
    /// Shadow rays.
    pub shadows: ShadowMode,
    /// Shading normals.
    pub normals: NormalMethod,
    /// Averaging of C.
    pub c_estimator: CEstimator,
    /// BVH build preset (build time against tracing speed).
    pub bvh_quality: BuildQuality,
}

impl DerenderConfig {
    /// The defaults: every pixel, 75° grazing limit (a 1° normal error then costs at most
    /// 6.5% in `1/cos θ_i`; at 60° it is 3%), noise floor 0.01 (1% of white: ten times a
    /// typical 8-bit quantisation step), shadows when needed, planar-fit normals with the
    /// radius from the scan's noise, median C, medium BVH build.
    pub const DEFAULT: Self = Self {
        stride: 1,
        grazing_limit_deg: 75.0,
        noise_floor: 0.01,
        shadows: ShadowMode::Auto,
        normals: NormalMethod::PlanarFitAuto,
        c_estimator: CEstimator::Median,
        bvh_quality: BuildQuality::Medium,
    };

    /// Checks ranges.
    pub fn validate(&self) -> Result<(), DerenderError> {
        if !(self.grazing_limit_deg > 0.0 && self.grazing_limit_deg < 90.0) {
            return Err(DerenderError::Input(format!(
                "grazing limit {}° must be in (0, 90): cos θ must stay bounded away from 0",
                self.grazing_limit_deg
            )));
        }
        if !(self.noise_floor.is_finite() && self.noise_floor >= 0.0) {
            return Err(DerenderError::Input(format!(
                "noise floor {} must be finite and non-negative",
                self.noise_floor
            )));
        }
        if self.stride == 0 {
            return Err(DerenderError::Input("stride must be at least 1".into()));
        }
        Ok(())
    }
}

impl Default for DerenderConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Error of samples against a known BRDF.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruthError {
    /// Samples compared.
    pub samples: usize,
    /// Median of |rho - rho_true| / rho_true over samples and channels.
    pub median_rel_error: f64,
    /// 90th percentile of the same.
    pub p90_rel_error: f64,
    /// Median signed relative error (bias).
    pub median_signed_rel_error: f64,
    /// Median relative error per channel.
    pub median_rel_error_rgb: [f64; 3],
}

/// Compares samples with the true BRDF evaluated at each sample's angles.
pub fn truth_error(samples: &[BrdfSample], truth: &BrdfModel) -> Option<TruthError> {
    if samples.is_empty() {
        return None;
    }
    let mut per: [Vec<f64>; 3] = Default::default();
    let mut signed = Vec::with_capacity(samples.len() * 3);
    for s in samples {
        let t = truth.eval_angles(
            s.theta_i_rad as f64,
            s.theta_e_rad as f64,
            s.phi_d_rad as f64,
        );
        for c in 0..3 {
            if t[c] > 0.0 {
                let e = (s.rho[c] as f64 - t[c]) / t[c];
                per[c].push(e.abs());
                signed.push(e);
            }
        }
    }
    let all: Vec<f64> = per.iter().flatten().copied().collect();
    let st = RobustStats::of(&all)?;
    let mut sorted = all.clone();
    sorted.sort_by(f64::total_cmp);
    Some(TruthError {
        samples: samples.len(),
        median_rel_error: st.median,
        p90_rel_error: stats::percentile_sorted(&sorted, 0.9),
        median_signed_rel_error: RobustStats::of(&signed).map_or(f64::NAN, |s| s.median),
        median_rel_error_rgb: std::array::from_fn(|c| {
            RobustStats::of(&per[c]).map_or(f64::NAN, |s| s.median)
        }),
    })
}

#[cfg(test)]
mod synthetic_tests;
