//! The calibration constant C from images of the reflectance standard (the method's
//! equation 3).
//!
//! The standard is a plane (z = 0 of its frame, normal +z) of known BRDF `rho_s`. Every pixel
//! that sees its central part (the inner [`STANDARD_INSET`] of each side, away from the edges
//! and the targets framing it) gives
//!
//! ```text
//! C_c = rho_s,c(w_i, w_e) · cos θ_i / (D² · V_c)
//! ```
//!
//! per channel (a photosite of a camera raw image loaded per photosite gives its own channel
//! only), and C is a robust average over the pixels (median by default, or the 10%
//! trimmed mean), reported with its spread (MAD σ and relative spread). Pixels that are
//! saturated, below the noise floor or beyond the grazing limit are skipped as for the skin.

use glam::{DVec2, DVec3};
use rayon::prelude::*;
use serde::Serialize;
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_mesh::CameraRays;

use crate::image::ImageView;
use crate::stats::RobustStats;
use crate::{DerenderConfig, DerenderError};

/// Fraction of the standard's width and height used (centred).
pub const STANDARD_INSET: f64 = 0.8;

/// Fewest usable standard pixels C is estimated from (a median of fewer says little about
/// its spread).
pub const MIN_STANDARD_PIXELS: usize = 10;

/// How C is averaged over the standard's pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum CEstimator {
    /// The median (default).
    #[default]
    Median,
    /// The mean of the central 80%.
    TrimmedMean,
}

/// The reflectance standard in one image.
#[derive(Debug, Clone, Copy)]
pub struct StandardImage<'a> {
    /// The pixels.
    pub image: ImageView<'a>,
    /// World from camera.
    pub world_from_camera: Pose,
    /// World from the standard's frame.
    pub world_from_standard: Pose,
    /// Pixels to use (true = standard), e.g. a truth mask; `None` = geometry only.
    pub mask: Option<&'a [bool]>,
}

/// The estimated C.
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    /// C per channel, sr⁻¹ m⁻² per unit linear value.
    pub c: [f64; 3],
    /// Robust statistics of the per-pixel C, per channel.
    pub stats: [RobustStats; 3],
    /// Relative spread per channel (MAD σ / median).
    pub rel_spread: [f64; 3],
    /// Pixels used.
    pub pixels: usize,
    /// The estimator.
    pub estimator: CEstimator,
}

/// Per-pixel C values of one standard image.
fn standard_pixels(
    rays: &CameraRays,
    light_world_m: DVec3,
    brdf: &BrdfModel,
    size_m: [f64; 2],
    s: &StandardImage<'_>,
    cfg: &DerenderConfig,
) -> Vec<[f64; 3]> {
    let camera = rays.camera();
    let std_from_world = s.world_from_standard.inverse();
    let std_from_cam = std_from_world * s.world_from_camera;
    let cam_from_std = std_from_cam.inverse();
    let light = std_from_world.transform_point(light_world_m);
    let o = std_from_cam.translation_m;
    let hx = 0.5 * size_m[0] * STANDARD_INSET;
    let hy = 0.5 * size_m[1] * STANDARD_INSET;
    // Pixel bounding box of the inset rectangle (dense edge samples: distortion bends edges).
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for k in 0..=64 {
        let f = k as f64 / 64.0 * 2.0 - 1.0;
        for p in [
            DVec3::new(f * hx, -hy, 0.0),
            DVec3::new(f * hx, hy, 0.0),
            DVec3::new(-hx, f * hy, 0.0),
            DVec3::new(hx, f * hy, 0.0),
        ] {
            if let Some(px) = camera.project(cam_from_std.transform_point(p)) {
                lo = lo.min(px);
                hi = hi.max(px);
            }
        }
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    let max = DVec2::new(camera.width_px as f64 - 1.0, camera.height_px as f64 - 1.0);
    let lo = lo.floor().max(DVec2::ZERO);
    let hi = hi.ceil().min(max);
    if lo.x > hi.x || lo.y > hi.y {
        return Vec::new();
    }
    let cos_limit = cfg.grazing_limit_deg.to_radians().cos();
    let stride = cfg.stride.max(1) as usize;
    let w = s.image.width as usize;
    let rows: Vec<u32> = (lo.y as u32..=hi.y as u32).step_by(stride).collect();
    rows.into_par_iter()
        .flat_map_iter(|y| {
            let mut out = Vec::new();
            for x in (lo.x as u32..=hi.x as u32).step_by(stride) {
                let idx = y as usize * w + x as usize;
                if s.mask.is_some_and(|m| !m[idx]) || s.image.saturated.is_some_and(|m| m[idx]) {
                    continue;
                }
                let Some(dc) = rays.pixel_ray(DVec2::new(x as f64, y as f64)) else {
                    continue;
                };
                let d = std_from_cam.transform_vector(dc);
                if d.z >= 0.0 {
                    continue;
                }
                let t = -o.z / d.z;
                let p = o + d * t;
                if t <= 0.0 || p.x.abs() > hx || p.y.abs() > hy {
                    continue;
                }
                let to_l = light - p;
                let dist = to_l.length();
                let wi = to_l / dist;
                let we = -d;
                if !(wi.z > cos_limit && we.z > cos_limit) {
                    continue;
                }
                let v = s.image.rgb[idx];
                let measured = s.image.measured(x, y);
                if v.iter()
                    .zip(measured)
                    .any(|(&c, m)| m && (c.is_nan() || (c as f64) < cfg.noise_floor))
                {
                    continue;
                }
                let rho = brdf.eval(wi, we);
                out.push(std::array::from_fn(|c| {
                    if measured[c] {
                        rho[c] * wi.z / (dist * dist * v[c] as f64)
                    } else {
                        f64::NAN
                    }
                }));
            }
            out
        })
        .collect()
}

/// Estimates C from one or more images of the standard.
pub fn calibrate_c(
    camera: &CameraModel,
    light_world_m: DVec3,
    brdf: &BrdfModel,
    size_m: [f64; 2],
    images: &[StandardImage<'_>],
    estimator: CEstimator,
    cfg: &DerenderConfig,
) -> Result<Calibration, DerenderError> {
    let mut all: Vec<[f64; 3]> = Vec::new();
    let rays = CameraRays::new(camera);
    for s in images {
        all.extend(standard_pixels(&rays, light_world_m, brdf, size_m, s, cfg));
    }
    // A photosite image measures each channel at some of its pixels only: every channel needs
    // enough of them.
    let pixels = (0..3)
        .map(|c| all.iter().filter(|p| !p[c].is_nan()).count())
        .min()
        .unwrap_or(0);
    if pixels < MIN_STANDARD_PIXELS {
        return Err(DerenderError::TooFewStandardPixels {
            pixels,
            images: images.len(),
            needed: MIN_STANDARD_PIXELS,
        });
    }
    let mut stats = Vec::with_capacity(3);
    for c in 0..3 {
        let v: Vec<f64> = all.iter().map(|p| p[c]).collect();
        stats.push(RobustStats::of(&v).ok_or(DerenderError::NoFiniteC { channel: c })?);
    }
    let stats: [RobustStats; 3] = [stats[0], stats[1], stats[2]];
    let c = stats.map(|s| match estimator {
        CEstimator::Median => s.median,
        CEstimator::TrimmedMean => s.trimmed_mean,
    });
    Ok(Calibration {
        c,
        rel_spread: stats.map(|s| s.mad_sigma / s.median),
        stats,
        pixels: all.len(),
        estimator,
    })
}
