//! `skinbrdf derender`: a session's images to calibrated BRDF samples.

use std::path::PathBuf;

use anyhow::Context;
use skinbrdf_derender::{CEstimator, DerenderConfig, ShadowMode};
use skinbrdf_mesh::NormalMethod;
use skinbrdf_pipeline::derender_request::{self, PoseRequest};
use skinbrdf_pipeline::pose_inputs::PoseChoice;
use skinbrdf_pipeline::stages::{DerenderOutputOptions, PoseSourceChoice};
use skinbrdf_pipeline::{stages, PlanOptions};

/// Flags of `skinbrdf derender`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session directory.
    pub session: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Use every N-th pixel in x and y.
    #[arg(long, default_value_t = 1)]
    pub stride: u32,
    /// Drop samples with theta_i or theta_e beyond this (degrees, < 90).
    #[arg(long, default_value_t = DerenderConfig::DEFAULT.grazing_limit_deg)]
    pub grazing_limit_deg: f64,
    /// Drop samples with a linear channel value below this (1.0 = white).
    #[arg(long, default_value_t = DerenderConfig::DEFAULT.noise_floor)]
    pub noise_floor: f64,
    /// Shadow rays: plan (as `process` plans them), auto (only if the geometry can shadow the
    /// region), always, never.
    #[arg(long, value_enum, default_value_t = Shadows::Plan)]
    pub shadows: Shadows,
    /// Normals: auto (planar fit, radius from the scan's noise), fit (needs --normal-radius-mm),
    /// vertex.
    #[arg(long, value_enum, default_value_t = Normals::Auto)]
    pub normals: Normals,
    /// Planar-fit radius in millimetres (implies --normals fit).
    #[arg(long)]
    pub normal_radius_mm: Option<f64>,
    /// Average of C over the standard.
    #[arg(long, value_enum, default_value_t = CAverage::Median)]
    pub c_estimator: CAverage,
    /// BVH build preset.
    #[arg(long, value_enum, default_value_t = super::BvhQuality::Medium)]
    pub bvh_quality: super::BvhQuality,
    /// Poses: auto (those session.toml gives, else the pose stage's SESSION/out/poses.json, as
    /// `process` does), session, estimated (the pose stage's output, --poses-file or
    /// SESSION/out/poses.json), truth (truth.json: a check of the derendering alone, marked as
    /// such in the output).
    #[arg(long, value_enum, default_value_t = Poses::Auto)]
    pub poses: Poses,
    /// The pose stage's output (implies --poses estimated).
    #[arg(long)]
    pub poses_file: Option<PathBuf>,
    /// Do not mask the projected printed targets.
    #[arg(long)]
    pub no_target_mask: bool,
    /// How camera raw images load: `photosite` (default) or `superpixel`; must be the mode the
    /// poses were estimated in (their camera is the images' as loaded).
    #[arg(long, value_enum, default_value_t = super::RawModeArg::Photosite)]
    pub raw_mode: super::RawModeArg,
    /// Output directory (default SESSION/out): samples.skbs, derender.json.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write samples.csv.
    #[arg(long)]
    pub csv: bool,
    /// Write coverage figures into OUT/figures: pixels used per image (PNG) and the exitant
    /// hemisphere at --figure-theta-i-deg (PNG and SVG).
    #[arg(long)]
    pub figures: bool,
    /// Incident angle of the hemisphere figure, degrees.
    #[arg(long, default_value_t = 30.0)]
    pub figure_theta_i_deg: f64,
    /// Tolerance on the incident angle of the hemisphere figure, degrees.
    #[arg(long, default_value_t = 2.0)]
    pub figure_tol_deg: f64,
}

/// `--shadows`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Shadows {
    /// As `process` plans them (skipped for a region known to be convex).
    Plan,
    /// Only if the geometry can shadow the region.
    Auto,
    /// Always.
    Always,
    /// Never.
    Never,
}

/// `--normals`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Normals {
    /// Planar fit, radius from the scan's noise.
    Auto,
    /// Planar fit of --normal-radius-mm.
    Fit,
    /// The scan's vertex normals.
    Vertex,
}

/// `--c-estimator`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CAverage {
    /// Median.
    Median,
    /// Trimmed mean.
    Trimmed,
}

/// `--poses`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Poses {
    /// The session's, else the pose stage's.
    Auto,
    /// Only the session's.
    Session,
    /// The pose stage's output.
    Estimated,
    /// The ground truth (synthetic sessions).
    Truth,
}

fn config(args: &Args) -> anyhow::Result<DerenderConfig> {
    let shadows = match args.shadows {
        Shadows::Plan | Shadows::Auto => ShadowMode::Auto,
        Shadows::Always => ShadowMode::Always,
        Shadows::Never => ShadowMode::Never,
    };
    let normals = match (args.normals, args.normal_radius_mm) {
        (_, Some(r)) => NormalMethod::PlanarFit { radius_m: r * 1e-3 },
        (Normals::Auto, None) => NormalMethod::PlanarFitAuto,
        (Normals::Vertex, None) => NormalMethod::Vertex,
        (Normals::Fit, None) => anyhow::bail!("--normals fit needs --normal-radius-mm"),
    };
    let c_estimator = match args.c_estimator {
        CAverage::Median => CEstimator::Median,
        CAverage::Trimmed => CEstimator::TrimmedMean,
    };
    let cfg = DerenderConfig {
        stride: args.stride,
        grazing_limit_deg: args.grazing_limit_deg,
        noise_floor: args.noise_floor,
        shadows,
        normals,
        c_estimator,
        bvh_quality: args.bvh_quality.into(),
    };
    cfg.validate()?;
    Ok(cfg)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut cfg = config(&args)?;
    let mut session = skinbrdf_session::Session::load(&args.session)
        .with_context(|| format!("loading session {}", args.session.display()))?;
    session.set_raw_mode(args.raw_mode.into());
    let plan_opts = PlanOptions::default();
    if args.shadows == Shadows::Plan {
        cfg = derender_request::planned_config(&session, &cfg, &plan_opts);
    }
    let request = PoseRequest {
        choice: match args.poses {
            Poses::Auto => PoseChoice::Auto,
            Poses::Session => PoseChoice::Session,
            Poses::Estimated => PoseChoice::Estimated,
            Poses::Truth => PoseChoice::Truth,
        },
        poses_file: args.poses_file.clone(),
        skip_target_mask: args.no_target_mask,
    };
    let source = derender_request::derender_pose_source(&session, &request)?;
    let out = args.out.clone().unwrap_or_else(|| args.session.join("out"));
    let opts = DerenderOutputOptions {
        skip_target_mask: args.no_target_mask,
        csv: args.csv,
        figures: args
            .figures
            .then_some((args.figure_theta_i_deg, args.figure_tol_deg)),
    };
    let written = stages::derender_chosen(&session, &source, &cfg, &plan_opts, &out, &opts)?;
    if source == PoseSourceChoice::Truth {
        eprintln!("note: derendered with the TRUE poses of truth.json (a check of derendering alone, not a measurement)");
    }
    if args.json {
        print!("{}", std::fs::read_to_string(&written.report_file)?);
    } else {
        crate::print::derender::text(&args.session, &written.run, &cfg, &written.samples_file);
    }
    Ok(())
}
