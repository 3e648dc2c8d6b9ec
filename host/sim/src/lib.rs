//! **The firmware simulator**: a stand-in for the trigger controller board. It runs the
//! firmware's own sequencer (`skinbrdf-sequencer`, the code the RP2040 image runs, not a
//! re-implementation) with a simulated clock and models of the attached camera and flash,
//! behind a pseudo-terminal or an in-process link, so host software (`skinbrdf capture`, the
//! conformance suite) talks to it exactly as to a board. It lives under `host/` only because it
//! runs on the host machine; it is device-side code.
//!
//! * [`SimDevice`]: deterministic, sans-IO. The sequencer plus a camera ([`CameraModel`]:
//!   shutter lag uniform in 60-120 ms, X-sync), a flash ([`FlashModel`]: recycle 0.5-3 s by
//!   power with jitter, ready signal, photodiode), and the byte link with the protocol's
//!   [`FrameDecoder`](skinbrdf_protocol::FrameDecoder). Fault injection ([`Faults`]): flash
//!   never ready, camera not firing (always or with a probability), misfires, a link drop
//!   mid-session, corrupted and truncated frames, a slow host. Tests drive it step by step.
//! * [`spawn_pty`] / [`spawn_in_process`]: the same device on a thread, device time =
//!   start + wall time × [`SimConfig::time_scale`] (1 = real time, 50 = fifty times faster,
//!   so tests never sleep for seconds). Host requests are timed by their arrival; hardware
//!   events are processed at their exact simulated times regardless of thread scheduling.
//!
//! What the simulator does *not* model: USB enumeration (there is no DTR on a pty; the host's
//! `Hello` starts a connection), edge-capture latency (timestamps are exact), and the time the
//! firmware needs to run (zero).

mod config;
mod device;
mod link;

pub use config::{CameraModel, Faults, FlashModel, LinkDrop, SimConfig};
pub use device::{SimDevice, SimStats};
pub use link::{
    memory_link, spawn, spawn_in_process, spawn_pty, DevicePort, EndReason, HostLink,
    MemoryDevicePort, PtyPort, SimHandle, SimReport,
};

/// Everything that can go wrong starting or running the simulator.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A configuration value is out of range.
    #[error("simulator config: {field}: {problem}")]
    Config {
        /// The field.
        field: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// The pseudo-terminal could not be created.
    #[error("cannot create a pseudo-terminal: {problem}")]
    Pty {
        /// The OS error.
        problem: String,
    },
    /// I/O on the link failed.
    #[error("simulator link: {what}")]
    Io {
        /// What was being done.
        what: &'static str,
        /// The error.
        #[source]
        source: std::io::Error,
    },
    /// The simulator thread panicked.
    #[error("the simulator thread panicked")]
    Poisoned,
}
