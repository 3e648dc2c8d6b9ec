//! Full-size render of one default measurement image (1524 x 1012, 4 rays per pixel), and
//! the one-time set-up (tessellation + BVH builds). `cargo bench -p skinbrdf-synth`.

use criterion::{criterion_group, criterion_main, Criterion};
use skinbrdf_synth::layout::{build_rig, plan_shots};
use skinbrdf_synth::photograph::Renderer;
use skinbrdf_synth::Scene;

fn bench(c: &mut Criterion) {
    let scene = Scene::load("default").expect("built-in scene");
    let rig = build_rig(&scene);
    let shots = plan_shots(&scene, &rig);
    let mut g = c.benchmark_group("synth");
    g.sample_size(10);
    g.bench_function("setup_rig_and_bvhs", |b| {
        b.iter(|| Renderer::new(&scene, &rig).expect("renderer"))
    });
    let renderer = Renderer::new(&scene, &rig).expect("renderer");
    g.bench_function("render_measurement_1524x1012_spp4", |b| {
        b.iter(|| renderer.render(&shots[10], &rig, 1, true))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
