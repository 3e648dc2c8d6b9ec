//! Rigid transforms.
//!
//! A [`Pose`] is a rotation followed by a translation, `p' = R p + t`, stored as a unit
//! quaternion and a translation in metres. Name poses `a_from_b`: it maps points in frame `b`
//! into frame `a`, so composition reads right to left: `a_from_c = a_from_b * b_from_c`.

use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// A rigid transform `p' = rotation * p + translation_m`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Unit quaternion.
    pub rotation: DQuat,
    /// Translation in metres.
    pub translation_m: DVec3,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Self = Self {
        rotation: DQuat::IDENTITY,
        translation_m: DVec3::ZERO,
    };

    /// Builds a pose from a rotation and a translation; the quaternion is normalised.
    pub fn new(rotation: DQuat, translation_m: DVec3) -> Self {
        Self {
            rotation: rotation.normalize(),
            translation_m,
        }
    }

    /// Builds a pose from a rotation vector (axis * angle, radians) and a translation.
    pub fn from_rotation_vector(rotvec_rad: DVec3, translation_m: DVec3) -> Self {
        let angle = rotvec_rad.length();
        let rotation = if angle < 1e-12 {
            // First-order expansion keeps tiny rotations exact to rounding.
            DQuat::from_xyzw(
                rotvec_rad.x * 0.5,
                rotvec_rad.y * 0.5,
                rotvec_rad.z * 0.5,
                1.0,
            )
            .normalize()
        } else {
            DQuat::from_axis_angle(rotvec_rad / angle, angle)
        };
        Self::new(rotation, translation_m)
    }

    /// The rotation as a rotation vector (axis * angle, radians, angle in `[0, pi]`).
    pub fn rotation_vector(&self) -> DVec3 {
        let q = if self.rotation.w < 0.0 {
            -self.rotation
        } else {
            self.rotation
        };
        let s = DVec3::new(q.x, q.y, q.z);
        let sin_half = s.length();
        if sin_half < 1e-12 {
            return s * 2.0;
        }
        let angle = 2.0 * sin_half.atan2(q.w);
        s * (angle / sin_half)
    }

    /// A camera pose `world_from_camera` for a camera at `eye_m` looking at `target_m`, with the
    /// image's "up" (−y in OpenCV camera coordinates) as close to `up` as possible.
    /// Returns `None` when the viewing direction is parallel to `up` or `eye == target`.
    pub fn look_at(eye_m: DVec3, target_m: DVec3, up: DVec3) -> Option<Self> {
        let z = (target_m - eye_m).try_normalize()?;
        let x = z.cross(up).try_normalize()?; // right
        let y = z.cross(x); // down
        let m = DMat3::from_cols(x, y, z);
        Some(Self::new(DQuat::from_mat3(&m), eye_m))
    }

    /// The rotation matrix.
    pub fn rotation_matrix(&self) -> DMat3 {
        DMat3::from_quat(self.rotation)
    }

    /// Applies the transform to a point.
    pub fn transform_point(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation_m
    }

    /// Applies only the rotation (for directions and normals).
    pub fn transform_vector(&self, v: DVec3) -> DVec3 {
        self.rotation * v
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Self {
        let r = self.rotation.inverse();
        Self {
            rotation: r,
            translation_m: -(r * self.translation_m),
        }
    }

    /// Rotation angle between two poses' rotations, radians.
    pub fn angle_to_rad(&self, other: &Self) -> f64 {
        self.rotation.angle_between(other.rotation)
    }

    /// Distance between two poses' translations, metres.
    pub fn distance_to_m(&self, other: &Self) -> f64 {
        self.translation_m.distance(other.translation_m)
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.rotation.is_finite() && self.translation_m.is_finite()
    }
}

impl core::ops::Mul for Pose {
    type Output = Pose;
    fn mul(self, rhs: Pose) -> Pose {
        Pose::new(
            self.rotation * rhs.rotation,
            self.rotation * rhs.translation_m + self.translation_m,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn vec3() -> impl Strategy<Value = DVec3> {
        (-2.0..2.0f64, -2.0..2.0f64, -2.0..2.0f64).prop_map(|(x, y, z)| DVec3::new(x, y, z))
    }

    proptest! {
        #[test]
        fn inverse_round_trips(r in vec3(), t in vec3(), p in vec3()) {
            let pose = Pose::from_rotation_vector(r, t);
            let back = pose.inverse().transform_point(pose.transform_point(p));
            prop_assert!((back - p).length() < 1e-12);
        }

        #[test]
        fn rotation_vector_round_trips(r in vec3()) {
            prop_assume!(r.length() < std::f64::consts::PI - 1e-6);
            let pose = Pose::from_rotation_vector(r, DVec3::ZERO);
            prop_assert!((pose.rotation_vector() - r).length() < 1e-9);
        }

        #[test]
        fn composition_is_application_order(r1 in vec3(), t1 in vec3(), r2 in vec3(), t2 in vec3(), p in vec3()) {
            let a = Pose::from_rotation_vector(r1, t1);
            let b = Pose::from_rotation_vector(r2, t2);
            let lhs = (a * b).transform_point(p);
            let rhs = a.transform_point(b.transform_point(p));
            prop_assert!((lhs - rhs).length() < 1e-12);
        }
    }

    #[test]
    fn look_at_points_the_optical_axis_at_the_target() {
        let eye = DVec3::new(2.0, 0.0, 1.5);
        let target = DVec3::new(0.0, 0.0, 1.6);
        let pose = Pose::look_at(eye, target, DVec3::Z).unwrap();
        let axis = pose.transform_vector(DVec3::Z);
        assert!((axis - (target - eye).normalize()).length() < 1e-12);
        // Image "down" (+y) points roughly to world -z.
        assert!(pose.transform_vector(DVec3::Y).z < -0.9);
        assert!(Pose::look_at(eye, eye, DVec3::Z).is_none());
    }
}
