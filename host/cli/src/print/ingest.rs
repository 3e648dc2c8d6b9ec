//! `skinbrdf ingest`: the camera clock fit with every pair's residual, the survey images, the
//! files left out and why, the exposures without a file, and what the session still needs.

use skinbrdf_ingest::ingest::CameraSource;
use skinbrdf_ingest::IngestReport;

/// The report on stdout.
pub fn text(r: &IngestReport) {
    clock_and_images(r);
    left_out(r);
    intrinsics(r);
    placements_and_session(r);
}

/// The camera, its clock fit, and one row per matched image; then the survey images.
fn clock_and_images(r: &IngestReport) {
    let c = &r.matching.clock;
    println!("camera: {}, {}", r.camera_body, r.lens);
    println!(
        "camera clock: offset {:+.3} s, drift {:+.1} ppm{}, residual rms {:.1} ms, max {:.1} ms over {} pairs (time resolution {} ms)",
        c.offset_s,
        c.drift_ppm,
        if c.drift_fitted { "" } else { " (not fitted: too few pairs)" },
        c.residual_rms_s * 1e3,
        c.residual_max_s * 1e3,
        c.pairs_used,
        c.time_resolution_s * 1e3
    );
    println!(
        "{:<42} {:>8} {:<20} {:>10} {:>8}",
        "image", "exposure", "role", "resid ms", "scale"
    );
    for i in &r.images {
        println!(
            "{:<42} {:>8} {:<20} {:>10.2} {:>8.4}",
            i.card_file
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            i.exposure_index,
            i.role.name(),
            i.time_residual_s * 1e3,
            i.exposure_scale
        );
    }
    if !r.survey_images.is_empty() {
        println!(
            "survey images: {} (role survey; exposure not compared: geometry only)",
            r.survey_images.len()
        );
        for s in &r.survey_images {
            println!(
                "  {:<40} {:<24} {}",
                s.source_file.display(),
                s.settings.map_or("?".to_string(), |x| x.to_string()),
                if s.before_session {
                    "before the session"
                } else {
                    "after the session's first file"
                }
            );
        }
    }
}

/// Files left out or skipped, exposures without a file, the scan's repair.
fn left_out(r: &IngestReport) {
    for (f, why) in &r.matching.extra_files {
        println!("left out: {f}: {why}");
    }
    for e in &r.matching.missing {
        println!("missing: exposure {e} fired the camera but has no file on the card");
    }
    if !r.matching.no_file_expected.is_empty() {
        let list: Vec<String> = r
            .matching
            .no_file_expected
            .iter()
            .map(ToString::to_string)
            .collect();
        println!(
            "no file expected (the camera did not fire): exposures {}",
            list.join(", ")
        );
    }
    for (f, what) in &r.skipped_files {
        println!("skipped: {f}: {what}");
    }
    if let Some(repair) = &r.scan_repair {
        println!("scan: repaired when loaded (process loads it the same way): {repair}");
    }
}

/// Where the intrinsics come from (and the focal length to start a calibration from).
fn intrinsics(r: &IngestReport) {
    match &r.camera {
        CameraSource::File { path } => {
            println!("intrinsics: {} (--camera)", path.display())
        }
        CameraSource::Rig { path } => {
            println!("intrinsics: the rig's [camera] ({})", path.display())
        }
        CameraSource::ToBeCalibrated => {
            println!(
                "intrinsics: to be calibrated from the reference targets ({}x{} images as loaded)",
                r.image_size_px.0, r.image_size_px.1
            );
            match &r.focal_guess {
                Some(g) => println!("focal length to start from: {g}"),
                None => println!(
                    "focal length to start from: none in the files ({}); the calibration searches",
                    r.focal_guess_refused.join("; ")
                ),
            }
        }
    }
    for n in &r.camera_notes {
        println!("camera: {n}");
    }
}

/// What the rig made known, the placements, and the session written.
fn placements_and_session(r: &IngestReport) {
    for k in &r.known_from_rig {
        println!("known from the rig: {k}");
    }
    if r.unplaced_targets > 0 {
        println!(
            "placements: {} targets placed, {} without a placement (listed as targets.unplaced: the placement survey fills them in)",
            r.placed_targets, r.unplaced_targets
        );
    } else {
        println!(
            "placements: all {} targets placed by the rig file",
            r.placed_targets
        );
    }
    println!(
        "session written to {} ({} images {}) in {:.2} s (metadata and matching {:.2} s, decoding {:.2} s)",
        r.session_dir.display(),
        r.images.len() + r.survey_images.len(),
        if r.copied { "copied" } else { "referenced in place" },
        r.total_s,
        r.metadata_s,
        r.decode_s
    );
}
