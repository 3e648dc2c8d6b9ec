//! `skinbrdf targets`: the JSON line per image of `--detect`, the layout files' headers and the
//! lines saying what was written.

use std::path::{Path, PathBuf};

use serde_json::{json, Value};
use skinbrdf_targets::sheet::{Sheet, SheetKind};
use skinbrdf_targets::{DetectStats, Detection};

/// One image's detections (`--detect`): file, time, the detector's statistics and every tag
/// with its corners, their sigmas and its decoding margins.
pub fn detection_line(file: &Path, ms: f64, stats: &DetectStats, dets: &[Detection]) -> Value {
    json!({
        "file": file,
        "ms": ms,
        "stats": stats,
        "detections": dets.iter().map(|d| json!({
            "id": d.id,
            "corners_px": d.corners_px.iter().map(|c| [c.x, c.y]).collect::<Vec<_>>(),
            "corner_sigma_px": d.corner_sigma_px(),
            "hamming": d.hamming,
            "decision_margin": d.decision_margin,
            "occluded_corners": d.occluded_corners,
        })).collect::<Vec<_>>(),
    })
}

/// The comment lines heading a standard sheet's layout file.
pub fn sheet_layout_header(out: &Path, kind: SheetKind, section: &str) -> String {
    format!(
        "# Target layout of {} (sheet frame: origin at the sheet centre{}, x right, y up on the\n# page, z out of the paper, metres). Copy `targets` into session.toml under [{section}]\n# after mounting; measure and correct positions if the sheet is not flat.\n",
        out.display(),
        if matches!(kind, SheetKind::Flash) { " = flash disc centre" } else { "" }
    )
}

/// The comment lines heading a scene's cut-outs' layout file.
pub fn scene_layout_header(scene: &str, frame: &str, out: &Path, section: &str) -> String {
    format!(
        "# Target layout of scene `{}` ({frame}, metres): where each cut-out of {} goes.\n# Copy `targets` into session.toml under [{section}]; measure and correct positions after\n# mounting.\n",
        scene,
        out.display(),
    )
}

/// A standard sheet and its layout file written.
pub fn sheet_written(out: &Path, sheet: &Sheet, layout_path: &Path) {
    println!(
        "wrote {} ({} tags, IDs {}..={}) and {}",
        out.display(),
        sheet.tags.len(),
        sheet.tags.first().map(|t| t.id).unwrap_or(0),
        sheet.tags.last().map(|t| t.id).unwrap_or(0),
        layout_path.display()
    );
}

/// A scene's cut-out pages and their layout file written.
pub fn cutouts_written(
    written: &[PathBuf],
    tags: usize,
    scene: &str,
    pages: usize,
    layout_path: &Path,
) {
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    println!(
        "wrote {} ({} tags of scene `{}` on {} page(s)) and {}",
        names.join(", "),
        tags,
        scene,
        pages,
        layout_path.display()
    );
}
