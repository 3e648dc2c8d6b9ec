//! Loading and validating a session directory.
//!
//! [`Session::load`] parses `session.toml` section by section and item by item (so one bad
//! image entry does not hide the next), then checks every invariant and every cross-reference
//! (files exist, image sizes match the camera, target ids are unique across layouts, exposure
//! indices exist in `capture.json` with the same role, the stages that have no known quantity
//! to skip them have the targets and images they need). It returns all problems at once.
//! The parsing is in `parse`, the checks in `validate` (one function per section) and
//! `checks` (single values); this module puts them together.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::capture::{CaptureRecord, ImageRole};
use crate::decoded::DecodeCache;
use crate::error::{FileError, SessionErrors};
use crate::format::*;
use crate::linear::{
    load_linear_image, load_raw_mosaic, photosite_geometry_grey, raw_kind, LinearImage,
    Linearization, RawMode,
};
use crate::needs::is_raw_file;
use crate::parse::parse_session_toml;
use crate::truth::Truth;
use crate::validate::validate;

pub use crate::checks::{TAG36H11_CODES, TARGET_SIZE_REL_TOL};
pub use crate::needs::SectionNeeds;

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
    /// Where raw files decoded in this run are kept (see [`Session::keep_decoded`]).
    decoded: Decoded,
}

/// A session's [`DecodeCache`], shared by its clones; it is no part of what a session is, so
/// sessions compare equal whatever their caches.
#[derive(Debug, Clone, Default)]
struct Decoded(Option<Arc<DecodeCache>>);

impl PartialEq for Decoded {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// A single-channel image for geometry (see [`Session::load_geometry_grey`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GreyImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Values, row-major.
    pub data: Vec<f32>,
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
            decoded: Decoded::default(),
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
            decoded: Decoded::default(),
        }
    }

    /// Keeps every camera raw file this session (and its clones) decode in `cache`, so that
    /// each is decoded once: by the input check ([`Session::check_images`]) or whichever load
    /// comes first, the others reading it back (see [`crate::decoded`]).
    pub fn keep_decoded(&mut self, cache: DecodeCache) {
        self.decoded = Decoded(Some(Arc::new(cache)));
    }

    /// The cache of decoded raw files, if the session keeps one.
    pub fn decode_cache(&self) -> Option<&DecodeCache> {
        self.decoded.0.as_deref()
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

    fn entry(&self, index: usize) -> Result<&ImageEntry, FileError> {
        self.file
            .images
            .get(index)
            .ok_or_else(|| FileError::Invalid {
                path: self.dir.join(SESSION_FILE),
                field: format!("images[{index}]"),
                problem: format!("no such image (the session has {})", self.file.images.len()),
            })
    }

    /// Loads image `index` as linear RGB (a camera raw file through the session's
    /// [`DecodeCache`] when it keeps one).
    pub fn load_image(&self, index: usize) -> Result<LinearImage, FileError> {
        let entry = self.entry(index)?;
        let path = self.path(&entry.file);
        let lin = self.linearization(index);
        let mut img = match self.decode_cache() {
            Some(cache) if raw_kind(&path)?.is_some() => {
                LinearImage::from_mosaic(&load_raw_mosaic(&path, lin, Some(cache))?, self.raw_mode)
            }
            _ => load_linear_image(&path, lin, self.raw_mode)?,
        };
        if let Some(k) = entry.exposure_scale {
            let k = k as f32;
            img.rgb
                .iter_mut()
                .for_each(|p| p.iter_mut().for_each(|c| *c *= k));
        }
        Ok(img)
    }

    /// Image `index` as a single-channel image for geometry (target detection): what
    /// [`LinearImage::geometry_grey`] gives for [`Session::load_image`], computed for a camera
    /// raw file loaded per photosite from its mosaic, without the RGB image.
    pub fn load_geometry_grey(&self, index: usize) -> Result<GreyImage, FileError> {
        let entry = self.entry(index)?;
        let path = self.path(&entry.file);
        if self.raw_mode == RawMode::Photosite && raw_kind(&path)?.is_some() {
            let m = load_raw_mosaic(&path, self.linearization(index), self.decode_cache())?;
            let scale = entry.exposure_scale.map(|k| k as f32);
            return Ok(GreyImage {
                width: m.width_px,
                height: m.height_px,
                data: photosite_geometry_grey(&m, scale),
            });
        }
        let img = self.load_image(index)?;
        Ok(GreyImage {
            width: img.width,
            height: img.height,
            data: img.geometry_grey(),
        })
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
                    self.decode_cache(),
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

/// Why an image cannot be used (see [`Session::check_images`]), or `None` when it can. A camera
/// raw file is decoded to its mosaic (through `cache`, which then keeps it for the run's later
/// loads) and, per photosite, checked from it without the RGB image.
fn image_problem(
    path: &Path,
    lin: &Linearization,
    raw_mode: RawMode,
    cache: Option<&DecodeCache>,
) -> Option<String> {
    let loaded = match raw_kind(path) {
        Ok(Some(_)) => load_raw_mosaic(path, lin, cache).map(|m| match raw_mode {
            RawMode::Photosite => Loaded::Photosites(m),
            RawMode::Superpixel => Loaded::Image(LinearImage::from_mosaic(&m, raw_mode)),
        }),
        Ok(None) => load_linear_image(path, lin, raw_mode).map(Loaded::Image),
        Err(e) => Err(e),
    };
    match loaded {
        Ok(Loaded::Image(img)) => values_problem(&img, lin),
        Ok(Loaded::Photosites(m)) => photosite_problem(&m, lin),
        Err(e) => Some(load_problem(e)),
    }
}

/// What the input check decoded.
enum Loaded {
    Image(LinearImage),
    Photosites(skinbrdf_raw::RawMosaic),
}

/// The input check's words for an image that cannot be loaded.
fn load_problem(e: FileError) -> String {
    match e {
        FileError::Image { source, .. } => format!("cannot be decoded: {source}"),
        FileError::Io { source, .. } => format!("cannot be read: {source}"),
        FileError::Invalid { field, problem, .. } => format!("`{field}`: {problem}"),
        e => skinbrdf_core::error_text(&e),
    }
}

/// The sentence for `n` non-finite pixels, the first at `(x, y)`.
fn non_finite_problem(n: usize, x: usize, y: usize) -> String {
    format!(
        "{n} pixel(s) have non-finite values (inf or NaN; first at x = {x}, y = {y}): not a photograph's values"
    )
}

/// The sentence for an image with no value above the black level.
fn all_black_problem(lin: &Linearization) -> String {
    format!(
        "no stored value is above the black level ({}): the image is black or the linearization's levels do not fit it",
        lin.black_level
    )
}

/// Why a loaded image's values are not a photograph's, or `None`.
fn values_problem(img: &LinearImage, lin: &Linearization) -> Option<String> {
    let w = img.width as usize;
    // A photosite image's unmeasured channels are NaN by design: only measured ones count.
    let broken = |(i, p): (usize, &[f32; 3])| {
        let measured = img.measured_channels((i % w.max(1)) as u32, (i / w.max(1)) as u32);
        p.iter().zip(measured).any(|(c, m)| m && !c.is_finite())
    };
    let bad = img.rgb.iter().enumerate().position(broken);
    if let Some(first) = bad {
        let n = img.rgb.iter().enumerate().filter(|&p| broken(p)).count();
        return Some(non_finite_problem(n, first % w.max(1), first / w.max(1)));
    }
    if img
        .rgb
        .iter()
        .all(|p| p.iter().all(|&c| c.is_nan() || c <= 0.0))
    {
        return Some(all_black_problem(lin));
    }
    None
}

/// [`values_problem`] of the photosite image of mosaic `m`, row by row from the mosaic.
fn photosite_problem(m: &skinbrdf_raw::RawMosaic, lin: &Linearization) -> Option<String> {
    let (w, h) = (m.width_px as usize, m.height_px as usize);
    let mut row = vec![0.0f32; w];
    let (mut bad, mut first, mut above) = (0usize, None, false);
    for y in 0..h {
        m.photosite_row(y, &mut row);
        for (x, v) in row.iter().enumerate() {
            if !v.is_finite() {
                bad += 1;
                first.get_or_insert((x, y));
            }
            above |= *v > 0.0;
        }
    }
    if let Some((x, y)) = first {
        return Some(non_finite_problem(bad, x, y));
    }
    (!above).then(|| all_black_problem(lin))
}
