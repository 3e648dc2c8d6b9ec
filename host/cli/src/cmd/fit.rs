//! `skinbrdf fit`: fit a BRDF model to samples, smooth them, and write the parameters (JSON),
//! a Markdown report, the figures and the exported model.

use std::path::PathBuf;

use anyhow::Context;
use skinbrdf_brdf::ModelSpec;
use skinbrdf_fit::report::{fit_and_report, load_input, ReportOptions};
use skinbrdf_fit::{FitConfig, ResidualKind};

/// Flags of `skinbrdf fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A sample file (.skbs), a Cornell .brdf file, or a session directory (uses out/samples.skbs
    /// and, if present, truth.json).
    pub input: PathBuf,
    /// Model: lambertian, lafortune1, lafortune2, lafortune3, cook-torrance.
    #[arg(long, default_value = "lafortune2")]
    pub model: String,
    /// Output directory (default: INPUT-fit next to the input, or SESSION/out/fit).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Residual: log (relative error, default) or cosine (cos(theta_i)-weighted absolute error).
    #[arg(long, value_enum, default_value_t = Residual::Log)]
    pub residual: Residual,
    /// Log-residual floor as a fraction of the median grey level.
    #[arg(long, default_value_t = skinbrdf_fit::fit::LOG_FLOOR_REL_MEDIAN)]
    pub log_floor: f64,
    /// Fail when the samples do not determine some parameters (default: warn).
    #[arg(long)]
    pub strict: bool,
    /// Also write the MERL binary table (model.binary, 35 MB).
    #[arg(long)]
    pub merl: bool,
    /// Skip the figures.
    #[arg(long)]
    pub no_figures: bool,
    /// Skip the head rendering (a session directory with scan.ply gets
    /// head_comparison.{png,svg}: Lambertian vs the fitted BRDF, the method's Figs. 7 and 10).
    #[arg(long)]
    pub no_render: bool,
}

/// `--residual`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Residual {
    /// Log residuals.
    Log,
    /// Cosine-weighted residuals.
    Cosine,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let model: ModelSpec = args.model.parse().context("--model")?;
    let residual = match args.residual {
        Residual::Log => None,
        Residual::Cosine => Some(ResidualKind::CosineWeighted),
    };
    if !(args.log_floor > 0.0 && args.log_floor.is_finite()) {
        anyhow::bail!("--log-floor must be positive, got {}", args.log_floor);
    }
    let input = load_input(&args.input)?;
    let out = args.out.clone().unwrap_or_else(|| {
        if args.input.is_dir() {
            args.input.join("out").join("fit")
        } else {
            let mut s = args.input.clone().into_os_string();
            s.push("-fit");
            PathBuf::from(s)
        }
    });
    let opts = ReportOptions {
        model,
        fit: FitConfig {
            residual,
            strict: args.strict,
            log_floor_rel_median: args.log_floor,
            ..FitConfig::default()
        },
        merl: args.merl,
        figures: !args.no_figures,
    };
    let report = fit_and_report(&input, &out, &opts)?;
    if args.json {
        super::print_json(&report)?;
        return Ok(());
    }
    let f = &report.fit;
    println!(
        "{}: {} samples, model {}, fit {:.3} s",
        report.input, report.n_samples, f.model_name, f.fit_time_s
    );
    for (c, ch) in f.channels.iter().enumerate() {
        println!(
            "  {}: log-RMSE {:.4}, median rel. error {:.4}, {} iterations ({}), condition {}",
            ["R", "G", "B"][c],
            ch.error.log_rmse,
            ch.error.median_rel_err,
            ch.iterations,
            match ch.status {
                skinbrdf_fit::lm::LmStatus::CostConverged => "cost converged",
                skinbrdf_fit::lm::LmStatus::GradientConverged => "gradient converged",
                skinbrdf_fit::lm::LmStatus::StepConverged => "step converged",
                skinbrdf_fit::lm::LmStatus::MaxIterations => "iteration limit reached",
            },
            skinbrdf_fit::fit::condition_text(ch.condition_number)
        );
    }
    if let Some(t) = &report.truth {
        for (c, m) in t.channels.iter().enumerate() {
            println!(
                "  vs truth {}: log-RMSE {:.4}, median rel. error {:.4}",
                ["R", "G", "B"][c],
                m.log_rmse,
                m.median_rel_err
            );
        }
    }
    for w in &f.warnings {
        eprintln!("warning: {w}");
    }
    for (k, v) in report.timings.rows() {
        println!("  {k}: {v:.3} s");
    }
    println!("wrote {} (params.json, report.md, figures)", out.display());
    let scan = args.input.join("scan.ply");
    if args.input.is_dir() && scan.is_file() && !args.no_figures && !args.no_render {
        let mesh = skinbrdf_mesh::load_mesh(&scan, &skinbrdf_mesh::LoadOptions::default())
            .with_context(|| format!("loading {}", scan.display()))?;
        let cfg = skinbrdf_render::RenderConfig::default();
        let img = skinbrdf_render::render_comparison(&mesh.mesh, &f.model, &cfg)?;
        let files = img.write(&out.join("head_comparison"), &cfg.labels)?;
        println!(
            "  render: {:.3} s ({} rays); wrote {}",
            img.stats.trace_s + img.stats.compose_s,
            img.stats.rays,
            files
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}
