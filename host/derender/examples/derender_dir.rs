//! Derenders one synthetic session directory with the default settings (poses, light and
//! camera from `truth.json`: the pipeline resolves a real session's poses) and prints the stage
//! times, the ray throughput and the error against the true BRDF. Nothing is written.
//!
//! ```text
//! cargo run --release -p skinbrdf-derender --example derender_dir -- SESSION_DIR [--bvh-quality Q] [--stride N]
//! ```

use skinbrdf_derender::{derender_session, DerenderConfig, ResolvedPoses, TargetMask};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = args
        .first()
        .ok_or("usage: derender_dir SESSION_DIR [--bvh-quality Q]")?;
    let opt = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let mut cfg = DerenderConfig::DEFAULT;
    if let Some(q) = opt("--bvh-quality") {
        cfg.bvh_quality = q.parse()?;
    }
    if let Some(s) = opt("--stride") {
        cfg.stride = s.parse()?;
    }
    let session = skinbrdf_session::Session::load(std::path::Path::new(dir))
        .map_err(|e| format!("{dir}: {e}"))?;
    let run = derender_session(&session, &truth_poses(&session)?, TargetMask::Printed, &cfg)?;
    let r = &run.report;
    let t = &r.times;
    let (w, h) = session
        .file
        .camera
        .model()
        .copied()
        .or_else(|| session.load_truth().and_then(Result::ok).map(|t| t.camera))
        .map(|c| (c.width_px, c.height_px))
        .unwrap_or((0, 0));
    println!(
        "{dir}: {} measurement images {w}x{h}, {} triangles, {} region pixels, {} primary rays, {} kept",
        r.images.len(),
        run.triangles,
        r.region_pixels,
        r.primary_rays,
        r.counts.kept
    );
    println!(
        "times (s): mesh {:.3}, bvh ({}) {:.3}, normals {:.3}, convexity {:.3}, image decode {:.3}, C {:.3}, rays+samples {:.3} (primary rays {:.3}), total {:.3}",
        t.mesh_load_s,
        cfg.bvh_quality.name(),
        t.bvh_s,
        t.normals_s,
        t.convexity_s,
        t.image_load_s,
        t.calibration_s,
        t.derender_s,
        t.rays_s,
        t.total_s
    );
    println!(
        "throughput: {:.2} M primary rays/s traced, {:.2} M pixels/s derendered (rays + samples)",
        r.primary_rays as f64 / t.rays_s.max(1e-9) / 1e6,
        r.primary_rays as f64 / t.derender_s.max(1e-9) / 1e6
    );
    for (reason, n) in r.counts.reasons() {
        if n > 0 {
            println!("  dropped {reason:<18} {n}");
        }
    }
    if let Some(e) = &r.truth_error {
        println!(
            "median relative error vs truth {:.3}% (p90 {:.3}%) over {} samples",
            e.median_rel_error * 100.0,
            e.p90_rel_error * 100.0,
            e.samples
        );
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
