//! Ray throughput: 1.5 Mpx of primary rays on a ~200k-triangle head-sized mesh.
//!
//! The mesh and the rays are defined by formulas shared with `scripts/peers/embree_bench.py`
//! (which traces the same rays with Embree through `embreex`); the bench also writes the mesh
//! to `$CARGO_TARGET_DIR/skinbrdf-bench/head200k.ply` so the script can load it byte for byte.
//!
//! ```text
//! cargo bench -p skinbrdf-mesh --bench rays
//! python3 scripts/peers/embree_bench.py target/skinbrdf-bench/head200k.ply
//! ```
//!
//! The one-command comparison (our example and Embree back to back, with the ratio) is
//! `python3 scripts/peers/embree_bench.py --compare`.

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::{DVec3, Vec3};
use skinbrdf_core::TriMesh;
use skinbrdf_mesh::{BuildQuality, MeshBvh, MeshRay};

/// Bumpy sphere: r(θ, φ) = 0.08 m · (1 + 0.03 sin 5θ cos 7φ), 224 rings of 448 vertices.
fn head_mesh() -> TriMesh {
    skinbrdf_mesh::shapes::bumpy_sphere(0.08, 0.03, 224, 448)
}

/// 1500 x 1000 pinhole rays, 30° horizontal field of view, from (0, 0, 0.45) m looking down -z
/// (image x = world +x, image y = world -y).
fn primary_rays() -> Vec<MeshRay> {
    let (w, h) = (1500u32, 1000u32);
    let f = 0.5 * w as f64 / (15f64.to_radians()).tan();
    let (cx, cy) = ((w as f64 - 1.0) * 0.5, (h as f64 - 1.0) * 0.5);
    let origin = Vec3::new(0.0, 0.0, 0.45);
    let mut rays = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let d = DVec3::new((x as f64 - cx) / f, -(y as f64 - cy) / f, -1.0).normalize();
            rays.push(MeshRay::new(origin, d.as_vec3()));
        }
    }
    rays
}

fn bench(c: &mut Criterion) {
    let mesh = head_mesh();
    let dir = PathBuf::from(std::env::var("CARGO_TARGET_DIR").unwrap_or_else(|_| "target".into()))
        .join("skinbrdf-bench");
    if std::fs::create_dir_all(&dir).is_ok() {
        let _ = skinbrdf_mesh::write_ply_binary(&dir.join("head200k.ply"), &mesh);
    }
    let rays = primary_rays();
    let mut g = c.benchmark_group("rays");
    g.sample_size(10);
    g.bench_function("build_medium_200k", |b| {
        b.iter(|| MeshBvh::build(black_box(&mesh), BuildQuality::Medium).expect("valid mesh"))
    });
    let bvh = MeshBvh::build(&mesh, BuildQuality::Medium).expect("valid mesh");
    let hits = bvh
        .intersect_batch(&rays)
        .iter()
        .filter(|h| h.is_some())
        .count();
    eprintln!(
        "{} triangles, {} rays, {} hits ({:.1}%), rayon threads {}",
        mesh.indices.len(),
        rays.len(),
        hits,
        100.0 * hits as f64 / rays.len() as f64,
        rayon::current_num_threads()
    );
    g.throughput(Throughput::Elements(rays.len() as u64));
    let dirs: Vec<Vec3> = rays.iter().map(|r| r.dir).collect();
    g.bench_function("primary_1.5Mpx_grid_closest_hit_parallel", |b| {
        b.iter(|| {
            bvh.intersect_grid(
                Vec3::new(0.0, 0.0, 0.45),
                black_box(&dirs),
                1500,
                f32::INFINITY,
            )
        })
    });
    g.bench_function("primary_1.5Mpx_closest_hit_parallel", |b| {
        b.iter(|| bvh.intersect_batch(black_box(&rays)))
    });
    g.bench_function("primary_1.5Mpx_occlusion_parallel", |b| {
        b.iter(|| bvh.occluded_batch(black_box(&rays)))
    });
    g.bench_function("primary_1.5Mpx_closest_hit_1_thread", |b| {
        b.iter(|| {
            rays.iter()
                .map(|r| bvh.intersect(r.origin, r.dir, r.t_max))
                .filter(Option::is_some)
                .count()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
