//! `skinbrdf targets --layout headdress|reference|flash|board --out FILE.svg|pdf`: a printable
//! sheet at true scale with IDs, plus the matching layout file `FILE.layout.toml` (the targets in
//! the session format, in the sheet's frame: origin at the sheet centre / flash disc centre, x
//! right, y up on the page, z out of the paper, metres).
//!
//! `skinbrdf targets --scene NAME --layout reference|headdress|flash --out FILE.svg|pdf` prints
//! the targets a scene's rig uses (a built-in scene or a scene TOML: the reference cage, the
//! headdress tags, the flash ring) as cut-outs at their true sizes with their IDs, on as many A4
//! pages as needed (`FILE.pdf` has them all; SVG gets one file per page, `FILE-2.svg`, ...), and
//! the layout file with each target where the scene places it (reference: world frame,
//! headdress: head frame, flash: flash frame), as the scene's `session.toml` lists them: build
//! the rig to that file and a real session uses the same layout as the synthetic one.
//!
//! `skinbrdf targets --detect IMAGE... [--corners edge|reference]` instead prints the tags found
//! in images (JSON lines), corners in the project's convention (integer = pixel centre; the
//! AprilTag C library's coordinates are these + 0.5). `--corners reference` reports the C
//! library's own unrefined quad corners (its `refine_edges = 0` output, reproduced to a few
//! hundredths of a pixel) instead of our edge-refined ones, to compare with that library.

use anyhow::Context;
use glam::DVec3;
use skinbrdf_session::{write_atomic, LayoutFile, Target};
use skinbrdf_targets::sheet::{Sheet, SheetKind};
use skinbrdf_targets::{detect::detect_with_stats, CornerModel, DetectorConfig, GrayF32};
use std::path::PathBuf;

use crate::print::targets as print;

/// Flags of `skinbrdf targets`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Which sheet to print.
    #[arg(long, value_enum)]
    pub layout: Option<Layout>,
    /// Output file: `.svg` or `.pdf`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print the targets of this scene's rig (built-in name or scene TOML) as cut-outs, with the
    /// scene's layout, instead of the standard sheet.
    #[arg(long)]
    pub scene: Option<String>,
    /// Detect tags in these images instead (prints one JSON line per image).
    #[arg(long, num_args = 1..)]
    pub detect: Vec<PathBuf>,
    /// Which corners `--detect` reports.
    #[arg(long, value_enum, default_value_t = Corners::Edge, requires = "detect")]
    pub corners: Corners,
    /// With `--corners edge`: refine small tags (cells up to 4 px) by fitting their edge
    /// profiles (skinbrdf_targets::profile; off by default, see there).
    #[arg(long, requires = "detect")]
    pub profile_small_tags: bool,
}

/// Corner estimators of `--detect`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Corners {
    /// Edge refinement on the grey image (the accurate one).
    Edge,
    /// The AprilTag C library's unrefined quad, to compare with that library's output.
    Reference,
}

/// Sheet kinds.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Layout {
    /// Headdress band tags.
    Headdress,
    /// Reference field.
    Reference,
    /// Ring around the flash disc.
    Flash,
    /// Calibration board.
    Board,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.detect.is_empty() {
        let cfg = DetectorConfig {
            corner_model: match args.corners {
                Corners::Edge => CornerModel::EdgeGradient,
                Corners::Reference => CornerModel::BinaryBoundary,
            },
            profile_small_tags: args.profile_small_tags,
            ..DetectorConfig::default()
        };
        for f in &args.detect {
            let img = GrayF32::load(f)?;
            let t = std::time::Instant::now();
            let (dets, stats) = detect_with_stats(&img, &cfg);
            let ms = t.elapsed().as_secs_f64() * 1e3;
            println!("{}", print::detection_line(f, ms, &stats, &dets));
        }
        return Ok(());
    }
    let layout = args
        .layout
        .context("give --layout headdress|reference|flash|board (or --detect IMAGE...)")?;
    let out = args.out.context("give --out FILE.svg or FILE.pdf")?;
    let kind = match layout {
        Layout::Headdress => SheetKind::Headdress,
        Layout::Reference => SheetKind::Reference,
        Layout::Flash => SheetKind::Flash,
        Layout::Board => SheetKind::Board,
    };
    if let Some(scene) = &args.scene {
        return scene_cutouts(scene, kind, &out);
    }
    let sheet = Sheet::standard(kind);
    let ext = out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let bytes = match ext.as_deref() {
        Some("svg") => sheet.to_svg().into_bytes(),
        Some("pdf") => sheet.to_pdf(),
        _ => anyhow::bail!("{}: the output must end in .svg or .pdf", out.display()),
    };
    write_atomic(&out, &bytes)?;
    let targets: Vec<Target> = sheet
        .tags
        .iter()
        .map(|t| {
            Target::square(
                t.id,
                t.size_mm * 1e-3,
                DVec3::new(t.centre_mm[0] * 1e-3, t.centre_mm[1] * 1e-3, 0.0),
                DVec3::Z,
                DVec3::Y,
            )
            .context("sheet tag geometry")
        })
        .collect::<anyhow::Result<_>>()?;
    let section = match kind {
        SheetKind::Headdress => "targets.headdress",
        SheetKind::Reference | SheetKind::Board => "targets.reference",
        SheetKind::Flash => "flash.targets",
    };
    let header = print::sheet_layout_header(&out, kind, section);
    let layout_path = write_layout(&out, section, targets, &header)?;
    print::sheet_written(&out, &sheet, &layout_path);
    Ok(())
}

/// Writes `OUT.layout.toml`: `header` (comment lines) and the targets under `section`.
fn write_layout(
    out: &std::path::Path,
    section: &str,
    targets: Vec<Target>,
    header: &str,
) -> anyhow::Result<PathBuf> {
    let layout_path = out.with_extension("layout.toml");
    let text = toml::to_string(&LayoutFile {
        section: section.into(),
        targets,
    })
    .context("serialising the layout")?;
    write_atomic(&layout_path, format!("{header}{text}").as_bytes())?;
    Ok(layout_path)
}

/// `--scene`: the scene rig's targets of one kind as cut-outs, and their layout.
fn scene_cutouts(scene_name: &str, kind: SheetKind, out: &std::path::Path) -> anyhow::Result<()> {
    let scene = skinbrdf_synth::Scene::load(scene_name)
        .with_context(|| format!("loading scene `{scene_name}`"))?;
    let rig = skinbrdf_synth::layout::build_rig(&scene);
    let (targets, section, frame) = match kind {
        SheetKind::Reference => (&rig.reference, "targets.reference", "world frame"),
        SheetKind::Headdress => (&rig.headdress, "targets.headdress", "head (scan) frame"),
        SheetKind::Flash => (&rig.flash_targets, "flash.targets", "flash frame"),
        SheetKind::Board => anyhow::bail!(
            "--scene: scenes have no calibration board (their intrinsics are given); use --layout reference, headdress or flash"
        ),
    };
    anyhow::ensure!(
        !targets.is_empty(),
        "scene `{}` has no {} targets",
        scene.name,
        kind.name()
    );
    let tags: Vec<(u32, f64)> = targets.iter().map(|t| (t.id, t.size_m * 1e3)).collect();
    let pages =
        Sheet::cutouts(kind, &tags).map_err(|e| anyhow::anyhow!("scene `{}`: {e}", scene.name))?;
    let ext = out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let mut written = Vec::new();
    match ext.as_deref() {
        Some("pdf") => {
            write_atomic(out, &skinbrdf_targets::sheet::pdf_document(&pages))?;
            written.push(out.to_path_buf());
        }
        Some("svg") => {
            for (i, p) in pages.iter().enumerate() {
                let path = if i == 0 {
                    out.to_path_buf()
                } else {
                    let stem = out
                        .file_stem()
                        .and_then(|s| s.to_str())
                        .unwrap_or("targets");
                    out.with_file_name(format!("{stem}-{}.svg", i + 1))
                };
                write_atomic(&path, p.to_svg().as_bytes())?;
                written.push(path);
            }
        }
        _ => anyhow::bail!("{}: the output must end in .svg or .pdf", out.display()),
    }
    let header = print::scene_layout_header(&scene.name, frame, out, section);
    let layout_path = write_layout(out, section, targets.clone(), &header)?;
    print::cutouts_written(&written, tags.len(), &scene.name, pages.len(), &layout_path);
    Ok(())
}

#[cfg(test)]
mod tests;
