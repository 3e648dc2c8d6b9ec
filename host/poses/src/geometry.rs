//! Closed-form initialisations: homographies (DLT with Hartley normalisation), pose from a plane
//! homography, the 6-point DLT for non-planar points, nearest rotation, and plane fitting.

use glam::{DMat3, DQuat, DVec2, DVec3};
use nalgebra::{DMatrix, Matrix3, SVD};
use skinbrdf_core::Pose;

/// Nearest rotation (Frobenius) to a 3x3 matrix, via SVD with the determinant fixed to +1.
pub fn nearest_rotation(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let svd = SVD::new(*m, true, true);
    let u = svd.u?;
    let vt = svd.v_t?;
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        let mut u2 = u;
        for i in 0..3 {
            u2[(i, 2)] = -u2[(i, 2)];
        }
        r = u2 * vt;
    }
    Some(r)
}

/// Converts a nalgebra rotation matrix to a glam quaternion.
pub fn quat_from_na(r: &Matrix3<f64>) -> DQuat {
    let m = DMat3::from_cols(
        DVec3::new(r[(0, 0)], r[(1, 0)], r[(2, 0)]),
        DVec3::new(r[(0, 1)], r[(1, 1)], r[(2, 1)]),
        DVec3::new(r[(0, 2)], r[(1, 2)], r[(2, 2)]),
    );
    DQuat::from_mat3(&m).normalize()
}

fn normalise2(pts: &[DVec2]) -> (Vec<DVec2>, Matrix3<f64>) {
    let n = pts.len() as f64;
    let c = pts.iter().copied().sum::<DVec2>() / n;
    let d = pts.iter().map(|p| p.distance(c)).sum::<f64>() / n;
    let s = if d > 1e-15 {
        std::f64::consts::SQRT_2 / d
    } else {
        1.0
    };
    let t = Matrix3::new(s, 0.0, -s * c.x, 0.0, s, -s * c.y, 0.0, 0.0, 1.0);
    (pts.iter().map(|p| (*p - c) * s).collect(), t)
}

/// Homography `H` with `dst ~ H src` from at least 4 correspondences (normalised DLT).
pub fn homography(src: &[DVec2], dst: &[DVec2]) -> Option<Matrix3<f64>> {
    if src.len() < 4 || src.len() != dst.len() {
        return None;
    }
    let (s, ts) = normalise2(src);
    let (d, td) = normalise2(dst);
    let n = s.len();
    let mut a = DMatrix::zeros(2 * n.max(5), 9);
    for i in 0..n {
        let (x, y) = (s[i].x, s[i].y);
        let (u, v) = (d[i].x, d[i].y);
        let r0 = [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u];
        let r1 = [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v];
        for k in 0..9 {
            a[(2 * i, k)] = r0[k];
            a[(2 * i + 1, k)] = r1[k];
        }
    }
    // Rows beyond 2n (when n = 4) stay zero so the SVD has a full V.
    let svd = SVD::new(a, false, true);
    let vt = svd.v_t?;
    let (imin, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let h = vt.row(imin);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let full = td.try_inverse()? * hn * ts;
    Some(full)
}

/// A plane fitted to points: `world_from_plane` (origin at the centroid, z the normal) and the
/// singular values of the centred points (descending), which measure planarity/collinearity.
pub fn fit_plane(pts: &[DVec3]) -> Option<(Pose, [f64; 3])> {
    if pts.len() < 3 {
        return None;
    }
    let n = pts.len() as f64;
    let c = pts.iter().copied().sum::<DVec3>() / n;
    let mut m = DMatrix::zeros(pts.len(), 3);
    for (i, p) in pts.iter().enumerate() {
        let d = *p - c;
        m[(i, 0)] = d.x;
        m[(i, 1)] = d.y;
        m[(i, 2)] = d.z;
    }
    let svd = SVD::new(m, false, true);
    let vt = svd.v_t?;
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let axis = |k: usize| DVec3::new(vt[(idx[k], 0)], vt[(idx[k], 1)], vt[(idx[k], 2)]);
    let x = axis(0).normalize();
    let mut z = axis(2).normalize();
    if x.cross(axis(1)).dot(z) < 0.0 {
        z = -z;
    }
    let y = z.cross(x);
    let rot = DQuat::from_mat3(&DMat3::from_cols(x, y, z));
    let sv = [
        svd.singular_values[idx[0]],
        svd.singular_values[idx[1]],
        svd.singular_values[idx[2]],
    ];
    Some((Pose::new(rot, c), sv))
}

/// `camera_from_plane` from a homography mapping plane `(X, Y)` to undistorted normalised image
/// points. The sign is chosen so the plane is in front of the camera.
pub fn pose_from_plane_homography(h: &Matrix3<f64>) -> Option<Pose> {
    let h1 = h.column(0).into_owned();
    let h2 = h.column(1).into_owned();
    let h3 = h.column(2).into_owned();
    let norm = 0.5 * (h1.norm() + h2.norm());
    if norm < 1e-15 {
        return None;
    }
    let mut lam = 1.0 / norm;
    if h3[2] * lam < 0.0 {
        lam = -lam;
    }
    let r1 = h1 * lam;
    let r2 = h2 * lam;
    let r3 = r1.cross(&r2);
    let m = Matrix3::from_columns(&[r1, r2, r3]);
    let r = nearest_rotation(&m)?;
    let t = h3 * lam;
    Some(Pose::new(quat_from_na(&r), DVec3::new(t[0], t[1], t[2])))
}

/// `camera_from_world` by the direct linear transform from at least 6 non-coplanar points and
/// their undistorted normalised image points.
pub fn dlt_pose(obj: &[DVec3], norm: &[DVec2]) -> Option<Pose> {
    let n = obj.len();
    if n < 6 || norm.len() != n {
        return None;
    }
    // Normalise the object points (centroid, unit mean distance).
    let c = obj.iter().copied().sum::<DVec3>() / n as f64;
    let s = obj.iter().map(|p| p.distance(c)).sum::<f64>() / n as f64;
    if s < 1e-12 {
        return None;
    }
    let mut a = DMatrix::zeros(2 * n, 12);
    for i in 0..n {
        let p = (obj[i] - c) / s;
        let (u, v) = (norm[i].x, norm[i].y);
        let x = [p.x, p.y, p.z, 1.0];
        for k in 0..4 {
            a[(2 * i, k)] = x[k];
            a[(2 * i, 8 + k)] = -u * x[k];
            a[(2 * i + 1, 4 + k)] = x[k];
            a[(2 * i + 1, 8 + k)] = -v * x[k];
        }
    }
    let svd = SVD::new(a, false, true);
    let vt = svd.v_t?;
    let (imin, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let p = vt.row(imin);
    let m = Matrix3::new(p[0], p[1], p[2], p[4], p[5], p[6], p[8], p[9], p[10]);
    let t = nalgebra::Vector3::new(p[3], p[7], p[11]);
    let sv = SVD::new(m, false, false).singular_values;
    let mut scale = (sv[0] + sv[1] + sv[2]) / 3.0;
    if scale < 1e-15 {
        return None;
    }
    // Points must be in front: the centroid (normalised origin) has depth t_z.
    if t[2] < 0.0 {
        scale = -scale;
    }
    let r = nearest_rotation(&(m / scale))?;
    let t = t / scale;
    // Undo the normalisation: P_norm = (P - c)/s, so t_real = s t - R c.
    let q = quat_from_na(&r);
    let tr = DVec3::new(t[0], t[1], t[2]) * s - q * c;
    Some(Pose::new(q, tr))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homography_pose_recovers_a_plane_pose() {
        let cam_from_plane =
            Pose::from_rotation_vector(DVec3::new(0.3, -0.2, 0.1), DVec3::new(0.05, -0.02, 0.8));
        let plane: Vec<DVec2> = [
            (-0.1, -0.1),
            (0.1, -0.1),
            (0.1, 0.1),
            (-0.1, 0.1),
            (0.03, 0.07),
        ]
        .iter()
        .map(|&(x, y)| DVec2::new(x, y))
        .collect();
        let img: Vec<DVec2> = plane
            .iter()
            .map(|p| {
                let c = cam_from_plane.transform_point(DVec3::new(p.x, p.y, 0.0));
                DVec2::new(c.x / c.z, c.y / c.z)
            })
            .collect();
        let h = homography(&plane, &img).expect("homography");
        let pose = pose_from_plane_homography(&h).expect("pose");
        assert!(pose.distance_to_m(&cam_from_plane) < 1e-9);
        assert!(pose.angle_to_rad(&cam_from_plane) < 1e-9);
    }

    #[test]
    fn dlt_recovers_a_pose_from_nonplanar_points() {
        let cam_from_world =
            Pose::from_rotation_vector(DVec3::new(-0.4, 0.9, 0.2), DVec3::new(0.1, 0.2, 1.5));
        let obj: Vec<DVec3> = (0..10)
            .map(|i| {
                let f = i as f64;
                DVec3::new(
                    (f * 0.7).sin() * 0.3,
                    (f * 1.3).cos() * 0.2,
                    (f * 0.37).sin() * 0.25,
                )
            })
            .collect();
        let img: Vec<DVec2> = obj
            .iter()
            .map(|p| {
                let c = cam_from_world.transform_point(*p);
                DVec2::new(c.x / c.z, c.y / c.z)
            })
            .collect();
        let pose = dlt_pose(&obj, &img).expect("pose");
        assert!(pose.distance_to_m(&cam_from_world) < 1e-8, "{pose:?}");
        assert!(pose.angle_to_rad(&cam_from_world) < 1e-8);
    }
}
