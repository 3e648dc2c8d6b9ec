//! A synthetic studio: exactly what a studio holds after a capture, so that the path from the
//! camera's card to a session (`skinbrdf ingest`) is tested end to end without a camera.
//!
//! `skinbrdf synth --studio` writes, beside the PNG session and its truth, `S/studio/`:
//!
//! ```text
//! studio/
//!   card/DCIM/100SKBRF/SKB_NNNN.DNG   the camera's raw files (Bayer CFA, EXIF)
//!   survey/SKB_NNNN.DNG               the survey shots, when the scene takes any
//!                                     (crate::survey_shots): same body, taken and numbered
//!                                     before the card's first file, a longer exposure
//!   capture.json                      the controller's record (no image names: it never knew them)
//!   layouts/NAME.layout.toml          each printed sheet's layout (sheet frame, nominal print,
//!                                     the format `skinbrdf targets` writes)
//!   rig-measured.toml                 the rig with its true placements, scanner frame (a
//!                                     surveyed rig): flat sheets by pose and print scale,
//!                                     a folded sheet's and the headdress band's targets as
//!                                     cut-outs (no pose places their flat layouts)
//!   rig.toml                          what a studio states before any survey: the declared
//!                                     origin, the printed flash and standard layouts, the flash
//!                                     stand's panel (only without a relay) and the ROI, in the
//!                                     textured scan's frame; every sheet by its layout, unplaced
//!   scan.ply                          the head scan, scanner frame (untextured, already
//!                                     registered: rig-measured.toml places the headdress in it)
//!   scan/head.obj, head.mtl, head.png the textured scan in the scanner's frame, headdress
//!                                     included (crate::textured_scan), scan-truth.json;
//!                                     head.glb, head-colours.ply the same scan as binary glTF
//!                                     and as PLY with vertex colours, when the scene's
//!                                     `[studio] scan_formats` asks for them
//!   truth.json                        the truth with the head frame the scanner's, the frame of
//!                                     every file here (scores a session ingested with either
//!                                     rig and either scan)
//! ```
//!
//! # Raw image formation
//!
//! The renderer's linear value `V` of superpixel `(u, v)` (1.0 = the white level of the PNG
//! session) becomes the four photosites of the Bayer quad whose top-left photosite is
//! `(2u, 2v)` of the active area, each with its own noise:
//!
//! ```text
//! raw_c = black + clip(g_c k V_c + n) (white - black),   n ~ N(0, g_c k V_c / full_well + read²)
//! ```
//!
//! with `g_c` the channel's gain (the sensor's spectral sensitivity: `C`, per channel, absorbs
//! it, so a session ingested from the card has `C / g_c` where the PNG session has `C`), `k`
//! the exposure factor of the shot (`t ISO / N²` over the scene's; 1 but for a scene's exposure
//! change) and quantisation to `raw_bits`. The masked border around the active area reads
//! black plus read noise. The superpixel image then has the camera's size, so the intrinsics of
//! the PNG session are those of the loaded raw images (`docs/ingest.md`).
//!
//! With `[studio] mosaic = "photosite"` ([`Mosaic::Photosite`]) the render is the sensor's full
//! resolution instead: rendered pixel `(x, y)` is active-area photosite `(x, y)`, holding its
//! own filter's channel `c`, the same formula with `V_c` of that pixel. Each photosite's value
//! then belongs to its own place (as on a camera's sensor), the PNG session holds the
//! full-resolution images of the same renders, `camera.toml` states the camera in superpixel
//! units (half the size, as a raw session states it) and `truth.json` the full-resolution
//! camera (a session scores it in the units it loads its images in).
//!
//! # Camera clock
//!
//! The camera's clock runs off the controller's host clock by a scene-set offset and drift:
//! `t_camera = h + offset + drift (h - h_0)` for an exposure at host time `h` (its X-sync,
//! through the controller's clock model), plus a few milliseconds of release jitter, written
//! as a local date-time with the scene's UTC offset, `SubSecTimeOriginal` with the scene's
//! number of digits (none: whole seconds, truncated as cameras do) and `OffsetTimeOriginal`.
//! Test shots (before and after the session) and deleted files (an exposure whose file is
//! missing from the card) advance the file number and the shutter count like real actuations.
//!
//! # What the rig files do not say
//!
//! A scene's `[studio]` can make the rig differ from what its files state, for the placement
//! survey to find: a target that moves mid-session ([`MovedTarget`]), sheets taped on crooked
//! (`sheet_tilt_deg`), a sheet printed at another scale ([`PrintScaleFault`]) or folded
//! ([`BentSheet`]), the headdress stated as one flat band although it is wrapped
//! (`headdress_band`), and a target printed with another's code ([`DuplicateId`]: the rig
//! files list the code once and the misprinted target nowhere). The geometry is in
//! [`crate::sheets`]; `truth.json` has every target's true corners and every sheet's truth
//! (`sheets`: pose, print scale, tilt, fold, whether its layout is rigid).

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use skinbrdf_core::Pose;
use skinbrdf_raw::dng::{write_dng, DngImage, FocalPlaneResolution, FocalPlaneUnit};
use skinbrdf_raw::{BayerPhase, CaptureTime, LocalDateTime};
use skinbrdf_session::capture::{
    CapturePlan, CaptureRecord, ClockModel, DeviceIdentity, Exposure, FlashMode, ImageRole,
    ShotGroup, ShotOutcome, CAPTURE_FORMAT_VERSION,
};
use skinbrdf_session::rig::{
    LayoutFile, RigFile, RigFlash, RigSheet, RigStandard, RigTarget, RIG_FORMAT_VERSION,
};
use skinbrdf_session::{Rig as RigIo, SheetTruth, Target, TargetGroup, TAG_FAMILY};

use crate::generate::SynthError;
use crate::layout::{Layout, Rig, Shot};
use crate::photograph::Rendered;
use crate::scene::Scene;
use crate::sheets::{PrintedSheet, SheetShape};

/// The studio directory inside a synthetic session.
pub const STUDIO_DIR: &str = "studio";
/// The card's image folder inside the studio directory.
pub const CARD_FOLDER: &str = "card/DCIM/100SKBRF";
/// The survey shots' folder inside the studio directory (`skinbrdf ingest --survey`): taken by
/// hand before the session, copied off the camera apart from the session's card.
pub const SURVEY_DIR: &str = "survey";
/// The camera's calibration as the studio keeps it (a `[camera]` table as in `session.toml`,
/// what `skinbrdf ingest --camera` reads).
pub const CAMERA_FILE: &str = "camera.toml";

/// How a scene's studio differs from the default (`[studio]` in a scene file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StudioScene {
    /// Camera clock minus controller host clock at the first exposure, seconds.
    pub camera_clock_offset_s: f64,
    /// Camera clock rate error, parts per million.
    pub camera_clock_drift_ppm: f64,
    /// Standard deviation of the camera's time stamp against the X-sync, milliseconds.
    pub release_jitter_ms: f64,
    /// The camera's time zone, minutes east of UTC (written as `OffsetTimeOriginal`).
    pub utc_offset_min: i32,
    /// Whether the camera writes `OffsetTimeOriginal`.
    pub write_utc_offset: bool,
    /// Digits of `SubSecTimeOriginal` (0: none; whole seconds).
    pub subsec_digits: u32,
    /// Raw bit depth: 12, 14 or 16.
    pub raw_bits: u32,
    /// Raw code of black.
    pub raw_black_level: u16,
    /// Raw code of white (clipping).
    pub raw_white_level: u16,
    /// Masked photosites around the active area, on each side.
    pub masked_border_px: u32,
    /// The Bayer phase at the active area's top-left photosite: rggb, bggr, grbg or gbrg.
    pub bayer: String,
    /// Per-channel gains (R, G, B) of the sensor relative to the renderer's linear values.
    pub channel_gains: [f64; 3],
    /// Reference targets whose corners `rig.toml` states: the studio's declared world origin
    /// (the ones seen in the most images). Every other reference target is left to the survey.
    pub origin_targets: u32,
    /// Headdress targets whose corners (in the scan's frame) `rig.toml` states; 0: the head
    /// frame comes from registering the survey to the head scan.
    pub declared_headdress_targets: u32,
    /// Test shots the photographer took before the session (files with no exposure).
    pub test_shots_before: u32,
    /// Test shots after the session.
    pub test_shots_after: u32,
    /// Exposure indices whose file was deleted from the card.
    pub missing_files: Vec<u32>,
    /// Exposure indices at which the camera did not fire (the record says MissingXsync).
    pub misfired_exposures: Vec<u32>,
    /// One exposure shot at another ISO (a photographer's slip), if any.
    pub exposure_change: Option<ExposureChange>,
    /// One reference target whose tape slipped during the session, if any: rendered at its
    /// placement up to `from_shot`, then moved (the survey must name it, not average it in).
    /// A target printed on a sheet moves with its sheet.
    pub moved_target: Option<MovedTarget>,
    /// Every reference sheet is taped on crooked: turned about its horizontal axis by an angle
    /// drawn uniformly within ± this, degrees, from the seed (`crate::sheets`).
    pub sheet_tilt_deg: f64,
    /// One reference sheet printed at another scale than its layout's, if any.
    pub print_scale: Option<PrintScaleFault>,
    /// One reference sheet folded about its vertical centre line although its layout is flat,
    /// if any.
    pub bent_sheet: Option<BentSheet>,
    /// The headdress targets are stated as one printed band (`[[sheets]]` with a flat layout:
    /// the band unrolled) although on the head it is wrapped round the forehead.
    pub headdress_band: bool,
    /// One reference target printed with another target's code, if any.
    pub duplicate_id: Option<DuplicateId>,
    /// Reference targets on a low stand between the head and the flash (the relay,
    /// `crate::layout::relay_targets`), seen with the flash stand's panel in some survey shots
    /// and with the cage in others ([`crate::survey_shots::link_shots`]); 0: no relay, and
    /// `rig.toml` states the panel's placement (no image links it to the cage).
    #[serde(default)]
    pub flash_relay_targets: u32,
    /// File number of the first file on the card.
    pub first_file_number: u32,
    /// Shutter count of the first file on the card.
    pub first_shutter_count: u32,
    /// Host time of the first exposure, Unix seconds (the session's date).
    pub start_unix_s: f64,
    /// Camera make.
    pub make: String,
    /// Camera model.
    pub model: String,
    /// Body serial number.
    pub body_serial: String,
    /// Lens model.
    pub lens_model: String,
    /// Width of the sensor's active area, millimetres (sets the focal length, the focal-plane
    /// resolution and the 35 mm equivalent focal length in EXIF).
    pub sensor_width_mm: f64,
    /// Exposure time, seconds (the flash's X-sync speed).
    pub exposure_time_s: f64,
    /// Aperture f-number.
    pub f_number: f64,
    /// ISO.
    pub iso: u32,
    /// The formats the textured scan is written in (`scan/`): `obj` (always), `glb`
    /// (`head.glb`), `ply` (`head-colours.ply`, vertex colours).
    #[serde(default = "default_scan_formats")]
    pub scan_formats: Vec<crate::textured_scan::ScanFormat>,
    /// How the raw files are formed from the renders (see the module docs): `quad` (the
    /// default) or `photosite`.
    #[serde(default)]
    pub mosaic: Mosaic,
}

/// How a render becomes the sensor's photosites (`[studio] mosaic`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mosaic {
    /// Each rendered pixel becomes a 2x2 Bayer quad: the superpixel image has the scene
    /// camera's size and every photosite of a quad holds the quad's value. A card for reading
    /// as superpixels: read per photosite, its photosites hold no value of their own place
    /// (`docs/derender.md`, "Why photosites are the default").
    #[default]
    Quad,
    /// Each rendered pixel is one photosite holding its own filter's channel: the scene camera
    /// is the sensor's full resolution (width and height multiples of 4), so a raw file loaded
    /// per photosite sees every value where it was rendered, as a camera's sensor records it.
    Photosite,
}

fn default_scan_formats() -> Vec<crate::textured_scan::ScanFormat> {
    vec![crate::textured_scan::ScanFormat::Obj]
}

/// An exposure shot at another ISO.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExposureChange {
    /// The exposure's index in the capture record.
    pub exposure_index: u32,
    /// Its ISO.
    pub iso: u32,
}

/// Which sheet of the rig: its name, or its index in the rig's sheet list (the order of
/// `rig.toml`'s `[[sheets]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SheetRef {
    /// By index.
    Index(usize),
    /// By name.
    Name(String),
}

impl SheetRef {
    /// Whether this names the sheet `name` at `index`.
    pub fn names(&self, name: &str, index: usize) -> bool {
        match self {
            Self::Index(k) => *k == index,
            Self::Name(n) => n == name,
        }
    }
}

impl std::fmt::Display for SheetRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Index(k) => write!(f, "sheet #{k}"),
            Self::Name(n) => write!(f, "sheet `{n}`"),
        }
    }
}

/// A sheet printed at another scale.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PrintScaleFault {
    /// The sheet.
    pub sheet: SheetRef,
    /// Printed size over the layout's nominal size.
    pub scale: f64,
}

/// A sheet folded about its vertical centre line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BentSheet {
    /// The sheet.
    pub sheet: SheetRef,
    /// The angle between its halves' normals, degrees (each half turned by half of it).
    pub bend_deg: f64,
}

/// A reference target printed with another target's code.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DuplicateId {
    /// The target misprinted (the rig files do not list it).
    pub id: u32,
    /// The code printed on it: another reference target's id.
    pub printed_as: u32,
}

/// Largest sheet tilt a scene may ask for, degrees (a sheet taped on crooked, not turned
/// away from the cameras).
pub const MAX_SHEET_TILT_DEG: f64 = 30.0;

/// Most relay targets a scene may ask for: six columns of two rows at the relay's spacing span
/// 0.75 m, as wide as a low stand between the head and the flash can be without reaching into
/// the measurement images' frames.
pub const MAX_RELAY_TARGETS: u32 = 12;
/// Largest fold of a bent sheet, degrees.
pub const MAX_BEND_DEG: f64 = 45.0;

/// A reference target that moves during the session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MovedTarget {
    /// Its tag36h11 id (a reference target that is not one of the declared origin targets).
    pub id: u32,
    /// The first shot (index in the rendered shot list) that sees it moved.
    pub from_shot: usize,
    /// Its centre's displacement, world frame, millimetres.
    pub shift_mm: [f64; 3],
    /// Its rotation about its own normal, degrees.
    pub rotate_deg: f64,
}

impl MovedTarget {
    /// The rig after the move: the target's corners shifted and turned about its centre, and
    /// with it every target of its sheet (the sheet's tape slipped) and the sheet's paper.
    pub fn apply(&self, rig: &Rig) -> Rig {
        let mut moved = rig.clone();
        let Some(t) = rig.reference.iter().find(|t| t.id == self.id) else {
            return moved;
        };
        let c = t.centre();
        let turn = glam::DQuat::from_axis_angle(t.outward_normal(), self.rotate_deg.to_radians());
        let shift = glam::DVec3::from_array(self.shift_mm) * 1e-3;
        // p -> c + shift + turn (p - c)
        let by = Pose::new(turn, c + shift - turn * c);
        let body = rig.reference_body(self.id);
        for t in moved.reference.iter_mut().filter(|t| body.contains(&t.id)) {
            *t = crate::sheets::move_target(t, &by);
        }
        for (_, p) in moved.prints.iter_mut().filter(|(id, _)| body.contains(id)) {
            *p = p.moved(&by);
        }
        for s in moved
            .sheets
            .iter_mut()
            .filter(|s| s.layout == crate::layout::Layout::Reference && s.ids().contains(&self.id))
        {
            s.group_from_sheet = by * s.group_from_sheet;
        }
        moved
    }
}

impl StudioScene {
    /// Every invariant violation, as `field: problem` strings.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !matches!(self.raw_bits, 12 | 14 | 16) {
            out.push(format!(
                "`studio.raw_bits` must be 12, 14 or 16, got {}",
                self.raw_bits
            ));
        }
        let max = (1u32 << self.raw_bits.min(16)) - 1;
        if !(u32::from(self.raw_black_level) < u32::from(self.raw_white_level)
            && u32::from(self.raw_white_level) <= max)
        {
            out.push(format!(
                "`studio.raw_black_level` {} < `studio.raw_white_level` {} <= {max} does not hold",
                self.raw_black_level, self.raw_white_level
            ));
        }
        if self.bayer_phase().is_none() {
            out.push(format!(
                "`studio.bayer` must be rggb, bggr, grbg or gbrg, got `{}`",
                self.bayer
            ));
        }
        if !self.channel_gains.iter().all(|g| g.is_finite() && *g > 0.0) {
            out.push(format!(
                "`studio.channel_gains` must be positive, got [{}]",
                self.channel_gains
                    .iter()
                    .map(f64::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        if let Some(m) = &self.moved_target {
            if !(m.shift_mm.iter().all(|v| v.is_finite()) && m.rotate_deg.is_finite()) {
                out.push("`studio.moved_target` shift and rotation must be finite".into());
            }
        }
        if self.flash_relay_targets != 0
            && !(crate::survey_shots::LINK_MIN_TARGETS as u32..=MAX_RELAY_TARGETS)
                .contains(&self.flash_relay_targets)
        {
            out.push(format!(
                "`studio.flash_relay_targets` must be 0 (no relay) or in [{}, {MAX_RELAY_TARGETS}], \
                 got {}",
                crate::survey_shots::LINK_MIN_TARGETS,
                self.flash_relay_targets
            ));
        }
        if !(self.sheet_tilt_deg.is_finite()
            && (0.0..=MAX_SHEET_TILT_DEG).contains(&self.sheet_tilt_deg))
        {
            out.push(format!(
                "`studio.sheet_tilt_deg` must be in [0, {MAX_SHEET_TILT_DEG}], got {}",
                self.sheet_tilt_deg
            ));
        }
        if let Some(p) = &self.print_scale {
            if !(p.scale.is_finite() && (0.5..=2.0).contains(&p.scale)) {
                out.push(format!(
                    "`studio.print_scale.scale` must be in [0.5, 2] (a rig file's range), got {}",
                    p.scale
                ));
            }
        }
        if let Some(b) = &self.bent_sheet {
            if !(b.bend_deg.is_finite() && b.bend_deg != 0.0 && b.bend_deg.abs() <= MAX_BEND_DEG) {
                out.push(format!(
                    "`studio.bent_sheet.bend_deg` must be non-zero and within ±{MAX_BEND_DEG}, got {}",
                    b.bend_deg
                ));
            }
        }
        if let Some(d) = &self.duplicate_id {
            if d.id == d.printed_as {
                out.push(format!(
                    "`studio.duplicate_id`: `id` and `printed_as` are both {}",
                    d.id
                ));
            }
        }
        if self.headdress_band && self.declared_headdress_targets > 0 {
            out.push(
                "`studio.headdress_band` states the headdress as one unplaced band: \
                 `studio.declared_headdress_targets` must be 0"
                    .into(),
            );
        }
        if self.subsec_digits > 6 {
            out.push(format!(
                "`studio.subsec_digits` must be at most 6, got {}",
                self.subsec_digits
            ));
        }
        if !(self.camera_clock_offset_s.is_finite() && self.camera_clock_drift_ppm.is_finite()) {
            out.push("`studio.camera_clock_offset_s` and `_drift_ppm` must be finite".into());
        }
        for (f, v) in [
            ("sensor_width_mm", self.sensor_width_mm),
            ("exposure_time_s", self.exposure_time_s),
            ("f_number", self.f_number),
        ] {
            if !(v.is_finite() && v > 0.0) {
                out.push(format!("`studio.{f}` must be positive, got {v}"));
            }
        }
        if self.iso == 0 {
            out.push("`studio.iso` must be positive".into());
        }
        if !self
            .scan_formats
            .contains(&crate::textured_scan::ScanFormat::Obj)
        {
            out.push(format!(
                "`studio.scan_formats` must include \"obj\" (the studio's scan), got [{}]",
                self.scan_formats
                    .iter()
                    .map(|f| format!("\"{}\"", f.name()))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        if self.origin_targets == 0 {
            out.push("`studio.origin_targets` must be at least 1 (the world's origin)".into());
        }
        out
    }

    /// The Bayer phase named by `bayer`.
    pub fn bayer_phase(&self) -> Option<BayerPhase> {
        match self.bayer.to_ascii_lowercase().as_str() {
            "rggb" => Some(BayerPhase::Rggb),
            "bggr" => Some(BayerPhase::Bggr),
            "grbg" => Some(BayerPhase::Grbg),
            "gbrg" => Some(BayerPhase::Gbrg),
            _ => None,
        }
    }

    /// The exposure factor `t ISO / N²` of an exposure relative to the scene's settings.
    fn exposure_factor(&self, exposure_index: Option<u32>) -> (u32, f64) {
        match (&self.exposure_change, exposure_index) {
            (Some(c), Some(k)) if c.exposure_index == k => {
                (c.iso, f64::from(c.iso) / f64::from(self.iso))
            }
            _ => (self.iso, 1.0),
        }
    }
}

/// The capture record a controller writes for the scene's shot list, when no record is given:
/// the method's groups (measurement, light-position, reference-standard, standard-position),
/// one shot every `session.shot_interval_s` plus up to 0.6 s of flash recycle, on a device clock
/// that runs at real time (the simulator's time scale would compress the host times, which the
/// camera's clock does not).
pub fn planned_capture(scene: &Scene) -> CaptureRecord {
    let st = &scene.studio;
    let n = scene.session.measurement_images;
    let groups_spec = [
        ("measurement", ImageRole::Measurement, n),
        ("light-position", ImageRole::LightPosition, 3),
        ("reference-standard", ImageRole::ReferenceStandard, 1),
        ("standard-position", ImageRole::StandardPosition, 2),
    ];
    let interval_us = (scene.session.shot_interval_s * 1e6) as u64;
    let groups: Vec<ShotGroup> = groups_spec
        .iter()
        .map(|&(label, role, count)| ShotGroup {
            label: label.into(),
            role,
            count,
            min_interval_us: interval_us,
            pre_focus_us: 300_000,
            shutter_pulse_us: 100_000,
            xsync_timeout_us: 500_000,
            flash_ready_timeout_us: 10_000_000,
            flash_mode: FlashMode::CameraHotShoe,
        })
        .collect();
    let clock = ClockModel {
        device_ref_us: 0,
        host_ref_us: st.start_unix_s * 1e6 - 1.0e6,
        drift_ppm: 3.1,
        residual_rms_us: 18.0,
        samples: 40,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed ^ 0xc1a9_7e5d);
    let mut exposures = Vec::new();
    let mut t_us: u64 = 1_000_000;
    let mut index = 0u32;
    for (g, &(_, role, count)) in groups_spec.iter().enumerate() {
        for _ in 0..count {
            let shutter_command_us = t_us + 300_000;
            let lag_us = rng.random_range(55_000..70_000);
            let xsync = shutter_command_us + lag_us;
            let misfired = st.misfired_exposures.contains(&index);
            exposures.push(Exposure {
                index,
                group: g as u32,
                role,
                shutter_command_us,
                xsync_us: (!misfired).then_some(xsync),
                flash_fired_us: (!misfired).then_some(xsync + 180),
                recycle_us: (index > 0).then(|| rng.random_range(1_700_000..2_100_000)),
                outcome: if misfired {
                    ShotOutcome::MissingXsync
                } else {
                    ShotOutcome::Ok
                },
                host_time_us: clock.to_host_us(if misfired { shutter_command_us } else { xsync }),
                image: None,
            });
            index += 1;
            t_us += interval_us + rng.random_range(0..600_000);
        }
    }
    CaptureRecord {
        format_version: CAPTURE_FORMAT_VERSION,
        plan: CapturePlan {
            groups,
            max_retries: 0,
        },
        device: DeviceIdentity {
            protocol_version: 1,
            firmware_version: "synthetic".into(),
            serial: "SKB-SYNTH-0001".into(),
            kind: "synthetic".into(),
        },
        clock,
        exposures,
        complete: true,
    }
}

/// One file the camera wrote (or would have written, for a deleted one).
#[derive(Debug, Clone, PartialEq)]
pub struct CardFile {
    /// Path relative to the studio directory.
    pub file: String,
    /// The exposure it belongs to (`None`: a test shot).
    pub exposure_index: Option<u32>,
    /// Index of the shot (in the generator's list) whose render it carries.
    pub shot: usize,
    /// The camera's time stamp.
    pub time: CaptureTime,
    /// EXIF `ImageNumber`.
    pub shutter_count: u32,
    /// ISO of the shot.
    pub iso: u32,
    /// Exposure factor against the scene's settings, applied to the render (a survey shot's
    /// longer exposure is in its render already: 1 for it).
    pub exposure_factor: f64,
    /// Exposure time written in the file's EXIF, seconds.
    pub exposure_time_s: f64,
    /// False for a file deleted from the card (numbers used, nothing written).
    pub on_card: bool,
}

/// The camera's files in the order it wrote them: the survey shots (in [`SURVEY_DIR`], taken
/// [`crate::survey_shots::SURVEY_LEAD_S`] and more before the session, numbered before the
/// card's first file), then the card's: test shots before, one per exposure that fired (in the
/// record's order), test shots after.
pub fn card_files(scene: &Scene, rec: &CaptureRecord, shots: &[Shot]) -> Vec<CardFile> {
    let st = &scene.studio;
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed ^ 0x0ca3_d5e7);
    let fired: Vec<(&Exposure, usize)> = rec
        .exposures
        .iter()
        .filter_map(|e| {
            shots
                .iter()
                .position(|s| s.exposure_index == Some(e.index))
                .map(|k| (e, k))
        })
        .collect();
    let h0_s = fired
        .first()
        .map(|(e, _)| e.host_time_us * 1e-6)
        .unwrap_or(0.0);
    let last_s = fired
        .last()
        .map(|(e, _)| e.host_time_us * 1e-6)
        .unwrap_or(0.0);
    let camera_time = |h_s: f64, rng: &mut ChaCha8Rng| -> CaptureTime {
        let jitter: f64 = StandardNormal.sample(rng);
        let c = h_s
            + st.camera_clock_offset_s
            + st.camera_clock_drift_ppm * 1e-6 * (h_s - h0_s)
            + jitter * st.release_jitter_ms * 1e-3
            + f64::from(st.utc_offset_min) * 60.0;
        let whole = c.floor();
        let digits = st.subsec_digits;
        let subsec_digits = (digits > 0).then(|| {
            let scale = 10f64.powi(digits as i32);
            let frac = (((c - whole) * scale).floor() as u64).min(scale as u64 - 1);
            format!("{frac:0width$}", width = digits as usize)
        });
        CaptureTime {
            local: LocalDateTime::from_naive_seconds(whole as i64),
            subsec_digits,
            utc_offset_min: st.write_utc_offset.then_some(st.utc_offset_min),
        }
    };
    let mut out = Vec::new();
    // The survey shots, one file each: numbers and shutter counts just before the card's.
    let survey: Vec<usize> = (0..shots.len())
        .filter(|&k| shots[k].role == ImageRole::Survey)
        .collect();
    let n_survey = survey.len() as u32;
    for (k, &shot) in survey.iter().enumerate() {
        let back = n_survey - k as u32;
        let h = h0_s
            - crate::survey_shots::SURVEY_LEAD_S
            - f64::from(back) * crate::survey_shots::SURVEY_INTERVAL_S;
        out.push(CardFile {
            file: format!(
                "{SURVEY_DIR}/SKB_{:04}.DNG",
                dcf_number_before(st.first_file_number, back)
            ),
            exposure_index: None,
            shot,
            time: camera_time(h, &mut rng),
            shutter_count: st.first_shutter_count.saturating_sub(back),
            iso: st.iso,
            exposure_factor: 1.0,
            exposure_time_s: st.exposure_time_s * shots[shot].exposure_gain,
            on_card: true,
        });
    }
    let mut number = st.first_file_number;
    let mut count = st.first_shutter_count;
    let mut push = |exposure_index: Option<u32>, shot: usize, time: CaptureTime, on_card| {
        let (iso, factor) = st.exposure_factor(exposure_index);
        out.push(CardFile {
            file: format!("{CARD_FOLDER}/SKB_{:04}.DNG", number % 10_000),
            exposure_index,
            shot,
            time,
            shutter_count: count,
            iso,
            exposure_factor: factor,
            exposure_time_s: st.exposure_time_s,
            on_card,
        });
        number = if number >= 9999 { 1 } else { number + 1 };
        count += 1;
    };
    for k in 0..st.test_shots_before {
        let h = h0_s - 40.0 + 7.0 * f64::from(k);
        push(None, 0, camera_time(h, &mut rng), true);
    }
    for &(e, shot) in &fired {
        let t = camera_time(e.host_time_us * 1e-6, &mut rng);
        push(Some(e.index), shot, t, !st.missing_files.contains(&e.index));
    }
    for k in 0..st.test_shots_after {
        let h = last_s + 30.0 + 9.0 * f64::from(k);
        let last_shot = fired.last().map(|f| f.1).unwrap_or(0);
        push(None, last_shot, camera_time(h, &mut rng), true);
    }
    out
}

/// The DCF file number `back` files before `first` (numbers run 1..=9999 and roll over).
fn dcf_number_before(first: u32, back: u32) -> u32 {
    /// DCF file numbers per roll-over.
    const DCF_NUMBERS: i64 = 9999;
    ((i64::from(first) - 1 - i64::from(back)).rem_euclid(DCF_NUMBERS) + 1) as u32
}

/// The mosaicked sensor image of a render (see the module docs), with the studio's metadata.
pub fn mosaic(
    r: &Rendered,
    scene: &Scene,
    card: &CardFile,
    noise_free: bool,
    seed: u64,
) -> Result<DngImage, SynthError> {
    let st = &scene.studio;
    let phase = st.bayer_phase().ok_or_else(|| SynthError::Invalid {
        field: "studio.bayer",
        problem: format!("unknown Bayer phase `{}`", st.bayer),
    })?;
    let b = st.masked_border_px as usize;
    let (w, h) = (r.width as usize, r.height as usize);
    // Active-area photosites per rendered pixel, each way.
    let per_px = match st.mosaic {
        Mosaic::Quad => 2,
        Mosaic::Photosite => {
            if !(w.is_multiple_of(4) && h.is_multiple_of(4)) {
                return Err(SynthError::Invalid {
                    field: "studio.mosaic",
                    problem: format!(
                        "a photosite mosaic needs an image size in multiples of 4 (whole 2x2 quads, whole bytes per row), got {w}x{h}"
                    ),
                });
            }
            1
        }
    };
    let (sw, sh) = (per_px * w + 2 * b, per_px * h + 2 * b);
    let black = f64::from(st.raw_black_level);
    let white = f64::from(st.raw_white_level);
    let span = white - black;
    let full_well = scene.sensor.full_well_e;
    let read = scene.sensor.read_noise;
    let gains = st.channel_gains;
    let k = card.exposure_factor;
    let mut data = vec![0u16; sw * sh];
    data.par_chunks_mut(sw).enumerate().for_each(|(y, row)| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ ((y as u64) << 24) ^ 0x0d96_5eed);
        for (x, px) in row.iter_mut().enumerate() {
            let inside = x >= b && y >= b && x < b + per_px * w && y < b + per_px * h;
            let mean = if inside {
                let (ax, ay) = (x - b, y - b);
                let c = usize::from(phase.colour_at(ax, ay).dng_code());
                let v = f64::from(r.v[(ay / per_px) * w + ax / per_px][c]);
                v * gains[c] * k
            } else {
                0.0
            };
            let mut val = mean;
            if !noise_free {
                let sigma = (mean.max(0.0) / full_well + read * read).sqrt();
                let z: f64 = StandardNormal.sample(&mut rng);
                val += sigma * z;
            }
            let code = (black + val.min(1.0) * span).round().clamp(0.0, white);
            *px = code as u16;
        }
    });
    let mut img = DngImage::new(sw as u32, sh as u32, phase, st.raw_bits, data);
    img.active_area = (b > 0).then_some([
        b as u32,
        b as u32,
        (b + per_px * h) as u32,
        (b + per_px * w) as u32,
    ]);
    img.black_levels = [st.raw_black_level; 4];
    img.white_level = st.raw_white_level;
    img.make = st.make.clone();
    img.model = st.model.clone();
    img.unique_camera_model = format!("{} {}", st.make, st.model);
    img.body_serial = Some(st.body_serial.clone());
    img.lens_model = Some(st.lens_model.clone());
    img.exposure_time_s = Some(card.exposure_time_s);
    img.f_number = Some(st.f_number);
    img.iso = Some(card.iso);
    img.focal_length_mm = Some(focal_length_mm(scene));
    let pitch_mm = photosite_pitch_mm(scene);
    img.focal_plane_resolution = Some(FocalPlaneResolution::from_pitch_mm(
        pitch_mm,
        FocalPlaneUnit::Inch,
    ));
    img.focal_length_35mm_mm = Some(focal_length_35mm_mm(scene).round().clamp(1.0, 65535.0) as u16);
    img.capture_time = Some(card.time.clone());
    img.image_number = Some(card.shutter_count);
    Ok(img)
}

/// The lens's focal length for the scene's field of view on the studio's sensor width.
pub fn focal_length_mm(scene: &Scene) -> f64 {
    0.5 * scene.studio.sensor_width_mm / (0.5 * scene.camera.hfov_deg.to_radians()).tan()
}

/// The photosites' pitch, millimetres: the sensor's active area (`sensor_width_mm`) holds
/// [`photosites_per_pixel`] photosites per pixel of the scene's image. The DNG's focal-plane
/// resolution states it, so `focal_length_mm / pitch / 2` is the superpixel image's focal
/// length in pixels, as a real camera's tags give it.
pub fn photosite_pitch_mm(scene: &Scene) -> f64 {
    scene.studio.sensor_width_mm / (photosites_per_pixel(scene) * f64::from(scene.camera.width_px))
}

/// Active-area photosites per pixel of the scene's image, each way: 2 for a quad mosaic, 1 for
/// a photosite mosaic ([`Mosaic`]).
pub fn photosites_per_pixel(scene: &Scene) -> f64 {
    match scene.studio.mosaic {
        Mosaic::Quad => 2.0,
        Mosaic::Photosite => 1.0,
    }
}

/// The 35 mm equivalent focal length of the scene's lens on the studio's sensor, millimetres
/// (before EXIF rounds it to whole millimetres): the focal length scaled by the 36 x 24 mm
/// frame's diagonal over the active area's (square photosites, the image's aspect).
pub fn focal_length_35mm_mm(scene: &Scene) -> f64 {
    let c = &scene.camera;
    let diagonal_mm = photosite_pitch_mm(scene)
        * photosites_per_pixel(scene)
        * f64::from(c.width_px).hypot(f64::from(c.height_px));
    focal_length_mm(scene) * skinbrdf_raw::FULL_FRAME_DIAGONAL_MM / diagonal_mm
}

/// Where the studio keeps its sheets' layout files, relative to the studio directory (and so
/// to its rig files).
pub const LAYOUTS_DIR: &str = "layouts";

/// A sheet's layout file, relative to the studio directory.
pub fn layout_path(sheet: &PrintedSheet) -> String {
    format!("{LAYOUTS_DIR}/{}.layout.toml", sheet.name)
}

/// The rig-file group of a layout.
fn group_of(l: Layout) -> TargetGroup {
    match l {
        Layout::Reference => TargetGroup::Reference,
        Layout::Headdress => TargetGroup::Headdress,
        Layout::Flash => TargetGroup::Flash,
        Layout::Standard => TargetGroup::Standard,
    }
}

/// The target a duplicated id hides: printed with another's code, so the studio does not
/// know it exists and no rig file or layout lists it.
fn misprinted(scene: &Scene) -> Option<u32> {
    scene.studio.duplicate_id.as_ref().map(|d| d.id)
}

/// A sheet's layout file as the studio holds it: the nominal layout (printed sizes as
/// designed, whatever the printer did), without a misprinted target.
pub fn layout_file(scene: &Scene, sheet: &PrintedSheet) -> LayoutFile {
    let section = match sheet.layout {
        Layout::Headdress => "targets.headdress",
        _ => "targets.reference",
    };
    LayoutFile {
        section: section.into(),
        targets: sheet
            .targets
            .iter()
            .filter(|t| Some(t.id) != misprinted(scene))
            .cloned()
            .collect(),
    }
}

/// The layout file's text: a header like `skinbrdf targets` writes, then the layout.
pub fn layout_text(scene: &Scene, sheet: &PrintedSheet) -> Result<String, SynthError> {
    let text = toml::to_string(&layout_file(scene, sheet)).map_err(|e| SynthError::Invalid {
        field: "studio layout",
        problem: format!("cannot serialise the layout of sheet `{}`: {e}", sheet.name),
    })?;
    Ok(format!(
        "# Target layout of sheet `{}` of scene `{}` (sheet frame: origin at the sheet centre, x right,\n\
         # y up on the page, z out of the paper, metres; nominal printed sizes).\n{text}",
        sheet.name, scene.name
    ))
}

/// The parts every rig file of the scene shares: flash, standard, region of interest.
fn rig_base(scene: &Scene, rig: &Rig, description: String) -> RigFile {
    RigFile {
        format_version: RIG_FORMAT_VERSION,
        description,
        family: TAG_FAMILY.into(),
        sheets: Vec::new(),
        targets: Vec::new(),
        flash: RigFlash {
            diameter_m: scene.session.flash_diameter_m,
            light_centre_m: glam::DVec3::ZERO,
            light_position_m: None,
            world_from_flash: None,
        },
        standard: Some(RigStandard {
            brdf: scene.standard.brdf.clone(),
            size_m: [scene.standard.size_m; 2],
            world_from_standard: None,
        }),
        camera: None,
        roi: Some(skinbrdf_session::RegionOfInterest {
            centre_m: rig.roi_centre_head,
            radius_m: scene.geometry.roi_radius_m,
        }),
        geometry: crate::generate::analytic_geometry(scene),
    }
}

/// Every target of the rig by group, true corners, in rig order.
fn all_targets(rig: &Rig) -> impl Iterator<Item = (Layout, &Target)> {
    [
        (Layout::Reference, &rig.reference),
        (Layout::Headdress, &rig.headdress),
        (Layout::Flash, &rig.flash_targets),
        (Layout::Standard, &rig.standard_targets),
    ]
    .into_iter()
    .flat_map(|(l, list)| list.iter().map(move |t| (l, t)))
}

/// The rig as a studio that surveyed everything holds it (`rig-measured.toml`): every flat
/// sheet with its layout, its true pose and print scale; every other target a cut-out with its
/// true corners, the targets of a folded sheet and of the wrapped headdress band included
/// (their layouts do not describe them). A misprinted target is not listed.
pub fn rig_file(scene: &Scene, rig: &Rig) -> RigFile {
    let mut f = rig_base(
        scene,
        rig,
        format!(
            "synthetic studio rig of scene `{}`, surveyed: flat sheets placed by their layout, \
             pose and print scale, every other target a cut-out",
            scene.name
        ),
    );
    let on_rigid_sheet = |l: Layout, id: u32| rig.sheet_of(l, id).is_some_and(|s| s.rigid());
    for sheet in rig.sheets.iter().filter(|s| s.rigid()) {
        f.sheets.push(RigSheet {
            name: sheet.name.clone(),
            group: group_of(sheet.layout),
            layout: Some(layout_path(sheet)),
            group_from_sheet: Some(sheet.group_from_sheet),
            print_scale: Some(sheet.print_scale),
        });
    }
    for (l, t) in all_targets(rig) {
        if on_rigid_sheet(l, t.id) || (l == Layout::Reference && Some(t.id) == misprinted(scene)) {
            continue;
        }
        f.targets.push(RigTarget {
            id: t.id,
            size_m: t.size_m,
            group: group_of(l),
            sheet: None,
            corners_m: Some(t.corners_m),
        });
    }
    f
}

/// The rig as a studio that measured nothing holds it (`rig.toml`): every sheet with its layout
/// file and no placement, every other target with its printed size; placements only for what
/// the studio defines rather than measures: the world origin (`origin`: reference targets, a
/// sheet among them stated whole with its pose and print scale), the `declared_head` headdress
/// targets, and the flash ring and the standard's frame (their printed layouts define their
/// frames). The studio's head frame is its textured scan's (`scanner_from_head`): the region of
/// interest and any declared headdress target are given in it. A misprinted target is not
/// listed.
pub fn unmeasured_rig(
    scene: &Scene,
    rig: &Rig,
    origin: &[u32],
    declared_head: &[u32],
    scanner_from_head: &Pose,
) -> RigFile {
    let mut f = rig_base(
        scene,
        rig,
        format!(
            "synthetic studio rig of scene `{}`: the declared origin, the flash and the standard; \
             every other placement to survey",
            scene.name
        ),
    );
    let declared_sheet = |s: &PrintedSheet| {
        s.layout == Layout::Reference && s.rigid() && s.ids().iter().any(|id| origin.contains(id))
    };
    for sheet in &rig.sheets {
        let declared = declared_sheet(sheet);
        f.sheets.push(RigSheet {
            name: sheet.name.clone(),
            group: group_of(sheet.layout),
            layout: Some(layout_path(sheet)),
            group_from_sheet: declared.then_some(sheet.group_from_sheet),
            print_scale: declared.then_some(sheet.print_scale),
        });
    }
    for (l, t) in all_targets(rig) {
        if rig.sheet_of(l, t.id).is_some()
            || (l == Layout::Reference && Some(t.id) == misprinted(scene))
        {
            continue;
        }
        let corners_m = match l {
            Layout::Reference => origin.contains(&t.id).then_some(t.corners_m),
            Layout::Headdress => declared_head.contains(&t.id).then_some(t.corners_m),
            Layout::Flash | Layout::Standard => Some(t.corners_m),
        };
        f.targets.push(RigTarget {
            id: t.id,
            size_m: t.size_m,
            group: group_of(l),
            sheet: None,
            corners_m,
        });
    }
    in_scanner_frame(f, scanner_from_head)
}

/// Every sheet's truth (`truth.json`'s `sheets`).
pub fn sheet_truths(rig: &Rig) -> Vec<SheetTruth> {
    rig.sheets
        .iter()
        .map(|s| SheetTruth {
            name: s.name.clone(),
            group: group_of(s.layout),
            ids: s.ids(),
            group_from_sheet: (s.shape != SheetShape::Wrapped).then_some(s.group_from_sheet),
            print_scale: s.print_scale,
            tilt_deg: s.tilt_deg,
            bend_deg: match s.shape {
                SheetShape::Folded { bend_deg } => bend_deg,
                _ => 0.0,
            },
            rigid: s.rigid(),
        })
        .collect()
}

/// The reference targets `rig.toml` places as the studio's world origin: the bodies (a sheet
/// whole, or a cut-out) of the reference targets seen in the most shots, most-seen first, as
/// long as they hold at most `studio.origin_targets` targets together (a sheet that would
/// exceed it is passed over, so that a rig of sheets declares about as much as one of
/// cut-outs and its best-seen sheets are left to the survey; the first body is taken whatever
/// its size). A body the scene moves, misprints, folds or prints at another scale is never
/// the origin (a studio that knew would not choose it; the survey is to find those).
pub fn origin_ids(
    renderer: &crate::photograph::Renderer,
    rig: &Rig,
    shots: &[Shot],
    scene: &Scene,
) -> Vec<u32> {
    let st = &scene.studio;
    let mut excluded: Vec<u32> = Vec::new();
    if let Some(m) = &st.moved_target {
        excluded.extend(rig.reference_body(m.id));
    }
    if let Some(d) = &st.duplicate_id {
        excluded.extend(rig.reference_body(d.id));
        excluded.extend(rig.reference_body(d.printed_as));
    }
    for s in &rig.sheets {
        if !s.rigid() || s.print_scale != 1.0 {
            excluded.extend(s.ids());
        }
    }
    let want = st.origin_targets as usize;
    let mut out: Vec<u32> = Vec::new();
    for id in most_seen(renderer, rig, shots, Layout::Reference, usize::MAX) {
        if out.len() >= want {
            break;
        }
        if excluded.contains(&id) || out.contains(&id) {
            continue;
        }
        let body = rig.reference_body(id);
        if out.is_empty() || out.len() + body.len() <= want {
            out.extend(body);
        }
    }
    out
}

/// What of a scene's studio faults needs the rig to check: the sheets and targets they name
/// exist and carry the fault.
pub fn rig_problems(scene: &Scene, rig: &Rig) -> Vec<String> {
    let st = &scene.studio;
    let mut out = Vec::new();
    let sheets = || {
        let names: Vec<String> = rig
            .sheets
            .iter()
            .filter(|s| s.layout == Layout::Reference)
            .map(|s| s.name.clone())
            .collect();
        if names.is_empty() {
            "the rig has no reference sheet (`targets.reference_sheet_targets` = 1?)".to_string()
        } else {
            format!("the reference sheets are {}", names.join(", "))
        }
    };
    if let Some(p) = &st.print_scale {
        if !rig
            .find_sheet(&p.sheet)
            .is_some_and(|s| s.layout == Layout::Reference && s.print_scale == p.scale)
        {
            out.push(format!(
                "`studio.print_scale`: {} is not a reference sheet; {}",
                p.sheet,
                sheets()
            ));
        }
    }
    if let Some(b) = &st.bent_sheet {
        if !rig
            .find_sheet(&b.sheet)
            .is_some_and(|s| s.layout == Layout::Reference && !s.rigid())
        {
            out.push(format!(
                "`studio.bent_sheet`: {} is not a reference sheet; {}",
                b.sheet,
                sheets()
            ));
        }
    }
    if let Some(d) = &st.duplicate_id {
        for (field, id) in [("id", d.id), ("printed_as", d.printed_as)] {
            if !rig.reference.iter().any(|t| t.id == id) {
                out.push(format!(
                    "`studio.duplicate_id.{field}`: {id} is not a reference target"
                ));
            }
        }
    }
    if let Some(m) = &st.moved_target {
        if !rig.reference.iter().any(|t| t.id == m.id) {
            out.push(format!(
                "`studio.moved_target.id`: {} is not a reference target",
                m.id
            ));
        }
    }
    // The layout leaves out a relay target that would shadow the forehead or the standard (or
    // whose id would run into the headdress's): a relay smaller than asked is not the scene
    // that was written.
    let placed = rig.relay_ids.len();
    if placed != st.flash_relay_targets as usize {
        out.push(format!(
            "`studio.flash_relay_targets`: {} asked, {placed} placed (the others would shadow \
             the forehead or the standard from the flash, or their ids would reach the \
             headdress's)",
            st.flash_relay_targets
        ));
    }
    out
}

/// The flash stand's panel targets whose placement `rig.toml` states: all of them without a
/// relay (no image links the panel to the cage, so the studio measured it with the stand),
/// none with one (the link shots chain it to the cage and the survey places it).
pub fn stated_panel_ids(rig: &Rig) -> Vec<u32> {
    if rig.relay_ids.is_empty() {
        flash_panel_ids(rig)
    } else {
        Vec::new()
    }
}

/// The reference targets on the flash stand (the panel the light-position images see): the
/// light-position images see no other reference target, so without a relay
/// (`flash_relay_targets`) no image links the panel to the rest of the reference structure.
pub fn flash_panel_ids(rig: &Rig) -> Vec<u32> {
    let flash = rig.world_from_flash.translation_m;
    rig.reference
        .iter()
        .filter(|t| t.centre().distance(flash) < FLASH_PANEL_RADIUS_M)
        .map(|t| t.id)
        .collect()
}

/// Reference targets this close to the flash are its stand's panel, metres (the panel spans
/// about 0.2 m; the head's cage is 1.5 m away).
const FLASH_PANEL_RADIUS_M: f64 = 0.4;

/// The `n` targets of a group seen (usable) in the most shots, most-seen first (ties: lower id).
pub fn most_seen(
    renderer: &crate::photograph::Renderer,
    rig: &Rig,
    shots: &[Shot],
    layout: crate::layout::Layout,
    n: usize,
) -> Vec<u32> {
    let mut count: std::collections::BTreeMap<u32, usize> = std::collections::BTreeMap::new();
    for shot in shots {
        for (l, id, _) in crate::visibility::usable_targets(renderer, rig, shot) {
            if l == layout {
                *count.entry(id).or_insert(0) += 1;
            }
        }
    }
    let mut v: Vec<(u32, usize)> = count.into_iter().collect();
    v.sort_by_key(|(id, c)| (std::cmp::Reverse(*c), *id));
    v.into_iter().take(n).map(|(id, _)| id).collect()
}

/// Writes the studio's files other than the raw images: the capture record (without image
/// names), the sheets' layout files (`layouts/`), both rig files and the scan (copied from the
/// session). `origin` and `declared_head` are the targets `rig.toml` keeps placed
/// ([`unmeasured_rig`]).
pub fn write_studio_files(
    session_dir: &Path,
    scene: &Scene,
    rig: &Rig,
    rec: &CaptureRecord,
    origin: &[u32],
    declared_head: &[u32],
) -> Result<PathBuf, SynthError> {
    let dir = session_dir.join(STUDIO_DIR);
    let io = |path: &Path, source| skinbrdf_session::FileError::Io {
        path: path.to_path_buf(),
        source,
    };
    std::fs::create_dir_all(dir.join(CARD_FOLDER)).map_err(|e| io(&dir, e))?;
    let mut rec = rec.clone();
    for e in &mut rec.exposures {
        e.image = None;
    }
    skinbrdf_session::write_json_atomic(&dir.join("capture.json"), &rec)?;
    if !rig.sheets.is_empty() {
        let layouts = dir.join(LAYOUTS_DIR);
        std::fs::create_dir_all(&layouts).map_err(|e| io(&layouts, e))?;
    }
    for sheet in &rig.sheets {
        skinbrdf_session::write_atomic(
            &dir.join(layout_path(sheet)),
            layout_text(scene, sheet)?.as_bytes(),
        )?;
    }
    // A session states a raw camera in superpixel units (`skinbrdf_session::linear`).
    let stated_camera = match scene.studio.mosaic {
        Mosaic::Quad => rig.camera,
        Mosaic::Photosite => skinbrdf_raw::sensor_camera_to_superpixel(&rig.camera),
    };
    write_camera_file(&dir.join(CAMERA_FILE), &stated_camera)?;
    let scanner_from_head = scanner_from_head(scene);
    RigIo::write_file(
        &dir.join("rig-measured.toml"),
        &in_scanner_frame(rig_file(scene, rig), &scanner_from_head),
    )?;
    RigIo::write_file(
        &dir.join("rig.toml"),
        &unmeasured_rig(scene, rig, origin, declared_head, &scanner_from_head),
    )?;
    // A head is scanned (with its headdress, textured); an ideal sample's shape is in the rig.
    if crate::generate::analytic_geometry(scene).is_none() {
        write_scan_in_scanner_frame(scene, &session_dir.join("scan.ply"), &dir.join("scan.ply"))?;
        crate::textured_scan::write_textured_scan(&dir.join("scan"), scene, rig)?;
    }
    Ok(dir)
}

/// A rig file's head-frame placements (headdress sheets and targets, the region of interest)
/// moved into the scanner's frame, the one frame of every file in `studio/`: the studio's
/// truth then scores a session ingested with any of its rigs and scans.
pub fn in_scanner_frame(mut f: RigFile, scanner_from_head: &Pose) -> RigFile {
    if let Some(roi) = f.roi.as_mut() {
        roi.centre_m = scanner_from_head.transform_point(roi.centre_m);
    }
    for sheet in f
        .sheets
        .iter_mut()
        .filter(|s| s.group == TargetGroup::Headdress)
    {
        sheet.group_from_sheet = sheet.group_from_sheet.map(|p| *scanner_from_head * p);
    }
    for t in f
        .targets
        .iter_mut()
        .filter(|t| t.group == TargetGroup::Headdress)
    {
        t.corners_m = t
            .corners_m
            .map(|c| c.map(|p| scanner_from_head.transform_point(p)));
    }
    f
}

/// Writes the session's scan (`from`, head frame, in the scene's scan units) as the studio's
/// `scan.ply` in the scanner's frame (see [`in_scanner_frame`]).
fn write_scan_in_scanner_frame(scene: &Scene, from: &Path, to: &Path) -> Result<(), SynthError> {
    let (mut mesh, _) = skinbrdf_mesh::read_ply(from)?;
    let units = scene.geometry.scan_units;
    let m_per_unit = units.to_m();
    let scanner_from_head = scanner_from_head(scene);
    for p in &mut mesh.positions {
        let q = scanner_from_head.transform_point(p.as_dvec3() * m_per_unit) / m_per_unit;
        *p = q.as_vec3();
    }
    if let Some(normals) = mesh.normals.as_mut() {
        for n in normals.iter_mut() {
            *n = scanner_from_head.transform_vector(n.as_dvec3()).as_vec3();
        }
    }
    skinbrdf_mesh::write_ply_binary_in(to, &mesh, crate::generate::unit_name(units))?;
    Ok(())
}

/// Writes the camera's calibration as a studio keeps it from an earlier calibration: the
/// `[camera]` table of `session.toml` alone.
fn write_camera_file(path: &Path, camera: &skinbrdf_core::CameraModel) -> Result<(), SynthError> {
    #[derive(Serialize)]
    struct CameraFile {
        camera: skinbrdf_session::CameraSpec,
    }
    let body = toml::to_string(&CameraFile {
        camera: skinbrdf_session::CameraSpec::Calibrated(*camera),
    })
    .map_err(|e| SynthError::Invalid {
        field: "camera",
        problem: format!("cannot be written as TOML: {e}"),
    })?;
    let text = format!("# The camera's calibration (intrinsics and distortion), as `skinbrdf ingest --camera` reads it.\n{body}");
    skinbrdf_session::write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// The frame the studio states head-frame placements in: the textured scan's (the scanner's
/// own frame) for a head; the head frame itself for an ideal sample, which has no scan.
pub fn scanner_from_head(scene: &Scene) -> Pose {
    if crate::generate::analytic_geometry(scene).is_some() {
        Pose::IDENTITY
    } else {
        crate::textured_scan::scanner_from_head(scene)
    }
}

/// Headdress targets the studio's rig declares: the scene's number, and for an ideal sample
/// (no scan to register the headdress to) at least [`IDEAL_SAMPLE_DECLARED_HEADDRESS`].
pub fn declared_headdress_count(scene: &Scene) -> usize {
    let n = scene.studio.declared_headdress_targets as usize;
    if crate::generate::analytic_geometry(scene).is_some() {
        n.max(IDEAL_SAMPLE_DECLARED_HEADDRESS)
    } else {
        n
    }
}

/// Without a scan, the sample's frame is fixed by the headdress targets the rig places (a
/// calibration sphere's mount with its printed targets): three spread ones fix it without a
/// single tag's orientation error.
pub const IDEAL_SAMPLE_DECLARED_HEADDRESS: usize = 3;

/// Writes one card file's raw image (nothing for a deleted file).
pub fn write_card_file(
    studio_dir: &Path,
    r: &Rendered,
    scene: &Scene,
    card: &CardFile,
    noise_free: bool,
    seed: u64,
) -> Result<(), SynthError> {
    if !card.on_card {
        return Ok(());
    }
    let img = mosaic(r, scene, card, noise_free, seed)?;
    let path = studio_dir.join(&card.file);
    write_dng(&path, &img).map_err(|source| SynthError::Raw { source })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_relay_is_none_or_two_to_twelve_targets() {
        let mut scene = Scene::load("default").expect("scene");
        let max = MAX_RELAY_TARGETS;
        for (n, ok) in [
            (0, true),
            (1, false),
            (2, true),
            (max, true),
            (max + 1, false),
        ] {
            scene.studio.flash_relay_targets = n;
            let p = scene.studio.problems();
            assert_eq!(
                p.iter().all(|m| !m.contains("flash_relay_targets")),
                ok,
                "{n}: {p:?}"
            );
        }
    }

    #[test]
    fn every_scene_places_the_relay_it_asks_for() {
        for (name, _) in crate::scene::BUILTIN_SCENES {
            let scene = Scene::load(name).expect("scene");
            let rig = crate::layout::build_rig(&scene);
            assert_eq!(
                rig.relay_ids.len(),
                scene.studio.flash_relay_targets as usize,
                "{name}"
            );
            assert!(rig_problems(&scene, &rig).is_empty(), "{name}");
        }
    }

    #[test]
    fn a_relay_short_of_what_was_asked_is_a_problem() {
        let scene = Scene::load("default").expect("scene");
        let mut rig = crate::layout::build_rig(&scene);
        assert!(rig_problems(&scene, &rig).is_empty());
        rig.relay_ids.pop();
        let p = rig_problems(&scene, &rig);
        assert!(
            p.len() == 1 && p[0].contains("flash_relay_targets") && p[0].contains("placed"),
            "{p:?}"
        );
    }

    #[test]
    fn a_moved_target_is_printed_where_its_corners_are() {
        let scene = Scene::load("default").expect("scene");
        let rig = crate::layout::build_rig(&scene);
        let id = rig.reference[5].id;
        let m = MovedTarget {
            id,
            from_shot: 3,
            shift_mm: [3.0, 0.0, -1.5],
            rotate_deg: 2.0,
        };
        let before = rig.reference[5];
        let after = m
            .apply(&rig)
            .reference
            .into_iter()
            .find(|t| t.id == id)
            .expect("still there");
        // The renderer prints the tag around `centre()`: it must be the corners' centre.
        let mean = after.corners_m.iter().copied().sum::<glam::DVec3>() * 0.25;
        assert!(after.centre().distance(mean) < 1e-12);
        let shift = after.centre() - before.centre();
        assert!((shift * 1e3 - glam::DVec3::new(3.0, 0.0, -1.5)).length() < 1e-9);
    }

    #[test]
    fn the_card_numbers_every_actuation_and_keeps_deleted_numbers() {
        let mut scene = Scene::load("default").expect("scene");
        scene.studio.missing_files = vec![3];
        scene.studio.test_shots_after = 1;
        let rig = crate::layout::build_rig(&scene);
        let rec = planned_capture(&scene);
        let shots = crate::layout::shots_from_capture(&scene, &rig, &rec);
        let card = card_files(&scene, &rec, &shots);
        assert_eq!(card.len(), shots.len() + 2);
        assert!(card[0].exposure_index.is_none());
        let deleted: Vec<_> = card.iter().filter(|c| !c.on_card).collect();
        assert_eq!(deleted.len(), 1);
        assert_eq!(deleted[0].exposure_index, Some(3));
        for w in card.windows(2) {
            assert_eq!(w[1].shutter_count, w[0].shutter_count + 1);
            assert!(w[1].time.naive_seconds() >= w[0].time.naive_seconds());
        }
    }

    #[test]
    fn camera_times_follow_the_host_clock_by_the_offset() {
        let scene = Scene::load("default").expect("scene");
        let rig = crate::layout::build_rig(&scene);
        let rec = planned_capture(&scene);
        let shots = crate::layout::shots_from_capture(&scene, &rig, &rec);
        let card = card_files(&scene, &rec, &shots);
        let st = &scene.studio;
        for c in card.iter().filter(|c| c.exposure_index.is_some()) {
            let e = &rec.exposures[c.exposure_index.unwrap_or(0) as usize];
            let utc = c.time.unix_seconds().expect("offset written");
            let d = utc - e.host_time_us * 1e-6 - st.camera_clock_offset_s;
            // Truncation to the sub-second digits, the drift over the session (< 3 ms) and the
            // release jitter (a few sigma).
            let tol_s =
                10f64.powi(-(st.subsec_digits as i32)) + 3e-3 + 5.0 * st.release_jitter_ms * 1e-3;
            assert!(d.abs() < tol_s, "{} off by {d} s", c.file);
        }
    }
}
