//! `skinbrdf poses SESSION_DIR [--json]`: detect the coded targets in every image, estimate the
//! camera, head, flash and standard poses with covariances, write `out/poses.json` (atomically)
//! and print per image the targets found, reprojection RMS and time. With `truth.json` present,
//! errors against the truth are printed too. When the camera was calibrated (`--recalibrate`,
//! or `status = "to-be-calibrated"`), the calibration is also written as `camera.toml` beside
//! `poses.json`: the `[camera]` table that `skinbrdf ingest --camera` reads.
//!
//! `skinbrdf poses --scenes all --work DIR` is the per-scene benchmark: it renders every
//! built-in scene (or the comma-separated list given) into `DIR/<scene>` (kept with `--keep`,
//! reused with `--reuse`),
//! estimates its poses and prints one Markdown row per scene of the errors against the truth
//! (medians over the images) and the cost (`--json`: the same as JSON).

use anyhow::Context;
use skinbrdf_poses::session::{compare_truth, median};
use skinbrdf_poses::PoseConfig;
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
    // A session with placements nobody measured is surveyed first (or its current survey
    // reused), as `process` does.
    let mut progress = super::StageProgress::default();
    let (session, _) = skinbrdf_pipeline::survey::surveyed_session(
        &dir,
        &skinbrdf_pipeline::process::ProcessConfig::new(),
        &mut |e| match e {
            skinbrdf_pipeline::process::Event::Finished(r)
                if r.stage == skinbrdf_pipeline::Stage::PlacementSurvey =>
            {
                super::process::print_event(&mut progress, e)
            }
            skinbrdf_pipeline::process::Event::Started(_) => {
                super::process::print_event(&mut progress, e)
            }
            _ => {}
        },
    )
    .with_context(|| format!("loading session {}", dir.display()))?;
    progress.finish();
    let cfg = PoseConfig {
        recalibrate: args.recalibrate,
        ..PoseConfig::default()
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| dir.join("out").join(skinbrdf_pipeline::stages::POSES_FILE));
    let (est, files) = skinbrdf_pipeline::stages::estimate_and_write_poses(&session, &cfg, &out)?;
    if let Some(path) = &files.camera {
        eprintln!(
            "camera calibration written to {} (`skinbrdf ingest --camera`)",
            path.display()
        );
    }
    let truth = session.load_truth().transpose()?;
    let errs = truth.as_ref().map(|t| compare_truth(&est, t));
    if args.json {
        // An error the truth cannot give (an image without a pose: NaN in `compare_truth`'s
        // per-image lists, a median of nothing) is `null`, stated here rather than left to
        // serde_json's silent NaN-to-null.
        let finite = |v: f64| Some(v).filter(|v| v.is_finite());
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
                    "camera_position_error_m": errs.as_ref().and_then(|e| finite(e.camera_position_error_m[i])),
                    "camera_orientation_error_deg": errs.as_ref().and_then(|e| finite(e.camera_orientation_error_deg[i])),
                    "head_position_error_m": errs.as_ref().and_then(|e| finite(e.head_position_error_m[i])),
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
                "camera_position_error_median_m": finite(median(&e.camera_position_error_m)),
                "camera_orientation_error_median_deg": finite(median(&e.camera_orientation_error_deg)),
                "head_position_error_median_m": finite(median(&e.head_position_error_m)),
                "head_orientation_error_median_deg": finite(median(&e.head_orientation_error_deg)),
                "light_position_error_m": e.light_position_error_m,
                "standard_position_error_m": e.standard_position_error_m,
                "focal_error_px": e.focal_error_px,
                "detection": e.corner_summary(),
                "false_detections": e.false_detections,
            })),
        });
        super::print_json(&summary)?;
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
            im.role.name(),
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
            println!("    warning: {d}");
        }
        for d in &im.errors {
            println!("    error: {d}");
        }
    }
    if let Some(c) = &est.calibration {
        // A sigma that was not estimated (held fixed) is said so, not printed as a number.
        let pm = |s: Option<f64>, digits: usize| {
            s.map_or_else(
                || "(sd not estimated)".to_string(),
                |s| format!("± {s:.digits$}"),
            )
        };
        println!(
            "calibration: fx {:.2} {} px, k1 {:.4} {}, rms {:.3} px over {} points",
            c.camera.fx_px,
            pm(c.sigma[0], 2),
            c.camera.distortion.k1,
            pm(c.sigma[4], 4),
            c.rms_px,
            c.points
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
        // A statistic of no corners (every target of the layout missed) is "-".
        let stat = |v: Option<f64>, digits: usize| {
            v.map_or_else(|| "-".to_string(), |v| format!("{v:.digits$}"))
        };
        for (layout, c) in e.corner_summary() {
            println!(
                "vs truth: {layout} corners: {} compared, error median {} px, p90 {}, max {}, error/sigma median {} (1.18 if the sigmas are honest); {} fully visible targets missed",
                c.corners,
                stat(c.corner_error_median_px, 3),
                stat(c.corner_error_p90_px, 3),
                stat(c.corner_error_max_px, 3),
                stat(c.error_over_sigma_median, 2),
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
fn bench_scenes(list: &str, args: &Args) -> anyhow::Result<()> {
    let cfg = skinbrdf_pipeline::scenes::ScenesConfig {
        scenes: if list == "all" {
            Vec::new()
        } else {
            list.split(',').map(|s| s.trim().to_string()).collect()
        },
        work: args.work.clone(),
        reuse: args.reuse,
        keep: args.keep,
    };
    let json = args.json;
    let rows = skinbrdf_pipeline::scenes::pose_scenes(&cfg, &mut |name| {
        if !json {
            eprintln!("{name}: done");
        }
    })?;
    if json {
        super::print_json(&rows)?;
    } else {
        print!("{}", skinbrdf_pipeline::scenes::markdown(&rows));
    }
    Ok(())
}
