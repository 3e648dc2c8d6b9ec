//! Prints what this crate reads from raw files, one JSON line per file, for the parity check
//! against LibRaw (`scripts/peers/raw_parity.py`, docs/ingest.md "Real cameras against LibRaw").
//!
//! ```text
//! cargo run -p skinbrdf-raw --example raw_info -- FILE...
//! ```
//!
//! Each line holds the file's name, its kind from its content (`sniff`) and whether its
//! extension agrees (`check_extension`, which ingest applies), then one object per reader, each
//! either its result or `{"error": "..."}` with the error text as a user sees it:
//!
//! * `metadata` ([`read_metadata`]): make and model as the crate returns them, exposure time,
//!   ISO, f-number, focal length and capture time;
//! * `header` ([`read_raw_header`]): the image size as loaded (superpixels), bit depth, phase;
//! * `photosites` ([`decode_photosites`]): full sensor size, the active area's origin and the
//!   size of the image as loaded (its even part), the CFA pattern at its origin, the black
//!   level per quad position and the white level, and the decoded values turned back into raw
//!   units (`n * (white - black_c) + black_c`): the mean per quad position over the image, and
//!   a few sample photosites (`[x, y, raw]`, image coordinates).

use std::path::{Path, PathBuf};

use serde_json::{json, Value};
use skinbrdf_raw::{
    check_extension, decode_photosites, read_metadata, read_raw_header, sniff, RawFrame, RawOptions,
};

fn main() {
    let files: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    if files.is_empty() {
        eprintln!("usage: raw_info FILE...");
        std::process::exit(2);
    }
    // The readers catch the decoder's panics and return them as errors; the default hook would
    // still print each one.
    std::panic::set_hook(Box::new(|_| {}));
    for f in files {
        println!("{}", info(&f));
    }
}

/// Everything read from one file.
fn info(path: &Path) -> Value {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let kind = sniff(path);
    let extension = match &kind {
        Ok(k) => match check_extension(path, *k) {
            Ok(()) => json!("ok"),
            Err(e) => json!({ "error": e.to_string() }),
        },
        Err(_) => Value::Null,
    };
    json!({
        "file": name,
        "kind": kind.as_ref().map_or_else(|e| json!({"error": e.to_string()}), |k| json!(k.name())),
        "extension": extension,
        "metadata": metadata(path),
        "header": header(path),
        "photosites": photosites(path),
    })
}

fn metadata(path: &Path) -> Value {
    match read_metadata(path) {
        Err(e) => json!({ "error": e.to_string() }),
        Ok(m) => {
            let time = m.capture_time.as_ref().map(|t| t.local.exif_text());
            json!({
                "make": m.camera_make,
                "model": m.camera_model,
                "exposure_time_s": m.exposure_time_s,
                "iso": m.iso,
                "f_number": m.f_number,
                "focal_length_mm": m.focal_length_mm,
                "capture_time": time,
            })
        }
    }
}

fn header(path: &Path) -> Value {
    match read_raw_header(path) {
        Err(e) => json!({ "error": e.to_string() }),
        Ok(h) => json!({
            "superpixel_width_px": h.width_px,
            "superpixel_height_px": h.height_px,
            "bits_per_sample": h.bits_per_sample,
            "cfa": h.cfa.name(),
        }),
    }
}

fn photosites(path: &Path) -> Value {
    match decode_photosites(path, &RawOptions::default()) {
        Err(e) => json!({ "error": e.to_string() }),
        Ok(frame) => frame_stats(&frame),
    }
}

/// The photosite at image `(x, y)` in raw units (its own channel's value un-normalised).
fn raw_at(frame: &RawFrame, x: u32, y: u32) -> Option<f64> {
    let k = ((y % 2) * 2 + x % 2) as usize;
    let px = frame.get(x, y)?;
    let n = px.iter().copied().find(|v| !v.is_nan())?;
    let black = frame.black_levels[k];
    Some(f64::from(n) * (frame.white_level - black) + black)
}

fn frame_stats(frame: &RawFrame) -> Value {
    let (w, h) = (frame.width_px, frame.height_px);
    let mut sum = [0.0f64; 4];
    let mut count = [0u64; 4];
    for y in 0..h {
        for x in 0..w {
            if let Some(v) = raw_at(frame, x, y) {
                let k = ((y % 2) * 2 + x % 2) as usize;
                sum[k] += v;
                count[k] += 1;
            }
        }
    }
    let mean: Vec<Option<f64>> = (0..4)
        .map(|k| (count[k] > 0).then(|| sum[k] / count[k] as f64))
        .collect();
    let points = [
        (0, 0),
        (1, 0),
        (0, 1),
        (1, 1),
        (w / 2, h / 2),
        (w.saturating_sub(1), h.saturating_sub(1)),
    ];
    let samples: Vec<Value> = points
        .iter()
        .filter_map(|&(x, y)| raw_at(frame, x, y).map(|v| json!([x, y, v])))
        .collect();
    json!({
        "sensor_width_px": frame.sensor_width_px,
        "sensor_height_px": frame.sensor_height_px,
        "active_left_px": frame.active_left_px,
        "active_top_px": frame.active_top_px,
        "width_px": w,
        "height_px": h,
        "cfa": frame.cfa.name(),
        "bits_per_sample": frame.bits_per_sample,
        "black_levels": frame.black_levels,
        "white_level": frame.white_level,
        "mean_raw_per_position": mean,
        "samples_raw": samples,
    })
}
