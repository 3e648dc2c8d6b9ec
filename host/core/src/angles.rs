//! BRDF angle conventions for isotropic reflectance.
//!
//! In the local shading frame (+z = surface normal) the incident direction `w_i` (towards the
//! light) and the exitant direction `w_e` (towards the camera) are unit vectors pointing away
//! from the surface. For an isotropic BRDF only three angles matter:
//!
//! * `theta_i_rad`, `theta_e_rad`: polar angles of `w_i`, `w_e` from the normal, in `[0, pi/2]`;
//! * `phi_d_rad`: the azimuth of `w_e` relative to `w_i`, folded into `[0, pi]`. `phi_d = 0`
//!   puts the camera on the light's side (retro-reflection), `phi_d = pi` on the mirror side
//!   (forward scattering). The **incidence plane** is `phi_d ∈ {0, pi}`.
//!
//! The half/difference parametrisation of Rusinkiewicz (1998), used by the MERL tables, is also
//! provided: `h = normalize(w_i + w_e)`, `theta_h` its polar angle, and `(theta_d, phi_diff)` the
//! polar and azimuthal angles of `w_i` in the frame where `h` is the pole.
//!
//! Canonical directions: [`BrdfAngles::canonical_directions`] puts `w_i` in the xz-plane at
//! azimuth 0, so any BRDF model can be evaluated from the three angles alone.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// An orthonormal frame whose +z is a surface normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadingFrame {
    /// Tangent (local x).
    pub t: DVec3,
    /// Bitangent (local y).
    pub b: DVec3,
    /// Normal (local z).
    pub n: DVec3,
}

impl ShadingFrame {
    /// Builds a frame around a unit normal without a branch-induced discontinuity worth worrying
    /// about (Duff et al., "Building an Orthonormal Basis, Revisited", JCGT 2017).
    pub fn from_normal(n: DVec3) -> Self {
        let sign = 1.0f64.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let t = DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let bt = DVec3::new(b, sign + n.y * n.y * a, -n.y);
        Self { t, b: bt, n }
    }

    /// World direction to local coordinates.
    pub fn to_local(&self, v: DVec3) -> DVec3 {
        DVec3::new(v.dot(self.t), v.dot(self.b), v.dot(self.n))
    }

    /// Local direction to world coordinates.
    pub fn to_world(&self, v: DVec3) -> DVec3 {
        self.t * v.x + self.b * v.y + self.n * v.z
    }
}

/// The angles of one (w_i, w_e) pair, in both parametrisations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BrdfAngles {
    /// Incident polar angle.
    pub theta_i_rad: f64,
    /// Exitant polar angle.
    pub theta_e_rad: f64,
    /// Relative azimuth folded into `[0, pi]`; 0 = retro side, pi = mirror side.
    pub phi_d_rad: f64,
    /// Half-vector polar angle.
    pub theta_h_rad: f64,
    /// Difference polar angle.
    pub theta_diff_rad: f64,
    /// Difference azimuth folded into `[0, pi]` (reciprocity and isotropy).
    pub phi_diff_rad: f64,
}

/// Polar angle of a unit vector from +z. `atan2` keeps full precision near 0 and pi/2, where
/// `acos(z)` loses half the significant digits (near-mirror lobes live exactly there).
fn polar(v: DVec3) -> f64 {
    (v.x * v.x + v.y * v.y).sqrt().atan2(v.z)
}

impl BrdfAngles {
    /// Angles of two local unit directions (both should have z >= 0).
    pub fn from_local(wi: DVec3, we: DVec3) -> Self {
        let theta_i = polar(wi);
        let theta_e = polar(we);
        // Azimuth difference; undefined (set to 0) when either direction is the normal.
        let pi_xy = (wi.x * wi.x + wi.y * wi.y).sqrt();
        let pe_xy = (we.x * we.x + we.y * we.y).sqrt();
        let phi_d = if pi_xy < 1e-12 || pe_xy < 1e-12 {
            0.0
        } else {
            let c = wi.x * we.x + wi.y * we.y;
            let s = wi.x * we.y - wi.y * we.x;
            s.abs().atan2(c)
        };
        let h = (wi + we).try_normalize().unwrap_or(DVec3::Z);
        let theta_h = polar(h);
        let phi_h = h.y.atan2(h.x);
        // Rotate wi by -phi_h about z, then by -theta_h about y.
        let (s, c) = (-phi_h).sin_cos();
        let d1 = DVec3::new(c * wi.x - s * wi.y, s * wi.x + c * wi.y, wi.z);
        let (s, c) = (-theta_h).sin_cos();
        let d = DVec3::new(c * d1.x + s * d1.z, d1.y, -s * d1.x + c * d1.z);
        let theta_d = polar(d);
        let mut phi_diff = d.y.atan2(d.x);
        if phi_diff < 0.0 {
            phi_diff += std::f64::consts::PI;
        }
        if phi_diff >= std::f64::consts::PI {
            phi_diff -= std::f64::consts::PI;
        }
        Self {
            theta_i_rad: theta_i,
            theta_e_rad: theta_e,
            phi_d_rad: phi_d,
            theta_h_rad: theta_h,
            theta_diff_rad: theta_d,
            phi_diff_rad: phi_diff,
        }
    }

    /// Angles of two world directions at a surface with the given unit normal.
    pub fn from_world(normal: DVec3, wi: DVec3, we: DVec3) -> Self {
        let f = ShadingFrame::from_normal(normal);
        Self::from_local(f.to_local(wi), f.to_local(we))
    }

    /// Local directions with `w_i` at azimuth 0 (the canonical pair for isotropic evaluation).
    pub fn canonical_directions(
        theta_i_rad: f64,
        theta_e_rad: f64,
        phi_d_rad: f64,
    ) -> (DVec3, DVec3) {
        let (si, ci) = theta_i_rad.sin_cos();
        let (se, ce) = theta_e_rad.sin_cos();
        let (sp, cp) = phi_d_rad.sin_cos();
        (DVec3::new(si, 0.0, ci), DVec3::new(se * cp, se * sp, ce))
    }

    /// Signed exitant angle in the incidence plane: negative on the light's (retro) side,
    /// positive on the mirror side, as in the method's polar plots.
    pub fn signed_theta_e_rad(&self) -> f64 {
        if self.phi_d_rad > std::f64::consts::FRAC_PI_2 {
            self.theta_e_rad
        } else {
            -self.theta_e_rad
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::PI;

    proptest! {
        #[test]
        fn canonical_directions_round_trip(ti in 0.01..1.55f64, te in 0.01..1.55f64, pd in 0.0..PI) {
            let (wi, we) = BrdfAngles::canonical_directions(ti, te, pd);
            let a = BrdfAngles::from_local(wi, we);
            prop_assert!((a.theta_i_rad - ti).abs() < 1e-9);
            prop_assert!((a.theta_e_rad - te).abs() < 1e-9);
            prop_assert!((a.phi_d_rad - pd).abs() < 1e-7);
        }

        #[test]
        fn frame_is_orthonormal(x in -1.0..1.0f64, y in -1.0..1.0f64, z in -1.0..1.0f64) {
            let n = DVec3::new(x, y, z);
            prop_assume!(n.length() > 1e-3);
            let f = ShadingFrame::from_normal(n.normalize());
            prop_assert!(f.t.dot(f.b).abs() < 1e-12);
            prop_assert!(f.t.dot(f.n).abs() < 1e-12);
            prop_assert!((f.t.cross(f.b) - f.n).length() < 1e-12);
        }

        #[test]
        fn half_difference_is_reciprocal(ti in 0.01..1.5f64, te in 0.01..1.5f64, pd in 0.0..PI) {
            let (wi, we) = BrdfAngles::canonical_directions(ti, te, pd);
            let a = BrdfAngles::from_local(wi, we);
            let b = BrdfAngles::from_local(we, wi);
            prop_assert!((a.theta_h_rad - b.theta_h_rad).abs() < 1e-9);
            prop_assert!((a.theta_diff_rad - b.theta_diff_rad).abs() < 1e-9);
        }
    }

    #[test]
    fn mirror_direction_has_zero_half_angle() {
        let (wi, we) = BrdfAngles::canonical_directions(0.6, 0.6, PI);
        let a = BrdfAngles::from_local(wi, we);
        assert!(a.theta_h_rad.abs() < 1e-9);
        assert!((a.theta_diff_rad - 0.6).abs() < 1e-9);
        assert!(a.signed_theta_e_rad() > 0.0);
    }
}
