//! Camera calibration (intrinsics and Brown-Conrady distortion) by bundle adjustment over views of
//! known 3D points: a printed board, or the session's own reference field.
//!
//! Parameters: `fx, fy, cx, cy, k1, k2, p1, p2, k3` (any subset can be held fixed, see
//! [`CalibConfig`]) plus a pose per view (`δ, C`, as in [`crate::pnp`]). Each view's pose is
//! initialised by PnP with the starting camera; when no focal length is known the starting
//! focal length is the one, among horizontal fields of view [`FOV_SEARCH_MIN_DEG`] to
//! [`FOV_SEARCH_MAX_DEG`] (a long lens framing a forehead at 2 m sees about 10 degrees, a wide
//! one 100), whose PnP fits best.
//!
//! Without any known 3D point (a survey of a rig nobody measured), [`focal_from_squares`]
//! estimates the focal length from the printed targets alone. Each tag is a square, so the
//! homography `H = [h1 h2 h3]` from its printed frame to the image (pixels centred on the
//! principal point) is `K [r1 r2 t]` up to scale, with `K = diag(f, f, 1)`. With `u = 1 / f²`
//! the two rotation constraints (Zhang 2000) are linear in `u`:
//!
//! ```text
//! r1 . r2 = 0:        (h11 h12 + h21 h22) u + h31 h32          = 0
//! |r1| = |r2|:        (h11² + h21² - h12² - h22²) u + h31² - h32² = 0
//! ```
//!
//! Each tag gives `u` by least squares over its two constraints (`u = -Σ a b / Σ a²`). One small
//! tag seen from far has little perspective (`h31`, `h32` are near the corner noise), and a tag
//! seen edge-on has a wild one, so the estimate is the median over every tag in every image: the
//! tags that see the lens well agree, the rest scatter on both sides.
//! The covariance of the parameters comes from the LM normal matrix scaled by the a-posteriori
//! variance factor; a view set that cannot separate focal length from distance (a single
//! fronto-parallel planar view, say) shows up as a huge condition number and is refused.

use crate::error::PoseError;
use crate::lm::{minimize, LmConfig};
use crate::pnp::{estimate_pose, exp_so3, PnpConfig, PointObs};
use glam::{DVec2, DVec3};
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

/// Narrowest horizontal field of view the starting search tries, degrees (a 600 mm lens on a
/// full-frame body sees 3.4).
pub const FOV_SEARCH_MIN_DEG: f64 = 2.0;
/// Widest horizontal field of view the starting search tries, degrees.
pub const FOV_SEARCH_MAX_DEG: f64 = 120.0;
/// Ratio between neighbouring fields of view in the search: 3 % apart, well inside the
/// calibration's basin of convergence.
const FOV_SEARCH_STEP: f64 = 1.03;

/// The horizontal fields of view the starting search tries, degrees (geometric steps from
/// [`FOV_SEARCH_MIN_DEG`] to [`FOV_SEARCH_MAX_DEG`]).
pub fn fov_search_deg() -> impl Iterator<Item = f64> {
    std::iter::successors(Some(FOV_SEARCH_MIN_DEG), |f| Some(f * FOV_SEARCH_STEP))
        .take_while(|f| *f <= FOV_SEARCH_MAX_DEG)
}

/// A starting camera when only the image size is known: the focal length whose PnP fits the
/// views best among [`fov_search_deg`]; `None` without views to judge by.
pub fn guess_camera(width_px: u32, height_px: u32, views: &[Vec<PointObs>]) -> Option<CameraModel> {
    if views.is_empty() {
        return None;
    }
    let mut best: Option<(f64, CameraModel)> = None;
    for fov in fov_search_deg() {
        let cam = CameraModel::from_fov(width_px, height_px, fov.to_radians());
        let total: f64 = views
            .iter()
            .map(|v| {
                estimate_pose(&cam, v, None, &PnpConfig::DEFAULT)
                    .map(|e| e.rms_px * e.rms_px * e.points_used as f64)
                    .unwrap_or(1e6)
            })
            .sum();
        if best.as_ref().is_none_or(|(b, _)| total < *b) {
            best = Some((total, cam));
        }
    }
    best.map(|(_, c)| c)
}

/// Fewest tag views [`focal_from_squares`] pools before it states a focal length.
pub const MIN_SQUARES_FOR_FOCAL: usize = 8;

/// The focal length, pixels, from the images of printed squares (each a tag's four corners in
/// the printed order: `(-1, 1)`, `(1, 1)`, `(1, -1)`, `(-1, -1)` of its frame), the principal
/// point taken at the image centre (see the module docs); `None` when fewer than
/// [`MIN_SQUARES_FOR_FOCAL`] squares are given, or the pooled constraints do not give a
/// field of view inside the search range.
pub fn focal_from_squares(width_px: u32, height_px: u32, squares: &[[DVec2; 4]]) -> Option<f64> {
    let model = [
        DVec2::new(-1.0, 1.0),
        DVec2::new(1.0, 1.0),
        DVec2::new(1.0, -1.0),
        DVec2::new(-1.0, -1.0),
    ];
    // Pixels centred on the principal point and scaled by the width, for conditioning.
    let centre = DVec2::new(
        (width_px as f64 - 1.0) * 0.5,
        (height_px as f64 - 1.0) * 0.5,
    );
    let scale = width_px as f64;
    let mut per_square: Vec<f64> = Vec::with_capacity(squares.len());
    for sq in squares {
        let img: Vec<DVec2> = sq.iter().map(|p| (*p - centre) / scale).collect();
        let Some(h) = crate::geometry::homography(&model, &img) else {
            continue;
        };
        let pairs = [
            (
                h[(0, 0)] * h[(0, 1)] + h[(1, 0)] * h[(1, 1)],
                h[(2, 0)] * h[(2, 1)],
            ),
            (
                h[(0, 0)].powi(2) + h[(1, 0)].powi(2) - h[(0, 1)].powi(2) - h[(1, 1)].powi(2),
                h[(2, 0)].powi(2) - h[(2, 1)].powi(2),
            ),
        ];
        let saa: f64 = pairs.iter().map(|(a, _)| a * a).sum();
        let sab: f64 = pairs.iter().map(|(a, b)| a * b).sum();
        let u = -sab / saa;
        if u.is_finite() {
            per_square.push(u);
        }
    }
    if per_square.len() < MIN_SQUARES_FOR_FOCAL {
        return None;
    }
    let u = skinbrdf_core::stats::median(&per_square);
    if !(u.is_finite() && u > 0.0) {
        return None;
    }
    let f_px = scale / u.sqrt();
    let hfov_deg = 2.0 * (0.5 * width_px as f64 / f_px).atan().to_degrees();
    (FOV_SEARCH_MIN_DEG..=FOV_SEARCH_MAX_DEG)
        .contains(&hfov_deg)
        .then_some(f_px)
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

    /// Tags of 35 mm on a cage around the origin, seen from 2 m by `truth`: each tag's corners
    /// in pixels with `noise_px` uniform noise.
    fn tag_squares(truth: &CameraModel, views: usize, noise_px: f64) -> Vec<[DVec2; 4]> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut out = Vec::new();
        for v in 0..views {
            let az = (v as f64 * 7.0 - 30.0).to_radians();
            let eye = DVec3::new(2.0 * az.sin(), 2.0 * az.cos(), 0.1);
            let pose = Pose::look_at(eye, DVec3::ZERO, DVec3::Z).expect("valid");
            let inv = pose.inverse();
            for t in 0..24 {
                let a = (t as f64 * 15.0).to_radians();
                let centre =
                    DVec3::new(0.12 * a.sin(), 0.12 * a.cos(), 0.05 * (t % 3) as f64 - 0.05);
                // Each tag leans: its normal between the outward direction and the camera's.
                let normal = (DVec3::new(a.sin(), a.cos(), 0.3 * ((t % 5) as f64 - 2.0))
                    + 0.5 * eye.normalize())
                .normalize();
                let u = normal.cross(DVec3::Z).normalize();
                let w = normal.cross(u);
                let corners = [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)]
                    .map(|(x, y)| centre + 0.0175 * (x * u + y * w));
                let px: Option<Vec<DVec2>> = corners
                    .iter()
                    .map(|c| {
                        let q = truth.project(inv.transform_point(*c))?;
                        truth.contains(q).then(|| {
                            let mut n = || {
                                if noise_px > 0.0 {
                                    rng.random_range(-noise_px..noise_px)
                                } else {
                                    0.0
                                }
                            };
                            q + DVec2::new(n(), n())
                        })
                    })
                    .collect();
                if let Some(px) = px {
                    out.push([px[0], px[1], px[2], px[3]]);
                }
            }
        }
        out
    }

    #[test]
    fn focal_from_squares_finds_a_long_lens_from_tags_alone() {
        // The method's optics: about 10 degrees across, tags 35 mm at 2 m (~30 px).
        for hfov_deg in [6.0, 10.0, 16.0] {
            let truth = CameraModel::from_fov(1524, 1012, f64::to_radians(hfov_deg));
            let squares = tag_squares(&truth, 30, 0.08);
            assert!(squares.len() > 100, "{} tags seen", squares.len());
            let f = focal_from_squares(1524, 1012, &squares).expect("a focal length");
            let rel = f / truth.fx_px - 1.0;
            // The start must sit well inside the survey adjustment's basin of convergence
            // (docs/photogrammetry.md), which a start off by a factor is not.
            assert!(
                rel.abs() < 0.05,
                "hfov {hfov_deg}: f {f:.0} px vs {:.0} px",
                truth.fx_px
            );
        }
    }

    #[test]
    fn focal_from_squares_needs_enough_tags() {
        let truth = CameraModel::from_fov(1524, 1012, 10f64.to_radians());
        let squares = tag_squares(&truth, 1, 0.0);
        assert_eq!(
            focal_from_squares(1524, 1012, &squares[..MIN_SQUARES_FOR_FOCAL - 1]),
            None
        );
    }

    #[test]
    fn the_fov_search_reaches_a_long_and_a_wide_lens() {
        let fovs: Vec<f64> = fov_search_deg().collect();
        assert_eq!(fovs.first(), Some(&FOV_SEARCH_MIN_DEG));
        assert!(fovs.last().is_some_and(|f| *f > 0.97 * FOV_SEARCH_MAX_DEG));
        assert!(fovs.windows(2).all(|w| w[1] / w[0] < 1.031));
        assert_eq!(guess_camera(1524, 1012, &[]), None);
    }
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
        let init = guess_camera(1524, 1012, &views).expect("views to judge by");
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
