//! Camera calibration (intrinsics and Brown-Conrady distortion) by bundle adjustment over views of
//! known 3D points: a printed board, or the session's own reference field.
//!
//! Parameters: `fx, fy, cx, cy, k1, k2, p1, p2, k3` (any subset can be held fixed, see
//! [`CalibConfig`]) plus a pose per view (`δ, C`, as in [`crate::pnp`]). Each view's pose is
//! initialised by PnP with the starting camera; when no focal length is known the starting
//! focal length is the one, among horizontal fields of view 20..100 degrees, whose PnP fits best.
//! The covariance of the parameters comes from the LM normal matrix scaled by the a-posteriori
//! variance factor; a view set that cannot separate focal length from distance (a single
//! fronto-parallel planar view, say) shows up as a huge condition number and is refused.

use crate::error::PoseError;
use crate::lm::{minimize, LmConfig};
use crate::pnp::{estimate_pose, exp_so3, PnpConfig, PointObs};
use glam::DVec3;
use nalgebra::DVector;
use serde::{Deserialize, Serialize};
use skinbrdf_core::{BrownConrady, CameraModel, Pose};

/// Names of the intrinsic parameters in order.
pub const PARAM_NAMES: [&str; 9] = [
    "fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "p1", "p2", "k3",
];

/// Which parameters to estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CalibConfig {
    /// Estimate one focal length for x and y (square pixels).
    pub equal_focal: bool,
    /// Estimate the tangential coefficients p1, p2.
    pub tangential: bool,
    /// Estimate k3.
    pub k3: bool,
    /// Condition number above which the calibration is refused.
    pub max_condition: f64,
}

impl CalibConfig {
    /// Square pixels, radial k1, k2 and tangential terms; k3 only with many views.
    pub const DEFAULT: Self = Self {
        equal_focal: true,
        tangential: true,
        k3: false,
        max_condition: 1e14,
    };
}

impl Default for CalibConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The result of a calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// The calibrated camera.
    pub camera: CameraModel,
    /// Standard deviation of each intrinsic parameter, order [`PARAM_NAMES`]; `None` where it
    /// was not estimated: the parameter was held fixed, or the normal matrix was too
    /// ill-conditioned to invert (written as `null` in JSON).
    pub sigma: [Option<f64>; 9],
    /// RMS reprojection error over all views, pixels.
    pub rms_px: f64,
    /// Per view `frame_from_camera`.
    pub views: Vec<Pose>,
    /// Number of points used.
    pub points: usize,
    /// Condition number of the normal matrix.
    pub condition_number: f64,
}

fn camera_from(base: &CameraModel, p: &[f64; 9]) -> CameraModel {
    CameraModel {
        fx_px: p[0],
        fy_px: p[1],
        cx_px: p[2],
        cy_px: p[3],
        distortion: BrownConrady {
            k1: p[4],
            k2: p[5],
            p1: p[6],
            p2: p[7],
            k3: p[8],
        },
        ..*base
    }
}

/// A starting camera when only the image size is known: the focal length whose PnP fits the
/// views best.
pub fn guess_camera(width_px: u32, height_px: u32, views: &[Vec<PointObs>]) -> CameraModel {
    let mut best = (
        f64::INFINITY,
        CameraModel::from_fov(width_px, height_px, 50f64.to_radians()),
    );
    let mut fov = 20.0;
    while fov <= 100.0 {
        let cam = CameraModel::from_fov(width_px, height_px, f64::to_radians(fov));
        let mut total = 0.0;
        for v in views {
            total += estimate_pose(&cam, v, None, &PnpConfig::DEFAULT)
                .map(|e| e.rms_px * e.rms_px * e.points_used as f64)
                .unwrap_or(1e6);
        }
        if total < best.0 {
            best = (total, cam);
        }
        fov += 2.5;
    }
    best.1
}

/// Calibrates intrinsics and distortion from views of known points, starting from `init`.
pub fn calibrate(
    init: &CameraModel,
    views: &[Vec<PointObs>],
    cfg: &CalibConfig,
) -> Result<Calibration, PoseError> {
    let mut poses = Vec::new();
    let mut used_views = Vec::new();
    for v in views {
        if let Ok(e) = estimate_pose(init, v, None, &PnpConfig::DEFAULT) {
            let inl: Vec<PointObs> = v
                .iter()
                .copied()
                .filter(|p| e.targets_used.contains(&p.target))
                .collect();
            poses.push(e.frame_from_camera);
            used_views.push(inl);
        }
    }
    if used_views.is_empty() {
        return Err(PoseError::TooFewTargets {
            found: 0,
            points: 0,
            needed: 1,
        });
    }
    // Free intrinsic parameters.
    let mut free: Vec<usize> = vec![0];
    if !cfg.equal_focal {
        free.push(1);
    }
    free.extend([2, 3, 4, 5]);
    if cfg.tangential {
        free.extend([6, 7]);
    }
    if cfg.k3 {
        free.push(8);
    }
    let d = init.distortion;
    let p0 = [
        init.fx_px, init.fy_px, init.cx_px, init.cy_px, d.k1, d.k2, d.p1, d.p2, d.k3,
    ];
    let ni = free.len();
    let mut x0 = Vec::with_capacity(ni + 6 * poses.len());
    for &i in &free {
        x0.push(p0[i]);
    }
    for p in &poses {
        x0.extend([
            0.0,
            0.0,
            0.0,
            p.translation_m.x,
            p.translation_m.y,
            p.translation_m.z,
        ]);
    }
    let n_points: usize = used_views.iter().map(|v| v.len()).sum();
    let unpack = |x: &[f64]| -> [f64; 9] {
        let mut p = p0;
        for (k, &i) in free.iter().enumerate() {
            p[i] = x[k];
        }
        if cfg.equal_focal {
            p[1] = p[0] * (init.fy_px / init.fx_px);
        }
        p
    };
    let f = |x: &DVector<f64>| -> Option<DVector<f64>> {
        let xs = x.as_slice();
        let cam = camera_from(init, &unpack(xs));
        let mut r = DVector::zeros(2 * n_points);
        let mut k = 0;
        for (vi, v) in used_views.iter().enumerate() {
            let o = ni + 6 * vi;
            let rot = exp_so3(DVec3::new(xs[o], xs[o + 1], xs[o + 2])) * poses[vi].rotation;
            let c = DVec3::new(xs[o + 3], xs[o + 4], xs[o + 5]);
            let inv = rot.inverse();
            for p in v {
                let q = cam.project(inv * (p.object_m - c))?;
                let s = p.sigma_px.max(0.05);
                r[k] = (q.x - p.image_px.x) / s;
                r[k + 1] = (q.y - p.image_px.y) / s;
                k += 2;
            }
        }
        Some(r)
    };
    let res =
        minimize(f, DVector::from_vec(x0), &LmConfig::DEFAULT).ok_or(PoseError::NoConsensus {
            targets: used_views.len(),
        })?;
    if res.condition_number > cfg.max_condition {
        return Err(PoseError::IllConditioned {
            condition_number: res.condition_number,
        });
    }
    let xs = res.x.as_slice();
    let params = unpack(xs);
    let camera = camera_from(init, &params);
    let mut sigma = [None; 9];
    if let Some(cov) = &res.covariance {
        for (k, &i) in free.iter().enumerate() {
            sigma[i] = Some(cov[(k, k)].max(0.0).sqrt()).filter(|s| s.is_finite());
        }
        if cfg.equal_focal {
            sigma[1] = sigma[0].map(|s| s * (init.fy_px / init.fx_px));
        }
    }
    let views_out: Vec<Pose> = (0..used_views.len())
        .map(|vi| {
            let o = ni + 6 * vi;
            Pose::new(
                exp_so3(DVec3::new(xs[o], xs[o + 1], xs[o + 2])) * poses[vi].rotation,
                DVec3::new(xs[o + 3], xs[o + 4], xs[o + 5]),
            )
        })
        .collect();
    // RMS in pixels (residuals are whitened by sigma).
    let mut se = 0.0;
    for (vi, v) in used_views.iter().enumerate() {
        let inv = views_out[vi].inverse();
        for p in v {
            if let Some(q) = camera.project(inv.transform_point(p.object_m)) {
                se += q.distance_squared(p.image_px);
            }
        }
    }
    Ok(Calibration {
        camera,
        sigma,
        rms_px: (se / n_points.max(1) as f64).sqrt(),
        views: views_out,
        points: n_points,
        condition_number: res.condition_number,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;
    use rand::{Rng, SeedableRng};

    #[test]
    fn recovers_focal_and_distortion_from_a_3d_field() {
        let mut truth = CameraModel::from_fov(1524, 1012, 48f64.to_radians());
        truth.cx_px += 6.0;
        truth.cy_px -= 4.0;
        truth.distortion.k1 = -0.12;
        truth.distortion.k2 = 0.05;
        // A 3D field: points on three planes.
        let mut obj = Vec::new();
        for i in -4..=4 {
            for j in -3..=3 {
                let z = if i < -1 {
                    0.0
                } else if i < 2 {
                    0.04
                } else {
                    0.09
                };
                obj.push(DVec3::new(i as f64 * 0.05, j as f64 * 0.05, z));
            }
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let mut views = Vec::new();
        for k in 0..6 {
            let a = k as f64 * 0.5;
            let eye = DVec3::new(0.35 * a.cos(), 0.25 * a.sin(), -0.75);
            let pose = Pose::look_at(eye, DVec3::ZERO, DVec3::new(0.0, -1.0, 0.0)).expect("valid");
            let inv = pose.inverse();
            let v: Vec<PointObs> = obj
                .iter()
                .enumerate()
                .filter_map(|(n, p)| {
                    let px = truth.project(inv.transform_point(*p))?;
                    truth.contains(px).then(|| PointObs {
                        object_m: *p,
                        image_px: px
                            + DVec2::new(rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1)),
                        sigma_px: 0.06,
                        target: (n / 4) as u32,
                        normal: DVec3::ZERO,
                    })
                })
                .collect();
            views.push(v);
        }
        let init = guess_camera(1524, 1012, &views);
        let cal = calibrate(&init, &views, &CalibConfig::DEFAULT).expect("calibrates");
        // Errors within 4 stated standard deviations, and the deviations small.
        let c = &cal.camera;
        let sigma = |i: usize| cal.sigma[i].expect("estimated");
        assert!(
            (c.fx_px - truth.fx_px).abs() < 4.0 * sigma(0),
            "{} vs {}",
            c.fx_px,
            truth.fx_px
        );
        assert!((c.cx_px - truth.cx_px).abs() < 4.0 * sigma(2));
        assert!((c.distortion.k1 - truth.distortion.k1).abs() < 4.0 * sigma(4));
        assert!(sigma(0) < 5.0 && sigma(4) < 0.02);
        assert!(cal.rms_px < 0.1);
        // fy follows fx (square pixels); k3 is held fixed by the default and has no sigma.
        assert!(cal.sigma[1].is_some());
        assert_eq!(cal.sigma[8], None);
        // A held-fixed parameter's sigma is written as null and read back as not estimated.
        let json = skinbrdf_core::json::to_vec_pretty(std::path::Path::new("c.json"), &cal)
            .expect("finite");
        let back: Calibration = serde_json::from_slice(&json).expect("reads back");
        assert_eq!(back.sigma, cal.sigma);
    }
}
