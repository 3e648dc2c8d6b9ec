//! Surface normals for shading: a local planar fit over a radius (the method's remedy for scan
//! noise), or area-weighted vertex normals.
//!
//! **Planar fit.** For each vertex `p`, the scan vertices within radius `r` of `p` are fitted
//! with a plane by principal component analysis: the normal is the eigenvector of the smallest
//! eigenvalue of their covariance (nalgebra's symmetric eigen-solver, in f64 about the
//! neighbourhood mean, so it stays accurate for millimetre-sized neighbourhoods at metre
//! coordinates). It is oriented to agree with the area-weighted vertex normal (the faces'
//! winding). On a surface with curvature radius `R` the fit is unbiased at the centre of a
//! symmetric neighbourhood; at a boundary it tilts by about `r / (2R)`. Vertices with fewer
//! than [`MIN_FIT_POINTS`] neighbours, or a neighbourhood that is a line rather than a patch,
//! fall back to the vertex normal, and are counted.
//!
//! **Radius from the noise.** [`estimate_noise`] fits planes at a small radius (three median
//! edge lengths) on a sample of vertices and takes the median RMS residual as the scan noise
//! `σ`. A plane fitted to `N` points with noise `σ` spread over a disc of radius `r` tilts by
//! about `σ / (r √(N/4))` (the RMS lever arm of a uniform disc is `r/2`); with `N = π r² / a`
//! (`a` the area per vertex) the radius that brings the tilt to `target` is
//! `r = (2 σ √a / (target √π))^(1/2)`, clamped to `[2, 40]` median edges and at most
//! [`MAX_RADIUS_M`] so curvature bias stays small.
//!
//! Normals at a ray hit interpolate the per-vertex fitted normals barycentrically
//! ([`SurfaceNormals::at`]).

use std::collections::HashMap;

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use skinbrdf_core::TriMesh;

use crate::bvh::Hit;
use crate::error::MeshError;

/// Fewest neighbours (the vertex included) a plane fit needs; fewer falls back.
pub const MIN_FIT_POINTS: usize = 4;

/// Upper bound on an automatically chosen fit radius: a forehead's curvature radius is ~8 cm,
/// so a 12 mm disc keeps the boundary tilt `r / 2R` below ~4°, and the centre unbiased.
pub const MAX_RADIUS_M: f64 = 0.012;

/// Normal-direction noise an automatic radius aims for: 0.005 rad keeps the relative error of
/// `cos θ` below 1% up to θ = 60°.
pub const TARGET_NORMAL_NOISE_RAD: f64 = 0.005;

/// How the shading normals are computed.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum NormalMethod {
    /// Area-weighted average of the adjacent face normals.
    Vertex,
    /// Plane fit over a given radius, metres.
    PlanarFit {
        /// Neighbourhood radius, metres.
        radius_m: f64,
    },
    /// Plane fit with the radius estimated from the scan's noise.
    PlanarFitAuto,
}

impl std::fmt::Display for NormalMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Vertex => write!(f, "vertex normals"),
            Self::PlanarFit { radius_m } => {
                write!(f, "plane fit over {:.2} mm", radius_m * 1e3)
            }
            Self::PlanarFitAuto => write!(f, "plane fit, radius from the scan's noise"),
        }
    }
}

/// The scan's noise and the fit radius it suggests.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct NoiseEstimate {
    /// Median edge length, metres.
    pub median_edge_m: f64,
    /// Mean area per vertex, square metres.
    pub area_per_vertex_m2: f64,
    /// Median RMS distance of vertices from their local plane, metres.
    pub noise_rms_m: f64,
    /// Radius that brings the normal noise to [`TARGET_NORMAL_NOISE_RAD`] (clamped).
    pub suggested_radius_m: f64,
    /// Expected normal noise at the suggested radius, radians.
    pub expected_normal_noise_rad: f64,
}

/// Per-vertex shading normals and how they were made.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceNormals {
    /// Unit normal per vertex.
    pub normals: Vec<Vec3>,
    /// The method used.
    pub method: NormalMethod,
    /// Fit radius actually used (0 for vertex normals).
    pub radius_m: f64,
    /// Vertices that fell back to the vertex normal (too few neighbours or a degenerate patch).
    pub fallbacks: usize,
    /// Mean neighbours per fit.
    pub mean_neighbours: f64,
    /// The noise estimate, when the radius was chosen from it.
    pub noise: Option<NoiseEstimate>,
}

impl SurfaceNormals {
    /// Computes normals for a mesh.
    pub fn compute(mesh: &TriMesh, method: NormalMethod) -> Result<Self, MeshError> {
        let vertex = area_weighted_vertex_normals(mesh);
        match method {
            NormalMethod::Vertex => Ok(Self {
                normals: vertex,
                method,
                radius_m: 0.0,
                fallbacks: 0,
                mean_neighbours: 0.0,
                noise: None,
            }),
            NormalMethod::PlanarFit { radius_m } => {
                if !(radius_m.is_finite() && radius_m > 0.0) {
                    return Err(MeshError::InvalidParameter {
                        field: "radius_m",
                        reason: format!("fit radius must be positive and finite, got {radius_m}"),
                    });
                }
                let (normals, fallbacks, mean) = planar_fit(mesh, &vertex, radius_m);
                Ok(Self {
                    normals,
                    method,
                    radius_m,
                    fallbacks,
                    mean_neighbours: mean,
                    noise: None,
                })
            }
            NormalMethod::PlanarFitAuto => {
                let noise = estimate_noise(mesh);
                let (normals, fallbacks, mean) =
                    planar_fit(mesh, &vertex, noise.suggested_radius_m);
                Ok(Self {
                    normals,
                    method,
                    radius_m: noise.suggested_radius_m,
                    fallbacks,
                    mean_neighbours: mean,
                    noise: Some(noise),
                })
            }
        }
    }

    /// The interpolated unit normal at a hit (barycentric blend of the corner normals); falls
    /// back to the face normal if the blend cancels.
    pub fn at(&self, mesh: &TriMesh, hit: &Hit) -> Vec3 {
        let [a, b, c] = mesh.indices[hit.triangle as usize];
        let w0 = 1.0 - hit.u - hit.v;
        let n = self.normals[a as usize] * w0
            + self.normals[b as usize] * hit.u
            + self.normals[c as usize] * hit.v;
        n.try_normalize().unwrap_or_else(|| {
            mesh.face_normal_area2(hit.triangle as usize)
                .normalize_or_zero()
        })
    }
}

/// Area-weighted vertex normals (unit; zero-area neighbourhoods give +z).
pub fn area_weighted_vertex_normals(mesh: &TriMesh) -> Vec<Vec3> {
    let mut acc = vec![DVec3::ZERO; mesh.positions.len()];
    for (t, tri) in mesh.indices.iter().enumerate() {
        let n = mesh.face_normal_area2(t).as_dvec3();
        for &v in tri {
            acc[v as usize] += n;
        }
    }
    acc.into_iter()
        .map(|n| n.try_normalize().unwrap_or(DVec3::Z).as_vec3())
        .collect()
}

/// A uniform grid over the vertices for radius queries.
struct Grid {
    cell_m: f64,
    cells: HashMap<[i32; 3], Vec<u32>>,
}

impl Grid {
    fn new(points: &[Vec3], cell_m: f64) -> Self {
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            cells
                .entry(Self::key(p.as_dvec3(), cell_m))
                .or_default()
                .push(i as u32);
        }
        Self { cell_m, cells }
    }

    fn key(p: DVec3, cell_m: f64) -> [i32; 3] {
        (p / cell_m).floor().as_ivec3().to_array()
    }

    fn for_each_within(&self, points: &[Vec3], q: DVec3, r: f64, mut f: impl FnMut(DVec3)) {
        let k = Self::key(q, self.cell_m);
        let r2 = r * r;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if let Some(list) = self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                        for &i in list {
                            let p = points[i as usize].as_dvec3();
                            if p.distance_squared(q) <= r2 {
                                f(p);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Plane fit of the points: `(unit normal, rms residual)`, or `None` when degenerate.
fn fit_plane(points: &[DVec3]) -> Option<(DVec3, f64)> {
    if points.len() < 3 {
        return None;
    }
    let mean = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let mut c = nalgebra::Matrix3::<f64>::zeros();
    for p in points {
        let d = *p - mean;
        let v = nalgebra::Vector3::new(d.x, d.y, d.z);
        c += v * v.transpose();
    }
    c /= points.len() as f64;
    let eig = c.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let (l0, l1) = (eig.eigenvalues[order[0]], eig.eigenvalues[order[1]]);
    // A line, not a patch: the second eigenvalue is no larger than the smallest's noise.
    if l1.is_nan() || l1 <= 1e-6 * eig.eigenvalues[order[2]] || l1 <= 0.0 {
        return None;
    }
    let v = eig.eigenvectors.column(order[0]);
    let n = DVec3::new(v[0], v[1], v[2]).try_normalize()?;
    Some((n, l0.max(0.0).sqrt()))
}

fn planar_fit(mesh: &TriMesh, vertex: &[Vec3], radius_m: f64) -> (Vec<Vec3>, usize, f64) {
    let grid = Grid::new(&mesh.positions, radius_m);
    let results: Vec<(Vec3, bool, usize)> = mesh
        .positions
        .par_iter()
        .enumerate()
        .map_init(Vec::new, |buf, (i, p)| {
            buf.clear();
            grid.for_each_within(&mesh.positions, p.as_dvec3(), radius_m, |q| buf.push(q));
            let fallback = (vertex[i], true, buf.len());
            if buf.len() < MIN_FIT_POINTS {
                return fallback;
            }
            match fit_plane(buf) {
                Some((n, _)) => {
                    let n = if n.dot(vertex[i].as_dvec3()) < 0.0 {
                        -n
                    } else {
                        n
                    };
                    (n.as_vec3(), false, buf.len())
                }
                None => fallback,
            }
        })
        .collect();
    let fallbacks = results.iter().filter(|r| r.1).count();
    let mean = results.iter().map(|r| r.2 as f64).sum::<f64>() / results.len().max(1) as f64;
    (results.into_iter().map(|r| r.0).collect(), fallbacks, mean)
}

/// Estimates the scan's noise and a fit radius (see the module docs).
pub fn estimate_noise(mesh: &TriMesh) -> NoiseEstimate {
    let mut edges: Vec<f64> = mesh
        .indices
        .iter()
        .step_by((mesh.indices.len() / 20_000).max(1))
        .flat_map(|t| {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize].as_dvec3());
            [a.distance(b), b.distance(c), c.distance(a)]
        })
        .collect();
    edges.sort_by(f64::total_cmp);
    let median_edge_m = edges.get(edges.len() / 2).copied().unwrap_or(0.0).max(1e-9);
    let area: f64 = (0..mesh.indices.len())
        .map(|t| 0.5 * mesh.face_normal_area2(t).as_dvec3().length())
        .sum();
    let area_per_vertex_m2 = (area / mesh.positions.len().max(1) as f64).max(1e-18);
    let r0 = 3.0 * median_edge_m;
    let grid = Grid::new(&mesh.positions, r0);
    let step = (mesh.positions.len() / 2000).max(1);
    let mut rms: Vec<f64> = mesh
        .positions
        .par_iter()
        .step_by(step)
        .filter_map(|p| {
            let mut buf = Vec::new();
            grid.for_each_within(&mesh.positions, p.as_dvec3(), r0, |q| buf.push(q));
            if buf.len() < MIN_FIT_POINTS + 2 {
                return None;
            }
            fit_plane(&buf).map(|(_, r)| r)
        })
        .collect();
    rms.sort_by(f64::total_cmp);
    let noise_rms_m = rms.get(rms.len() / 2).copied().unwrap_or(0.0);
    let raw = (2.0 * noise_rms_m * area_per_vertex_m2.sqrt()
        / (TARGET_NORMAL_NOISE_RAD * std::f64::consts::PI.sqrt()))
    .sqrt();
    let suggested_radius_m = raw
        .max(2.0 * median_edge_m)
        .min(40.0 * median_edge_m)
        .min(MAX_RADIUS_M)
        .max(1.5 * median_edge_m);
    let n = std::f64::consts::PI * suggested_radius_m.powi(2) / area_per_vertex_m2;
    let expected_normal_noise_rad = noise_rms_m / (suggested_radius_m * (n / 4.0).sqrt());
    NoiseEstimate {
        median_edge_m,
        area_per_vertex_m2,
        noise_rms_m,
        suggested_radius_m,
        expected_normal_noise_rad,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sphere patch (z > 0 cap) of radius `r`, as a grid in (theta, phi), with optional
    /// deterministic radial noise.
    pub(crate) fn sphere_cap(radius: f32, n: u32, noise: f32) -> TriMesh {
        let mut positions = Vec::new();
        let mut s = 12345u64;
        let mut rnd = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 11) as f64 / (1u64 << 53) as f64) as f32 - 0.5
        };
        for j in 0..=n {
            for i in 0..=n {
                let x = (i as f32 / n as f32 - 0.5) * radius;
                let y = (j as f32 / n as f32 - 0.5) * radius;
                let z = (radius * radius - x * x - y * y).sqrt();
                let p = Vec3::new(x, y, z);
                positions.push(p * (1.0 + noise * rnd() * 3.46 / radius));
            }
        }
        let mut indices = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                indices.push([a, a + 1, a + n + 2]);
                indices.push([a, a + n + 2, a + n + 1]);
            }
        }
        TriMesh {
            positions,
            indices,
            normals: None,
        }
    }

    fn max_error_deg(mesh: &TriMesh, normals: &[Vec3], interior: f32) -> f64 {
        mesh.positions
            .iter()
            .zip(normals)
            .filter(|(p, _)| p.x.abs() < interior && p.y.abs() < interior)
            .map(|(p, n)| p.normalize().dot(*n).clamp(-1.0, 1.0).acos().to_degrees() as f64)
            .fold(0.0, f64::max)
    }

    #[test]
    fn planar_fit_recovers_sphere_normals() {
        let m = sphere_cap(0.08, 60, 0.0);
        let s = SurfaceNormals::compute(&m, NormalMethod::PlanarFit { radius_m: 0.004 }).unwrap();
        assert_eq!(s.fallbacks, 0);
        // Interior vertices (symmetric neighbourhoods): unbiased to well under a degree.
        assert!(max_error_deg(&m, &s.normals, 0.03) < 0.2);
    }

    #[test]
    fn planar_fit_beats_vertex_normals_on_noisy_scans() {
        let m = sphere_cap(0.08, 80, 0.0002);
        let v = SurfaceNormals::compute(&m, NormalMethod::Vertex).unwrap();
        let noise = estimate_noise(&m);
        assert!(
            noise.noise_rms_m > 0.00005 && noise.noise_rms_m < 0.0004,
            "{noise:?}"
        );
        let f = SurfaceNormals::compute(&m, NormalMethod::PlanarFitAuto).unwrap();
        let ev = max_error_deg(&m, &v.normals, 0.025);
        let ef = max_error_deg(&m, &f.normals, 0.025);
        assert!(ef < 0.5 * ev, "fit {ef} deg vs vertex {ev} deg, {noise:?}");
        assert!(f.radius_m > noise.median_edge_m);
    }

    #[test]
    fn hit_normal_interpolates_and_bad_radius_is_refused() {
        let m = sphere_cap(0.08, 20, 0.0);
        let s = SurfaceNormals::compute(&m, NormalMethod::Vertex).unwrap();
        let h = Hit {
            t_m: 1.0,
            triangle: 5,
            u: 0.25,
            v: 0.25,
        };
        let n = s.at(&m, &h);
        assert!((n.length() - 1.0).abs() < 1e-6);
        let [a, b, c] = m.triangle(5);
        let p = a * 0.5 + b * 0.25 + c * 0.25;
        assert!(n.dot(p.normalize()) > 0.999);
        assert!(matches!(
            SurfaceNormals::compute(&m, NormalMethod::PlanarFit { radius_m: -1.0 }),
            Err(MeshError::InvalidParameter {
                field: "radius_m",
                ..
            })
        ));
    }
}
