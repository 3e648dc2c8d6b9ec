//! The committed real-camera corpus (`host/raw/tests/data/real/`) read by this crate's
//! LibRaw 0.21, against `expected.json`: LibRaw 0.22 (through rawpy) for the sensor, exiftool
//! for the metadata. Every field a reference reads must agree, except the differences listed
//! in [`DIFFERENCES`] (each with its reason); a listed difference that no longer differs fails
//! the test, so the list stays true.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::{json, Value};
use skinbrdf_libraw::RawFile;

/// Exposure time, f-number and focal length: exiftool prints rationals with 10 significant
/// digits, LibRaw keeps them as `f32` (about 6e-8 relative), and APEX-coded values (CRW) are
/// rounded by each reader.
const REL_TOL_EXIF: f64 = 1e-3;
/// Black and white levels: both readers report integers from the same tags or tables.
const ABS_TOL_LEVEL_RAW: f64 = 0.5;

/// Where this crate (LibRaw 0.21.3) and the references differ: (file, field, why).
const DIFFERENCES: &[(&str, &str, &str)] = &[
    (
        "CanonRaw.crw",
        "make",
        "CIFF has no TIFF directory: LibRaw gives only its normalised make and model",
    ),
    (
        "CanonRaw.crw",
        "model",
        "CIFF has no TIFF directory: LibRaw gives only its normalised model (EOS 300D)",
    ),
    (
        "CanonRaw.crw",
        "exposure_time_s",
        "LibRaw reads the shot info's APEX value (1/60 s), exiftool the exposure record (1/64 s)",
    ),
    (
        "CanonRaw.crw",
        "f_number",
        "LibRaw reads the shot info's APEX value (f/3.51), exiftool another rounding (f/3.56)",
    ),
    (
        "exiv2-canon-powershot-s40.crw",
        "make",
        "CIFF has no TIFF directory: LibRaw gives only its normalised make and model",
    ),
    (
        "exiv2-canon-powershot-s40.crw",
        "model",
        "CIFF has no TIFF directory: LibRaw gives only its normalised model (PowerShot S40)",
    ),
    (
        "exiv2-canon-powershot-s40.crw",
        "exposure_time_s",
        "LibRaw reads the shot info's APEX value (1/15 s), exiftool another record (0.0653 s)",
    ),
    (
        "exiv2-canon-powershot-s40.crw",
        "f_number",
        "LibRaw reads the shot info's APEX value (f/2.80), exiftool another rounding (f/2.92)",
    ),
    (
        "FujiFilm.raf",
        "visible size",
        "LibRaw 0.21 crops the S5Pro to 3584 x 3583, LibRaw 0.22 to 3552 x 3551",
    ),
    (
        "FujiFilm.raf",
        "margins",
        "LibRaw 0.21 places the S5Pro's visible area at (32, 2), LibRaw 0.22 at (48, 10)",
    ),
    (
        "KyoceraRaw.raw",
        "make",
        "headerless: LibRaw identifies it by size and names it Contax (exiftool: KYOCERA)",
    ),
    (
        "KyoceraRaw.raw",
        "model",
        "headerless: LibRaw names it N Digital (exiftool: N DIGITAL)",
    ),
    (
        "Sigma.x3f",
        "make",
        "X3F has no TIFF directory: LibRaw gives only its normalised make (Sigma)",
    ),
    (
        "Sigma.x3f",
        "model",
        "X3F has no TIFF directory: LibRaw gives only its normalised model (SD10)",
    ),
    (
        "SigmaDP2.x3f",
        "make",
        "X3F has no TIFF directory: LibRaw gives only its normalised make (Sigma)",
    ),
    (
        "SigmaDP2.x3f",
        "model",
        "X3F has no TIFF directory: LibRaw gives only its normalised model (DP2)",
    ),
    (
        "KyoceraRaw.raw",
        "iso",
        "LibRaw reads ISO 100, exiftool the raw ISO code 13",
    ),
];

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../raw/tests/data/real")
}

fn expected() -> BTreeMap<String, Value> {
    let text = std::fs::read_to_string(data_dir().join("expected.json")).expect("expected.json");
    let v: Value = serde_json::from_str(&text).expect("expected.json is JSON");
    v["files"]
        .as_object()
        .expect("files")
        .iter()
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect()
}

/// What LibRaw 0.21 reads, per field, or the error's text under `error`.
fn ours(path: &Path) -> BTreeMap<&'static str, Value> {
    let mut out = BTreeMap::new();
    let file = match RawFile::open(path) {
        Ok(f) => f,
        Err(e) => {
            out.insert("error", Value::from(e.to_string()));
            return out;
        }
    };
    let h = file.header();
    let m = file.metadata();
    out.insert("sensor size", json!([h.raw_width_px, h.raw_height_px]));
    out.insert("visible size", json!([h.width_px, h.height_px]));
    out.insert("margins", json!([h.left_margin_px, h.top_margin_px]));
    if let Some(cfa) = &h.cfa {
        out.insert("CFA", Value::from(cfa.clone()));
        out.insert("black", json!(h.black_levels));
        out.insert("white", Value::from(h.white_level));
    }
    let mut put = |k: &'static str, v: Option<Value>| {
        if let Some(v) = v {
            out.insert(k, v);
        }
    };
    put("make", m.make_as_written.map(Value::from));
    put("model", m.model_as_written.map(Value::from));
    put("exposure_time_s", m.exposure_time_s.map(Value::from));
    put("f_number", m.f_number.map(Value::from));
    put("iso", m.iso.map(Value::from));
    put("focal_length_mm", m.focal_length_mm.map(Value::from));
    put("capture_time", m.capture_time.map(Value::from));
    out
}

/// The references per field: exiftool for the metadata, LibRaw 0.22 for the sensor.
fn reference(exp: &Value) -> BTreeMap<&'static str, Value> {
    let mut out = BTreeMap::new();
    for f in [
        "make",
        "model",
        "exposure_time_s",
        "f_number",
        "iso",
        "focal_length_mm",
        "capture_time",
    ] {
        let v = match &exp["exiftool"][f] {
            Value::String(s) if s.trim().is_empty() => Value::Null,
            Value::String(s) => Value::from(s.trim()),
            v => v.clone(),
        };
        if !v.is_null() {
            out.insert(f, v);
        }
    }
    let lr = &exp["libraw"];
    if let Some(e) = lr.get("error") {
        out.insert("error", e.clone());
        return out;
    }
    let n = |k: &str| lr[k].as_u64();
    if let (Some(w), Some(h)) = (n("raw_width"), n("raw_height")) {
        out.insert("sensor size", json!([w, h]));
    }
    if let (Some(w), Some(h)) = (n("width"), n("height")) {
        out.insert("visible size", json!([w, h]));
    }
    if let (Some(l), Some(t)) = (n("left_margin"), n("top_margin")) {
        out.insert("margins", json!([l, t]));
    }
    for (k, f) in [("cfa", "CFA"), ("black", "black"), ("white", "white")] {
        if let Some(v) = lr.get(k) {
            out.insert(f, v.clone());
        }
    }
    out
}

fn agrees(field: &str, ours: &Value, reference: &Value) -> bool {
    let num = |v: &Value| v.as_f64();
    let close_abs = |a: &Value, b: &Value| match (num(a), num(b)) {
        (Some(a), Some(b)) => (a - b).abs() <= ABS_TOL_LEVEL_RAW,
        _ => false,
    };
    match field {
        "exposure_time_s" | "f_number" | "focal_length_mm" => match (num(ours), num(reference)) {
            (Some(a), Some(b)) => (a - b).abs() <= REL_TOL_EXIF * b.abs(),
            _ => false,
        },
        "iso" => num(ours) == num(reference),
        "white" => close_abs(ours, reference),
        "black" => match (ours.as_array(), reference.as_array()) {
            (Some(a), Some(b)) => {
                a.len() == b.len() && a.iter().zip(b).all(|(x, y)| close_abs(x, y))
            }
            _ => false,
        },
        // Both failed to open the file: the reasons may be worded differently.
        "error" => true,
        _ => ours == reference,
    }
}

fn is_difference(file: &str, field: &str) -> bool {
    DIFFERENCES
        .iter()
        .any(|(f, what, _)| *f == file && *what == field)
}

/// Every disagreement that is not listed, and every listed one that agrees.
fn check_file(name: &str, exp: &Value) -> Vec<String> {
    let path = data_dir().join(name);
    let mine = ours(&path);
    let mut problems = Vec::new();
    if let Some(e) = mine.get("error").and_then(Value::as_str) {
        if !e.contains(name) {
            problems.push(format!("{name}: the error does not name the file: {e}"));
        }
    }
    let refs = reference(exp);
    if refs.contains_key("error") {
        // LibRaw 0.22 refuses the file: this crate must refuse it too, and then reads nothing.
        if !mine.contains_key("error") && !is_difference(name, "error") {
            problems.push(format!("{name}: LibRaw 0.22 refuses it, 0.21 reads it"));
        }
        return problems;
    }
    for (field, want) in refs {
        let got = mine.get(field);
        let ok = got.is_some_and(|v| agrees(field, v, &want));
        let listed = is_difference(name, field);
        if !ok && !listed {
            problems.push(format!("{name}: {field}: ours {got:?}, reference {want}"));
        } else if ok && listed {
            problems.push(format!(
                "{name}: {field} now agrees ({want}): take it off DIFFERENCES"
            ));
        }
    }
    if let (Some(e), false) = (mine.get("error"), is_difference(name, "error")) {
        problems.push(format!("{name}: LibRaw 0.21 refuses it: {e}"));
    }
    problems
}

#[test]
fn committed_corpus_agrees_with_libraw_022_and_exiftool_except_listed_differences() {
    let exp = expected();
    let mut names: Vec<String> = std::fs::read_dir(data_dir())
        .expect("the corpus")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !n.ends_with(".md") && !n.ends_with(".json"))
        .collect();
    names.sort();
    assert!(
        names.len() >= 10,
        "the committed corpus is there: {names:?}"
    );
    let mut problems = Vec::new();
    for name in &names {
        match exp.get(name) {
            Some(e) => problems.extend(check_file(name, e)),
            None => problems.push(format!("{name}: not in expected.json")),
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn every_listed_difference_names_a_file_of_the_corpus() {
    let exp = expected();
    for (file, field, why) in DIFFERENCES {
        assert!(
            exp.contains_key(*file),
            "{file} ({field}: {why}) is not in expected.json"
        );
    }
}

#[test]
fn the_bundled_libraw_is_0_21() {
    assert!(
        skinbrdf_libraw::version().starts_with("0.21"),
        "{}",
        skinbrdf_libraw::version()
    );
}

#[test]
fn a_file_libraw_cannot_read_is_an_error_naming_it() {
    let dir = std::env::temp_dir().join(format!("skinbrdf-libraw-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("not-raw.cr2");
    std::fs::write(&path, b"this is not a raw file at all").expect("write");
    let e = RawFile::open(&path).expect_err("not raw");
    assert!(e.to_string().contains("not-raw.cr2"), "{e}");
    let missing = RawFile::open(&dir.join("missing.nef")).expect_err("missing");
    assert!(missing.to_string().contains("missing.nef"), "{missing}");
    std::fs::remove_dir_all(&dir).ok();
}
