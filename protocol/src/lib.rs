//! Wire protocol between the trigger controller and the host: postcard messages in COBS frames
//! with a CRC (`no_std`, no allocation).
//!
//! * [`messages`]: every type on the wire. The host sends [`Request`]s (each with a `seq`); the
//!   device answers each with exactly one [`Response`] (same `seq`, `Ok` body or typed
//!   [`DeviceError`]) and sends [`Event`]s (exposure records, flash-ready changes, faults, log
//!   lines, group/session completion). Both directions of the device's output are wrapped in
//!   [`DeviceMessage`].
//! * [`frame`]: the framing, `COBS(postcard ‖ CRC-32 LE) ‖ 0x00`, with [`encode`] and the
//!   resynchronising streaming [`FrameDecoder`].
//! * [`limits`]: the fixed sizes (frame length, string capacities, group count) that make every
//!   message fit [`MAX_FRAME_LEN`] bytes, so `heapless` buffers hold any frame.
//!
//! * `pipe` (feature `std`): the in-process byte pipe that the host's memory transport and
//!   the simulator's in-process link share.
//!
//! `docs/protocol.md` specifies the format byte by byte; `tests/golden.rs` pins it.
#![no_std]

#[cfg(any(test, feature = "std"))]
extern crate std;

pub mod frame;
pub mod messages;
#[cfg(feature = "std")]
pub mod pipe;

pub use frame::{
    decode_frame_in_place, encode, encode_to_vec, DecoderStats, EncodeError, FrameDecoder,
    FrameError, CRC32, CRC_LEN,
};
/// The `heapless` version the message types use (`String<N>`, `Vec<T, N>`).
pub use heapless;
pub use limits::*;
pub use messages::*;

/// Protocol version; the device refuses a `Hello` with a different one
/// ([`DeviceError::VersionMismatch`]). Bump on any incompatible change of the wire format.
pub const PROTOCOL_VERSION: u32 = 1;

/// Shortest time the device keeps the camera's focus and shutter lines released between two
/// presses. A camera needs its remote contacts open for some 10-50 ms to register a new press
/// (bodies differ; 50 ms covers the slow ones), and a press that follows a release sooner is
/// merged into the previous one: the camera sees one long press and takes one picture. The
/// device enforces this whatever the plan says (a plan whose interval is shorter is shot
/// with presses spaced by this time, and the device logs a warning when it loads such a plan);
/// the host's plan check rejects such plans with the numbers to fix.
pub const MIN_SHUTTER_OFF_US: u64 = 50_000;

/// Longest host watchdog the device accepts ([`RequestBody::SetWatchdog`]): larger values,
/// and `0` (which once meant "disabled"), are set to this. A session must always end by itself
/// when its host is gone; ten minutes is far longer than any pause of a working host.
pub const MAX_WATCHDOG_US: u64 = 600_000_000;

/// Fixed sizes of the protocol.
pub mod limits {
    /// Largest encoded frame in bytes, **including** the `0x00` delimiter. Every message of
    /// this crate fits (the largest, `LoadPlan` with [`MAX_GROUPS`] full groups, needs 768
    /// bytes; a test checks the worst cases). Receivers size their decoder buffer to this.
    pub const MAX_FRAME_LEN: usize = 1024;
    /// Most groups in a plan.
    pub const MAX_GROUPS: usize = 8;
    /// Capacity of a group label, bytes of UTF-8.
    pub const LABEL_LEN: usize = 24;
    /// Capacity of a log line, bytes of UTF-8.
    pub const LOG_LINE_LEN: usize = 96;
    /// Capacity of the firmware version string.
    pub const FIRMWARE_VERSION_LEN: usize = 16;
    /// Capacity of the serial string.
    pub const SERIAL_LEN: usize = 24;
}

/// Checks the device's handshake answer against this crate's [`PROTOCOL_VERSION`].
pub fn check_version(info: &DeviceInfo) -> Result<(), DeviceError> {
    if info.protocol_version == PROTOCOL_VERSION {
        Ok(())
    } else {
        Err(DeviceError::VersionMismatch {
            device: info.protocol_version,
            host: PROTOCOL_VERSION,
        })
    }
}

/// Copies `text` into a fixed-capacity string, truncating at a character boundary.
pub fn truncated<const N: usize>(text: &str) -> heapless::String<N> {
    let mut out = heapless::String::new();
    for ch in text.chars() {
        if out.push(ch).is_err() {
            break;
        }
    }
    out
}

impl core::fmt::Display for DeviceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::VersionMismatch { device, host } => write!(
                f,
                "protocol version mismatch: device speaks {device}, host speaks {host}"
            ),
            Self::HandshakeRequired => write!(f, "handshake (Hello) required first"),
            Self::Busy => write!(f, "a session is running"),
            Self::NoPlan => write!(f, "no plan loaded"),
            Self::InvalidPlan { group, problem } => {
                write!(f, "invalid plan: group {group}: {problem:?}")
            }
            Self::BadGroupRange { groups, next_group } => write!(
                f,
                "bad group range: the plan has {groups} groups, the next one to run is {next_group}"
            ),
            Self::UnackedRecords { unacked } => {
                write!(
                    f,
                    "{unacked} records of the previous session are unacknowledged"
                )
            }
            Self::AckBeyondEnd { next_index } => {
                write!(f, "ack beyond the last record (next index {next_index})")
            }
            Self::AlreadyAcked { oldest_held } => {
                write!(
                    f,
                    "records were acknowledged already (oldest held {oldest_held})"
                )
            }
            Self::SessionAborted => write!(f, "the session was aborted; load a plan again"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DeviceError {}
