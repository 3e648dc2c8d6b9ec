//! `skinbrdf ingest`: from the camera's card, the controller's record, the rig file and the
//! head scan to a session directory that `Session::load` accepts and `skinbrdf process` runs.
//!
//! # Steps
//!
//! 1. **Read the inputs**: `capture.json`, the rig file ([`skinbrdf_session::Rig`]), the scan
//!    (PLY, OBJ, binary glTF or `.gltf`, loaded once to check it; an OBJ's material and texture
//!    files and a `.gltf`'s external buffers and images come along, at the same relative
//!    paths),
//!    the camera calibration when one is given.
//! 2. **List the card**: every file under the card directory, by content
//!    ([`skinbrdf_raw::sniff`]): camera raw files, JPEG and TIFF are photographs; anything else
//!    (sidecars, thumbnails) is listed as skipped. A photograph whose name says another format
//!    than its content is an error naming the file ([`skinbrdf_raw::check_extension`]).
//! 3. **Read each photograph's metadata** ([`skinbrdf_raw::read_metadata`], in parallel).
//! 4. **Match files to exposures** by time ([`crate::matching`]): the camera clock's offset and
//!    drift, the residual per pair, test shots, missing files, other bodies, duplicates.
//! 5. **Check one camera**: a body, lens or focal-length change among the session's files is
//!    refused (the intrinsics would differ), as is a file from another body taken during the
//!    session (the body was swapped).
//! 6. **Check the exposure**: the method's `C` bundles exposure and gain, so every image must
//!    be exposed like the reference-standard image (exposure time, f-number, ISO). A
//!    difference is refused with the list of files and settings, or, with
//!    [`ExposurePolicy::Normalise`], the image's `V` is scaled by
//!    `(t ISO / N²)_standard / (t ISO / N²)_image` (`exposure_scale` in `session.toml`).
//! 7. **Decode every matched photograph once** (a truncated file is refused here, not half-way
//!    through `process`); the loaded size sets the camera's image size. Without a calibration
//!    the camera is to be calibrated, starting from the focal length the metadata give in the
//!    loaded image's pixels ([`crate::focal`]; `focal_guess_px`, and in the report with its
//!    source, or why there is none).
//! 8. **Write** the session into a temporary directory beside the output, load it with
//!    `Session::load`, and only then move it into place (an existing session is replaced only
//!    with `overwrite`, and kept until the new one is in place). On any error nothing is
//!    written.
//!
//! **Survey images** (`survey_dir`, `skinbrdf ingest --survey DIR`): shots taken by hand
//! before the subject sits (room light, no flash, not fired by the controller, so not in the
//! record) to strengthen the placement survey's geometry. Every photograph in the folder (the
//! card's content sniffing and metadata) becomes an image with role `survey` and no exposure
//! index. They must come from the session's camera body (a known serial other than the
//! session's is refused naming the file) with its lens and focal length (the intrinsics are
//! shared), and load at the session's image size; their exposure is not compared with the
//! flash images' (they serve the geometry only, never the radiometry). The session lists the
//! images in the order they were taken (camera time): the survey images taken before the
//! session's first file, then the session's, then any taken after; the placement survey reads
//! a body's views in that order.
//!
//! Images are referenced where they are (a path relative to the session directory) unless
//! `copy` is set (survey images then go to [`SURVEY_IMAGES_DIR`]: a survey file may share a
//! card file's name); they are never converted.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use skinbrdf_raw::{CaptureTime, ExposureMeta, FileKind, RawError};
use skinbrdf_session::capture::CaptureRecord;
use skinbrdf_session::rig::RigCamera;
use skinbrdf_session::{
    CameraSpec, GeometrySpec, ImageEntry, ImageRole, LengthUnit, Linearization, RegistrationFit,
    RegistrationSpec, Rig, Session, SessionErrors, SessionFile, SESSION_FILE,
    SESSION_FORMAT_VERSION,
};

use crate::focal::{focal_guess_px, stated_focal_guess, FocalGuess};
use crate::matching::{
    self, CameraShot, CameraTime, ExposureInput, ExtraReason, MatchError, MatchOptions, Matching,
};

/// What to do with images exposed unlike the reference-standard image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ExposurePolicy {
    /// Refuse the session, listing every file and its settings.
    #[default]
    Refuse,
    /// Scale each image's values to the reference-standard image's exposure.
    Normalise,
}

/// The ingest's inputs and choices.
#[derive(Debug, Clone)]
pub struct IngestConfig {
    /// The card (or a copy of it): searched recursively.
    pub card_dir: PathBuf,
    /// The controller's `capture.json`.
    pub capture: PathBuf,
    /// The rig file.
    pub rig: PathBuf,
    /// The head scan (PLY, OBJ, `.glb` or `.gltf`); `None` when the rig states the sample's
    /// ideal shape (a calibration sphere or cylinder).
    pub scan: Option<PathBuf>,
    /// The scan's length unit; `None`: from the PLY or OBJ header's comment (glTF: metres, by
    /// specification), else an error.
    pub scan_units: Option<LengthUnit>,
    /// Hand-picked target corners on the scan (a `[[points]]` file, see
    /// `skinbrdf_register::points`): the survey's headdress is registered to the scan by them
    /// instead of by the scan's texture (a scan without one).
    pub scan_points: Option<PathBuf>,
    /// The registration's fit: rigid, or a similarity.
    pub registration_fit: RegistrationFit,
    /// A camera calibration (a TOML file with a `[camera]` table as in `session.toml`).
    pub camera: Option<PathBuf>,
    /// The session directory to write.
    pub out_dir: PathBuf,
    /// Copy the photographs into `OUT/images/` instead of referencing them in place.
    pub copy: bool,
    /// Replace an existing session in `out_dir`.
    pub overwrite: bool,
    /// Exposure differences: refuse or normalise.
    pub exposure: ExposurePolicy,
    /// Matching tolerances.
    pub matching: MatchOptions,
    /// A folder of survey images (see the module docs), searched recursively.
    pub survey_dir: Option<PathBuf>,
    /// Where the raw decoder runs: in a child process per file under memory and time limits
    /// (the CLI's choice: a file that makes the decoder abort or hang fails only itself), or
    /// in this process (`None`).
    pub decoder: Option<skinbrdf_raw::Isolation>,
}

impl IngestConfig {
    /// A configuration with the defaults: reference in place, refuse exposure differences.
    pub fn new(
        card_dir: PathBuf,
        capture: PathBuf,
        rig: PathBuf,
        scan: impl Into<Option<PathBuf>>,
        out_dir: PathBuf,
    ) -> Self {
        Self {
            card_dir,
            capture,
            rig,
            scan: scan.into(),
            scan_units: None,
            scan_points: None,
            registration_fit: RegistrationFit::Rigid,
            camera: None,
            out_dir,
            copy: false,
            overwrite: false,
            exposure: ExposurePolicy::Refuse,
            matching: MatchOptions::default(),
            survey_dir: None,
            decoder: None,
        }
    }
}

/// One photograph's exposure settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ExposureSettings {
    /// Exposure time, seconds.
    pub exposure_time_s: f64,
    /// Aperture f-number.
    pub f_number: f64,
    /// ISO.
    pub iso: u32,
}

impl ExposureSettings {
    /// `t ISO / N²`: the factor by which the settings scale a pixel's value.
    pub fn factor(&self) -> f64 {
        self.exposure_time_s * f64::from(self.iso) / (self.f_number * self.f_number)
    }

    fn same_as(&self, other: &Self) -> bool {
        let close = |a: f64, b: f64| (a - b).abs() <= EXIF_RATIONAL_REL_TOL * a.abs().max(b.abs());
        close(self.exposure_time_s, other.exposure_time_s)
            && close(self.f_number, other.f_number)
            && self.iso == other.iso
    }
}

impl std::fmt::Display for ExposureSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let t = if self.exposure_time_s < 1.0 {
            format!("1/{:.0} s", 1.0 / self.exposure_time_s)
        } else {
            format!("{} s", self.exposure_time_s)
        };
        write!(f, "{t}, f/{}, ISO {}", self.f_number, self.iso)
    }
}

/// Relative tolerance between two EXIF rationals meant to be the same setting (cameras write
/// 1/125 as 1/125 or 8/1000; f-numbers as 110/10 or 11/1).
pub const EXIF_RATIONAL_REL_TOL: f64 = 1e-3;

/// One image of the written session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IngestedImage {
    /// The file as `session.toml` names it.
    pub file: String,
    /// The file on the card.
    pub card_file: PathBuf,
    /// The exposure in the capture record.
    pub exposure_index: u32,
    /// Its role.
    pub role: ImageRole,
    /// Its exposure settings, when the metadata has them.
    pub settings: Option<ExposureSettings>,
    /// The factor applied to its values (1 unless normalised).
    pub exposure_scale: f64,
    /// Its camera time minus the fitted clock's prediction, seconds.
    pub time_residual_s: f64,
}

/// One survey image of the written session (role `survey`, no exposure).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IngestedSurveyImage {
    /// The file as `session.toml` names it.
    pub file: String,
    /// The photograph in the survey folder.
    pub source_file: PathBuf,
    /// Its exposure settings, when the metadata has them (not compared with the session's).
    pub settings: Option<ExposureSettings>,
    /// Whether it was taken before the session's first file (by the camera's clock; one
    /// without a time counts as before).
    pub before_session: bool,
}

/// Where the camera's intrinsics come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "source")]
pub enum CameraSource {
    /// A calibration file (`--camera`).
    File {
        /// The file.
        path: PathBuf,
    },
    /// The rig file's `[camera]` calibration.
    Rig {
        /// The rig file.
        path: PathBuf,
    },
    /// None given: the session calibrates the camera from its reference targets.
    ToBeCalibrated,
}

/// What the ingest did (also written as `OUT/ingest.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IngestReport {
    /// The session directory.
    pub session_dir: PathBuf,
    /// The session's images, in exposure order.
    pub images: Vec<IngestedImage>,
    /// The survey images (`--survey`), in the order they were taken.
    #[serde(default)]
    pub survey_images: Vec<IngestedSurveyImage>,
    /// The matching: the camera clock fit, extra files, missing exposures.
    pub matching: Matching,
    /// Files on the card that are not photographs, with what they are.
    pub skipped_files: Vec<(String, String)>,
    /// What loading the scan repairs (non-finite vertices, degenerate or duplicate triangles,
    /// winding), when it repairs anything: `process` loads it the same way.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan_repair: Option<String>,
    /// Camera make and model, body serial, lens, focal length.
    pub camera_body: String,
    /// The lens and focal length.
    pub lens: String,
    /// Where the intrinsics come from.
    pub camera: CameraSource,
    /// What was chosen over what (a `--camera` file over the rig's `[camera]`), in words.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub camera_notes: Vec<String>,
    /// The loaded image size (superpixels for raw files).
    pub image_size_px: (u32, u32),
    /// Without a calibration file: the focal length written as the session's
    /// `focal_guess_px`, from the first matched photograph's metadata, with its source.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focal_guess: Option<FocalGuess>,
    /// Without a calibration file and without a guess: why the metadata give none (one reason
    /// per source); the calibration then starts from its own guess.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub focal_guess_refused: Vec<String>,
    /// What the rig states as known (the session's `[known]`), in words: each skips the stage
    /// that would estimate it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub known_from_rig: Vec<String>,
    /// Targets with a placement / without one (the survey fills those in).
    pub placed_targets: usize,
    /// Targets without a placement.
    pub unplaced_targets: usize,
    /// The reference settings every image was compared with, and the file they come from.
    pub reference_settings: Option<(String, ExposureSettings)>,
    /// The photographs were copied into the session.
    pub copied: bool,
    /// Seconds reading metadata, matching, decoding and writing.
    pub metadata_s: f64,
    /// Seconds decoding every matched photograph once.
    pub decode_s: f64,
    /// Total seconds.
    pub total_s: f64,
}

/// Why an ingest failed (nothing was written).
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    /// A file could not be read or written.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The capture record is not valid JSON of the format.
    #[error("{path}: not a capture record")]
    Capture {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: serde_json::Error,
    },
    /// The rig file has problems, or lacks what the session's stages need.
    #[error("{}: the rig file is not valid, or does not state what the session needs", path.display())]
    Rig {
        /// The rig file.
        path: PathBuf,
        /// Every problem, each naming the file and the key.
        source: SessionErrors,
    },
    /// A key of an input file is unusable.
    #[error("{}: `{key}`: {problem}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The key in it.
        key: String,
        /// What is wrong.
        problem: String,
    },
    /// An input is unusable.
    #[error("{path}: {problem}")]
    Input {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A photograph is unreadable, or misnamed, or of an unsupported layout.
    #[error(transparent)]
    Raw(#[from] RawError),
    /// The scan does not load.
    #[error("{path}: the scan does not load")]
    Scan {
        /// The scan.
        path: PathBuf,
        /// The mesh reader's error.
        source: skinbrdf_mesh::MeshError,
    },
    /// A file could not be read within its limits (not a regular file, or too large).
    #[error(transparent)]
    Read(#[from] skinbrdf_core::untrusted::ReadError),
    /// The files could not be matched to the exposures.
    #[error("matching the card's files to {capture}")]
    Match {
        /// The capture record.
        capture: PathBuf,
        /// Why.
        source: MatchError,
    },
    /// The camera changed within the session.
    #[error("the camera changed within the session ({what}); the intrinsics would differ:\n{}", .files.join("\n"))]
    CameraChanged {
        /// Body, lens or focal length.
        what: &'static str,
        /// Each file with its value.
        files: Vec<String>,
    },
    /// Images were exposed unlike the reference-standard image.
    #[error("{} image(s) are exposed unlike the reference image {reference} ({settings}); C bundles the exposure, so every image must match it (or ingest with exposure normalisation):\n{}", .files.len(), .files.join("\n"))]
    ExposureMismatch {
        /// The reference image.
        reference: String,
        /// Its settings.
        settings: ExposureSettings,
        /// Each differing file with its settings.
        files: Vec<String>,
    },
    /// The output directory holds a session.
    #[error(
        "{dir}: already holds a session (session.toml); choose another --out or pass --overwrite"
    )]
    OutputExists {
        /// The directory.
        dir: PathBuf,
    },
    /// A survey image was taken with another camera body than the session's.
    #[error("{}: a survey image from body {serial}, but the session's body is {expected}: survey images must come from the session's camera (its intrinsics)", file.display())]
    SurveyFromAnotherBody {
        /// The survey image.
        file: PathBuf,
        /// Its body serial.
        serial: String,
        /// The session's.
        expected: String,
    },
    /// A survey image is one of the session's own files.
    #[error("{}: given as a survey image, but it is the card's file of exposure {exposure_index}", file.display())]
    SurveyIsSessionFile {
        /// The file.
        file: PathBuf,
        /// The exposure it was matched to.
        exposure_index: u32,
    },
    /// Photographs that cannot be read (cut short, another format under a photograph's name,
    /// unreadable) and could be exposures of the session that have no file.
    #[error("{} photograph(s) on the card cannot be read and could be the session's missing exposure(s) {missing}:\n{}", .files.len(), .files.join("\n"))]
    UnreadablePhotographs {
        /// Each file with why it cannot be read.
        files: Vec<String>,
        /// The exposures without a file.
        missing: String,
    },
    /// The session written from the inputs does not load: each problem is named by the input
    /// file (and key) it comes from.
    #[error("the session written from these files does not load")]
    Session {
        /// Every problem.
        source: SessionErrors,
    },
}

/// A photograph on the card with its metadata.
struct CardPhoto {
    path: PathBuf,
    name: String,
    meta: ExposureMeta,
}

/// Runs the ingest (see the module docs).
pub fn ingest(cfg: &IngestConfig) -> Result<IngestReport, IngestError> {
    let t0 = std::time::Instant::now();
    // 1. Inputs.
    let record = read_capture(&cfg.capture)?;
    let rig_error = |source| IngestError::Rig {
        path: cfg.rig.clone(),
        source,
    };
    let rig = Rig::load(&cfg.rig).map_err(rig_error)?;
    rig.check_needs().map_err(rig_error)?;
    let parts = rig.session_parts();
    let known_from_rig = known_in_words(&parts.known);
    let mut scan_repair = None;
    let shape = match (&cfg.scan, &rig.file.geometry) {
        (Some(scan), None) => {
            let (units, files, repair) = check_scan(scan, cfg.scan_units)?;
            scan_repair = repair;
            Shape::Scan {
                path: scan.clone(),
                units,
                files,
            }
        }
        (None, Some(g)) => Shape::Ideal(g.clone()),
        (Some(_), Some(_)) => {
            return Err(IngestError::Input {
                path: cfg.rig.clone(),
                problem: "the rig states the sample's ideal shape ([geometry]) and a scan was \
                          given: give one of them"
                    .into(),
            })
        }
        (None, None) => {
            return Err(IngestError::Input {
                path: cfg.rig.clone(),
                problem: "no scan was given and the rig states no ideal shape ([geometry]): \
                          give the head scan"
                    .into(),
            })
        }
    };
    if let Some(p) = &cfg.scan_points {
        if cfg.scan.is_none() {
            return Err(IngestError::Input {
                path: p.clone(),
                problem: "registration points are corners on a scan, and no scan was given".into(),
            });
        }
        let points = skinbrdf_register::load_point_pairs(p).map_err(|e| IngestError::Input {
            path: p.clone(),
            problem: skinbrdf_core::error_text(&e),
        })?;
        check_points_on_headdress(p, &points, &parts)?;
    }
    let camera_file = cfg.camera.as_deref().map(read_camera).transpose()?;
    if cfg.out_dir.join("session.toml").exists() && !cfg.overwrite {
        return Err(IngestError::OutputExists {
            dir: cfg.out_dir.clone(),
        });
    }

    // 2-3. The card.
    let (photos, skipped_files, unreadable) = list_card(&cfg.card_dir, cfg.decoder.as_ref())?;
    let shots: Vec<CameraShot> = photos
        .iter()
        .map(|p| camera_shot(&p.name, &p.meta))
        .collect::<Result<_, _>>()?;

    // 4. Matching.
    let exposures = ExposureInput::from_exposures(&record.exposures);
    let m = matching::match_shots(&shots, &exposures, &cfg.matching).map_err(|source| {
        IngestError::Match {
            capture: cfg.capture.clone(),
            source,
        }
    })?;
    let by_name: HashMap<&str, &CardPhoto> = photos.iter().map(|p| (p.name.as_str(), p)).collect();
    let matched: Vec<(&matching::MatchedPair, &CardPhoto)> = m
        .pairs
        .iter()
        .filter_map(|pair| by_name.get(pair.file.as_str()).map(|p| (pair, *p)))
        .collect();

    check_roles(&cfg.capture, &matched)?;

    // A photograph that cannot be read fails the ingest if it could be a missing exposure.
    let (unreadable_errors, unreadable_skips) = sort_unreadable(unreadable, &m, &matched);
    if !unreadable_errors.is_empty() {
        return Err(IngestError::UnreadablePhotographs {
            missing: m
                .missing
                .iter()
                .map(u32::to_string)
                .collect::<Vec<_>>()
                .join(", "),
            files: unreadable_errors,
        });
    }
    let skipped_files: SkippedFiles = skipped_files.into_iter().chain(unreadable_skips).collect();

    // 5. One camera, the survey images' included.
    check_one_camera(&m, &matched, &shots)?;
    let (survey, survey_skipped) = match &cfg.survey_dir {
        Some(dir) => survey_photos(dir, &matched, cfg.decoder.as_ref())?,
        None => (Vec::new(), Vec::new()),
    };
    let mut skipped_files = skipped_files;
    skipped_files.extend(survey_skipped);

    // 6. Exposure.
    let reference = matched
        .iter()
        .find(|(pair, _)| pair.role == ImageRole::ReferenceStandard)
        .or_else(|| matched.first())
        .and_then(|(_, p)| settings_of(&p.meta).map(|s| (p.name.clone(), s)));
    let mut scales = vec![1.0; matched.len()];
    if let Some((ref_name, ref_settings)) = &reference {
        let differing: Vec<(usize, ExposureSettings)> = matched
            .iter()
            .enumerate()
            .filter_map(|(i, (_, p))| settings_of(&p.meta).map(|s| (i, s)))
            .filter(|(_, s)| !s.same_as(ref_settings))
            .collect();
        if !differing.is_empty() {
            match cfg.exposure {
                ExposurePolicy::Refuse => {
                    return Err(IngestError::ExposureMismatch {
                        reference: ref_name.clone(),
                        settings: *ref_settings,
                        files: differing
                            .iter()
                            .map(|(i, s)| format!("  {}: {s}", matched[*i].1.path.display()))
                            .collect(),
                    })
                }
                ExposurePolicy::Normalise => {
                    for (i, s) in differing {
                        scales[i] = ref_settings.factor() / s.factor();
                    }
                }
            }
        }
    }
    let metadata_s = t0.elapsed().as_secs_f64();

    // 7. Decode every matched photograph once.
    let t_decode = std::time::Instant::now();
    let sizes: Vec<(u32, u32)> = matched
        .par_iter()
        .map(|(_, p)| decoded_size(&p.path, cfg.decoder.as_ref()))
        .collect::<Result<_, _>>()?;
    let survey_sizes: Vec<(u32, u32)> = survey
        .par_iter()
        .map(|p| decoded_size(&p.path, cfg.decoder.as_ref()))
        .collect::<Result<_, _>>()?;
    let decode_s = t_decode.elapsed().as_secs_f64();
    let image_size_px = sizes.first().copied().unwrap_or((0, 0));
    let all_paths = matched
        .iter()
        .map(|(_, p)| &p.path)
        .chain(survey.iter().map(|p| &p.path));
    let all_sizes = sizes.iter().chain(&survey_sizes);
    if let Some((path, s)) = all_paths.zip(all_sizes).find(|(_, s)| **s != image_size_px) {
        return Err(IngestError::CameraChanged {
            what: "image size",
            files: vec![
                format!(
                    "  {}: {}x{}",
                    matched[0].1.path.display(),
                    image_size_px.0,
                    image_size_px.1
                ),
                format!("  {}: {}x{}", path.display(), s.0, s.1),
            ],
        });
    }

    // 8. The session, written beside the output and moved into place.
    let ChosenCamera {
        spec: camera,
        source: camera_source,
        focal,
        notes: camera_notes,
    } = choose_camera(
        camera_file,
        &rig,
        image_size_px,
        matched.first().map(|(_, p)| *p),
    )?;
    let (focal_guess, focal_guess_refused) = match focal {
        Ok(g) => (g, Vec::new()),
        Err(reasons) => (None, reasons),
    };
    let staging = staging_dir(&cfg.out_dir)?;
    let result = write_session(
        cfg, &staging, &record, &rig, parts, &matched, &scales, &survey, camera, &shape,
    );
    let (images, survey_images, sources) = match result {
        Ok(images) => images,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(e);
        }
    };
    let body = matched.first().map(|(_, p)| &p.meta);
    let mut report = IngestReport {
        session_dir: cfg.out_dir.clone(),
        images,
        survey_images,
        matching: m,
        skipped_files,
        scan_repair,
        camera_body: body
            .map(|b| {
                format!(
                    "{} {} (serial {})",
                    b.camera_make.as_deref().unwrap_or("?"),
                    b.camera_model.as_deref().unwrap_or("?"),
                    b.body_serial.as_deref().unwrap_or("?")
                )
            })
            .unwrap_or_default(),
        lens: body
            .map(|b| {
                format!(
                    "{} at {} mm",
                    b.lens_model.as_deref().unwrap_or("?"),
                    b.focal_length_mm.map_or("?".into(), |f| format!("{f:.1}"))
                )
            })
            .unwrap_or_default(),
        camera: camera_source,
        camera_notes,
        known_from_rig,
        image_size_px,
        focal_guess,
        focal_guess_refused,
        placed_targets: 0,
        unplaced_targets: 0,
        reference_settings: reference,
        copied: cfg.copy,
        metadata_s,
        decode_s,
        total_s: 0.0,
    };
    // The written session must load; a rig without placements leaves exactly one kind of
    // problem, the unplaced targets a stage needs, which the placement survey resolves.
    let owners = Owners {
        cfg,
        staging: &staging,
        camera: &report.camera,
        rig_camera: rig.file.camera.is_some(),
        images: &sources,
    };
    if let Err(source) = Session::load(&staging) {
        if !source
            .problems
            .iter()
            .all(|p| p.field == "targets.unplaced")
        {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(IngestError::Session {
                source: owners.of(source),
            });
        }
    }
    let session_file = {
        let p = staging.join(SESSION_FILE);
        let text = std::fs::read_to_string(&p).map_err(io(&p))?;
        Session::parse_toml(&text, &p).map_err(|source| IngestError::Session {
            source: owners.of(source),
        })?
    };
    let t = &session_file.targets;
    report.placed_targets = t.reference.len()
        + t.headdress.len()
        + session_file.flash.targets.len()
        + session_file
            .standard
            .as_ref()
            .map_or(0, |s| s.targets.len());
    report.unplaced_targets = t.unplaced.len();
    report.total_s = t0.elapsed().as_secs_f64();
    let report_file = staging.join(INGEST_REPORT_FILE);
    let json = skinbrdf_core::json::to_vec_pretty(&report_file, &report).map_err(|e| {
        IngestError::Input {
            path: report_file.clone(),
            problem: format!("cannot serialise the report: {}", e.problem()),
        }
    })?;
    write_file(&staging.join(INGEST_REPORT_FILE), &json)?;
    move_into_place(&staging, &cfg.out_dir)?;
    Ok(report)
}

/// The known quantities a rig states, in words.
fn known_in_words(k: &skinbrdf_session::KnownQuantities) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(p) = k.light_position_m {
        out.push(format!(
            "the light position ([flash] light_position_m, [{:.4}, {:.4}, {:.4}] m): no flash \
             triangulation",
            p.x, p.y, p.z
        ));
    }
    if k.world_from_flash.is_some() {
        out.push("the flash's pose ([flash] world_from_flash): no flash triangulation".into());
    }
    if k.world_from_standard.is_some() {
        out.push(
            "the standard's pose ([standard] world_from_standard): not located from its targets"
                .into(),
        );
    }
    out
}

/// The camera the session states, where it comes from, the focal length a calibration starts
/// from (or why the files give none), and what was chosen over what.
struct ChosenCamera {
    spec: CameraSpec,
    source: CameraSource,
    focal: Result<Option<FocalGuess>, Vec<String>>,
    notes: Vec<String>,
}

/// The session's camera: a `--camera` file, else the rig's `[camera]`, else one to be
/// calibrated from the focal length the first photograph's metadata give. A stated image
/// size must be the photographs' as loaded.
fn choose_camera(
    camera_file: Option<(PathBuf, CameraSpec)>,
    rig: &Rig,
    image_size_px: (u32, u32),
    first: Option<&CardPhoto>,
) -> Result<ChosenCamera, IngestError> {
    let raw = first.is_some_and(|p| sniff_raw(&p.path));
    let size_problem = |stated: (u32, u32)| {
        (stated != image_size_px).then(|| {
            format!(
                "the camera is stated for {}x{} images, the photographs load as {}x{}{}",
                stated.0,
                stated.1,
                image_size_px.0,
                image_size_px.1,
                if raw {
                    " (raw files load as 2x2 superpixels: half the sensor's size; see \
                     docs/ingest.md)"
                } else {
                    ""
                }
            )
        })
    };
    // A camera to be calibrated starts where the lens is (the files share one lens and focal
    // length: checked before).
    let files_guess = || match first {
        Some(photo) => {
            // The pixels the focal-plane resolution counts: a raw file's photosites, two per
            // superpixel across and down; another image's own pixels.
            let per = if raw { 2 } else { 1 };
            let sensor = (
                image_size_px.0.saturating_mul(per),
                image_size_px.1.saturating_mul(per),
            );
            focal_guess_px(&photo.meta, image_size_px, sensor).map_err(|e| e.reasons)
        }
        None => Err(vec!["no matched photograph".to_string()]),
    };
    let to_be_calibrated = |guess: Result<FocalGuess, Vec<String>>, notes| ChosenCamera {
        spec: CameraSpec::ToBeCalibrated {
            width_px: image_size_px.0,
            height_px: image_size_px.1,
            focal_guess_px: guess.as_ref().ok().map(|g| g.focal_px),
        },
        source: CameraSource::ToBeCalibrated,
        focal: guess.map(Some),
        notes,
    };
    let rig_camera = rig.file.camera;
    match (camera_file, rig_camera) {
        (Some((path, spec)), rc) => {
            if let Some(problem) = size_problem(spec.size_px()) {
                return Err(IngestError::Input { path, problem });
            }
            let notes = rc
                .map(|c| {
                    format!(
                        "--camera {} is used; the rig's [camera] ({c}) is not",
                        path.display()
                    )
                })
                .into_iter()
                .collect();
            Ok(ChosenCamera {
                spec,
                source: CameraSource::File { path },
                focal: Ok(None),
                notes,
            })
        }
        (None, Some(c)) => {
            if let Some(problem) = c.size_px().and_then(size_problem) {
                return Err(IngestError::Invalid {
                    path: rig.path.clone(),
                    key: "camera.width_px".into(),
                    problem,
                });
            }
            match c {
                RigCamera::Calibrated(m) => Ok(ChosenCamera {
                    spec: CameraSpec::Calibrated(m),
                    source: CameraSource::Rig {
                        path: rig.path.clone(),
                    },
                    focal: Ok(None),
                    notes: Vec::new(),
                }),
                RigCamera::ToBeCalibrated {
                    focal_guess_px: Some(f),
                    ..
                } => {
                    let files = files_guess().ok();
                    let guess = stated_focal_guess(f, image_size_px.0, files.as_ref());
                    Ok(to_be_calibrated(Ok(guess), Vec::new()))
                }
                RigCamera::ToBeCalibrated { .. } => Ok(to_be_calibrated(files_guess(), Vec::new())),
            }
        }
        (None, None) => Ok(to_be_calibrated(files_guess(), Vec::new())),
    }
}

/// The matched photographs must include the measurement and the reference standard (the
/// radiometric calibration): a refusal names the capture record.
fn check_roles(
    capture: &Path,
    matched: &[(&matching::MatchedPair, &CardPhoto)],
) -> Result<(), IngestError> {
    let needed = [
        (ImageRole::Measurement, "the measurement needs them"),
        (
            ImageRole::ReferenceStandard,
            "the radiometric calibration (C) needs one",
        ),
    ];
    for (role, why) in needed {
        if !matched.iter().any(|(pair, _)| pair.role == role) {
            return Err(IngestError::Invalid {
                path: capture.to_path_buf(),
                key: "exposures".into(),
                problem: format!(
                    "no exposure of role {} has a file on the card ({why})",
                    role.name()
                ),
            });
        }
    }
    Ok(())
}

/// Who owns what ingest writes into the session: a problem of the written session is the
/// problem of the user's file (and key) it was written from, never of the staging directory.
struct Owners<'a> {
    cfg: &'a IngestConfig,
    staging: &'a Path,
    camera: &'a CameraSource,
    /// The rig states the camera (a camera to be calibrated from its focal length).
    rig_camera: bool,
    /// Each image entry's source photograph, in the session's order.
    images: &'a [PathBuf],
}

impl Owners<'_> {
    /// The problems, each moved to the input file and key its section was written from.
    fn of(&self, errs: SessionErrors) -> SessionErrors {
        let mut out = SessionErrors::default();
        for p in errs.problems {
            let (file, field) = self.owner(&p.file, &p.field);
            out.push(file, field, p.problem);
        }
        out
    }

    fn owner(&self, file: &Path, field: &str) -> (PathBuf, String) {
        let cfg = self.cfg;
        if file != self.staging.join(SESSION_FILE) {
            // A file ingest wrote beside session.toml (capture.json), or an image.
            return match file.strip_prefix(self.staging) {
                Ok(rel) if rel == Path::new("capture.json") => (cfg.capture.clone(), field.into()),
                Ok(rel) => (cfg.out_dir.join(rel), field.into()),
                Err(_) => (file.to_path_buf(), field.into()),
            };
        }
        let head = field.split(['.', '[']).next().unwrap_or_default();
        let rig = |key: &str| (cfg.rig.clone(), key.to_string());
        match head {
            "images" if field == "images" => (cfg.capture.clone(), "exposures".into()),
            "images" => {
                let index = field
                    .strip_prefix("images[")
                    .and_then(|r| r.split(']').next())
                    .and_then(|i| i.parse::<usize>().ok());
                match index.and_then(|i| self.images.get(i)) {
                    Some(photo) => (photo.clone(), String::new()),
                    None => (cfg.out_dir.join(SESSION_FILE), field.into()),
                }
            }
            "capture" => (cfg.capture.clone(), String::new()),
            "camera" => match self.camera {
                CameraSource::File { path } => (path.clone(), field.into()),
                CameraSource::Rig { path } => (path.clone(), field.into()),
                CameraSource::ToBeCalibrated if self.rig_camera => rig(field),
                CameraSource::ToBeCalibrated => (cfg.card_dir.clone(), String::new()),
            },
            "targets" => rig("targets"),
            "known" => rig(match field {
                "known.light_position_m" => "flash.light_position_m",
                "known.world_from_flash" => "flash.world_from_flash",
                "known.world_from_standard" => "standard.world_from_standard",
                _ => field,
            }),
            // The rig lists every group's targets in [[targets]] and [[sheets]].
            "flash" | "standard" if field.contains(".targets") => rig("targets"),
            "flash" | "standard" | "roi" => rig(field),
            "geometry" => match &cfg.scan {
                Some(scan) => (scan.clone(), String::new()),
                None => rig(field),
            },
            "registration" => match &cfg.scan_points {
                Some(points) => (points.clone(), String::new()),
                None => (cfg.out_dir.join(SESSION_FILE), field.into()),
            },
            _ => (cfg.out_dir.join(SESSION_FILE), field.into()),
        }
    }
}

/// The ingest's report inside the session directory.
pub const INGEST_REPORT_FILE: &str = "ingest.json";

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> IngestError + '_ {
    move |source| IngestError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), IngestError> {
    skinbrdf_core::fsio::write_atomic(path, bytes).map_err(|e| IngestError::Io {
        path: e.path,
        source: e.source,
    })
}

/// The most exposures a capture record may hold (a session has about 30; a plan of thousands
/// is a damaged or hostile file, and matching costs grow with the count).
pub const MAX_EXPOSURES: usize = 10_000;

/// The largest camera clock drift a capture record may state, parts per million (quartz
/// oscillators drift tens of ppm; more is not a clock).
pub const MAX_CLOCK_DRIFT_PPM: f64 = 1000.0;

/// Every key path of a JSON `input` that `round_trip` (the parsed value serialised again)
/// lacks: the keys the format does not have.
fn json_unknown_keys(
    input: &serde_json::Value,
    round_trip: &serde_json::Value,
    path: &str,
    out: &mut Vec<String>,
) {
    use serde_json::Value;
    let join = |k: &str| {
        if path.is_empty() {
            k.to_string()
        } else {
            format!("{path}.{k}")
        }
    };
    match (input, round_trip) {
        (Value::Object(a), Value::Object(b)) => {
            for (k, v) in a {
                match b.get(k) {
                    None => out.push(join(k)),
                    Some(w) => json_unknown_keys(v, w, &join(k), out),
                }
            }
        }
        (Value::Array(a), Value::Array(b)) if a.len() == b.len() => {
            for (i, (v, w)) in a.iter().zip(b).enumerate() {
                json_unknown_keys(v, w, &format!("{path}[{i}]"), out);
            }
        }
        _ => {}
    }
}

/// Impossible values of a capture record: the first one found, as `(key, problem)`.
fn capture_value_problem(rec: &CaptureRecord) -> Option<(String, String)> {
    let c = &rec.clock;
    if !(c.drift_ppm.is_finite() && c.drift_ppm.abs() <= MAX_CLOCK_DRIFT_PPM) {
        return Some((
            "clock.drift_ppm".into(),
            format!(
                "{} is not a clock's drift (at most {MAX_CLOCK_DRIFT_PPM} ppm either way)",
                c.drift_ppm
            ),
        ));
    }
    if !c.host_ref_us.is_finite() {
        return Some(("clock.host_ref_us".into(), "is not finite".into()));
    }
    if !(c.residual_rms_us.is_finite() && c.residual_rms_us >= 0.0) {
        return Some((
            "clock.residual_rms_us".into(),
            format!("{} is not a residual", c.residual_rms_us),
        ));
    }
    if rec.exposures.len() > MAX_EXPOSURES {
        return Some((
            "exposures".into(),
            format!(
                "{} exposures, more than the {MAX_EXPOSURES} a record may hold",
                rec.exposures.len()
            ),
        ));
    }
    rec.exposures
        .iter()
        .enumerate()
        .find(|(_, e)| !e.host_time_us.is_finite())
        .map(|(i, _)| {
            (
                format!("exposures[{i}].host_time_us"),
                "is not finite".into(),
            )
        })
}

/// Reads and checks a controller's capture record (`capture.json`) as `ingest` does: within
/// its read limit, no unknown key, values in range, a format version this build reads.
pub fn read_capture(path: &Path) -> Result<CaptureRecord, IngestError> {
    let bytes =
        skinbrdf_core::untrusted::read_bounded(path, skinbrdf_core::untrusted::CAPTURE_RECORD)?;
    let capture_err = |source| IngestError::Capture {
        path: path.to_path_buf(),
        source,
    };
    let value: serde_json::Value = serde_json::from_slice(&bytes).map_err(capture_err)?;
    let rec: CaptureRecord = serde_json::from_value(value.clone()).map_err(capture_err)?;
    let bad = |problem: String| IngestError::Input {
        path: path.to_path_buf(),
        problem,
    };
    let round_trip = serde_json::to_value(&rec).map_err(capture_err)?;
    let mut unknown = Vec::new();
    json_unknown_keys(&value, &round_trip, "", &mut unknown);
    if !unknown.is_empty() {
        return Err(bad(format!(
            "unknown key(s) {} (not in the capture record's format)",
            unknown.join(", ")
        )));
    }
    if let Some((key, problem)) = capture_value_problem(&rec) {
        return Err(bad(format!("`{key}`: {problem}")));
    }
    if rec.format_version != skinbrdf_session::capture::CAPTURE_FORMAT_VERSION {
        return Err(IngestError::Input {
            path: path.to_path_buf(),
            problem: format!(
                "format_version {} is not supported (this build reads {})",
                rec.format_version,
                skinbrdf_session::capture::CAPTURE_FORMAT_VERSION
            ),
        });
    }
    if rec.exposures.is_empty() {
        return Err(IngestError::Input {
            path: path.to_path_buf(),
            problem: "the record has no exposures".into(),
        });
    }
    Ok(rec)
}

/// A file that comes with the scan: where it is, and where it goes relative to the session
/// directory (beside the scan, so the scan's own references still resolve).
#[derive(Debug, Clone, PartialEq, Eq)]
struct ScanCompanion {
    source: PathBuf,
    relative: PathBuf,
}

/// Scan points name headdress targets of the rig (the targets on the scanned head): another
/// id is refused naming the entry.
fn check_points_on_headdress(
    path: &Path,
    points: &[skinbrdf_register::ScanPoint],
    parts: &skinbrdf_session::SessionParts,
) -> Result<(), IngestError> {
    let t = &parts.targets;
    let headdress: Vec<u32> = t
        .headdress
        .iter()
        .map(|t| t.id)
        .chain(
            t.unplaced
                .iter()
                .filter(|u| u.group == skinbrdf_session::TargetGroup::Headdress)
                .map(|u| u.id),
        )
        .collect();
    match points
        .iter()
        .enumerate()
        .find(|(_, p)| !headdress.contains(&p.target))
    {
        Some((i, p)) => Err(IngestError::Input {
            path: path.to_path_buf(),
            problem: format!(
                "`points[{i}].target`: {} is not a headdress target of the rig (its headdress \
                 targets: {})",
                p.target,
                headdress
                    .iter()
                    .map(u32::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }),
        None => Ok(()),
    }
}

/// The scan's unit and the files that come with it (an OBJ's material library and textures, a
/// glTF's external buffers and images).
fn check_scan(
    path: &Path,
    units: Option<LengthUnit>,
) -> Result<(LengthUnit, Vec<ScanCompanion>, Option<String>), IngestError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("ply" | "obj" | "glb" | "gltf")) {
        return Err(IngestError::Input {
            path: path.to_path_buf(),
            problem: "a scan must be a .ply, .obj, .glb or .gltf file".into(),
        });
    }
    let loaded = skinbrdf_mesh::load_mesh(path, &skinbrdf_mesh::LoadOptions::default()).map_err(
        |source| IngestError::Scan {
            path: path.to_path_buf(),
            source,
        },
    )?;
    let repair = (!loaded.report.is_clean()).then(|| loaded.report.summary());
    // The files that come along: each a regular file inside the scan's folder (an absolute
    // path, `..`, a link out or a device is refused naming the file, line and path).
    let companions = match ext.as_deref() {
        Some("glb" | "gltf") => skinbrdf_mesh::gltf_external_files(path),
        Some("obj") => skinbrdf_mesh::obj_companion_files(path),
        _ => Ok(Vec::new()),
    }
    .map_err(|source| IngestError::Scan {
        path: path.to_path_buf(),
        source,
    })?;
    let extra: Vec<ScanCompanion> = companions
        .into_iter()
        .map(|(relative, source)| ScanCompanion {
            source,
            relative: PathBuf::from(relative),
        })
        .collect();
    if matches!(ext.as_deref(), Some("glb" | "gltf")) {
        // glTF states its unit: metres, unless the caller says the exporter did otherwise.
        return Ok((units.unwrap_or(LengthUnit::M), extra, repair));
    }
    let text = read_head(path, UNIT_COMMENT_BYTES)?;
    let stated = units.or_else(|| units_in_header(&text));
    let Some(units) = stated else {
        return Err(IngestError::Input {
            path: path.to_path_buf(),
            problem: "the scan's length unit is not stated in the file: give --scan-units (m, cm, mm or in)".into(),
        });
    };
    Ok((units, extra, repair))
}

/// How much of a PLY or OBJ is searched for its unit comment (the header's first lines).
const UNIT_COMMENT_BYTES: u64 = 64 * 1024;

/// The first `max_bytes` of a regular file, as text.
fn read_head(path: &Path, max_bytes: u64) -> Result<String, IngestError> {
    use std::io::Read;
    let (file, _) = skinbrdf_core::untrusted::open_regular(path)?;
    let mut head = Vec::new();
    file.take(max_bytes)
        .read_to_end(&mut head)
        .map_err(io(path))?;
    Ok(String::from_utf8_lossy(&head).into_owned())
}

/// The unit a PLY or OBJ header's comment names (`comment skinbrdf mesh, millimetres`,
/// `comment units mm`).
fn units_in_header(text: &str) -> Option<LengthUnit> {
    for line in text.lines().take(64) {
        let l = line.to_ascii_lowercase();
        if !(l.starts_with("comment") || l.starts_with('#')) {
            if l.starts_with("end_header") {
                break;
            }
            continue;
        }
        let words: Vec<&str> = l
            .split(|c: char| !c.is_ascii_alphanumeric())
            .filter(|w| !w.is_empty())
            .collect();
        for w in words {
            match w {
                "millimetres" | "millimeters" | "mm" => return Some(LengthUnit::Mm),
                "centimetres" | "centimeters" | "cm" => return Some(LengthUnit::Cm),
                "metres" | "meters" => return Some(LengthUnit::M),
                "inches" => return Some(LengthUnit::In),
                _ => {}
            }
        }
    }
    None
}

/// Reads and checks a camera file (a `[camera]` table as in session.toml) as `ingest` does.
/// Returns the file and the camera.
pub fn read_camera(path: &Path) -> Result<(PathBuf, CameraSpec), IngestError> {
    let text =
        skinbrdf_core::untrusted::read_bounded_text(path, skinbrdf_core::untrusted::SETTINGS_FILE)?;
    let bad = |problem: String| IngestError::Input {
        path: path.to_path_buf(),
        problem,
    };
    let mut table: toml::Table =
        toml::from_str(&text).map_err(|e| bad(format!("not TOML: {}", e.message())))?;
    let camera = table
        .remove("camera")
        .ok_or_else(|| bad("no [camera] table (as in session.toml)".into()))?;
    if let Some(k) = table.keys().next() {
        return Err(bad(format!(
            "unknown key `{k}` (a camera file holds a [camera] table only)"
        )));
    }
    let spec: CameraSpec = camera
        .clone()
        .try_into()
        .map_err(|e: toml::de::Error| bad(format!("`camera`: {}", e.message())))?;
    let unknown = skinbrdf_session::toml_unknown_keys(&camera, &spec);
    if !unknown.is_empty() {
        return Err(bad(format!(
            "unknown key(s) {} (not in session.toml's [camera])",
            unknown
                .iter()
                .map(|k| format!("`camera.{k}`"))
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    if let CameraSpec::Calibrated(m) = &spec {
        if let Err(e) = m.validate() {
            return Err(bad(format!("`camera`: {e}")));
        }
    }
    Ok((path.to_path_buf(), spec))
}

/// Files on the card that are not photographs: name and what it is.
type SkippedFiles = Vec<(String, String)>;

/// A file named like a photograph that cannot be read or identified as one.
#[derive(Debug, Clone)]
struct UnreadablePhoto {
    path: PathBuf,
    name: String,
    reason: String,
}

/// What a card holds: its photographs with their metadata, the files that are not
/// photographs (with why), and those named like photographs that cannot be read.
type CardListing = (Vec<CardPhoto>, SkippedFiles, Vec<UnreadablePhoto>);

/// The regular files under `root` (its folders searched; a symbolic link is followed only to
/// a regular file inside `root`), and the entries skipped with why (FIFOs, devices, sockets,
/// links out of the folder or to folders).
fn walk_folder(root: &Path) -> Result<(Vec<PathBuf>, SkippedFiles), IngestError> {
    let root_real = std::fs::canonicalize(root).map_err(io(root))?;
    let name_of = |p: &Path| {
        p.strip_prefix(root)
            .unwrap_or(p)
            .to_string_lossy()
            .replace('\\', "/")
    };
    let mut files = Vec::new();
    let mut skipped = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).map_err(io(&dir))? {
            let entry = entry.map_err(io(&dir))?;
            let p = entry.path();
            let t = entry.file_type().map_err(io(&p))?;
            if t.is_dir() {
                stack.push(p);
            } else if t.is_file() {
                files.push(p);
            } else if t.is_symlink() {
                match std::fs::canonicalize(&p) {
                    Ok(real) if !real.starts_with(&root_real) => skipped.push((
                        name_of(&p),
                        format!(
                            "a symbolic link to {}, outside the folder: not followed",
                            real.display()
                        ),
                    )),
                    Ok(real) if real.is_file() => files.push(p),
                    Ok(real) => skipped.push((
                        name_of(&p),
                        format!(
                            "a symbolic link to {}: not followed",
                            skinbrdf_core::untrusted::file_type_words(
                                std::fs::metadata(&real).map_err(io(&p))?.file_type()
                            )
                        ),
                    )),
                    Err(_) => skipped.push((name_of(&p), "a broken symbolic link".into())),
                }
            } else {
                skipped.push((
                    name_of(&p),
                    format!(
                        "{}, not a regular file: not read",
                        skinbrdf_core::untrusted::file_type_words(t)
                    ),
                ));
            }
        }
    }
    files.sort();
    Ok((files, skipped))
}

/// Whether a file's extension names a photograph (a camera raw format, JPEG or TIFF).
fn named_like_photograph(p: &Path) -> bool {
    let ext = p
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    FileKind::from_extension(&ext)
        .is_some_and(|k| k.is_raw() || matches!(k, FileKind::Jpeg | FileKind::Tiff))
}

/// Every file under the card, photographs (with their metadata) and the rest.
fn list_card(
    card: &Path,
    decoder: Option<&skinbrdf_raw::Isolation>,
) -> Result<CardListing, IngestError> {
    if !card.is_dir() {
        return Err(IngestError::Input {
            path: card.to_path_buf(),
            problem: "not a directory (give the card's root or its DCIM folder)".into(),
        });
    }
    let (files, mut skipped) = walk_folder(card)?;
    let name_of = |p: &Path| {
        p.strip_prefix(card)
            .unwrap_or(p)
            .to_string_lossy()
            .replace('\\', "/")
    };
    let kinds: Vec<(PathBuf, Result<FileKind, RawError>)> = files
        .into_par_iter()
        .map(|p| {
            let k = skinbrdf_raw::sniff(&p);
            (p, k)
        })
        .collect();
    let mut photos_paths = Vec::new();
    let mut unreadable = Vec::new();
    let mut cannot_read = |p: PathBuf, reason: String| {
        unreadable.push(UnreadablePhoto {
            name: name_of(&p),
            path: p,
            reason,
        })
    };
    for (p, kind) in kinds {
        match kind {
            Ok(k) if k.is_raw() || matches!(k, FileKind::Jpeg | FileKind::Tiff) => {
                skinbrdf_raw::check_extension(&p, k)?;
                photos_paths.push(p);
            }
            Ok(k) if named_like_photograph(&p) => {
                let e = skinbrdf_raw::check_extension(&p, k)
                    .err()
                    .map(|e| skinbrdf_core::error_text(&e))
                    .unwrap_or_else(|| format!("its content is {}, not a photograph", k.name()));
                cannot_read(p, e);
            }
            Ok(k) => skipped.push((name_of(&p), format!("{} file, not a photograph", k.name()))),
            Err(e) if named_like_photograph(&p) => cannot_read(p, skinbrdf_core::error_text(&e)),
            Err(_) => skipped.push((name_of(&p), "not an image file".to_string())),
        }
    }
    let read: Vec<(PathBuf, Result<ExposureMeta, RawError>)> = photos_paths
        .into_par_iter()
        .map(|p| {
            let meta = skinbrdf_raw::read_metadata_with(decoder, &p);
            (p, meta)
        })
        .collect();
    let mut photos = Vec::new();
    for (p, meta) in read {
        match meta {
            Ok(meta) => photos.push(CardPhoto {
                name: name_of(&p),
                path: p,
                meta,
            }),
            Err(e) => cannot_read(p, skinbrdf_core::error_text(&e)),
        }
    }
    if photos.is_empty() {
        return Err(IngestError::Input {
            path: card.to_path_buf(),
            problem: format!(
                "no photograph (camera raw, JPEG or TIFF) found ({} other files)",
                skipped.len()
            ),
        });
    }
    Ok((photos, skipped, unreadable))
}

/// How far (seconds) a file's modification time may lie outside the session's files' and still
/// say it could be one of them (a card's times are the camera's, good to a second).
const SESSION_MTIME_SLACK_S: f64 = 600.0;

/// Sorts the photographs that cannot be read: one that could be an exposure of the session
/// (some exposure has no file, and the file's number lies among the session's file numbers,
/// or its name has no number and its time lies within the session's) is returned as an error
/// line; the others become listed skips, with why.
fn sort_unreadable(
    unreadable: Vec<UnreadablePhoto>,
    m: &Matching,
    matched: &[(&matching::MatchedPair, &CardPhoto)],
) -> (Vec<String>, SkippedFiles) {
    let numbers: Vec<u32> = matched
        .iter()
        .filter_map(|(_, p)| matching::file_number_from_name(&p.name))
        .collect();
    let k = m.missing.len() as u32;
    let number_range = numbers
        .iter()
        .min()
        .zip(numbers.iter().max())
        .map(|(lo, hi)| (lo.saturating_sub(k), hi.saturating_add(k)));
    let mtime_s = |p: &Path| {
        std::fs::metadata(p)
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map(|d| d.as_secs_f64())
    };
    let times: Vec<f64> = matched
        .iter()
        .filter_map(|(_, p)| mtime_s(&p.path))
        .collect();
    let time_range = times
        .iter()
        .copied()
        .reduce(f64::min)
        .zip(times.iter().copied().reduce(f64::max));
    let mut errors = Vec::new();
    let mut skips = Vec::new();
    for u in unreadable {
        let by_name = matching::file_number_from_name(&u.name)
            .zip(number_range)
            .map(|(n, (lo, hi))| (lo..=hi).contains(&n));
        let by_time = mtime_s(&u.path).zip(time_range).map(|(t, (lo, hi))| {
            t >= lo - SESSION_MTIME_SLACK_S && t <= hi + SESSION_MTIME_SLACK_S
        });
        let could_be = k > 0 && by_name.or(by_time).unwrap_or(true);
        if could_be {
            errors.push(format!("  {}: {}", u.path.display(), u.reason));
        } else {
            let why = if k == 0 {
                "every exposure has its file"
            } else {
                "its name and time are outside the session's files"
            };
            skips.push((
                u.name,
                format!(
                    "cannot be read ({}); not one of the session's exposures: {why}",
                    u.reason
                ),
            ));
        }
    }
    (errors, skips)
}

fn sniff_raw(p: &Path) -> bool {
    skinbrdf_raw::sniff(p).is_ok_and(FileKind::is_raw)
}

fn camera_shot(name: &str, meta: &ExposureMeta) -> Result<CameraShot, IngestError> {
    let Some(t) = &meta.capture_time else {
        return Err(IngestError::Input {
            path: PathBuf::from(name),
            problem: "no DateTimeOriginal in its metadata: it cannot be matched to an exposure"
                .into(),
        });
    };
    let subsec_s = t.subsec_digits.as_ref().map(|_| t.subsec_s());
    Ok(CameraShot {
        file: name.to_string(),
        time: CameraTime {
            naive_local_s: t.local.naive_seconds(),
            subsec_s,
            utc_offset_s: t.utc_offset_min.map(|m| m * 60),
        },
        shutter_count: meta.image_number,
        file_number: matching::file_number_from_name(name),
        body_serial: meta.body_serial.clone(),
    })
}

fn settings_of(meta: &ExposureMeta) -> Option<ExposureSettings> {
    Some(ExposureSettings {
        exposure_time_s: meta.exposure_time_s?,
        f_number: meta.f_number?,
        iso: meta.iso?,
    })
}

/// A body, lens or focal-length change among the session's files, or a file from another body
/// taken during the session, is refused.
fn check_one_camera(
    m: &Matching,
    matched: &[(&matching::MatchedPair, &CardPhoto)],
    shots: &[CameraShot],
) -> Result<(), IngestError> {
    let during: Vec<String> = m
        .extra_files
        .iter()
        .filter_map(|(file, reason)| match reason {
            ExtraReason::AnotherBody { serial, expected } => {
                let t = shots.iter().find(|s| &s.file == file)?.time;
                let (first, last) = (
                    matched
                        .first()
                        .and_then(|(_, p)| p.meta.capture_time.as_ref())?,
                    matched
                        .last()
                        .and_then(|(_, p)| p.meta.capture_time.as_ref())?,
                );
                let ts = t.naive_local_s as f64 + t.subsec_s.unwrap_or(0.0);
                (ts > first.naive_seconds() && ts < last.naive_seconds())
                    .then(|| format!("  {file}: body {serial} (the session's body is {expected})"))
            }
            _ => None,
        })
        .collect();
    if !during.is_empty() {
        return Err(IngestError::CameraChanged {
            what: "body",
            files: during,
        });
    }
    check_same_camera(&matched.iter().map(|(_, p)| *p).collect::<Vec<_>>())
}

/// A body, lens or focal-length difference among `photos` is refused, listing each value with
/// its files.
fn check_same_camera(photos: &[&CardPhoto]) -> Result<(), IngestError> {
    type Field = fn(&ExposureMeta) -> Option<String>;
    let fields: [(&'static str, Field); 4] = [
        ("body", |m| {
            Some(format!(
                "{} {} #{}",
                m.camera_make.as_deref().unwrap_or(""),
                m.camera_model.as_deref().unwrap_or(""),
                m.body_serial.as_deref().unwrap_or("")
            ))
        }),
        ("lens", |m| m.lens_model.clone()),
        ("focal length", |m| {
            m.focal_length_mm.map(|f| format!("{f:.1} mm"))
        }),
        ("lens make", |m| m.lens_make.clone()),
    ];
    for (what, field) in fields {
        let mut values: BTreeMap<String, Vec<&str>> = BTreeMap::new();
        for p in photos {
            if let Some(v) = field(&p.meta) {
                values.entry(v).or_default().push(p.name.as_str());
            }
        }
        if values.len() > 1 {
            return Err(IngestError::CameraChanged {
                what,
                files: values
                    .iter()
                    .map(|(v, files)| format!("  {v}: {}", files.join(", ")))
                    .collect(),
            });
        }
    }
    Ok(())
}

/// The survey folder's photographs, in the order they were taken (camera time; one without a
/// time first), with its other files: each from the session's body (a known serial other than
/// the matched files' is refused naming the file) with the same lens and focal length, and none
/// of them a file matched to an exposure.
fn survey_photos(
    dir: &Path,
    matched: &[(&matching::MatchedPair, &CardPhoto)],
    decoder: Option<&skinbrdf_raw::Isolation>,
) -> Result<(Vec<CardPhoto>, SkippedFiles), IngestError> {
    let (mut photos, mut skipped, unreadable) = list_card(dir, decoder)?;
    // Survey images are no exposures: one that cannot be read is a listed skip.
    skipped.extend(
        unreadable
            .into_iter()
            .map(|u| (u.name, format!("cannot be read: {}", u.reason))),
    );
    let canonical = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    for p in &photos {
        let c = canonical(&p.path);
        if let Some((pair, _)) = matched.iter().find(|(_, m)| canonical(&m.path) == c) {
            return Err(IngestError::SurveyIsSessionFile {
                file: p.path.clone(),
                exposure_index: pair.exposure_index,
            });
        }
    }
    if let Some(expected) = matched.iter().find_map(|(_, p)| p.meta.body_serial.clone()) {
        if let Some((p, serial)) = photos.iter().find_map(|p| {
            p.meta
                .body_serial
                .as_ref()
                .filter(|s| **s != expected)
                .map(|s| (p, s.clone()))
        }) {
            return Err(IngestError::SurveyFromAnotherBody {
                file: p.path.clone(),
                serial,
                expected,
            });
        }
    }
    let all: Vec<&CardPhoto> = matched
        .iter()
        .map(|(_, p)| *p)
        .chain(photos.iter())
        .collect();
    check_same_camera(&all)?;
    photos.sort_by(|a, b| {
        taken_s(a)
            .unwrap_or(f64::NEG_INFINITY)
            .total_cmp(&taken_s(b).unwrap_or(f64::NEG_INFINITY))
            .then_with(|| a.name.cmp(&b.name))
    });
    let skipped = skipped
        .into_iter()
        .map(|(f, why)| (format!("survey: {f}"), why))
        .collect();
    Ok((photos, skipped))
}

/// When a photograph was taken, seconds on the camera's own clock.
fn taken_s(p: &CardPhoto) -> Option<f64> {
    p.meta.capture_time.as_ref().map(CaptureTime::naive_seconds)
}

/// The size of a photograph as the session loads it (superpixels for raw files).
fn decoded_size(
    path: &Path,
    decoder: Option<&skinbrdf_raw::Isolation>,
) -> Result<(u32, u32), IngestError> {
    if sniff_raw(path) {
        Ok(skinbrdf_raw::decoded_size_with(decoder, path)?)
    } else {
        let h = skinbrdf_session::read_header(path).map_err(|e| IngestError::Input {
            path: path.to_path_buf(),
            problem: skinbrdf_core::error_text(&e),
        })?;
        Ok((h.width, h.height))
    }
}

/// A fresh directory beside `out` to build the session in.
fn staging_dir(out: &Path) -> Result<PathBuf, IngestError> {
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(io(&parent))?;
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "session".into());
    remove_dead_staging(&parent, &name);
    let staging = parent.join(format!(".{name}.ingest-{}", std::process::id()));
    if staging.exists() {
        std::fs::remove_dir_all(&staging).map_err(io(&staging))?;
    }
    std::fs::create_dir_all(&staging).map_err(io(&staging))?;
    Ok(staging)
}

/// Removes the staging directories (`.NAME.ingest-PID`, and `.NAME.ingest-PID.old` of a
/// replaced session) that runs which no longer exist left beside `NAME`.
fn remove_dead_staging(parent: &Path, name: &str) {
    let prefix = format!(".{name}.ingest-");
    let Ok(rd) = std::fs::read_dir(parent) else {
        return;
    };
    for e in rd.filter_map(Result::ok) {
        let file_name = e.file_name().to_string_lossy().into_owned();
        let Some(rest) = file_name.strip_prefix(&prefix) else {
            continue;
        };
        let pid = rest.strip_suffix(".old").unwrap_or(rest);
        let Ok(pid) = pid.parse::<u32>() else {
            continue;
        };
        let is_dir = e.file_type().is_ok_and(|t| t.is_dir());
        if is_dir && pid != std::process::id() && !skinbrdf_core::fsio::process_alive(pid) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Moves the staged session to `out`, replacing what is there only once the new one is ready.
fn move_into_place(staging: &Path, out: &Path) -> Result<(), IngestError> {
    if out.exists() {
        let old = staging.with_extension("old");
        std::fs::rename(out, &old).map_err(io(out))?;
        if let Err(e) = std::fs::rename(staging, out) {
            let _ = std::fs::rename(&old, out);
            return Err(io(out)(e));
        }
        let _ = std::fs::remove_dir_all(&old);
    } else {
        std::fs::rename(staging, out).map_err(io(out))?;
    }
    Ok(())
}

/// The sample's shape: a scan with its unit and companion files, or the rig's ideal shape.
#[derive(Debug)]
enum Shape {
    Scan {
        path: PathBuf,
        units: LengthUnit,
        files: Vec<ScanCompanion>,
    },
    Ideal(GeometrySpec),
}

#[allow(clippy::too_many_arguments)]
fn write_session(
    cfg: &IngestConfig,
    staging: &Path,
    record: &CaptureRecord,
    rig: &Rig,
    parts: skinbrdf_session::SessionParts,
    matched: &[(&matching::MatchedPair, &CardPhoto)],
    scales: &[f64],
    survey: &[CardPhoto],
    camera: CameraSpec,
    shape: &Shape,
) -> Result<WrittenImages, IngestError> {
    // The images: copied into images/, or referenced where they are, relative to the final
    // directory (a sibling of the staging directory, so the same relative path).
    let final_dir = cfg
        .out_dir
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let mut images = Vec::new();
    let mut entries = Vec::new();
    if cfg.copy {
        std::fs::create_dir_all(staging.join("images")).map_err(io(staging))?;
    }
    // A photograph copied into `folder`, or referenced where it is.
    let place = |photo: &CardPhoto, folder: &str| -> Result<String, IngestError> {
        if cfg.copy {
            let base = photo
                .path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| photo.name.clone());
            let rel = format!("{folder}/{base}");
            let dst = staging.join(&rel);
            if let Some(parent) = dst.parent() {
                std::fs::create_dir_all(parent).map_err(io(parent))?;
            }
            std::fs::copy(&photo.path, &dst).map_err(io(&photo.path))?;
            Ok(rel)
        } else {
            let rel_to_parent = skinbrdf_session::write::relative_path(&photo.path, &final_dir);
            Ok(if rel_to_parent.is_absolute() {
                rel_to_parent.to_string_lossy().into_owned()
            } else {
                Path::new("..")
                    .join(rel_to_parent)
                    .to_string_lossy()
                    .replace('\\', "/")
            })
        }
    };
    // Survey images in the order taken: those before the session's first file lead.
    let first_s = matched
        .iter()
        .filter_map(|(_, p)| taken_s(p))
        .fold(f64::INFINITY, f64::min);
    let mut survey_images = Vec::new();
    let mut survey_entries = (Vec::new(), Vec::new());
    // Each entry's source file, in the entries' order.
    let mut survey_sources = (Vec::new(), Vec::new());
    for photo in survey {
        let before = taken_s(photo).is_none_or(|t| t < first_s);
        // Their own folder when copied: survey and card files may share a name.
        let file = place(photo, SURVEY_IMAGES_DIR)?;
        let entry = ImageEntry {
            file: file.clone(),
            role: ImageRole::Survey,
            exposure_index: None,
            linearization: None,
            mask: None,
            world_from_camera: None,
            world_from_head: None,
            exposure_scale: None,
        };
        if before {
            survey_entries.0.push(entry);
            survey_sources.0.push(photo.path.clone());
        } else {
            survey_entries.1.push(entry);
            survey_sources.1.push(photo.path.clone());
        }
        survey_images.push(IngestedSurveyImage {
            file,
            source_file: photo.path.clone(),
            settings: settings_of(&photo.meta),
            before_session: before,
        });
    }
    let mut sources: Vec<PathBuf> = survey_sources.0;
    entries.append(&mut survey_entries.0);
    for ((pair, photo), &scale) in matched.iter().zip(scales) {
        let file = place(photo, "images")?;
        entries.push(ImageEntry {
            file: file.clone(),
            role: pair.role,
            exposure_index: Some(pair.exposure_index),
            linearization: None,
            mask: None,
            world_from_camera: None,
            world_from_head: None,
            exposure_scale: (scale != 1.0).then_some(scale),
        });
        sources.push(photo.path.clone());
        images.push(IngestedImage {
            file,
            card_file: photo.path.clone(),
            exposure_index: pair.exposure_index,
            role: pair.role,
            settings: settings_of(&photo.meta),
            exposure_scale: scale,
            time_residual_s: pair.residual_s,
        });
    }
    entries.append(&mut survey_entries.1);
    sources.append(&mut survey_sources.1);
    // The scan and what comes with it, or the rig's ideal shape.
    let geometry = match shape {
        Shape::Scan { path, units, files } => {
            let scan_name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scan.ply".into());
            std::fs::copy(path, staging.join(&scan_name)).map_err(io(path))?;
            for f in files {
                let to = staging.join(&f.relative);
                if let Some(parent) = to.parent() {
                    std::fs::create_dir_all(parent).map_err(io(parent))?;
                }
                std::fs::copy(&f.source, &to).map_err(io(&f.source))?;
            }
            GeometrySpec::Scan {
                file: scan_name,
                units: *units,
                accept_repair_loss: None,
            }
        }
        Shape::Ideal(g) => g.clone(),
    };
    // The registration's points come along beside the scan.
    let points = match &cfg.scan_points {
        Some(p) => {
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scan-points.toml".into());
            std::fs::copy(p, staging.join(&name)).map_err(io(p))?;
            Some(name)
        }
        None => None,
    };
    let registration = (points.is_some() || cfg.registration_fit != RegistrationFit::Rigid)
        .then_some(RegistrationSpec {
            points,
            fit: cfg.registration_fit,
        });
    // The capture record, with each exposure's image.
    let mut rec = record.clone();
    for e in &mut rec.exposures {
        e.image = images
            .iter()
            .find(|i| i.exposure_index == e.index)
            .map(|i| i.file.clone());
    }
    let json =
        skinbrdf_core::json::to_vec_pretty(&cfg.capture, &rec).map_err(|e| IngestError::Input {
            path: cfg.capture.clone(),
            problem: format!("cannot serialise the record: {}", e.problem()),
        })?;
    write_file(&staging.join("capture.json"), &json)?;
    let session = SessionFile {
        format_version: SESSION_FORMAT_VERSION,
        description: format!(
            "ingested from {} with rig {} ({} images)",
            cfg.card_dir.display(),
            cfg.rig.display(),
            entries.len()
        ),
        capture: Some("capture.json".into()),
        camera,
        linearization: Linearization::LINEAR,
        images: entries,
        targets: parts.targets,
        flash: parts.flash,
        standard: parts.standard,
        geometry,
        roi: rig.file.roi,
        known: parts.known,
        registration,
    };
    Session::write_file(staging, &session).map_err(|e| IngestError::Input {
        path: staging.join("session.toml"),
        problem: skinbrdf_core::error_text(&e),
    })?;
    Ok((images, survey_images, sources))
}

/// The images written: the card's, the survey's, and every entry's source file in the
/// session's order.
type WrittenImages = (Vec<IngestedImage>, Vec<IngestedSurveyImage>, Vec<PathBuf>);

/// Where `--copy` puts the survey images inside the session.
pub const SURVEY_IMAGES_DIR: &str = "images/survey";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_are_read_from_the_header_comment() {
        let ply = "ply\nformat binary_little_endian 1.0\ncomment skinbrdf mesh, millimetres\nend_header\n";
        assert_eq!(units_in_header(ply), Some(LengthUnit::Mm));
        assert_eq!(units_in_header("ply\nend_header\n"), None);
        assert_eq!(
            units_in_header("# units: metres\nv 0 0 0\n"),
            Some(LengthUnit::M)
        );
    }

    #[test]
    fn a_problem_of_the_written_session_names_the_input_it_came_from() {
        let mut cfg = IngestConfig::new(
            "card".into(),
            "in/capture.json".into(),
            "in/rig.toml".into(),
            PathBuf::from("in/head.obj"),
            "out/S2".into(),
        );
        cfg.camera = Some("in/camera.toml".into());
        let staging = Path::new("out/.S2.ingest-1");
        let images = [PathBuf::from("card/A.DNG"), PathBuf::from("card/B.DNG")];
        let camera = CameraSource::File {
            path: "in/camera.toml".into(),
        };
        let owners = Owners {
            cfg: &cfg,
            staging,
            camera: &camera,
            rig_camera: false,
            images: &images,
        };
        let mut errs = SessionErrors::default();
        let toml = staging.join(SESSION_FILE);
        for field in [
            "images[1].file",
            "images",
            "camera.fx_px",
            "flash.targets",
            "known.light_position_m",
            "targets.unplaced",
            "geometry.file",
            "linearization.white_level",
        ] {
            errs.push(&toml, field, "a problem");
        }
        errs.push(staging.join("capture.json"), "format_version", "a problem");
        let mapped = owners.of(errs);
        let got: Vec<(String, String)> = mapped
            .problems
            .iter()
            .map(|p| (p.file.to_string_lossy().replace('\\', "/"), p.field.clone()))
            .collect();
        let want = [
            ("card/B.DNG", ""),
            ("in/capture.json", "exposures"),
            ("in/camera.toml", "camera.fx_px"),
            ("in/rig.toml", "targets"),
            ("in/rig.toml", "flash.light_position_m"),
            ("in/rig.toml", "targets"),
            ("in/head.obj", ""),
            ("out/S2/session.toml", "linearization.white_level"),
            ("in/capture.json", "format_version"),
        ];
        let want: Vec<(String, String)> = want
            .iter()
            .map(|(f, k)| (f.to_string(), k.to_string()))
            .collect();
        assert_eq!(got, want);
        assert!(!mapped.to_string().contains(".ingest-"), "{mapped}");
    }

    #[test]
    fn exposure_settings_compare_within_rational_rounding() {
        let a = ExposureSettings {
            exposure_time_s: 1.0 / 125.0,
            f_number: 11.0,
            iso: 100,
        };
        let b = ExposureSettings {
            exposure_time_s: 0.008,
            ..a
        };
        assert!(a.same_as(&b));
        let c = ExposureSettings { iso: 200, ..a };
        assert!(!a.same_as(&c));
        assert!((c.factor() / a.factor() - 2.0).abs() < 1e-12);
        assert_eq!(a.to_string(), "1/125 s, f/11, ISO 100");
    }
}
