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
    /// Image size WxH (default: the scene's, about 1524x1012): the sensor's photosites, so
    /// multiples of 4 (whole 2x2 quads, whole bytes per 14-bit row).
    #[arg(long)]
    pub resolution: Option<String>,
    /// Simulated device time per host time during the capture.
    #[arg(long, default_value_t = 50.0)]
    pub time_scale: f64,
    /// Process the generator's session with every target placement given, instead of the
    /// studio's path (raw files, ingest, survey, registration to the textured scan).
    #[arg(long)]
    pub given_layout: bool,
    /// Print a JSON summary on stdout (capture, synthesis, every stage's figures, total time).
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut cfg = DemoConfig::new(args.out.clone());
    cfg.scene = args.scene.clone();
    cfg.given_layout = args.given_layout;
    if !(args.time_scale.is_finite() && args.time_scale > 0.0) {
        anyhow::bail!("--time-scale must be positive");
    }
    cfg.time_scale = args.time_scale;
    cfg.resolution = args
        .resolution
        .as_deref()
        .map(super::parse_size)
        .transpose()?;
    let mut progress = super::StageProgress::default();
    let out = run_demo(&cfg, &mut |e| match e {
        DemoEvent::Step(s) => {
            progress.finish();
            progress.println(&format!("== {s}"));
            tracing::info!(step = s, "demo step");
            progress.start(s);
        }
        DemoEvent::Captured(c, secs) => {
            progress.finish();
            for m in capture_metrics(c, secs) {
                progress.println(&format!("    {:<40} {:.4} {}", m.name, m.value, m.unit));
            }
        }
        DemoEvent::Synthesized(s) => {
            progress.finish();
            progress.println(&format!(
                "    {} images at {}x{} in {:.2} s",
                s.images, s.resolution.0, s.resolution.1, s.total_s
            ));
        }
        DemoEvent::Ingested(i) => {
            progress.finish();
            progress.println(&format!(
                "    {} raw files matched to the record, {} targets left to the survey, in {:.2} s",
                i.images.len(),
                i.unplaced_targets,
                i.total_s
            ));
        }
        DemoEvent::Process(e) => super::process::print_event(&mut progress, e),
    })
    .context("skinbrdf demo")?;
    if args.json {
        let capture: serde_json::Map<String, serde_json::Value> =
            capture_metrics(&out.capture, out.capture_s)
                .into_iter()
                .map(|m| {
                    (
                        format!("{}_{}", m.name, m.unit)
                            .trim_end_matches('_')
                            .to_string(),
                        m.value.into(),
                    )
                })
                .collect();
        let s = &out.synth;
        let summary = serde_json::json!({
            "total_s": out.total_s,
            "report": out.report_path,
            "capture": capture,
            "synth": {
                "images": s.images,
                "width_px": s.resolution.0,
                "height_px": s.resolution.1,
                "rays": s.rays,
                "render_s": s.render_s,
                "total_s": s.total_s,
            },
            "ingest": out.ingest.as_ref().map(|i| serde_json::json!({
                "images": i.images.len(),
                "placed_targets": i.placed_targets,
                "unplaced_targets": i.unplaced_targets,
                "total_s": i.total_s,
            })),
            "process": out.process.report,
        });
        super::print_json(&summary)?;
    } else {
        println!("\n{}", out.process.report.to_text());
        println!("demo finished in {:.1} s", out.total_s);
        println!(
            "report: {} (with the figures inline: {})",
            out.report_path.display(),
            out.report_path.with_extension("html").display()
        );
    }
    Ok(())
}
