//! Detects tag36h11 tags in image files and prints one JSON line per image:
//! `{"file": ..., "ms": ..., "detections": [...]}` (corners in the project's pixel convention).
//!
//! `cargo run --release -p skinbrdf-targets --example detect_json -- [--binary-boundary] [--profile] IMAGE...`
//! (`--binary-boundary`: report the reference library's unrefined quad corners,
//! [`CornerModel::BinaryBoundary`], instead of the edge-refined ones; `--profile`: fit small
//! tags' edge profiles, `DetectorConfig::profile_small_tags`).

use skinbrdf_targets::{detect::detect_with_stats, CornerModel, DetectorConfig, GrayF32};
use std::path::Path;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut cfg = DetectorConfig::default();
    for f in std::env::args().skip(1) {
        if f == "--binary-boundary" {
            cfg.corner_model = CornerModel::BinaryBoundary;
            continue;
        }
        if f == "--profile" {
            cfg.profile_small_tags = true;
            continue;
        }
        let img = GrayF32::load(Path::new(&f))?;
        let t0 = Instant::now();
        let (dets, stats) = detect_with_stats(&img, &cfg);
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let dets: Vec<_> = dets
            .iter()
            .map(|d| {
                serde_json::json!({
                    "id": d.id,
                    "corners": d.corners_px.iter().map(|c| [c.x, c.y]).collect::<Vec<_>>(),
                    "sigma": d.corner_sigma_px(),
                    "hamming": d.hamming,
                    "margin": d.decision_margin,
                    "occluded": d.occluded_corners,
                })
            })
            .collect();
        println!(
            "{}",
            serde_json::json!({"file": f, "ms": ms, "stats": stats, "detections": dets})
        );
    }
    Ok(())
}
