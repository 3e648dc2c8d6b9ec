//! The pinhole camera with Brown-Conrady lens distortion (OpenCV's model).
//!
//! A point `P = (X, Y, Z)` in the camera frame (x right, y down, z forward) projects to the
//! normalised image point `(x, y) = (X/Z, Y/Z)`, is distorted by
//!
//! ```text
//! r² = x² + y²
//! x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
//! y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y
//! ```
//!
//! and lands on pixel `(u, v) = (fx x_d + cx, fy y_d + cy)`.
//!
//! **Pixel convention:** integer coordinates are pixel *centres* (OpenCV's convention): the
//! pixel in column `c`, row `r` covers `[c - 0.5, c + 0.5) x [r - 0.5, r + 0.5)`.
//!
//! Undistortion inverts the polynomial with Newton's method on the 2x2 Jacobian, which converges
//! in a few iterations even for strong barrel distortion where OpenCV's fixed-point iteration
//! stalls. Points beyond the radius where the radial polynomial stops being monotonic (the lens
//! model "folds back") are rejected rather than silently mapped to a wrong ray.

use glam::{DVec2, DVec3};
use serde::{Deserialize, Serialize};

/// Errors of the camera model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// A parameter is out of range.
    #[error("camera parameter `{field}` is invalid: {reason}")]
    InvalidParameter {
        /// Parameter name.
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
}

/// Brown-Conrady distortion coefficients (OpenCV order k1, k2, p1, p2, k3).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct BrownConrady {
    /// Radial r² coefficient.
    pub k1: f64,
    /// Radial r⁴ coefficient.
    pub k2: f64,
    /// Radial r⁶ coefficient.
    pub k3: f64,
    /// Tangential coefficient p1.
    pub p1: f64,
    /// Tangential coefficient p2.
    pub p2: f64,
}

impl BrownConrady {
    /// No distortion.
    pub const NONE: Self = Self {
        k1: 0.0,
        k2: 0.0,
        k3: 0.0,
        p1: 0.0,
        p2: 0.0,
    };

    /// True when every coefficient is zero (projection can skip the polynomial).
    pub fn is_zero(&self) -> bool {
        *self == Self::NONE
    }

    /// Distorts a normalised image point.
    pub fn distort(&self, p: DVec2) -> DVec2 {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        DVec2::new(
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// Jacobian of [`Self::distort`] at `p`, as rows `[[dxd/dx, dxd/dy], [dyd/dx, dyd/dy]]`.
    pub fn jacobian(&self, p: DVec2) -> [[f64; 2]; 2] {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let dradial_dr2 = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
        let dxd_dx = radial + x * dradial_dr2 * 2.0 * x + 2.0 * self.p1 * y + self.p2 * 6.0 * x;
        let dxd_dy = x * dradial_dr2 * 2.0 * y + 2.0 * self.p1 * x + self.p2 * 2.0 * y;
        let dyd_dx = y * dradial_dr2 * 2.0 * x + self.p1 * 2.0 * x + 2.0 * self.p2 * y;
        let dyd_dy = radial + y * dradial_dr2 * 2.0 * y + self.p1 * 6.0 * y + 2.0 * self.p2 * x;
        [[dxd_dx, dxd_dy], [dyd_dx, dyd_dy]]
    }

    /// True when the radial map `r -> r (1 + k1 r² + k2 r⁴ + k3 r⁶)` is strictly increasing on
    /// `[0, sqrt(r2)]`, i.e. the lens model has not folded back before radius² `r2`.
    ///
    /// The derivative in `s = r²` is the cubic `g(s) = 1 + 3 k1 s + 5 k2 s² + 7 k3 s³` with
    /// `g(0) = 1`; its minimum over `[0, r2]` is at an end point or at a root of
    /// `g'(s) = 3 k1 + 10 k2 s + 21 k3 s²`, so the check is exact and O(1).
    pub fn radially_monotonic_to(&self, r2: f64) -> bool {
        if !r2.is_finite() || r2 < 0.0 {
            return false;
        }
        let g = |s: f64| 1.0 + s * (3.0 * self.k1 + s * (5.0 * self.k2 + s * 7.0 * self.k3));
        let (a, b, c) = (21.0 * self.k3, 10.0 * self.k2, 3.0 * self.k1);
        let mut candidates = [r2, f64::NAN, f64::NAN];
        if a.abs() > f64::EPSILON {
            let disc = b * b - 4.0 * a * c;
            if disc >= 0.0 {
                let q = disc.sqrt();
                candidates[1] = (-b + q) / (2.0 * a);
                candidates[2] = (-b - q) / (2.0 * a);
            }
        } else if b.abs() > f64::EPSILON {
            candidates[1] = -c / b;
        }
        candidates
            .iter()
            .filter(|s| s.is_finite() && **s >= 0.0 && **s <= r2)
            .all(|&s| g(s) > 0.0)
    }

    /// Inverts [`Self::distort`] by Newton's method. Returns `None` if it does not converge to
    /// `tol` (normalised units) or lands where the model is not invertible.
    pub fn undistort(&self, pd: DVec2) -> Option<DVec2> {
        if self.is_zero() {
            return Some(pd);
        }
        let mut p = pd;
        for _ in 0..50 {
            let r = self.distort(p) - pd;
            if r.length() < 1e-14 {
                return self.radially_monotonic_to(p.length_squared()).then_some(p);
            }
            let [[a, b], [c, d]] = self.jacobian(p);
            let det = a * d - b * c;
            if !det.is_finite() || det.abs() < 1e-12 {
                return None;
            }
            let step = DVec2::new(d * r.x - b * r.y, -c * r.x + a * r.y) / det;
            p -= step;
            if !p.is_finite() {
                return None;
            }
        }
        let r = self.distort(p) - pd;
        (r.length() < 1e-10 && self.radially_monotonic_to(p.length_squared())).then_some(p)
    }
}

/// A calibrated camera: image size, pinhole intrinsics and Brown-Conrady distortion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraModel {
    /// Image width in pixels.
    pub width_px: u32,
    /// Image height in pixels.
    pub height_px: u32,
    /// Focal length in pixels along x.
    pub fx_px: f64,
    /// Focal length in pixels along y.
    pub fy_px: f64,
    /// Principal point x (pixel-centre convention).
    pub cx_px: f64,
    /// Principal point y (pixel-centre convention).
    pub cy_px: f64,
    /// Lens distortion.
    #[serde(default)]
    pub distortion: BrownConrady,
}

impl CameraModel {
    /// A camera of the given size and horizontal field of view, principal point at the centre,
    /// no distortion.
    pub fn from_fov(width_px: u32, height_px: u32, hfov_rad: f64) -> Self {
        let f = 0.5 * width_px as f64 / (0.5 * hfov_rad).tan();
        Self {
            width_px,
            height_px,
            fx_px: f,
            fy_px: f,
            cx_px: (width_px as f64 - 1.0) * 0.5,
            cy_px: (height_px as f64 - 1.0) * 0.5,
            distortion: BrownConrady::NONE,
        }
    }

    /// Checks the invariants: positive size, positive finite focal lengths, finite centre and
    /// coefficients.
    pub fn validate(&self) -> Result<(), CameraError> {
        let bad = |field, reason: &str| {
            Err(CameraError::InvalidParameter {
                field,
                reason: reason.to_string(),
            })
        };
        if self.width_px == 0 || self.height_px == 0 {
            return bad("width_px/height_px", "image size must be positive");
        }
        for (field, v) in [("fx_px", self.fx_px), ("fy_px", self.fy_px)] {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, "focal length must be positive and finite");
            }
        }
        for (field, v) in [
            ("cx_px", self.cx_px),
            ("cy_px", self.cy_px),
            ("k1", self.distortion.k1),
            ("k2", self.distortion.k2),
            ("k3", self.distortion.k3),
            ("p1", self.distortion.p1),
            ("p2", self.distortion.p2),
        ] {
            if !v.is_finite() {
                return bad(field, "must be finite");
            }
        }
        Ok(())
    }

    /// Projects a camera-frame point to pixel coordinates. `None` for points at or behind the
    /// camera (z <= 1e-9 m) and for points beyond the radius where the lens model folds back
    /// (their "pixel" would be a mirror image, not where the lens puts them).
    pub fn project(&self, p_cam: DVec3) -> Option<DVec2> {
        if p_cam.z <= 1e-9 || !p_cam.is_finite() {
            return None;
        }
        let n = DVec2::new(p_cam.x / p_cam.z, p_cam.y / p_cam.z);
        if !self.distortion.radially_monotonic_to(n.length_squared()) {
            return None;
        }
        Some(self.normalized_to_pixel(self.distortion.distort(n)))
    }

    /// Maps a distorted normalised point to pixels.
    pub fn normalized_to_pixel(&self, nd: DVec2) -> DVec2 {
        DVec2::new(
            self.fx_px * nd.x + self.cx_px,
            self.fy_px * nd.y + self.cy_px,
        )
    }

    /// Maps pixels to the distorted normalised point.
    pub fn pixel_to_normalized(&self, px: DVec2) -> DVec2 {
        DVec2::new(
            (px.x - self.cx_px) / self.fx_px,
            (px.y - self.cy_px) / self.fy_px,
        )
    }

    /// The undistorted normalised image point `(X/Z, Y/Z)` seen at a pixel.
    pub fn undistort_pixel(&self, px: DVec2) -> Option<DVec2> {
        self.distortion.undistort(self.pixel_to_normalized(px))
    }

    /// Unit ray direction in the camera frame through a pixel (inverse of [`Self::project`]).
    pub fn pixel_ray(&self, px: DVec2) -> Option<DVec3> {
        let n = self.undistort_pixel(px)?;
        Some(DVec3::new(n.x, n.y, 1.0).normalize())
    }

    /// True when the pixel coordinate lies inside the image (pixel-centre convention).
    pub fn contains(&self, px: DVec2) -> bool {
        px.x >= -0.5
            && px.y >= -0.5
            && px.x < self.width_px as f64 - 0.5
            && px.y < self.height_px as f64 - 0.5
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn strong() -> CameraModel {
        let mut c = CameraModel::from_fov(1524, 1012, 50f64.to_radians());
        c.distortion = BrownConrady {
            k1: -0.25,
            k2: 0.08,
            k3: -0.01,
            p1: 0.001,
            p2: -0.0005,
        };
        c
    }

    proptest! {
        #[test]
        fn pixel_ray_inverts_project(x in -0.4..0.4f64, y in -0.3..0.3f64) {
            let cam = strong();
            let p = DVec3::new(x, y, 1.0) * 2.0;
            let px = cam.project(p).unwrap();
            let ray = cam.pixel_ray(px).unwrap();
            prop_assert!((ray - p.normalize()).length() < 1e-9);
        }
    }

    #[test]
    fn distortion_jacobian_matches_finite_differences() {
        let d = strong().distortion;
        let p = DVec2::new(0.21, -0.13);
        let j = d.jacobian(p);
        let h = 1e-7;
        for (col, dp) in [DVec2::new(h, 0.0), DVec2::new(0.0, h)].iter().enumerate() {
            let fd = (d.distort(p + *dp) - d.distort(p - *dp)) / (2.0 * h);
            assert!((fd.x - j[0][col]).abs() < 1e-6);
            assert!((fd.y - j[1][col]).abs() < 1e-6);
        }
    }

    #[test]
    fn the_fold_is_rejected_both_ways() {
        let mut cam = strong();
        cam.distortion = BrownConrady {
            k1: -0.35,
            ..BrownConrady::NONE
        };
        // Fold at r* = 1/sqrt(1.05) = 0.976.
        assert!(cam.distortion.radially_monotonic_to(0.97 * 0.97));
        assert!(!cam.distortion.radially_monotonic_to(0.98 * 0.98));
        assert!(cam.project(DVec3::new(1.4, 0.0, 1.0)).is_none());
        assert!(cam.project(DVec3::new(0.9, 0.0, 1.0)).is_some());
        // k2 > 0 makes the derivative positive again beyond r = 2: still folded.
        cam.distortion.k2 = 0.04;
        assert!(!cam.distortion.radially_monotonic_to(2.5 * 2.5));
        // A corner pixel whose only inverse is beyond the fold has no ray.
        cam.distortion = BrownConrady {
            k1: -0.35,
            ..BrownConrady::NONE
        };
        if let Some(ray) = cam.pixel_ray(DVec2::new(0.0, 0.0)) {
            let n = DVec2::new(ray.x / ray.z, ray.y / ray.z);
            assert!(cam.distortion.radially_monotonic_to(n.length_squared()));
        }
    }

    #[test]
    fn behind_the_camera_does_not_project() {
        assert!(strong().project(DVec3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn validate_rejects_bad_focal_length() {
        let mut c = strong();
        c.fx_px = f64::NAN;
        assert!(matches!(
            c.validate(),
            Err(CameraError::InvalidParameter { field: "fx_px", .. })
        ));
    }
}
