//! The true sample surface, in the head frame (origin at the head centre, +y forward out of the
//! face, +z up, x = y × z).
//!
//! * **Head**: a star-shaped surface `p = r(d) d` over unit directions `d`, where `r` is a
//!   superellipsoid's radial function `(|dx/a|^e + |dy/b|^e + |dz/c|^e)^(-1/e)` plus a brow
//!   ridge: `h exp(-(el - el_b)² / 2σ²) cos²(π az / 2A)` for `|az| < A` (azimuth `az` from +y
//!   towards +x, elevation `el` from the horizontal). This has compound curvature (different in
//!   the horizontal and vertical) and a concave band under the ridge that can shadow itself.
//! * **Sphere**: the same with `a = b = c` and `e = 2`, no ridge.
//! * **Cylinder**: vertical axis (z), radius `R`, length `L`, capped.
//!
//! The renderer intersects a fine tessellation ([`Shape::tessellate`], sagitta of a few µm) and
//! shades with the analytic normal [`Shape::normal`] at the hit point (the implicit function's
//! analytic gradient, [`Shape::implicit_gradient`], in f64; checked against central
//! differences).

use glam::{DVec3, Vec3};
use serde::Serialize;
use skinbrdf_core::TriMesh;

use crate::scene::{GeometryKind, GeometryScene};

/// The true surface.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Shape {
    /// Star-shaped head or sphere.
    Star {
        /// Semi-axes x, y, z, metres.
        semi_axes_m: [f64; 3],
        /// Superellipsoid exponent.
        exponent: f64,
        /// Brow ridge height, metres (0 = none).
        brow_height_m: f64,
        /// Brow ridge elevation, radians.
        brow_elevation_rad: f64,
        /// Brow ridge sigma in elevation, radians.
        brow_width_rad: f64,
        /// Brow ridge half extent in azimuth, radians.
        brow_half_azimuth_rad: f64,
    },
    /// Vertical capped cylinder centred at the origin.
    Cylinder {
        /// Radius, metres.
        radius_m: f64,
        /// Length, metres.
        length_m: f64,
    },
}

/// Unit direction at azimuth `az` (from +y towards +x) and elevation `el`.
pub fn direction(az: f64, el: f64) -> DVec3 {
    let (sa, ca) = az.sin_cos();
    let (se, ce) = el.sin_cos();
    DVec3::new(ce * sa, ce * ca, se)
}

impl Shape {
    /// The shape a scene describes.
    pub fn from_scene(g: &GeometryScene) -> Self {
        match g.kind {
            GeometryKind::Head => Self::Star {
                semi_axes_m: g.semi_axes_m,
                exponent: g.superellipse_exponent,
                brow_height_m: g.brow_height_m,
                brow_elevation_rad: g.brow_elevation_deg.to_radians(),
                brow_width_rad: g.brow_width_deg.to_radians(),
                brow_half_azimuth_rad: g.brow_half_azimuth_deg.to_radians(),
            },
            GeometryKind::Sphere => Self::Star {
                semi_axes_m: [g.sphere_radius_m; 3],
                exponent: 2.0,
                brow_height_m: 0.0,
                brow_elevation_rad: 0.0,
                brow_width_rad: 1.0,
                brow_half_azimuth_rad: 1.0,
            },
            GeometryKind::Cylinder => Self::Cylinder {
                radius_m: g.cylinder_radius_m,
                length_m: g.cylinder_length_m,
            },
        }
    }

    /// Radius of the star surface along unit direction `d`.
    fn star_radius(&self, d: DVec3) -> f64 {
        match *self {
            Self::Star {
                semi_axes_m: [a, b, c],
                exponent: e,
                brow_height_m,
                brow_elevation_rad,
                brow_width_rad,
                brow_half_azimuth_rad,
            } => {
                let s = (d.x / a).abs().powf(e) + (d.y / b).abs().powf(e) + (d.z / c).abs().powf(e);
                let mut r = s.powf(-1.0 / e);
                if brow_height_m > 0.0 {
                    let az = d.x.atan2(d.y);
                    let el = d.z.clamp(-1.0, 1.0).asin();
                    if az.abs() < brow_half_azimuth_rad {
                        let w = (0.5 * std::f64::consts::PI * az / brow_half_azimuth_rad).cos();
                        let g = (-0.5 * ((el - brow_elevation_rad) / brow_width_rad).powi(2)).exp();
                        r += brow_height_m * w * w * g;
                    }
                }
                r
            }
            Self::Cylinder { .. } => 0.0,
        }
    }

    /// Radius of the star surface along unit `d` and its gradient with respect to `d` (the
    /// formulas of [`Self::star_radius`] differentiated, with `d` treated as free: only the part
    /// tangent to the sphere matters to [`Self::implicit_gradient`]).
    fn star_radius_grad(&self, d: DVec3) -> (f64, DVec3) {
        match *self {
            Self::Star {
                semi_axes_m: [a, b, c],
                exponent: e,
                brow_height_m,
                brow_elevation_rad,
                brow_width_rad,
                brow_half_azimuth_rad,
            } => {
                let axes = [a, b, c];
                let comps = [d.x, d.y, d.z];
                let t: [f64; 3] = std::array::from_fn(|i| (comps[i] / axes[i]).abs());
                let te: [f64; 3] = std::array::from_fn(|i| t[i].powf(e));
                let s = te[0] + te[1] + te[2];
                let mut r = s.powf(-1.0 / e);
                // d r0 / d d_i = -(r0 / s) t_i^(e-1) sign(d_i) / a_i, with t^(e-1) = t^e / t.
                let mut g = DVec3::from_array(std::array::from_fn(|i| {
                    if t[i] > 0.0 {
                        -(r / s) * (te[i] / t[i]) * comps[i].signum() / axes[i]
                    } else {
                        0.0
                    }
                }));
                if brow_height_m > 0.0 {
                    let az = d.x.atan2(d.y);
                    let z = d.z.clamp(-1.0, 1.0);
                    let el = z.asin();
                    if az.abs() < brow_half_azimuth_rad {
                        let k = 0.5 * std::f64::consts::PI / brow_half_azimuth_rad;
                        let (sw, w) = (k * az).sin_cos();
                        let u = (el - brow_elevation_rad) / brow_width_rad;
                        let gauss = (-0.5 * u * u).exp();
                        r += brow_height_m * w * w * gauss;
                        let rho2 = d.x * d.x + d.y * d.y;
                        let daz = if rho2 > 0.0 {
                            DVec3::new(d.y / rho2, -d.x / rho2, 0.0)
                        } else {
                            DVec3::ZERO
                        };
                        let cos_el = (1.0 - z * z).sqrt();
                        let del = if cos_el > 0.0 {
                            DVec3::new(0.0, 0.0, 1.0 / cos_el)
                        } else {
                            DVec3::ZERO
                        };
                        let dbrow_daz = -2.0 * w * k * sw * gauss;
                        let dbrow_del = -w * w * gauss * u / brow_width_rad;
                        g += brow_height_m * (daz * dbrow_daz + del * dbrow_del);
                    }
                }
                (r, g)
            }
            Self::Cylinder { .. } => (0.0, DVec3::ZERO),
        }
    }

    /// Gradient of [`Self::implicit`], analytic for the star surface: with `l = |p|`,
    /// `d = p / l` and `f = l - r(d)`, `grad f = d - (I - d dᵀ) grad_d r / l`. One evaluation
    /// of the radial function instead of the six a central difference needs.
    pub fn implicit_gradient(&self, p: DVec3) -> DVec3 {
        match *self {
            Self::Star { .. } => {
                let l = p.length();
                if l < 1e-12 {
                    return DVec3::ZERO;
                }
                let d = p / l;
                let (_, g) = self.star_radius_grad(d);
                d - (g - d * d.dot(g)) / l
            }
            Self::Cylinder { .. } => self.gradient(p),
        }
    }

    /// Signed implicit function: negative inside, zero on the surface (metres-like).
    pub fn implicit(&self, p: DVec3) -> f64 {
        match *self {
            Self::Star { .. } => {
                let l = p.length();
                if l < 1e-12 {
                    return -1.0;
                }
                l - self.star_radius(p / l)
            }
            Self::Cylinder { radius_m, length_m } => {
                let side = p.truncate().length() - radius_m;
                let cap = p.z.abs() - 0.5 * length_m;
                side.max(cap)
            }
        }
    }

    /// Gradient of [`Self::implicit`] (central differences, f64).
    pub fn gradient(&self, p: DVec3) -> DVec3 {
        let h = 1e-7;
        DVec3::new(
            self.implicit(p + DVec3::X * h) - self.implicit(p - DVec3::X * h),
            self.implicit(p + DVec3::Y * h) - self.implicit(p - DVec3::Y * h),
            self.implicit(p + DVec3::Z * h) - self.implicit(p - DVec3::Z * h),
        ) / (2.0 * h)
    }

    /// Moves a point near the surface along `dir` onto the surface (Newton on the implicit
    /// function, at most 4 steps; the start is within a few µm).
    pub fn refine_along(&self, mut p: DVec3, dir: DVec3) -> DVec3 {
        for _ in 0..4 {
            let f = self.implicit(p);
            if f.abs() < 1e-13 {
                break;
            }
            let denom = self.gradient(p).dot(dir);
            if denom.abs() < 1e-6 {
                break;
            }
            let step = f / denom;
            if step.abs() > 1e-4 {
                break; // not near the surface along this ray: keep the mesh hit
            }
            p -= dir * step;
        }
        p
    }

    /// Outward unit normal of the surface at (or very near) `p`.
    pub fn normal(&self, p: DVec3) -> DVec3 {
        match *self {
            Self::Star { .. } => self
                .implicit_gradient(p)
                .normalize_or(p.normalize_or(DVec3::Z)),
            Self::Cylinder { radius_m, length_m } => {
                let side = (p.truncate().length() - radius_m).abs();
                let cap = (p.z.abs() - 0.5 * length_m).abs();
                if cap < side {
                    DVec3::Z * p.z.signum()
                } else {
                    p.truncate().extend(0.0).normalize_or(DVec3::Y)
                }
            }
        }
    }

    /// The surface point at azimuth/elevation (for a cylinder, elevation is read as height
    /// `z = radius * tan(el)` on the side).
    pub fn point(&self, az: f64, el: f64) -> DVec3 {
        match *self {
            Self::Star { .. } => {
                let d = direction(az, el);
                d * self.star_radius(d)
            }
            Self::Cylinder { radius_m, length_m } => {
                let (sa, ca) = az.sin_cos();
                let z = (radius_m * el.tan()).clamp(-0.5 * length_m, 0.5 * length_m);
                DVec3::new(radius_m * sa, radius_m * ca, z)
            }
        }
    }

    /// Largest distance of the surface from the origin (bounding sphere radius).
    pub fn bounding_radius(&self) -> f64 {
        match *self {
            Self::Star {
                semi_axes_m,
                brow_height_m,
                ..
            } => semi_axes_m.iter().fold(0.0f64, |m, v| m.max(*v)) + brow_height_m,
            Self::Cylinder { radius_m, length_m } => radius_m.hypot(0.5 * length_m),
        }
    }

    /// Intersects a ray (head frame, unit `dir`) with the analytic surface: first sign change of
    /// the implicit function, refined by bisection to 1e-12 m. Independent of any mesh; used to
    /// check the renderer.
    pub fn intersect_analytic(&self, origin: DVec3, dir: DVec3) -> Option<f64> {
        let r = self.bounding_radius() * 1.01;
        // Ray/bounding-sphere interval.
        let b = origin.dot(dir);
        let c = origin.length_squared() - r * r;
        let disc = b * b - c;
        if disc <= 0.0 {
            return None;
        }
        let (t0, t1) = (-b - disc.sqrt(), -b + disc.sqrt());
        let step = 2e-4;
        let mut t = t0.max(0.0);
        let mut f = self.implicit(origin + dir * t);
        while t < t1 {
            let tn = t + step;
            let fnext = self.implicit(origin + dir * tn);
            if f > 0.0 && fnext <= 0.0 {
                let (mut lo, mut hi) = (t, tn);
                for _ in 0..80 {
                    let mid = 0.5 * (lo + hi);
                    if self.implicit(origin + dir * mid) > 0.0 {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                return Some(0.5 * (lo + hi));
            }
            t = tn;
            f = fnext;
        }
        None
    }

    /// Tessellates the surface with about `spacing_m` between vertices, over azimuths
    /// `az_range` and elevations `el_range` (radians). The full range (`-pi..pi`, `-pi/2..pi/2`)
    /// gives a closed surface. Triangles are counter-clockwise seen from outside.
    pub fn tessellate(
        &self,
        spacing_m: f64,
        az_range: (f64, f64),
        el_range: (f64, f64),
    ) -> TriMesh {
        use std::f64::consts::{FRAC_PI_2, PI};
        let full_az = az_range.1 - az_range.0 >= 2.0 * PI - 1e-9;
        let r = self.bounding_radius();
        let n_az = (((az_range.1 - az_range.0) * r / spacing_m).ceil() as usize).max(3);
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        match *self {
            Self::Star { .. } => {
                let n_el = (((el_range.1 - el_range.0) * r / spacing_m).ceil() as usize).max(2);
                let cols = if full_az { n_az } else { n_az + 1 };
                for i in 0..=n_el {
                    let el = el_range.0 + (el_range.1 - el_range.0) * i as f64 / n_el as f64;
                    let el = el.clamp(-FRAC_PI_2, FRAC_PI_2);
                    for j in 0..cols {
                        let az = az_range.0 + (az_range.1 - az_range.0) * j as f64 / n_az as f64;
                        positions.push(self.point(az, el).as_vec3());
                    }
                }
                let idx = |i: usize, j: usize| (i * cols + (j % cols)) as u32;
                for i in 0..n_el {
                    for j in 0..n_az {
                        // Outward CCW: azimuth grows towards +x (clockwise seen from +z), so
                        // (el, az) -> (el, az+1) -> (el+1, az+1) is counter-clockwise from outside.
                        let (a, b, c, d) =
                            (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
                        indices.push([a, c, b]);
                        indices.push([a, d, c]);
                    }
                }
            }
            Self::Cylinder { radius_m, length_m } => {
                let n_z = ((length_m / spacing_m).ceil() as usize).max(2);
                let cols = if full_az { n_az } else { n_az + 1 };
                let ring = |z: f64, positions: &mut Vec<Vec3>| {
                    for j in 0..cols {
                        let az = az_range.0 + (az_range.1 - az_range.0) * j as f64 / n_az as f64;
                        let (s, c) = az.sin_cos();
                        positions.push(DVec3::new(radius_m * s, radius_m * c, z).as_vec3());
                    }
                };
                for i in 0..=n_z {
                    ring(
                        -0.5 * length_m + length_m * i as f64 / n_z as f64,
                        &mut positions,
                    );
                }
                let idx = |i: usize, j: usize| (i * cols + (j % cols)) as u32;
                for i in 0..n_z {
                    for j in 0..n_az {
                        let (a, b, c, d) =
                            (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
                        indices.push([a, c, b]);
                        indices.push([a, d, c]);
                    }
                }
                if full_az {
                    // Caps: fans around centre vertices.
                    for (ring_i, z, up) in [
                        (0usize, -0.5 * length_m, false),
                        (n_z, 0.5 * length_m, true),
                    ] {
                        let centre = positions.len() as u32;
                        positions.push(Vec3::new(0.0, 0.0, z as f32));
                        for j in 0..n_az {
                            let (a, b) = (idx(ring_i, j), idx(ring_i, j + 1));
                            indices.push(if up { [centre, a, b] } else { [centre, b, a] });
                        }
                    }
                }
            }
        }
        TriMesh {
            positions,
            indices,
            normals: None,
        }
    }

    /// Description for `truth.json`.
    pub fn describe(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or(serde_json::Value::Null)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    #[test]
    fn the_analytic_gradient_matches_central_differences() {
        // Over the whole head (brow ridge included), a sphere and a ridge-free superellipsoid,
        // at points on, inside and outside the surface.
        let mut worst = 0.0f64;
        for name in ["default", "sphere", "oily", "near-mirror"] {
            let s = Shape::from_scene(&Scene::load(name).unwrap().geometry);
            for i in 0..60 {
                for j in 0..30 {
                    let az = -3.1 + 6.2 * (f64::from(i) + 0.37) / 60.0;
                    let el = -1.5 + 3.0 * (f64::from(j) + 0.61) / 30.0;
                    for scale in [0.97, 1.0, 1.03] {
                        let p = s.point(az, el) * scale;
                        let h = 1e-6;
                        let fd = DVec3::new(
                            s.implicit(p + DVec3::X * h) - s.implicit(p - DVec3::X * h),
                            s.implicit(p + DVec3::Y * h) - s.implicit(p - DVec3::Y * h),
                            s.implicit(p + DVec3::Z * h) - s.implicit(p - DVec3::Z * h),
                        ) / (2.0 * h);
                        let an = s.implicit_gradient(p);
                        let err = (an - fd).length() / fd.length().max(1e-12);
                        worst = worst.max(err);
                        assert!(err < 1e-5, "{name} az {az} el {el} x{scale}: {an} vs {fd}");
                    }
                }
            }
        }
        eprintln!("worst relative gradient difference {worst:.2e}");
    }

    #[test]
    fn normals_are_outward_and_match_the_mesh() {
        for name in ["default", "sphere", "cylinder"] {
            let s = Shape::from_scene(&Scene::load(name).unwrap().geometry);
            let m = s.tessellate(
                0.004,
                (-std::f64::consts::PI, std::f64::consts::PI),
                (-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2),
            );
            assert!(m.validate().is_empty());
            // Face normals agree with analytic normals at face centroids (outward winding).
            let mut agree = 0;
            let mut total = 0;
            for t in 0..m.indices.len() {
                let n = m.face_normal_area2(t);
                if n.length() < 1e-9 {
                    continue;
                }
                let [a, b, c] = m.triangle(t);
                let centroid = ((a + b + c) / 3.0).as_dvec3();
                let an = s.normal(centroid);
                total += 1;
                if n.as_dvec3().normalize().dot(an) > 0.95 {
                    agree += 1;
                }
            }
            assert!(
                agree as f64 > 0.98 * total as f64,
                "{name}: {agree}/{total}"
            );
        }
    }

    #[test]
    fn analytic_intersection_lands_on_the_surface() {
        let s = Shape::from_scene(&Scene::load("default").unwrap().geometry);
        let o = DVec3::new(0.01, 2.0, 0.03);
        let t = s.intersect_analytic(o, DVec3::NEG_Y).unwrap();
        let p = o + DVec3::NEG_Y * t;
        assert!(s.implicit(p).abs() < 1e-10);
        assert!(s.normal(p).y > 0.8);
    }
}
