//! Parsing `session.toml` section by section, naming the field of every problem.
//!
//! Each section is deserialised on its own (so one bad section does not hide the next), and each
//! item of an array of tables on its own. Two guarantees hold for every table, including the
//! ones whose types live in other crates (`skinbrdf_core::CameraModel`, the BRDF models):
//!
//! * **Unknown keys are errors.** After a section deserialises, it is serialised again and every
//!   key of the input that the round trip does not reproduce is reported as unknown, with its full
//!   path (`camera.distortion.k4`). This holds through tagged enums and flattened tables, where
//!   serde's own `deny_unknown_fields` does not reach. It relies on the format types serialising
//!   every field they read (they skip only `None` options, which TOML cannot state).
//! * **Type errors name the field.** Tagged tables (`[camera] status`, `[geometry] kind`,
//!   `[standard.brdf] model`) are dispatched on their tag here, so each variant is read as a
//!   plain struct and the TOML deserialiser's key path reaches the offending field
//!   (`camera.fx_px`, `standard.brdf.albedo`).

use std::path::Path;

use glam::DVec3;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use skinbrdf_brdf::{BrdfModel, CookTorrance, Lafortune};
use skinbrdf_core::CameraModel;

use crate::error::SessionErrors;
use crate::format::*;
use crate::linear::Linearization;

/// What `session.toml` stated, beyond the parsed values: which optional sections were given
/// (the loader's rules depend on it; see [`crate::needs::SectionNeeds`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stated {
    /// `[linearization]` was given.
    pub linearization: bool,
    /// `[targets]` was given.
    pub targets: bool,
    /// `[flash]` was given.
    pub flash: bool,
}

/// Splits a TOML deserialisation error into its key path (inside the value that was
/// deserialised; empty when the deserialiser did not track it) and its message.
fn de_error_parts(e: &toml::de::Error) -> (String, String) {
    let message = e.message().trim().to_string();
    let keys = e
        .to_string()
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("in `").and_then(|r| r.strip_suffix('`')))
        .unwrap_or_default()
        .to_string();
    (keys, message)
}

fn join(prefix: &str, key: &str) -> String {
    if prefix.is_empty() {
        key.to_string()
    } else if key.is_empty() {
        prefix.to_string()
    } else {
        format!("{prefix}.{key}")
    }
}

/// The field a deserialisation error is about: the section's path, the key path the TOML
/// deserialiser tracked, and for "missing field `x`" / "unknown field `x`" that field itself.
fn error_field(field: &str, e: &toml::de::Error) -> (String, String) {
    let (keys, message) = de_error_parts(e);
    let mut path = join(field, &keys);
    let named = ["missing field `", "unknown field `"]
        .iter()
        .find_map(|p| message.strip_prefix(p))
        .and_then(|r| r.split('`').next());
    if let Some(name) = named {
        path = join(&path, name);
    }
    (path, message)
}

/// Every key path of `input` that `round_trip` (the parsed value serialised again) lacks.
fn unknown_keys(input: &toml::Value, round_trip: &toml::Value, path: &str, out: &mut Vec<String>) {
    match (input, round_trip) {
        (toml::Value::Table(a), toml::Value::Table(b)) => {
            for (k, v) in a {
                let p = join(path, k);
                match b.get(k) {
                    None => out.push(p),
                    Some(w) => unknown_keys(v, w, &p, out),
                }
            }
        }
        (toml::Value::Array(a), toml::Value::Array(b)) if a.len() == b.len() => {
            for (i, (v, w)) in a.iter().zip(b).enumerate() {
                unknown_keys(v, w, &format!("{path}[{i}]"), out);
            }
        }
        _ => {}
    }
}

/// Every key path of a TOML value that the value deserialised from it does not read (its
/// serialisation lacks them): unknown keys, also inside tagged enums and types without
/// `deny_unknown_fields`. Empty when `parsed` does not serialise. See the module docs.
pub fn toml_unknown_keys<T: Serialize>(input: &toml::Value, parsed: &T) -> Vec<String> {
    let Ok(round_trip) = toml::Value::try_from(parsed) else {
        return Vec::new();
    };
    let mut unknown = Vec::new();
    unknown_keys(input, &round_trip, "", &mut unknown);
    unknown
}

/// Reports every key of `input` that `parsed` does not read (see the module docs).
fn report_unknown<T: Serialize>(
    input: &toml::Value,
    parsed: &T,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> bool {
    // A value that does not serialise back (none of the format's types) cannot be audited.
    let Ok(round_trip) = toml::Value::try_from(parsed) else {
        return true;
    };
    let mut unknown = Vec::new();
    unknown_keys(input, &round_trip, field, &mut unknown);
    for p in &unknown {
        errs.push(file, p.as_str(), "unknown field");
    }
    unknown.is_empty()
}

/// Deserialises one value, reporting a type error at its field and every unknown key.
pub(crate) fn item<T: DeserializeOwned + Serialize>(
    v: toml::Value,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> Option<T> {
    match v.clone().try_into::<T>() {
        Ok(t) => report_unknown(&v, &t, file, field, errs).then_some(t),
        Err(e) => {
            let (path, message) = error_field(field, &e);
            errs.push(file, path, message);
            None
        }
    }
}

/// Takes an array-of-items out of a table and deserialises each item on its own.
fn take_list<T: DeserializeOwned + Serialize>(
    table: &mut toml::Table,
    key: &str,
    prefix: &str,
    file: &Path,
    errs: &mut SessionErrors,
) -> (Vec<T>, bool) {
    let field = join(prefix, key);
    match table.remove(key) {
        None => (Vec::new(), true),
        Some(toml::Value::Array(items)) => {
            let mut ok = true;
            let mut out = Vec::with_capacity(items.len());
            for (i, v) in items.into_iter().enumerate() {
                match item(v, file, &format!("{field}[{i}]"), errs) {
                    Some(t) => out.push(t),
                    None => ok = false,
                }
            }
            (out, ok)
        }
        Some(other) => {
            errs.push(
                file,
                field,
                format!("must be an array of tables, found a {}", other.type_str()),
            );
            (Vec::new(), false)
        }
    }
}

fn as_table(
    v: toml::Value,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> Option<toml::Table> {
    match v {
        toml::Value::Table(t) => Some(t),
        other => {
            errs.push(
                file,
                field,
                format!("must be a table, found a {}", other.type_str()),
            );
            None
        }
    }
}

/// Takes the string tag `tag` out of a tagged table.
fn take_tag(
    t: &mut toml::Table,
    tag: &str,
    expected: &str,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> Option<String> {
    let path = join(field, tag);
    match t.remove(tag) {
        None => {
            errs.push(file, path, format!("missing (required): one of {expected}"));
            None
        }
        Some(toml::Value::String(s)) => Some(s),
        Some(other) => {
            errs.push(
                file,
                path,
                format!(
                    "must be a string ({expected}), found a {}",
                    other.type_str()
                ),
            );
            None
        }
    }
}

fn unknown_variant(tag: &str, value: &str, expected: &str) -> String {
    format!("unknown {tag} `{value}`, expected one of {expected}")
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ToBeCalibrated {
    width_px: u32,
    height_px: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    focal_guess_px: Option<f64>,
}

fn parse_camera(v: toml::Value, file: &Path, errs: &mut SessionErrors) -> Option<CameraSpec> {
    let field = "camera";
    let mut t = as_table(v, file, field, errs)?;
    const EXPECTED: &str = "\"calibrated\", \"to-be-calibrated\"";
    let status = take_tag(&mut t, "status", EXPECTED, file, field, errs)?;
    let rest = toml::Value::Table(t);
    match status.as_str() {
        "calibrated" => item::<CameraModel>(rest, file, field, errs).map(CameraSpec::Calibrated),
        "to-be-calibrated" => {
            item::<ToBeCalibrated>(rest, file, field, errs).map(|c| CameraSpec::ToBeCalibrated {
                width_px: c.width_px,
                height_px: c.height_px,
                focal_guess_px: c.focal_guess_px,
            })
        }
        other => {
            errs.push(
                file,
                "camera.status",
                unknown_variant("status", other, EXPECTED),
            );
            None
        }
    }
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Lambertian {
    albedo: [f64; 3],
}

/// Reads a `BrdfModel` table (`model = "lambertian" | "lafortune" | "cook_torrance"`).
fn parse_brdf(
    v: toml::Value,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> Option<BrdfModel> {
    let mut t = as_table(v, file, field, errs)?;
    const EXPECTED: &str = "\"lambertian\", \"lafortune\", \"cook_torrance\"";
    let model = take_tag(&mut t, "model", EXPECTED, file, field, errs)?;
    let rest = toml::Value::Table(t);
    match model.as_str() {
        "lambertian" => item::<Lambertian>(rest, file, field, errs)
            .map(|l| BrdfModel::Lambertian { albedo: l.albedo }),
        "lafortune" => item::<Lafortune>(rest, file, field, errs).map(BrdfModel::Lafortune),
        "cook_torrance" => {
            item::<CookTorrance>(rest, file, field, errs).map(BrdfModel::CookTorrance)
        }
        other => {
            errs.push(
                file,
                join(field, "model"),
                unknown_variant("model", other, EXPECTED),
            );
            None
        }
    }
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Scan {
    file: String,
    units: LengthUnit,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    accept_repair_loss: Option<f64>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Sphere {
    centre_m: DVec3,
    radius_m: f64,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Cylinder {
    centre_m: DVec3,
    axis: DVec3,
    radius_m: f64,
    length_m: f64,
}

fn parse_geometry(v: toml::Value, file: &Path, errs: &mut SessionErrors) -> Option<GeometrySpec> {
    let field = "geometry";
    let mut t = as_table(v, file, field, errs)?;
    const EXPECTED: &str = "\"scan\", \"sphere\", \"cylinder\"";
    let kind = take_tag(&mut t, "kind", EXPECTED, file, field, errs)?;
    let rest = toml::Value::Table(t);
    match kind.as_str() {
        "scan" => item::<Scan>(rest, file, field, errs).map(|s| GeometrySpec::Scan {
            file: s.file,
            units: s.units,
            accept_repair_loss: s.accept_repair_loss,
        }),
        "sphere" => item::<Sphere>(rest, file, field, errs).map(|s| GeometrySpec::Sphere {
            centre_m: s.centre_m,
            radius_m: s.radius_m,
        }),
        "cylinder" => item::<Cylinder>(rest, file, field, errs).map(|c| GeometrySpec::Cylinder {
            centre_m: c.centre_m,
            axis: c.axis,
            radius_m: c.radius_m,
            length_m: c.length_m,
        }),
        other => {
            errs.push(
                file,
                "geometry.kind",
                unknown_variant("kind", other, EXPECTED),
            );
            None
        }
    }
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FlashWithoutTargets {
    diameter_m: f64,
    #[serde(default)]
    light_centre_m: DVec3,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct StandardWithoutParts {
    size_m: [f64; 2],
}

fn parse_targets(v: toml::Value, file: &Path, errs: &mut SessionErrors) -> Option<TargetLayouts> {
    let mut t = as_table(v, file, "targets", errs)?;
    let (reference, ok1) = take_list::<Target>(&mut t, "reference", "targets", file, errs);
    let (headdress, ok2) = take_list::<Target>(&mut t, "headdress", "targets", file, errs);
    let (unplaced, ok3) = take_list::<UnplacedTarget>(&mut t, "unplaced", "targets", file, errs);
    let family = t
        .remove("family")
        .and_then(|v| item::<String>(v, file, "targets.family", errs))
        .unwrap_or_else(|| TAG_FAMILY.to_string());
    for k in t.keys() {
        errs.push(
            file,
            format!("targets.{k}"),
            "unknown field (expected family, reference, headdress, unplaced)",
        );
    }
    (ok1 && ok2 && ok3 && t.is_empty()).then_some(TargetLayouts {
        family,
        reference,
        headdress,
        unplaced,
    })
}

fn parse_flash(v: toml::Value, file: &Path, errs: &mut SessionErrors) -> Option<FlashSpec> {
    let mut t = as_table(v, file, "flash", errs)?;
    let (targets, ok) = take_list::<Target>(&mut t, "targets", "flash", file, errs);
    item::<FlashWithoutTargets>(toml::Value::Table(t), file, "flash", errs)
        .filter(|_| ok)
        .map(|f| FlashSpec {
            diameter_m: f.diameter_m,
            light_centre_m: f.light_centre_m,
            targets,
        })
}

fn parse_standard(v: toml::Value, file: &Path, errs: &mut SessionErrors) -> Option<StandardSpec> {
    let mut t = as_table(v, file, "standard", errs)?;
    let (targets, ok) = take_list::<Target>(&mut t, "targets", "standard", file, errs);
    let brdf = match t.remove("brdf") {
        Some(b) => parse_brdf(b, file, "standard.brdf", errs),
        None => {
            errs.push(file, "standard.brdf", "missing (required)");
            None
        }
    };
    let rest = item::<StandardWithoutParts>(toml::Value::Table(t), file, "standard", errs);
    match (brdf, rest, ok) {
        (Some(brdf), Some(r), true) => Some(StandardSpec {
            brdf,
            size_m: r.size_m,
            targets,
        }),
        _ => None,
    }
}

/// Parses the text of `session.toml`: the file (when every section parsed) and what it stated.
pub(crate) fn parse_session_toml(
    text: &str,
    file: &Path,
    errs: &mut SessionErrors,
) -> Option<(SessionFile, Stated)> {
    let mut root: toml::Table = match text.parse() {
        Ok(t) => t,
        Err(e) => {
            let e: toml::de::Error = e;
            let at = e
                .span()
                .map(|s| {
                    let line = text[..s.start.min(text.len())].matches('\n').count() + 1;
                    format!(" (line {line})")
                })
                .unwrap_or_default();
            errs.push(
                file,
                "",
                format!("not valid TOML{at}: {}", e.message().trim()),
            );
            return None;
        }
    };
    let n_before = errs.len();
    let need = |root: &mut toml::Table, key: &str, errs: &mut SessionErrors| {
        let v = root.remove(key);
        if v.is_none() {
            errs.push(file, key, "missing (required)");
        }
        v
    };
    let format_version = need(&mut root, "format_version", errs)
        .and_then(|v| item::<u32>(v, file, "format_version", errs));
    if let Some(v) = format_version {
        if v != SESSION_FORMAT_VERSION {
            errs.push(
                file,
                "format_version",
                format!("version {v} is not supported (this build reads {SESSION_FORMAT_VERSION})"),
            );
        }
    }
    let description = root
        .remove("description")
        .and_then(|v| item::<String>(v, file, "description", errs))
        .unwrap_or_default();
    let capture = root
        .remove("capture")
        .and_then(|v| item::<String>(v, file, "capture", errs));
    let camera = need(&mut root, "camera", errs).and_then(|v| parse_camera(v, file, errs));
    let mut stated = Stated::default();
    let linearization = match root.remove("linearization") {
        Some(v) => {
            stated.linearization = true;
            item::<Linearization>(v, file, "linearization", errs)
        }
        None => Some(Linearization::LINEAR),
    };
    let images = {
        let mut holder = toml::Table::new();
        match root.remove("images") {
            Some(v) => {
                holder.insert("images".into(), v);
            }
            None => errs.push(
                file,
                "images",
                "missing (required): at least one [[images]] entry",
            ),
        }
        let (list, ok) = take_list::<ImageEntry>(&mut holder, "images", "", file, errs);
        ok.then_some(list)
    };
    let targets = match root.remove("targets") {
        Some(v) => {
            stated.targets = true;
            parse_targets(v, file, errs)
        }
        None => Some(TargetLayouts::default()),
    };
    let flash = match root.remove("flash") {
        Some(v) => {
            stated.flash = true;
            parse_flash(v, file, errs)
        }
        None => Some(FlashSpec::default()),
    };
    let standard = match root.remove("standard") {
        Some(v) => parse_standard(v, file, errs).map(Some),
        None => Some(None),
    };
    let geometry = need(&mut root, "geometry", errs).and_then(|v| parse_geometry(v, file, errs));
    let roi = match root.remove("roi") {
        Some(v) => item::<RegionOfInterest>(v, file, "roi", errs).map(Some),
        None => Some(None),
    };
    let known = match root.remove("known") {
        Some(v) => item::<KnownQuantities>(v, file, "known", errs),
        None => Some(KnownQuantities::default()),
    };
    let registration = match root.remove("registration") {
        Some(v) => item::<RegistrationSpec>(v, file, "registration", errs).map(Some),
        None => Some(None),
    };
    for k in root.keys() {
        errs.push(file, k.as_str(), "unknown field");
    }
    if errs.len() > n_before {
        // The needs of the stages can still be stated from what did parse.
        if let (Some(images), Some(known)) = (&images, &known) {
            report_missing_sections(images, known, camera.as_ref(), stated, file, errs);
        } else {
            report_missing_sections(&[], &KnownQuantities::default(), None, stated, file, errs);
        }
        return None;
    }
    let f = SessionFile {
        format_version: format_version?,
        description,
        capture,
        camera: camera?,
        linearization: linearization?,
        images: images?,
        targets: targets?,
        flash: flash?,
        standard: standard?,
        geometry: geometry?,
        roi: roi?,
        known: known?,
        registration: registration?,
    };
    report_missing_sections(&f.images, &f.known, Some(&f.camera), stated, file, errs);
    (errs.len() == n_before).then_some((f, stated))
}

/// The sections `[targets]`, `[flash]` and `[linearization]` are required only when a stage
/// needs them (see [`crate::needs::SectionNeeds`]); reports the ones missing.
fn report_missing_sections(
    images: &[ImageEntry],
    known: &KnownQuantities,
    camera: Option<&CameraSpec>,
    stated: Stated,
    file: &Path,
    errs: &mut SessionErrors,
) {
    let needs = crate::needs::SectionNeeds::of(images, known, camera);
    if !stated.targets {
        if let Some(why) = needs
            .reference_targets
            .as_ref()
            .or(needs.headdress_targets.as_ref())
        {
            errs.push(
                file,
                "targets",
                format!("missing (required): [targets] with reference/headdress layouts: {why}"),
            );
        }
    }
    if !stated.flash {
        if let Some(why) = &needs.flash_targets {
            errs.push(
                file,
                "flash",
                format!("missing (required): [flash] with diameter_m and targets: {why}"),
            );
        }
    }
    if !stated.linearization {
        if let Some(why) = &needs.linearization {
            errs.push(
                file,
                "linearization",
                format!(
                    "missing (required): {why}; state curve and black_level (e.g. `[linearization] curve = \"srgb\"`, `black_level = 0`)"
                ),
            );
        }
    }
}
