//! `skinbrdf demo`: the whole system on the built-in default scene.

use std::path::PathBuf;

use anyhow::Context;
use skinbrdf_pipeline::demo::{capture_metrics, run_demo, DemoConfig, DemoEvent};

/// Flags of `skinbrdf demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directory.
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// Scene name or scene file.
    #[arg(long, default_value = "default")]
    pub scene: String,
    /// Image size WxH (default: the scene's, about 1524x1012).
    #[arg(long)]
    pub resolution: Option<String>,
    /// Simulated device time per host time during the capture.
    #[arg(long, default_value_t = 50.0)]
    pub time_scale: f64,
    /// Print the pipeline's report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut cfg = DemoConfig::new(args.out.clone());
    cfg.scene = args.scene.clone();
    if !(args.time_scale.is_finite() && args.time_scale > 0.0) {
        anyhow::bail!("--time-scale must be positive");
    }
    cfg.time_scale = args.time_scale;
    cfg.resolution = args
        .resolution
        .as_deref()
        .map(super::parse_size)
        .transpose()?;
    let out = run_demo(&cfg, &mut |e| match e {
        DemoEvent::Step(s) => eprintln!("== {s}"),
        DemoEvent::Captured(c, secs) => {
            for m in capture_metrics(c, secs) {
                eprintln!("    {:<40} {:.4} {}", m.name, m.value, m.unit);
            }
        }
        DemoEvent::Synthesized(s) => eprintln!(
            "    {} images at {}x{} in {:.2} s",
            s.images, s.resolution.0, s.resolution.1, s.total_s
        ),
        DemoEvent::Process(e) => super::process::print_event(e),
    })
    .context("skinbrdf demo")?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&out.process.report)?);
    } else {
        println!("\n{}", out.process.report.to_text());
        println!("demo finished in {:.1} s", out.total_s);
        println!("report: {}", out.report_path.display());
    }
    Ok(())
}
