//! One BRDF sample, as derendering produces it and fitting consumes it, and the point of the
//! scan it was measured at ([`SurfacePoint`]).

use serde::{Deserialize, Serialize};

use crate::BrdfAngles;

/// Where on the scan a sample was measured: the triangle the pixel's ray hit, the hit's
/// barycentric coordinates, and the scan's texture coordinates there (when it has them).
///
/// 20 bytes: a `u32` triangle index and four `f32`. The point is
/// `p = (1 − b1 − b2)·v0 + b1·v1 + b2·v2` with `[b1, b2] = barycentric` and `v0, v1, v2` the
/// triangle's corners in the order of the scan's (loaded and repaired) mesh; the texture
/// coordinate interpolates the corners' the same way (OBJ convention: `v = 0` at the bottom of
/// the image). A sample from elsewhere (a gonioreflectometer, a model, a version-1 sample file)
/// has no surface point: [`SurfacePoint::NONE`], triangle [`SurfacePoint::NO_TRIANGLE`] and NaN
/// coordinates. A point on a scan without texture coordinates has NaN `uv`.
///
/// Equality treats a NaN coordinate as equal to a NaN coordinate (an absent value equals an
/// absent value), so samples without a surface point compare equal to themselves.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct SurfacePoint {
    /// Index of the triangle in the scan's mesh ([`SurfacePoint::NO_TRIANGLE`] = no point).
    pub triangle: u32,
    /// Barycentric weights of the triangle's second and third corner (the first has
    /// `1 − b1 − b2`); NaN when there is no point.
    pub barycentric: [f32; 2],
    /// Texture coordinates `(u, v)` of the point on the scan; NaN when the scan (or this
    /// triangle) has none.
    pub uv: [f32; 2],
}

impl SurfacePoint {
    /// The triangle index that means "no surface point".
    pub const NO_TRIANGLE: u32 = u32::MAX;

    /// No surface point.
    pub const NONE: Self = Self {
        triangle: Self::NO_TRIANGLE,
        barycentric: [f32::NAN; 2],
        uv: [f32::NAN; 2],
    };

    /// A point on triangle `triangle` at barycentrics `barycentric`, without texture
    /// coordinates.
    pub fn on_triangle(triangle: u32, barycentric: [f32; 2]) -> Self {
        Self {
            triangle,
            barycentric,
            uv: [f32::NAN; 2],
        }
    }

    /// True when the sample knows its triangle.
    pub fn is_known(&self) -> bool {
        self.triangle != Self::NO_TRIANGLE
    }

    /// The texture coordinates, when the point has them.
    pub fn texture_uv(&self) -> Option<[f32; 2]> {
        (self.is_known() && self.uv.iter().all(|c| c.is_finite())).then_some(self.uv)
    }

    /// The barycentric weights of the triangle's three corners, when the point is known.
    pub fn weights(&self) -> Option<[f32; 3]> {
        let [b1, b2] = self.barycentric;
        self.is_known().then_some([1.0 - b1 - b2, b1, b2])
    }
}

impl Default for SurfacePoint {
    fn default() -> Self {
        Self::NONE
    }
}

impl PartialEq for SurfacePoint {
    fn eq(&self, other: &Self) -> bool {
        let same = |a: f32, b: f32| a == b || (a.is_nan() && b.is_nan());
        self.triangle == other.triangle
            && self
                .barycentric
                .iter()
                .chain(&self.uv)
                .zip(other.barycentric.iter().chain(&other.uv))
                .all(|(&a, &b)| same(a, b))
    }
}

/// A BRDF sample: the angles of one (light, camera) pair at one surface point and the measured
/// reflectance per RGB channel (1/sr). Compact (f32) because sessions hold millions.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct BrdfSample {
    /// Incident polar angle.
    pub theta_i_rad: f32,
    /// Exitant polar angle.
    pub theta_e_rad: f32,
    /// Relative azimuth in `[0, pi]` (0 = retro side, pi = mirror side).
    pub phi_d_rad: f32,
    /// Half-vector polar angle (Rusinkiewicz).
    pub theta_h_rad: f32,
    /// Difference polar angle (Rusinkiewicz).
    pub theta_diff_rad: f32,
    /// Difference azimuth in `[0, pi]` (Rusinkiewicz).
    pub phi_diff_rad: f32,
    /// Reflectance per channel, 1/sr; NaN in a channel the sample did not measure (a
    /// *partial* sample: a camera raw photosite measures its own filter's channel only).
    pub rho: [f32; 3],
    /// Index of the source image in the session (u16::MAX for samples from elsewhere).
    pub image_index: u16,
    /// Source pixel (column, row).
    pub pixel: [u16; 2],
    /// Relative weight (1 for an ordinary sample; fitting multiplies residuals by it).
    pub weight: f32,
    /// The point of the scan the sample was measured at ([`SurfacePoint::NONE`] for samples
    /// from elsewhere).
    #[serde(default)]
    pub surface: SurfacePoint,
}

impl BrdfSample {
    /// A sample from angles and a value, with no image provenance, no surface point and unit
    /// weight.
    pub fn from_angles(angles: &BrdfAngles, rho: [f32; 3]) -> Self {
        Self {
            theta_i_rad: angles.theta_i_rad as f32,
            theta_e_rad: angles.theta_e_rad as f32,
            phi_d_rad: angles.phi_d_rad as f32,
            theta_h_rad: angles.theta_h_rad as f32,
            theta_diff_rad: angles.theta_diff_rad as f32,
            phi_diff_rad: angles.phi_diff_rad as f32,
            rho,
            image_index: u16::MAX,
            pixel: [0, 0],
            weight: 1.0,
            surface: SurfacePoint::NONE,
        }
    }

    /// The sample's angles in f64.
    pub fn angles(&self) -> BrdfAngles {
        BrdfAngles {
            theta_i_rad: self.theta_i_rad as f64,
            theta_e_rad: self.theta_e_rad as f64,
            phi_d_rad: self.phi_d_rad as f64,
            theta_h_rad: self.theta_h_rad as f64,
            theta_diff_rad: self.theta_diff_rad as f64,
            phi_diff_rad: self.phi_diff_rad as f64,
        }
    }

    /// The channels the sample measured: those whose `rho` is not NaN.
    pub fn measured(&self) -> [bool; 3] {
        self.rho.map(|r| !r.is_nan())
    }

    /// True when the sample measured channel `c` (0 red, 1 green, 2 blue).
    pub fn measures(&self, c: usize) -> bool {
        self.rho.get(c).is_some_and(|r| !r.is_nan())
    }

    /// True when the sample measured fewer than three channels.
    pub fn is_partial(&self) -> bool {
        self.rho.iter().any(|r| r.is_nan())
    }

    /// The mean of the measured channels' `rho` (NaN when none is measured).
    pub fn mean_measured_rho(&self) -> f32 {
        let (sum, n) = self
            .rho
            .iter()
            .filter(|r| !r.is_nan())
            .fold((0.0f32, 0u8), |(s, n), r| (s + r, n + 1));
        if n == 0 {
            f32::NAN
        } else {
            sum / f32::from(n)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sample_without_a_surface_point_equals_itself() {
        let s = BrdfSample::default();
        assert!(!s.surface.is_known());
        assert_eq!(s, s);
        assert_eq!(s.surface.weights(), None);
        assert_eq!(s.surface.texture_uv(), None);
    }

    #[test]
    fn samples_stay_compact() {
        // Sessions hold millions: 48 bytes before the surface point, 20 more with it.
        assert_eq!(std::mem::size_of::<SurfacePoint>(), 20);
        assert_eq!(std::mem::size_of::<BrdfSample>(), 68);
    }

    #[test]
    fn surface_points_compare_by_value() {
        let a = SurfacePoint::on_triangle(7, [0.25, 0.5]);
        assert_eq!(a.weights(), Some([0.25, 0.25, 0.5]));
        assert_eq!(a.texture_uv(), None);
        assert_ne!(a, SurfacePoint::NONE);
        assert_ne!(a, SurfacePoint::on_triangle(7, [0.25, 0.25]));
        let b = SurfacePoint {
            uv: [0.5, 0.75],
            ..a
        };
        assert_ne!(a, b);
        assert_eq!(b.texture_uv(), Some([0.5, 0.75]));
    }
}
