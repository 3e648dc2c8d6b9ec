//! Derendering 24 MP images against the time to decode them.
//!
//! Generates (once, cached in `--dir`) the default synthetic scene at 6000 x 4000 pixels with
//! `--images` measurement images (default 4) and one ray per pixel, with sensor noise, then
//! derenders it with the default settings and prints the stage times: image decoding and
//! linearization (the `skinbrdf-session` loader, all rayon threads) against the derender
//! proper (camera table, region projection, rays, samples), and the error against the truth.
//!
//! ```text
//! cargo run --release -p skinbrdf-derender --example derender_24mp -- [--dir DIR] [--images N] [--regen] [--runs R]
//! ```
//!
//! `--resolution WxH`, `--spp N` and `--images N` (`--images 0` keeps the scene's count) make
//! it any synthetic session: `--resolution 1524x1012 --spp 4 --images 0 --regen` is the
//! default session (and times its synthesis); `--noise-free` renders without sensor and scanner
//! noise.

use std::path::PathBuf;
use std::time::Instant;

use skinbrdf_derender::{derender_session, DerenderConfig, ResolvedPoses, TargetMask};
use skinbrdf_synth::{generate, Scene, SynthOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let opt = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let dir = PathBuf::from(opt("--dir").unwrap_or_else(|| {
        std::env::temp_dir()
            .join("skinbrdf_24mp")
            .display()
            .to_string()
    }));
    let images: u32 = opt("--images").map(|s| s.parse()).transpose()?.unwrap_or(4);
    let spp: u32 = opt("--spp").map(|s| s.parse()).transpose()?.unwrap_or(1);
    let resolution = match opt("--resolution") {
        Some(r) => {
            let (w, h) = r.split_once('x').ok_or("--resolution WxH")?;
            (w.parse()?, h.parse()?)
        }
        None => (6000, 4000),
    };
    let runs: usize = opt("--runs").map(|s| s.parse()).transpose()?.unwrap_or(2);
    if args.iter().any(|a| a == "--regen") || !dir.join("session.toml").exists() {
        let mut scene = Scene::load("default")?;
        if images > 0 {
            scene.session.measurement_images = images;
        }
        let t = Instant::now();
        let s = generate(
            &scene,
            &SynthOptions {
                resolution: Some(resolution),
                samples_per_pixel: Some(spp),
                noise_free: args.iter().any(|a| a == "--noise-free"),
                ..Default::default()
            },
            &dir,
        )?;
        println!(
            "generated {} images {}x{} into {} in {:.1} s ({} rays)",
            s.images,
            s.resolution.0,
            s.resolution.1,
            dir.display(),
            t.elapsed().as_secs_f64(),
            s.rays
        );
    }
    let session =
        skinbrdf_session::Session::load(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let cfg = DerenderConfig::DEFAULT;
    for run in 0..runs.max(1) {
        let r =
            derender_session(&session, &truth_poses(&session)?, TargetMask::Printed, &cfg)?.report;
        let t = &r.times;
        let decode = t.image_load_s;
        let proper = t.total_s - decode;
        println!(
            "run {run}: {} measurement images: {} region pixels, {} primary rays, {} samples kept",
            r.images.len(),
            r.region_pixels,
            r.primary_rays,
            r.counts.kept
        );
        println!(
            "  decode + linearize {decode:.3} s | derender proper {proper:.3} s = {:.2} x decode (mesh {:.3}, bvh {:.3}, normals {:.3}, C {:.3}, rays+samples {:.3} of which primary rays {:.3}) | total {:.3} s",
            proper / decode.max(1e-9),
            t.mesh_load_s,
            t.bvh_s,
            t.normals_s,
            t.calibration_s,
            t.derender_s,
            t.rays_s,
            t.total_s
        );
        println!(
            "  {:.2} M primary rays/s traced, {:.2} M pixels/s derendered",
            r.primary_rays as f64 / t.rays_s.max(1e-9) / 1e6,
            r.primary_rays as f64 / t.derender_s.max(1e-9) / 1e6
        );
        if let Some(e) = &r.truth_error {
            println!(
                "  median relative error vs truth {:.3}% (p90 {:.3}%)",
                e.median_rel_error * 100.0,
                e.p90_rel_error * 100.0
            );
        }
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
