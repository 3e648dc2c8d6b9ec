//! Every message on the wire.
//!
//! Two top-level types travel: [`Request`] (host to device) and [`DeviceMessage`] (device to
//! host: either the one [`Response`] to a request or an unsolicited [`Event`]). Their postcard
//! encoding is the wire format; `docs/protocol.md` spells out the byte layout and the golden
//! vectors in `tests/golden.rs` pin it. **Variant order is part of the format**: add new variants
//! only at the end of an enum and bump [`PROTOCOL_VERSION`](crate::PROTOCOL_VERSION) for any
//! other change.
//!
//! All times are the device's free-running microsecond clock as `u64` (`*_us`), which does not
//! wrap for 584 000 years. Durations are `u64` microseconds too.

use heapless::{String, Vec};
use serde::{Deserialize, Serialize};

use crate::limits::{FIRMWARE_VERSION_LEN, LABEL_LEN, LOG_LINE_LEN, MAX_GROUPS, SERIAL_LEN};

// ---------------------------------------------------------------------------------------------
// Plan
// ---------------------------------------------------------------------------------------------

/// What an image (and its exposure) is for. Maps 1:1 to `skinbrdf_session::ImageRole`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ImageRole {
    /// The ~30 images of the forehead from around the circle.
    Measurement,
    /// Images that locate the flash (its targets).
    LightPosition,
    /// The calibrated reflectance standard under the flash.
    ReferenceStandard,
    /// Images that locate the reference standard.
    StandardPosition,
}

/// How the flash is fired. Maps 1:1 to `skinbrdf_session::FlashMode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum FlashMode {
    /// The camera fires the flash through its hot shoe; the controller only watches
    /// (X-sync input and photodiode).
    CameraHotShoe,
    /// The controller asserts its flash-trigger output when it sees the camera's X-sync edge.
    ControllerOnXsync,
}

/// One group of shots. Maps 1:1 to `skinbrdf_session::ShotGroup` plus `flash_window_us`
/// (which the session file does not carry; use [`ShotGroup::DEFAULT_FLASH_WINDOW_US`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShotGroup {
    /// Human-readable label ("measurement", "light-position", ...), at most [`LABEL_LEN`] bytes.
    pub label: String<LABEL_LEN>,
    /// The role of the images this group produces.
    pub role: ImageRole,
    /// Number of shots (retries are extra attempts of the same shot).
    pub count: u32,
    /// Minimum time between consecutive shutter commands.
    pub min_interval_us: u64,
    /// Time the focus line is held before the shutter line is asserted (0: no pre-focus).
    pub pre_focus_us: u64,
    /// Shutter pulse width (focus stays held during the pulse).
    pub shutter_pulse_us: u64,
    /// How long after the shutter command the X-sync edge may come.
    pub xsync_timeout_us: u64,
    /// How long to wait for the flash to report ready before a shot.
    pub flash_ready_timeout_us: u64,
    /// How long after the X-sync edge the photodiode must see the flash.
    pub flash_window_us: u64,
    /// How the flash is fired.
    pub flash_mode: FlashMode,
}

impl ShotGroup {
    /// A sensible photodiode window: flash tubes reach peak within ~1 ms of the trigger, the
    /// extra margin covers slow optoisolators and the camera's own X-sync-to-flash delay.
    pub const DEFAULT_FLASH_WINDOW_US: u64 = 20_000;
}

/// What to do once a shot has used up its retries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ExhaustedAction {
    /// Abort the session (all outputs released, `SessionDone { outcome: Faulted }`).
    AbortSession,
    /// Give up on this shot (its fault records stay) and continue with the next one.
    SkipShot,
}

/// Retry/abort policy for faulted shots (missing X-sync, missing flash, flash not ready).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct FaultPolicy {
    /// Extra attempts allowed per shot; each attempt is a new record with a new index.
    pub max_retries: u32,
    /// What happens when the retries are used up.
    pub on_exhausted: ExhaustedAction,
}

/// A capture plan as loaded into the device.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Plan {
    /// Groups in the order they are shot, at most [`MAX_GROUPS`].
    pub groups: Vec<ShotGroup, MAX_GROUPS>,
    /// Retry/abort policy for faulted shots.
    pub policy: FaultPolicy,
    /// Width of the flash-trigger pulse in [`FlashMode::ControllerOnXsync`].
    pub flash_trigger_pulse_us: u64,
}

impl Plan {
    /// Total number of planned shots (without retries).
    pub fn total_shots(&self) -> u64 {
        self.groups.iter().map(|g| u64::from(g.count)).sum()
    }
}

// ---------------------------------------------------------------------------------------------
// Host -> device
// ---------------------------------------------------------------------------------------------

/// A host-to-device request. The device answers every request with exactly one [`Response`]
/// carrying the same `seq`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Request {
    /// Host-chosen sequence number, echoed in the response.
    pub seq: u32,
    /// What is asked.
    pub body: RequestBody,
}

/// What a request asks. Variant 0 (`Hello`) is frozen across protocol versions.
///
/// `LoadPlan` makes this enum ~730 bytes; without an allocator there is nothing to box it
/// into, and a device handles one request at a time, so the size is paid once.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum RequestBody {
    /// Handshake. Must come first on every connection; answered by
    /// [`ResponseBody::Hello`] or [`DeviceError::VersionMismatch`].
    Hello {
        /// [`PROTOCOL_VERSION`](crate::PROTOCOL_VERSION) of the host.
        protocol_version: u32,
    },
    /// Read the device clock (for clock offset/drift fits); answered by [`ResponseBody::Clock`].
    ReadClock,
    /// Load a plan (only when no session runs); answered by [`ResponseBody::PlanLoaded`].
    /// Loading a plan starts a new session: record indices restart at 0 once all previous
    /// records are acknowledged (otherwise [`DeviceError::UnackedRecords`]).
    LoadPlan(Plan),
    /// Run groups `first_group..=last_group` of the loaded plan, then stop and emit
    /// [`Event::GroupsDone`] (plus [`Event::SessionDone`] after the last group of the plan).
    /// Lets the host prompt the operator between groups.
    Run {
        /// First group to run (index into the plan).
        first_group: u32,
        /// Last group to run (inclusive).
        last_group: u32,
    },
    /// Abort the running session; every output is released. Idempotent.
    Abort,
    /// The host holds every record with `index < next_index`; the device may forget them.
    AckRecords {
        /// One past the highest index the host holds (contiguously from 0).
        next_index: u32,
    },
    /// Resend every unacknowledged record with `index >= from_index` as [`Event::Record`]s
    /// (after the response).
    FetchRecords {
        /// First index wanted.
        from_index: u32,
    },
    /// Keep-alive; feeds the host watchdog. Answered by [`ResponseBody::Pong`].
    Ping,
    /// Set the host watchdog: a running session aborts after this long without any valid
    /// request. `0` and values above [`crate::MAX_WATCHDOG_US`] set that maximum (a session
    /// must never be left running with nobody able to stop it); the answer carries the
    /// timeout in force.
    SetWatchdog {
        /// Host silence that aborts a session.
        timeout_us: u64,
    },
    /// Read the device status; answered by [`ResponseBody::Status`].
    GetStatus,
}

// ---------------------------------------------------------------------------------------------
// Device -> host
// ---------------------------------------------------------------------------------------------

/// Everything the device sends.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum DeviceMessage {
    /// The one response to a request.
    Response(Response),
    /// Something that happened.
    Event(Event),
}

/// The response to the request with the same `seq`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Response {
    /// The request's sequence number.
    pub seq: u32,
    /// Ok body or typed error (postcard: variant 0 = `Ok`, 1 = `Err`).
    pub result: Result<ResponseBody, DeviceError>,
}

/// What kind of device answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum DeviceKind {
    /// A real RP2040 board.
    Board,
    /// The host-side firmware simulator.
    Simulator,
    /// The firmware image in an emulator.
    Emulator,
}

/// The device's identity, from the handshake.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceInfo {
    /// Protocol version the device speaks.
    pub protocol_version: u32,
    /// Firmware version string (e.g. `"0.1.0"`).
    pub firmware_version: String<FIRMWARE_VERSION_LEN>,
    /// Device serial string (the USB serial number on a board).
    pub serial: String<SERIAL_LEN>,
    /// Board, simulator or emulator.
    pub kind: DeviceKind,
    /// Device clock when the handshake was answered.
    pub clock_us: u64,
}

/// What the sequencer is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum SessionState {
    /// No plan loaded.
    Idle,
    /// A plan is loaded and no group is running.
    Ready,
    /// Groups are running.
    Running,
    /// The plan ran to its end.
    Completed,
    /// The session was aborted (by the host, the watchdog or a fault).
    Aborted,
}

/// Device status snapshot.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Status {
    /// Device clock.
    pub now_us: u64,
    /// Session state.
    pub state: SessionState,
    /// Index the next record will get.
    pub next_index: u32,
    /// Records held unacknowledged in the ring buffer.
    pub unacked: u32,
    /// Oldest unacknowledged index, if any.
    pub oldest_unacked: Option<u32>,
    /// Flash-ready input level.
    pub flash_ready: bool,
    /// Frames the device could not decode since boot (CRC, COBS, oversize).
    pub bad_frames: u32,
    /// Outgoing messages dropped because the transmit queue was full (records are never lost:
    /// they stay in the ring buffer).
    pub dropped_messages: u32,
    /// Host watchdog timeout (0: disabled).
    pub watchdog_us: u64,
}

/// The successful answer to a request.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum ResponseBody {
    /// Answer to [`RequestBody::Hello`].
    Hello(DeviceInfo),
    /// Answer to [`RequestBody::ReadClock`].
    Clock {
        /// Device time when the request was handled.
        device_us: u64,
    },
    /// Answer to [`RequestBody::LoadPlan`].
    PlanLoaded {
        /// Planned shots (without retries).
        total_shots: u32,
    },
    /// Answer to [`RequestBody::Run`].
    Running {
        /// Index the first record of this run will get.
        first_index: u32,
    },
    /// Answer to [`RequestBody::Abort`].
    Aborted {
        /// True if a session was running.
        was_running: bool,
    },
    /// Answer to [`RequestBody::AckRecords`].
    Acked {
        /// Records still unacknowledged.
        unacked: u32,
    },
    /// Answer to [`RequestBody::FetchRecords`]; `count` [`Event::Record`]s follow.
    Fetching {
        /// Number of records that will be resent.
        count: u32,
    },
    /// Answer to [`RequestBody::Ping`].
    Pong {
        /// Device time.
        device_us: u64,
    },
    /// Answer to [`RequestBody::SetWatchdog`].
    WatchdogSet {
        /// The timeout now in force.
        timeout_us: u64,
    },
    /// Answer to [`RequestBody::GetStatus`].
    Status(Status),
}

impl ResponseBody {
    /// The answer's name in words, for messages (`hello`, `clock`, ...).
    pub const fn name(&self) -> &'static str {
        match self {
            Self::Hello(_) => "hello",
            Self::Clock { .. } => "clock",
            Self::PlanLoaded { .. } => "plan loaded",
            Self::Running { .. } => "running",
            Self::Aborted { .. } => "aborted",
            Self::Acked { .. } => "records acknowledged",
            Self::Fetching { .. } => "fetching records",
            Self::Pong { .. } => "pong",
            Self::WatchdogSet { .. } => "watchdog set",
            Self::Status(_) => "status",
        }
    }
}

/// What is wrong with a plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum PlanProblem {
    /// The plan has no groups.
    NoGroups,
    /// A group has `count == 0`.
    ZeroCount,
    /// A group has `shutter_pulse_us == 0`.
    ZeroShutterPulse,
    /// `xsync_timeout_us` is 0.
    ZeroXsyncTimeout,
    /// `flash_window_us` is 0.
    ZeroFlashWindow,
    /// `flash_trigger_pulse_us` is 0 but a group uses `ControllerOnXsync`.
    ZeroFlashTriggerPulse,
    /// The plan has more than `u32::MAX` shots.
    TooManyShots,
}

/// A typed error answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum DeviceError {
    /// The host's protocol version differs from the device's.
    VersionMismatch {
        /// What the device speaks.
        device: u32,
        /// What the host asked for.
        host: u32,
    },
    /// A request other than `Hello` came before a successful handshake.
    HandshakeRequired,
    /// A session is running; abort it first.
    Busy,
    /// `Run` without a loaded plan.
    NoPlan,
    /// The plan is invalid.
    InvalidPlan {
        /// Index of the offending group (0 for plan-level problems).
        group: u32,
        /// What is wrong.
        problem: PlanProblem,
    },
    /// `Run` names groups outside the plan, or `first_group > last_group`, or groups already
    /// shot.
    BadGroupRange {
        /// Number of groups in the plan.
        groups: u32,
        /// The next group that may run.
        next_group: u32,
    },
    /// `LoadPlan` while records of the previous session are still unacknowledged.
    UnackedRecords {
        /// How many.
        unacked: u32,
    },
    /// `AckRecords` acknowledges indices that were never produced.
    AckBeyondEnd {
        /// Index the next record will get.
        next_index: u32,
    },
    /// `FetchRecords` asks for records that were acknowledged (and forgotten) already.
    AlreadyAcked {
        /// Oldest index still held.
        oldest_held: u32,
    },
    /// The session was aborted after a fault and must be reloaded.
    SessionAborted,
}

/// How a shot ended. Maps 1:1 to `skinbrdf_session::ShotOutcome`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ShotOutcome {
    /// Shutter, X-sync and flash all seen.
    Ok,
    /// No X-sync edge within the timeout: the camera did not fire.
    MissingXsync,
    /// X-sync seen but no flash on the photodiode within the window: misfire.
    MissingFlash,
    /// The flash never reported ready within the timeout; no shutter command was issued.
    FlashNotReady,
    /// The session was aborted during this shot.
    Aborted,
}

/// One exposure attempt.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExposureRecord {
    /// Index in the session (0-based; every attempt, retries included, gets its own index).
    pub index: u32,
    /// Group index in the plan.
    pub group: u32,
    /// Shot number within the group (0-based; retries repeat it).
    pub shot: u32,
    /// Attempt number of this shot (0 = first try).
    pub attempt: u32,
    /// Role of the group.
    pub role: ImageRole,
    /// Device time the attempt began (waiting for the interval and flash ready).
    pub started_us: u64,
    /// Device time the shutter line was asserted (`None` if it never was).
    pub shutter_command_us: Option<u64>,
    /// Device time of the X-sync edge, if seen.
    pub xsync_us: Option<u64>,
    /// Device time of the photodiode edge (flash fired), if seen.
    pub flash_fired_us: Option<u64>,
    /// Recycle time before this shot: from the previous flash to flash-ready, if measured.
    pub recycle_us: Option<u64>,
    /// How the attempt ended.
    pub outcome: ShotOutcome,
}

/// Why the device raised a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum FaultKind {
    /// No X-sync edge within the timeout.
    MissingXsync,
    /// No photodiode edge within the flash window.
    MissingFlash,
    /// The flash did not become ready within the timeout.
    FlashNotReady,
    /// A shot used up its retries; the policy decides what follows.
    RetriesExhausted,
    /// No valid request within the watchdog timeout: the session was aborted.
    HostSilent,
}

/// A fault. Every fault releases all outputs before it is reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Fault {
    /// When it was detected.
    pub at_us: u64,
    /// What happened.
    pub kind: FaultKind,
    /// The record index of the affected attempt, if any.
    pub index: Option<u32>,
}

/// Log severity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum LogLevel {
    /// Debug detail.
    Debug,
    /// Normal operation.
    Info,
    /// Something odd.
    Warn,
    /// Something failed.
    Error,
}

/// How a session ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum SessionOutcome {
    /// Every planned shot was taken (faulted shots included when the policy skipped them).
    Completed,
    /// Aborted by the host.
    Aborted,
    /// Aborted by a fault (retries exhausted with `AbortSession`, or host watchdog).
    Faulted,
}

/// Something that happened on the device.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum Event {
    /// One exposure attempt (also resent by `FetchRecords`).
    Record(ExposureRecord),
    /// The flash-ready input changed.
    FlashReady {
        /// When.
        at_us: u64,
        /// New level: true = ready, false = recycling.
        ready: bool,
        /// On a rising edge after a flash: time from that flash to ready.
        recycle_us: Option<u64>,
    },
    /// A fault.
    Fault(Fault),
    /// A log line.
    Log {
        /// When.
        at_us: u64,
        /// Severity.
        level: LogLevel,
        /// Text (truncated to [`LOG_LINE_LEN`] bytes).
        text: String<LOG_LINE_LEN>,
    },
    /// A `Run` finished its groups (and no fault aborted it).
    GroupsDone {
        /// When.
        at_us: u64,
        /// The last group that ran.
        last_group: u32,
        /// Index the next record will get.
        next_index: u32,
    },
    /// The session ended.
    SessionDone {
        /// When.
        at_us: u64,
        /// How.
        outcome: SessionOutcome,
        /// Records produced in this session.
        records: u32,
    },
}
