//! Simulator configuration: hardware models, fault injection, clock.

use crate::SimError;

/// Camera model: the shutter line to X-sync delay is uniform in
/// `[shutter_lag_min_us, shutter_lag_max_us]` (a DSLR: 60-120 ms including mirror and shutter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraModel {
    /// Shortest shutter lag.
    pub shutter_lag_min_us: u64,
    /// Longest shutter lag.
    pub shutter_lag_max_us: u64,
}

impl CameraModel {
    /// A typical DSLR.
    pub const DSLR: CameraModel = CameraModel {
        shutter_lag_min_us: 60_000,
        shutter_lag_max_us: 120_000,
    };
}

/// Flash model. Recycle time grows linearly with the power setting, from
/// `recycle_min_us` at power 0 to `recycle_max_us` at full power (studio flashes: ~0.5-3 s),
/// with a relative jitter. The flash fires only while ready; it drops its ready signal when it
/// fires and raises it once recycled. It is triggered by whichever comes first of the
/// controller's flash-trigger output and the camera's X-sync (hot shoe): the simulator wires
/// it to both, which matches either plan flash mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlashModel {
    /// Power setting in `[0, 1]`.
    pub power: f64,
    /// Recycle at power 0.
    pub recycle_min_us: u64,
    /// Recycle at full power.
    pub recycle_max_us: u64,
    /// Relative recycle jitter (uniform `±`).
    pub recycle_jitter: f64,
    /// Trigger to light on the photodiode.
    pub trigger_to_light_us: u64,
}

impl FlashModel {
    /// A studio flash at half power (recycle ~1.75 s).
    pub const STUDIO_HALF_POWER: FlashModel = FlashModel {
        power: 0.5,
        recycle_min_us: 500_000,
        recycle_max_us: 3_000_000,
        recycle_jitter: 0.05,
        trigger_to_light_us: 40,
    };

    /// Nominal (jitter-free) recycle time at the configured power.
    pub fn nominal_recycle_us(&self) -> u64 {
        let span = self.recycle_max_us.saturating_sub(self.recycle_min_us) as f64;
        self.recycle_min_us + (span * self.power.clamp(0.0, 1.0)).round() as u64
    }
}

/// Drop the link once `after_records` records exist, for `duration_us` of device time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkDrop {
    /// Records produced before the drop.
    pub after_records: u32,
    /// How long the link stays down (device time).
    pub duration_us: u64,
}

/// Fault injection. All probabilities are in `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Faults {
    /// The flash never reports ready.
    pub flash_never_ready: bool,
    /// The camera never fires (no X-sync).
    pub camera_not_firing: bool,
    /// Probability that one shutter press does not fire the camera.
    pub camera_fail_probability: f64,
    /// Probability that a triggered, ready flash does not emit light (misfire).
    pub misfire_probability: f64,
    /// Drop the link mid-session.
    pub link_drop: Option<LinkDrop>,
    /// Probability that one device-to-host frame has a byte flipped.
    pub corrupt_to_host_probability: f64,
    /// Probability that one device-to-host frame is cut short (its tail and delimiter lost).
    pub truncate_to_host_probability: f64,
    /// Probability that one chunk of host-to-device bytes has a byte flipped.
    pub corrupt_to_device_probability: f64,
    /// A slow host: the link drains at most this many bytes per second of device time, so the
    /// device's transmit queue backs up and drops events (records survive in the ring).
    pub host_bytes_per_s: Option<u64>,
}

/// Everything the simulator needs.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Camera model.
    pub camera: CameraModel,
    /// Flash model.
    pub flash: FlashModel,
    /// Fault injection.
    pub faults: Faults,
    /// Device time at start (use a value beyond `2^32` to exercise the u64 clock).
    pub start_us: u64,
    /// Simulated seconds per wall-clock second (1 = real time; 50 = fifty times faster).
    pub time_scale: f64,
    /// RNG seed (the simulation is deterministic for a given seed and input timing).
    pub seed: u64,
    /// Serial string reported in the handshake.
    pub serial: String,
    /// Bytes the device-to-host buffer holds before the device stops draining the sequencer
    /// (a USB CDC endpoint plus the host's tty buffer).
    pub tx_buffer_bytes: usize,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            camera: CameraModel::DSLR,
            flash: FlashModel::STUDIO_HALF_POWER,
            faults: Faults::default(),
            start_us: 1_000_000,
            time_scale: 1.0,
            seed: 1,
            serial: "SIM-0001".into(),
            tx_buffer_bytes: 4096,
        }
    }
}

impl SimConfig {
    /// Checks ranges; names the offending field.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |field: &'static str, problem: String| Err(SimError::Config { field, problem });
        if self.camera.shutter_lag_min_us > self.camera.shutter_lag_max_us {
            return bad(
                "camera.shutter_lag_min_us",
                format!(
                    "{} exceeds shutter_lag_max_us {}",
                    self.camera.shutter_lag_min_us, self.camera.shutter_lag_max_us
                ),
            );
        }
        if !(0.0..=1.0).contains(&self.flash.power) {
            return bad(
                "flash.power",
                format!("{} is outside [0, 1]", self.flash.power),
            );
        }
        if self.flash.recycle_min_us > self.flash.recycle_max_us {
            return bad("flash.recycle_min_us", "exceeds recycle_max_us".to_string());
        }
        if !(0.0..1.0).contains(&self.flash.recycle_jitter) {
            return bad(
                "flash.recycle_jitter",
                format!("{} is outside [0, 1)", self.flash.recycle_jitter),
            );
        }
        let probs = [
            (
                "faults.camera_fail_probability",
                self.faults.camera_fail_probability,
            ),
            (
                "faults.misfire_probability",
                self.faults.misfire_probability,
            ),
            (
                "faults.corrupt_to_host_probability",
                self.faults.corrupt_to_host_probability,
            ),
            (
                "faults.truncate_to_host_probability",
                self.faults.truncate_to_host_probability,
            ),
            (
                "faults.corrupt_to_device_probability",
                self.faults.corrupt_to_device_probability,
            ),
        ];
        for (field, p) in probs {
            if !(0.0..=1.0).contains(&p) {
                return bad(field, format!("probability {p} is outside [0, 1]"));
            }
        }
        if self.faults.host_bytes_per_s == Some(0) {
            return bad("faults.host_bytes_per_s", "must be positive".to_string());
        }
        if !(self.time_scale.is_finite() && self.time_scale > 0.0) {
            return bad(
                "time_scale",
                format!("{} must be finite and positive", self.time_scale),
            );
        }
        if self.tx_buffer_bytes < skinbrdf_protocol::MAX_FRAME_LEN {
            return bad(
                "tx_buffer_bytes",
                format!(
                    "must hold one frame ({} bytes)",
                    skinbrdf_protocol::MAX_FRAME_LEN
                ),
            );
        }
        Ok(())
    }
}
