//! Running a capture plan: [`run_capture`].
//!
//! The host connects and handshakes, reads the device clock a few times, loads the plan and
//! runs it group by group (asking the [`CaptureObserver`] before each group, so the CLI can
//! prompt the operator). Every exposure record is appended to the [`CaptureRecord`], written
//! atomically to `capture.json` and only *then* acknowledged to the device, so the device
//! forgets a record only once it is on disk (one `AckRecords` per burst of records).
//!
//! **No record lost, none duplicated.** Records are accepted strictly in index order: a record
//! below the next expected index is a duplicate and dropped, one above it is held back and the
//! gap fetched (`FetchRecords`). When the link fails (disconnect, or a keep-alive that times
//! out) the host reconnects through its [`Connector`], handshakes again, reads the device
//! status and fetches every record from the next expected index on: the device holds all
//! unacknowledged records in its ring buffer, so nothing taken during the outage is lost.
//!
//! **Keep-alive and clock.** Throughout the session the host sends `GetStatus` every
//! [`CaptureOptions::keepalive`]: it feeds the device's host watchdog, detects a run that ended
//! while its events were lost, and each answer is also a round-trip clock read, so the drift fit
//! has a baseline as long as the session (plus a few reads at the start and the end). The clock
//! model is refitted over all reads before every write, and every exposure's `host_time_us` is
//! mapped through the latest model.
//!
//! **Watchdog in host time.** The keep-alive cadence is host time, the device's watchdog is
//! device time, and the two clocks need not run at the same rate (a simulator at
//! `--time-scale 20` spends twenty device seconds per host second). So
//! [`CaptureOptions::watchdog_us`] is given in host microseconds and converted to device
//! microseconds with the clock rate fitted over the initial clock reads
//! ([`crate::clock::device_rate`], taken over at least [`crate::clock::MIN_RATE_SPAN_US`] of host
//! time): the watchdog then means the same wall time on a board (rate ~1), a time-scaled
//! simulator and an emulator.
//!
//! **Noisy links.** Each request is re-sent (same `seq`) while its answer is late
//! ([`crate::client`]); lost records are fetched again in rounds that stop as soon as the
//! records stop coming, and only rounds that bring nothing count towards giving up.
//!
//! **Abort.** When [`CaptureOptions::abort`] is set (Ctrl-C) or the observer declines a group,
//! the host sends `Abort` (the device releases every output), collects the records taken so
//! far, writes `capture.json` with `complete: false` and returns [`CaptureError::Aborted`].

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use skinbrdf_protocol as proto;
use skinbrdf_protocol::{
    DeviceError, Event, ExhaustedAction, ExposureRecord, Fault, FaultKind, LogLevel, RequestBody,
    ResponseBody, SessionOutcome, SessionState, Status,
};
use skinbrdf_session::capture::{
    CapturePlan, CaptureRecord, ClockModel, Exposure, FlashMode, ImageRole, ShotGroup, ShotOutcome,
    CAPTURE_FORMAT_VERSION,
};

use crate::client::{
    identity, Client, ClientError, LinkStats, DEFAULT_REQUEST_TIMEOUT, RESEND_INTERVAL,
};
use crate::clock::{
    device_rate, fit_clock, host_now_us, host_span_us, select_reads, ClockError, ClockRead,
    MIN_RATE_SPAN_US,
};
use crate::plan::{validate_plan, PlanError};
use crate::store::{CaptureWriter, StoreError};
use crate::transport::{SerialTransport, Transport, TransportError};

/// Opens (and re-opens, after a link failure) the byte link to the device.
pub trait Connector {
    /// Opens a fresh link.
    fn connect(&mut self) -> Result<Box<dyn Transport>, TransportError>;
}

/// Opens a serial port by path (reconnects reopen the same path).
#[derive(Debug, Clone)]
pub struct SerialConnector {
    /// The port path.
    pub path: String,
}

impl Connector for SerialConnector {
    fn connect(&mut self) -> Result<Box<dyn Transport>, TransportError> {
        Ok(Box::new(SerialTransport::open(&self.path)?))
    }
}

/// Any closure that opens a link is a connector.
impl<F> Connector for F
where
    F: FnMut() -> Result<Box<dyn Transport>, TransportError>,
{
    fn connect(&mut self) -> Result<Box<dyn Transport>, TransportError> {
        self()
    }
}

/// A single already-open link: a reconnect after it fails is impossible.
#[derive(Debug)]
pub struct OnceConnector<T>(Option<T>);

impl<T> OnceConnector<T> {
    /// Wraps an open link.
    pub fn new(transport: T) -> Self {
        Self(Some(transport))
    }
}

impl<T: Transport + 'static> Connector for OnceConnector<T> {
    fn connect(&mut self) -> Result<Box<dyn Transport>, TransportError> {
        match self.0.take() {
            Some(t) => Ok(Box::new(t)),
            None => Err(TransportError::Disconnected {
                port: "the link (it cannot be reopened)".into(),
            }),
        }
    }
}

/// Default host watchdog, host microseconds: 10 s, the firmware's own default on a board
/// (`skinbrdf_sequencer::DEFAULT_WATCHDOG_US`), long enough for a USB re-enumeration and a few
/// request budgets, short enough that a crashed host does not leave a session shooting.
pub const DEFAULT_WATCHDOG_US: u64 = 10_000_000;

/// Fetch rounds in a row that bring no new record before the link counts as failed.
pub const FETCH_ROUNDS_WITHOUT_PROGRESS: u32 = 3;

/// Pause between the extra clock reads that stretch the initial reads over
/// [`MIN_RATE_SPAN_US`] of host time (so the clock rate can be fitted): a few reads per
/// millisecond would add nothing but traffic.
const RATE_READ_PAUSE: Duration = Duration::from_millis(2);

/// Settings of a capture run.
#[derive(Debug, Clone)]
pub struct CaptureOptions {
    /// Session directory for `capture.json` (`None`: keep the record in memory only).
    pub out_dir: Option<PathBuf>,
    /// How long a request waits for its response, all re-sends included.
    pub request_timeout: Duration,
    /// Interval between copies of a request whose response is late (same `seq`).
    pub resend_interval: Duration,
    /// Clock reads before the session starts (more reads: a better initial offset). When a
    /// watchdog is set, reads continue until they span [`MIN_RATE_SPAN_US`] of host time.
    pub initial_clock_reads: u32,
    /// Interval of `GetStatus` keep-alives (also clock reads) while waiting for events.
    pub keepalive: Duration,
    /// Host watchdog, **host** microseconds (wall time without a valid request after which the
    /// device stops a running session; 0 asks for the device's longest,
    /// [`skinbrdf_protocol::MAX_WATCHDOG_US`]: a session is never left without one; `None`:
    /// leave the device's own, which is in device time). Converted to device microseconds
    /// with the fitted clock rate.
    pub watchdog_us: Option<u64>,
    /// How long to keep trying to reconnect after the link fails.
    pub reconnect_window: Duration,
    /// Pause between reconnect attempts.
    pub reconnect_pause: Duration,
    /// Reconnects in a row without a new exposure before the run gives up with
    /// [`CaptureError::LinkUnusable`]: a line that drops every other frame re-handshakes for
    /// ever otherwise, each reconnect succeeding and the next request failing again.
    pub max_stalled_reconnects: u32,
    /// Replace a `capture.json` of an interrupted session (`"complete": false`) in `out_dir`.
    /// Without it the run refuses before touching the device ([`CaptureError::ExistingSession`]):
    /// that file holds exposures that exist nowhere else.
    pub overwrite: bool,
    /// Flash-trigger pulse width for `controller-on-xsync` groups.
    pub flash_trigger_pulse_us: u64,
    /// How long after X-sync the photodiode must see the flash.
    pub flash_window_us: u64,
    /// Set from another thread (Ctrl-C) to abort cleanly.
    pub abort: Arc<AtomicBool>,
}

/// Default of [`CaptureOptions::max_stalled_reconnects`]: a noisy but usable line (the
/// robustness tests' 20 % corruption each way) needs at most 3.
pub const DEFAULT_MAX_STALLED_RECONNECTS: u32 = 5;

impl Default for CaptureOptions {
    fn default() -> Self {
        Self {
            out_dir: None,
            request_timeout: DEFAULT_REQUEST_TIMEOUT,
            resend_interval: RESEND_INTERVAL,
            initial_clock_reads: 16,
            keepalive: Duration::from_millis(500),
            watchdog_us: Some(DEFAULT_WATCHDOG_US),
            reconnect_window: Duration::from_secs(30),
            reconnect_pause: Duration::from_millis(100),
            max_stalled_reconnects: DEFAULT_MAX_STALLED_RECONNECTS,
            overwrite: false,
            flash_trigger_pulse_us: 1_000,
            flash_window_us: proto::ShotGroup::DEFAULT_FLASH_WINDOW_US,
            abort: Arc::new(AtomicBool::new(false)),
        }
    }
}

/// What the observer wants before a group.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GroupDecision {
    /// Shoot the group.
    Continue,
    /// Abort the session.
    Abort,
}

/// Progress callbacks (all optional).
#[allow(unused_variables)]
pub trait CaptureObserver {
    /// Connected and handshaken; the initial clock model is fitted.
    fn connected(&mut self, record: &CaptureRecord) {}
    /// Before group `index` is shot; `shots` exposures were recorded so far.
    fn before_group(&mut self, index: usize, group: &ShotGroup, shots: usize) -> GroupDecision {
        GroupDecision::Continue
    }
    /// An exposure was recorded (and written).
    fn exposure(&mut self, exposure: &Exposure, record: &ExposureRecord) {}
    /// The device reported a fault.
    fn fault(&mut self, fault: &Fault) {}
    /// The flash-ready input changed.
    fn flash_ready(&mut self, ready: bool, recycle_us: Option<u64>) {}
    /// A device log line, or a host-side warning.
    fn log(&mut self, level: LogLevel, text: &str) {}
    /// Group `index` finished.
    fn group_done(&mut self, index: usize) {}
    /// The link failed; reconnecting.
    fn link_lost(&mut self, error: &ClientError) {}
    /// The run ended (completed, aborted or failed); what the link went through.
    fn finished(&mut self, summary: &RunSummary) {}
    /// Reconnected; `fetched` records were recovered.
    fn reconnected(&mut self, fetched: u32) {}
}

/// What a run cost and what the link went through (for the operator and for reports).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RunSummary {
    /// Wall time from connecting to the end, seconds.
    pub elapsed_s: f64,
    /// Exposures recorded.
    pub exposures: usize,
    /// Successful reconnects (handshakes again after a link failure).
    pub reconnects: u32,
    /// Records the device resent on `FetchRecords` (missed live: link down, queue overflow).
    pub fetched: u32,
    /// Duplicate records dropped.
    pub duplicates: u32,
    /// Frames from the device rejected by the decoder (CRC, COBS, oversize).
    pub bad_frames: u64,
    /// Requests sent (handshakes and clock reads excluded).
    pub requests: u64,
    /// Extra copies of late requests (same `seq`), handshakes and clock reads included.
    pub resends: u64,
    /// Requests that got no answer within their budget (each led to a re-handshake).
    pub timeouts: u64,
    /// Answers dropped as stale or duplicate (their `seq` was not the one awaited).
    pub stale_responses: u64,
    /// Device watchdog set, device microseconds (0: none or disabled).
    pub watchdog_device_us: u64,
    /// Device microseconds per host microsecond, fitted over the initial clock reads (0: not
    /// fitted).
    pub device_rate: f64,
}

/// An observer that continues every group and reports nothing.
#[derive(Debug, Default, Clone, Copy)]
pub struct Unattended;

impl CaptureObserver for Unattended {}

/// Why a capture did not complete.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The plan cannot be run on this controller.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// Connecting or talking to the device failed.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// `capture.json` could not be written.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// No clock model.
    #[error(transparent)]
    Clock(#[from] ClockError),
    /// The device ended the session on a fault.
    #[error("device fault: {detail}; the session stopped after {shots_kept} exposures (all kept)")]
    DeviceFault {
        /// What the device reported.
        detail: String,
        /// Exposures recorded.
        shots_kept: usize,
    },
    /// The operator aborted.
    #[error("aborted by the operator after {shots_kept} exposures (all kept)")]
    Aborted {
        /// Exposures recorded.
        shots_kept: usize,
    },
    /// The session directory holds an interrupted session that this run would overwrite.
    #[error(
        "{} holds an interrupted session ({exposures} exposures, \"complete\": false) that a new \
         capture would overwrite; resuming it is not supported: move it away, choose another \
         --out, or pass --overwrite to replace it",
        path.display()
    )]
    ExistingSession {
        /// The `capture.json`.
        path: PathBuf,
        /// Exposures it holds (0 if it cannot be read).
        exposures: usize,
    },
    /// The controller restarted during the session (its state is `Idle` after a reconnect).
    #[error(
        "the controller restarted during the session (a watchdog reset after a hang, a panic, \
         or power): it is idle now and its record ring, which lives in RAM, is gone. Kept: \
         {shots_kept} exposures (indices below {first_lost}; {acked} acknowledged). Lost: any \
         exposure from index {first_lost} on that the controller took before it restarted (at \
         most the shot in flight, since every record is acknowledged as it arrives). Start a \
         new capture for the shots that remain"
    )]
    DeviceRestarted {
        /// Exposures on disk.
        shots_kept: usize,
        /// The first index the host does not have.
        first_lost: u32,
        /// Records the host had acknowledged.
        acked: u32,
    },
    /// The link keeps failing right after each reconnect: the run gave up.
    #[error(
        "the link is unusable: {reconnects} reconnects in a row without a new exposure \
         ({bad_frames} bad frames, {resends} re-sent requests, {timeouts} timeouts so far); \
         {shots_kept} exposures kept; check the cable, the port and what else uses it"
    )]
    LinkUnusable {
        /// Reconnects without progress.
        reconnects: u32,
        /// Frames that failed to decode.
        bad_frames: u64,
        /// Requests re-sent.
        resends: u64,
        /// Requests that timed out.
        timeouts: u64,
        /// Exposures recorded.
        shots_kept: usize,
    },
    /// The link failed and could not be re-established.
    #[error("lost the device and could not reconnect within {window_s} s ({last_error}); {shots_kept} exposures kept")]
    LinkLost {
        /// The reconnect window.
        window_s: u64,
        /// The last error.
        last_error: String,
        /// Exposures recorded.
        shots_kept: usize,
    },
}

/// Converts a session plan to the protocol's plan (the plan must be valid).
pub fn to_protocol_plan(
    plan: &CapturePlan,
    options: &CaptureOptions,
) -> Result<proto::Plan, PlanError> {
    let origin = std::path::Path::new("the plan");
    validate_plan(plan, origin)?;
    let mut groups = heapless::Vec::new();
    for g in &plan.groups {
        let label =
            heapless::String::try_from(g.label.as_str()).map_err(|_| PlanError::Invalid {
                path: origin.to_path_buf(),
                location: format!("label `{}`", g.label),
                problem: "too long for the controller".into(),
            })?;
        let group = proto::ShotGroup {
            label,
            role: match g.role {
                ImageRole::Measurement => proto::ImageRole::Measurement,
                ImageRole::LightPosition => proto::ImageRole::LightPosition,
                ImageRole::ReferenceStandard => proto::ImageRole::ReferenceStandard,
                ImageRole::StandardPosition => proto::ImageRole::StandardPosition,
                // `validate_plan` refuses such a group; kept an error here too.
                ImageRole::Survey => {
                    return Err(PlanError::Invalid {
                        path: origin.to_path_buf(),
                        location: format!("group `{}`.role", g.label),
                        problem: "survey images are not fired by the controller".into(),
                    })
                }
            },
            count: g.count,
            min_interval_us: g.min_interval_us,
            pre_focus_us: g.pre_focus_us,
            shutter_pulse_us: g.shutter_pulse_us,
            xsync_timeout_us: g.xsync_timeout_us,
            flash_ready_timeout_us: g.flash_ready_timeout_us,
            flash_window_us: options.flash_window_us,
            flash_mode: match g.flash_mode {
                FlashMode::CameraHotShoe => proto::FlashMode::CameraHotShoe,
                FlashMode::ControllerOnXsync => proto::FlashMode::ControllerOnXsync,
            },
        };
        groups.push(group).map_err(|_| PlanError::Invalid {
            path: origin.to_path_buf(),
            location: "groups".into(),
            problem: "too many groups for the controller".into(),
        })?;
    }
    Ok(proto::Plan {
        groups,
        policy: proto::FaultPolicy {
            max_retries: plan.max_retries,
            on_exhausted: ExhaustedAction::AbortSession,
        },
        flash_trigger_pulse_us: options.flash_trigger_pulse_us,
    })
}

fn role(r: proto::ImageRole) -> ImageRole {
    match r {
        proto::ImageRole::Measurement => ImageRole::Measurement,
        proto::ImageRole::LightPosition => ImageRole::LightPosition,
        proto::ImageRole::ReferenceStandard => ImageRole::ReferenceStandard,
        proto::ImageRole::StandardPosition => ImageRole::StandardPosition,
    }
}

fn outcome(o: proto::ShotOutcome) -> ShotOutcome {
    match o {
        proto::ShotOutcome::Ok => ShotOutcome::Ok,
        proto::ShotOutcome::MissingXsync => ShotOutcome::MissingXsync,
        proto::ShotOutcome::MissingFlash => ShotOutcome::MissingFlash,
        proto::ShotOutcome::FlashNotReady => ShotOutcome::FlashNotReady,
        proto::ShotOutcome::Aborted => ShotOutcome::Aborted,
    }
}

/// The capture.json exposure for a device record, its time mapped through `clock`.
pub fn exposure_from_record(r: &ExposureRecord, clock: &ClockModel) -> Exposure {
    let shutter_command_us = r.shutter_command_us.unwrap_or(r.started_us);
    Exposure {
        index: r.index,
        group: r.group,
        role: role(r.role),
        shutter_command_us,
        xsync_us: r.xsync_us,
        flash_fired_us: r.flash_fired_us,
        recycle_us: r.recycle_us,
        outcome: outcome(r.outcome),
        host_time_us: clock.to_host_us(r.xsync_us.unwrap_or(shutter_command_us)),
        image: None,
    }
}

/// How a run (one `Run` request) ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RunEnd {
    Groups {
        next_index: u32,
    },
    Session {
        outcome: SessionOutcome,
        records: u32,
    },
}

struct Runner<'a, C: Connector, O: CaptureObserver> {
    connector: C,
    observer: &'a mut O,
    options: &'a CaptureOptions,
    client: Option<Client<Box<dyn Transport>>>,
    writer: Option<CaptureWriter>,
    record: CaptureRecord,
    raw: Vec<ExposureRecord>,
    held: BTreeMap<u32, ExposureRecord>,
    reads: Vec<ClockRead>,
    run_end: Option<RunEnd>,
    last_fault: Option<Fault>,
    last_status: Instant,
    aborting: bool,
    summary: RunSummary,
    started: Instant,
    /// Link counters of clients closed so far.
    closed_stats: LinkStats,
    /// Records below this index are acknowledged to the device.
    acked: u32,
    /// Reconnects since the last new exposure, and the exposure count then.
    stalled_reconnects: u32,
    shots_at_last_reconnect: usize,
    /// The device confirmed our plan (from then on it is never `Idle` unless it restarted).
    plan_loaded: bool,
}

/// Runs `plan` on the device behind `connector`, writing `capture.json` after every exposure
/// when `options.out_dir` is set. Returns the complete record, or an error after keeping every
/// exposure taken (see [`CaptureError`]).
pub fn run_capture<C: Connector, O: CaptureObserver>(
    connector: C,
    plan: &CapturePlan,
    options: &CaptureOptions,
    observer: &mut O,
) -> Result<CaptureRecord, CaptureError> {
    let proto_plan = to_protocol_plan(plan, options)?;
    if let Some(dir) = &options.out_dir {
        refuse_interrupted_session(dir, options.overwrite)?;
    }
    let writer = match &options.out_dir {
        Some(dir) => Some(CaptureWriter::create(dir)?),
        None => None,
    };
    let mut connector = connector;
    let transport = connector.connect().map_err(ClientError::from)?;
    let client = open_client(transport, options)?;
    let device = client
        .info()
        .map(identity)
        .ok_or_else(|| ClientError::Unexpected {
            port: client.port().to_string(),
            request: "Hello",
            got: "no device info".into(),
        })?;
    let mut runner = Runner {
        connector,
        observer,
        options,
        client: Some(client),
        writer,
        record: CaptureRecord {
            format_version: CAPTURE_FORMAT_VERSION,
            plan: plan.clone(),
            device,
            clock: ClockModel {
                device_ref_us: 0,
                host_ref_us: 0.0,
                drift_ppm: 0.0,
                residual_rms_us: 0.0,
                samples: 0,
            },
            exposures: Vec::new(),
            complete: false,
        },
        raw: Vec::new(),
        held: BTreeMap::new(),
        reads: Vec::new(),
        run_end: None,
        last_fault: None,
        last_status: Instant::now(),
        aborting: false,
        summary: RunSummary::default(),
        started: Instant::now(),
        closed_stats: LinkStats::default(),
        acked: 0,
        stalled_reconnects: 0,
        shots_at_last_reconnect: 0,
        plan_loaded: false,
    };
    let result = runner.run(&proto_plan);
    let summary = runner.finish_summary();
    tracing::info!(
        exposures = summary.exposures,
        elapsed_s = summary.elapsed_s,
        requests = summary.requests,
        resends = summary.resends,
        timeouts = summary.timeouts,
        reconnects = summary.reconnects,
        fetched = summary.fetched,
        duplicates = summary.duplicates,
        stale_responses = summary.stale_responses,
        bad_frames = summary.bad_frames,
        watchdog_device_us = summary.watchdog_device_us,
        device_rate = summary.device_rate,
        "capture run finished"
    );
    runner.observer.finished(&summary);
    result
}

/// An interrupted session's `capture.json` in `dir` is refused unless `overwrite`; a complete
/// one (a finished run being repeated, e.g. the demo) is replaced.
fn refuse_interrupted_session(dir: &std::path::Path, overwrite: bool) -> Result<(), CaptureError> {
    let path = dir.join(crate::store::CAPTURE_FILE_NAME);
    if overwrite || !path.exists() {
        return Ok(());
    }
    match crate::store::read_capture(&path) {
        Ok(r) if r.complete => Ok(()),
        Ok(r) => Err(CaptureError::ExistingSession {
            path,
            exposures: r.exposures.len(),
        }),
        // Unreadable (a crash mid-write leaves the old file, so this is someone else's file):
        // not ours to destroy either.
        Err(_) => Err(CaptureError::ExistingSession { path, exposures: 0 }),
    }
}

/// Handshakes on `transport` with the request budget and re-send interval of `options`.
fn open_client(
    transport: Box<dyn Transport>,
    options: &CaptureOptions,
) -> Result<Client<Box<dyn Transport>>, ClientError> {
    let mut client = Client::new(transport);
    client.request_timeout = options.request_timeout;
    client.resend_interval = options.resend_interval;
    client.handshake()?;
    Ok(client)
}

impl<C: Connector, O: CaptureObserver> Runner<'_, C, O> {
    fn client(&mut self) -> Result<&mut Client<Box<dyn Transport>>, ClientError> {
        self.client
            .as_mut()
            .ok_or(ClientError::Transport(TransportError::Disconnected {
                port: "the device".into(),
            }))
    }

    /// Drops the client, keeping its counters.
    fn close_client(&mut self) {
        if let Some(c) = self.client.take() {
            self.keep_stats(c.stats());
        }
    }

    fn keep_stats(&mut self, s: LinkStats) {
        let k = &mut self.closed_stats;
        k.bad_frames += s.bad_frames;
        k.resends += s.resends;
        k.timeouts += s.timeouts;
        k.stray_responses += s.stray_responses;
    }

    fn finish_summary(&mut self) -> RunSummary {
        let live = self.client.as_ref().map(Client::stats).unwrap_or_default();
        let k = self.closed_stats;
        RunSummary {
            elapsed_s: self.started.elapsed().as_secs_f64(),
            exposures: self.shots(),
            bad_frames: k.bad_frames + live.bad_frames,
            resends: k.resends + live.resends,
            timeouts: k.timeouts + live.timeouts,
            stale_responses: k.stray_responses + live.stray_responses,
            ..self.summary
        }
    }

    fn request(&mut self, body: RequestBody) -> Result<ResponseBody, ClientError> {
        self.summary.requests += 1;
        // Events that arrive while waiting are queued and handled by the caller's event loop.
        self.client()?.request(body)
    }

    fn shots(&self) -> usize {
        self.record.exposures.len()
    }

    fn next_index(&self) -> u32 {
        u32::try_from(self.record.exposures.len()).unwrap_or(u32::MAX)
    }

    fn run(&mut self, plan: &proto::Plan) -> Result<CaptureRecord, CaptureError> {
        // Both steps are safe to repeat, so a link failure here is retried after a reconnect.
        self.with_reconnect(|r| r.prepare())?;
        let mut total_shots = 0;
        self.with_reconnect(|r| {
            match r.request(RequestBody::LoadPlan(plan.clone()))? {
                ResponseBody::PlanLoaded { total_shots: n } => total_shots = n,
                other => return Err(r.unexpected("LoadPlan", &other).into()),
            }
            Ok(())
        })?;
        tracing::info!(total_shots, "plan loaded");
        self.plan_loaded = true;
        self.refit_and_write()?;
        self.observer.connected(&self.record);
        for (g, group) in self.record.plan.groups.clone().iter().enumerate() {
            if self.options.abort.load(Ordering::SeqCst) {
                return self.abort();
            }
            if self.observer.before_group(g, group, self.shots()) == GroupDecision::Abort
                || self.options.abort.load(Ordering::SeqCst)
            {
                return self.abort();
            }
            let gi = u32::try_from(g).unwrap_or(u32::MAX);
            self.with_reconnect(|r| {
                match r.request(RequestBody::Run {
                    first_group: gi,
                    last_group: gi,
                }) {
                    Ok(_) => {}
                    // A retried `Run` whose first copy reached the device: it runs (or ran).
                    Err(ClientError::Device {
                        error: DeviceError::Busy,
                        ..
                    }) => {}
                    Err(ClientError::Device {
                        error: DeviceError::BadGroupRange { next_group, .. },
                        ..
                    }) if next_group > gi => {}
                    Err(e) => return Err(e.into()),
                }
                // Only now: a reconnect while `Run` was unanswered may have read a status from
                // before the run (the previous group's end). A run that already ended is seen
                // by the next keep-alive's status.
                r.run_end = None;
                Ok(())
            })?;
            match self.wait_run()? {
                RunEnd::Groups { .. } => self.observer.group_done(g),
                RunEnd::Session {
                    outcome: SessionOutcome::Completed,
                    ..
                } => {
                    self.observer.group_done(g);
                    break;
                }
                RunEnd::Session { outcome, .. } => return self.session_failed(outcome),
            }
        }
        self.record.complete = true;
        self.flush_acks_best_effort();
        self.final_clock_reads();
        self.refit_and_write()?;
        Ok(self.record.clone())
    }

    /// Clears what a previous host left on the device, sets the watchdog, reads the clock.
    fn prepare(&mut self) -> Result<(), CaptureError> {
        let status = self.status()?;
        if status.state == SessionState::Running {
            self.observer.log(
                LogLevel::Warn,
                "the device was running a session of an earlier connection: aborting it",
            );
            self.request(RequestBody::Abort)?;
        }
        let status = self.status()?;
        if status.unacked > 0 {
            self.observer.log(
                LogLevel::Warn,
                &format!(
                    "the device held {} unacknowledged records of an earlier session: \
                     releasing them (they are not part of this session)",
                    status.unacked
                ),
            );
            match self.request(RequestBody::AckRecords {
                next_index: status.next_index,
            }) {
                Ok(_)
                | Err(ClientError::Device {
                    error: DeviceError::AlreadyAcked { .. },
                    ..
                }) => {}
                Err(e) => return Err(e.into()),
            }
        }
        // Clock reads first: the watchdog is converted to device time with the rate they give.
        let wants_rate = self.options.watchdog_us.is_some_and(|w| w > 0);
        let first = self.reads.len();
        let planned = self.options.initial_clock_reads.max(1);
        // Bound the stretching: at RATE_READ_PAUSE per read this is far beyond the span.
        let limit =
            planned.saturating_add(u32::try_from(MIN_RATE_SPAN_US / 1000).unwrap_or(u32::MAX));
        for n in 1..=limit {
            let read = self.client()?.read_clock()?;
            self.reads.push(read);
            if n >= planned {
                if !wants_rate || host_span_us(&self.reads[first..]) >= MIN_RATE_SPAN_US {
                    break;
                }
                std::thread::sleep(RATE_READ_PAUSE);
            }
        }
        if let Some(host_us) = self.options.watchdog_us {
            let timeout_us = self.device_watchdog_us(host_us);
            // The device bounds the timeout (0, "none", becomes its longest): keep what it set.
            self.summary.watchdog_device_us =
                match self.request(RequestBody::SetWatchdog { timeout_us })? {
                    ResponseBody::WatchdogSet { timeout_us } => timeout_us,
                    _ => timeout_us,
                };
        }
        self.drain_queued()?;
        Ok(())
    }

    /// A host-time watchdog in device microseconds, through the fitted clock rate.
    fn device_watchdog_us(&mut self, host_us: u64) -> u64 {
        if host_us == 0 {
            return 0;
        }
        let rate = match device_rate(&self.reads) {
            Some(rate) => rate,
            None => {
                self.observer.log(
                    LogLevel::Warn,
                    "the clock reads span too little host time to fit the device clock's rate: \
                     setting the watchdog as if device and host clocks ran at the same rate",
                );
                1.0
            }
        };
        self.summary.device_rate = rate;
        let device_us = (host_us as f64 * rate).round();
        // At least 1 us: 0 would disable the watchdog.
        let device_us = if device_us >= u64::MAX as f64 {
            u64::MAX
        } else {
            (device_us as u64).max(1)
        };
        tracing::info!(
            host_ms = host_us / 1000,
            device_ms = device_us / 1000,
            rate,
            "host watchdog in device time"
        );
        device_us
    }

    fn status(&mut self) -> Result<Status, ClientError> {
        self.last_status = Instant::now();
        let host_send_us = host_now_us();
        match self.request(RequestBody::GetStatus)? {
            ResponseBody::Status(s) => {
                self.reads.push(ClockRead {
                    host_send_us,
                    device_us: s.now_us,
                    host_recv_us: host_now_us(),
                });
                Ok(s)
            }
            other => Err(self.unexpected("GetStatus", &other)),
        }
    }

    fn unexpected(&self, request: &'static str, got: &ResponseBody) -> ClientError {
        ClientError::Unexpected {
            port: self
                .client
                .as_ref()
                .map_or_else(String::new, |c| c.port().to_string()),
            request,
            got: got.name().to_string(),
        }
    }

    /// Handles queued events without waiting.
    fn drain_queued(&mut self) -> Result<(), CaptureError> {
        while let Some(e) = self.client()?.next_event(Duration::ZERO)? {
            self.handle_event(e)?;
        }
        Ok(())
    }

    /// Waits until the current run ends, keeping the link alive and recovering from failures.
    fn wait_run(&mut self) -> Result<RunEnd, CaptureError> {
        loop {
            if self.options.abort.load(Ordering::SeqCst) && !self.aborting {
                return Err(self.abort().err().unwrap_or(CaptureError::Aborted {
                    shots_kept: self.shots(),
                }));
            }
            let step = self.with_reconnect(|r| r.step());
            step?;
            if let Some(&max) = self.held.keys().next_back() {
                let want = max.saturating_add(1);
                self.with_reconnect(|r| r.ensure_records(want))?;
            }
            if let Some(end) = self.run_end {
                let n = match end {
                    RunEnd::Groups { next_index } => next_index,
                    RunEnd::Session { records, .. } => records,
                };
                self.with_reconnect(|r| r.ensure_records(n))?;
                self.with_reconnect(|r| r.flush_acks())?;
                return Ok(end);
            }
            self.with_reconnect(|r| r.flush_acks())?;
        }
    }

    /// One wait for an event, or a keep-alive when due.
    fn step(&mut self) -> Result<(), CaptureError> {
        let since = self.last_status.elapsed();
        if since >= self.options.keepalive {
            return self.keepalive();
        }
        let wait = (self.options.keepalive - since).min(Duration::from_millis(100));
        if let Some(e) = self.client()?.next_event(wait)? {
            self.handle_event(e)?;
        }
        self.drain_queued()
    }

    /// `GetStatus`: feeds the watchdog, reads the clock, notices a run that ended unseen.
    fn keepalive(&mut self) -> Result<(), CaptureError> {
        let status = self.status()?;
        self.drain_queued()?;
        if self.run_end.is_none() && status.state != SessionState::Running {
            self.run_end = Some(run_end_from_status(&status));
        }
        Ok(())
    }

    /// Makes sure every record below `n` is held, fetching what is missing. A round waits
    /// for the records that follow `Fetching` until they stop coming (no record for one re-send
    /// interval) or the request budget ends; a round that brings nothing new counts towards
    /// [`FETCH_ROUNDS_WITHOUT_PROGRESS`], after which the link counts as failed.
    fn ensure_records(&mut self, n: u32) -> Result<(), CaptureError> {
        let mut fruitless = 0;
        while self.next_index() < n {
            let from_index = self.next_index();
            match self.request(RequestBody::FetchRecords { from_index })? {
                ResponseBody::Fetching { count } => {
                    tracing::debug!(from_index, count, "fetching records");
                    self.summary.fetched += count;
                }
                other => return Err(self.unexpected("FetchRecords", &other).into()),
            }
            let quiet = self.options.resend_interval.max(Duration::from_millis(1));
            let deadline = Instant::now() + self.options.request_timeout;
            let mut quiet_until = Instant::now() + quiet;
            while self.next_index() < n {
                let now = Instant::now();
                if now >= deadline || now >= quiet_until {
                    break;
                }
                let left = deadline.min(quiet_until) - now;
                if let Some(e) = self.client()?.next_event(left)? {
                    let record = matches!(e, Event::Record(_));
                    self.handle_event(e)?;
                    if record {
                        quiet_until = Instant::now() + quiet;
                    }
                }
            }
            if self.next_index() > from_index {
                fruitless = 0;
            } else {
                fruitless += 1;
                if fruitless >= FETCH_ROUNDS_WITHOUT_PROGRESS {
                    return Err(ClientError::Timeout {
                        port: self.client()?.port().to_string(),
                        request: "FetchRecords (records did not arrive)",
                        timeout_ms: self.options.request_timeout.as_millis(),
                    }
                    .into());
                }
            }
        }
        Ok(())
    }

    fn handle_event(&mut self, event: Event) -> Result<(), CaptureError> {
        match event {
            Event::Record(r) => self.accept(r)?,
            Event::FlashReady {
                ready, recycle_us, ..
            } => self.observer.flash_ready(ready, recycle_us),
            Event::Fault(f) => {
                self.last_fault = Some(f);
                self.observer.fault(&f);
            }
            Event::Log { level, text, .. } => self.observer.log(level, text.as_str()),
            Event::GroupsDone { next_index, .. } => {
                if self.run_end.is_none() {
                    self.run_end = Some(RunEnd::Groups { next_index });
                }
            }
            Event::SessionDone {
                outcome, records, ..
            } => self.run_end = Some(RunEnd::Session { outcome, records }),
        }
        Ok(())
    }

    /// Accepts a record in index order: duplicates dropped, early ones held back.
    fn accept(&mut self, r: ExposureRecord) -> Result<(), CaptureError> {
        let next = self.next_index();
        if r.index < next {
            tracing::debug!(index = r.index, "duplicate record dropped");
            self.summary.duplicates += 1;
            return Ok(());
        }
        if r.index > next {
            self.held.insert(r.index, r);
            return Ok(());
        }
        let mut progressed = vec![r];
        let mut want = next + 1;
        while let Some(h) = self.held.remove(&want) {
            progressed.push(h);
            want += 1;
        }
        for r in progressed {
            let e = exposure_from_record(&r, &self.record.clock);
            self.record.exposures.push(e);
            self.raw.push(r);
        }
        self.refit_and_write()?;
        for (e, r) in self
            .record
            .exposures
            .iter()
            .zip(&self.raw)
            .skip(usize::try_from(next).unwrap_or(usize::MAX))
        {
            self.observer.exposure(e, r);
        }
        // Acknowledged by `flush_acks` once the burst of queued events is handled.
        Ok(())
    }

    /// Acknowledges every record written so far, in one `AckRecords` (records arrive in
    /// bursts, and on a noisy line every request costs re-sends).
    fn flush_acks(&mut self) -> Result<(), CaptureError> {
        let next_index = self.next_index();
        if next_index <= self.acked {
            return Ok(());
        }
        match self.request(RequestBody::AckRecords { next_index }) {
            Ok(_) => {}
            // Acks are an optimisation of the device's memory: a refused ack loses nothing.
            Err(ClientError::Device { error, .. }) => tracing::debug!(%error, "ack refused"),
            Err(e) => return Err(e.into()),
        }
        self.acked = next_index;
        Ok(())
    }

    /// [`Self::flush_acks`] where the records are already safe and only the device's memory
    /// is at stake (the end of a run): a failure is logged, not returned.
    fn flush_acks_best_effort(&mut self) {
        if let Err(e) = self.flush_acks() {
            self.observer.log(
                LogLevel::Warn,
                &format!(
                    "could not acknowledge the last records: {}",
                    skinbrdf_core::error_text(&e)
                ),
            );
        }
    }

    /// A few clock reads at the end give the drift fit its longest baseline (best effort).
    fn final_clock_reads(&mut self) {
        for _ in 0..self.options.initial_clock_reads.min(8) {
            match self.client.as_mut().map(Client::read_clock) {
                Some(Ok(read)) => self.reads.push(read),
                _ => break,
            }
        }
    }

    /// Refits the clock over all reads, remaps every exposure and writes `capture.json`.
    fn refit_and_write(&mut self) -> Result<(), CaptureError> {
        if self.reads.is_empty() {
            // The link failed before the first clock read: nothing to map yet.
            return Ok(());
        }
        let kept = select_reads(&self.reads);
        let clock = fit_clock(if kept.is_empty() { &self.reads } else { &kept })?;
        self.record.clock = clock;
        for (e, r) in self.record.exposures.iter_mut().zip(&self.raw) {
            *e = Exposure {
                image: e.image.take(),
                ..exposure_from_record(r, &clock)
            };
        }
        if let Some(w) = &self.writer {
            w.write(&self.record)?;
        }
        Ok(())
    }

    /// Runs `f`; on a link failure reconnects (within the window) and runs it again.
    fn with_reconnect(
        &mut self,
        mut f: impl FnMut(&mut Self) -> Result<(), CaptureError>,
    ) -> Result<(), CaptureError> {
        loop {
            match f(self) {
                Err(CaptureError::Client(e)) if is_link_failure(&e) => self.reconnect(e)?,
                other => return other,
            }
        }
    }

    /// Re-establishes the link after `error` and catches up with the device (status, missed
    /// records). A link failure while catching up (a noisy line) is another loss: handled the
    /// same way, within the same reconnect window.
    fn reconnect(&mut self, error: ClientError) -> Result<(), CaptureError> {
        let deadline = Instant::now() + self.options.reconnect_window;
        let mut error = error;
        loop {
            self.reestablish(error, deadline)?;
            match self.catch_up() {
                Ok(()) => return Ok(()),
                Err(CaptureError::Client(e)) if is_link_failure(&e) => error = e,
                Err(e) => return Err(e),
            }
        }
    }

    /// Handshakes again (on the same link after silence, else on a reopened one) before
    /// `deadline`.
    fn reestablish(&mut self, error: ClientError, deadline: Instant) -> Result<(), CaptureError> {
        self.observer.link_lost(&error);
        if self.shots() > self.shots_at_last_reconnect {
            self.shots_at_last_reconnect = self.shots();
            self.stalled_reconnects = 0;
        }
        if self.stalled_reconnects >= self.options.max_stalled_reconnects {
            self.close_client();
            let s = self.finish_summary();
            self.refit_and_write()?;
            return Err(CaptureError::LinkUnusable {
                reconnects: self.stalled_reconnects,
                bad_frames: s.bad_frames,
                resends: s.resends,
                timeouts: s.timeouts,
                shots_kept: self.shots(),
            });
        }
        self.stalled_reconnects += 1;
        // A silent link (timeouts) may come back on its own: handshake again on it first. A
        // dead link is closed before reopening (a serial port is opened exclusively).
        let mut keep = if matches!(
            error,
            ClientError::Timeout { .. }
                | ClientError::Device {
                    error: DeviceError::HandshakeRequired,
                    ..
                }
        ) {
            self.client.take()
        } else {
            self.close_client();
            None
        };
        let mut last_error = error.to_string();
        loop {
            if self.options.abort.load(Ordering::SeqCst) {
                self.refit_and_write()?;
                return Err(CaptureError::Aborted {
                    shots_kept: self.shots(),
                });
            }
            if Instant::now() >= deadline {
                self.refit_and_write()?;
                return Err(CaptureError::LinkLost {
                    window_s: self.options.reconnect_window.as_secs(),
                    last_error,
                    shots_kept: self.shots(),
                });
            }
            if let Some(mut c) = keep.take() {
                match c.handshake() {
                    Ok(_) => {
                        self.client = Some(c);
                        break;
                    }
                    Err(e @ ClientError::VersionMismatch { .. }) => return Err(e.into()),
                    // The link is dead: fall through and reopen it.
                    Err(ClientError::Transport(_)) => self.keep_stats(c.stats()),
                    Err(e) => {
                        last_error = skinbrdf_core::error_text(&e);
                        keep = Some(c);
                        continue;
                    }
                }
            }
            match self.connector.connect() {
                Ok(t) => match open_client(t, self.options) {
                    Ok(c) => {
                        self.client = Some(c);
                        break;
                    }
                    Err(e @ ClientError::VersionMismatch { .. }) => return Err(e.into()),
                    Err(e) => last_error = skinbrdf_core::error_text(&e),
                },
                Err(e) => last_error = skinbrdf_core::error_text(&e),
            }
            std::thread::sleep(self.options.reconnect_pause);
        }
        self.summary.reconnects += 1;
        Ok(())
    }

    /// After a reconnect: reads the status and fetches every record missed meanwhile.
    fn catch_up(&mut self) -> Result<(), CaptureError> {
        let before = self.next_index();
        let status = self.status()?;
        // Once our plan is loaded the device never goes back to `Idle`: the controller restarted (watchdog reset
        // after a hang, a panic, power) and its RAM ring, with every unacknowledged record,
        // is gone.
        if self.plan_loaded && status.state == SessionState::Idle {
            self.refit_and_write()?;
            return Err(CaptureError::DeviceRestarted {
                shots_kept: self.shots(),
                first_lost: self.next_index(),
                acked: self.acked,
            });
        }
        self.drain_queued()?;
        self.ensure_records(status.next_index)?;
        if self.run_end.is_none() && status.state != SessionState::Running {
            self.run_end = Some(run_end_from_status(&status));
        }
        self.observer.reconnected(self.next_index() - before);
        Ok(())
    }

    fn abort(&mut self) -> Result<CaptureRecord, CaptureError> {
        self.aborting = true;
        if let Some(c) = self.client.as_mut() {
            if let Err(e) = c.request(RequestBody::Abort) {
                self.observer.log(
                    LogLevel::Warn,
                    &format!("abort request failed: {}", skinbrdf_core::error_text(&e)),
                );
            }
        }
        if let Ok(status) = self.status() {
            // Keep every record taken before the abort.
            let _ = self.drain_queued();
            if let Err(e) = self.ensure_records(status.next_index) {
                self.observer.log(
                    LogLevel::Warn,
                    &format!(
                        "could not fetch every record: {}",
                        skinbrdf_core::error_text(&e)
                    ),
                );
            }
            self.flush_acks_best_effort();
        }
        self.refit_and_write()?;
        Err(CaptureError::Aborted {
            shots_kept: self.shots(),
        })
    }

    fn session_failed(&mut self, outcome: SessionOutcome) -> Result<CaptureRecord, CaptureError> {
        self.flush_acks_best_effort();
        self.final_clock_reads();
        self.refit_and_write()?;
        let detail = match (outcome, self.last_fault) {
            (_, Some(f)) => format!(
                "{} at record {}",
                fault_text(f.kind),
                f.index.map_or_else(|| "-".into(), |i| i.to_string())
            ),
            (SessionOutcome::Aborted, None) => "the device aborted the session".into(),
            _ => "the session faulted".into(),
        };
        Err(CaptureError::DeviceFault {
            detail,
            shots_kept: self.shots(),
        })
    }
}

/// What a status says about a run that is no longer running.
fn run_end_from_status(status: &Status) -> RunEnd {
    match status.state {
        SessionState::Completed => RunEnd::Session {
            outcome: SessionOutcome::Completed,
            records: status.next_index,
        },
        SessionState::Aborted => RunEnd::Session {
            outcome: SessionOutcome::Faulted,
            records: status.next_index,
        },
        _ => RunEnd::Groups {
            next_index: status.next_index,
        },
    }
}

/// True for errors a reconnect can cure.
fn is_link_failure(e: &ClientError) -> bool {
    matches!(
        e,
        ClientError::Transport(
            TransportError::Disconnected { .. }
                | TransportError::WriteTimeout { .. }
                | TransportError::Io { .. }
        ) | ClientError::Timeout { .. }
            // The device saw the link go down and up: it wants a new handshake.
            | ClientError::Device {
                error: DeviceError::HandshakeRequired,
                ..
            }
    )
}

/// A fault kind in words.
pub fn fault_text(kind: FaultKind) -> &'static str {
    match kind {
        FaultKind::MissingXsync => "camera did not fire (no X-sync)",
        FaultKind::MissingFlash => "flash misfire (no light on the photodiode)",
        FaultKind::FlashNotReady => "flash never became ready",
        FaultKind::RetriesExhausted => "retries exhausted",
        FaultKind::HostSilent => "host silent: the device's watchdog stopped the session",
    }
}
