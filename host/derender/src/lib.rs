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
//! * [`from_inputs`]: the whole derender from plain data ([`derender_with_loader`]: poses per
//!   image, light, C or the standard, images loaded one at a time), timings per stage.
//! * [`poses`]: the poses as plain, already-resolved data ([`ResolvedPoses`], each quantity
//!   with its [`PoseSource`]) and the one constructor of [`DerenderInputs`] from a session.
//! * [`from_session`]: the same from a `skinbrdf-session` directory ([`derender_session`]),
//!   with, when `truth.json` is present, the samples' error against the true BRDF.
//! * [`figures`]: coverage figures (pixels used per image; the exitant hemisphere for one θ_i
//!   with the reciprocal samples in another colour), PNG and SVG.
//!
//! The API takes poses as plain data (`world_from_camera`, `world_from_head` per image, the
//! light position in the world): where they come from (the session, the pose stage, the
//! truth) is decided by the caller (the pipeline's `pose_inputs`), not here.

pub mod calibrate;
pub mod figures;
pub mod from_inputs;
pub mod from_session;
pub mod geometry;
pub mod image;
pub mod poses;
pub mod stats;

pub use calibrate::{calibrate_c, CEstimator, Calibration, StandardImage};
pub use from_inputs::{
    derender_with_loader, CalibrationInput, CalibrationSource, DerenderInputs, DerenderReport,
    ImagePoses, OwnedImage, PoseSource, StageTimes,
};
pub use from_session::{derender_session, SessionRun, TargetMask};
pub use geometry::{Geometry, Roi};
pub use image::{
    derender_image, derender_image_with_rays, region_pixels, FilterCounts, ImageSamples, ImageView,
    Measurement, RegionPixels,
};
pub use poses::{ResolvedImage, ResolvedPoses, ResolvedStandard, Sourced};
pub use stats::RobustStats;

use serde::Serialize;
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::BrdfSample;
use skinbrdf_mesh::{BuildQuality, NormalMethod};

/// Errors of derendering. Each names what is wrong and, where there is one, the file; a
/// wrapped error is printed in the message (and not also exposed as `source`).
#[derive(Debug, thiserror::Error)]
pub enum DerenderError {
    /// The mesh could not be used.
    #[error(transparent)]
    Mesh(#[from] skinbrdf_mesh::MeshError),
    /// No scan vertex lies in the region of interest.
    #[error("the region of interest contains no vertex of the scan")]
    EmptyRegion,
    /// A setting of [`DerenderConfig`] is out of range.
    #[error("{setting} = {value}: {requirement}")]
    Config {
        /// The setting.
        setting: ConfigSetting,
        /// Its value.
        value: f64,
        /// What it must satisfy, and why.
        requirement: &'static str,
    },
    /// Too few pixels of the reflectance standard passed the filters to estimate C.
    #[error(
        "calibration: only {pixels} usable pixels on the reflectance standard in {images} \
         image(s) (need {needed})"
    )]
    TooFewStandardPixels {
        /// Usable pixels found.
        pixels: usize,
        /// Standard images searched.
        images: usize,
        /// Pixels needed.
        needed: usize,
    },
    /// A channel's per-pixel C values were all non-finite.
    #[error("calibration: channel {channel}: no finite C value")]
    NoFiniteC {
        /// The channel (0 = red).
        channel: usize,
    },
    /// A session input derendering needs is missing.
    #[error("{file}: {missing}", file = file.display())]
    Missing {
        /// The file that should provide it (`session.toml`, `truth.json`).
        file: std::path::PathBuf,
        /// What is missing.
        missing: MissingInput,
    },
    /// An image could not be loaded.
    #[error("images[{index}]: {error}")]
    Image {
        /// Session image index.
        index: usize,
        /// The loader's error (names the file).
        error: skinbrdf_session::FileError,
    },
    /// A user mask could not be loaded.
    #[error("images[{index}].mask: {error}")]
    Mask {
        /// Session image index.
        index: usize,
        /// The loader's error (names the file).
        error: skinbrdf_session::FileError,
    },
    /// A user mask's size differs from its image's.
    #[error(
        "{file}: mask is {}x{} but the image is {}x{}",
        mask_px[0], mask_px[1], image_px[0], image_px[1], file = file.display()
    )]
    MaskSize {
        /// The mask file.
        file: std::path::PathBuf,
        /// Mask width and height, pixels.
        mask_px: [u32; 2],
        /// Image width and height, pixels.
        image_px: [u32; 2],
    },
    /// An image's size is not the camera's (for a raw session: poses estimated with the other
    /// raw mode).
    #[error(
        "image {index} is {}x{} px as loaded but the camera is {}x{} px (a raw session's poses and its derender must load the images alike: same --raw-mode)",
        image_px[0], image_px[1], camera_px[0], camera_px[1]
    )]
    ImageSize {
        /// Index of the image in the session.
        index: usize,
        /// Image width and height, pixels.
        image_px: [u32; 2],
        /// Camera width and height, pixels.
        camera_px: [u32; 2],
    },
    /// `truth.json` exists but could not be read (it is read for scoring only).
    #[error("scoring: {error}")]
    Truth {
        /// The loader's error (names the file).
        error: skinbrdf_session::FileError,
    },
    /// A session image index does not fit the samples' 16-bit image index.
    #[error("image index {index} exceeds 65535 (samples store it in 16 bits)")]
    ImageIndex {
        /// The index.
        index: usize,
    },
    /// Writing the samples failed.
    #[error(transparent)]
    Output(#[from] skinbrdf_samples::SamplesError),
}

/// A setting of [`DerenderConfig`] (named in [`DerenderError::Config`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ConfigSetting {
    /// [`DerenderConfig::grazing_limit_deg`].
    GrazingLimitDeg,
    /// [`DerenderConfig::noise_floor`].
    NoiseFloor,
    /// [`DerenderConfig::stride`].
    Stride,
}

impl std::fmt::Display for ConfigSetting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::GrazingLimitDeg => "grazing_limit_deg",
            Self::NoiseFloor => "noise_floor",
            Self::Stride => "stride",
        })
    }
}

/// What a session lacks for derendering (named in [`DerenderError::Missing`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MissingInput {
    /// C is not known and there is no standard to calibrate from.
    #[error("no known.calibration_c and no [standard] to calibrate from")]
    Calibration,
    /// C is to come from the standard but its pose, or every standard image's camera pose, is
    /// unknown.
    #[error(
        "no known.calibration_c, and the reflectance standard's pose or every \
         reference-standard image's camera pose is unknown"
    )]
    StandardPoses,
    /// No measurement image has both poses.
    #[error("no measurement image has both a camera and a head pose ({unposed} without)")]
    PosedMeasurement {
        /// Measurement images without poses.
        unposed: usize,
    },
    /// `truth.json` has no entry for an image.
    #[error("no entry for images[{index}] ({image})")]
    ImageTruth {
        /// Session image index.
        index: usize,
        /// Its file.
        image: String,
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
        let bad = |setting, value, requirement| {
            Err(DerenderError::Config {
                setting,
                value,
                requirement,
            })
        };
        if !(self.grazing_limit_deg > 0.0 && self.grazing_limit_deg < 90.0) {
            return bad(
                ConfigSetting::GrazingLimitDeg,
                self.grazing_limit_deg,
                "must be in (0, 90) degrees: cos θ must stay bounded away from 0",
            );
        }
        if !(self.noise_floor.is_finite() && self.noise_floor >= 0.0) {
            return bad(
                ConfigSetting::NoiseFloor,
                self.noise_floor,
                "must be finite and non-negative",
            );
        }
        if self.stride == 0 {
            return bad(
                ConfigSetting::Stride,
                f64::from(self.stride),
                "must be at least 1",
            );
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
    /// Median relative error per channel; `None` for a channel the true BRDF is zero in
    /// everywhere (no sample has a relative error there).
    pub median_rel_error_rgb: [Option<f64>; 3],
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
            // A partial sample is scored on the channels it measured.
            if t[c] > 0.0 && s.measures(c) {
                let e = (s.rho[c] as f64 - t[c]) / t[c];
                per[c].push(e.abs());
                signed.push(e);
            }
        }
    }
    let mut sorted: Vec<f64> = per
        .iter()
        .flatten()
        .copied()
        .filter(|e| e.is_finite())
        .collect();
    let st = RobustStats::of(&sorted)?;
    sorted.sort_by(f64::total_cmp);
    // `signed` holds the same errors with their signs, so it has a finite value too.
    let signed = RobustStats::of(&signed)?;
    Some(TruthError {
        samples: samples.len(),
        median_rel_error: st.median,
        p90_rel_error: stats::percentile_sorted(&sorted, 0.9),
        median_signed_rel_error: signed.median,
        median_rel_error_rgb: std::array::from_fn(|c| RobustStats::of(&per[c]).map(|s| s.median)),
    })
}

#[cfg(test)]
mod synthetic_tests;
