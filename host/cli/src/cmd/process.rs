//! `skinbrdf process SESSION_DIR`: the planned pipeline (poses, derendering, smoothing,
//! fitting), resumable, with every stage's accuracy and run time.

use std::path::PathBuf;

use skinbrdf_pipeline::process::{process, Event, ProcessConfig};
use skinbrdf_pipeline::report::StageStatus;
use skinbrdf_pipeline::PlanOptions;

/// Flags of `skinbrdf process`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session directory.
    pub session: PathBuf,
    /// Output directory (default SESSION/out).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Model: lambertian, lafortune1, lafortune2, lafortune3, cook-torrance.
    #[arg(long, default_value = "lafortune2")]
    pub model: skinbrdf_brdf::ModelSpec,
    /// Only the incidence plane: skip the rest of the hemisphere.
    #[arg(long)]
    pub incidence_plane_only: bool,
    /// Cast shadow rays even for a convex region.
    #[arg(long)]
    pub force_shadow_rays: bool,
    /// Use every N-th pixel in x and y.
    #[arg(long, default_value_t = 1)]
    pub stride: u32,
    /// Run every planned stage even if its inputs have not changed.
    #[arg(long)]
    pub force: bool,
    /// No figures.
    #[arg(long)]
    pub no_figures: bool,
    /// Also write the MERL binary table (35 MB).
    #[arg(long)]
    pub merl: bool,
    /// Print the run's report as JSON on stdout (progress goes to stderr).
    #[arg(long)]
    pub json: bool,
    /// Leave unreadable or implausible images out (each listed with its cause in the summary
    /// and the report) instead of failing.
    #[arg(long)]
    pub skip_bad_images: bool,
    /// Score against this ground truth (a synthetic session's `truth.json`) instead of the
    /// session's own: a session written by `skinbrdf ingest` from a synthetic studio pairs its
    /// images with the truth's by exposure index.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Go on when a stage FAILED its self-checks (the report still says FAILED); by default
    /// the stages after it do not run and the exit status is non-zero.
    #[arg(long)]
    pub accept_failed_checks: bool,
    /// How camera raw images load: `photosite` (each photosite a sample of its own channel
    /// along its own ray, full resolution) or `superpixel` (2x2 quads, half resolution, faster).
    #[arg(long, value_enum, default_value_t = super::RawModeArg::Photosite)]
    pub raw_mode: super::RawModeArg,
}

/// Validates the flags into a pipeline configuration.
pub fn config(args: &Args) -> anyhow::Result<ProcessConfig> {
    let mut cfg = ProcessConfig::new();
    cfg.plan = PlanOptions {
        incidence_plane_only: args.incidence_plane_only,
        force_shadow_rays: args.force_shadow_rays,
    };
    if args.stride == 0 {
        anyhow::bail!("--stride must be at least 1");
    }
    cfg.derender.stride = args.stride;
    cfg.fit.model = args.model;
    cfg.fit.figures = !args.no_figures;
    cfg.fit.merl = args.merl;
    cfg.force = args.force;
    cfg.out_dir = args.out.clone();
    cfg.skip_bad_images = args.skip_bad_images;
    if let Some(t) = &args.truth {
        if !t.is_file() {
            anyhow::bail!("--truth {}: no such file", t.display());
        }
    }
    cfg.truth_file = args.truth.clone();
    cfg.accept_failed_checks = args.accept_failed_checks;
    cfg.raw_mode = args.raw_mode.into();
    Ok(cfg)
}

/// Prints pipeline events to stderr, with a spinner while a stage runs.
pub(crate) fn print_event(progress: &mut super::StageProgress, e: Event<'_>) {
    match e {
        Event::Plan(p) => progress.println(p.to_text().trim_end()),
        Event::Started(s) => {
            tracing::info!(stage = s.name(), "stage started");
            progress.start(s.name());
        }
        Event::Finished(r) => {
            progress.finish();
            let status = match &r.status {
                StageStatus::Ran => format!("{:.3} s", r.run_time_s),
                StageStatus::Reused => "reused (inputs unchanged)".into(),
                StageStatus::Skipped { reason } => format!("skipped: {reason}"),
            };
            tracing::info!(stage = r.stage.name(), status = %status, "stage finished");
            progress.println(&format!("{:<30} {status}", r.stage.name()));
            for m in &r.metrics {
                progress.println(&format!("    {:<40} {:.4} {}", m.name, m.value, m.unit));
            }
            for n in &r.notes {
                progress.println(&format!("    note: {n}"));
            }
        }
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let cfg = config(&args)?;
    let mut progress = super::StageProgress::default();
    // The errors name the session directory or the file at fault themselves.
    let out = process(&args.session, &cfg, &mut |e| print_event(&mut progress, e))?;
    if args.json {
        super::print_json(&out.report)?;
    } else {
        print!("{}", out.report.to_text());
        println!(
            "report: {} (with the figures inline: {})",
            out.out_dir.join("report.md").display(),
            out.out_dir.join("report.html").display()
        );
    }
    Ok(())
}
