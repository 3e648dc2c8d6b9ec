//! End-to-end and conformance tests: one set of protocol and session cases, many devices.
//!
//! A [`Backend`] is something that speaks the controller protocol on a serial port:
//!
//! * [`BackendKind::Sim`]: the firmware simulator (`skinbrdf-sim`) on a pseudo-terminal, fifty
//!   times faster than real time. Always runs.
//! * [`BackendKind::Emulator`]: the real firmware image in rp2040js via `tests/emulator/harness.js`
//!   (engineer h2's harness), as fast as the emulator goes. Runs when `SKINBRDF_EMULATOR=1`
//!   (needs the ELF built by `firmware/rp2040/build.sh` and `npm ci` in `tests/emulator`).
//! * [`BackendKind::Hil`]: a real board on the port named by `SKINBRDF_HIL_PORT`, with a camera
//!   and flash attached (or their stand-ins, see `docs/capture.md`).
//!
//! Each case in `tests/conformance.rs` asks [`start`] for a device with a [`Scenario`] (fault
//! injection); a backend that cannot produce the scenario (a board cannot be told to misfire)
//! or is not enabled returns `None` after printing why, and the case passes as skipped.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use skinbrdf_capture::transport::{SerialTransport, Transport, TransportError};
use skinbrdf_capture::CaptureOptions;
use skinbrdf_session::capture::{CapturePlan, FlashMode, ImageRole, ShotGroup};

/// Environment variable that enables the emulator backend.
pub const EMULATOR_ENV: &str = "SKINBRDF_EMULATOR";
/// Environment variable naming the firmware ELF for the emulator (default: the harness's own
/// default, `$CARGO_TARGET_DIR` or `firmware/rp2040/target`, release build).
pub const EMULATOR_ELF_ENV: &str = "SKINBRDF_EMULATOR_ELF";
/// Environment variable naming a real board's serial port.
pub const HIL_PORT_ENV: &str = "SKINBRDF_HIL_PORT";
/// Simulated seconds per wall second for the simulator backend.
pub const SIM_TIME_SCALE: f64 = 50.0;
/// Device start time of the simulator: beyond 2^32 us, so every test exercises the u64 clock.
pub const SIM_START_US: u64 = (1 << 32) + 123_456_789;

/// Which device a case runs against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendKind {
    /// The firmware simulator.
    Sim,
    /// The firmware image in rp2040js.
    Emulator,
    /// A real board.
    Hil,
}

/// Fault injection a case needs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Scenario {
    /// The flash never reports ready.
    pub flash_never_ready: bool,
    /// The camera never fires.
    pub camera_not_firing: bool,
    /// Silence the link once this many records exist, for this long (device us).
    pub link_silence: Option<(u32, u64)>,
    /// Probability that a device-to-host frame arrives with a flipped byte.
    pub corrupt_to_host: f64,
}

impl Scenario {
    /// True when the scenario needs fault injection.
    pub fn injects_faults(&self) -> bool {
        *self != Self::default()
    }
}

/// A running device.
pub trait Backend: Send {
    /// Which kind.
    fn kind(&self) -> BackendKind;
    /// The `DeviceInfo.kind` the device reports ("simulator", "emulator", "board").
    fn device_kind(&self) -> &'static str;
    /// Serial port path.
    fn port(&self) -> String;
    /// Opens a fresh link (again after a disconnect).
    fn connect(&self) -> Result<Box<dyn Transport>, TransportError> {
        Ok(Box::new(SerialTransport::open(&self.port())?))
    }
    /// Capture options suited to this device's speed.
    fn options(&self) -> CaptureOptions;
    /// True when the camera/flash are models with known timing (sim, emulator).
    fn modelled_hardware(&self) -> bool;
    /// Device times (us, fractional) at which the hardware model asserted input `signal`
    /// (`xsync`, `photodiode`), when the backend knows them independently of the firmware.
    fn input_edges_us(&self, _signal: &str) -> Option<Vec<f64>> {
        None
    }
    /// Sends a fault-injection command to the device's environment (the emulator harness's
    /// JSON commands, e.g. `{"cmd":"hang"}`); false if the backend cannot.
    fn inject(&self, _json: &str) -> bool {
        false
    }
}

/// Serialises cases on devices that exist once (the board) or are heavy (the emulator).
static EXCLUSIVE: Mutex<()> = Mutex::new(());

/// A started backend plus the lock that keeps other cases off a shared device.
pub struct Started {
    /// The device.
    pub backend: Box<dyn Backend>,
    _guard: Option<MutexGuard<'static, ()>>,
}

impl std::fmt::Debug for Started {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Started({})", self.backend.port())
    }
}

impl std::ops::Deref for Started {
    type Target = dyn Backend;
    fn deref(&self) -> &Self::Target {
        &*self.backend
    }
}

/// Starts `kind` for `scenario`, or prints why not and returns `None` (the case is skipped).
pub fn start(kind: BackendKind, case: &str, scenario: Scenario) -> Option<Started> {
    match kind {
        BackendKind::Sim => Some(Started {
            backend: Box::new(SimBackend::start(scenario).expect("start the simulator")),
            _guard: None,
        }),
        BackendKind::Emulator => {
            if std::env::var(EMULATOR_ENV).as_deref() != Ok("1") {
                eprintln!("skipped {case} on the emulator: set {EMULATOR_ENV}=1 to run it");
                return None;
            }
            if scenario.link_silence.is_some() || scenario.corrupt_to_host > 0.0 {
                eprintln!("skipped {case} on the emulator: it cannot silence or corrupt its link");
                return None;
            }
            let guard = EXCLUSIVE.lock().unwrap_or_else(|p| p.into_inner());
            let backend = EmulatorBackend::start(scenario).expect("start the emulator harness");
            Some(Started {
                backend: Box::new(backend),
                _guard: Some(guard),
            })
        }
        BackendKind::Hil => {
            let Ok(port) = std::env::var(HIL_PORT_ENV) else {
                eprintln!("skipped {case} on a board: set {HIL_PORT_ENV}=/dev/ttyACM0 to run it");
                return None;
            };
            if scenario.injects_faults() {
                eprintln!("skipped {case} on a board: it needs fault injection");
                return None;
            }
            let guard = EXCLUSIVE.lock().unwrap_or_else(|p| p.into_inner());
            Some(Started {
                backend: Box::new(HilBackend { port }),
                _guard: Some(guard),
            })
        }
    }
}

/// The simulator on a pseudo-terminal.
#[derive(Debug)]
pub struct SimBackend {
    /// The running simulator (tests may inspect its device).
    pub handle: skinbrdf_sim::SimHandle,
    path: String,
}

impl SimBackend {
    /// Starts a simulator for `scenario`.
    pub fn start(scenario: Scenario) -> Result<Self, skinbrdf_sim::SimError> {
        let mut cfg = skinbrdf_sim::SimConfig {
            time_scale: SIM_TIME_SCALE,
            start_us: SIM_START_US,
            ..Default::default()
        };
        cfg.faults.flash_never_ready = scenario.flash_never_ready;
        cfg.faults.camera_not_firing = scenario.camera_not_firing;
        cfg.faults.corrupt_to_host_probability = scenario.corrupt_to_host;
        cfg.faults.link_drop =
            scenario
                .link_silence
                .map(|(after_records, duration_us)| skinbrdf_sim::LinkDrop {
                    after_records,
                    duration_us,
                });
        let (handle, path) = skinbrdf_sim::spawn_pty(cfg)?;
        Ok(Self { handle, path })
    }
}

impl Backend for SimBackend {
    fn kind(&self) -> BackendKind {
        BackendKind::Sim
    }
    fn device_kind(&self) -> &'static str {
        "simulator"
    }
    fn port(&self) -> String {
        self.path.clone()
    }
    fn options(&self) -> CaptureOptions {
        sim_options()
    }
    fn modelled_hardware(&self) -> bool {
        true
    }
}

/// Capture options for the simulator at [`SIM_TIME_SCALE`].
pub fn sim_options() -> CaptureOptions {
    CaptureOptions {
        // 20 ms wall = 1 s device: the keep-alive stays well inside the watchdog.
        keepalive: Duration::from_millis(20),
        // Host time (converted with the fitted clock rate: 500 s of device time at 50x): a
        // loaded CI machine never trips it.
        watchdog_us: Some(10_000_000),
        // Generous: a loaded CI machine may not schedule the simulator thread for a while.
        request_timeout: Duration::from_secs(2),
        initial_clock_reads: 8,
        reconnect_window: Duration::from_secs(10),
        reconnect_pause: Duration::from_millis(10),
        ..CaptureOptions::default()
    }
}

/// The firmware image in rp2040js (`tests/emulator/harness.js`).
#[derive(Debug)]
pub struct EmulatorBackend {
    child: Child,
    stdin: Mutex<ChildStdin>,
    path: String,
    /// Input assertions the harness reported: (signal, sim time in us).
    edges: Arc<Mutex<Vec<(String, f64)>>>,
}

/// Parses a harness line like `{"event":"xsync","asserted":true,"sim_ns":1,"sim_us":0.001}`.
fn parse_edge(line: &str) -> Option<(String, f64)> {
    let v: serde_json::Value = serde_json::from_str(line).ok()?;
    let event = v.get("event")?.as_str()?;
    if !matches!(event, "xsync" | "photodiode") || v.get("asserted")?.as_bool() != Some(true) {
        return None;
    }
    let ns = v.get("sim_ns")?.as_f64()?;
    Some((event.to_string(), ns / 1000.0))
}

impl EmulatorBackend {
    /// Starts the harness and configures its camera/flash models for `scenario`.
    pub fn start(scenario: Scenario) -> std::io::Result<Self> {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("emulator");
        let mut cmd = Command::new("node");
        cmd.arg(dir.join("harness.js"))
            .args(["--speed", "0", "--recycle-us", "300000"]);
        if let Ok(elf) = std::env::var(EMULATOR_ELF_ENV) {
            cmd.args(["--elf", &elf]);
        }
        let mut child = cmd
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()?;
        let stdout = child
            .stdout
            .take()
            .ok_or_else(|| std::io::Error::other("no stdout"))?;
        let stdin = child
            .stdin
            .take()
            .ok_or_else(|| std::io::Error::other("no stdin"))?;
        let mut lines = BufReader::new(stdout).lines();
        let path = loop {
            match lines.next() {
                Some(Ok(line)) => {
                    if let Some(p) = line.strip_prefix("PORT ") {
                        break p.trim().to_string();
                    }
                }
                _ => {
                    let _ = child.kill();
                    return Err(std::io::Error::other(
                        "the emulator harness exited before printing its port",
                    ));
                }
            }
        };
        // Keep draining its event lines (so the harness never blocks on a full pipe) and keep
        // the input edges: they are the reference for the timestamp-accuracy case.
        let edges = Arc::new(Mutex::new(Vec::new()));
        let sink = edges.clone();
        std::thread::spawn(move || {
            for line in lines.map_while(Result::ok) {
                if let Some(edge) = parse_edge(&line) {
                    sink.lock().unwrap_or_else(|p| p.into_inner()).push(edge);
                }
            }
        });
        let me = Self {
            child,
            stdin: Mutex::new(stdin),
            path,
            edges,
        };
        if scenario.flash_never_ready {
            me.command(r#"{"cmd":"configure","flash":{"neverReady":true}}"#)?;
        }
        if scenario.camera_not_firing {
            me.command(r#"{"cmd":"configure","camera":{"enabled":false}}"#)?;
        }
        Ok(me)
    }

    /// Sends one JSON command line to the harness.
    pub fn command(&self, json: &str) -> std::io::Result<()> {
        let mut stdin = self.stdin.lock().unwrap_or_else(|p| p.into_inner());
        writeln!(stdin, "{json}")?;
        stdin.flush()
    }
}

impl Drop for EmulatorBackend {
    fn drop(&mut self) {
        let _ = self.command(r#"{"cmd":"quit"}"#);
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Backend for EmulatorBackend {
    fn kind(&self) -> BackendKind {
        BackendKind::Emulator
    }
    fn device_kind(&self) -> &'static str {
        "emulator"
    }
    fn port(&self) -> String {
        self.path.clone()
    }
    fn inject(&self, json: &str) -> bool {
        self.command(json).is_ok()
    }
    fn input_edges_us(&self, signal: &str) -> Option<Vec<f64>> {
        let edges = self.edges.lock().unwrap_or_else(|p| p.into_inner());
        Some(
            edges
                .iter()
                .filter(|(s, _)| s == signal)
                .map(|(_, t)| *t)
                .collect(),
        )
    }
    fn options(&self) -> CaptureOptions {
        CaptureOptions {
            keepalive: Duration::from_millis(50),
            // The emulator's clock runs at a load-dependent multiple of wall time that may
            // change after the rate is fitted: no watchdog.
            watchdog_us: Some(0),
            request_timeout: Duration::from_secs(3),
            initial_clock_reads: 4,
            reconnect_window: Duration::from_secs(20),
            ..CaptureOptions::default()
        }
    }
    fn modelled_hardware(&self) -> bool {
        true
    }
}

/// A real board.
#[derive(Debug)]
pub struct HilBackend {
    port: String,
}

impl Backend for HilBackend {
    fn kind(&self) -> BackendKind {
        BackendKind::Hil
    }
    fn device_kind(&self) -> &'static str {
        "board"
    }
    fn port(&self) -> String {
        self.port.clone()
    }
    fn options(&self) -> CaptureOptions {
        CaptureOptions {
            watchdog_us: Some(10_000_000),
            ..CaptureOptions::default()
        }
    }
    fn modelled_hardware(&self) -> bool {
        false
    }
}

/// The host end of the simulator's in-process link as a [`Transport`] (no pseudo-terminal).
#[derive(Debug)]
pub struct InProcess(pub skinbrdf_sim::HostLink);

impl Transport for InProcess {
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        self.0
            .read_timeout(buf, timeout)
            .map_err(|e| match e.kind() {
                std::io::ErrorKind::BrokenPipe => {
                    TransportError::Disconnected { port: self.name() }
                }
                _ => TransportError::Io {
                    port: self.name(),
                    source: e,
                },
            })
    }
    fn write_all(&mut self, data: &[u8]) -> Result<(), TransportError> {
        self.0
            .send(data)
            .map_err(|_| TransportError::Disconnected { port: self.name() })
    }
    fn name(&self) -> String {
        "sim:in-process".into()
    }
}

/// A transport the test can cut, as if the cable were pulled.
pub struct Cuttable {
    inner: Option<Box<dyn Transport>>,
    cut: Arc<AtomicBool>,
    name: String,
}

impl Cuttable {
    /// Wraps `inner`; setting `cut` disconnects it.
    pub fn new(inner: Box<dyn Transport>, cut: Arc<AtomicBool>) -> Self {
        let name = inner.name();
        Self {
            inner: Some(inner),
            cut,
            name,
        }
    }

    fn live(&mut self) -> Result<&mut Box<dyn Transport>, TransportError> {
        if self.cut.load(Ordering::SeqCst) {
            self.inner = None;
        }
        self.inner.as_mut().ok_or(TransportError::Disconnected {
            port: self.name.clone(),
        })
    }
}

impl std::fmt::Debug for Cuttable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Cuttable({})", self.name)
    }
}

impl Transport for Cuttable {
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        self.live()?.read(buf, timeout)
    }
    fn write_all(&mut self, data: &[u8]) -> Result<(), TransportError> {
        self.live()?.write_all(data)
    }
    fn name(&self) -> String {
        self.name.clone()
    }
}

/// A short plan with the method's four groups; `interval_us` between shots.
pub fn short_plan(counts: [u32; 4], interval_us: u64, max_retries: u32) -> CapturePlan {
    let roles = [
        ("measurement", ImageRole::Measurement),
        ("light position", ImageRole::LightPosition),
        ("reference standard", ImageRole::ReferenceStandard),
        ("standard position", ImageRole::StandardPosition),
    ];
    CapturePlan {
        groups: roles
            .iter()
            .zip(counts)
            .filter(|(_, n)| *n > 0)
            .map(|((label, role), count)| ShotGroup {
                label: (*label).to_string(),
                role: *role,
                count,
                min_interval_us: interval_us,
                pre_focus_us: 20_000,
                shutter_pulse_us: 30_000,
                xsync_timeout_us: 400_000,
                flash_ready_timeout_us: 5_000_000,
                flash_mode: FlashMode::ControllerOnXsync,
            })
            .collect(),
        max_retries,
    }
}
