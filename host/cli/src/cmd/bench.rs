//! `skinbrdf bench`: error against run time over the settings that trade one for the other.

use std::path::PathBuf;

use anyhow::Context;
use skinbrdf_pipeline::bench::{run_bench, BenchConfig};

/// Flags of `skinbrdf bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directory (table.md, table.csv, pareto.png/svg, session/).
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Scene to generate.
    #[arg(long, default_value = "default")]
    pub scene: String,
    /// Use an existing synthetic session (with truth.json) instead of generating one.
    #[arg(long)]
    pub session: Option<PathBuf>,
    /// Image size WxH of the generated session.
    #[arg(long)]
    pub resolution: Option<String>,
    /// Fewer settings per sweep.
    #[arg(long)]
    pub quick: bool,
    /// Print the rows, the photogrammetry figures and the files written as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let cfg = BenchConfig {
        out_dir: args.out.clone(),
        scene: args.scene.clone(),
        session: args.session.clone(),
        resolution: args
            .resolution
            .as_deref()
            .map(super::parse_size)
            .transpose()?,
        quick: args.quick,
    };
    let mut progress = super::StageProgress::default();
    let out = run_bench(&cfg, &mut |m| {
        tracing::info!(setting = m, "bench");
        progress.println(&format!("... {m}"));
        progress.start(m);
    })
    .context("skinbrdf bench")?;
    progress.finish();
    if args.json {
        super::print_json(&out)?;
    } else {
        print!("{}", out.table_md);
        for f in &out.files {
            println!("wrote {}", f.display());
        }
    }
    Ok(())
}
