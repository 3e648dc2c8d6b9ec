//! Ray throughput on the benchmark mesh: 1500 x 1000 primary rays on a 199,808-triangle bumpy
//! sphere (the same mesh and rays as `scripts/peers/embree_bench.py`, which runs this example
//! and Embree back to back: `python3 scripts/peers/embree_bench.py --compare`).
//!
//! ```text
//! cargo run --release -p skinbrdf-mesh --example ray_throughput -- [--ply PATH] [--quality Q] [--reps N] [--json]
//! ```
//!
//! Times (best of `reps`): the coherent grid tracer (`intersect_grid`, all rayon threads, and
//! on one thread), per-ray traversal (`intersect_batch`, all threads, and one thread), and the
//! build of every quality preset (or only `--quality`). Then **shadow rays**: from every hit
//! (offset 10 µm along the face normal) to a light at (0.25, 0.15, 0.35) m, per ray
//! (`occluded_batch` / `occluded`, obvhs any-hit traversal) and coherent
//! (`occluded_toward_grid`), checked identical.

use std::time::Instant;

use glam::{DVec3, Vec3};
use skinbrdf_mesh::{shadow_ray, BuildQuality, Hit, MeshBvh, MeshRay, ShadowScratch, TraceScratch};

/// 1500 x 1000 pinhole rays, 30° horizontal field of view, looking down -z (image x = world
/// +x, image y = world -y).
fn primary_dirs() -> (Vec<Vec3>, usize) {
    let (w, h) = (1500usize, 1000usize);
    let f = 0.5 * w as f64 / (15f64.to_radians()).tan();
    let (cx, cy) = ((w as f64 - 1.0) * 0.5, (h as f64 - 1.0) * 0.5);
    let mut dirs = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let d = DVec3::new((x as f64 - cx) / f, -(y as f64 - cy) / f, -1.0).normalize();
            dirs.push(d.as_vec3());
        }
    }
    (dirs, w)
}

fn best_of<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..reps.max(1) {
        let t = Instant::now();
        let r = f();
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(r);
    }
    (best, out.expect("at least one repetition"))
}

/// The command line: `--reps`, `--quality`, `--ply`, `--json`, `--grid-only`.
struct Args {
    reps: usize,
    only: Option<BuildQuality>,
    ply: Option<String>,
    json: bool,
    grid_only: bool,
}

impl Args {
    fn parse() -> Result<Self, Box<dyn std::error::Error>> {
        let args: Vec<String> = std::env::args().skip(1).collect();
        let opt = |name: &str| {
            args.iter()
                .position(|a| a == name)
                .and_then(|i| args.get(i + 1).cloned())
        };
        Ok(Self {
            reps: opt("--reps").map(|s| s.parse()).transpose()?.unwrap_or(5),
            only: opt("--quality").map(|s| s.parse()).transpose()?,
            ply: opt("--ply"),
            json: args.iter().any(|a| a == "--json"),
            grid_only: args.iter().any(|a| a == "--grid-only"),
        })
    }
}

/// Primary rays: the grid's hits, their counts and the times.
struct Primary {
    grid: Vec<Option<Hit>>,
    hits: usize,
    batch_hits: usize,
    grid_s: f64,
    grid1_s: f64,
    batch_s: f64,
    single_s: f64,
    scratch: TraceScratch,
}

/// Shadow rays from the hits: counts, agreement and times.
struct Shadow {
    rays: usize,
    shadowed: usize,
    differ: usize,
    grid_s: f64,
    grid1_s: f64,
    batch_s: f64,
    single_s: f64,
    scratch: ShadowScratch,
}

const ORIGIN: Vec3 = Vec3::new(0.0, 0.0, 0.45);
const LIGHT: Vec3 = Vec3::new(0.25, 0.15, 0.35);
const STOP_SHORT_M: f32 = 1e-5;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse()?;
    let reps = args.reps;
    let mesh = skinbrdf_mesh::shapes::bumpy_sphere(0.08, 0.03, 224, 448);
    let (dirs, width) = primary_dirs();
    if args.grid_only {
        // For `perf stat`: one build, `reps` one-thread grid passes.
        let bvh = MeshBvh::build(&mesh, args.only.unwrap_or(BuildQuality::Medium))?;
        let mut scratch = TraceScratch::default();
        let mut out = vec![None; dirs.len()];
        let (s, _) = best_of(reps, || {
            bvh.intersect_grid_into(ORIGIN, &dirs, width, f32::INFINITY, &mut out, &mut scratch)
        });
        println!(
            "grid 1 thread {s:.4} s, {} candidates per tile",
            scratch.counts.candidates / scratch.counts.tiles.max(1)
        );
        return Ok(());
    }
    if let Some(p) = &args.ply {
        skinbrdf_mesh::write_ply_binary(std::path::Path::new(p), &mesh)?;
    }
    let mut builds = Vec::new();
    for q in BuildQuality::ALL {
        if args.only.is_some_and(|o| o != q) {
            continue;
        }
        let (s, _) = best_of(reps.min(3), || MeshBvh::build(&mesh, q));
        builds.push((q, s));
    }
    let quality = args.only.unwrap_or(BuildQuality::Medium);
    let bvh = MeshBvh::build(&mesh, quality)?;
    let p = primary(&bvh, &dirs, width, reps);
    let sh = shadow(&bvh, &mesh, &dirs, &p.grid, width, reps);
    let run = Run {
        mesh: &mesh,
        rays: dirs.len(),
        quality,
        builds: &builds,
        reps,
    };
    if args.json {
        print_json(&run, &p, &sh);
    } else {
        print_text(&run, &p, &sh);
    }
    Ok(())
}

/// What was traced, for the printers.
struct Run<'a> {
    mesh: &'a skinbrdf_core::TriMesh,
    rays: usize,
    quality: BuildQuality,
    builds: &'a [(BuildQuality, f64)],
    reps: usize,
}

/// Times the primary rays: coherent grid (all threads, one thread) and per ray.
fn primary(bvh: &MeshBvh, dirs: &[Vec3], width: usize, reps: usize) -> Primary {
    let rays: Vec<MeshRay> = dirs.iter().map(|&d| MeshRay::new(ORIGIN, d)).collect();
    let (grid_s, grid) = best_of(reps, || {
        bvh.intersect_grid(ORIGIN, dirs, width, f32::INFINITY)
    });
    let hits = grid.iter().filter(|h| h.is_some()).count();
    let mut scratch = TraceScratch::default();
    let mut out = vec![None; dirs.len()];
    let (grid1_s, _) = best_of(reps, || {
        bvh.intersect_grid_into(ORIGIN, dirs, width, f32::INFINITY, &mut out, &mut scratch)
    });
    let (batch_s, batch) = best_of(reps, || bvh.intersect_batch(&rays));
    let batch_hits = batch.iter().filter(|h| h.is_some()).count();
    let (single_s, _) = best_of(reps.min(3), || {
        rays.iter()
            .filter(|r| bvh.intersect(r.origin, r.dir, r.t_max).is_some())
            .count()
    });
    Primary {
        grid,
        hits,
        batch_hits,
        grid_s,
        grid1_s,
        batch_s,
        single_s,
        scratch,
    }
}

/// Times the shadow rays from the hits towards one light, per ray and coherent, and counts
/// where the two differ.
fn shadow(
    bvh: &MeshBvh,
    mesh: &skinbrdf_core::TriMesh,
    dirs: &[Vec3],
    grid: &[Option<Hit>],
    width: usize,
    reps: usize,
) -> Shadow {
    let (light, stop_short) = (LIGHT, STOP_SHORT_M);
    let origins: Vec<Vec3> = grid
        .iter()
        .zip(dirs)
        .map(|(h, d)| match h {
            Some(h) => {
                let ng = mesh.face_normal_area2(h.triangle as usize).normalize();
                ORIGIN + *d * h.t_m + ng * 1e-5
            }
            None => Vec3::NAN,
        })
        .collect();
    let shadow_rays: Vec<MeshRay> = origins
        .iter()
        .filter_map(|&o| {
            let (d, t_max) = shadow_ray(o, light, stop_short)?;
            Some(MeshRay {
                origin: o,
                dir: d,
                t_max,
            })
        })
        .collect();
    let (batch_s, sh_batch) = best_of(reps, || bvh.occluded_batch(&shadow_rays));
    let (single_s, _) = best_of(reps.min(3), || {
        shadow_rays
            .iter()
            .filter(|r| bvh.occluded(r.origin, r.dir, r.t_max))
            .count()
    });
    let (grid_s, sh_grid) = best_of(reps, || {
        bvh.occluded_toward_grid(light, &origins, width, stop_short)
    });
    let mut scratch = ShadowScratch::default();
    let mut sh_out = vec![false; origins.len()];
    let (grid1_s, _) = best_of(reps, || {
        bvh.occluded_toward_grid_into(
            light,
            &origins,
            width,
            stop_short,
            &mut sh_out,
            &mut scratch,
        )
    });
    let sh_grid_valid: Vec<bool> = origins
        .iter()
        .zip(&sh_grid)
        .filter(|(o, _)| shadow_ray(**o, light, stop_short).is_some())
        .map(|(_, b)| *b)
        .collect();
    let shadowed = sh_batch.iter().filter(|b| **b).count();
    let differ = sh_grid_valid
        .iter()
        .zip(&sh_batch)
        .filter(|(a, b)| a != b)
        .count();
    Shadow {
        rays: shadow_rays.len(),
        shadowed,
        differ,
        grid_s,
        grid1_s,
        batch_s,
        single_s,
        scratch,
    }
}

fn print_json(run: &Run<'_>, p: &Primary, sh: &Shadow) {
    let (mesh, dirs_len, quality, reps) = (run.mesh, run.rays, run.quality, run.reps);
    let (hits, batch_hits, grid_s, grid1_s, batch_s, single_s, scratch) = (
        p.hits,
        p.batch_hits,
        p.grid_s,
        p.grid1_s,
        p.batch_s,
        p.single_s,
        &p.scratch,
    );
    let (shadowed, shadow_differ) = (sh.shadowed, sh.differ);
    let (sh_grid_s, sh_grid1_s, sh_batch_s, sh_single_s) =
        (sh.grid_s, sh.grid1_s, sh.batch_s, sh.single_s);
    let tiles = scratch.counts.tiles + scratch.counts.fallback_tiles;
    let threads = rayon::current_num_threads();
    let b: Vec<String> = run
        .builds
        .iter()
        .map(|(q, s)| format!("\"{}\": {s:.4}", q.name()))
        .collect();
    println!(
        "{{\"triangles\": {}, \"rays\": {}, \"hits\": {hits}, \"per_ray_hits\": {batch_hits}, \"threads\": {threads}, \"quality\": \"{}\", \"build_s\": {{{}}}, \"grid_s\": {grid_s:.4}, \"grid_1_thread_s\": {grid1_s:.4}, \"per_ray_s\": {batch_s:.4}, \"per_ray_1_thread_s\": {single_s:.4}, \"fallback_tiles\": {}, \"tiles\": {tiles}, \"mean_candidates\": {:.1}, \"shadow_rays\": {}, \"shadowed\": {shadowed}, \"shadow_differ\": {shadow_differ}, \"shadow_grid_s\": {sh_grid_s:.4}, \"shadow_grid_1_thread_s\": {sh_grid1_s:.4}, \"shadow_per_ray_s\": {sh_batch_s:.4}, \"shadow_per_ray_1_thread_s\": {sh_single_s:.4}}}",
        mesh.indices.len(),
        dirs_len,
        quality.name(),
        b.join(", "),
        scratch.counts.fallback_tiles / reps.max(1) as u64,
        scratch.counts.mean_candidates(),
        sh.rays,
    );
}

fn print_text(run: &Run<'_>, p: &Primary, sh: &Shadow) {
    let (mesh, dirs_len, quality, builds, reps) =
        (run.mesh, run.rays, run.quality, run.builds, run.reps);
    let (hits, batch_hits, grid_s, grid1_s, batch_s, single_s, scratch) = (
        p.hits,
        p.batch_hits,
        p.grid_s,
        p.grid1_s,
        p.batch_s,
        p.single_s,
        &p.scratch,
    );
    let (shadowed, shadow_differ, sh_scratch) = (sh.shadowed, sh.differ, &sh.scratch);
    let (sh_grid_s, sh_grid1_s, sh_batch_s, sh_single_s) =
        (sh.grid_s, sh.grid1_s, sh.batch_s, sh.single_s);
    let light = LIGHT;
    let threads = rayon::current_num_threads();
    let tiles = scratch.counts.tiles + scratch.counts.fallback_tiles;
    let (n, ns) = (dirs_len as f64, sh.rays as f64);
    let mrays = |s: f64| n / s / 1e6;
    println!(
        "{} triangles, {} rays, {hits} hits (per-ray path {batch_hits}), {threads} rayon threads, quality {}",
        mesh.indices.len(),
        dirs_len,
        quality.name()
    );
    for (q, s) in builds {
        println!("build {:10} {s:.3} s", q.name());
    }
    println!(
        "grid (coherent), {threads} threads   {grid_s:.4} s  {:.2} Mrays/s",
        mrays(grid_s)
    );
    println!(
        "grid (coherent), 1 thread    {grid1_s:.4} s  {:.2} Mrays/s",
        mrays(grid1_s)
    );
    println!(
        "per ray, {threads} threads           {batch_s:.4} s  {:.2} Mrays/s",
        mrays(batch_s)
    );
    println!(
        "per ray, 1 thread            {single_s:.4} s  {:.2} Mrays/s",
        mrays(single_s)
    );
    println!(
        "tiles {tiles} ({} per ray), mean candidates per tile {:.1}",
        scratch.counts.fallback_tiles,
        scratch.counts.mean_candidates()
    );
    let ms = |s: f64| ns / s / 1e6;
    println!(
        "shadow rays: {} towards {light:?}, {shadowed} occluded, coherent differs on {shadow_differ}",
        sh.rays
    );
    println!(
        "shadow coherent, {threads} threads  {sh_grid_s:.4} s  {:.2} Mrays/s",
        ms(sh_grid_s)
    );
    println!(
        "shadow coherent, 1 thread   {sh_grid1_s:.4} s  {:.2} Mrays/s ({} tiles, {} per ray, {:.1} candidates per tile)",
        ms(sh_grid1_s),
        sh_scratch.counts.tiles / reps.max(1) as u64,
        sh_scratch.counts.fallback_tiles / reps.max(1) as u64,
        sh_scratch.counts.mean_candidates()
    );
    println!(
        "shadow per ray, {threads} threads   {sh_batch_s:.4} s  {:.2} Mrays/s",
        ms(sh_batch_s)
    );
    println!(
        "shadow per ray, 1 thread    {sh_single_s:.4} s  {:.2} Mrays/s",
        ms(sh_single_s)
    );
}
