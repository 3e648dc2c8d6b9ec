//! The session directory: format, loading, validation, images and their linearization, ground
//! truth. The full format is specified in `docs/session-format.md`.
//!
//! # A session directory
//!
//! ```text
//! SESSION/
//!   session.toml     format version, camera, images (file, role, linearization), target layouts,
//!                    flash, reflectance standard, geometry, region of interest, known quantities
//!   capture.json     the trigger controller's record (optional; see [`capture`])
//!   images/...       the photographs (PNG/TIFF 8/16-bit, OpenEXR, JPEG, camera raw files)
//!   scan.ply         the head scan (or an ideal sphere/cylinder in session.toml)
//!   truth.json       ground truth (synthetic sessions only; see [`truth`])
//!   truth/...        per-image truth masks
//! ```
//!
//! # API
//!
//! * [`Session::load`] reads and validates a directory and returns **every** problem at once as
//!   [`SessionErrors`] (each with file, field path and a message).
//! * [`Session::load_image`] decodes an image and linearizes it ([`LinearImage`], values `V`
//!   with 1.0 at the white level; see [`linear`] for the exact formula). The value `V` is the
//!   `L_pixel` of the method's equation 2. [`Session::load_geometry_grey`] gives target
//!   detection its grey image. With a [`DecodeCache`] ([`Session::keep_decoded`]) each camera
//!   raw file is decoded once, by its first load, and read back from the cache by the others.
//! * [`SessionFile`] and its parts are the `session.toml` types; [`Session::write_file`] writes one.
//! * [`Rig`] (`rig.toml`): a studio's targets, flash and standard, with or without placements.
//! * [`Truth`] (`truth.json`): every pose, the light position, C, the BRDF and per-image masks.
//! * [`mod@write`]: atomic writers (JSON, TOML, 16-bit PNG, EXR, masks) and [`load_mask`].
//!
//! # Radiometric convention
//!
//! `rho(w_i, w_e) = C · D² · V / cos(theta_i)` per RGB channel (the method's equation 2), with
//! `rho` in 1/sr, `D` the distance from the surface point to the flash's emitting point in
//! metres, `V` the linearized pixel value and `C` (per channel, sr⁻¹·m⁻²) the calibration
//! constant. Equivalently a surface point renders to `V = rho · cos(theta_i) / (C · D²)`.

pub mod capture;
mod checks;
pub mod decoded;
pub mod error;
pub mod format;
pub mod linear;
pub mod load;
mod needs;
mod parse;
pub mod rig;
pub mod truth;
mod validate;
pub mod write;

pub use capture::{CaptureRecord, ImageRole};
pub use decoded::DecodeCache;
pub use error::{FileError, SessionErrors, SessionProblem};
pub use format::*;
pub use linear::{
    load_linear_image, load_raw_image, load_raw_mosaic, measured_channels, photosite_geometry_grey,
    raw_kind, raw_options, read_header, BayerPhase, ImageHeader, LinearImage, Linearization,
    RawLayout, RawMode, ResponseTable, StoredFormat, ToneCurve,
};
pub use load::{
    BadImagePolicy, GreyImage, LinearizationSource, SectionNeeds, Session, SkippedImage,
    TAG36H11_CODES, TARGET_SIZE_REL_TOL,
};
pub use parse::toml_unknown_keys;
pub use rig::{LayoutFile, Rig, RigCamera, RigFile, SessionParts, RIG_FORMAT_VERSION};
pub use truth::{
    ImageTruth, PlacementTruth, RenderTruth, SheetTruth, SurfaceTruth, TargetTruth, Truth,
    TRUTH_FORMAT_VERSION,
};
pub use write::{load_mask, write_atomic, write_json_atomic, write_mask_png, Mask};
