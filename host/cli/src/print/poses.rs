//! `skinbrdf poses`: the per-image table, the calibration, bundle and truth lines, and the
//! `--json` summary.

use std::path::Path;

use serde_json::{json, Value};
use skinbrdf_poses::session::{median, ImagePoses, TruthErrors};
use skinbrdf_poses::SessionPoses;

/// An error the truth cannot give (an image without a pose: NaN in `compare_truth`'s per-image
/// lists, a median of nothing) is `null`, stated here rather than left to serde_json's silent
/// NaN-to-null.
fn finite(v: f64) -> Option<f64> {
    Some(v).filter(|v| v.is_finite())
}

/// The `--json` summary: every image, the flash, the bundle, the calibration and the errors
/// against the truth (when known).
pub fn json(est: &SessionPoses, errs: Option<&TruthErrors>, out: &Path) -> Value {
    let images: Vec<_> = est
        .images
        .iter()
        .enumerate()
        .map(|(i, im)| image_json(i, im, errs))
        .collect();
    json!({
        "poses_file": out,
        "images": images,
        "light_position_m": est.light_position_m,
        "skipped": est.skipped,
        "bundle": est.bundle,
        "total_ms": est.total_ms,
        "calibration": est.calibration.as_ref().map(|c| json!({
            "camera": c.camera, "sigma": c.sigma, "rms_px": c.rms_px})),
        "errors_vs_truth": errs.map(truth_json),
    })
}

fn image_json(i: usize, im: &ImagePoses, errs: Option<&TruthErrors>) -> Value {
    json!({
        "file": im.file,
        "role": im.role,
        "targets_found": im.targets_found,
        "camera_rms_px": im.world_from_camera.as_ref().map(|p| p.rms_px),
        "camera_position_sigma_m": im.world_from_camera.as_ref().map(|p| p.position_sigma_m()),
        "detect_ms": im.detect_ms,
        "pose_ms": im.pose_ms,
        "camera_position_error_m": errs.and_then(|e| finite(e.camera_position_error_m[i])),
        "camera_orientation_error_deg": errs.and_then(|e| finite(e.camera_orientation_error_deg[i])),
        "head_position_error_m": errs.and_then(|e| finite(e.head_position_error_m[i])),
        "diagnostics": im.diagnostics,
        "errors": im.errors,
    })
}

fn truth_json(e: &TruthErrors) -> Value {
    json!({
        "camera_position_error_median_m": finite(median(&e.camera_position_error_m)),
        "camera_orientation_error_median_deg": finite(median(&e.camera_orientation_error_deg)),
        "head_position_error_median_m": finite(median(&e.head_position_error_m)),
        "head_orientation_error_median_deg": finite(median(&e.head_orientation_error_deg)),
        "light_position_error_m": e.light_position_error_m,
        "standard_position_error_m": e.standard_position_error_m,
        "focal_error_px": e.focal_error_px,
        "detection": e.corner_summary(),
        "false_detections": e.false_detections,
    })
}

/// The text report on stdout.
pub fn text(est: &SessionPoses, errs: Option<&TruthErrors>, out: &Path) {
    image_table(est, errs);
    calibration(est);
    if let Some(l) = est.light_position_m {
        println!("flash position: {:.4} {:.4} {:.4} m", l.x, l.y, l.z);
    }
    for s in &est.skipped {
        println!("skipped: {s}");
    }
    bundle(est);
    if let Some(e) = errs {
        truth(e);
    }
    println!(
        "poses written to {} in {:.0} ms",
        out.display(),
        est.total_ms
    );
}

/// One row per image: targets found per layout, reprojection RMS, times, errors against the
/// truth; then the image's warnings and errors.
fn image_table(est: &SessionPoses, errs: Option<&TruthErrors>) {
    println!(
        "{:<28} {:<18} {:>4} {:>4} {:>4} {:>8} {:>8} {:>8} {:>9} {:>9} {:>9}",
        "image",
        "role",
        "ref",
        "head",
        "fl",
        "rms_px",
        "det_ms",
        "pose_ms",
        "cam_mm",
        "cam_deg",
        "head_mm"
    );
    for (i, im) in est.images.iter().enumerate() {
        let n = |k: &str| im.targets_found.get(k).copied().unwrap_or(0);
        let fl = n("flash") + n("standard");
        let rms = im
            .world_from_camera
            .as_ref()
            .map(|p| format!("{:.3}", p.rms_px))
            .unwrap_or_else(|| "-".into());
        let e = |v: Option<f64>, s: f64, p: usize| match v {
            Some(x) if x.is_finite() => format!("{:.*}", p, x * s),
            _ => "-".into(),
        };
        println!(
            "{:<28} {:<18} {:>4} {:>4} {:>4} {:>8} {:>8.1} {:>8.1} {:>9} {:>9} {:>9}",
            im.file,
            im.role.name(),
            n("reference"),
            n("headdress"),
            fl,
            rms,
            im.detect_ms,
            im.pose_ms,
            e(errs.map(|e| e.camera_position_error_m[i]), 1e3, 3),
            e(errs.map(|e| e.camera_orientation_error_deg[i]), 1.0, 4),
            e(errs.map(|e| e.head_position_error_m[i]), 1e3, 3),
        );
        for d in &im.diagnostics {
            println!("    warning: {d}");
        }
        for d in &im.errors {
            println!("    error: {d}");
        }
    }
}

fn calibration(est: &SessionPoses) {
    let Some(c) = &est.calibration else {
        return;
    };
    // A sigma that was not estimated (held fixed) is said so, not printed as a number.
    let pm = |s: Option<f64>, digits: usize| {
        s.map_or_else(
            || "(sd not estimated)".to_string(),
            |s| format!("± {s:.digits$}"),
        )
    };
    println!(
        "calibration: fx {:.2} {} px, k1 {:.4} {}, rms {:.3} px over {} points",
        c.camera.fx_px,
        pm(c.sigma[0], 2),
        c.camera.distortion.k1,
        pm(c.sigma[4], 4),
        c.rms_px,
        c.points
    );
}

fn bundle(est: &SessionPoses) {
    let Some(b) = &est.bundle else {
        return;
    };
    println!(
        "bundle adjustment: {} corners ({} targets gated out), {} parameters, robust cost {:.1} -> {:.1} ({:.2}% lower), rms {:.3} -> {:.3} px, {} down-weighted, {} iterations, {:.0} ms",
        b.observations,
        b.gated_targets,
        b.parameters,
        b.initial_cost,
        b.final_cost,
        100.0 * b.relative_improvement,
        b.initial_rms_px,
        b.final_rms_px,
        b.downweighted,
        b.iterations,
        b.time_ms
    );
}

fn truth(e: &TruthErrors) {
    println!(
        "vs truth (median): camera position error {:.3} mm, orientation error {:.4} deg, head position error {:.3} mm, head orientation error {:.4} deg",
        median(&e.camera_position_error_m) * 1e3,
        median(&e.camera_orientation_error_deg),
        median(&e.head_position_error_m) * 1e3,
        median(&e.head_orientation_error_deg)
    );
    if let Some(l) = e.light_position_error_m {
        println!("vs truth: flash position error {:.3} mm", l * 1e3);
    }
    if let Some(s) = e.standard_position_error_m {
        println!("vs truth: standard position error {:.3} mm", s * 1e3);
    }
    // A statistic of no corners (every target of the layout missed) is "-".
    let stat = |v: Option<f64>, digits: usize| {
        v.map_or_else(|| "-".to_string(), |v| format!("{v:.digits$}"))
    };
    for (layout, c) in e.corner_summary() {
        println!(
            "vs truth: {layout} corners: {} compared, error median {} px, p90 {}, max {}, error/sigma median {} (1.18 if the sigmas are honest); {} fully visible targets missed",
            c.corners,
            stat(c.corner_error_median_px, 3),
            stat(c.corner_error_p90_px, 3),
            stat(c.corner_error_max_px, 3),
            stat(c.error_over_sigma_median, 2),
            c.missed_targets
        );
    }
    println!(
        "vs truth: {} detections of ids not in their image",
        e.false_detections
    );
}
