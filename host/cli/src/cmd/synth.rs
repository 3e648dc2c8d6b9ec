//! `skinbrdf synth`: write a synthetic measurement session with ground truth.
//!
//! `skinbrdf synth --scene default --out DIR` renders the built-in default scene (~36 images at
//! 1524 x 1012); `--scene` also takes a path to a scene TOML (merged over the default scene).
//! With `--capture capture.json` it renders one image per recorded exposure (roles and times
//! from the record) and copies the record into the session. With `--studio` it also writes
//! `DIR/studio/` (see `skinbrdf_synth::studio`): the input of `skinbrdf ingest`.

use std::path::PathBuf;

use anyhow::Context;
use skinbrdf_synth::{generate, Scene, SynthOptions, BUILTIN_SCENES};

/// Flags of `skinbrdf synth`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Built-in scene name or path to a scene TOML file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Output session directory.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Image size WxH (e.g. 6000x4000 for 24 MP); the field of view is kept.
    #[arg(long)]
    resolution: Option<String>,
    /// Render one image per exposure of this capture record.
    #[arg(long)]
    capture: Option<PathBuf>,
    /// No sensor noise and no scanner noise (quantisation remains).
    #[arg(long)]
    noise_free: bool,
    /// Rays per pixel (anti-aliasing); default from the scene.
    #[arg(long)]
    samples_per_pixel: Option<u32>,
    /// Also write SESSION/studio/: the camera's raw files (DNG) on a card, the controller's
    /// record, the rig with and without placements, and the scan, as a studio holds them
    /// after a capture (the input of `skinbrdf ingest`).
    #[arg(long)]
    studio: bool,
    /// With --studio: write only the studio's files and the truth, not the generator's own
    /// session (its linear images and session.toml), which the studio's path never reads.
    #[arg(long, requires = "studio")]
    studio_only: bool,
    /// List the built-in scenes and exit.
    #[arg(long)]
    list: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

pub(crate) fn parse_resolution(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("--resolution `{s}`: expected WxH, e.g. 1524x1012"))?;
    Ok((
        w.trim()
            .parse()
            .with_context(|| format!("--resolution `{s}`: bad width"))?,
        h.trim()
            .parse()
            .with_context(|| format!("--resolution `{s}`: bad height"))?,
    ))
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.list {
        for (name, _) in BUILTIN_SCENES {
            let s = Scene::load(name)?;
            println!("{name:18} {}", s.description);
        }
        return Ok(());
    }
    let out = args.out.context("--out DIR is required")?;
    let scene = Scene::load(&args.scene)?;
    let capture = match &args.capture {
        Some(p) => {
            let bytes = std::fs::read(p).with_context(|| format!("reading {}", p.display()))?;
            Some(
                serde_json::from_slice(&bytes)
                    .with_context(|| format!("{}: not a capture record", p.display()))?,
            )
        }
        None => None,
    };
    let opts = SynthOptions {
        resolution: args
            .resolution
            .as_deref()
            .map(parse_resolution)
            .transpose()?,
        capture,
        noise_free: args.noise_free,
        samples_per_pixel: args.samples_per_pixel,
        studio: args.studio,
        studio_only: args.studio_only,
    };
    let s = generate(&scene, &opts, &out)
        .with_context(|| format!("generating scene `{}`", scene.name))?;
    if args.json {
        let v = serde_json::json!({
            "scene": scene.name,
            "dir": s.dir,
            "images": s.images,
            "width_px": s.resolution.0,
            "height_px": s.resolution.1,
            "rays": s.rays,
            "render_triangles": s.render_triangles,
            "scan_vertices": s.scan_vertices,
            "setup_s": s.setup_s,
            "render_s": s.render_s,
            "write_s": s.write_s,
            "total_s": s.total_s,
        });
        println!("{v}");
    } else {
        println!(
            "scene `{}`: {} images {}x{} -> {}\n  rays {:.1} M ({:.1} Mrays/s), render mesh {} triangles, scan {} vertices\n  time: setup {:.2} s, render {:.2} s, noise+encode+write {:.2} s, total {:.2} s",
            scene.name,
            s.images,
            s.resolution.0,
            s.resolution.1,
            s.dir.display(),
            s.rays as f64 * 1e-6,
            s.rays as f64 * 1e-6 / s.render_s.max(1e-9),
            s.render_triangles,
            s.scan_vertices,
            s.setup_s,
            s.render_s,
            s.write_s,
            s.total_s
        );
    }
    Ok(())
}
