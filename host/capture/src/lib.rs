//! Host side of the trigger controller: serial link, request/response client, clock model,
//! capture records.
//!
//! * [`plan`]: `plan.toml` loading with strict validation and precise errors.
//! * [`clock`]: device-to-host clock model (offset + drift by least squares over round-trip
//!   clock reads), with its residual in microseconds.
//! * [`store`]: the atomic `capture.json` writer (temp file + rename after every shot).
//! * [`transport`]: the byte link ([`Transport`]): serial ports and an in-memory pair.
//! * [`ports`]: listing serial ports and recognising our controllers by USB VID/PID.

pub mod clock;
pub mod plan;
pub mod ports;
pub mod store;
pub mod transport;

pub use clock::{device_rate, fit_clock, ClockError, ClockRead};
pub use plan::{load_plan, parse_plan, validate_plan, PlanError};
pub use ports::{list_ports, PortListing};
/// The wire protocol crate, re-exported for observers and tests.
pub use skinbrdf_protocol as protocol;
pub use store::{read_capture, CaptureWriter, StoreError};
pub use transport::{memory_pair, MemoryTransport, SerialTransport, Transport, TransportError};

pub mod client;
pub mod session;

pub use client::{Client, ClientError};
pub use session::{
    run_capture, CaptureError, CaptureObserver, CaptureOptions, Connector, GroupDecision,
    OnceConnector, RunSummary, SerialConnector, Unattended,
};
