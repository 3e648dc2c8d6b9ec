//! Least-squares alignment of corresponding points, with rejection of bad targets.
//!
//! # The fit (Kabsch / Umeyama)
//!
//! Given pairs `x_i` (survey frame) and `y_i` (scan frame), the rigid fit minimises
//! `sum |y_i - (R x_i + t)|²` over rotations `R` and translations `t`; the similarity fit adds a
//! scale `s` (`y ≈ s R x + t`). With the centroids `x̄, ȳ`, the cross-covariance
//! `Σ = (1/n) sum (y_i - ȳ)(x_i - x̄)ᵀ = U D Vᵀ` (SVD) and `S = diag(1, 1, det(U) det(V))`
//! (which keeps `R` a rotation when the best orthogonal matrix would be a reflection):
//!
//! ```text
//! R = U S Vᵀ,   s = tr(D S) / σx²  (σx² = (1/n) sum |x_i - x̄|²; s = 1 for a rigid fit),
//! t = ȳ - s R x̄
//! ```
//!
//! (Kabsch 1976 for the rotation, Umeyama 1991 for the scale and the reflection guard). The
//! solution is unique when the points are not collinear: [`MIN_SPREAD_M`] is required of the
//! second singular value of the centred survey points.
//!
//! # Rejection
//!
//! Every target contributes its four corners. After a fit, a target's residual is the RMS over
//! its corners of `|y_i - (s R x_i + t)|`. The threshold is
//!
//! ```text
//! threshold = max(max_target_residual_mm, reject_factor × robust_median_mm)
//! ```
//!
//! ([`AlignConfig`]), where `robust_median_mm` is the least median of the targets' residuals
//! over the fits to every pair of targets (least median of squares over pairs: a fit to two
//! good targets sees the bad ones as what they are, while the fit to all of them spreads a
//! gross error into every residual and inflates their median). The worst target is then
//! dropped and the fit to the rest repeated while its residual exceeds the threshold and more
//! than `min_targets` targets remain: one at a time, worst first, because a gross error also
//! raises the good targets' residuals until it is gone.
//!
//! The absolute floor ([`MAX_TARGET_RESIDUAL_MM`], 1 mm) is several times what a good target
//! shows (scan corners ~0.1 mm, a survey's ~0.1..0.3 mm) and far below what a bad one shows (a
//! tag detected on a creased or partly scanned paper, a target moved between survey and scan:
//! millimetres); the relative part keeps a survey that is coarse everywhere from losing all
//! its targets.
//!
//! # Uncertainty
//!
//! With `p_i = s R x_i`, a small rotation `δθ` (applied in the scan frame), translation `δt` and
//! relative scale `δs` move the prediction by `-[p_i]× δθ + δt + p_i δs`: the rows of the
//! Jacobian `J`. With `σ² = sum |r_i|² / (3n - k)` (`k` = 6 or 7 parameters), the parameter
//! covariance is `σ² (JᵀJ)⁻¹`; [`Alignment::rotation_sd_deg`] is the square root of the trace of
//! its rotation block (the RMS rotation error), [`Alignment::translation_sd_mm`] that of the
//! translation block (the error of `scan_from_survey`'s translation, i.e. at the survey
//! frame's origin) and [`Alignment::centroid_sd_mm`] the same at the points' centroid.

use glam::{DMat3, DQuat, DVec3};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};
use skinbrdf_core::Pose;

use crate::RegisterError;

/// A target whose RMS corner residual exceeds this after the fit is dropped (unless the
/// median target's is comparable, see [`AlignConfig::reject_factor`]), millimetres. See the
/// module docs for the rationale.
pub const MAX_TARGET_RESIDUAL_MM: f64 = 1.0;
/// Relative part of the rejection threshold: a multiple of the median target residual.
pub const REJECT_FACTOR: f64 = 5.0;
/// Smallest number of targets the rejection keeps.
pub const MIN_TARGETS: usize = 3;
/// The points must spread at least this much off their best line (second singular value of
/// the centred points, RMS), metres: below it the rotation about that line is undetermined.
pub const MIN_SPREAD_M: f64 = 1e-3;

/// Rigid or similarity fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlignKind {
    /// Rotation and translation (the scan and the survey are both metric).
    #[default]
    Rigid,
    /// Rotation, translation and one scale (a survey known only up to scale).
    Similarity,
}

/// Rejection settings of [`crate::align()`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AlignConfig {
    /// Absolute floor of the rejection threshold, millimetres ([`MAX_TARGET_RESIDUAL_MM`]).
    pub max_target_residual_mm: f64,
    /// Relative part: a multiple of the median target residual ([`REJECT_FACTOR`]).
    pub reject_factor: f64,
    /// Targets the rejection never goes below ([`MIN_TARGETS`]).
    pub min_targets: usize,
}

impl Default for AlignConfig {
    fn default() -> Self {
        Self {
            max_target_residual_mm: MAX_TARGET_RESIDUAL_MM,
            reject_factor: REJECT_FACTOR,
            min_targets: MIN_TARGETS,
        }
    }
}

/// One target's fit residual.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TargetResidual {
    /// tag36h11 id.
    pub id: u32,
    /// RMS over its corners, millimetres.
    pub residual_mm: f64,
    /// Its worst corner, millimetres.
    pub max_corner_mm: f64,
    /// Corners used.
    pub corners: usize,
}

/// A target left out of the fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DroppedTarget {
    /// tag36h11 id.
    pub id: u32,
    /// Its residual when it was dropped, millimetres.
    pub residual_mm: f64,
    /// The threshold it exceeded, millimetres.
    pub threshold_mm: f64,
}

/// The result of an alignment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Alignment {
    /// Rigid or similarity.
    pub kind: AlignKind,
    /// Maps survey-frame points into the scan frame (`y = scale · R x + t`; the pose holds `R`
    /// and `t`).
    pub scan_from_survey: Pose,
    /// Scale (1 for a rigid fit).
    pub scale: f64,
    /// Residual of every target kept.
    pub residuals: Vec<TargetResidual>,
    /// RMS over all corners kept, millimetres.
    pub rms_mm: f64,
    /// Targets left out, in the order they were dropped.
    pub dropped: Vec<DroppedTarget>,
    /// The rejection threshold used, millimetres (see the module docs).
    pub threshold_mm: f64,
    /// The least median target residual over the fits to pairs of targets, millimetres.
    pub robust_median_mm: f64,
    /// Targets in only one of the two sets (not used).
    pub unmatched: Vec<u32>,
    /// Points (corners) in the final fit.
    pub points_used: usize,
    /// RMS rotation error from the residuals, degrees.
    pub rotation_sd_deg: f64,
    /// Standard error of the pose's translation (at the survey frame's origin), millimetres.
    pub translation_sd_mm: f64,
    /// Standard error of the translation at the points' centroid, millimetres.
    pub centroid_sd_mm: f64,
    /// Standard error of the scale (0 for a rigid fit).
    pub scale_sd: f64,
}

/// One correspondence: target, corner, survey point, scan point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correspondence {
    /// tag36h11 id.
    pub id: u32,
    /// Corner index (0..4, session order).
    pub corner: u8,
    /// Survey frame, metres.
    pub survey_m: DVec3,
    /// Scan frame, metres.
    pub scan_m: DVec3,
}

/// The closed-form fit of `y ≈ s R x + t` (see the module docs): `(R, t, s)`.
pub fn umeyama(
    pairs: &[Correspondence],
    kind: AlignKind,
) -> Result<(DMat3, DVec3, f64), RegisterError> {
    let n = pairs.len();
    if n < 3 {
        return Err(RegisterError::TooFewPoints { points: n });
    }
    let v = |p: DVec3| Vector3::new(p.x, p.y, p.z);
    let xm = pairs.iter().map(|p| v(p.survey_m)).sum::<Vector3<f64>>() / n as f64;
    let ym = pairs.iter().map(|p| v(p.scan_m)).sum::<Vector3<f64>>() / n as f64;
    let mut sigma = Matrix3::zeros();
    let mut sxx = Matrix3::zeros();
    let mut var_x = 0.0;
    for p in pairs {
        let dx = v(p.survey_m) - xm;
        let dy = v(p.scan_m) - ym;
        sigma += dy * dx.transpose();
        sxx += dx * dx.transpose();
        var_x += dx.norm_squared();
    }
    sigma /= n as f64;
    sxx /= n as f64;
    var_x /= n as f64;
    let spread = sxx.symmetric_eigenvalues();
    let mut ev: Vec<f64> = spread.iter().copied().collect();
    ev.sort_by(f64::total_cmp);
    let second = ev[1].max(0.0).sqrt();
    if second.is_nan() || second < MIN_SPREAD_M {
        return Err(RegisterError::Degenerate {
            spread_mm: second * 1e3,
            min_spread_mm: MIN_SPREAD_M * 1e3,
        });
    }
    let svd = sigma.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(RegisterError::Numerical {
            what: "SVD of the cross-covariance did not converge",
        });
    };
    let d = if (u.determinant() * vt.determinant()) < 0.0 {
        -1.0
    } else {
        1.0
    };
    let s_diag = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d));
    let r = u * s_diag * vt;
    let scale = match kind {
        AlignKind::Rigid => 1.0,
        AlignKind::Similarity => {
            let dsum = svd.singular_values[0] + svd.singular_values[1] + d * svd.singular_values[2];
            dsum / var_x
        }
    };
    let t = ym - r * xm * scale;
    let rot = DMat3::from_cols(
        DVec3::new(r[(0, 0)], r[(1, 0)], r[(2, 0)]),
        DVec3::new(r[(0, 1)], r[(1, 1)], r[(2, 1)]),
        DVec3::new(r[(0, 2)], r[(1, 2)], r[(2, 2)]),
    );
    if !(scale.is_finite() && scale > 0.0 && rot.is_finite()) {
        return Err(RegisterError::Numerical {
            what: "the fit is not finite",
        });
    }
    Ok((rot, DVec3::new(t.x, t.y, t.z), scale))
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Per-target residuals of a fit, ordered by id.
fn target_residuals(pairs: &[Correspondence], r: &DMat3, t: DVec3, s: f64) -> Vec<TargetResidual> {
    let mut ids: Vec<u32> = pairs.iter().map(|p| p.id).collect();
    ids.sort_unstable();
    ids.dedup();
    ids.into_iter()
        .map(|id| {
            let e: Vec<f64> = pairs
                .iter()
                .filter(|p| p.id == id)
                .map(|p| (p.scan_m - (*r * p.survey_m * s + t)).length() * 1e3)
                .collect();
            TargetResidual {
                id,
                residual_mm: (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt(),
                max_corner_mm: e.iter().copied().fold(0.0, f64::max),
                corners: e.len(),
            }
        })
        .collect()
}

/// Fits `pairs` with iterative rejection of targets (see the module docs).
pub fn fit_correspondences(
    pairs: &[Correspondence],
    kind: AlignKind,
    cfg: &AlignConfig,
) -> Result<Alignment, RegisterError> {
    if !(cfg.max_target_residual_mm.is_finite()
        && cfg.max_target_residual_mm > 0.0
        && cfg.reject_factor.is_finite()
        && cfg.reject_factor > 0.0)
    {
        return Err(RegisterError::InvalidParameter {
            field: "align config",
            reason: format!(
                "thresholds must be positive and finite: max_target_residual_mm {}, \
                 reject_factor {}",
                cfg.max_target_residual_mm, cfg.reject_factor
            ),
        });
    }
    let mut kept: Vec<Correspondence> = pairs.to_vec();
    let mut dropped = Vec::new();
    let robust_median_mm = robust_median_mm(pairs, kind)?;
    let threshold_mm = cfg
        .max_target_residual_mm
        .max(cfg.reject_factor * robust_median_mm);
    loop {
        let (r, t, s) = umeyama(&kept, kind)?;
        let res = target_residuals(&kept, &r, t, s);
        let worst = res
            .iter()
            .copied()
            .max_by(|a, b| a.residual_mm.total_cmp(&b.residual_mm));
        match worst {
            Some(w) if w.residual_mm > threshold_mm && res.len() > cfg.min_targets.max(1) => {
                dropped.push(DroppedTarget {
                    id: w.id,
                    residual_mm: w.residual_mm,
                    threshold_mm,
                });
                kept.retain(|p| p.id != w.id);
            }
            _ => {
                let rejection = Rejection {
                    dropped,
                    threshold_mm,
                    robust_median_mm,
                };
                return Ok(finish(&kept, kind, r, t, s, res, rejection));
            }
        }
    }
}

/// What the rejection loop of [`align`] decided, carried into the [`Alignment`].
#[derive(Debug)]
struct Rejection {
    /// Targets left out, in the order they were dropped.
    dropped: Vec<DroppedTarget>,
    /// The rejection threshold, millimetres.
    threshold_mm: f64,
    /// The least median target residual over the pair fits, millimetres.
    robust_median_mm: f64,
}

/// Pairs of targets tried at most for the robust scale (all pairs of up to 25 targets).
const MAX_PAIR_FITS: usize = 300;

/// The least median of the targets' residuals over the fits to pairs of targets (or the fit to
/// all when there are fewer than three targets, or a pair's points are degenerate), mm.
fn robust_median_mm(pairs: &[Correspondence], kind: AlignKind) -> Result<f64, RegisterError> {
    let mut ids: Vec<u32> = pairs.iter().map(|p| p.id).collect();
    ids.sort_unstable();
    ids.dedup();
    let all = |pairs: &[Correspondence]| -> Result<f64, RegisterError> {
        let (r, t, s) = umeyama(pairs, kind)?;
        Ok(median(
            target_residuals(pairs, &r, t, s)
                .iter()
                .map(|x| x.residual_mm)
                .collect(),
        ))
    };
    if ids.len() < 3 {
        return all(pairs);
    }
    let combos: Vec<(u32, u32)> = ids
        .iter()
        .enumerate()
        .flat_map(|(i, &a)| ids[i + 1..].iter().map(move |&b| (a, b)))
        .collect();
    let stride = combos.len().div_ceil(MAX_PAIR_FITS).max(1);
    let mut best = f64::INFINITY;
    for &(a, b) in combos.iter().step_by(stride) {
        let sub: Vec<Correspondence> = pairs
            .iter()
            .copied()
            .filter(|p| p.id == a || p.id == b)
            .collect();
        let Ok((r, t, s)) = umeyama(&sub, kind) else {
            continue;
        };
        let m = median(
            target_residuals(pairs, &r, t, s)
                .iter()
                .map(|x| x.residual_mm)
                .collect(),
        );
        best = best.min(m);
    }
    if best.is_finite() {
        Ok(best)
    } else {
        all(pairs)
    }
}

fn finish(
    pairs: &[Correspondence],
    kind: AlignKind,
    r: DMat3,
    t: DVec3,
    s: f64,
    residuals: Vec<TargetResidual>,
    rejection: Rejection,
) -> Alignment {
    let n = pairs.len();
    let mut sse = 0.0;
    let mut jtj = SMatrix::<f64, 7, 7>::zeros();
    for p in pairs {
        let q = r * p.survey_m * s;
        sse += (p.scan_m - (q + t)).length_squared();
        // Rows of J for the three coordinates: [-[q]x | I | q].
        let qx = Matrix3::new(0.0, -q.z, q.y, q.z, 0.0, -q.x, -q.y, q.x, 0.0);
        for row in 0..3 {
            let mut j = SVector::<f64, 7>::zeros();
            for c in 0..3 {
                j[c] = -qx[(row, c)];
            }
            j[3 + row] = 1.0;
            j[6] = q[row];
            jtj += j * j.transpose();
        }
    }
    let k = match kind {
        AlignKind::Rigid => 6,
        AlignKind::Similarity => 7,
    };
    let dof = (3 * n).saturating_sub(k).max(1);
    let sigma2 = sse / dof as f64;
    let (rot_var, trans_var, scale_var, centroid_var) = {
        let cov = if k == 6 {
            let sub: SMatrix<f64, 6, 6> = jtj.fixed_view::<6, 6>(0, 0).into_owned();
            sub.try_inverse().map(|inv| {
                let mut full = SMatrix::<f64, 7, 7>::zeros();
                full.fixed_view_mut::<6, 6>(0, 0).copy_from(&inv);
                full
            })
        } else {
            jtj.try_inverse()
        };
        match cov {
            Some(c) => {
                let c = c * sigma2;
                let rot = c[(0, 0)] + c[(1, 1)] + c[(2, 2)];
                let tr = c[(3, 3)] + c[(4, 4)] + c[(5, 5)];
                // Error of the prediction at the centroid, whose rotated survey point is
                // m = mean(s R x_i): δt - [m]x δθ.
                let m = pairs.iter().map(|p| r * p.survey_m * s).sum::<DVec3>() / n as f64;
                let mut a = SMatrix::<f64, 3, 7>::zeros();
                let mx = Matrix3::new(0.0, -m.z, m.y, m.z, 0.0, -m.x, -m.y, m.x, 0.0);
                for row in 0..3 {
                    for col in 0..3 {
                        a[(row, col)] = -mx[(row, col)];
                    }
                    a[(row, 3 + row)] = 1.0;
                }
                let cm = a * c * a.transpose();
                (rot, tr, c[(6, 6)], cm.trace())
            }
            None => (f64::NAN, f64::NAN, f64::NAN, f64::NAN),
        }
    };
    Alignment {
        kind,
        scan_from_survey: Pose::new(DQuat::from_mat3(&r), t),
        scale: s,
        rms_mm: (sse / n.max(1) as f64).sqrt() * 1e3,
        residuals,
        dropped: rejection.dropped,
        threshold_mm: rejection.threshold_mm,
        robust_median_mm: rejection.robust_median_mm,
        unmatched: Vec::new(),
        points_used: n,
        rotation_sd_deg: rot_var.max(0.0).sqrt().to_degrees(),
        translation_sd_mm: trans_var.max(0.0).sqrt() * 1e3,
        centroid_sd_mm: centroid_var.max(0.0).sqrt() * 1e3,
        scale_sd: if k == 7 {
            scale_var.max(0.0).sqrt()
        } else {
            0.0
        },
    }
}

/// Correspondences of the corners of the targets both sets have (by id); the ids in only one
/// set are returned separately, sorted.
pub fn match_targets(
    survey: &[(u32, [DVec3; 4])],
    scan: &[(u32, [DVec3; 4])],
) -> (Vec<Correspondence>, Vec<u32>) {
    let mut pairs = Vec::new();
    let mut unmatched = Vec::new();
    for (id, xs) in survey {
        match scan.iter().find(|(j, _)| j == id) {
            Some((_, ys)) => {
                for k in 0..4 {
                    pairs.push(Correspondence {
                        id: *id,
                        corner: k as u8,
                        survey_m: xs[k],
                        scan_m: ys[k],
                    });
                }
            }
            None => unmatched.push(*id),
        }
    }
    unmatched.extend(
        scan.iter()
            .filter(|(id, _)| !survey.iter().any(|(j, _)| j == id))
            .map(|(id, _)| *id),
    );
    unmatched.sort_unstable();
    unmatched.dedup();
    (pairs, unmatched)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_pairs(pose: &Pose, scale: f64) -> Vec<Correspondence> {
        let mut v = Vec::new();
        for id in 0..6u32 {
            for k in 0..4u8 {
                let x = DVec3::new(
                    0.03 * f64::from(id) + 0.01 * f64::from(k % 2),
                    0.02 * f64::from(k / 2) + 0.005 * f64::from(id % 3),
                    0.004 * f64::from(id),
                );
                v.push(Correspondence {
                    id,
                    corner: k,
                    survey_m: x,
                    scan_m: pose.transform_point(x * scale),
                });
            }
        }
        v
    }

    #[test]
    fn exact_rigid_and_similarity_fits() {
        let pose =
            Pose::from_rotation_vector(DVec3::new(0.3, -0.7, 0.2), DVec3::new(0.1, 0.2, -0.3));
        let a = fit_correspondences(
            &grid_pairs(&pose, 1.0),
            AlignKind::Rigid,
            &AlignConfig::default(),
        )
        .expect("fit");
        assert!(a.scan_from_survey.angle_to_rad(&pose) < 1e-9);
        assert!(a.scan_from_survey.distance_to_m(&pose) < 1e-9);
        assert!(a.rms_mm < 1e-6 && a.dropped.is_empty());
        let b = fit_correspondences(
            &grid_pairs(&pose, 1.02),
            AlignKind::Similarity,
            &AlignConfig::default(),
        )
        .expect("fit");
        assert!((b.scale - 1.02).abs() < 1e-9, "{}", b.scale);
        assert!(b.scan_from_survey.distance_to_m(&pose) < 1e-9);
    }

    #[test]
    fn a_reflection_is_not_returned_and_collinear_points_are_refused() {
        let mut pairs = grid_pairs(&Pose::IDENTITY, 1.0);
        for p in &mut pairs {
            p.scan_m.x = -p.scan_m.x;
        }
        let (r, _, _) = umeyama(&pairs, AlignKind::Rigid).expect("fit");
        assert!(r.determinant() > 0.0);
        let line: Vec<Correspondence> = (0..5)
            .map(|i| Correspondence {
                id: i,
                corner: 0,
                survey_m: DVec3::X * f64::from(i) * 0.01,
                scan_m: DVec3::Y * f64::from(i) * 0.01,
            })
            .collect();
        let e = umeyama(&line, AlignKind::Rigid).expect_err("collinear");
        assert!(matches!(e, RegisterError::Degenerate { .. }), "{e}");
    }
}
