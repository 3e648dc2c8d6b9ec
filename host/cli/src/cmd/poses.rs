//! `skinbrdf poses SESSION_DIR [--json]`: detect the coded targets in every image, estimate the
//! camera, head, flash and standard poses with covariances, write `out/poses.json` (atomically)
//! and print per image the targets found, reprojection RMS and time. With `truth.json` present,
//! errors against the truth are printed too.
//!
//! `skinbrdf poses --scenes all --work DIR` is the per-scene benchmark: it renders every
//! built-in scene (or the comma-separated list given) into `DIR/<scene>` (kept with `--keep`,
//! reused with `--reuse`),
//! estimates its poses and prints one Markdown row per scene of the errors against the truth
//! (medians over the images) and the cost (`--json`: the same as JSON).

use anyhow::Context;
use skinbrdf_poses::session::{compare_truth, median};
use skinbrdf_poses::{estimate_session, PoseConfig};
use skinbrdf_session::{write_json_atomic, Session};
use std::path::PathBuf;

/// Flags of `skinbrdf poses`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session directory (not with `--scenes`).
    #[arg(required_unless_present = "scenes")]
    pub session: Option<PathBuf>,
    /// Benchmark: `all` or a comma-separated list of built-in scenes, rendered into `--work`.
    #[arg(long, conflicts_with = "session")]
    pub scenes: Option<String>,
    /// Working directory of `--scenes` (one session per scene).
    #[arg(long, default_value = "poses-bench")]
    pub work: PathBuf,
    /// With `--scenes`: reuse a scene's session already rendered in `--work`.
    #[arg(long)]
    pub reuse: bool,
    /// With `--scenes`: keep each rendered session (by default it is removed once measured:
    /// ~270 MB per scene).
    #[arg(long)]
    pub keep: bool,
    /// Print a machine-readable summary instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Recalibrate the camera from the reference field even if session.toml calibrates it.
    #[arg(long)]
    pub recalibrate: bool,
    /// Output file (default SESSION/out/poses.json).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(list) = &args.scenes {
        return bench_scenes(list, &args);
    }
    let dir = args.session.clone().context("SESSION_DIR is required")?;
    let session = Session::load(&dir)
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("loading session {}", dir.display()))?;
    let cfg = PoseConfig {
        recalibrate: args.recalibrate,
        ..PoseConfig::default()
    };
    let est = estimate_session(&session, &cfg).context("estimating poses")?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| dir.join("out").join("poses.json"));
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    write_json_atomic(&out, &est).map_err(|e| anyhow::anyhow!("{e}"))?;
    let truth = session
        .load_truth()
        .transpose()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let errs = truth.as_ref().map(|t| compare_truth(&est, t));
    if args.json {
        let images: Vec<_> = est
            .images
            .iter()
            .enumerate()
            .map(|(i, im)| {
                serde_json::json!({
                    "file": im.file,
                    "role": im.role,
                    "targets_found": im.targets_found,
                    "camera_rms_px": im.world_from_camera.as_ref().map(|p| p.rms_px),
                    "camera_position_sigma_m": im.world_from_camera.as_ref().map(|p| p.position_sigma_m()),
                    "detect_ms": im.detect_ms,
                    "pose_ms": im.pose_ms,
                    "camera_position_error_m": errs.as_ref().map(|e| e.camera_position_error_m[i]),
                    "camera_orientation_error_deg": errs.as_ref().map(|e| e.camera_orientation_error_deg[i]),
                    "head_position_error_m": errs.as_ref().map(|e| e.head_position_error_m[i]),
                    "diagnostics": im.diagnostics,
                    "errors": im.errors,
                })
            })
            .collect();
        let summary = serde_json::json!({
            "poses_file": out,
            "images": images,
            "light_position_m": est.light_position_m,
            "skipped": est.skipped,
            "bundle": est.bundle,
            "total_ms": est.total_ms,
            "calibration": est.calibration.as_ref().map(|c| serde_json::json!({
                "camera": c.camera, "sigma": c.sigma, "rms_px": c.rms_px})),
            "errors_vs_truth": errs.as_ref().map(|e| serde_json::json!({
                "camera_position_error_median_m": median(&e.camera_position_error_m),
                "camera_orientation_error_median_deg": median(&e.camera_orientation_error_deg),
                "head_position_error_median_m": median(&e.head_position_error_m),
                "head_orientation_error_median_deg": median(&e.head_orientation_error_deg),
                "light_position_error_m": e.light_position_error_m,
                "standard_position_error_m": e.standard_position_error_m,
                "focal_error_px": e.focal_error_px,
                "detection": e.corner_summary(),
                "false_detections": e.false_detections,
            })),
        });
        println!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(());
    }
    println!(
        "{:<28} {:<18} {:>4} {:>4} {:>4} {:>8} {:>8} {:>8} {:>9} {:>9} {:>9}",
        "image",
        "role",
        "ref",
        "head",
        "fl",
        "rms_px",
        "det_ms",
        "pose_ms",
        "cam_mm",
        "cam_deg",
        "head_mm"
    );
    for (i, im) in est.images.iter().enumerate() {
        let n = |k: &str| im.targets_found.get(k).copied().unwrap_or(0);
        let fl = n("flash") + n("standard");
        let rms = im
            .world_from_camera
            .as_ref()
            .map(|p| format!("{:.3}", p.rms_px))
            .unwrap_or_else(|| "-".into());
        let e = |v: Option<f64>, s: f64, p: usize| match v {
            Some(x) if x.is_finite() => format!("{:.*}", p, x * s),
            _ => "-".into(),
        };
        println!(
            "{:<28} {:<18} {:>4} {:>4} {:>4} {:>8} {:>8.1} {:>8.1} {:>9} {:>9} {:>9}",
            im.file,
            format!("{:?}", im.role),
            n("reference"),
            n("headdress"),
            fl,
            rms,
            im.detect_ms,
            im.pose_ms,
            e(errs.as_ref().map(|e| e.camera_position_error_m[i]), 1e3, 3),
            e(
                errs.as_ref().map(|e| e.camera_orientation_error_deg[i]),
                1.0,
                4
            ),
            e(errs.as_ref().map(|e| e.head_position_error_m[i]), 1e3, 3),
        );
        for d in &im.diagnostics {
            println!("    warning: {d:?}");
        }
        for d in &im.errors {
            println!("    error: {d}");
        }
    }
    if let Some(c) = &est.calibration {
        println!(
            "calibration: fx {:.2} ± {:.2} px, k1 {:.4} ± {:.4}, rms {:.3} px over {} points",
            c.camera.fx_px, c.sigma[0], c.camera.distortion.k1, c.sigma[4], c.rms_px, c.points
        );
    }
    if let Some(l) = est.light_position_m {
        println!("flash position: {:.4} {:.4} {:.4} m", l.x, l.y, l.z);
    }
    for s in &est.skipped {
        println!("skipped: {s}");
    }
    if let Some(b) = &est.bundle {
        println!(
            "bundle adjustment: {} corners ({} targets gated out), {} parameters, robust cost {:.1} -> {:.1} ({:.2}% lower), rms {:.3} -> {:.3} px, {} down-weighted, {} iterations, {:.0} ms",
            b.observations,
            b.gated_targets,
            b.parameters,
            b.initial_cost,
            b.final_cost,
            100.0 * b.relative_improvement,
            b.initial_rms_px,
            b.final_rms_px,
            b.downweighted,
            b.iterations,
            b.time_ms
        );
    }
    if let Some(e) = &errs {
        println!(
            "vs truth (median): camera position error {:.3} mm, orientation error {:.4} deg, head position error {:.3} mm, head orientation error {:.4} deg",
            median(&e.camera_position_error_m) * 1e3,
            median(&e.camera_orientation_error_deg),
            median(&e.head_position_error_m) * 1e3,
            median(&e.head_orientation_error_deg)
        );
        if let Some(l) = e.light_position_error_m {
            println!("vs truth: flash position error {:.3} mm", l * 1e3);
        }
        if let Some(s) = e.standard_position_error_m {
            println!("vs truth: standard position error {:.3} mm", s * 1e3);
        }
        for (layout, c) in e.corner_summary() {
            println!(
                "vs truth: {layout} corners: {} compared, error median {:.3} px, p90 {:.3}, max {:.3}, error/sigma median {:.2} (1.18 if the sigmas are honest); {} fully visible targets missed",
                c.corners,
                c.corner_error_median_px,
                c.corner_error_p90_px,
                c.corner_error_max_px,
                c.error_over_sigma_median,
                c.missed_targets
            );
        }
        println!(
            "vs truth: {} detections of ids not in their image",
            e.false_detections
        );
    }
    println!(
        "poses written to {} in {:.0} ms",
        out.display(),
        est.total_ms
    );
    Ok(())
}

/// One row of the per-scene benchmark.
#[derive(Debug, serde::Serialize)]
struct SceneRow {
    scene: String,
    measurement_images: usize,
    images_with_camera_pose: usize,
    measurement_images_with_head_pose: usize,
    camera_position_error_median_mm: f64,
    camera_orientation_error_median_deg: f64,
    head_position_error_median_mm: f64,
    head_position_error_max_mm: f64,
    head_position_error_median_before_bundle_mm: f64,
    bundle_cost_before: Option<f64>,
    bundle_cost_after: Option<f64>,
    bundle_ms: Option<f64>,
    head_orientation_error_median_deg: f64,
    flash_position_error_mm: Option<f64>,
    standard_position_error_mm: Option<f64>,
    detect_plus_pose_per_image_median_ms: f64,
    poses_total_s: f64,
}

fn bench_scenes(list: &str, args: &Args) -> anyhow::Result<()> {
    use skinbrdf_session::ImageRole;
    use skinbrdf_synth::{generate, Scene, SynthOptions, BUILTIN_SCENES};
    let names: Vec<String> = if list == "all" {
        BUILTIN_SCENES.iter().map(|(n, _)| n.to_string()).collect()
    } else {
        list.split(',').map(|s| s.trim().to_string()).collect()
    };
    let mut rows = Vec::new();
    for name in &names {
        let dir = args.work.join(name);
        if !(args.reuse && dir.join("session.toml").is_file()) {
            let scene = Scene::load(name).with_context(|| format!("scene {name}"))?;
            generate(&scene, &SynthOptions::default(), &dir)
                .with_context(|| format!("rendering scene {name} into {}", dir.display()))?;
        }
        let session = Session::load(&dir)
            .map_err(|e| anyhow::anyhow!("{e}"))
            .with_context(|| format!("loading session {}", dir.display()))?;
        let truth = session
            .load_truth()
            .transpose()
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .with_context(|| format!("{}: no truth.json", dir.display()))?;
        let (before, est) =
            skinbrdf_poses::session::estimate_session_stages(&session, &PoseConfig::default())
                .with_context(|| format!("estimating the poses of {name}"))?;
        let e = compare_truth(&est, &truth);
        let e0 = compare_truth(&before, &truth);
        let meas: Vec<usize> = est
            .images
            .iter()
            .enumerate()
            .filter(|(_, im)| im.role == ImageRole::Measurement)
            .map(|(i, _)| i)
            .collect();
        let head_mm: Vec<f64> = meas
            .iter()
            .map(|&i| e.head_position_error_m[i] * 1e3)
            .collect();
        let per_image: Vec<f64> = est
            .images
            .iter()
            .map(|im| im.detect_ms + im.pose_ms)
            .collect();
        let row = SceneRow {
            scene: name.clone(),
            measurement_images: meas.len(),
            images_with_camera_pose: est
                .images
                .iter()
                .filter(|im| im.world_from_camera.is_some())
                .count(),
            measurement_images_with_head_pose: meas
                .iter()
                .filter(|&&i| est.images[i].world_from_head.is_some())
                .count(),
            camera_position_error_median_mm: median(&e.camera_position_error_m) * 1e3,
            camera_orientation_error_median_deg: median(&e.camera_orientation_error_deg),
            head_position_error_median_mm: median(&head_mm),
            head_position_error_max_mm: head_mm
                .iter()
                .copied()
                .filter(|v| v.is_finite())
                .fold(f64::NAN, f64::max),
            head_position_error_median_before_bundle_mm: median(
                &meas
                    .iter()
                    .map(|&i| e0.head_position_error_m[i] * 1e3)
                    .collect::<Vec<_>>(),
            ),
            bundle_cost_before: est.bundle.as_ref().map(|b| b.initial_cost),
            bundle_cost_after: est.bundle.as_ref().map(|b| b.final_cost),
            bundle_ms: est.bundle.as_ref().map(|b| b.time_ms),
            head_orientation_error_median_deg: median(&e.head_orientation_error_deg),
            flash_position_error_mm: e.light_position_error_m.map(|v| v * 1e3),
            standard_position_error_mm: e.standard_position_error_m.map(|v| v * 1e3),
            detect_plus_pose_per_image_median_ms: median(&per_image),
            poses_total_s: est.total_ms * 1e-3,
        };
        if !args.json {
            eprintln!("{name}: done");
        }
        rows.push(row);
        if !args.keep {
            std::fs::remove_dir_all(&dir).with_context(|| format!("removing {}", dir.display()))?;
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!("| scene | camera pos. (mm) | camera orient. (deg) | head pos. median / max (mm) | head pos. before BA (mm) | head posed | head orient. (deg) | flash (mm) | standard (mm) | BA cost before -> after | BA (ms) | detect+pose per image (ms) | poses total (s) |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let opt = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |x| format!("{x:.3}"));
    for r in &rows {
        println!(
            "| {} | {:.3} | {:.4} | {:.3} / {:.3} | {:.3} | {}/{} | {:.4} | {} | {} | {} | {} | {:.0} | {:.1} |",
            r.scene,
            r.camera_position_error_median_mm,
            r.camera_orientation_error_median_deg,
            r.head_position_error_median_mm,
            r.head_position_error_max_mm,
            r.head_position_error_median_before_bundle_mm,
            r.measurement_images_with_head_pose,
            r.measurement_images,
            r.head_orientation_error_median_deg,
            opt(r.flash_position_error_mm),
            opt(r.standard_position_error_mm),
            match (r.bundle_cost_before, r.bundle_cost_after) {
                (Some(a), Some(b)) => format!("{a:.0} -> {b:.0}"),
                _ => "-".into(),
            },
            r.bundle_ms.map_or_else(|| "-".into(), |v| format!("{v:.0}")),
            r.detect_plus_pose_per_image_median_ms,
            r.poses_total_s
        );
    }
    Ok(())
}
