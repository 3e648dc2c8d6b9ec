//! The sample's geometry prepared for derendering: the scan, its BVH, its shading normals, the
//! region of interest and whether the geometry can shadow the region at all.
//!
//! **Convexity test (skipping shadow rays).** A point `p` of the region with normal `n` can only
//! be shadowed by geometry in front of its tangent plane, and only for light arriving from the
//! direction of that geometry. Samples lit at `θ_i` beyond the grazing limit are dropped
//! anyway, so geometry that rises less than `90° − grazing limit` above the tangent plane (seen
//! from `p`) cannot shadow any sample that is kept. [`Geometry::new`] takes, for a sample of up
//! to [`CONVEXITY_SAMPLE`] region vertices (evenly spread), the largest **elevation** of any
//! vertex `q` of the whole mesh above the tangent plane of `p`:
//!
//! ```text
//! elevation = asin( max(0, (q − p)·n − tol) / |q − p| )
//! ```
//!
//! with `tol` = [`Geometry::convexity_tol_m`] (three times the scan's estimated noise, at least
//! [`MIN_CONVEXITY_TOL_M`]): a vertex pushed out by noise is not geometry. Vertices closer to
//! `p` than the planar-fit radius are skipped: they are the patch `p`'s normal is fitted to
//! (at sub-millimetre distances scan noise alone gives any elevation). The region can shadow
//! itself at a grazing limit `L` when that elevation reaches `90° − L −`
//! [`CONVEXITY_MARGIN_DEG`] ([`Geometry::can_shadow_within`]); [`Geometry::can_self_shadow`] is
//! the verdict at the default limit (75°).
//!
//! Measuring the elevation rather than the height above the plane matters on long shapes: the
//! planar-fit normal of a vertex tilts by ~1 mrad when rounding puts a neighbour at exactly the
//! fit radius on one side only, which lifts the far end of a 25 cm cylinder ~0.2 mm above the
//! tangent plane (the old height test then called the cylinder non-convex); its elevation is
//! 0.08°. The test looks at vertices only: a triangle whose corners all lie low could still
//! rise over `p` if it were large compared with its distance from `p`; scan triangles (a few
//! millimetres) near `p` are `p`'s own surface.

use std::time::{Duration, Instant};

use glam::DVec3;
use rayon::prelude::*;
use skinbrdf_core::{SurfacePoint, TriMesh};
use skinbrdf_mesh::{BuildQuality, CornerUv, Hit, MeshBvh, NormalMethod, SurfaceNormals};

use crate::DerenderError;

/// Region vertices tested for convexity.
pub const CONVEXITY_SAMPLE: usize = 512;
/// Smallest tolerance of the convexity test (10 µm: below any scan's noise).
pub const MIN_CONVEXITY_TOL_M: f64 = 1e-5;
/// Angular margin of the convexity test, degrees: the normal at a hit interpolates vertex
/// normals and the test samples region vertices, so the grazing filter sees normals a little
/// different from the tested ones (planar-fit normals vary by well under a degree between
/// neighbouring vertices on skin-like curvature); 2° covers that.
pub const CONVEXITY_MARGIN_DEG: f64 = 2.0;

/// A sphere in the head frame selecting the region of interest.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Roi {
    /// Centre, head frame, metres.
    pub centre_m: DVec3,
    /// Radius, metres.
    pub radius_m: f64,
}

impl Roi {
    /// Whether a head-frame point is inside.
    pub fn contains(&self, p: DVec3) -> bool {
        p.distance_squared(self.centre_m) <= self.radius_m * self.radius_m
    }
}

/// The prepared geometry.
#[derive(Debug)]
pub struct Geometry {
    /// The scan, metres, head frame.
    pub mesh: TriMesh,
    /// Its BVH.
    pub bvh: MeshBvh,
    /// Shading normals.
    pub normals: SurfaceNormals,
    /// Region of interest (`None` = everything).
    pub roi: Option<Roi>,
    /// The scan's texture coordinates per triangle corner, when it has them
    /// ([`Geometry::with_texture_coordinates`]); samples record the interpolated coordinate.
    pub uv: Option<CornerUv>,
    /// Whether the region can be shadowed by the geometry at the default grazing limit
    /// ([`crate::DerenderConfig::DEFAULT`]; see the module docs and [`Geometry::can_shadow_within`]).
    pub can_self_shadow: bool,
    /// Largest elevation of any mesh vertex above the tangent plane of a sampled region vertex
    /// (beyond the tolerance), degrees; 0 when every vertex lies behind the planes.
    pub shadow_elevation_deg: f64,
    /// Tolerance used by the convexity test, metres.
    pub convexity_tol_m: f64,
    /// Region vertices (indices): inside the region sphere (convexity test, bounding box).
    pub roi_vertices: Vec<u32>,
    /// Vertices of the triangles that can reach into the region (their bounding box meets the
    /// region sphere): projected per image to find the pixels that need rays.
    pub region_vertices: Vec<u32>,
    /// Those triangles, as indices into `region_vertices`.
    pub region_triangles: Vec<[u32; 3]>,
    /// Time to build the BVH.
    pub bvh_time: Duration,
    /// Time to compute normals.
    pub normals_time: Duration,
    /// Time of the convexity test.
    pub convexity_time: Duration,
}

impl Geometry {
    /// Prepares a mesh: BVH (default build quality), normals, region vertices and the
    /// convexity test.
    pub fn new(
        mesh: TriMesh,
        normals: NormalMethod,
        roi: Option<Roi>,
    ) -> Result<Self, DerenderError> {
        Self::with_quality(mesh, normals, roi, BuildQuality::default())
    }

    /// [`Geometry::new`] with a chosen BVH build preset.
    pub fn with_quality(
        mesh: TriMesh,
        normals: NormalMethod,
        roi: Option<Roi>,
        quality: BuildQuality,
    ) -> Result<Self, DerenderError> {
        let bvh = MeshBvh::build(&mesh, quality)?;
        let bvh_time = bvh.build_time();
        let t = Instant::now();
        let normals = SurfaceNormals::compute(&mesh, normals)?;
        let normals_time = t.elapsed();
        let roi_vertices: Vec<u32> = (0..mesh.positions.len() as u32)
            .filter(|&i| roi.is_none_or(|r| r.contains(mesh.positions[i as usize].as_dvec3())))
            .collect();
        if roi_vertices.is_empty() {
            return Err(DerenderError::EmptyRegion);
        }
        let (region_vertices, region_triangles) = region_triangles(&mesh, roi);
        let t = Instant::now();
        let noise = normals
            .noise
            .map(|n| n.noise_rms_m)
            .unwrap_or_else(|| skinbrdf_mesh::estimate_noise(&mesh).noise_rms_m);
        let convexity_tol_m = (3.0 * noise).max(MIN_CONVEXITY_TOL_M);
        let shadow_elevation_deg =
            max_elevation_deg(&mesh, &normals, &roi_vertices, convexity_tol_m);
        let can_self_shadow = shadows_within(
            shadow_elevation_deg,
            crate::DerenderConfig::DEFAULT.grazing_limit_deg,
        );
        Ok(Self {
            mesh,
            bvh,
            normals,
            roi,
            uv: None,
            can_self_shadow,
            shadow_elevation_deg,
            convexity_tol_m,
            roi_vertices,
            region_vertices,
            region_triangles,
            bvh_time,
            normals_time,
            convexity_time: t.elapsed(),
        })
    }
}

impl Geometry {
    /// The geometry with the scan's texture coordinates per triangle corner (as
    /// [`skinbrdf_mesh::load_mesh_with_uv`] gives them for this mesh). A triangle past the
    /// list, or without coordinates, gives samples without texture coordinates.
    pub fn with_texture_coordinates(mut self, uv: Option<CornerUv>) -> Self {
        self.uv = uv;
        self
    }

    /// The surface point of a ray hit on the mesh: its triangle, its barycentrics and, when
    /// the triangle has texture coordinates, their barycentric blend.
    pub fn surface_point(&self, hit: &Hit) -> SurfacePoint {
        let mut p = SurfacePoint::on_triangle(hit.triangle, [hit.u, hit.v]);
        let corners = self
            .uv
            .as_ref()
            .and_then(|uv| uv.get(hit.triangle as usize).copied().flatten());
        if let Some(c) = corners {
            let uv = c[0] * (1.0 - hit.u - hit.v) + c[1] * hit.u + c[2] * hit.v;
            p.uv = uv.to_array();
        }
        p
    }

    /// Whether geometry can shadow a sample kept at this grazing limit (degrees): some vertex
    /// rises at least `90° − limit −` [`CONVEXITY_MARGIN_DEG`] above a region vertex's tangent
    /// plane.
    pub fn can_shadow_within(&self, grazing_limit_deg: f64) -> bool {
        shadows_within(self.shadow_elevation_deg, grazing_limit_deg)
    }
}

fn shadows_within(elevation_deg: f64, grazing_limit_deg: f64) -> bool {
    elevation_deg >= 90.0 - grazing_limit_deg - CONVEXITY_MARGIN_DEG
}

/// Triangles whose bounding box meets the region sphere (all without a region), with their
/// vertices renumbered into a compact list.
fn region_triangles(mesh: &TriMesh, roi: Option<Roi>) -> (Vec<u32>, Vec<[u32; 3]>) {
    let mut local = vec![u32::MAX; mesh.positions.len()];
    let mut verts = Vec::new();
    let mut tris = Vec::new();
    for t in &mesh.indices {
        if let Some(r) = roi {
            let p = t.map(|i| mesh.positions[i as usize].as_dvec3());
            let lo = p[0].min(p[1]).min(p[2]);
            let hi = p[0].max(p[1]).max(p[2]);
            let nearest = r.centre_m.clamp(lo, hi);
            if nearest.distance_squared(r.centre_m) > r.radius_m * r.radius_m {
                continue;
            }
        }
        tris.push(t.map(|i| {
            let l = &mut local[i as usize];
            if *l == u32::MAX {
                *l = verts.len() as u32;
                verts.push(i);
            }
            *l
        }));
    }
    (verts, tris)
}

/// Largest elevation (degrees) of a mesh vertex above the tangent plane of a sampled region
/// vertex, the height first reduced by `tol_m` (see the module docs).
fn max_elevation_deg(mesh: &TriMesh, normals: &SurfaceNormals, roi: &[u32], tol_m: f64) -> f64 {
    let step = (roi.len() / CONVEXITY_SAMPLE).max(1);
    let tol = tol_m as f32;
    // Vertices within the normal's fit radius are the patch the normal was fitted to (the
    // surface itself, its noise averaged out), not geometry that could shadow it.
    let near2 = (normals.radius_m * normals.radius_m) as f32;
    let normals = &normals.normals;
    let sin_max = roi
        .par_iter()
        .step_by(step)
        .map(|&i| {
            let p = mesh.positions[i as usize];
            let n = normals[i as usize];
            // Relative to p so f32 keeps micrometres.
            mesh.positions
                .iter()
                .filter_map(|q| {
                    let d = *q - p;
                    let h = d.dot(n) - tol;
                    (h > 0.0 && d.length_squared() > near2).then(|| h / d.length())
                })
                .fold(0.0f32, f32::max)
        })
        .reduce(|| 0.0, f32::max);
    f64::from(sin_max.min(1.0)).asin().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A UV sphere (closed) of radius r.
    pub(crate) fn uv_sphere(r: f32, n_lat: u32, n_lon: u32) -> TriMesh {
        skinbrdf_mesh::shapes::uv_sphere(glam::DVec3::ZERO, f64::from(r), n_lat, n_lon)
    }

    #[test]
    fn sphere_needs_no_shadow_rays_but_a_bump_does() {
        let m = uv_sphere(0.1, 40, 80);
        let roi = Roi {
            centre_m: DVec3::new(0.0, 0.0, 0.1),
            radius_m: 0.05,
        };
        let g = Geometry::new(m.clone(), NormalMethod::Vertex, Some(roi)).unwrap();
        assert!(!g.can_self_shadow);
        // Add a "nose": a triangle standing in front of the region's tangent planes.
        let mut m2 = m;
        let b = m2.positions.len() as u32;
        m2.positions.extend([
            Vec3::new(0.06, 0.0, 0.1),
            Vec3::new(0.07, 0.01, 0.1),
            Vec3::new(0.07, -0.01, 0.1),
        ]);
        m2.indices.push([b, b + 1, b + 2]);
        let g = Geometry::new(m2, NormalMethod::Vertex, Some(roi)).unwrap();
        assert!(g.can_self_shadow);
    }

    /// Gaussian noise of standard deviation `sigma_m` on every vertex coordinate (xorshift and
    /// Box–Muller: no random-number crate needed).
    pub(crate) fn add_noise(m: &mut TriMesh, sigma_m: f64, seed: u64) {
        let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut unit = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        for p in &mut m.positions {
            let g: [f64; 3] = std::array::from_fn(|_| {
                (-2.0 * unit().ln()).sqrt() * (std::f64::consts::TAU * unit()).cos()
            });
            *p += (DVec3::from_array(g) * sigma_m).as_vec3();
        }
    }

    fn cylinder_scene_geometry(noise_m: f64) -> Geometry {
        // As `from_session` tessellates the cylinder scene: r = 9 cm, 25 cm long, 1 mm edges.
        let mut m = skinbrdf_mesh::shapes::cylinder(DVec3::ZERO, DVec3::Z, 0.09, 0.25, 250, 566);
        add_noise(&mut m, noise_m, 7);
        let roi = Roi {
            centre_m: DVec3::new(0.0, 0.09, 0.0),
            radius_m: 0.03,
        };
        Geometry::new(m, NormalMethod::PlanarFitAuto, Some(roi)).unwrap()
    }

    #[test]
    fn cylinder_and_sphere_scenes_are_convex() {
        let g = cylinder_scene_geometry(0.0);
        assert!(
            !g.can_self_shadow && !g.can_shadow_within(85.0),
            "cylinder: elevation {}°",
            g.shadow_elevation_deg
        );
        // The sphere scene: r = 9 cm at 1 mm edges, region at the equator.
        let m = skinbrdf_mesh::shapes::uv_sphere(DVec3::ZERO, 0.09, 283, 566);
        let roi = Roi {
            centre_m: DVec3::new(0.0, 0.09, 0.0),
            radius_m: 0.03,
        };
        let g = Geometry::new(m, NormalMethod::PlanarFitAuto, Some(roi)).unwrap();
        assert!(
            !g.can_self_shadow,
            "sphere: elevation {}°",
            g.shadow_elevation_deg
        );
    }

    #[test]
    fn convex_patches_with_scan_noise_are_convex() {
        // 0.1 mm per coordinate, the default scene's scanner noise, on 1 mm edges: ten times the
        // edge's share of noise a 3 mm scan has.
        let g = cylinder_scene_geometry(1e-4);
        assert!(
            !g.can_self_shadow,
            "cylinder: elevation {}°",
            g.shadow_elevation_deg
        );
        let mut m = uv_sphere(0.09, 100, 200);
        add_noise(&mut m, 1e-4, 3);
        let roi = Roi {
            centre_m: DVec3::new(0.09, 0.0, 0.0),
            radius_m: 0.03,
        };
        let g = Geometry::new(m, NormalMethod::PlanarFitAuto, Some(roi)).unwrap();
        assert!(
            !g.can_self_shadow,
            "sphere: elevation {}°",
            g.shadow_elevation_deg
        );
    }

    #[test]
    fn head_forehead_region() {
        // The default scene's head scan (3 mm spacing, 0.1 mm noise) and forehead region.
        let scene = skinbrdf_synth::Scene::load("default").unwrap();
        let rig = skinbrdf_synth::layout::build_rig(&scene);
        let mut m = rig.shape.tessellate(
            scene.geometry.scan_spacing_m,
            (-80f64.to_radians(), 80f64.to_radians()),
            (-35f64.to_radians(), 75f64.to_radians()),
        );
        add_noise(&mut m, scene.geometry.scan_noise_m, 1);
        let roi = Roi {
            centre_m: rig.roi_centre_head,
            radius_m: scene.geometry.roi_radius_m,
        };
        let g = Geometry::new(m, NormalMethod::PlanarFitAuto, Some(roi)).unwrap();
        // The brow ridge (4 mm) leaves a valley at the region's lower edge: seen from there the
        // forehead above rises ~5° over the tangent plane. It can shadow light arriving within
        // ~5° of the surface, i.e. only samples at θ_i > ~85°: none kept at the default 75°
        // grazing limit, some at 85°.
        let e = g.shadow_elevation_deg;
        assert!(e > 3.0 && e < 8.0, "head: elevation {e}°");
        assert!(!g.can_self_shadow && !g.can_shadow_within(75.0), "{e}°");
        assert!(g.can_shadow_within(85.0), "{e}°");
    }

    #[test]
    fn empty_region_is_an_error() {
        let m = uv_sphere(0.1, 10, 20);
        let roi = Roi {
            centre_m: DVec3::new(5.0, 0.0, 0.0),
            radius_m: 0.01,
        };
        assert!(matches!(
            Geometry::new(m, NormalMethod::Vertex, Some(roi)),
            Err(DerenderError::EmptyRegion)
        ));
    }
}
