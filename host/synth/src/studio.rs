//! A synthetic studio: exactly what a studio holds after a capture, so that the path from the
//! camera's card to a session (`skinbrdf ingest`) is tested end to end without a camera.
//!
//! `skinbrdf synth --studio` writes, beside the PNG session and its truth, `S/studio/`:
//!
//! ```text
//! studio/
//!   card/DCIM/100SKBRF/SKB_NNNN.DNG   the camera's raw files (Bayer CFA, EXIF)
//!   capture.json                      the controller's record (no image names: it never knew them)
//!   rig-measured.toml                 the rig with its true placements, head frame (a surveyed
//!                                     rig, for scan.ply)
//!   rig.toml                          what a studio states before any survey: the declared
//!                                     origin, the printed flash and standard layouts, the flash
//!                                     stand's panel and the ROI, in the textured scan's frame
//!   scan.ply                          the head scan, head frame (already registered)
//!   scan/head.obj, head.mtl, head.png the textured scan in the scanner's frame, headdress
//!                                     included (crate::textured_scan), scan-truth.json
//!   truth.json                        the truth with the head frame the textured scan's (for
//!                                     scoring a session ingested with scan/head.obj)
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
//! # Camera clock
//!
//! The camera's clock runs off the controller's host clock by a scene-set offset and drift:
//! `t_camera = h + offset + drift (h - h_0)` for an exposure at host time `h` (its X-sync,
//! through the controller's clock model), plus a few milliseconds of release jitter, written
//! as a local date-time with the scene's UTC offset, `SubSecTimeOriginal` with the scene's
//! number of digits (none: whole seconds, truncated as cameras do) and `OffsetTimeOriginal`.
//! Test shots (before and after the session) and deleted files (an exposure whose file is
//! missing from the card) advance the file number and the shutter count like real actuations.

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use skinbrdf_core::Pose;
use skinbrdf_raw::dng::{write_dng, DngImage};
use skinbrdf_raw::{BayerPhase, CaptureTime, LocalDateTime};
use skinbrdf_session::capture::{
    CapturePlan, CaptureRecord, ClockModel, DeviceIdentity, Exposure, FlashMode, ImageRole,
    ShotGroup, ShotOutcome, CAPTURE_FORMAT_VERSION,
};
use skinbrdf_session::rig::{RigFile, RigFlash, RigStandard, RigTarget, RIG_FORMAT_VERSION};
use skinbrdf_session::{Rig as RigIo, Target, TargetGroup, TAG_FAMILY};

use crate::generate::SynthError;
use crate::layout::{Rig, Shot};
use crate::photograph::Rendered;
use crate::scene::Scene;

/// The studio directory inside a synthetic session.
pub const STUDIO_DIR: &str = "studio";
/// The card's image folder inside the studio directory.
pub const CARD_FOLDER: &str = "card/DCIM/100SKBRF";

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
    pub moved_target: Option<MovedTarget>,
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
    /// Width of the sensor's active area, millimetres (sets the focal length in EXIF).
    pub sensor_width_mm: f64,
    /// Exposure time, seconds (the flash's X-sync speed).
    pub exposure_time_s: f64,
    /// Aperture f-number.
    pub f_number: f64,
    /// ISO.
    pub iso: u32,
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
    /// The rig after the move: the target's corners shifted and turned about its centre.
    pub fn apply(&self, rig: &Rig) -> Rig {
        let mut moved = rig.clone();
        for t in moved.reference.iter_mut().filter(|t| t.id == self.id) {
            let c = t.centre();
            let turn =
                glam::DQuat::from_axis_angle(t.outward_normal(), self.rotate_deg.to_radians());
            let shift = glam::DVec3::from_array(self.shift_mm) * 1e-3;
            t.corners_m = t.corners_m.map(|p| c + shift + turn * (p - c));
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
                "`studio.channel_gains` must be positive, got {:?}",
                self.channel_gains
            ));
        }
        if let Some(m) = &self.moved_target {
            if !(m.shift_mm.iter().all(|v| v.is_finite()) && m.rotate_deg.is_finite()) {
                out.push("`studio.moved_target` shift and rotation must be finite".into());
            }
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
    /// Exposure factor against the scene's settings.
    pub exposure_factor: f64,
    /// False for a file deleted from the card (numbers used, nothing written).
    pub on_card: bool,
}

/// The card's files in the order the camera wrote them: test shots before, one per exposure
/// that fired (in the record's order), test shots after.
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
    let (sw, sh) = (2 * w + 2 * b, 2 * h + 2 * b);
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
            let inside = x >= b && y >= b && x < b + 2 * w && y < b + 2 * h;
            let mean = if inside {
                let (ax, ay) = (x - b, y - b);
                let c = usize::from(phase.colour_at(ax, ay).dng_code());
                let v = f64::from(r.v[(ay / 2) * w + ax / 2][c]);
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
    img.active_area =
        (b > 0).then_some([b as u32, b as u32, (b + 2 * h) as u32, (b + 2 * w) as u32]);
    img.black_levels = [st.raw_black_level; 4];
    img.white_level = st.raw_white_level;
    img.make = st.make.clone();
    img.model = st.model.clone();
    img.unique_camera_model = format!("{} {}", st.make, st.model);
    img.body_serial = Some(st.body_serial.clone());
    img.lens_model = Some(st.lens_model.clone());
    img.exposure_time_s = Some(st.exposure_time_s);
    img.f_number = Some(st.f_number);
    img.iso = Some(card.iso);
    img.focal_length_mm = Some(focal_length_mm(scene));
    img.capture_time = Some(card.time.clone());
    img.image_number = Some(card.shutter_count);
    Ok(img)
}

/// The lens's focal length for the scene's field of view on the studio's sensor width.
pub fn focal_length_mm(scene: &Scene) -> f64 {
    0.5 * scene.studio.sensor_width_mm / (0.5 * scene.camera.hfov_deg.to_radians()).tan()
}

/// The rig as the studio's files state it, with the true placements.
pub fn rig_file(scene: &Scene, rig: &Rig) -> RigFile {
    let mut targets = Vec::new();
    let mut add = |group: TargetGroup, list: &[Target]| {
        for t in list {
            targets.push(RigTarget {
                id: t.id,
                size_m: t.size_m,
                group,
                sheet: None,
                corners_m: Some(t.corners_m),
            });
        }
    };
    add(TargetGroup::Reference, &rig.reference);
    add(TargetGroup::Headdress, &rig.headdress);
    add(TargetGroup::Flash, &rig.flash_targets);
    add(TargetGroup::Standard, &rig.standard_targets);
    RigFile {
        format_version: RIG_FORMAT_VERSION,
        description: format!(
            "synthetic studio rig of scene `{}`: every target a cut-out",
            scene.name
        ),
        family: TAG_FAMILY.into(),
        sheets: Vec::new(),
        targets,
        flash: RigFlash {
            diameter_m: scene.session.flash_diameter_m,
            light_centre_m: glam::DVec3::ZERO,
        },
        standard: Some(RigStandard {
            brdf: scene.standard.brdf.clone(),
            size_m: [scene.standard.size_m; 2],
        }),
        roi: Some(skinbrdf_session::RegionOfInterest {
            centre_m: rig.roi_centre_head,
            radius_m: scene.geometry.roi_radius_m,
        }),
    }
}

/// The rig as a studio that measured nothing holds it: every placement removed except what
/// the studio defines rather than measures: the world origin (the `origin` reference targets),
/// the `declared_head` headdress targets, and the flash ring and the standard's frame (their
/// printed layouts define their frames). The studio's head frame is its textured scan's
/// (`scanner_from_head`): the region of interest and any declared headdress target are given
/// in it.
pub fn unmeasured_rig(
    measured: &RigFile,
    origin: &[u32],
    declared_head: &[u32],
    scanner_from_head: &Pose,
) -> RigFile {
    let mut f = RigIo::without_placements(measured);
    for (t, m) in f.targets.iter_mut().zip(&measured.targets) {
        let keep = match t.group {
            TargetGroup::Reference => origin.contains(&t.id),
            TargetGroup::Headdress => declared_head.contains(&t.id),
            TargetGroup::Flash | TargetGroup::Standard => true,
        };
        if keep {
            t.corners_m = match t.group {
                TargetGroup::Headdress => m
                    .corners_m
                    .map(|c| c.map(|p| scanner_from_head.transform_point(p))),
                _ => m.corners_m,
            };
        }
    }
    if let Some(roi) = f.roi.as_mut() {
        roi.centre_m = scanner_from_head.transform_point(roi.centre_m);
    }
    f
}

/// The reference targets on the flash stand (the panel the light-position images see): the
/// light-position images see no other reference target, so no image links the panel to the
/// rest of the reference structure, and the studio states its placement (measured with the
/// stand) instead of surveying it.
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
/// names), both rig files and the scan (copied from the session). `origin` and
/// `declared_head` are the targets `rig.toml` keeps placed ([`unmeasured_rig`]).
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
    let measured = rig_file(scene, rig);
    RigIo::write_file(&dir.join("rig-measured.toml"), &measured)?;
    RigIo::write_file(
        &dir.join("rig.toml"),
        &unmeasured_rig(
            &measured,
            origin,
            declared_head,
            &crate::textured_scan::scanner_from_head(scene),
        ),
    )?;
    let scan = session_dir.join("scan.ply");
    let bytes = std::fs::read(&scan).map_err(|e| io(&scan, e))?;
    skinbrdf_session::write_atomic(&dir.join("scan.ply"), &bytes)?;
    crate::textured_scan::write_textured_scan(&dir.join("scan"), scene, rig)?;
    Ok(dir)
}

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
