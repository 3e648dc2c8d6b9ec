//! Accuracy and cost of derendering on the default synthetic scene, per filter setting.
//!
//! ```text
//! cargo run --release -p skinbrdf-derender --example synthetic_accuracy -- [OUT_DIR] [--keep]
//! ```
//!
//! Generates the default scene twice (with sensor and scanner noise, and noise-free) with
//! `skinbrdf-synth`, derenders each with several settings and prints one table row per run:
//! samples kept, median / p90 relative error against `truth.json`'s BRDF, C's spread, and time.

use std::path::PathBuf;

use skinbrdf_derender::{derender_session, DerenderConfig, ResolvedPoses, ShadowMode, TargetMask};
use skinbrdf_mesh::NormalMethod;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let base = args
        .iter()
        .find(|a| !a.starts_with("--"))
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("skinbrdf-derender-accuracy"));
    let scene = skinbrdf_synth::Scene::load("default")?;
    println!("| scene | setting | kept | median rel. err | p90 | bias | C spread (G) | rays/s | derender s | total s |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for noise_free in [true, false] {
        let dir = base.join(if noise_free { "noise-free" } else { "noisy" });
        if !dir.join("session.toml").exists() {
            let s = skinbrdf_synth::generate(
                &scene,
                &skinbrdf_synth::SynthOptions {
                    noise_free,
                    ..Default::default()
                },
                &dir,
            )?;
            eprintln!(
                "generated {} ({} images {}x{}) in {:.1} s",
                dir.display(),
                s.images,
                s.resolution.0,
                s.resolution.1,
                s.total_s
            );
        }
        let session = skinbrdf_session::Session::load(&dir).map_err(|e| e.to_string())?;
        let settings: Vec<(&str, DerenderConfig)> = vec![
            (
                "default (75°, floor 0.01, fit auto)",
                DerenderConfig::DEFAULT,
            ),
            (
                "grazing 60°",
                DerenderConfig {
                    grazing_limit_deg: 60.0,
                    ..DerenderConfig::DEFAULT
                },
            ),
            (
                "grazing 85°",
                DerenderConfig {
                    grazing_limit_deg: 85.0,
                    ..DerenderConfig::DEFAULT
                },
            ),
            (
                "floor 0.03",
                DerenderConfig {
                    noise_floor: 0.03,
                    ..DerenderConfig::DEFAULT
                },
            ),
            (
                "vertex normals",
                DerenderConfig {
                    normals: NormalMethod::Vertex,
                    ..DerenderConfig::DEFAULT
                },
            ),
            (
                "shadow rays always",
                DerenderConfig {
                    shadows: ShadowMode::Always,
                    ..DerenderConfig::DEFAULT
                },
            ),
            (
                "stride 4",
                DerenderConfig {
                    stride: 4,
                    ..DerenderConfig::DEFAULT
                },
            ),
        ];
        for (name, cfg) in settings {
            let run =
                derender_session(&session, &truth_poses(&session)?, TargetMask::Printed, &cfg)?;
            let r = &run.report;
            let e = r.truth_error.as_ref();
            println!(
                "| {} | {} | {} | {:.3}% | {:.3}% | {:+.3}% | {:.3}% | {:.2} M | {:.2} | {:.2} |",
                if noise_free { "noise-free" } else { "noisy" },
                name,
                r.counts.kept,
                e.map_or(f64::NAN, |e| e.median_rel_error * 100.0),
                e.map_or(f64::NAN, |e| e.p90_rel_error * 100.0),
                e.map_or(f64::NAN, |e| e.median_signed_rel_error * 100.0),
                r.calibration
                    .as_ref()
                    .map_or(f64::NAN, |c| c.rel_spread[1] * 100.0),
                r.primary_rays as f64 / r.times.derender_s.max(1e-9) / 1e6,
                r.times.derender_s,
                r.times.total_s,
            );
            if name.starts_with("default") {
                eprintln!("{}", serde_json::to_string(&run)?);
            }
        }
    }
    if !args.iter().any(|a| a == "--keep") {
        let _ = std::fs::remove_dir_all(&base);
    }
    Ok(())
}

/// Every pose from the synthetic session's `truth.json` (derendering in isolation from the pose
/// stage).
fn truth_poses(
    session: &skinbrdf_session::Session,
) -> Result<ResolvedPoses, Box<dyn std::error::Error>> {
    let truth = session
        .load_truth()
        .ok_or("no truth.json: these examples derender synthetic sessions")??;
    Ok(ResolvedPoses::from_truth(session, &truth)?)
}
