//! Loading and validating a session directory.
//!
//! [`Session::load`] parses `session.toml` section by section and item by item (so one bad
//! image entry does not hide the next), then checks every invariant and every cross-reference
//! (files exist, image sizes match the camera, target ids are unique across layouts, exposure
//! indices exist in `capture.json` with the same role, the stages that have no known quantity
//! to skip them have the targets and images they need). It returns all problems at once.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::de::DeserializeOwned;
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::Pose;

use crate::capture::{CaptureRecord, ImageRole, CAPTURE_FORMAT_VERSION};
use crate::error::{FileError, SessionErrors};
use crate::format::*;
use crate::linear::{load_linear_image, LinearImage, Linearization};
use crate::truth::Truth;

/// Number of codes in the tag36h11 family.
pub const TAG36H11_CODES: u32 = 587;

/// Relative tolerance on a target's edge lengths against `size_m` (printing and measuring a
/// layout is good to well under 1%; more means a wrong corner order or unit).
pub const TARGET_SIZE_REL_TOL: f64 = 0.01;

/// A loaded, validated session.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    /// The session directory.
    pub dir: PathBuf,
    /// The parsed `session.toml`.
    pub file: SessionFile,
    /// The parsed `capture.json`, if the session references one.
    pub capture: Option<CaptureRecord>,
}

impl Session {
    /// Loads and validates the session in `dir`, reporting every problem found.
    pub fn load(dir: impl AsRef<Path>) -> Result<Session, SessionErrors> {
        let dir = dir.as_ref().to_path_buf();
        let mut errs = SessionErrors::default();
        let toml_path = dir.join(SESSION_FILE);
        let text = match std::fs::read_to_string(&toml_path) {
            Ok(t) => t,
            Err(e) => {
                errs.push(&toml_path, "", format!("cannot read: {e}"));
                return Err(errs);
            }
        };
        let file = parse_session_toml(&text, &toml_path, &mut errs);
        let Some(file) = file else {
            return Err(errs);
        };
        let capture = validate(&dir, &file, &mut errs);
        errs.into_result(Session { dir, file, capture })
    }

    /// Parses and validates a `session.toml` text (no file checks; for tools and tests).
    pub fn parse_toml(text: &str, file_name: &Path) -> Result<SessionFile, SessionErrors> {
        let mut errs = SessionErrors::default();
        let f = parse_session_toml(text, file_name, &mut errs);
        match f {
            Some(f) if errs.is_empty() => Ok(f),
            _ => Err(errs),
        }
    }

    /// Writes a `session.toml` into `dir` atomically.
    pub fn write_file(dir: &Path, file: &SessionFile) -> Result<(), FileError> {
        crate::write::write_toml_atomic(&dir.join(SESSION_FILE), file)
    }

    /// A path relative to the session directory.
    pub fn path(&self, rel: &str) -> PathBuf {
        self.dir.join(rel)
    }

    /// The images with a role, with their indices.
    pub fn images_with_role(&self, role: ImageRole) -> impl Iterator<Item = (usize, &ImageEntry)> {
        self.file
            .images
            .iter()
            .enumerate()
            .filter(move |(_, e)| e.role == role)
    }

    /// The linearization of image `index` (its override or the session default).
    pub fn linearization(&self, index: usize) -> &Linearization {
        self.file
            .images
            .get(index)
            .and_then(|e| e.linearization.as_ref())
            .unwrap_or(&self.file.linearization)
    }

    /// Loads image `index` as linear RGB.
    pub fn load_image(&self, index: usize) -> Result<LinearImage, FileError> {
        let entry = self
            .file
            .images
            .get(index)
            .ok_or_else(|| FileError::Invalid {
                path: self.dir.join(SESSION_FILE),
                field: format!("images[{index}]"),
                problem: format!("no such image (the session has {})", self.file.images.len()),
            })?;
        load_linear_image(&self.path(&entry.file), self.linearization(index))
    }

    /// The scan file and the factor to metres, when the geometry is a scan.
    pub fn scan(&self) -> Option<(PathBuf, f64)> {
        match &self.file.geometry {
            GeometrySpec::Scan { file, units } => Some((self.path(file), units.to_m())),
            _ => None,
        }
    }

    /// The path of `truth.json` (it may not exist).
    pub fn truth_path(&self) -> PathBuf {
        self.dir.join(TRUTH_FILE)
    }

    /// Loads `truth.json` if present.
    pub fn load_truth(&self) -> Option<Result<Truth, FileError>> {
        let p = self.truth_path();
        p.exists().then(|| Truth::load(&p))
    }
}

fn de_error_text(e: &toml::de::Error) -> String {
    e.message().trim().to_string()
}

fn item<T: DeserializeOwned>(
    v: toml::Value,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> Option<T> {
    match v.try_into::<T>() {
        Ok(t) => Some(t),
        Err(e) => {
            errs.push(file, field, de_error_text(&e));
            None
        }
    }
}

/// Takes an array-of-items out of a table and deserialises each item on its own.
fn take_list<T: DeserializeOwned>(
    table: &mut toml::Table,
    key: &str,
    prefix: &str,
    file: &Path,
    errs: &mut SessionErrors,
) -> (Vec<T>, bool) {
    let field = format!("{prefix}{key}");
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

fn take_table(
    root: &mut toml::Table,
    key: &str,
    file: &Path,
    errs: &mut SessionErrors,
) -> Option<toml::Table> {
    match root.remove(key) {
        None => None,
        Some(toml::Value::Table(t)) => Some(t),
        Some(other) => {
            errs.push(
                file,
                key,
                format!("must be a table, found a {}", other.type_str()),
            );
            None
        }
    }
}

fn parse_session_toml(text: &str, file: &Path, errs: &mut SessionErrors) -> Option<SessionFile> {
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
                format!("not valid TOML{at}: {}", de_error_text(&e)),
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
    let camera =
        need(&mut root, "camera", errs).and_then(|v| item::<CameraSpec>(v, file, "camera", errs));
    let linearization = match root.remove("linearization") {
        Some(v) => item::<Linearization>(v, file, "linearization", errs),
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
    let targets = match take_table(&mut root, "targets", file, errs) {
        Some(mut t) => {
            let (reference, ok1) = take_list::<Target>(&mut t, "reference", "targets.", file, errs);
            let (headdress, ok2) = take_list::<Target>(&mut t, "headdress", "targets.", file, errs);
            let family = t
                .remove("family")
                .and_then(|v| item::<String>(v, file, "targets.family", errs))
                .unwrap_or_else(|| TAG_FAMILY.to_string());
            for k in t.keys() {
                errs.push(
                    file,
                    format!("targets.{k}"),
                    "unknown field (expected family, reference, headdress)",
                );
            }
            (ok1 && ok2).then_some(TargetLayouts {
                family,
                reference,
                headdress,
            })
        }
        None => {
            errs.push(
                file,
                "targets",
                "missing (required): [targets] with reference/headdress layouts",
            );
            None
        }
    };
    let flash = match take_table(&mut root, "flash", file, errs) {
        Some(mut t) => {
            let (targets, ok) = take_list::<Target>(&mut t, "targets", "flash.", file, errs);
            item::<FlashSpecNoTargets>(toml::Value::Table(t), file, "flash", errs)
                .filter(|_| ok)
                .map(|f| FlashSpec {
                    diameter_m: f.diameter_m,
                    light_centre_m: f.light_centre_m,
                    targets,
                })
        }
        None => {
            errs.push(
                file,
                "flash",
                "missing (required): [flash] with diameter_m and targets",
            );
            None
        }
    };
    let standard = match take_table(&mut root, "standard", file, errs) {
        Some(mut t) => {
            let (targets, ok) = take_list::<Target>(&mut t, "targets", "standard.", file, errs);
            item::<StandardSpecNoTargets>(toml::Value::Table(t), file, "standard", errs)
                .filter(|_| ok)
                .map(|s| {
                    Some(StandardSpec {
                        brdf: s.brdf,
                        size_m: s.size_m,
                        targets,
                    })
                })
        }
        None => Some(None),
    };
    let geometry = need(&mut root, "geometry", errs)
        .and_then(|v| item::<GeometrySpec>(v, file, "geometry", errs));
    let roi = match root.remove("roi") {
        Some(v) => item::<RegionOfInterest>(v, file, "roi", errs).map(Some),
        None => Some(None),
    };
    let known = match root.remove("known") {
        Some(v) => item::<KnownQuantities>(v, file, "known", errs),
        None => Some(KnownQuantities::default()),
    };
    for k in root.keys() {
        errs.push(file, k.as_str(), "unknown field");
    }
    if errs.len() > n_before {
        return None;
    }
    Some(SessionFile {
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
    })
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct FlashSpecNoTargets {
    diameter_m: f64,
    #[serde(default)]
    light_centre_m: DVec3,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct StandardSpecNoTargets {
    brdf: BrdfModel,
    size_m: [f64; 2],
}

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

fn check_pose(p: &Pose, file: &Path, field: &str, errs: &mut SessionErrors) {
    if !p.is_finite() {
        errs.push(file, field, "pose has a non-finite component");
    } else if (p.rotation.length() - 1.0).abs() > 1e-6 {
        errs.push(
            file,
            format!("{field}.rotation"),
            format!(
                "quaternion must be unit length, has length {}",
                p.rotation.length()
            ),
        );
    }
}

fn check_relative_file(
    dir: &Path,
    rel: &str,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> bool {
    let p = Path::new(rel);
    if rel.is_empty() {
        errs.push(file, field, "empty file name");
        return false;
    }
    if p.is_absolute()
        || p.components()
            .any(|c| matches!(c, std::path::Component::ParentDir))
    {
        errs.push(
            file,
            field,
            format!("`{rel}` must be a path inside the session directory"),
        );
        return false;
    }
    if !dir.join(p).is_file() {
        errs.push(file, field, format!("file `{rel}` does not exist"));
        return false;
    }
    true
}

fn check_target(t: &Target, file: &Path, field: &str, errs: &mut SessionErrors) {
    if t.id >= TAG36H11_CODES {
        errs.push(
            file,
            format!("{field}.id"),
            format!("{} is not a tag36h11 id (0..{TAG36H11_CODES})", t.id),
        );
    }
    if !positive(t.size_m) {
        errs.push(
            file,
            format!("{field}.size_m"),
            format!("must be positive, got {}", t.size_m),
        );
        return;
    }
    if !t.corners_m.iter().all(|c| c.is_finite()) || !t.centre_m.is_none_or(|c| c.is_finite()) {
        errs.push(file, format!("{field}.corners_m"), "non-finite coordinate");
        return;
    }
    let c = t.corners_m;
    let tol = TARGET_SIZE_REL_TOL * t.size_m;
    for i in 0..4 {
        let e = c[(i + 1) % 4].distance(c[i]);
        if (e - t.size_m).abs() > tol {
            errs.push(
                file,
                format!("{field}.corners_m"),
                format!(
                    "edge {i}->{} is {e:.5} m, but size_m is {} m",
                    (i + 1) % 4,
                    t.size_m
                ),
            );
            return;
        }
    }
    let d = c[2].distance(c[0]);
    if (d - t.size_m * std::f64::consts::SQRT_2).abs() > 2.0 * tol {
        errs.push(
            file,
            format!("{field}.corners_m"),
            "corners do not form a square",
        );
        return;
    }
    let n = (c[1] - c[0]).cross(c[3] - c[0]).normalize_or_zero();
    if (c[2] - c[0]).dot(n).abs() > tol {
        errs.push(
            file,
            format!("{field}.corners_m"),
            "corners are not coplanar",
        );
    }
    if let Some(centre) = t.centre_m {
        let mean = c.iter().copied().sum::<DVec3>() * 0.25;
        if centre.distance(mean) > tol {
            errs.push(
                file,
                format!("{field}.centre_m"),
                "is not the centre of the corners",
            );
        }
    }
}

fn check_brdf(b: &BrdfModel, file: &Path, field: &str, errs: &mut SessionErrors) {
    if let Err(e) = b.validate() {
        match e {
            skinbrdf_brdf::BrdfError::InvalidParameter { field: f, reason } => {
                errs.push(file, format!("{field}.{f}"), reason)
            }
            other => errs.push(file, field, other.to_string()),
        }
    }
}

/// Semantic and cross-file checks. Returns the capture record if it was loaded.
fn validate(dir: &Path, s: &SessionFile, errs: &mut SessionErrors) -> Option<CaptureRecord> {
    let file = dir.join(SESSION_FILE);
    let file = file.as_path();

    // Camera.
    let (w, h) = s.camera.size_px();
    match &s.camera {
        CameraSpec::Calibrated(m) => {
            if let Err(skinbrdf_core::CameraError::InvalidParameter { field, reason }) =
                m.validate()
            {
                errs.push(file, format!("camera.{field}"), reason);
            }
        }
        CameraSpec::ToBeCalibrated { focal_guess_px, .. } => {
            if w == 0 || h == 0 {
                errs.push(
                    file,
                    "camera.width_px/height_px",
                    "image size must be positive",
                );
            }
            if let Some(f) = focal_guess_px {
                if !positive(*f) {
                    errs.push(file, "camera.focal_guess_px", "must be positive and finite");
                }
            }
        }
    }

    // Default linearization.
    for (f, p) in s.linearization.problems() {
        errs.push(file, format!("linearization.{f}"), p);
    }

    // Capture record.
    let capture = s.capture.as_ref().and_then(|rel| {
        if !check_relative_file(dir, rel, file, "capture", errs) {
            return None;
        }
        let path = dir.join(rel);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) => {
                errs.push(&path, "", format!("cannot read: {e}"));
                return None;
            }
        };
        match serde_json::from_slice::<CaptureRecord>(&bytes) {
            Ok(c) if c.format_version == CAPTURE_FORMAT_VERSION => Some(c),
            Ok(c) => {
                errs.push(
                    &path,
                    "format_version",
                    format!(
                        "version {} is not supported (this build reads {CAPTURE_FORMAT_VERSION})",
                        c.format_version
                    ),
                );
                None
            }
            Err(e) => {
                errs.push(&path, "", format!("not a valid capture record: {e}"));
                None
            }
        }
    });

    // Images.
    if s.images.is_empty() {
        errs.push(file, "images", "the session has no images");
    }
    let mut seen: HashMap<&str, usize> = HashMap::new();
    for (i, im) in s.images.iter().enumerate() {
        let field = format!("images[{i}]");
        if let Some(prev) = seen.insert(im.file.as_str(), i) {
            errs.push(
                file,
                format!("{field}.file"),
                format!("`{}` is also images[{prev}]", im.file),
            );
        }
        if check_relative_file(dir, &im.file, file, &format!("{field}.file"), errs) {
            match image::image_dimensions(dir.join(&im.file)) {
                Ok((iw, ih)) if (iw, ih) != (w, h) => errs.push(
                    file,
                    format!("{field}.file"),
                    format!("`{}` is {iw}x{ih} px but the camera is {w}x{h} px", im.file),
                ),
                Ok(_) => {}
                Err(e) => errs.push(
                    file,
                    format!("{field}.file"),
                    format!("`{}` is not a readable image: {e}", im.file),
                ),
            }
        }
        if let Some(l) = &im.linearization {
            for (f, p) in l.problems() {
                errs.push(file, format!("{field}.linearization.{f}"), p);
            }
        }
        if let Some(m) = &im.mask {
            check_relative_file(dir, m, file, &format!("{field}.mask"), errs);
        }
        if let Some(p) = &im.world_from_camera {
            check_pose(p, file, &format!("{field}.world_from_camera"), errs);
        }
        if let Some(p) = &im.world_from_head {
            check_pose(p, file, &format!("{field}.world_from_head"), errs);
        }
        match (im.exposure_index, &capture) {
            (Some(x), Some(c)) => match c.exposures.iter().find(|e| e.index == x) {
                None => errs.push(
                    file,
                    format!("{field}.exposure_index"),
                    format!(
                        "exposure {x} is not in `{}`",
                        s.capture.as_deref().unwrap_or_default()
                    ),
                ),
                Some(e) if e.role != im.role => errs.push(
                    file,
                    format!("{field}.role"),
                    format!("is {:?} but exposure {x} was shot as {:?}", im.role, e.role),
                ),
                Some(_) => {}
            },
            (Some(_), None) if s.capture.is_none() => errs.push(
                file,
                format!("{field}.exposure_index"),
                "given, but the session has no `capture` record",
            ),
            _ => {}
        }
    }
    let count = |role| s.images.iter().filter(|i| i.role == role).count();
    if !s.images.is_empty() && count(ImageRole::Measurement) == 0 {
        errs.push(file, "images", "no image has role = \"measurement\"");
    }

    // Targets.
    if s.targets.family != TAG_FAMILY {
        errs.push(
            file,
            "targets.family",
            format!(
                "`{}` is not supported (only {TAG_FAMILY})",
                s.targets.family
            ),
        );
    }
    let mut ids: HashMap<u32, String> = HashMap::new();
    let mut all_targets: Vec<(String, &Target)> = Vec::new();
    for (name, list) in [
        ("targets.reference", &s.targets.reference),
        ("targets.headdress", &s.targets.headdress),
        ("flash.targets", &s.flash.targets),
    ] {
        for (i, t) in list.iter().enumerate() {
            all_targets.push((format!("{name}[{i}]"), t));
        }
    }
    if let Some(st) = &s.standard {
        for (i, t) in st.targets.iter().enumerate() {
            all_targets.push((format!("standard.targets[{i}]"), t));
        }
    }
    for (field, t) in &all_targets {
        check_target(t, file, field, errs);
        if let Some(prev) = ids.insert(t.id, field.clone()) {
            errs.push(
                file,
                format!("{field}.id"),
                format!("id {} is also used by {prev}", t.id),
            );
        }
    }

    // Flash and standard.
    if !positive(s.flash.diameter_m) {
        errs.push(
            file,
            "flash.diameter_m",
            format!("must be positive, got {}", s.flash.diameter_m),
        );
    }
    if !s.flash.light_centre_m.is_finite() {
        errs.push(file, "flash.light_centre_m", "non-finite coordinate");
    }
    if let Some(st) = &s.standard {
        check_brdf(&st.brdf, file, "standard.brdf", errs);
        if !st.size_m.iter().all(|&v| positive(v)) {
            errs.push(
                file,
                "standard.size_m",
                format!("must be positive, got {:?}", st.size_m),
            );
        }
    }

    // Geometry and region of interest.
    match &s.geometry {
        GeometrySpec::Scan { file: scan, .. } => {
            if check_relative_file(dir, scan, file, "geometry.file", errs) {
                let ext = Path::new(scan)
                    .extension()
                    .map(|e| e.to_string_lossy().to_ascii_lowercase())
                    .unwrap_or_default();
                if ext != "ply" && ext != "obj" {
                    errs.push(
                        file,
                        "geometry.file",
                        format!("`{scan}`: scans must be .ply or .obj"),
                    );
                }
            }
        }
        GeometrySpec::Sphere { centre_m, radius_m } => {
            if !centre_m.is_finite() {
                errs.push(file, "geometry.centre_m", "non-finite coordinate");
            }
            if !positive(*radius_m) {
                errs.push(
                    file,
                    "geometry.radius_m",
                    format!("must be positive, got {radius_m}"),
                );
            }
        }
        GeometrySpec::Cylinder {
            centre_m,
            axis,
            radius_m,
            length_m,
        } => {
            if !centre_m.is_finite() {
                errs.push(file, "geometry.centre_m", "non-finite coordinate");
            }
            if !axis.is_finite() || axis.length() < 1e-12 {
                errs.push(file, "geometry.axis", "must be a finite non-zero vector");
            }
            if !positive(*radius_m) {
                errs.push(
                    file,
                    "geometry.radius_m",
                    format!("must be positive, got {radius_m}"),
                );
            }
            if !positive(*length_m) {
                errs.push(
                    file,
                    "geometry.length_m",
                    format!("must be positive, got {length_m}"),
                );
            }
        }
    }
    if let Some(r) = &s.roi {
        if !r.centre_m.is_finite() {
            errs.push(file, "roi.centre_m", "non-finite coordinate");
        }
        if !positive(r.radius_m) {
            errs.push(
                file,
                "roi.radius_m",
                format!("must be positive, got {}", r.radius_m),
            );
        }
    }

    // Known quantities.
    let k = &s.known;
    if let Some(p) = k.light_position_m {
        if !p.is_finite() {
            errs.push(file, "known.light_position_m", "non-finite coordinate");
        }
    }
    if let Some(c) = k.calibration_c {
        if !c.iter().all(|&v| positive(v)) {
            errs.push(
                file,
                "known.calibration_c",
                format!("must be positive and finite, got {c:?}"),
            );
        }
    }
    if let Some(p) = &k.world_from_flash {
        check_pose(p, file, "known.world_from_flash", errs);
    }
    if let Some(p) = &k.world_from_standard {
        check_pose(p, file, "known.world_from_standard", errs);
    }

    // What the stages need when nothing known lets them skip.
    let no_cam: Vec<usize> = (0..s.images.len())
        .filter(|&i| s.images[i].world_from_camera.is_none())
        .collect();
    if !no_cam.is_empty() && s.targets.reference.is_empty() {
        errs.push(
            file,
            "targets.reference",
            format!(
                "empty, but {} image(s) have no known world_from_camera (first: images[{}])",
                no_cam.len(),
                no_cam[0]
            ),
        );
    }
    let no_head = s
        .images
        .iter()
        .position(|i| i.role == ImageRole::Measurement && i.world_from_head.is_none());
    if let (Some(i), false) = (no_head, k.stationary_sample) {
        if s.targets.headdress.is_empty() {
            errs.push(
                file,
                "targets.headdress",
                format!("empty, but images[{i}] has no known world_from_head and the sample is not stationary"),
            );
        }
    }
    if k.light_position_m.is_none() && k.world_from_flash.is_none() && s.flash.targets.is_empty() {
        errs.push(
            file,
            "flash.targets",
            "empty, and neither known.light_position_m nor known.world_from_flash is given",
        );
    }
    if k.calibration_c.is_none() {
        if s.standard.is_none() {
            errs.push(
                file,
                "standard",
                "missing, and known.calibration_c is not given",
            );
        }
        if count(ImageRole::ReferenceStandard) == 0 {
            errs.push(
                file,
                "images",
                "no reference-standard image, and known.calibration_c is not given",
            );
        }
    }
    capture
}
