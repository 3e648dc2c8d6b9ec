//! The driver shared by the coherent tracers ([`crate::coherent`]'s camera rays,
//! [`crate::shadow`]'s shadow rays): rays laid out row-major on a grid, all through one point
//! (the apex: a camera's centre, a point light).
//!
//! 1. **Bands.** The grid is cut into bands of rows one super-tile high, traced in parallel
//!    (rayon), each with its own scratch buffers ([`in_bands`]).
//! 2. **Super-tiles.** Within a band, each super-tile of rays is bounded by a convex region
//!    through the apex ([`Cull`]: the tracer's frustum or cone); one walk of the CWBVH keeps
//!    the leaf triangles that region does not exclude ([`candidates`]). Too wide a region, or
//!    too many candidates, and the super-tile is traced ray by ray.
//! 3. **Tiles.** Each tile of the super-tile re-culls those candidates with its own region and
//!    hands them to the tracer's test ([`TileTracer::trace_candidates`]); again ray by ray when
//!    its region is too wide or it keeps too many.
//!
//! Culling only removes triangles no ray of the tile can meet, so each tracer's answer is its
//! per-ray answer; the driver decides only which rays are traced together.

use glam::Vec3A;
use rayon::prelude::*;

use crate::bvh::MeshBvh;

/// A convex region through the apex holding every ray of a tile (coordinates relative to the
/// apex). Conservative: it may keep what no ray meets, never the reverse.
pub(crate) trait Cull {
    /// Whether the box `lo..hi` is not entirely outside the region.
    fn keeps_box(&self, lo: Vec3A, hi: Vec3A) -> bool;
    /// Whether the triangle `a, b, c` is not entirely outside the region.
    fn keeps_tri(&self, a: Vec3A, b: Vec3A, c: Vec3A) -> bool;
}

/// The driver's buffers: the BVH walk's stack, the candidates of the tile and of its
/// super-tile (leaf slots), and the rays of the current tile.
#[derive(Debug, Clone)]
pub(crate) struct TileBuffers<R> {
    pub(crate) stack: Vec<u32>,
    pub(crate) cand: Vec<u32>,
    pub(crate) super_cand: Vec<u32>,
    pub(crate) tile: Vec<R>,
}

impl<R> Default for TileBuffers<R> {
    fn default() -> Self {
        Self {
            stack: Vec::new(),
            cand: Vec::new(),
            super_cand: Vec::new(),
            tile: Vec::new(),
        }
    }
}

/// How a coherent tracer's tiles were traced (summed over the tiles one scratch traced).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct TileCounts {
    /// Tiles traced with shared candidates.
    pub tiles: u64,
    /// Tiles (or super-tiles) traced ray by ray: too wide, or too many candidates.
    pub fallback_tiles: u64,
    /// Candidate triangles summed over the tiles traced with shared candidates.
    pub candidates: u64,
}

impl TileCounts {
    /// Mean candidates per tile traced with shared candidates (0 when there was none).
    pub fn mean_candidates(&self) -> f64 {
        self.candidates as f64 / self.tiles.max(1) as f64
    }
}

/// A tracer's scratch: the driver's buffers and the tile counters.
pub(crate) trait TileScratch<R> {
    /// The driver's buffers.
    fn buffers(&mut self) -> &mut TileBuffers<R>;
    /// The tile counters.
    fn counts(&mut self) -> &mut TileCounts;
}

/// One coherent tracer over one band of the grid.
pub(crate) trait TileTracer {
    /// A ray as the tracer keeps it in a tile (with its grid index).
    type Ray;
    /// The answer per grid cell.
    type Out;
    /// Its scratch buffers.
    type Scratch: TileScratch<Self::Ray>;
    /// The region bounding a tile's rays.
    type Cull: Cull;
    /// Tile side, rays.
    const TILE_PX: usize;
    /// Super-tile side, rays.
    const SUPER_TILE_PX: usize;
    /// More candidates than this in a super-tile and it is traced ray by ray.
    const MAX_SUPER_CANDIDATES: usize;
    /// More candidates than this in a tile and it is traced ray by ray.
    const MAX_TILE_CANDIDATES: usize;

    /// The mesh traced.
    fn bvh(&self) -> &MeshBvh;
    /// The point all rays pass through.
    fn apex(&self) -> Vec3A;
    /// The ray of grid cell `i` (`None`: the cell needs no ray).
    fn ray(&self, i: usize) -> Option<Self::Ray>;
    /// The region bounding `tile`'s rays, or `None` when they spread too far.
    fn cull(&self, tile: &[Self::Ray]) -> Option<Self::Cull>;
    /// Traces `tile`'s rays one by one (BVH traversal per ray).
    fn trace_per_ray(&self, tile: &[Self::Ray], out: &mut [Self::Out]);
    /// Traces the scratch's tile against its candidates (`buffers().cand`, not empty).
    fn trace_candidates(&self, sc: &mut Self::Scratch, out: &mut [Self::Out]);
}

/// Runs `trace` over bands of `rows_per_band` rows of a grid `width` wide in parallel, each
/// band with the inputs and outputs of its rows and a scratch from `init` (one per rayon job
/// split, reused across the bands it runs).
pub(crate) fn in_bands<I, O, S>(
    inputs: &[I],
    out: &mut [O],
    width: usize,
    rows_per_band: usize,
    init: impl Fn() -> S + Sync + Send,
    trace: impl Fn(&mut S, &[I], &mut [O]) + Sync + Send,
) where
    I: Sync,
    O: Send,
{
    let band = rows_per_band * width;
    out.par_chunks_mut(band)
        .zip(inputs.par_chunks(band))
        .for_each_init(init, |sc, (o, i)| trace(sc, i, o));
}

/// Traces the first `n` cells of a grid `width` wide (one band, on the calling thread): every
/// super-tile and tile as the module docs say.
pub(crate) fn trace_tiles<T: TileTracer>(
    t: &T,
    n: usize,
    width: usize,
    sc: &mut T::Scratch,
    out: &mut [T::Out],
) {
    let height = n.div_ceil(width);
    for ty in (0..height).step_by(T::SUPER_TILE_PX) {
        for tx in (0..width).step_by(T::SUPER_TILE_PX) {
            let (y1, x1) = (
                (ty + T::SUPER_TILE_PX).min(height),
                (tx + T::SUPER_TILE_PX).min(width),
            );
            gather(t, n, width, (tx, x1), (ty, y1), sc.buffers());
            if sc.buffers().tile.is_empty() {
                continue;
            }
            let Some(cull) = t.cull(&sc.buffers().tile) else {
                per_ray(t, sc, out);
                continue;
            };
            candidates(t.bvh(), t.apex(), &cull, sc.buffers());
            let bufs = sc.buffers();
            if bufs.cand.len() > T::MAX_SUPER_CANDIDATES {
                per_ray(t, sc, out);
                continue;
            }
            std::mem::swap(&mut bufs.cand, &mut bufs.super_cand);
            for sy in (ty..y1).step_by(T::TILE_PX) {
                for sx in (tx..x1).step_by(T::TILE_PX) {
                    let xs = (sx, (sx + T::TILE_PX).min(x1));
                    let ys = (sy, (sy + T::TILE_PX).min(y1));
                    gather(t, n, width, xs, ys, sc.buffers());
                    if !sc.buffers().tile.is_empty() {
                        trace_tile(t, sc, out);
                    }
                }
            }
        }
    }
}

/// The rays of the grid cells `x0..x1` x `y0..y1` (those that need one) into `bufs.tile`.
fn gather<T: TileTracer>(
    t: &T,
    n: usize,
    width: usize,
    (x0, x1): (usize, usize),
    (y0, y1): (usize, usize),
    bufs: &mut TileBuffers<T::Ray>,
) {
    bufs.tile.clear();
    for y in y0..y1 {
        for x in x0..x1 {
            let i = y * width + x;
            if i >= n {
                return;
            }
            if let Some(r) = t.ray(i) {
                bufs.tile.push(r);
            }
        }
    }
}

fn per_ray<T: TileTracer>(t: &T, sc: &mut T::Scratch, out: &mut [T::Out]) {
    sc.counts().fallback_tiles += 1;
    t.trace_per_ray(&sc.buffers().tile, out);
}

/// Traces the rays of the tile against the candidates of its super-tile that lie in the tile's
/// own region.
fn trace_tile<T: TileTracer>(t: &T, sc: &mut T::Scratch, out: &mut [T::Out]) {
    let Some(cull) = t.cull(&sc.buffers().tile) else {
        return per_ray(t, sc, out);
    };
    let (bvh, apex) = (t.bvh(), t.apex());
    let bufs = sc.buffers();
    bufs.cand.clear();
    for &k in &bufs.super_cand {
        let [v0, e1, e2] = bvh.leaf_tris[k as usize];
        let a = v0 - apex;
        if cull.keeps_tri(a, a + e1, a + e2) {
            bufs.cand.push(k);
        }
    }
    let count = bufs.cand.len();
    if count > T::MAX_TILE_CANDIDATES {
        return per_ray(t, sc, out);
    }
    let counts = sc.counts();
    counts.tiles += 1;
    counts.candidates += count as u64;
    if count == 0 {
        return;
    }
    t.trace_candidates(sc, out);
}

/// Leaf slots of the triangles that can lie in the region (relative to `apex`), into
/// `bufs.cand`.
fn candidates<C: Cull, R>(bvh: &MeshBvh, apex: Vec3A, cull: &C, bufs: &mut TileBuffers<R>) {
    bufs.cand.clear();
    bufs.stack.clear();
    if bvh.bvh.nodes.is_empty() {
        return;
    }
    bufs.stack.push(0);
    while let Some(ni) = bufs.stack.pop() {
        let node = &bvh.bvh.nodes[ni as usize];
        for ch in 0..8 {
            if node.is_child_empty(ch) {
                continue;
            }
            let b = node.child_aabb(ch);
            if !cull.keeps_box(b.min - apex, b.max - apex) {
                continue;
            }
            if node.is_leaf(ch) {
                let (first, count) = node.child_primitives(ch);
                for k in first..first + count {
                    let [v0, e1, e2] = bvh.leaf_tris[k as usize];
                    let a = v0 - apex;
                    if cull.keeps_tri(a, a + e1, a + e2) {
                        bufs.cand.push(k);
                    }
                }
            } else {
                bufs.stack.push(node.child_node_index(ch));
            }
        }
    }
}
