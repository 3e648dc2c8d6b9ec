//! The traced scene: camera, point light, BVH, shading normals; primary and shadow rays; the
//! shading of one pair of BRDFs from the same rays.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::TriMesh;
use skinbrdf_mesh::{BuildQuality, MeshBvh, MeshRay, NormalMethod, SurfaceNormals};

use crate::{NormalSource, RenderConfig, RenderError};

/// Minimum shadow-ray origin offset, in bounding radii (1e-4 of a 0.12 m head radius is 12 µm:
/// above f32 hit noise at that range, below any visible feature).
const SHADOW_BIAS_REL: f64 = 1e-4;
/// Shadow-ray origin offset along the shading normal in median edge lengths: the flat facets of
/// a coarse or noisy scan shadow each other near the terminator (black speckles where the smooth
/// shading normal still faces the light); starting the shadow ray half an edge out skips them
/// and hides only contact shadows smaller than the tessellation.
const SHADOW_BIAS_EDGES: f64 = 0.5;

/// A pinhole camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Position, metres (mesh frame).
    pub position: DVec3,
    /// Unit viewing direction.
    pub forward: DVec3,
    /// Unit image-right direction.
    pub right: DVec3,
    /// Unit image-up direction.
    pub up: DVec3,
    /// `tan(fov_y / 2)`.
    pub tan_half_fov_y: f64,
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
}

impl Camera {
    /// The unit direction through image point `(x_px, y_px)` (pixel `(i, j)` covers
    /// `[i, i+1) x [j, j+1)`, `y` down).
    pub fn ray_dir(&self, x_px: f64, y_px: f64) -> DVec3 {
        let aspect = f64::from(self.width_px) / f64::from(self.height_px);
        let sx = (2.0 * x_px / f64::from(self.width_px) - 1.0) * self.tan_half_fov_y * aspect;
        let sy = (1.0 - 2.0 * y_px / f64::from(self.height_px)) * self.tan_half_fov_y;
        (self.forward + sx * self.right + sy * self.up).normalize()
    }
}

/// A mesh ready to be rendered under one configuration.
#[derive(Debug)]
pub struct Scene<'a> {
    mesh: &'a TriMesh,
    bvh: MeshBvh,
    normals: SurfaceNormals,
    /// The camera.
    pub camera: Camera,
    /// Light position, metres.
    pub light_m: DVec3,
    /// Light intensity (irradiance 1 at the centre's distance).
    pub intensity: f64,
    /// Bounding-sphere centre, metres.
    pub centre_m: DVec3,
    /// Bounding-sphere radius, metres.
    pub radius_m: f64,
    supersample: u32,
    shadow_bias_m: f64,
}

/// Linear radiance of the two panels, per pixel (average of its samples).
#[derive(Debug, Clone)]
pub struct RenderedPair {
    /// Panel width, pixels.
    pub width_px: u32,
    /// Panel height, pixels.
    pub height_px: u32,
    /// Left panel (first BRDF), row-major, `y` down.
    pub left: Vec<[f32; 3]>,
    /// Right panel (second BRDF).
    pub right: Vec<[f32; 3]>,
    /// Fraction of each pixel's samples that hit the mesh.
    pub coverage: Vec<f32>,
    /// Fraction of each pixel's samples that are lit (hit and not shadowed).
    pub lit: Vec<f32>,
    /// Primary plus shadow rays traced.
    pub rays: u64,
    /// Fraction of primary rays that hit.
    pub hit_fraction: f64,
    /// Fraction of hits in shadow.
    pub shadowed_fraction: f64,
}

impl<'a> Scene<'a> {
    /// Builds the BVH and normals and places camera and light (see the crate docs).
    pub fn new(mesh: &'a TriMesh, cfg: &RenderConfig) -> Result<Self, RenderError> {
        cfg.validate()?;
        let bvh = MeshBvh::build(mesh, BuildQuality::Medium)?;
        let method = match cfg.normals {
            NormalSource::Vertex => NormalMethod::Vertex,
            NormalSource::Auto | NormalSource::PlanarFit => NormalMethod::PlanarFitAuto,
        };
        let normals = match (&mesh.normals, cfg.normals) {
            (Some(n), NormalSource::Auto) if n.len() == mesh.positions.len() => SurfaceNormals {
                normals: n.clone(),
                method: NormalMethod::Vertex,
                radius_m: 0.0,
                fallbacks: 0,
                mean_neighbours: 0.0,
                noise: None,
            },
            _ => SurfaceNormals::compute(mesh, method)?,
        };
        // Bounding sphere: bounding-box centre, farthest vertex.
        let (lo, hi) = mesh.positions.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(p.as_dvec3()), hi.max(p.as_dvec3())),
        );
        let centre_m = 0.5 * (lo + hi);
        let radius_m = mesh
            .positions
            .iter()
            .map(|p| p.as_dvec3().distance(centre_m))
            .fold(0.0, f64::max)
            .max(1e-6);
        let back = DVec3::from(cfg.view_dir).normalize();
        let right = DVec3::from(cfg.up).cross(back).normalize();
        let up = back.cross(right);
        let camera = Camera {
            position: centre_m + back * cfg.camera_distance_rel * radius_m,
            forward: -back,
            right,
            up,
            tan_half_fov_y: (0.5 * cfg.fov_y_deg.to_radians()).tan(),
            width_px: cfg.width_px * cfg.supersample,
            height_px: cfg.height_px * cfg.supersample,
        };
        let (sa, ca) = cfg.light_azimuth_deg.to_radians().sin_cos();
        let (se, ce) = cfg.light_elevation_deg.to_radians().sin_cos();
        let light_dir = (ce * (ca * back + sa * right) + se * up).normalize();
        let light_m = centre_m + light_dir * cfg.light_distance_rel * radius_m;
        let d_c = cfg.light_distance_rel * radius_m;
        let mut edges: Vec<f64> = mesh
            .indices
            .iter()
            .step_by((mesh.indices.len() / 20_000).max(1))
            .map(|t| {
                f64::from(mesh.positions[t[0] as usize].distance(mesh.positions[t[1] as usize]))
            })
            .collect();
        let median_edge_m = if edges.is_empty() {
            0.0
        } else {
            let k = edges.len() / 2;
            *edges.select_nth_unstable_by(k, f64::total_cmp).1
        };
        let shadow_bias_m = (SHADOW_BIAS_EDGES * median_edge_m).max(SHADOW_BIAS_REL * radius_m);
        Ok(Self {
            mesh,
            bvh,
            normals,
            camera,
            light_m,
            intensity: d_c * d_c,
            centre_m,
            radius_m,
            supersample: cfg.supersample,
            shadow_bias_m,
        })
    }

    /// BVH build time, seconds.
    pub fn bvh_build_s(&self) -> f64 {
        self.bvh.build_time().as_secs_f64()
    }

    /// Traces every sample once and shades it with both BRDFs.
    pub fn render_pair(&self, left: &BrdfModel, right: &BrdfModel) -> RenderedPair {
        let cam = &self.camera;
        let (sw, sh) = (cam.width_px as usize, cam.height_px as usize);
        let origin = cam.position.as_vec3();
        let primary: Vec<MeshRay> = (0..sw * sh)
            .into_par_iter()
            .map(|k| {
                let (x, y) = ((k % sw) as f64 + 0.5, (k / sw) as f64 + 0.5);
                MeshRay::new(origin, cam.ray_dir(x, y).as_vec3())
            })
            .collect();
        let hits = self.bvh.intersect_batch(&primary);
        let bias = self.shadow_bias_m as f32;
        // Per hit: point and shading normal, on the side of the geometric normal facing the
        // camera.
        struct Surf {
            p: DVec3,
            ns: DVec3,
        }
        let surfs: Vec<Option<Surf>> = primary
            .par_iter()
            .zip(&hits)
            .map(|(ray, hit)| {
                let hit = hit.as_ref()?;
                let p = (ray.origin + ray.dir * hit.t_m).as_dvec3();
                let mut ng = self
                    .mesh
                    .face_normal_area2(hit.triangle as usize)
                    .as_dvec3()
                    .normalize_or_zero();
                if ng.dot(ray.dir.as_dvec3()) > 0.0 {
                    ng = -ng;
                }
                let mut ns = self.normals.at(self.mesh, hit).as_dvec3();
                if ns.dot(ng) < 0.0 {
                    ns = -ns;
                }
                Some(Surf { p, ns })
            })
            .collect();
        let light = self.light_m;
        // Shadow rays only where the shading normal faces the light (others are unlit anyway).
        let shadow: Vec<MeshRay> = surfs
            .par_iter()
            .map(|s| match s {
                Some(s) if s.ns.dot(light - s.p) > 0.0 => {
                    let o = s.p.as_vec3() + s.ns.as_vec3() * bias;
                    let to = light.as_vec3() - o;
                    let d = to.length();
                    MeshRay {
                        origin: o,
                        dir: to / d,
                        t_max: (d - bias).max(0.0),
                    }
                }
                // A degenerate ray: hits nothing, is never counted.
                _ => MeshRay {
                    origin: Vec3::ZERO,
                    dir: Vec3::ZERO,
                    t_max: 0.0,
                },
            })
            .collect();
        let occluded = self.bvh.occluded_batch(&shadow);
        let n_shadow_rays = shadow.iter().filter(|r| r.dir != Vec3::ZERO).count() as u64;
        let shaded: Vec<Option<([f64; 3], [f64; 3])>> = surfs
            .par_iter()
            .zip(&shadow)
            .zip(&occluded)
            .map(|((s, ray), &occ)| {
                let s = s.as_ref()?;
                if ray.dir == Vec3::ZERO || occ {
                    return Some(([0.0; 3], [0.0; 3]));
                }
                let to = light - s.p;
                let d2 = to.length_squared();
                let wi = to / d2.sqrt();
                let we = (self.camera.position - s.p).normalize();
                let (wi_l, we_l) = to_local(s.ns, wi, we);
                if wi_l.z <= 0.0 || we_l.z <= 0.0 {
                    return Some(([0.0; 3], [0.0; 3]));
                }
                let e = self.intensity * wi_l.z / d2;
                let fl = left.eval(wi_l, we_l);
                let fr = right.eval(wi_l, we_l);
                Some((fl.map(|v| v * e), fr.map(|v| v * e)))
            })
            .collect();
        let hits_n = shaded.iter().filter(|s| s.is_some()).count();
        let lit_n = shaded
            .iter()
            .flatten()
            .filter(|(a, b)| a.iter().chain(b).any(|v| *v > 0.0))
            .count();
        // Box-filter the s x s samples of each pixel.
        let s = self.supersample as usize;
        let (w, h) = (sw / s, sh / s);
        let inv = 1.0 / (s * s) as f64;
        let pixels: Vec<([f32; 3], [f32; 3], f32, f32)> = (0..w * h)
            .into_par_iter()
            .map(|k| {
                let (px, py) = (k % w, k / w);
                let (mut a, mut b) = ([0.0f64; 3], [0.0f64; 3]);
                let (mut cov, mut lit) = (0.0, 0.0);
                for dy in 0..s {
                    for dx in 0..s {
                        let i = (py * s + dy) * sw + px * s + dx;
                        if let Some((l, r)) = &shaded[i] {
                            cov += inv;
                            if l.iter().chain(r).any(|v| *v > 0.0) {
                                lit += inv;
                            }
                            for c in 0..3 {
                                a[c] += l[c] * inv;
                                b[c] += r[c] * inv;
                            }
                        }
                    }
                }
                (
                    a.map(|v| v as f32),
                    b.map(|v| v as f32),
                    cov as f32,
                    lit as f32,
                )
            })
            .collect();
        RenderedPair {
            width_px: w as u32,
            height_px: h as u32,
            left: pixels.iter().map(|p| p.0).collect(),
            right: pixels.iter().map(|p| p.1).collect(),
            coverage: pixels.iter().map(|p| p.2).collect(),
            lit: pixels.iter().map(|p| p.3).collect(),
            rays: (sw * sh) as u64 + n_shadow_rays,
            hit_fraction: hits_n as f64 / (sw * sh).max(1) as f64,
            shadowed_fraction: if hits_n == 0 {
                0.0
            } else {
                1.0 - lit_n as f64 / hits_n as f64
            },
        }
    }
}

/// `w_i`, `w_e` in a frame whose +z is `n` (any tangent: the models are isotropic).
fn to_local(n: DVec3, wi: DVec3, we: DVec3) -> (DVec3, DVec3) {
    let helper = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let t = helper.cross(n).normalize();
    let b = n.cross(t);
    let l = |v: DVec3| DVec3::new(v.dot(t), v.dot(b), v.dot(n));
    (l(wi), l(we))
}

/// Strata per axis of the albedo quadrature (`sin^2 theta_e` and `phi`): 512 x 512 cells resolve
/// lobes down to ~0.1 degrees wide.
const ALBEDO_STRATA: usize = 512;

/// The directional albedo at normal incidence, per channel:
/// `a = integral f_r(n, w_e) cos(theta_e) dw_e`, by the midpoint rule in `u = sin^2 theta_e`
/// (`cos theta_e dw_e = du dphi / 2`, so the integral is `pi` times the mean of `f_r` over the
/// unit square) and `phi`. A Lambertian model returns its own albedo.
pub fn directional_albedo(model: &BrdfModel) -> [f64; 3] {
    if let BrdfModel::Lambertian { albedo } = model {
        return *albedo;
    }
    let n = ALBEDO_STRATA;
    let wi = DVec3::Z;
    let sum = (0..n)
        .into_par_iter()
        .map(|i| {
            let u = (i as f64 + 0.5) / n as f64;
            let (st, ct) = (u.sqrt(), (1.0 - u).sqrt());
            let mut acc = [0.0; 3];
            for j in 0..n {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / n as f64;
                let we = DVec3::new(st * phi.cos(), st * phi.sin(), ct);
                let f = model.eval(wi, we);
                for c in 0..3 {
                    acc[c] += f[c];
                }
            }
            acc
        })
        .reduce(|| [0.0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
    // cos(theta) dw = (1/2) du dphi; integral over u in [0,1], phi in [0, 2pi] = pi * mean.
    sum.map(|s| (std::f64::consts::PI * s / (n * n) as f64).max(0.0))
}
