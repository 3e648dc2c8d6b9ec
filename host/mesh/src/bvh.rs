//! Ray casting against a triangle mesh with an obvhs compressed wide BVH (CWBVH, 8-wide).
//!
//! Build once ([`MeshBvh::build`]), trace many: closest hit ([`MeshBvh::intersect`]), any hit
//! below a distance ([`MeshBvh::occluded`], for shadow rays) and batched, rayon-parallel versions
//! of both ([`MeshBvh::intersect_batch`], [`MeshBvh::occluded_batch`]).
//!
//! The BVH works in the mesh's frame and in `f32` (obvhs's precision). For a head a metre from
//! the camera that is a resolution of about 0.1 µm along the ray, far below any scan's noise.
//! Triangles are stored in BVH leaf order (no indirection in the inner loop) in the
//! precomputed-edge layout obvhs traverses fastest; [`Hit::triangle`] is the index in the input
//! mesh.
//!
//! Intersection is Möller–Trumbore (not watertight): a ray through a shared edge can, rarely,
//! pass between the two triangles. Callers that must never see such a leak (derendering) reject
//! hits whose geometric normal faces away from the ray, which is where a leak through a closed
//! scan lands. Degenerate (zero-area) triangles are never hit.

use std::time::{Duration, Instant};

use glam::{Vec3, Vec3A};
use obvhs::{
    cwbvh::{builder::build_cwbvh_from_tris, CwBvh},
    ray::{Ray, RayHit},
    rt_triangle::RtTriangle,
    triangle::Triangle,
    BvhBuildParams,
};
use rayon::prelude::*;
use skinbrdf_core::TriMesh;

use crate::error::MeshError;

/// How much time to spend building for faster traversal: the obvhs build presets, cheapest
/// first. Sweep them with [`BuildQuality::ALL`]; parse them from their [`BuildQuality::name`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BuildQuality {
    /// obvhs `fastest_build`: no reinsertion, one triangle per leaf.
    Fastest,
    /// obvhs `very_fast_build`.
    VeryFast,
    /// Quick build, slower traversal (obvhs `fast_build`): meshes rebuilt often.
    Fast,
    /// About Embree's build time with faster traversal (obvhs `medium_build`). The default.
    #[default]
    Medium,
    /// Spatial pre-splits and more reinsertion (obvhs `slow_build`): one mesh traced a lot.
    High,
    /// obvhs `very_slow_build`: full reinsertion.
    VeryHigh,
}

impl BuildQuality {
    /// Every preset, cheapest build first (for sweeps).
    pub const ALL: [Self; 6] = [
        Self::Fastest,
        Self::VeryFast,
        Self::Fast,
        Self::Medium,
        Self::High,
        Self::VeryHigh,
    ];

    /// The obvhs build parameters of the preset.
    pub const fn params(self) -> BvhBuildParams {
        match self {
            Self::Fastest => BvhBuildParams::fastest_build(),
            Self::VeryFast => BvhBuildParams::very_fast_build(),
            Self::Fast => BvhBuildParams::fast_build(),
            Self::Medium => BvhBuildParams::medium_build(),
            Self::High => BvhBuildParams::slow_build(),
            Self::VeryHigh => BvhBuildParams::very_slow_build(),
        }
    }

    /// Short name (`fastest`, `very_fast`, `fast`, `medium`, `high`, `very_high`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Fastest => "fastest",
            Self::VeryFast => "very_fast",
            Self::Fast => "fast",
            Self::Medium => "medium",
            Self::High => "high",
            Self::VeryHigh => "very_high",
        }
    }
}

impl std::str::FromStr for BuildQuality {
    type Err = MeshError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|q| q.name() == s.trim().replace('-', "_"))
            .ok_or_else(|| MeshError::InvalidParameter {
                field: "bvh build quality",
                reason: format!(
                    "`{s}` is not one of {}",
                    Self::ALL.map(Self::name).join(", ")
                ),
            })
    }
}

/// A ray in the mesh's frame. `dir` need not be unit length; `t` is measured in units of `dir`
/// (metres when `dir` is unit length).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshRay {
    /// Origin, metres.
    pub origin: Vec3,
    /// Direction (unit length for `t` in metres).
    pub dir: Vec3,
    /// Only hits with `t <= t_max` count.
    pub t_max: f32,
}

impl MeshRay {
    /// A ray with an unbounded range.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir,
            t_max: f32::INFINITY,
        }
    }
}

/// The closest intersection of a ray with the mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit (metres for a unit direction).
    pub t_m: f32,
    /// Index of the triangle in the input mesh.
    pub triangle: u32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex (the first has `1 - u - v`).
    pub v: f32,
}

/// A BVH over a [`TriMesh`], ready for ray casting.
#[derive(Clone)]
pub struct MeshBvh {
    pub(crate) bvh: CwBvh,
    /// Triangles in BVH leaf order.
    pub(crate) tris: Vec<RtTriangle>,
    /// Input-mesh index of each entry of `tris`.
    pub(crate) tri_ids: Vec<u32>,
    /// Original corners, input order (for barycentrics in the exact input coordinates).
    pub(crate) corners: Vec<[Vec3A; 3]>,
    /// Corners in BVH leaf order (`v0`, `v1 - v0`, `v2 - v0`) for the coherent tracer.
    pub(crate) leaf_tris: Vec<[Vec3A; 3]>,
    quality: BuildQuality,
    build_time: Duration,
}

impl std::fmt::Debug for MeshBvh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshBvh")
            .field("triangles", &self.corners.len())
            .field("nodes", &self.bvh.nodes.len())
            .field("quality", &self.quality)
            .field("build_time", &self.build_time)
            .finish()
    }
}

/// Batches smaller than this are traced on the calling thread (rayon's overhead dominates).
const PARALLEL_MIN_RAYS: usize = 4096;

impl MeshBvh {
    /// Builds the BVH. Fails on a mesh that breaks [`TriMesh::validate`] (empty, non-finite
    /// vertices, indices out of range): such a mesh would corrupt the BVH's bounds.
    pub fn build(mesh: &TriMesh, quality: BuildQuality) -> Result<Self, MeshError> {
        let problems = mesh.validate();
        if !problems.is_empty() {
            return Err(MeshError::Invalid { problems });
        }
        let start = Instant::now();
        let corners: Vec<[Vec3A; 3]> = (0..mesh.indices.len())
            .map(|t| mesh.triangle(t).map(Vec3A::from))
            .collect();
        let tris: Vec<Triangle> = corners
            .iter()
            .map(|&[v0, v1, v2]| Triangle { v0, v1, v2 })
            .collect();
        let mut core = Duration::ZERO;
        let bvh = build_cwbvh_from_tris(&tris, quality.params(), &mut core);
        let tri_ids = bvh.primitive_indices.clone();
        let leaf_tris = tri_ids
            .iter()
            .map(|&i| {
                let [a, b, c] = corners[i as usize];
                [a, b - a, c - a]
            })
            .collect();
        let tris = tri_ids
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        Ok(Self {
            bvh,
            tris,
            tri_ids,
            corners,
            leaf_tris,
            quality,
            build_time: start.elapsed(),
        })
    }

    /// The build preset used.
    pub fn quality(&self) -> BuildQuality {
        self.quality
    }

    /// Wall time the build took.
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Number of triangles of the input mesh.
    pub fn triangle_count(&self) -> usize {
        self.corners.len()
    }

    pub(crate) fn obvhs_ray(origin: Vec3, dir: Vec3, t_max: f32) -> Option<Ray> {
        if !(origin.is_finite() && dir.is_finite()) || dir == Vec3::ZERO || t_max.is_nan() {
            return None;
        }
        // obvhs picks the child order from `dir < 0` but the slab inverse from the sign bit:
        // a `-0.0` component (e.g. `-Vec3::Z`) disagrees and misses everything. `x + 0.0` maps
        // -0.0 to +0.0 and leaves every other value unchanged.
        let dir = Vec3::new(dir.x + 0.0, dir.y + 0.0, dir.z + 0.0);
        Some(Ray::new(origin.into(), dir.into(), 0.0, t_max))
    }

    /// The closest hit with `0 <= t <= t_max`, or `None`. Rays with a non-finite origin or
    /// direction, or a zero direction, hit nothing.
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        let ray = Self::obvhs_ray(origin, dir, t_max)?;
        let mut hit = RayHit::none();
        let tris = &self.tris;
        if !self
            .bvh
            .ray_traverse(ray, &mut hit, |r, id| tris[id].intersect(r))
        {
            return None;
        }
        Some(self.hit_at(hit.primitive_id as usize, hit.t, ray.origin, ray.direction))
    }

    /// The [`Hit`] for a BVH slot hit at `t`.
    pub(crate) fn hit_at(&self, slot: usize, t_m: f32, origin: Vec3A, dir: Vec3A) -> Hit {
        let triangle = self.tri_ids[slot];
        let (u, v) = barycentric(&self.corners[triangle as usize], origin, dir);
        Hit {
            t_m,
            triangle,
            u,
            v,
        }
    }

    /// True when any triangle is hit with `0 <= t <= t_max` (shadow rays: start slightly off the
    /// surface and stop slightly short of the light).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        let Some(ray) = Self::obvhs_ray(origin, dir, t_max) else {
            return false;
        };
        let tris = &self.tris;
        !self
            .bvh
            .ray_traverse_miss(ray, |r, id| tris[id].intersect(r))
    }

    /// Closest hits of many rays, in parallel (rayon) for large batches.
    pub fn intersect_batch(&self, rays: &[MeshRay]) -> Vec<Option<Hit>> {
        let f = |r: &MeshRay| self.intersect(r.origin, r.dir, r.t_max);
        if rays.len() < PARALLEL_MIN_RAYS {
            rays.iter().map(f).collect()
        } else {
            rays.par_iter().with_min_len(256).map(f).collect()
        }
    }

    /// Occlusion of many rays, in parallel (rayon) for large batches.
    pub fn occluded_batch(&self, rays: &[MeshRay]) -> Vec<bool> {
        let f = |r: &MeshRay| self.occluded(r.origin, r.dir, r.t_max);
        if rays.len() < PARALLEL_MIN_RAYS {
            rays.iter().map(f).collect()
        } else {
            rays.par_iter().with_min_len(256).map(f).collect()
        }
    }
}

/// Barycentric weights `(u, v)` of the second and third corner where the ray meets the plane
/// of the triangle (Möller–Trumbore with `e1 = v1 - v0`, `e2 = v2 - v0`), clamped into the
/// triangle (the traversal already decided it is inside; clamping absorbs rounding).
pub(crate) fn barycentric(c: &[Vec3A; 3], origin: Vec3A, dir: Vec3A) -> (f32, f32) {
    let e1 = c[1] - c[0];
    let e2 = c[2] - c[0];
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return (0.0, 0.0);
    }
    let inv = 1.0 / det;
    let s = origin - c[0];
    let q = s.cross(e1);
    let u = (s.dot(p) * inv).clamp(0.0, 1.0);
    let v = (dir.dot(q) * inv).clamp(0.0, 1.0 - u);
    (u, v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use proptest::prelude::*;

    /// Brute-force closest hit in f64. Returns the hit (t, triangle) and whether the answer is
    /// ambiguous in f32 (a hit or near-miss within `EDGE` of an edge, or two hits within `EDGE`
    /// in t), in which case the BVH may legitimately disagree.
    fn brute_force(mesh: &TriMesh, o: DVec3, d: DVec3, t_max: f64) -> (Option<(f64, u32)>, bool) {
        const EDGE: f64 = 1e-4;
        let mut best: Option<(f64, u32)> = None;
        let mut ambiguous = false;
        let mut ts = Vec::new();
        for (ti, _) in mesh.indices.iter().enumerate() {
            let [a, b, c] = mesh.triangle(ti).map(|p| p.as_dvec3());
            let e1 = b - a;
            let e2 = c - a;
            let p = d.cross(e2);
            let det = e1.dot(p);
            let area = e1.cross(e2).length();
            if det.abs() < 1e-9 * area.max(1e-30) || area < 1e-12 {
                continue;
            }
            let inv = 1.0 / det;
            let s = o - a;
            let u = s.dot(p) * inv;
            let q = s.cross(e1);
            let v = d.dot(q) * inv;
            let t = e2.dot(q) * inv;
            let w = 1.0 - u - v;
            let margin = u.min(v).min(w);
            let in_range = t >= 0.0 && t <= t_max;
            let near_range = (t.abs() < EDGE) || ((t - t_max).abs() < EDGE);
            if margin.abs() < EDGE && (in_range || near_range) {
                ambiguous = true;
            }
            if margin >= 0.0 && near_range {
                ambiguous = true;
            }
            if margin >= 0.0 && in_range {
                ts.push(t);
                if best.is_none_or(|(bt, _)| t < bt) {
                    best = Some((t, ti as u32));
                }
            }
        }
        ts.sort_by(f64::total_cmp);
        if ts.windows(2).any(|w| w[1] - w[0] < EDGE) {
            ambiguous = true;
        }
        (best, ambiguous)
    }

    fn random_mesh(seed: u64, n_tris: usize) -> TriMesh {
        // Small xorshift so the test needs no RNG crate.
        let mut s = seed | 1;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f32 / (1u64 << 53) as f32
        };
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for t in 0..n_tris {
            let centre = Vec3::new(next(), next(), next()) * 2.0 - Vec3::ONE;
            for _ in 0..3 {
                positions.push(centre + (Vec3::new(next(), next(), next()) - 0.5) * 0.6);
            }
            let b = 3 * t as u32;
            indices.push([b, b + 1, b + 2]);
        }
        TriMesh {
            positions,
            indices,
            normals: None,
        }
    }

    fn unit(v: (f32, f32, f32)) -> Option<Vec3> {
        Vec3::new(v.0, v.1, v.2).try_normalize()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        #[test]
        fn closest_hit_matches_brute_force(
            seed in any::<u64>(),
            n_tris in 1usize..300,
            quality in proptest::sample::select(BuildQuality::ALL.to_vec()),
            rays in proptest::collection::vec(
                ((-1.5f32..1.5, -1.5f32..1.5, -1.5f32..1.5), (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0), 0.1f32..4.0, any::<bool>()),
                64,
            ),
        ) {
            let mesh = random_mesh(seed, n_tris);
            let bvh = MeshBvh::build(&mesh, quality).unwrap();
            let mut batch = Vec::new();
            for ((ox, oy, oz), d, t_max, axis_aligned) in rays {
                let Some(mut dir) = unit(d) else { continue };
                if axis_aligned {
                    // Exactly axis-aligned, with negative zeros where `-axis` makes them.
                    let a = dir.abs();
                    let axis = if a.x >= a.y && a.x >= a.z { Vec3::X } else if a.y >= a.z { Vec3::Y } else { Vec3::Z };
                    dir = if dir.dot(axis) < 0.0 { -axis } else { axis };
                }
                let origin = Vec3::new(ox, oy, oz);
                batch.push(MeshRay { origin, dir, t_max });
                let (bf, ambiguous) = brute_force(&mesh, origin.as_dvec3(), dir.as_dvec3(), t_max as f64);
                let hit = bvh.intersect(origin, dir, t_max);
                let occ = bvh.occluded(origin, dir, t_max);
                if ambiguous {
                    continue;
                }
                match (bf, hit) {
                    (None, None) => prop_assert!(!occ),
                    (Some((t, tri)), Some(h)) => {
                        prop_assert!((h.t_m as f64 - t).abs() < 1e-4, "t {} vs {}", h.t_m, t);
                        prop_assert_eq!(h.triangle, tri);
                        prop_assert!(occ);
                        // The barycentrics reproduce the hit point.
                        let [a, b, c] = mesh.triangle(tri as usize);
                        let p = a * (1.0 - h.u - h.v) + b * h.u + c * h.v;
                        prop_assert!((p - (origin + dir * h.t_m)).length() < 1e-3);
                    }
                    (bf, hit) => prop_assert!(false, "brute force {:?} vs bvh {:?}", bf, hit),
                }
            }
            // Batches agree with single rays.
            let singles: Vec<_> = batch.iter().map(|r| bvh.intersect(r.origin, r.dir, r.t_max)).collect();
            prop_assert_eq!(bvh.intersect_batch(&batch), singles);
            let occ: Vec<_> = batch.iter().map(|r| bvh.occluded(r.origin, r.dir, r.t_max)).collect();
            prop_assert_eq!(bvh.occluded_batch(&batch), occ);
        }
    }

    #[test]
    fn large_batch_runs_in_parallel_and_agrees() {
        let mesh = random_mesh(7, 2000);
        let bvh = MeshBvh::build(&mesh, BuildQuality::Medium).unwrap();
        let rays: Vec<MeshRay> = (0..10_000)
            .map(|i| {
                let x = (i % 100) as f32 / 50.0 - 1.0;
                let y = (i / 100) as f32 / 50.0 - 1.0;
                MeshRay::new(Vec3::new(x, y, -3.0), Vec3::Z)
            })
            .collect();
        let batch = bvh.intersect_batch(&rays);
        assert!(batch.iter().filter(|h| h.is_some()).count() > 1000);
        for (r, h) in rays.iter().zip(&batch).step_by(37) {
            assert_eq!(*h, bvh.intersect(r.origin, r.dir, r.t_max));
        }
    }

    #[test]
    fn invalid_mesh_is_rejected_with_its_problems() {
        let mesh = TriMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, f32::INFINITY, 0.0)],
            indices: vec![[0, 1, 2]],
            normals: None,
        };
        match MeshBvh::build(&mesh, BuildQuality::Fast) {
            Err(MeshError::Invalid { problems }) => {
                assert!(matches!(
                    problems[0],
                    skinbrdf_core::MeshError::NonFiniteVertex { index: 2, .. }
                ))
            }
            other => panic!("expected Invalid, got {other:?}"),
        }
        assert!(matches!(
            MeshBvh::build(&TriMesh::default(), BuildQuality::Fast),
            Err(MeshError::Invalid { .. })
        ));
    }

    #[test]
    fn degenerate_rays_and_triangles_hit_nothing() {
        let mesh = TriMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0, Vec3::Y],
            indices: vec![[0, 1, 2], [0, 1, 3]],
            normals: None,
        };
        let bvh = MeshBvh::build(&mesh, BuildQuality::Fast).unwrap();
        let o = Vec3::new(0.2, 0.2, 1.0);
        assert_eq!(bvh.intersect(o, Vec3::ZERO, 10.0), None);
        assert_eq!(bvh.intersect(o, Vec3::new(f32::NAN, 0.0, -1.0), 10.0), None);
        let h = bvh.intersect(o, -Vec3::Z, 10.0).unwrap();
        assert_eq!(h.triangle, 1);
        assert!((h.t_m - 1.0).abs() < 1e-6);
        // Along the degenerate (collinear) triangle's line: only the real triangle can be hit.
        assert!(bvh
            .intersect(Vec3::new(1.5, 0.0, 1.0), -Vec3::Z, 10.0)
            .is_none_or(|h| h.triangle == 1));
        // Negative-zero components (the obvhs octant pitfall) and positive zeros agree.
        assert_eq!(bvh.intersect(o, Vec3::new(0.0, 0.0, -1.0), 10.0), Some(h));
        assert!(!bvh.occluded(o, -Vec3::Z, 0.5));
        assert!(bvh.occluded(o, -Vec3::Z, 1.5));
    }
}
