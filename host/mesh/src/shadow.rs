//! Coherent shadow rays: segments from many surface points to one point (a point light).
//!
//! [`MeshBvh::occluded_toward_grid`] answers, for every origin `o` of a grid (the surface
//! points behind an image's pixels), exactly what [`MeshBvh::occluded`] answers for the ray
//! [`shadow_ray`]`(o, target, stop_short_m)`: whether a triangle is hit with
//! `0 <= t < |target − o| − stop_short_m`. Neighbouring points see the light along nearly the
//! same direction, so the segments of a tile all lie in a thin cone with its apex at the light:
//!
//! 1. **Cone.** For a tile of origins, the directions `o − target` give four planes through
//!    `target` (the grid tracer's frustum, [`crate::coherent`]) and a far plane normal to
//!    their mean direction `c` at the farthest origin: every segment lies inside.
//! 2. **Candidates.** One CWBVH walk per super-tile ([`SHADOW_SUPER_TILE`]² origins) keeps the
//!    triangles not entirely outside that cone; each tile ([`SHADOW_TILE`]²) re-culls them with
//!    its own. Culling is conservative (padded), so it removes only triangles no segment of the
//!    tile can meet — the region's own surface behind the points and the rest of the head.
//! 3. **Any hit.** Each ray is tested against the candidates with obvhs's own Möller–Trumbore
//!    arithmetic (`RtTriangle::intersect`, same operations in the same order, four triangles per
//!    SIMD op) and stops at the first hit: the verdict is bit-for-bit the per-ray one (test
//!    `shadow_grid_equals_per_ray`).
//!
//! A tile falls back to per-ray traversal when its directions spread too far (as in the grid
//! tracer) or it gathers more than [`MAX_SHADOW_CANDIDATES`] triangles. Entries with a
//! non-finite origin, or an origin at the target, are not occluded (as with single rays).

use glam::{Vec3, Vec3A, Vec4};

use crate::bvh::MeshBvh;
use crate::coherent::{box_in_frustum, frustum_with_axis, tri_in_frustum, FRUSTUM_PAD};
use crate::tiled::{in_bands, trace_tiles, Cull, TileBuffers, TileCounts, TileScratch, TileTracer};

/// Tile side, origins: the rays tested together against one candidate list.
pub const SHADOW_TILE: usize = 8;
/// Super-tile side, origins: one BVH walk per super-tile.
pub const SHADOW_SUPER_TILE: usize = 16;
/// More candidates than this in a tile (or 8x this in a super-tile) and it is traced ray by
/// ray: the per-ray traversal is then cheaper than testing every candidate.
pub const MAX_SHADOW_CANDIDATES: usize = 384;

/// The ray [`MeshBvh::occluded_toward_grid`] tests for an origin: unit direction towards
/// `target` (f32) and the range `|target − o| − stop_short_m`; `None` for a non-finite origin
/// or one at the target. Pass it to [`MeshBvh::occluded`] for the per-ray answer.
pub fn shadow_ray(origin: Vec3, target: Vec3, stop_short_m: f32) -> Option<(Vec3, f32)> {
    let v = target - origin;
    let len = v.length();
    if !(origin.is_finite() && len.is_finite() && len > 0.0) {
        return None;
    }
    Some((v / len, len - stop_short_m))
}

/// Reusable buffers and counters of the coherent shadow tracer.
#[derive(Debug, Default, Clone)]
pub struct ShadowScratch {
    /// The driver's buffers; a tile's rays are [`ShadowRay`]s.
    bufs: TileBuffers<ShadowRay>,
    packs: Vec<ShadowPack>,
    /// How its tiles were traced.
    pub counts: TileCounts,
}

/// `(index, o − target, origin, unit direction, t_max)` of a ray of a tile.
type ShadowRay = (usize, Vec3A, Vec3A, Vec3A, f32);

/// Four candidate triangles (obvhs's `RtTriangle` layout) in SIMD lanes.
#[derive(Debug, Clone, Copy)]
struct ShadowPack {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    ng: [Vec4; 3],
}

/// The cone of a tile: four planes through the target and the far plane `(p − target)·c <= far`.
#[derive(Debug, Clone, Copy)]
struct Cone {
    planes: [Vec3A; 4],
    axis: Vec3A,
    far: f32,
}

impl Cone {
    fn of(tile: &[ShadowRay]) -> Option<Self> {
        let dirs: Vec<(usize, Vec3A)> = tile.iter().map(|r| (r.0, r.1)).collect();
        let (planes, axis) = frustum_with_axis(&dirs)?;
        let far = tile.iter().map(|r| r.1.dot(axis)).fold(0.0f32, f32::max);
        // Padded like the side planes, plus a micrometre for the f32 rounding of the tests.
        Some(Self {
            planes,
            axis,
            far: far * (1.0 + FRUSTUM_PAD) + 1e-6,
        })
    }
}

impl Cull for Cone {
    fn keeps_box(&self, lo: Vec3A, hi: Vec3A) -> bool {
        box_in_frustum(lo, hi, &self.planes)
            && Vec3A::select(self.axis.cmpge(Vec3A::ZERO), lo, hi).dot(self.axis) <= self.far
    }

    fn keeps_tri(&self, a: Vec3A, b: Vec3A, c: Vec3A) -> bool {
        tri_in_frustum(a, b, c, &self.planes)
            && (a.dot(self.axis) <= self.far
                || b.dot(self.axis) <= self.far
                || c.dot(self.axis) <= self.far)
    }
}

impl MeshBvh {
    /// Occlusion of the segments from `origins` (row-major on a grid `width` wide, e.g. the
    /// surface points behind an image's pixels) to `target`, in parallel over bands of tiles:
    /// for each origin exactly `self.occluded(o, d, t_max)` with `(d, t_max)` from
    /// [`shadow_ray`] (see the module docs). Entries with a non-finite origin are `false`.
    pub fn occluded_toward_grid(
        &self,
        target: Vec3,
        origins: &[Vec3],
        width: usize,
        stop_short_m: f32,
    ) -> Vec<bool> {
        let mut out = vec![false; origins.len()];
        if width == 0 {
            return out;
        }
        in_bands(
            origins,
            &mut out,
            width,
            SHADOW_SUPER_TILE,
            ShadowScratch::default,
            |sc, p, o| self.occluded_toward_grid_into(target, p, width, stop_short_m, o, sc),
        );
        out
    }

    /// [`MeshBvh::occluded_toward_grid`] on the calling thread, into `out` (same length as
    /// `origins`), with caller-owned scratch buffers.
    pub fn occluded_toward_grid_into(
        &self,
        target: Vec3,
        origins: &[Vec3],
        width: usize,
        stop_short_m: f32,
        out: &mut [bool],
        sc: &mut ShadowScratch,
    ) {
        let n = origins.len().min(out.len());
        out.iter_mut().for_each(|b| *b = false);
        if width == 0 || !target.is_finite() || stop_short_m.is_nan() {
            return;
        }
        let rays = ShadowRays {
            bvh: self,
            target,
            origins,
            stop_short_m,
        };
        trace_tiles(&rays, n, width, sc, out);
    }
}

/// Shadow rays of one band: a surface point per grid cell, one target.
struct ShadowRays<'a> {
    bvh: &'a MeshBvh,
    target: Vec3,
    origins: &'a [Vec3],
    stop_short_m: f32,
}

impl TileScratch<ShadowRay> for ShadowScratch {
    fn buffers(&mut self) -> &mut TileBuffers<ShadowRay> {
        &mut self.bufs
    }

    fn counts(&mut self) -> &mut TileCounts {
        &mut self.counts
    }
}

impl TileTracer for ShadowRays<'_> {
    type Ray = ShadowRay;
    type Out = bool;
    type Scratch = ShadowScratch;
    type Cull = Cone;
    const TILE_PX: usize = SHADOW_TILE;
    const SUPER_TILE_PX: usize = SHADOW_SUPER_TILE;
    const MAX_SUPER_CANDIDATES: usize = 8 * MAX_SHADOW_CANDIDATES;
    const MAX_TILE_CANDIDATES: usize = MAX_SHADOW_CANDIDATES;

    fn bvh(&self) -> &MeshBvh {
        self.bvh
    }

    fn apex(&self) -> Vec3A {
        Vec3A::from(self.target)
    }

    /// The valid shadow rays: a finite origin away from the target, a range that is a number.
    fn ray(&self, i: usize) -> Option<ShadowRay> {
        let o = self.origins[i];
        let (d, t_max) = shadow_ray(o, self.target, self.stop_short_m)?;
        if t_max.is_nan() {
            return None;
        }
        // -0.0 -> +0.0, as `MeshBvh::occluded` does (obvhs's octant pitfall).
        let d = Vec3A::new(d.x + 0.0, d.y + 0.0, d.z + 0.0);
        Some((i, Vec3A::from(o - self.target), Vec3A::from(o), d, t_max))
    }

    fn cull(&self, tile: &[ShadowRay]) -> Option<Cone> {
        Cone::of(tile)
    }

    fn trace_per_ray(&self, tile: &[ShadowRay], out: &mut [bool]) {
        for &(i, _, o, d, t_max) in tile {
            out[i] = self.bvh.occluded(o.into(), d.into(), t_max);
        }
    }

    /// Packs the candidates four to a SIMD lane group, then tests each ray for any hit.
    fn trace_candidates(&self, sc: &mut ShadowScratch, out: &mut [bool]) {
        sc.packs.clear();
        for chunk in sc.bufs.cand.chunks(4) {
            // Empty lanes: zero edges and normal (inv_det = inf, u = v = NaN: never a hit).
            let mut l = [[0.0f32; 12]; 4];
            for (lane, &k) in chunk.iter().enumerate() {
                let t = &self.bvh.tris[k as usize];
                l[lane] = [
                    t.v0.x, t.v0.y, t.v0.z, t.e1.x, t.e1.y, t.e1.z, t.e2.x, t.e2.y, t.e2.z, t.ng.x,
                    t.ng.y, t.ng.z,
                ];
            }
            let g = |j: usize| Vec4::new(l[0][j], l[1][j], l[2][j], l[3][j]);
            sc.packs.push(ShadowPack {
                v0: [g(0), g(1), g(2)],
                e1: [g(3), g(4), g(5)],
                e2: [g(6), g(7), g(8)],
                ng: [g(9), g(10), g(11)],
            });
        }
        for &(i, _, o, d, t_max) in &sc.bufs.tile {
            out[i] = any_hit(&sc.packs, o, d, t_max);
        }
    }
}

/// Whether the ray `(o, d)` hits a candidate with `0 <= t < t_max`: obvhs's
/// `RtTriangle::intersect` and `ray_traverse_miss` test, lane by lane, with the same operations
/// in the same order (glam's `Vec3A::dot` is `(x·x' + y·y') + z·z'`; cross products are
/// `a.y·b.z − a.z·b.y` and so on), so every lane's value equals the scalar one.
fn any_hit(packs: &[ShadowPack], o: Vec3A, d: Vec3A, t_max: f32) -> bool {
    let (ox, oy, oz) = (Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z));
    let (dx, dy, dz) = (Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z));
    let tmax = Vec4::splat(t_max);
    for p in packs {
        // c = v0 − o; r = d × c.
        let (cx, cy, cz) = (p.v0[0] - ox, p.v0[1] - oy, p.v0[2] - oz);
        let rx = dy * cz - dz * cy;
        let ry = dz * cx - dx * cz;
        let rz = dx * cy - dy * cx;
        let [e1x, e1y, e1z] = p.e1;
        let [e2x, e2y, e2z] = p.e2;
        let [nx, ny, nz] = p.ng;
        let inv_det = Vec4::ONE / ((nx * dx + ny * dy) + nz * dz);
        let u = ((rx * e2x + ry * e2y) + rz * e2z) * inv_det;
        let v = ((rx * e1x + ry * e1y) + rz * e1z) * inv_det;
        let w = (Vec4::ONE - u) - v;
        // obvhs: valid when inv_det != 0 and none of u, v, w has its sign bit set.
        let signs = u.is_negative_bitmask() | v.is_negative_bitmask() | w.is_negative_bitmask();
        let t = ((nx * cx + ny * cy) + nz * cz) * inv_det;
        let ok = inv_det.cmpne(Vec4::ZERO) & t.cmpge(Vec4::ZERO) & t.cmple(tmax) & t.cmplt(tmax);
        if ok.bitmask() & !signs & 0xf != 0 {
            return true;
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BuildQuality;
    use glam::DVec3;

    /// Surface points of a bumpy sphere seen by a camera grid (offset off the surface), with
    /// the per-ray and the coherent verdicts for a light.
    fn check(light: Vec3, stop_short: f32) -> (usize, usize) {
        let mesh = crate::shapes::bumpy_sphere(0.08, 0.03, 112, 224);
        let bvh = MeshBvh::build(&mesh, BuildQuality::Medium).unwrap();
        let (w, h) = (120usize, 90usize);
        let cam = Vec3::new(0.0, 0.0, 0.45);
        let f = 0.5 * w as f64 / (15f64.to_radians()).tan();
        let dirs: Vec<Vec3> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                DVec3::new((x - 0.5 * w as f64) / f, -(y - 0.5 * h as f64) / f, -1.0)
                    .normalize()
                    .as_vec3()
            })
            .collect();
        let hits = bvh.intersect_grid(cam, &dirs, w, f32::INFINITY);
        let origins: Vec<Vec3> = hits
            .iter()
            .zip(&dirs)
            .map(|(hit, d)| match hit {
                Some(hit) => {
                    let ng = mesh.face_normal_area2(hit.triangle as usize).normalize();
                    cam + *d * hit.t_m + ng * 1e-5
                }
                None => Vec3::NAN,
            })
            .collect();
        let grid = bvh.occluded_toward_grid(light, &origins, w, stop_short);
        let mut occluded = 0;
        let mut traced = 0;
        for (o, g) in origins.iter().zip(&grid) {
            let single =
                shadow_ray(*o, light, stop_short).is_some_and(|(d, t)| bvh.occluded(*o, d, t));
            assert_eq!(single, *g, "origin {o:?}");
            traced += usize::from(o.is_finite());
            occluded += usize::from(single);
        }
        (traced, occluded)
    }

    #[test]
    fn shadow_grid_equals_per_ray() {
        // Lights from the camera's side, grazing and behind the sphere: few, many and all
        // shadowed; some tiles straddle the terminator.
        let mut total_occluded = 0;
        for light in [
            Vec3::new(0.1, 0.05, 0.6),
            Vec3::new(0.5, 0.0, 0.05),
            Vec3::new(-0.3, 0.2, -0.4),
            Vec3::new(0.0, 0.0, -0.5),
        ] {
            let (traced, occluded) = check(light, 1e-5);
            assert!(traced > 3000, "{traced}");
            total_occluded += occluded;
        }
        assert!(total_occluded > 3000, "{total_occluded}");
    }

    #[test]
    fn degenerate_inputs_are_not_occluded() {
        let mesh = crate::shapes::uv_sphere(DVec3::ZERO, 0.1, 16, 32);
        let bvh = MeshBvh::build(&mesh, BuildQuality::Medium).unwrap();
        let light = Vec3::new(0.0, 0.0, 1.0);
        let origins = [
            Vec3::NAN,
            light,
            Vec3::new(0.01, 0.0, -1.0),
            Vec3::new(0.01, 0.02, 0.0),
        ];
        let r = bvh.occluded_toward_grid(light, &origins, 2, 0.0);
        // Behind the sphere and inside it (off the poles, where Möller–Trumbore may leak
        // through a vertex): occluded.
        assert_eq!(r, vec![false, false, true, true]);
        assert!(bvh.occluded_toward_grid(light, &origins, 0, 0.0) == vec![false; 4]);
        assert!(bvh
            .occluded_toward_grid(Vec3::NAN, &origins, 2, 0.0)
            .iter()
            .all(|b| !b));
    }
}
