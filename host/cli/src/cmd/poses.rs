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
use skinbrdf_poses::session::compare_truth;
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
        super::print_json(&crate::print::poses::json(&est, errs.as_ref(), &out))?;
    } else {
        crate::print::poses::text(&est, errs.as_ref(), &out);
    }
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
