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
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::Pose;

use crate::capture::{CaptureRecord, ImageRole, CAPTURE_FORMAT_VERSION};
use crate::error::{FileError, SessionErrors};
use crate::format::*;
use crate::linear::{
    load_linear_image, raw_options, LinearImage, Linearization, RawMode, StoredFormat,
};
use crate::parse::{parse_session_toml, Stated};
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
    /// Where the session's default linearization came from.
    pub linearization_source: LinearizationSource,
    /// Images left out by [`Session::check_images`] with [`BadImagePolicy::Skip`] (their
    /// entries are removed from `file.images`).
    pub skipped_images: Vec<SkippedImage>,
    /// Where the ground truth is read from when it is not the session's own `truth.json`
    /// (`skinbrdf process --truth FILE`: a session written by `ingest` scored against the
    /// synthetic session it came from).
    pub truth_file: Option<PathBuf>,
    /// How raw images load; with [`RawMode::Photosite`] in a session of raw images,
    /// `file.camera` is the photosite image's (see [`Session::set_raw_mode`]).
    raw_mode: RawMode,
}

/// Where the session's default linearization (`[linearization]`) came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinearizationSource {
    /// `session.toml` states it.
    Stated,
    /// Not stated, and every image that would use it is a float (OpenEXR) file: those are read
    /// as linear, black 0, white 1.0 (a default that the run's output and report state).
    FloatDefault,
    /// Not stated, and no image uses it (every image has its own `linearization`).
    Unused,
}

impl LinearizationSource {
    /// A sentence for the run's output when the linearization was not stated, else `None`.
    pub fn note(self) -> Option<&'static str> {
        match self {
            Self::FloatDefault => Some(
                "session.toml has no [linearization]: the OpenEXR images are read as linear \
                 values with black 0 and white 1.0",
            ),
            Self::Stated | Self::Unused => None,
        }
    }
}

/// An image that cannot be used: unreadable, or its values implausible.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SkippedImage {
    /// Its index in `session.toml`'s `[[images]]`.
    pub index: usize,
    /// Its file, relative to the session directory.
    pub file: String,
    /// Its role.
    pub role: ImageRole,
    /// What is wrong with it.
    pub cause: String,
}

/// What [`Session::check_images`] does with an image that cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BadImagePolicy {
    /// It is an error naming the file and the cause.
    #[default]
    Fail,
    /// It is left out of the session and listed in [`Session::skipped_images`].
    Skip,
}

impl Session {
    /// Loads and validates the session in `dir`, reporting every problem found.
    pub fn load(dir: impl AsRef<Path>) -> Result<Session, SessionErrors> {
        let dir = dir.as_ref().to_path_buf();
        let mut errs = SessionErrors::default();
        let toml_path = dir.join(SESSION_FILE);
        let text = match skinbrdf_core::untrusted::read_bounded_text(
            &toml_path,
            skinbrdf_core::untrusted::SETTINGS_FILE,
        ) {
            Ok(t) => t,
            Err(e) => {
                errs.push(&toml_path, "", e.reason());
                return Err(errs);
            }
        };
        let parsed = parse_session_toml(&text, &toml_path, &mut errs);
        let Some((file, stated)) = parsed else {
            return Err(errs);
        };
        let capture = validate(&dir, &file, stated, &mut errs);
        let linearization_source = if stated.linearization {
            LinearizationSource::Stated
        } else if file
            .images
            .iter()
            .any(|i| i.linearization.is_none() && !is_raw_file(&i.file))
        {
            LinearizationSource::FloatDefault
        } else {
            LinearizationSource::Unused
        };
        let mut session = Session {
            dir,
            file,
            capture,
            linearization_source,
            skipped_images: Vec::new(),
            truth_file: None,
            raw_mode: RawMode::Superpixel,
        };
        session.set_raw_mode(RawMode::default());
        errs.into_result(session)
    }

    /// A session from its parts, raw images loading as superpixels (for tools and tests that
    /// build one in memory; [`Session::load`] reads one from its directory).
    pub fn from_parts(dir: PathBuf, file: SessionFile, capture: Option<CaptureRecord>) -> Self {
        Self {
            dir,
            file,
            capture,
            linearization_source: LinearizationSource::Stated,
            skipped_images: Vec::new(),
            truth_file: None,
            raw_mode: RawMode::Superpixel,
        }
    }

    /// How the session's raw images load: the mode asked for when every image is a camera
    /// raw file; superpixels when the session mixes raw files with other images (its camera
    /// then describes the superpixel image and the others alike).
    pub fn raw_mode(&self) -> RawMode {
        self.raw_mode
    }

    /// True when the session's images are all camera raw files (by name).
    pub fn all_raw(&self) -> bool {
        !self.file.images.is_empty() && self.file.images.iter().all(|i| is_raw_file(&i.file))
    }

    /// Loads raw images in `mode` from now on and converts `file.camera` to the image as
    /// loaded: `session.toml` states a raw session's camera in superpixel units, and
    /// photosite mode doubles its size and focal lengths and maps its principal point
    /// `c -> 2 c + 0.5` ([`skinbrdf_raw::superpixel_camera_to_sensor`]). A session that is not
    /// all raw stays in superpixels (see [`Session::raw_mode`]).
    pub fn set_raw_mode(&mut self, mode: RawMode) {
        let mode = if self.all_raw() {
            mode
        } else {
            RawMode::Superpixel
        };
        if mode == self.raw_mode {
            return;
        }
        self.file.camera = match mode {
            RawMode::Photosite => photosite_camera(&self.file.camera),
            RawMode::Superpixel => self.camera_as_stated(&self.file.camera),
        };
        self.raw_mode = mode;
    }

    /// A camera of the image as loaded in the units `session.toml` states it in (the inverse
    /// of the conversion of [`Session::set_raw_mode`]): what a `[camera]` table written for
    /// the session must hold.
    pub fn camera_as_stated(&self, camera: &CameraSpec) -> CameraSpec {
        match (self.raw_mode, camera) {
            (RawMode::Superpixel, c) => *c,
            (RawMode::Photosite, CameraSpec::Calibrated(m)) => {
                CameraSpec::Calibrated(skinbrdf_raw::sensor_camera_to_superpixel(m))
            }
            (
                RawMode::Photosite,
                CameraSpec::ToBeCalibrated {
                    width_px,
                    height_px,
                    focal_guess_px,
                },
            ) => CameraSpec::ToBeCalibrated {
                width_px: width_px / 2,
                height_px: height_px / 2,
                focal_guess_px: focal_guess_px.map(skinbrdf_raw::sensor_to_superpixel_focal),
            },
        }
    }

    /// Parses and validates a `session.toml` text (no file checks; for tools and tests).
    pub fn parse_toml(text: &str, file_name: &Path) -> Result<SessionFile, SessionErrors> {
        let mut errs = SessionErrors::default();
        let f = parse_session_toml(text, file_name, &mut errs);
        match f {
            Some((f, _)) if errs.is_empty() => Ok(f),
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

    /// The linearization of image `index`: its override, else for a camera raw file
    /// [`Linearization::LINEAR`] (the file's own levels), else the session default.
    pub fn linearization(&self, index: usize) -> &Linearization {
        static RAW_OWN_LEVELS: Linearization = Linearization::LINEAR;
        let entry = self.file.images.get(index);
        match entry.and_then(|e| e.linearization.as_ref()) {
            Some(l) => l,
            None if entry.is_some_and(|e| is_raw_file(&e.file)) => &RAW_OWN_LEVELS,
            None => &self.file.linearization,
        }
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
        let mut img = load_linear_image(
            &self.path(&entry.file),
            self.linearization(index),
            self.raw_mode,
        )?;
        if let Some(k) = entry.exposure_scale {
            let k = k as f32;
            img.rgb
                .iter_mut()
                .for_each(|p| p.iter_mut().for_each(|c| *c *= k));
        }
        Ok(img)
    }

    /// Decodes every image and checks that its values are usable: readable to the end, every
    /// stored value finite, some value above the black level. With [`BadImagePolicy::Fail`] an
    /// unusable image is an error naming the file and the cause; with
    /// [`BadImagePolicy::Skip`] it is removed from `file.images` and listed in
    /// [`Session::skipped_images`] (then the session must still have what its stages need: a
    /// measurement image, and a reference-standard image unless C is known).
    pub fn check_images(&mut self, policy: BadImagePolicy) -> Result<(), SessionErrors> {
        let mut errs = SessionErrors::default();
        use rayon::prelude::*;
        // Decoding dominates: one image per core.
        let bad: Vec<SkippedImage> = self
            .file
            .images
            .par_iter()
            .enumerate()
            .filter_map(|(index, im)| {
                image_problem(
                    &self.path(&im.file),
                    self.linearization(index),
                    self.raw_mode,
                )
                .map(|cause| SkippedImage {
                    index,
                    file: im.file.clone(),
                    role: im.role,
                    cause,
                })
            })
            .collect();
        if bad.is_empty() {
            return Ok(());
        }
        if policy == BadImagePolicy::Fail {
            for b in &bad {
                errs.push(self.path(&b.file), "", b.cause.clone());
            }
            return Err(errs);
        }
        let drop: std::collections::HashSet<usize> = bad.iter().map(|b| b.index).collect();
        let kept = std::mem::take(&mut self.file.images)
            .into_iter()
            .enumerate()
            .filter(|(i, _)| !drop.contains(i))
            .map(|(_, im)| im)
            .collect();
        self.file.images = kept;
        self.skipped_images = bad;
        let file = self.dir.join(SESSION_FILE);
        let count = |role| self.file.images.iter().filter(|i| i.role == role).count();
        if count(ImageRole::Measurement) == 0 {
            errs.push(
                &file,
                "images",
                "no usable measurement image is left after skipping the bad ones",
            );
        }
        if self.file.known.calibration_c.is_none() && count(ImageRole::ReferenceStandard) == 0 {
            errs.push(
                &file,
                "images",
                "no usable reference-standard image is left after skipping the bad ones, and known.calibration_c is not given",
            );
        }
        errs.into_result(())
    }

    /// The scan file and the factor to metres, when the geometry is a scan.
    pub fn scan(&self) -> Option<(PathBuf, f64)> {
        match &self.file.geometry {
            GeometrySpec::Scan { file, units, .. } => Some((self.path(file), units.to_m())),
            _ => None,
        }
    }

    /// The path of the ground truth (it may not exist): [`Session::truth_file`] when set, else
    /// the session's `truth.json`.
    pub fn truth_path(&self) -> PathBuf {
        self.truth_file
            .clone()
            .unwrap_or_else(|| self.dir.join(TRUTH_FILE))
    }

    /// Loads the ground truth if present. A truth read from elsewhere
    /// ([`Session::truth_file`]) is keyed to this session's images by exposure index
    /// ([`Truth::keyed_to`]); it must then exist.
    pub fn load_truth(&self) -> Option<Result<Truth, FileError>> {
        let p = self.truth_path();
        match &self.truth_file {
            Some(_) => Some(
                Truth::load(&p)
                    .and_then(|t| t.keyed_to(&self.file.images, &p))
                    .map(|t| self.truth_in_image_units(t)),
            ),
            None => p
                .exists()
                .then(|| Truth::load(&p).map(|t| self.truth_in_image_units(t))),
        }
    }

    /// A truth stated for the superpixel image of a raw session scored against the photosite
    /// image, or the other way round (a truth's camera is the image it was stated for):
    /// its camera and target corners converted to the image as loaded. A truth of any other
    /// size is left as it is.
    fn truth_in_image_units(&self, mut t: Truth) -> Truth {
        let loaded = self.file.camera.size_px();
        let stated = (t.camera.width_px, t.camera.height_px);
        let to_photosite = stated.0.saturating_mul(2) == loaded.0
            && stated.1.saturating_mul(2) == loaded.1
            && self.raw_mode == RawMode::Photosite;
        let to_superpixel = stated.0 / 2 == loaded.0
            && stated.1 / 2 == loaded.1
            && stated.0 > loaded.0
            && self.all_raw();
        let map: fn(f64) -> f64 = if to_photosite {
            skinbrdf_raw::superpixel_to_sensor_centre
        } else if to_superpixel {
            skinbrdf_raw::sensor_to_superpixel_centre
        } else {
            return t;
        };
        t.camera = if to_photosite {
            skinbrdf_raw::superpixel_camera_to_sensor(&t.camera)
        } else {
            skinbrdf_raw::sensor_camera_to_superpixel(&t.camera)
        };
        for im in &mut t.images {
            for tt in &mut im.targets {
                for c in tt.corners_px.iter_mut().chain([&mut tt.centre_px]) {
                    *c = glam::DVec2::new(map(c.x), map(c.y));
                }
            }
        }
        t
    }
}

/// A raw session's camera as `session.toml` states it (superpixel units), converted to the
/// photosite image (see [`Session::set_raw_mode`]).
fn photosite_camera(camera: &CameraSpec) -> CameraSpec {
    match camera {
        CameraSpec::Calibrated(m) => {
            CameraSpec::Calibrated(skinbrdf_raw::superpixel_camera_to_sensor(m))
        }
        CameraSpec::ToBeCalibrated {
            width_px,
            height_px,
            focal_guess_px,
        } => CameraSpec::ToBeCalibrated {
            width_px: width_px.saturating_mul(2),
            height_px: height_px.saturating_mul(2),
            focal_guess_px: focal_guess_px.map(skinbrdf_raw::superpixel_to_sensor_focal),
        },
    }
}

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

pub(crate) fn check_pose(p: &Pose, file: &Path, field: &str, errs: &mut SessionErrors) {
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

/// Checks that a photograph named in `session.toml` exists. Unlike the session's other files,
/// a photograph may live outside the session directory (`skinbrdf ingest` references the
/// camera card's files in place unless asked to copy them): a relative path is taken from the
/// session directory, an absolute one as it is.
fn check_image_file(
    dir: &Path,
    rel: &str,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> bool {
    if rel.is_empty() {
        errs.push(file, field, "empty file name");
        return false;
    }
    if !dir.join(rel).is_file() {
        errs.push(file, field, format!("file `{rel}` does not exist"));
        return false;
    }
    true
}

fn check_relative_file(
    dir: &Path,
    rel: &str,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> bool {
    if rel.is_empty() {
        errs.push(file, field, "empty file name");
        return false;
    }
    // Inside the session directory (no absolute path, `..` or link out), a regular file.
    match skinbrdf_core::untrusted::confine(dir, rel) {
        Ok(_) => true,
        Err(skinbrdf_core::untrusted::ConfineError::Missing { .. }) => {
            errs.push(file, field, format!("file `{rel}` does not exist"));
            false
        }
        Err(e) => {
            errs.push(
                file,
                field,
                format!("must be a regular file inside the session directory: {e}"),
            );
            false
        }
    }
}

/// A target's id (a tag36h11 code) and printed size (positive); false when the size is not
/// (nothing geometric can be checked then).
pub(crate) fn check_id_and_size(
    id: u32,
    size_m: f64,
    file: &Path,
    field: &str,
    errs: &mut SessionErrors,
) -> bool {
    if id >= TAG36H11_CODES {
        errs.push(
            file,
            format!("{field}.id"),
            format!("{id} is not a tag36h11 id (0..{TAG36H11_CODES})"),
        );
    }
    if !positive(size_m) {
        errs.push(
            file,
            format!("{field}.size_m"),
            format!("must be positive, got {size_m}"),
        );
        return false;
    }
    true
}

/// Checks an analytic shape (sphere, cylinder): finite centre and axis, positive sizes. A scan
/// is checked where its file is resolved.
pub(crate) fn check_shape(g: &GeometrySpec, file: &Path, errs: &mut SessionErrors) {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    match g {
        GeometrySpec::Scan { .. } => {}
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
}

/// A placed target: id, size, finite corners forming a square of its size (edges within
/// [`TARGET_SIZE_REL_TOL`]), coplanar, its centre at their mean.
pub(crate) fn check_target(t: &Target, file: &Path, field: &str, errs: &mut SessionErrors) {
    if !check_id_and_size(t.id, t.size_m, file, field, errs) {
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
fn validate(
    dir: &Path,
    s: &SessionFile,
    stated: Stated,
    errs: &mut SessionErrors,
) -> Option<CaptureRecord> {
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
        let bytes = match skinbrdf_core::untrusted::read_bounded(
            &path,
            skinbrdf_core::untrusted::CAPTURE_RECORD,
        ) {
            Ok(b) => b,
            Err(e) => {
                errs.push(&path, "", e.reason());
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
    let mut seen_canonical: HashMap<PathBuf, usize> = HashMap::new();
    let mut existing: Vec<usize> = Vec::new();
    for (i, im) in s.images.iter().enumerate() {
        let field = format!("images[{i}]");
        if let Some(prev) = seen.insert(im.file.as_str(), i) {
            errs.push(
                file,
                format!("{field}.file"),
                format!("`{}` is also images[{prev}]", im.file),
            );
        } else if check_image_file(dir, &im.file, file, &format!("{field}.file"), errs) {
            existing.push(i);
            let path = dir.join(&im.file);
            let same_file = std::fs::canonicalize(&path)
                .ok()
                .and_then(|c| seen_canonical.insert(c, i));
            if let Some(prev) = same_file {
                errs.push(
                    file,
                    format!("{field}.file"),
                    format!(
                        "`{}` is the same file as images[{prev}] (`{}`)",
                        im.file, s.images[prev].file
                    ),
                );
            }
            match crate::linear::read_header(&path) {
                Ok(hd) if (hd.width, hd.height) != (w, h) => errs.push(
                    file,
                    format!("{field}.file"),
                    format!(
                        "`{}` is {}x{} px but the camera is {w}x{h} px",
                        im.file, hd.width, hd.height
                    ),
                ),
                Ok(hd) if matches!(hd.format, StoredFormat::Raw { .. }) => {
                    // No session default applies to a raw file; its own table may override
                    // the levels.
                    if let Some(Err((f, p))) = im.linearization.as_ref().map(raw_options) {
                        errs.push(
                            file,
                            format!("{field}.linearization.{f}"),
                            format!("`{}` (camera raw): {p}", im.file),
                        );
                    }
                }
                Ok(hd) => {
                    let (lin, lin_field) = match &im.linearization {
                        Some(l) => (l, format!("{field}.linearization")),
                        None => (&s.linearization, "linearization".to_string()),
                    };
                    for (f, p) in lin.problems_for(hd.format) {
                        errs.push(
                            file,
                            format!("{lin_field}.{f}"),
                            format!("`{}` ({}): {p}", im.file, hd.format.describe()),
                        );
                    }
                }
                Err(e) => errs.push(
                    file,
                    format!("{field}.file"),
                    format!(
                        "`{}` is not a readable image: {}",
                        im.file,
                        skinbrdf_core::error_text(&e)
                    ),
                ),
            }
        }
        if let Some(l) = &im.linearization {
            for (f, p) in l.problems() {
                errs.push(file, format!("{field}.linearization.{f}"), p);
            }
        }
        if let Some(k) = im.exposure_scale {
            if !(k.is_finite() && k > 0.0) {
                errs.push(
                    file,
                    format!("{field}.exposure_scale"),
                    format!("must be positive and finite, got {k}"),
                );
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
            (Some(x), _) if !im.role.fired_by_controller() => errs.push(
                file,
                format!("{field}.exposure_index"),
                format!(
                    "is {x}, but a survey image is taken by hand, never fired by the \
                     controller: it has no exposure in the capture record"
                ),
            ),
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
                    format!(
                        "is {} but exposure {x} was shot as {}",
                        im.role.name(),
                        e.role.name()
                    ),
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
    report_identical_contents(dir, s, &existing, file, errs);
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
    for (i, t) in s.targets.unplaced.iter().enumerate() {
        let field = format!("targets.unplaced[{i}]");
        check_id_and_size(t.id, t.size_m, file, &field, errs);
        if let Some(corners_m) = t.sheet_corners_m {
            let as_target = Target {
                id: t.id,
                size_m: t.size_m,
                corners_m,
                centre_m: None,
            };
            check_target(&as_target, file, &format!("{field}.sheet"), errs);
            if t.sheet.is_none() {
                errs.push(
                    file,
                    format!("{field}.sheet_corners_m"),
                    "corners in a sheet's frame need the sheet's name (`sheet`)",
                );
            }
        }
        if let Some(prev) = ids.insert(t.id, field.clone()) {
            errs.push(
                file,
                format!("{field}.id"),
                format!("id {} is also used by {prev}", t.id),
            );
        }
    }

    // Flash and standard.
    if stated.flash && !positive(s.flash.diameter_m) {
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
                format!(
                    "must be positive, got {} x {} m",
                    st.size_m[0], st.size_m[1]
                ),
            );
        }
    }

    if let Some(points) = s.registration.as_ref().and_then(|r| r.points.as_ref()) {
        check_relative_file(dir, points, file, "registration.points", errs);
    }
    // Geometry and region of interest.
    match &s.geometry {
        GeometrySpec::Scan {
            file: scan,
            accept_repair_loss,
            ..
        } => {
            if let Some(f) = accept_repair_loss {
                if !(0.0..=1.0).contains(f) {
                    errs.push(
                        file,
                        "geometry.accept_repair_loss",
                        format!("{f}: a fraction of the triangles, in [0, 1]"),
                    );
                }
            }
            if check_relative_file(dir, scan, file, "geometry.file", errs) {
                let ext = Path::new(scan)
                    .extension()
                    .map(|e| e.to_string_lossy().to_ascii_lowercase())
                    .unwrap_or_default();
                if !matches!(ext.as_str(), "ply" | "obj" | "glb" | "gltf") {
                    errs.push(
                        file,
                        "geometry.file",
                        format!("`{scan}`: scans must be .ply, .obj, .glb or .gltf"),
                    );
                }
            }
        }
        shape => check_shape(shape, file, errs),
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
                format!(
                    "must be positive and finite, got [{}, {}, {}]",
                    c[0], c[1], c[2]
                ),
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
    let needs = SectionNeeds::of(&s.images, k, Some(&s.camera));
    // Unplaced reference and headdress targets are the placement survey's to place; it needs
    // the world's origin (a placed reference target). Flash and standard targets are placed by
    // their printed layouts: unplaced ones are an error where a stage needs them.
    let mut unplaced_needed = |group: TargetGroup, why: &Option<String>| -> bool {
        let ids = s.targets.unplaced_ids(group);
        if ids.is_empty() || why.is_none() {
            return false;
        }
        let problem = match group {
            TargetGroup::Reference if s.targets.reference.is_empty() => Some(unplaced_problem(
                group,
                &ids,
                "no reference target has a placement to fix the world's origin: the rig must \
                 state the corners of at least one (or a reference sheet's placement)",
            )),
            TargetGroup::Reference | TargetGroup::Headdress => None,
            TargetGroup::Flash | TargetGroup::Standard => why.as_deref().map(|why| {
                unplaced_problem(
                    group,
                    &ids,
                    &format!(
                        "{why}; the survey places reference and headdress targets only, flash \
                         and standard targets are placed by their printed layouts"
                    ),
                )
            }),
        };
        if let Some(p) = problem {
            errs.push(file, "targets.unplaced", p);
        }
        true
    };
    let reference_unplaced = unplaced_needed(TargetGroup::Reference, &needs.reference_targets);
    let headdress_unplaced = unplaced_needed(TargetGroup::Headdress, &needs.headdress_targets);
    let flash_unplaced = unplaced_needed(TargetGroup::Flash, &needs.flash_targets);
    let standard_unplaced = unplaced_needed(TargetGroup::Standard, &needs.standard);
    let _ = standard_unplaced;
    if stated.targets {
        if let (Some(why), true, false) = (
            &needs.reference_targets,
            s.targets.reference.is_empty(),
            reference_unplaced,
        ) {
            errs.push(file, "targets.reference", format!("empty, but {why}"));
        }
        if let (Some(why), true, false) = (
            &needs.headdress_targets,
            s.targets.headdress.is_empty(),
            headdress_unplaced,
        ) {
            errs.push(file, "targets.headdress", format!("empty, but {why}"));
        }
    }
    if let (Some(why), true, true, false) = (
        &needs.flash_targets,
        stated.flash,
        s.flash.targets.is_empty(),
        flash_unplaced,
    ) {
        errs.push(file, "flash.targets", format!("empty, and {why}"));
    }
    if let Some(why) = &needs.standard {
        if s.standard.is_none() {
            errs.push(file, "standard", format!("missing, and {why}"));
        }
        if count(ImageRole::ReferenceStandard) == 0 {
            errs.push(
                file,
                "images",
                format!("no reference-standard image, and {why}"),
            );
        }
    }
    capture
}

/// The error of a group whose placements a planned stage needs but nobody measured.
fn unplaced_problem(group: TargetGroup, ids: &[u32], why: &str) -> String {
    let shown: Vec<String> = ids.iter().take(8).map(u32::to_string).collect();
    let more = if ids.len() > 8 { ", ..." } else { "" };
    format!(
        "{} {} target(s) have no placement in the {} frame (ids {}{more}), but {why}",
        ids.len(),
        group.name(),
        group.frame(),
        shown.join(", "),
    )
}

/// Reports images whose files have identical contents (the same photograph listed twice under
/// different names: a copy, or a hard link the canonical path does not reveal). Only files of
/// equal length are read and compared.
fn report_identical_contents(
    dir: &Path,
    s: &SessionFile,
    existing: &[usize],
    file: &Path,
    errs: &mut SessionErrors,
) {
    let mut by_len: HashMap<u64, Vec<usize>> = HashMap::new();
    for &i in existing {
        if let Ok(m) = std::fs::metadata(dir.join(&s.images[i].file)) {
            by_len.entry(m.len()).or_default().push(i);
        }
    }
    let mut groups: Vec<Vec<usize>> = by_len.into_values().filter(|g| g.len() > 1).collect();
    groups.sort();
    let path_of = |i: usize| dir.join(&s.images[i].file);
    for group in groups {
        // A digest per file, streamed (a session's raw files are tens of MB each, all of one
        // length); files are compared byte for byte only when their digests agree.
        let mut seen: Vec<(usize, u64)> = Vec::new();
        for i in group {
            let Some(digest) = stream_digest(&path_of(i)) else {
                continue;
            };
            let twin = seen
                .iter()
                .find(|(j, d)| *d == digest && same_contents(&path_of(*j), &path_of(i)));
            if let Some((prev, _)) = twin {
                errs.push(
                    file,
                    format!("images[{i}].file"),
                    format!(
                        "`{}` has the same contents as images[{prev}] (`{}`): the same photograph listed twice",
                        s.images[i].file, s.images[*prev].file
                    ),
                );
            } else {
                seen.push((i, digest));
            }
        }
    }
}

/// A 64-bit digest of a file's contents, read in chunks (`None` when unreadable).
fn stream_digest(path: &Path) -> Option<u64> {
    use std::hash::Hasher;
    use std::io::Read;
    let mut f = std::fs::File::open(path).ok()?;
    let mut h = std::collections::hash_map::DefaultHasher::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).ok()?;
        if n == 0 {
            return Some(h.finish());
        }
        h.write(&buf[..n]);
    }
}

/// Whether two files have the same bytes, compared in chunks.
fn same_contents(a: &Path, b: &Path) -> bool {
    let (Ok(mut fa), Ok(mut fb)) = (std::fs::File::open(a), std::fs::File::open(b)) else {
        return false;
    };
    let (mut ba, mut bb) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    loop {
        let (Ok(na), Ok(nb)) = (read_full(&mut fa, &mut ba), read_full(&mut fb, &mut bb)) else {
            return false;
        };
        if na != nb || ba[..na] != bb[..nb] {
            return false;
        }
        if na == 0 {
            return true;
        }
    }
}

/// Fills `buf` as far as the file allows; the number of bytes read.
fn read_full(f: &mut std::fs::File, buf: &mut [u8]) -> std::io::Result<usize> {
    use std::io::Read;
    let mut n = 0;
    while n < buf.len() {
        let k = f.read(&mut buf[n..])?;
        if k == 0 {
            break;
        }
        n += k;
    }
    Ok(n)
}

/// Which optional parts of a session its planned stages need, from the quantities it already
/// knows (the facts that plan `skinbrdf process`'s stages): `Some(reason)` = needed, `None` =
/// every stage that would use it is skipped.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SectionNeeds {
    /// `[[targets.reference]]`: camera calibration (unknown intrinsics) or camera poses (an
    /// image without `world_from_camera`).
    pub reference_targets: Option<String>,
    /// `[[targets.headdress]]`: head tracking (a measurement image without `world_from_head`,
    /// and the sample not stationary).
    pub headdress_targets: Option<String>,
    /// `[flash]` and its targets: flash triangulation (no known light position).
    pub flash_targets: Option<String>,
    /// `[standard]` and a reference-standard image: radiometric calibration (no known C).
    pub standard: Option<String>,
    /// `[linearization]`: an integer (PNG/TIFF/JPEG) image without its own linearization.
    pub linearization: Option<String>,
}

impl SectionNeeds {
    /// The needs of a session with these images, known quantities and camera (`None`: not
    /// known, e.g. because it did not parse).
    pub fn of(images: &[ImageEntry], known: &KnownQuantities, camera: Option<&CameraSpec>) -> Self {
        let no_cam: Vec<usize> = (0..images.len())
            .filter(|&i| images[i].world_from_camera.is_none())
            .collect();
        let reference_targets = if let Some(&first) = no_cam.first() {
            Some(format!(
                "{} image(s) have no known world_from_camera (first: images[{first}])",
                no_cam.len()
            ))
        } else if images.is_empty() {
            Some("no image has a known world_from_camera".to_string())
        } else if matches!(camera, Some(CameraSpec::ToBeCalibrated { .. })) {
            Some("the camera is to be calibrated (from the reference targets)".to_string())
        } else {
            None
        };
        let no_head = images
            .iter()
            .position(|i| i.role == ImageRole::Measurement && i.world_from_head.is_none());
        let headdress_targets = match (no_head, known.stationary_sample) {
            (_, true) => None,
            (Some(i), false) => Some(format!(
                "images[{i}] has no known world_from_head and the sample is not stationary"
            )),
            (None, false) if images.is_empty() => {
                Some("no image has a known world_from_head and the sample is not stationary".into())
            }
            (None, false) => None,
        };
        let flash_targets = (known.light_position_m.is_none() && known.world_from_flash.is_none())
            .then(|| "neither known.light_position_m nor known.world_from_flash is given".into());
        let standard = known
            .calibration_c
            .is_none()
            .then(|| "known.calibration_c is not given".to_string());
        let linearization = images
            .iter()
            .enumerate()
            .find(|(_, im)| {
                im.linearization.is_none() && !is_float_file(&im.file) && !is_raw_file(&im.file)
            })
            .map(|(i, im)| {
                format!(
                    "images[{i}] (`{}`) is an integer image without a linearization of its own",
                    im.file
                )
            });
        Self {
            reference_targets,
            headdress_targets,
            flash_targets,
            standard,
            linearization,
        }
    }
}

/// True for a camera raw file, by its extension (a content that disagrees with the name is
/// refused when the image is read).
fn is_raw_file(name: &str) -> bool {
    Path::new(name)
        .extension()
        .and_then(|e| skinbrdf_raw::FileKind::from_extension(&e.to_string_lossy()))
        .is_some_and(|k| k.is_raw())
}

/// True for an OpenEXR file (float values), by its extension.
fn is_float_file(name: &str) -> bool {
    Path::new(name)
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

/// Why an image cannot be used (see [`Session::check_images`]), or `None` when it can.
fn image_problem(path: &Path, lin: &Linearization, raw_mode: RawMode) -> Option<String> {
    let img = match load_linear_image(path, lin, raw_mode) {
        Ok(img) => img,
        Err(FileError::Image { source, .. }) => {
            return Some(format!("cannot be decoded: {source}"))
        }
        Err(FileError::Io { source, .. }) => return Some(format!("cannot be read: {source}")),
        Err(FileError::Invalid { field, problem, .. }) => {
            return Some(format!("`{field}`: {problem}"))
        }
        Err(e) => return Some(skinbrdf_core::error_text(&e)),
    };
    let w = img.width as usize;
    // A photosite image's unmeasured channels are NaN by design: only measured ones count.
    let broken = |(i, p): (usize, &[f32; 3])| {
        let measured = img.measured_channels((i % w.max(1)) as u32, (i / w.max(1)) as u32);
        p.iter().zip(measured).any(|(c, m)| m && !c.is_finite())
    };
    let bad = img.rgb.iter().enumerate().position(broken);
    if let Some(first) = bad {
        let n = img.rgb.iter().enumerate().filter(|&p| broken(p)).count();
        return Some(format!(
            "{n} pixel(s) have non-finite values (inf or NaN; first at x = {}, y = {}): not a photograph's values",
            first % w.max(1),
            first / w.max(1)
        ));
    }
    if img
        .rgb
        .iter()
        .all(|p| p.iter().all(|&c| c.is_nan() || c <= 0.0))
    {
        return Some(format!(
            "no stored value is above the black level ({}): the image is black or the linearization's levels do not fit it",
            lin.black_level
        ));
    }
    None
}
