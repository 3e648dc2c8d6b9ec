//! Per-sample geometry, precomputed once so that fitting loops evaluate models from a handful of
//! dot products.

use glam::DVec3;

/// The dot products every isotropic model here needs, for one `(w_i, w_e)` pair in the local
/// shading frame (+z = normal).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Geom {
    /// `cos theta_i = w_i . n`.
    pub cos_i: f64,
    /// `cos theta_e = w_e . n`.
    pub cos_e: f64,
    /// Tangential part of `w_i . w_e`: `u_x v_x + u_y v_y = sin ti sin te cos phi_d`
    /// (negative on the mirror side).
    pub dxy: f64,
    /// Normal part of `w_i . w_e`: `u_z v_z`.
    pub dz: f64,
    /// `cos theta_h = h . n`, `h = normalize(w_i + w_e)`.
    pub cos_h: f64,
    /// `cos theta_d = w_i . h`.
    pub cos_d: f64,
}

impl Geom {
    /// Geometry of two local unit directions.
    pub fn from_dirs(wi: DVec3, we: DVec3) -> Self {
        let dxy = wi.x * we.x + wi.y * we.y;
        let dz = wi.z * we.z;
        let dot = dxy + dz;
        let len = (2.0 + 2.0 * dot).max(0.0).sqrt();
        let (cos_h, cos_d) = if len < 1e-12 {
            (1.0, 0.0)
        } else {
            ((wi.z + we.z) / len, (1.0 + dot) / len)
        };
        Self {
            cos_i: wi.z,
            cos_e: we.z,
            dxy,
            dz,
            cos_h,
            cos_d,
        }
    }

    /// Geometry from the isotropic angles (see [`skinbrdf_core::angles`]).
    pub fn from_angles(theta_i_rad: f64, theta_e_rad: f64, phi_d_rad: f64) -> Self {
        let (wi, we) =
            skinbrdf_core::BrdfAngles::canonical_directions(theta_i_rad, theta_e_rad, phi_d_rad);
        Self::from_dirs(wi, we)
    }

    /// True when both directions are above the surface.
    pub fn is_above(&self) -> bool {
        self.cos_i > 0.0 && self.cos_e > 0.0
    }
}
