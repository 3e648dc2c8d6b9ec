//! Coherent ray casting: many rays from one origin laid out on a grid (a camera's pixels).
//!
//! [`MeshBvh::intersect_grid`] answers exactly the question [`MeshBvh::intersect`] answers for
//! each ray (closest hit with `0 <= t <= t_max`, Möller–Trumbore), but shares the work of rays
//! that start at one point and point in nearby directions — every camera ray of an image:
//!
//! 1. **Tiles.** The grid is cut into super-tiles of [`SUPER_TILE_PX`]² rays, each cut into
//!    tiles of [`TILE_PX`]² rays; bands of super-tiles run in parallel (rayon).
//! 2. **Frustum.** For a tile, `c` is the mean direction and `(u, v)` complete an orthonormal
//!    basis; every ray `d` has tangent coordinates `(d·u / d·c, d·v / d·c)` and the tile's
//!    rectangle `[a0, a1] x [b0, b1]` of them (padded by [`FRUSTUM_PAD`]) bounds the tile by
//!    four planes through the origin, normals `u - a0 c`, `a1 c - u`, `v - b0 c`, `b1 c - v`
//!    (a point `p` is inside when `(p - o)·n >= 0` for all four; together they imply
//!    `(p - o)·c >= 0`, so nothing behind the origin is kept).
//! 3. **Candidates.** One walk of the CWBVH per super-tile keeps the children whose (conservatively
//!    quantized) boxes are not entirely behind a plane, and the leaf triangles not entirely
//!    behind a plane; each tile keeps those of the super-tile's triangles not behind one of its
//!    own planes. Culling only removes triangles no ray of the tile can hit, so the result is
//!    the per-ray closest hit.
//! 4. **Rays against candidates.** The origin is common, so `s = o - v0`, `q = s x e1` and
//!    `t·det = e2·q` are computed once per candidate; per ray and triangle only `p = d x e2`
//!    and three dot products remain, four triangles at a time in SIMD lanes (`glam::Vec4`).
//!
//! A tile falls back to per-ray BVH traversal when its rays spread too far from their mean
//! (cosine below [`MIN_TILE_COS`]) or it gathers more than [`MAX_TILE_CANDIDATES`] triangles
//! (rays grazing along a surface), where testing every candidate would cost more than a
//! traversal. Rays with a non-finite or zero direction hit nothing (use them for pixels that
//! need no ray). Scratch buffers are per band (no allocation per ray).

use glam::{Vec3, Vec3A, Vec4};

use crate::bvh::{Hit, MeshBvh};
use crate::tiled::{in_bands, trace_tiles, Cull, TileBuffers, TileCounts, TileScratch, TileTracer};

/// Tile side, rays: the rays tested together against one candidate list.
pub const TILE_PX: usize = 8;
/// Super-tile side, rays: one BVH walk per super-tile; its candidates are re-culled per tile.
pub const SUPER_TILE_PX: usize = 16;
/// More candidates than this in a super-tile and it is traced ray by ray.
pub const MAX_SUPER_CANDIDATES: usize = 4096;
/// Padding of a tile's tangent rectangle (1e-5 of the distance: 40x the f32 rounding of the
/// plane tests, a few hundredths of a pixel for any camera).
pub const FRUSTUM_PAD: f32 = 1e-5;
/// Rays of a tile must stay within about 78° of the tile's mean direction.
pub const MIN_TILE_COS: f32 = 0.2;
/// More candidate triangles than this and a tile is traced ray by ray.
pub const MAX_TILE_CANDIDATES: usize = 384;

/// Reusable buffers and counters of the coherent tracer (one per thread or band).
#[derive(Debug, Default, Clone)]
pub struct TraceScratch {
    bufs: TileBuffers<(usize, Vec3A)>,
    packs: Vec<Pack>,
    /// How its tiles were traced.
    pub counts: TileCounts,
}

/// Four candidate triangles in SIMD lanes, relative to the tile's origin.
#[derive(Debug, Clone, Copy)]
struct Pack {
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    s: [Vec4; 3],
    q: [Vec4; 3],
    /// `t · det`.
    tn: Vec4,
    slot: [u32; 4],
}

pub(crate) fn box_in_frustum(lo: Vec3A, hi: Vec3A, planes: &[Vec3A; 4]) -> bool {
    planes
        .iter()
        .all(|n| Vec3A::select(n.cmpge(Vec3A::ZERO), hi, lo).dot(*n) >= 0.0)
}

pub(crate) fn tri_in_frustum(a: Vec3A, b: Vec3A, c: Vec3A, planes: &[Vec3A; 4]) -> bool {
    planes
        .iter()
        .all(|n| n.dot(a) >= 0.0 || n.dot(b) >= 0.0 || n.dot(c) >= 0.0)
}

/// The four planes (through the origin, inward normals) bounding a set of rays, or `None`
/// when a ray is too far from their mean direction.
fn frustum(tile: &[(usize, Vec3A)]) -> Option<[Vec3A; 4]> {
    frustum_with_axis(tile).map(|(planes, _)| planes)
}

/// [`frustum`] with its unit axis `c` (the normalised sum of the ray directions).
pub(crate) fn frustum_with_axis(tile: &[(usize, Vec3A)]) -> Option<([Vec3A; 4], Vec3A)> {
    // The axis only has to be some direction every ray is close to: the planes below bound
    // the rays' slopes about whichever axis is used (for a ray `d` with slope `a = d·u / d·c`
    // at least `a0`, `(u - c a0)·d = d·c (a - a0) >= 0`). The plain sum of the directions
    // (unit or nearly so: camera rays) serves and saves a normalisation per ray.
    let c = tile
        .iter()
        .fold(Vec3A::ZERO, |acc, (_, d)| acc + *d)
        .normalize_or_zero();
    if c == Vec3A::ZERO {
        return None;
    }
    let (u, v) = c.any_orthonormal_pair();
    let (mut a0, mut a1, mut b0, mut b1) = (
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
    );
    let min_cos2 = MIN_TILE_COS * MIN_TILE_COS;
    for &(_, d) in tile {
        let k = d.dot(c);
        // k > MIN_TILE_COS |d| without the square root (both sides positive).
        if !k.is_finite() || k <= 0.0 || k * k <= min_cos2 * d.length_squared() {
            return None;
        }
        let ik = 1.0 / k;
        let (a, b) = (d.dot(u) * ik, d.dot(v) * ik);
        a0 = a0.min(a);
        a1 = a1.max(a);
        b0 = b0.min(b);
        b1 = b1.max(b);
    }
    Some((
        [
            u - c * (a0 - FRUSTUM_PAD),
            c * (a1 + FRUSTUM_PAD) - u,
            v - c * (b0 - FRUSTUM_PAD),
            c * (b1 + FRUSTUM_PAD) - v,
        ],
        c,
    ))
}

impl MeshBvh {
    /// Closest hits of rays from one `origin` whose directions `dirs` are laid out row-major on
    /// a grid `width` wide (a camera's pixels, or sub-pixel samples), in parallel over bands of
    /// tiles. Same answer as [`MeshBvh::intersect`] per ray (see the module docs); entries with
    /// a non-finite or zero direction get `None`.
    pub fn intersect_grid(
        &self,
        origin: Vec3,
        dirs: &[Vec3],
        width: usize,
        t_max: f32,
    ) -> Vec<Option<Hit>> {
        let mut out = vec![None; dirs.len()];
        if width == 0 {
            return out;
        }
        in_bands(
            dirs,
            &mut out,
            width,
            SUPER_TILE_PX,
            TraceScratch::default,
            |scratch, d, o| self.intersect_grid_into(origin, d, width, t_max, o, scratch),
        );
        out
    }

    /// [`MeshBvh::intersect_grid`] on the calling thread, into `out` (same length as `dirs`),
    /// with caller-owned scratch buffers: for callers that parallelize over bands themselves.
    pub fn intersect_grid_into(
        &self,
        origin: Vec3,
        dirs: &[Vec3],
        width: usize,
        t_max: f32,
        out: &mut [Option<Hit>],
        scratch: &mut TraceScratch,
    ) {
        let n = dirs.len().min(out.len());
        out.iter_mut().for_each(|h| *h = None);
        if width == 0 || !origin.is_finite() || t_max.is_nan() {
            return;
        }
        let rays = GridRays {
            bvh: self,
            origin: Vec3A::from(origin),
            dirs,
            t_max,
        };
        trace_tiles(&rays, n, width, scratch, out);
    }
}

/// The four planes of a tile's frustum (through the origin, inward normals).
struct Frustum([Vec3A; 4]);

impl Cull for Frustum {
    fn keeps_box(&self, lo: Vec3A, hi: Vec3A) -> bool {
        box_in_frustum(lo, hi, &self.0)
    }

    fn keeps_tri(&self, a: Vec3A, b: Vec3A, c: Vec3A) -> bool {
        tri_in_frustum(a, b, c, &self.0)
    }
}

/// Camera rays of one band: one origin, a direction per grid cell.
struct GridRays<'a> {
    bvh: &'a MeshBvh,
    origin: Vec3A,
    dirs: &'a [Vec3],
    t_max: f32,
}

impl TileScratch<(usize, Vec3A)> for TraceScratch {
    fn buffers(&mut self) -> &mut TileBuffers<(usize, Vec3A)> {
        &mut self.bufs
    }

    fn counts(&mut self) -> &mut TileCounts {
        &mut self.counts
    }
}

impl TileTracer for GridRays<'_> {
    type Ray = (usize, Vec3A);
    type Out = Option<Hit>;
    type Scratch = TraceScratch;
    type Cull = Frustum;
    const TILE_PX: usize = TILE_PX;
    const SUPER_TILE_PX: usize = SUPER_TILE_PX;
    const MAX_SUPER_CANDIDATES: usize = MAX_SUPER_CANDIDATES;
    const MAX_TILE_CANDIDATES: usize = MAX_TILE_CANDIDATES;

    fn bvh(&self) -> &MeshBvh {
        self.bvh
    }

    fn apex(&self) -> Vec3A {
        self.origin
    }

    /// The valid rays: finite, non-zero direction.
    fn ray(&self, i: usize) -> Option<(usize, Vec3A)> {
        let d = self.dirs[i];
        // -0.0 -> +0.0, as for single rays (obvhs's octant pitfall).
        (d.is_finite() && d != Vec3::ZERO).then(|| (i, Vec3A::new(d.x + 0.0, d.y + 0.0, d.z + 0.0)))
    }

    fn cull(&self, tile: &[(usize, Vec3A)]) -> Option<Frustum> {
        frustum(tile).map(Frustum)
    }

    fn trace_per_ray(&self, tile: &[(usize, Vec3A)], out: &mut [Option<Hit>]) {
        for &(i, d) in tile {
            out[i] = self.bvh.intersect(self.origin.into(), d.into(), self.t_max);
        }
    }

    /// Packs the candidates four to a SIMD lane group, then finds each ray's closest hit.
    fn trace_candidates(&self, sc: &mut TraceScratch, out: &mut [Option<Hit>]) {
        sc.packs.clear();
        for chunk in sc.bufs.cand.chunks(4) {
            let mut l = [[0.0f32; 13]; 4];
            let mut slot = [u32::MAX; 4];
            for (lane, &k) in chunk.iter().enumerate() {
                let [v0, e1, e2] = self.bvh.leaf_tris[k as usize];
                let s = self.origin - v0;
                let q = s.cross(e1);
                let tn = e2.dot(q);
                l[lane] = [
                    e1.x, e1.y, e1.z, e2.x, e2.y, e2.z, s.x, s.y, s.z, q.x, q.y, q.z, tn,
                ];
                slot[lane] = k;
            }
            for lane in l.iter_mut().skip(chunk.len()) {
                // Empty lane: zero edges (det = 0 never hits) and a NaN distance.
                lane[12] = f32::NAN;
            }
            let g = |j: usize| Vec4::new(l[0][j], l[1][j], l[2][j], l[3][j]);
            sc.packs.push(Pack {
                e1: [g(0), g(1), g(2)],
                e2: [g(3), g(4), g(5)],
                s: [g(6), g(7), g(8)],
                q: [g(9), g(10), g(11)],
                tn: g(12),
                slot,
            });
        }
        for &(i, d) in &sc.bufs.tile {
            let (dx, dy, dz) = (Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z));
            let mut best_t = self.t_max;
            let mut best_slot = u32::MAX;
            let (mut best_u, mut best_v) = (0.0f32, 0.0f32);
            for p in &sc.packs {
                let [e1x, e1y, e1z] = p.e1;
                let [e2x, e2y, e2z] = p.e2;
                let px = dy * e2z - dz * e2y;
                let py = dz * e2x - dx * e2z;
                let pz = dx * e2y - dy * e2x;
                let det = e1x * px + e1y * py + e1z * pz;
                let un = p.s[0] * px + p.s[1] * py + p.s[2] * pz;
                let vn = dx * p.q[0] + dy * p.q[1] + dz * p.q[2];
                let inv = Vec4::ONE / det;
                let (uu, vv, t) = (un * inv, vn * inv, p.tn * inv);
                let m = uu.cmpge(Vec4::ZERO)
                    & vv.cmpge(Vec4::ZERO)
                    & (uu + vv).cmple(Vec4::ONE)
                    & t.cmpge(Vec4::ZERO)
                    & t.cmple(Vec4::splat(best_t));
                let bits = m.bitmask();
                if bits != 0 {
                    let (ts, us, vs) = (t.to_array(), uu.to_array(), vv.to_array());
                    for (lane, &tl) in ts.iter().enumerate() {
                        if bits & (1 << lane) != 0 && (tl < best_t || best_slot == u32::MAX) {
                            best_t = tl;
                            best_slot = p.slot[lane];
                            (best_u, best_v) = (us[lane], vs[lane]);
                        }
                    }
                }
            }
            if best_slot != u32::MAX {
                // The test's own barycentrics (in [0, 1], u + v <= 1 by the mask), for the
                // same corners in the same order as `intersect`'s.
                out[i] = Some(Hit {
                    t_m: best_t,
                    triangle: self.bvh.tri_ids[best_slot as usize],
                    u: best_u,
                    v: best_v,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BuildQuality;
    use glam::DVec3;
    use skinbrdf_core::TriMesh;

    /// Pinhole rays (width x height, horizontal field of view `fov_deg`) from `origin` looking
    /// down -z, with a few holes (zero directions).
    fn grid(width: usize, height: usize, fov_deg: f64) -> Vec<Vec3> {
        let f = 0.5 * width as f64 / (0.5 * fov_deg.to_radians()).tan();
        let (cx, cy) = ((width as f64 - 1.0) * 0.5, (height as f64 - 1.0) * 0.5);
        let mut dirs = Vec::new();
        for y in 0..height {
            for x in 0..width {
                if (x * 7 + y * 3) % 97 == 0 {
                    dirs.push(Vec3::ZERO);
                    continue;
                }
                let d = DVec3::new((x as f64 - cx) / f, -(y as f64 - cy) / f, -1.0).normalize();
                dirs.push(d.as_vec3());
            }
        }
        dirs
    }

    fn check(mesh: &TriMesh, origin: Vec3, dirs: &[Vec3], width: usize, quality: BuildQuality) {
        let bvh = MeshBvh::build(mesh, quality).unwrap();
        let grid = bvh.intersect_grid(origin, dirs, width, f32::INFINITY);
        let mut hits = 0;
        let mut differ = 0;
        // Within this of an edge, Möller–Trumbore in f32 may go either way (obvhs's test also
        // rejects -0.0 barycentrics, a leak on exact edges the grid tracer does not have).
        let on_edge = |h: &Hit| h.u.min(h.v).min(1.0 - h.u - h.v) < 1e-4;
        for (d, g) in dirs.iter().zip(&grid) {
            let single = bvh.intersect(origin, *d, f32::INFINITY);
            if *d == Vec3::ZERO {
                assert_eq!(*g, None);
                continue;
            }
            match (single, *g) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert!(
                        (a.t_m - b.t_m).abs() <= 1e-5 * a.t_m.max(1.0),
                        "{a:?} {b:?}"
                    );
                    if a.triangle == b.triangle {
                        assert!(
                            (a.u - b.u).abs() < 1e-4 && (a.v - b.v).abs() < 1e-4,
                            "{a:?} {b:?}"
                        );
                    } else {
                        // Only on a shared edge (same t): both hits are correct.
                        assert!(on_edge(&a) || on_edge(&b), "{a:?} {b:?}");
                        differ += 1;
                    }
                }
                (Some(h), None) | (None, Some(h)) if on_edge(&h) => {}
                (a, b) => panic!("single {a:?} vs grid {b:?} for {d:?}"),
            }
        }
        assert!(hits > dirs.len() / 10, "only {hits} hits");
        assert!(
            differ * 50 <= hits,
            "{differ} of {hits} on different triangles"
        );
    }

    #[test]
    fn grid_matches_single_rays_on_a_sphere() {
        let mesh = crate::shapes::uv_sphere(DVec3::ZERO, 0.08, 60, 120);
        let dirs = grid(157, 93, 30.0);
        for q in [
            BuildQuality::Fastest,
            BuildQuality::Medium,
            BuildQuality::High,
        ] {
            check(&mesh, Vec3::new(0.0, 0.01, 0.45), &dirs, 157, q);
        }
        // From inside the sphere (every ray hits, frusta contain the origin's surroundings).
        check(
            &mesh,
            Vec3::new(0.01, 0.0, 0.02),
            &dirs,
            157,
            BuildQuality::Medium,
        );
    }

    #[test]
    fn wide_tiles_fall_back_and_agree() {
        // 170° field of view on a small grid: tiles too wide for a frustum.
        let mesh = crate::shapes::uv_sphere(DVec3::ZERO, 0.5, 20, 40);
        let dirs = grid(20, 12, 170.0);
        check(
            &mesh,
            Vec3::new(0.0, 0.0, 0.2),
            &dirs,
            20,
            BuildQuality::Fast,
        );
        let bvh = MeshBvh::build(&mesh, BuildQuality::Fast).unwrap();
        let mut sc = TraceScratch::default();
        let mut out = vec![None; dirs.len()];
        bvh.intersect_grid_into(
            Vec3::new(0.0, 0.0, 0.2),
            &dirs,
            20,
            f32::INFINITY,
            &mut out,
            &mut sc,
        );
        assert!(sc.counts.fallback_tiles > 0);
        assert_eq!(
            out,
            bvh.intersect_grid(Vec3::new(0.0, 0.0, 0.2), &dirs, 20, f32::INFINITY)
        );
    }

    #[test]
    fn t_max_and_degenerate_inputs() {
        let mesh = crate::shapes::uv_sphere(DVec3::ZERO, 0.1, 16, 32);
        let bvh = MeshBvh::build(&mesh, BuildQuality::Medium).unwrap();
        let dirs = vec![-Vec3::Z; 16];
        // The sphere's front is 0.9 m away.
        assert!(bvh
            .intersect_grid(Vec3::Z, &dirs, 4, 0.5)
            .iter()
            .all(Option::is_none));
        assert!(bvh
            .intersect_grid(Vec3::Z, &dirs, 4, 2.0)
            .iter()
            .all(|h| h.is_some_and(|h| (h.t_m - 0.9).abs() < 1e-3)));
        assert!(bvh
            .intersect_grid(Vec3::NAN, &dirs, 4, 2.0)
            .iter()
            .all(Option::is_none));
        assert!(bvh.intersect_grid(Vec3::Z, &dirs, 0, 2.0).len() == 16);
        // A ragged last row.
        let h = bvh.intersect_grid(Vec3::Z, &dirs[..13], 4, 2.0);
        assert!(h.iter().all(Option::is_some));
    }
}
