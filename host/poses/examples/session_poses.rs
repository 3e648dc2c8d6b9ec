//! Generates a synthetic session (`skinbrdf-synth`, scene `default` unless given) if DIR has no
//! session.toml, then estimates every pose and prints the errors against truth.json.
//!
//! `cargo run --release -p skinbrdf-poses --example session_poses -- DIR [SCENE]`

use skinbrdf_poses::session::{compare_truth, median};
use skinbrdf_poses::{estimate_session, PoseConfig};
use skinbrdf_session::Session;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().ok_or("usage: session_poses DIR [SCENE]")?);
    let scene = args.next().unwrap_or_else(|| "default".into());
    if !dir.join("session.toml").exists() {
        let s = skinbrdf_synth::Scene::load(&scene)?;
        let t = std::time::Instant::now();
        let sum = skinbrdf_synth::generate(&s, &skinbrdf_synth::SynthOptions::default(), &dir)?;
        eprintln!(
            "generated {} images {:?} in {:.1} s",
            sum.images,
            sum.resolution,
            t.elapsed().as_secs_f64()
        );
    }
    let session = Session::load(&dir).map_err(|e| e.to_string())?;
    let est = estimate_session(&session, &PoseConfig::default())?;
    let truth = session.load_truth().transpose()?;
    for im in &est.images {
        println!(
            "{:<24} {:?} found {:?} rms {:?} det {:.1} ms pose {:.1} ms errors {:?} diag {:?}",
            im.file,
            im.role,
            im.targets_found,
            im.world_from_camera.as_ref().map(|p| p.rms_px),
            im.detect_ms,
            im.pose_ms,
            im.errors,
            im.diagnostics
        );
    }
    if let Some(t) = truth {
        let e = compare_truth(&est, &t);
        println!(
            "median camera position error {:.4} mm, orientation {:.5} deg, head {:.4} mm / {:.5} deg; flash {:?} mm; standard {:?} mm; total {:.0} ms",
            median(&e.camera_position_error_m) * 1e3,
            median(&e.camera_orientation_error_deg),
            median(&e.head_position_error_m) * 1e3,
            median(&e.head_orientation_error_deg),
            e.light_position_error_m.map(|x| x * 1e3),
            e.standard_position_error_m.map(|x| x * 1e3),
            est.total_ms
        );
        for (i, im) in est.images.iter().enumerate() {
            println!(
                "{:<24} camera {:.3} mm {:.4} deg  head {:.3} mm {:.4} deg (head targets {:?}, sigma {:.3} mm)",
                im.file,
                e.camera_position_error_m[i] * 1e3,
                e.camera_orientation_error_deg[i],
                e.head_position_error_m[i] * 1e3,
                e.head_orientation_error_deg[i],
                im.world_from_head.as_ref().map(|h| h.targets_used),
                im.world_from_head.as_ref().map(|h| h.position_sigma_m() * 1e3).unwrap_or(f64::NAN),
            );
        }
        for im in &est.images {
            if let (Some(h), Some(ti)) = (im.world_from_head.as_ref(), t.image(&im.file)) {
                let d = h.pose.translation_m - ti.world_from_head.translation_m;
                let dc = ti.world_from_camera.rotation.inverse() * d;
                println!(
                    "{:<24} head error in camera frame (mm): {:.3} {:.3} {:.3}",
                    im.file,
                    dc.x * 1e3,
                    dc.y * 1e3,
                    dc.z * 1e3
                );
            }
        }
        let max = |v: &[f64]| {
            v.iter()
                .copied()
                .filter(|x| x.is_finite())
                .fold(0.0, f64::max)
        };
        println!(
            "max camera position error {:.4} mm, orientation {:.5} deg, head {:.4} mm",
            max(&e.camera_position_error_m) * 1e3,
            max(&e.camera_orientation_error_deg),
            max(&e.head_position_error_m) * 1e3
        );
    }
    Ok(())
}
