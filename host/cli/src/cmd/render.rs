//! `skinbrdf render`: ray-trace a head mesh lit by a point light, with a Lambertian BRDF of the
//! measured albedo and with the measured (fitted) BRDF, side by side (the method's Figures 7
//! and 10); writes `head_comparison.png` and `.svg`.

use std::path::PathBuf;

use anyhow::Context;
use skinbrdf_mesh::{load_mesh, LoadOptions};
use skinbrdf_render::{load_model, render_comparison, NormalSource, RenderConfig};

/// Flags of `skinbrdf render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A processed session directory (uses scan.ply and out/fit/params.json) or a mesh file
    /// (.ply / .obj, then --model is required).
    pub input: PathBuf,
    /// The measured BRDF: a `skinbrdf fit` params.json, a truth.json or a bare model JSON.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Output directory (default: SESSION/out/render, or next to the mesh).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Size of one panel, WxH pixels.
    #[arg(long, default_value = "480x560")]
    pub size: String,
    /// Samples per pixel along each axis.
    #[arg(long, default_value_t = 2)]
    pub supersample: u32,
    /// Light rotation from the camera direction about the up axis, degrees (+ = image right).
    #[arg(long, default_value_t = 35.0, allow_negative_numbers = true)]
    pub light_azimuth_deg: f64,
    /// Light elevation, degrees.
    #[arg(long, default_value_t = 25.0, allow_negative_numbers = true)]
    pub light_elevation_deg: f64,
    /// Direction from the mesh centre to the camera, mesh frame, as x,y,z.
    #[arg(long, default_value = "0,1,0", allow_hyphen_values = true)]
    pub view: String,
    /// Image up direction, mesh frame, as x,y,z.
    #[arg(long, default_value = "0,0,1", allow_hyphen_values = true)]
    pub up: String,
    /// Linear exposure (default: automatic, shared by both panels).
    #[arg(long)]
    pub exposure: Option<f64>,
    /// Shading normals: auto (the file's, else vertex), vertex, planar (fit over the scan's
    /// noise radius).
    #[arg(long, value_enum, default_value_t = Normals::Auto)]
    pub normals: Normals,
    /// Print the statistics as JSON.
    #[arg(long)]
    pub json: bool,
}

fn parse_vec(s: &str, flag: &str) -> anyhow::Result<[f64; 3]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{flag}: `{s}` is not x,y,z"))?;
    <[f64; 3]>::try_from(v).map_err(|_| anyhow::anyhow!("{flag}: `{s}` needs three numbers"))
}

/// `--normals`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Normals {
    /// The file's, else vertex normals.
    Auto,
    /// Vertex normals.
    Vertex,
    /// A planar fit over the scan.
    Planar,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let (mesh_path, model_path, default_out) = if args.input.is_dir() {
        let d = &args.input;
        (
            d.join("scan.ply"),
            args.model
                .clone()
                .unwrap_or_else(|| d.join("out").join("fit").join("params.json")),
            d.join("out").join("render"),
        )
    } else {
        let model = args
            .model
            .clone()
            .context("--model is required when the input is a mesh file")?;
        let dir = args
            .input
            .parent()
            .map(|p| p.to_path_buf())
            .unwrap_or_default();
        (args.input.clone(), model, dir)
    };
    let (w, h) = super::parse_size(&args.size).context("--size")?;
    let normals = match args.normals {
        Normals::Auto => NormalSource::Auto,
        Normals::Vertex => NormalSource::Vertex,
        Normals::Planar => NormalSource::PlanarFit,
    };
    let cfg = RenderConfig {
        width_px: w,
        height_px: h,
        supersample: args.supersample,
        view_dir: parse_vec(&args.view, "--view")?,
        up: parse_vec(&args.up, "--up")?,
        light_azimuth_deg: args.light_azimuth_deg,
        light_elevation_deg: args.light_elevation_deg,
        exposure: args.exposure,
        normals,
        ..RenderConfig::default()
    };
    cfg.validate()?;
    let model = load_model(&model_path)?;
    let mesh = load_mesh(&mesh_path, &LoadOptions::default())
        .with_context(|| format!("loading {}", mesh_path.display()))?;
    let out_dir = args.out.clone().unwrap_or(default_out);
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let img = render_comparison(&mesh.mesh, &model, &cfg)?;
    let files = img.write(&out_dir.join("head_comparison"), &cfg.labels)?;
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "files": files,
                "stats": img.stats,
                "exposure": img.exposure,
                "lambertian_albedo": img.lambertian_albedo,
            })
        );
        return Ok(());
    }
    let s = &img.stats;
    println!(
        "rendered {} triangles, {} rays ({:.0}% of primary rays hit, {:.0}% of hits shadowed): BVH {:.3} s, trace+shade {:.3} s, compose {:.3} s",
        s.triangles,
        s.rays,
        100.0 * s.hit_fraction,
        100.0 * s.shadowed_fraction,
        s.bvh_build_s,
        s.trace_s,
        s.compose_s
    );
    println!(
        "Lambertian albedo (the model's directional albedo at normal incidence): {:.3} {:.3} {:.3}; exposure {:.4}",
        img.lambertian_albedo[0], img.lambertian_albedo[1], img.lambertian_albedo[2], img.exposure
    );
    for f in files {
        println!("wrote {}", f.display());
    }
    Ok(())
}
