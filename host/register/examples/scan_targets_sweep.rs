//! Accuracy and run time of `find_scan_targets` on the default scene's synthetic textured scan
//! for a few settings, and of the alignment that follows (docs/benchmarks-register.md).
//!
//! `cargo run --release -p skinbrdf-register --example scan_targets_sweep`

use glam::DVec3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use skinbrdf_register::{align, find_scan_targets, AlignConfig, AlignKind, ScanTargetConfig};
use skinbrdf_synth::layout::build_rig;
use skinbrdf_synth::textured_scan::{scan_truth, write_textured_scan};
use skinbrdf_synth::Scene;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let scene = Scene::load("default")?;
    let rig = build_rig(&scene);
    let dir = tempfile::tempdir()?;
    let t = std::time::Instant::now();
    let files = write_textured_scan(dir.path(), &scene, &rig)?;
    let write_s = t.elapsed().as_secs_f64();
    let size: u64 = [&files.obj, &files.mtl, &files.png]
        .iter()
        .map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0))
        .sum();
    let t = std::time::Instant::now();
    let scan = skinbrdf_mesh::load_textured(&files.obj, &Default::default())?;
    let load_s = t.elapsed().as_secs_f64();
    println!(
        "scan: {} vertices, {} triangles, texture {}x{}, {:.2} MB, written in {write_s:.2} s, \
         loaded in {load_s:.2} s",
        files.vertices,
        files.triangles,
        files.texture_px.0,
        files.texture_px.1,
        size as f64 / 1e6
    );
    let truth = scan_truth(&scene, &rig);
    let wanted: Vec<(u32, f64)> = rig.headdress.iter().map(|t| (t.id, t.size_m)).collect();
    let d = ScanTargetConfig::default();
    let configs = [
        ("default", d),
        (
            "overview only",
            ScanTargetConfig {
                detail_ring: 0,
                detail_px: 64,
                detail_mm_per_px: 10.0,
                ..d
            },
        ),
        (
            "frontal detail only",
            ScanTargetConfig {
                detail_ring: 0,
                ..d
            },
        ),
        (
            "overview 1024 px, 26 views",
            ScanTargetConfig {
                overview_px: 1024,
                overview_views: 26,
                ..d
            },
        ),
        (
            "detail 0.08 mm/px, 640 px",
            ScanTargetConfig {
                detail_mm_per_px: 0.08,
                detail_px: 640,
                ..d
            },
        ),
        (
            "detail 0.2 mm/px, 320 px",
            ScanTargetConfig {
                detail_mm_per_px: 0.2,
                detail_px: 320,
                ..d
            },
        ),
        (
            "ring of 8 at 30 deg",
            ScanTargetConfig {
                detail_ring: 8,
                detail_tilt_deg: 30.0,
                ..d
            },
        ),
    ];
    println!(
        "| settings | found | views | corner err. RMS mm | max mm | fit residual mean mm | \
         rotation err. deg | translation err. mm | time s (overview + detail) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (name, cfg) in configs {
        let found = match find_scan_targets(&scan, &wanted, &cfg) {
            Ok(f) => f,
            Err(e) => {
                println!("| {name} | error: {e} |");
                continue;
            }
        };
        let mut errs = Vec::new();
        for t in &found.targets {
            if let Some(tr) = truth.targets.iter().find(|x| x.id == t.id) {
                for k in 0..4 {
                    errs.push(t.corners_m[k].distance(tr.corners_m[k]) * 1e3);
                }
            }
        }
        let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len().max(1) as f64).sqrt();
        let max = errs.iter().copied().fold(0.0, f64::max);
        let fit = found.targets.iter().map(|t| t.fit_residual_mm).sum::<f64>()
            / found.targets.len() as f64;
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = Normal::new(0.0, 1e-4)?;
        let survey: Vec<(u32, [DVec3; 4])> = rig
            .headdress
            .iter()
            .map(|t| {
                (
                    t.id,
                    t.corners_m.map(|c| {
                        c + DVec3::new(n.sample(&mut rng), n.sample(&mut rng), n.sample(&mut rng))
                    }),
                )
            })
            .collect();
        let scan_c: Vec<(u32, [DVec3; 4])> =
            found.targets.iter().map(|t| (t.id, t.corners_m)).collect();
        let a = align(&survey, &scan_c, AlignKind::Rigid, &AlignConfig::default())?;
        let rot = a
            .scan_from_survey
            .angle_to_rad(&truth.scanner_from_head)
            .to_degrees();
        let tr = a.scan_from_survey.distance_to_m(&truth.scanner_from_head) * 1e3;
        let tm = found.timing;
        println!(
            "| {name} | {}/{} | {} | {rms:.3} | {max:.3} | {fit:.3} | {rot:.4} | {tr:.3} | \
             {:.2} ({:.2} + {:.2}) |",
            found.targets.len(),
            wanted.len(),
            found.views_rendered,
            tm.total_s,
            tm.overview_s,
            tm.detail_s
        );
    }
    // The method's floor: the same scan without scanner noise.
    let mut quiet = scene.clone();
    quiet.geometry.scan_noise_m = 0.0;
    let qdir = tempfile::tempdir()?;
    let qfiles = write_textured_scan(qdir.path(), &quiet, &rig)?;
    let qscan = skinbrdf_mesh::load_textured(&qfiles.obj, &Default::default())?;
    let found = find_scan_targets(&qscan, &wanted, &d)?;
    let errs: Vec<f64> = found
        .targets
        .iter()
        .flat_map(|t| {
            let tr = truth.targets.iter().find(|x| x.id == t.id);
            (0..4).filter_map(move |k| tr.map(|tr| t.corners_m[k].distance(tr.corners_m[k]) * 1e3))
        })
        .collect();
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len().max(1) as f64).sqrt();
    let max = errs.iter().copied().fold(0.0, f64::max);
    println!(
        "noise-free scan, default settings: {}/{} found, corner error RMS {rms:.3} mm, max \
         {max:.3} mm, {:.2} s",
        found.targets.len(),
        wanted.len(),
        found.timing.total_s
    );
    Ok(())
}
