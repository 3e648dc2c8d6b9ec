//! `skinbrdf targets --layout headdress|reference|flash|board --out FILE.svg|pdf`: a printable
//! sheet at true scale with IDs, plus the matching layout file `FILE.layout.toml` (the targets in
//! the session format, in the sheet's frame: origin at the sheet centre / flash disc centre, x
//! right, y up on the page, z out of the paper, metres).
//!
//! `skinbrdf targets --detect IMAGE...` instead prints the tags found in images (JSON lines).

use anyhow::Context;
use glam::DVec3;
use serde::Serialize;
use skinbrdf_session::{write_atomic, Target};
use skinbrdf_targets::sheet::{Sheet, SheetKind};
use skinbrdf_targets::{detect::detect_with_stats, DetectorConfig, GrayF32};
use std::path::PathBuf;

/// Flags of `skinbrdf targets`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Which sheet to print.
    #[arg(long, value_enum)]
    pub layout: Option<Layout>,
    /// Output file: `.svg` or `.pdf`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Detect tags in these images instead (prints one JSON line per image).
    #[arg(long, num_args = 1..)]
    pub detect: Vec<PathBuf>,
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

#[derive(Serialize)]
struct LayoutFile {
    /// Which table of session.toml the targets belong in.
    section: String,
    targets: Vec<Target>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.detect.is_empty() {
        for f in &args.detect {
            let img = GrayF32::load(f)?;
            let t = std::time::Instant::now();
            let (dets, stats) = detect_with_stats(&img, &DetectorConfig::default());
            let line = serde_json::json!({
                "file": f,
                "ms": t.elapsed().as_secs_f64() * 1e3,
                "stats": stats,
                "detections": dets.iter().map(|d| serde_json::json!({
                    "id": d.id,
                    "corners_px": d.corners_px.iter().map(|c| [c.x, c.y]).collect::<Vec<_>>(),
                    "corner_sigma_px": d.corner_sigma_px(),
                    "hamming": d.hamming,
                    "decision_margin": d.decision_margin,
                })).collect::<Vec<_>>(),
            });
            println!("{line}");
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
    write_atomic(&out, &bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
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
    let layout_path = out.with_extension("layout.toml");
    let text = toml::to_string(&LayoutFile {
        section: section.into(),
        targets,
    })
    .context("serialising the layout")?;
    let header = format!(
        "# Target layout of {} (sheet frame: origin at the sheet centre{}, x right, y up on the\n# page, z out of the paper, metres). Copy `targets` into session.toml under [{section}]\n# after mounting; measure and correct positions if the sheet is not flat.\n",
        out.display(),
        if matches!(kind, SheetKind::Flash) { " = flash disc centre" } else { "" }
    );
    write_atomic(&layout_path, format!("{header}{text}").as_bytes())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    println!(
        "wrote {} ({} tags, IDs {}..={}) and {}",
        out.display(),
        sheet.tags.len(),
        sheet.tags.first().map(|t| t.id).unwrap_or(0),
        sheet.tags.last().map(|t| t.id).unwrap_or(0),
        layout_path.display()
    );
    Ok(())
}
