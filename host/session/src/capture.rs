//! `capture.json`: the trigger controller's record of a session.
//!
//! Written by `skinbrdf capture` (atomically, after every shot) and read by the synthetic
//! generator (which renders one image per recorded exposure, so a simulated capture drives the
//! synthetic session) and by the pipeline (which pairs images with exposures).
//!
//! Device times are the controller's free-running microsecond clock (`u64`, never wraps in
//! practice). Host times are Unix microseconds obtained through the fitted [`ClockModel`].

use serde::{Deserialize, Serialize};

/// Current `capture.json` format version.
pub const CAPTURE_FORMAT_VERSION: u32 = 1;

/// What an image (and its exposure) is for, as in the method's session (section 4.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ImageRole {
    /// The ~30 images of the forehead from around the circle.
    Measurement,
    /// Images that locate the flash (its targets).
    LightPosition,
    /// The calibrated reflectance standard under the flash (radiometric calibration).
    ReferenceStandard,
    /// Images that locate the reference standard.
    StandardPosition,
    /// Images that strengthen the placement survey's geometry: taken by hand without the
    /// subject or the flash (room light), from wherever they see the targets the measurement
    /// arc sees poorly. Used by the placement survey (and the camera calibration when the
    /// camera is to be calibrated) only; never fired by the trigger controller, so never in a
    /// capture record or a capture plan.
    Survey,
}

impl ImageRole {
    /// The role's name in files (`measurement`, `light-position`, `reference-standard`,
    /// `standard-position`, `survey`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Measurement => "measurement",
            Self::LightPosition => "light-position",
            Self::ReferenceStandard => "reference-standard",
            Self::StandardPosition => "standard-position",
            Self::Survey => "survey",
        }
    }

    /// Whether the trigger controller fires images of this role (every role but
    /// [`ImageRole::Survey`]: survey images are taken by hand, without the flash).
    pub const fn fired_by_controller(self) -> bool {
        !matches!(self, Self::Survey)
    }

    /// Whether the subject (head and headdress) is in images of this role: in every role but
    /// [`ImageRole::Survey`], taken before the subject sits. Head tracking uses only these.
    pub const fn has_subject(self) -> bool {
        !matches!(self, Self::Survey)
    }
}

/// How the flash is fired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FlashMode {
    /// The camera fires the flash through its hot shoe; the controller only watches.
    CameraHotShoe,
    /// The controller fires the flash when it sees the camera's X-sync.
    ControllerOnXsync,
}

/// One group of shots in a capture plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShotGroup {
    /// Human-readable label ("measurement", "light-position", ...).
    pub label: String,
    /// The role of the images this group produces.
    pub role: ImageRole,
    /// Number of shots.
    pub count: u32,
    /// Minimum time between shutter commands.
    pub min_interval_us: u64,
    /// Time the focus line is held before the shutter.
    pub pre_focus_us: u64,
    /// Shutter pulse width.
    pub shutter_pulse_us: u64,
    /// How long to wait for the X-sync edge after the shutter command.
    pub xsync_timeout_us: u64,
    /// How long to wait for the flash to report ready before a shot.
    pub flash_ready_timeout_us: u64,
    /// How the flash is fired.
    pub flash_mode: FlashMode,
}

/// A capture plan (`plan.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CapturePlan {
    /// Groups in the order they are shot.
    pub groups: Vec<ShotGroup>,
    /// Retries allowed for a shot whose X-sync or flash is missing before the session aborts.
    #[serde(default)]
    pub max_retries: u32,
}

/// The controller's identity, from the handshake.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceIdentity {
    /// Protocol version the device speaks.
    pub protocol_version: u32,
    /// Firmware version string.
    pub firmware_version: String,
    /// Device serial string (USB serial number).
    pub serial: String,
    /// "board", "simulator" or "emulator".
    pub kind: String,
}

/// Affine map from device microseconds to host Unix microseconds,
/// `host_us = host_ref_us + (device_us - device_ref_us) * (1 + drift_ppm * 1e-6)`,
/// fitted by least squares to round-trip clock reads (midpoint of each round trip).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClockModel {
    /// Device time of the reference point.
    pub device_ref_us: u64,
    /// Host Unix time of the reference point.
    pub host_ref_us: f64,
    /// Device clock rate error relative to the host, parts per million.
    pub drift_ppm: f64,
    /// RMS residual of the fit, microseconds.
    pub residual_rms_us: f64,
    /// Number of round-trip reads the fit used.
    pub samples: u32,
}

impl ClockModel {
    /// Maps a device time to host Unix microseconds.
    pub fn to_host_us(&self, device_us: u64) -> f64 {
        let dt = device_us as f64 - self.device_ref_us as f64;
        self.host_ref_us + dt * (1.0 + self.drift_ppm * 1e-6)
    }
}

/// How a shot ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ShotOutcome {
    /// Shutter, X-sync and flash all seen.
    Ok,
    /// No X-sync edge within the timeout: the camera did not fire.
    MissingXsync,
    /// X-sync seen but no flash on the photodiode: misfire.
    MissingFlash,
    /// The flash never reported ready within the timeout.
    FlashNotReady,
    /// The session was aborted during this shot.
    Aborted,
}

impl ShotOutcome {
    /// The outcome in words, for messages.
    pub const fn describe(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::MissingXsync => "no X-sync (the camera did not fire)",
            Self::MissingFlash => "no flash seen (misfire)",
            Self::FlashNotReady => "the flash was not ready",
            Self::Aborted => "aborted",
        }
    }
}

/// One exposure, as the controller reported it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Exposure {
    /// Index of the shot in the session (0-based, counting retries as new shots).
    pub index: u32,
    /// Index of the group in the plan.
    pub group: u32,
    /// Role of the image.
    pub role: ImageRole,
    /// Device time the shutter line was asserted.
    pub shutter_command_us: u64,
    /// Device time of the hot-shoe X-sync edge, if seen.
    pub xsync_us: Option<u64>,
    /// Device time of the flash photodiode edge, if seen.
    pub flash_fired_us: Option<u64>,
    /// Time from the previous flash to flash-ready, if measured.
    pub recycle_us: Option<u64>,
    /// Outcome.
    pub outcome: ShotOutcome,
    /// `xsync_us` (or `shutter_command_us`) mapped to host Unix microseconds by the clock model.
    pub host_time_us: f64,
    /// Image file for this exposure, relative to the session directory, once known.
    #[serde(default)]
    pub image: Option<String>,
}

/// The whole `capture.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureRecord {
    /// Format version ([`CAPTURE_FORMAT_VERSION`]).
    pub format_version: u32,
    /// The plan that was run.
    pub plan: CapturePlan,
    /// Who captured it.
    pub device: DeviceIdentity,
    /// Device-to-host clock mapping.
    pub clock: ClockModel,
    /// Every exposure, in index order, faults included.
    pub exposures: Vec<Exposure>,
    /// True once the plan ran to its end (false for an interrupted session).
    pub complete: bool,
}

#[cfg(test)]
mod tests {
    use super::ImageRole;

    #[test]
    fn a_role_is_named_as_files_name_it() {
        for role in [
            ImageRole::Measurement,
            ImageRole::LightPosition,
            ImageRole::ReferenceStandard,
            ImageRole::StandardPosition,
            ImageRole::Survey,
        ] {
            let json = serde_json::to_string(&role).expect("serialises");
            assert_eq!(json, format!("\"{}\"", role.name()));
        }
    }
}
