//! The sample's geometry prepared for derendering: the scan, its BVH, its shading normals, the
//! region of interest and whether the geometry can shadow the region at all.
//!
//! **Convexity test (skipping shadow rays).** A point `p` of the region with normal `n` lit from
//! a direction with `n·w_i > 0` can only be shadowed by geometry lying in front of its tangent
//! plane. [`Geometry::new`] checks, for a sample of up to [`CONVEXITY_SAMPLE`] region vertices
//! (evenly spread), that every vertex of the whole mesh lies behind that vertex's tangent plane
//! within [`Geometry::convexity_tol_m`] (three times the scan's estimated noise, at least
//! [`MIN_CONVEXITY_TOL_M`]). When it holds the region is convex as far as lighting goes and no
//! shadow ray is cast; the report says so. Geometry within the tolerance can only shadow at
//! angles beyond the grazing limit. When it fails (a nose, a brow, hair in front of the tangent
//! plane) every kept sample gets a shadow ray.

use std::time::{Duration, Instant};

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use skinbrdf_core::TriMesh;
use skinbrdf_mesh::{BuildQuality, MeshBvh, NormalMethod, SurfaceNormals};

use crate::DerenderError;

/// Region vertices tested for convexity.
pub const CONVEXITY_SAMPLE: usize = 512;
/// Smallest tolerance of the convexity test (10 µm: below any scan's noise).
pub const MIN_CONVEXITY_TOL_M: f64 = 1e-5;

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
    /// Whether the region can be shadowed by the geometry (see the module docs).
    pub can_self_shadow: bool,
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
        let can_self_shadow =
            !region_is_convex(&mesh, &normals.normals, &roi_vertices, convexity_tol_m);
        Ok(Self {
            mesh,
            bvh,
            normals,
            roi,
            can_self_shadow,
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

fn region_is_convex(mesh: &TriMesh, normals: &[Vec3], roi: &[u32], tol_m: f64) -> bool {
    let step = (roi.len() / CONVEXITY_SAMPLE).max(1);
    let tol = tol_m as f32;
    roi.par_iter().step_by(step).all(|&i| {
        let p = mesh.positions[i as usize];
        let n = normals[i as usize];
        // Relative to p so f32 keeps micrometres.
        mesh.positions.iter().all(|q| (*q - p).dot(n) <= tol)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
