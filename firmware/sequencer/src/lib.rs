//! The trigger controller's sequencing logic as a sans-IO state machine (`no_std`, no
//! allocation, no async runtime).
//!
//! The driver (the RP2040 firmware, the host simulator, tests) owns the clock, the pins and the
//! link; this crate owns every decision. The contract:
//!
//! * **In**: [`Sequencer::handle`] with the current device time (`u64` microseconds since boot)
//!   and one [`Input`]: a pin edge carrying its own capture timestamp (X-sync, photodiode,
//!   flash-ready level), a decoded host [`Request`], a bad frame, link up/down. Call
//!   [`Sequencer::tick`] whenever the device time reaches [`Sequencer::next_deadline`].
//! * **Out**: after every call, apply [`Sequencer::outputs`] (the authoritative levels of the
//!   abstract [`Line`]s; [`Sequencer::take_pin_actions`] gives the same as a list of changes),
//!   send every [`Sequencer::pop_message`] (encode with [`skinbrdf_protocol::encode`]), and
//!   arm a timer for [`Sequencer::next_deadline`].
//!
//! The driver maps the abstract lines to real pins (there is no pin map in here). Timing
//! decisions use the edge timestamps, not the time an edge is handled, so a late `handle`
//! does not turn an in-time X-sync into a timeout: before an edge is applied, every deadline
//! earlier than the edge's timestamp fires first.
//!
//! # Session behaviour
//! Per attempt: wait for the group's minimum interval and the flash-ready input (up to
//! `flash_ready_timeout_us`), assert focus for `pre_focus_us`, assert the shutter for
//! `shutter_pulse_us` (focus stays held), timestamp the X-sync and photodiode edges, in
//! [`FlashMode::ControllerOnXsync`] pulse the flash-trigger output on X-sync, and emit one
//! [`ExposureRecord`]. Missing X-sync (`xsync_timeout_us` after the shutter command), missing
//! flash (`flash_window_us` after X-sync) and flash-not-ready are faults: every output is
//! released at once, a [`Fault`] event and a record with that outcome are emitted, and the
//! plan's [`FaultPolicy`] retries (a new record index) or gives up (abort or skip).
//!
//! # Guarantees (tested in `tests/`)
//! * Every attempt that began produces exactly one record; indices are contiguous from 0.
//! * Records stay in a ring buffer of `RING` entries until acknowledged; when it is full the
//!   next attempt waits for an acknowledgement, so no record is ever dropped.
//! * Abort, host silence longer than the watchdog while running, and every fault release all
//!   outputs; no path leaves the shutter, focus or flash-trigger line asserted once the session
//!   is not running.
//! * Between two presses the focus and shutter lines stay released for at least
//!   [`MIN_SHUTTER_OFF_US`] of driver time (the release and the next press are never issued by
//!   the same call), whatever the plan's intervals: otherwise the camera sees one long press.
//! * A link that goes down during a run pauses the session: the shot in flight finishes, then
//!   no new shot starts (all camera and flash lines released) until a host handshakes again;
//!   the host watchdog, which is never disabled (at most [`MAX_WATCHDOG_US`]), ends a session
//!   whose host does not come back.
#![no_std]

use core::fmt::Write as _;

use heapless::Deque;
use skinbrdf_protocol::{
    truncated, DeviceError, DeviceInfo, DeviceKind, DeviceMessage, Event, ExhaustedAction,
    ExposureRecord, Fault, FaultKind, FaultPolicy, FlashMode, FrameError, ImageRole, LogLevel,
    Plan, PlanProblem, Request, RequestBody, Response, ResponseBody, SessionOutcome, SessionState,
    ShotGroup, ShotOutcome, Status, FIRMWARE_VERSION_LEN, LOG_LINE_LEN, PROTOCOL_VERSION,
    SERIAL_LEN,
};

pub use skinbrdf_protocol as protocol;
pub use skinbrdf_protocol::{MAX_WATCHDOG_US, MIN_SHUTTER_OFF_US};

/// Default host watchdog: long enough for a USB re-enumeration, short enough that a crashed
/// host does not leave a session shooting for long.
pub const DEFAULT_WATCHDOG_US: u64 = 10_000_000;
/// Default record ring size (records, ~100 bytes each on the RP2040).
pub const DEFAULT_RING: usize = 64;
/// Outgoing message queue depth; overflow drops messages (counted), never records.
pub const TX_QUEUE_LEN: usize = 16;
/// After a flash, the flash-ready level is not trusted for this long: a flash drops its ready
/// signal when it fires, but that edge may reach us a little after the photodiode edge, and a
/// shot started in between would trigger a recycling flash. Flashes drop ready well within
/// 1 ms; 10 ms is a generous bound that costs nothing against 0.5-3 s recycle times.
pub const FLASH_READY_SETTLE_US: u64 = 10_000;

/// An abstract output line; the driver maps it to a pin (and its polarity).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Line {
    /// Camera focus (half-press) on the remote jack.
    Focus,
    /// Camera shutter (full press) on the remote jack.
    Shutter,
    /// Flash sync output (controller-fires-flash mode).
    FlashTrigger,
    /// Status LED: lit while a session runs.
    StatusLed,
}

impl Line {
    /// Every line, in a fixed order.
    pub const ALL: [Line; 4] = [
        Line::Focus,
        Line::Shutter,
        Line::FlashTrigger,
        Line::StatusLed,
    ];
}

/// Desired level of every output line (`true` = asserted). The safe state is all `false`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Outputs {
    /// Focus line asserted.
    pub focus: bool,
    /// Shutter line asserted.
    pub shutter: bool,
    /// Flash trigger asserted.
    pub flash_trigger: bool,
    /// Status LED lit.
    pub status_led: bool,
}

impl Outputs {
    /// All released.
    pub const SAFE: Outputs = Outputs {
        focus: false,
        shutter: false,
        flash_trigger: false,
        status_led: false,
    };

    /// Level of one line.
    pub fn level(&self, line: Line) -> bool {
        match line {
            Line::Focus => self.focus,
            Line::Shutter => self.shutter,
            Line::FlashTrigger => self.flash_trigger,
            Line::StatusLed => self.status_led,
        }
    }

    fn set(&mut self, line: Line, asserted: bool) {
        match line {
            Line::Focus => self.focus = asserted,
            Line::Shutter => self.shutter = asserted,
            Line::FlashTrigger => self.flash_trigger = asserted,
            Line::StatusLed => self.status_led = asserted,
        }
    }

    /// True if no camera or flash line is asserted (the LED does not count).
    pub fn camera_and_flash_released(&self) -> bool {
        !self.focus && !self.shutter && !self.flash_trigger
    }
}

/// One change of an output line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PinAction {
    /// Which line.
    pub line: Line,
    /// New level.
    pub asserted: bool,
}

/// Something the driver observed.
///
/// `Request` makes this ~740 bytes (a `LoadPlan` is inline); without an allocator there is
/// nothing to box it into, and inputs are handled one at a time.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Input {
    /// Rising edge on the hot-shoe X-sync input, captured at `at_us`.
    XsyncEdge {
        /// Capture time.
        at_us: u64,
    },
    /// Rising edge on the flash photodiode input, captured at `at_us`.
    PhotodiodeEdge {
        /// Capture time.
        at_us: u64,
    },
    /// The flash-ready input changed (or its initial level, at start-up).
    FlashReady {
        /// Capture time.
        at_us: u64,
        /// New level: true = ready.
        ready: bool,
    },
    /// A request decoded from the link.
    Request(Request),
    /// A frame from the link failed to decode.
    BadFrame(FrameError),
    /// The host opened the link (e.g. USB CDC DTR set).
    LinkUp,
    /// The link went away; outgoing messages are discarded until `LinkUp`.
    LinkDown,
}

/// Identity reported in the handshake.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Config {
    /// Firmware version string.
    pub firmware_version: heapless::String<FIRMWARE_VERSION_LEN>,
    /// Serial string.
    pub serial: heapless::String<SERIAL_LEN>,
    /// Board, simulator or emulator.
    pub kind: DeviceKind,
    /// Initial host watchdog (0: disabled).
    pub watchdog_us: u64,
}

impl Config {
    /// A config with [`DEFAULT_WATCHDOG_US`].
    pub fn new(firmware_version: &str, serial: &str, kind: DeviceKind) -> Self {
        Self {
            firmware_version: truncated(firmware_version),
            serial: truncated(serial),
            kind,
            watchdog_us: DEFAULT_WATCHDOG_US,
        }
    }
}

/// Where in an attempt we are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// Waiting for the minimum interval and flash ready.
    WaitReady {
        earliest_us: u64,
        ready_deadline_us: u64,
    },
    /// Focus held; shutter at `shutter_at_us`.
    Focus { shutter_at_us: u64 },
    /// Shutter commanded; waiting for X-sync / flash / outcome.
    Exposing,
    /// Outcome Ok known; waiting for the shutter pulse and flash trigger pulse to end.
    Settling,
}

/// The attempt in flight.
#[derive(Debug, Clone, Copy)]
struct Attempt {
    group: u32,
    shot: u32,
    attempt: u32,
    role: ImageRole,
    started_us: u64,
    stage: Stage,
    shutter_command_us: Option<u64>,
    xsync_us: Option<u64>,
    flash_fired_us: Option<u64>,
    recycle_us: Option<u64>,
    shutter_release_us: Option<u64>,
    flash_trigger_release_us: Option<u64>,
    xsync_deadline_us: Option<u64>,
    flash_deadline_us: Option<u64>,
}

/// The run in progress (`Run { first_group, last_group }`).
#[derive(Debug, Clone, Copy)]
struct RunState {
    last_group: u32,
    /// Next shot to take (group, shot, attempt).
    group: u32,
    shot: u32,
    attempt: u32,
    /// The attempt in flight; `None` while waiting for ring space.
    current: Option<Attempt>,
}

/// The sequencer. `RING` is the record ring capacity.
#[derive(Debug)]
pub struct Sequencer<const RING: usize = DEFAULT_RING> {
    config: Config,
    /// Logical time: the time of the event being processed.
    now_us: u64,
    /// Real time of the current `handle`/`tick` call: commands issued now are stamped with it.
    wall_us: u64,
    outputs: Outputs,
    applied: Outputs,
    tx: Deque<DeviceMessage, TX_QUEUE_LEN>,
    ring: Deque<ExposureRecord, RING>,
    /// Resend cursor of a `FetchRecords` in progress.
    resend_from: Option<u32>,
    link_up: bool,
    handshaken: bool,
    watchdog_us: u64,
    last_request_us: u64,
    state: SessionState,
    plan: Option<Plan>,
    next_group: u32,
    next_index: u32,
    run: Option<RunState>,
    flash_ready: bool,
    last_flash_us: Option<u64>,
    /// Time of the most recent photodiode edge (never cleared).
    last_light_us: Option<u64>,
    last_recycle_us: Option<u64>,
    last_shutter_us: Option<u64>,
    /// Driver time at which focus or shutter was last released: the next press waits
    /// [`MIN_SHUTTER_OFF_US`] from here.
    camera_released_us: Option<u64>,
    /// The link went down during a run: no new attempt starts until a host handshakes.
    paused: bool,
    bad_frames: u32,
    dropped_messages: u32,
    /// The last response, for retries that reuse its `seq`.
    last_response: Option<Response>,
}

impl<const RING: usize> Sequencer<RING> {
    /// A sequencer at device time `now_us`, all outputs released, link up, no plan.
    pub fn new(config: Config, now_us: u64) -> Self {
        Self {
            watchdog_us: bounded_watchdog(config.watchdog_us),
            config,
            now_us,
            wall_us: now_us,
            outputs: Outputs::SAFE,
            applied: Outputs::SAFE,
            tx: Deque::new(),
            ring: Deque::new(),
            resend_from: None,
            link_up: true,
            handshaken: false,
            last_request_us: now_us,
            state: SessionState::Idle,
            plan: None,
            next_group: 0,
            next_index: 0,
            run: None,
            flash_ready: false,
            last_flash_us: None,
            last_light_us: None,
            last_recycle_us: None,
            last_shutter_us: None,
            camera_released_us: None,
            paused: false,
            bad_frames: 0,
            dropped_messages: 0,
            last_response: None,
        }
    }

    // -----------------------------------------------------------------------------------------
    // Driver API
    // -----------------------------------------------------------------------------------------

    /// Handles one input at device time `now_us` (monotonic; an earlier value is treated as
    /// the last one seen).
    ///
    /// Edges carry their capture time: deadlines up to that time fire first, then the edge is
    /// applied; deadlines after it wait for the next input or [`Self::tick`] (so hand over
    /// every queued edge, oldest first, then tick). Requests and link changes happen at
    /// `now_us`.
    pub fn handle(&mut self, now_us: u64, input: Input) {
        let now_us = now_us.max(self.now_us);
        self.wall_us = now_us;
        match input {
            Input::XsyncEdge { at_us } => {
                let at = at_us.min(now_us);
                self.advance_to(at);
                self.on_xsync(at);
            }
            Input::PhotodiodeEdge { at_us } => {
                let at = at_us.min(now_us);
                self.advance_to(at);
                self.on_photodiode(at);
            }
            Input::FlashReady { at_us, ready } => {
                let at = at_us.min(now_us);
                self.advance_to(at);
                self.on_flash_ready(at, ready);
            }
            Input::Request(req) => {
                self.advance_to(now_us);
                self.on_request(req);
            }
            Input::BadFrame(_) => {
                self.advance_to(now_us);
                self.bad_frames = self.bad_frames.saturating_add(1);
            }
            Input::LinkUp => {
                self.advance_to(now_us);
                self.link_up = true;
                self.handshaken = false;
                self.last_response = None;
            }
            Input::LinkDown => {
                self.advance_to(now_us);
                // The host is gone: finish the shot in flight, start no other until it is back.
                if let Some(mut run) = self.run {
                    self.paused = true;
                    // An attempt still waiting for its interval or the flash has done nothing
                    // yet: drop it, the same shot starts afresh when the host is back.
                    if run
                        .current
                        .is_some_and(|a| matches!(a.stage, Stage::WaitReady { .. }))
                    {
                        run.current = None;
                        self.run = Some(run);
                    }
                }
                self.link_up = false;
                self.handshaken = false;
                self.last_response = None;
                self.tx.clear();
                self.resend_from = None;
            }
        }
        // Edges only advance time to their capture time: an edge captured later but not yet
        // handed over must still be able to beat a deadline that lies between the two. The
        // driver hands over queued edges in capture order, then calls `tick`.
    }

    /// Fires every deadline up to `now_us`. Call when the time reaches [`Self::next_deadline`]
    /// (calling more often is harmless).
    pub fn tick(&mut self, now_us: u64) {
        let now_us = now_us.max(self.now_us);
        self.wall_us = now_us;
        self.advance_to(now_us);
    }

    /// The earliest device time at which [`Self::tick`] must be called, if any.
    pub fn next_deadline(&self) -> Option<u64> {
        let mut next: Option<u64> = None;
        let mut consider = |t: Option<u64>| {
            if let Some(t) = t {
                next = Some(next.map_or(t, |n| n.min(t)));
            }
        };
        if let Some(run) = &self.run {
            consider(Some(self.last_request_us.saturating_add(self.watchdog_us)));
            if let Some(a) = &run.current {
                match a.stage {
                    Stage::WaitReady {
                        earliest_us,
                        ready_deadline_us,
                    } => {
                        let go_us = earliest_us.max(self.settle_until_us());
                        if go_us > self.now_us {
                            consider(Some(go_us));
                        }
                        consider(Some(ready_deadline_us));
                    }
                    Stage::Focus { shutter_at_us } => consider(Some(shutter_at_us)),
                    Stage::Exposing | Stage::Settling => {}
                }
                consider(a.shutter_release_us);
                consider(a.flash_trigger_release_us);
                if a.stage == Stage::Exposing {
                    if a.xsync_us.is_none() {
                        consider(a.xsync_deadline_us);
                    }
                    if a.flash_fired_us.is_none() {
                        consider(a.flash_deadline_us);
                    }
                }
            }
        }
        next
    }

    /// The levels every output line must have now.
    pub fn outputs(&self) -> Outputs {
        self.outputs
    }

    /// The line changes since the last call (lossless: computed from levels).
    pub fn take_pin_actions(&mut self) -> PinActions {
        let before = self.applied;
        self.applied = self.outputs;
        PinActions {
            before,
            after: self.outputs,
            next: 0,
        }
    }

    /// The next message to send, if any (responses and events in order, then records being
    /// resent by `FetchRecords`).
    pub fn pop_message(&mut self) -> Option<DeviceMessage> {
        if let Some(m) = self.tx.pop_front() {
            return Some(m);
        }
        let from = self.resend_from?;
        match self.ring.iter().find(|r| r.index >= from) {
            Some(r) => {
                self.resend_from = Some(r.index.saturating_add(1));
                Some(DeviceMessage::Event(Event::Record(r.clone())))
            }
            None => {
                self.resend_from = None;
                None
            }
        }
    }

    /// True if [`Self::pop_message`] would return a message.
    pub fn has_message(&self) -> bool {
        !self.tx.is_empty()
            || self
                .resend_from
                .is_some_and(|from| self.ring.iter().any(|r| r.index >= from))
    }

    /// Session state.
    pub fn state(&self) -> SessionState {
        self.state
    }

    /// Status snapshot (as sent for `GetStatus`).
    pub fn status(&self) -> Status {
        Status {
            now_us: self.now_us,
            state: self.state,
            next_index: self.next_index,
            unacked: self.unacked(),
            oldest_unacked: self.ring.front().map(|r| r.index),
            flash_ready: self.flash_ready,
            bad_frames: self.bad_frames,
            dropped_messages: self.dropped_messages,
            watchdog_us: self.watchdog_us,
        }
    }

    /// Records held unacknowledged.
    pub fn unacked(&self) -> u32 {
        u32::try_from(self.ring.len()).unwrap_or(u32::MAX)
    }

    /// The unacknowledged records, oldest first.
    pub fn unacked_records(&self) -> impl Iterator<Item = &ExposureRecord> {
        self.ring.iter()
    }

    /// Whether the link is up.
    pub fn link_up(&self) -> bool {
        self.link_up
    }

    /// Whether the run is paused because the link went down (until a host handshakes).
    pub fn paused(&self) -> bool {
        self.paused
    }

    // -----------------------------------------------------------------------------------------
    // Time
    // -----------------------------------------------------------------------------------------

    /// Fires deadlines `<= until_us` in order, each at its own time (commands issued while
    /// catching up are stamped with the real time `wall_us`).
    fn advance_to(&mut self, until_us: u64) {
        // Each deadline either ends an attempt stage or is removed; bound the loop anyway.
        for _ in 0..64 {
            match self.next_deadline() {
                Some(d) if d <= until_us => {
                    self.now_us = self.now_us.max(d).min(self.wall_us);
                    self.fire_deadline(d);
                }
                _ => break,
            }
        }
        self.now_us = self.now_us.max(until_us);
    }

    fn fire_deadline(&mut self, d: u64) {
        let Some(run) = self.run else { return };
        if self.last_request_us.saturating_add(self.watchdog_us) <= d {
            self.push_event(Event::Fault(Fault {
                at_us: d,
                kind: FaultKind::HostSilent,
                index: run.current.map(|_| self.next_index),
            }));
            self.abort(d, SessionOutcome::Faulted);
            return;
        }
        let Some(mut a) = run.current else { return };
        // Pulse ends first: they never depend on anything else.
        if a.shutter_release_us.is_some_and(|t| t <= d) {
            a.shutter_release_us = None;
            self.set_line(Line::Shutter, false);
            self.set_line(Line::Focus, false);
        }
        if a.flash_trigger_release_us.is_some_and(|t| t <= d) {
            a.flash_trigger_release_us = None;
            self.set_line(Line::FlashTrigger, false);
        }
        self.store_attempt(a);
        match a.stage {
            Stage::WaitReady {
                ready_deadline_us, ..
            } => {
                if self.flash_ready_and_interval_ok(a, d) {
                    self.begin_focus();
                } else if ready_deadline_us <= d {
                    self.fault(d, FaultKind::FlashNotReady, ShotOutcome::FlashNotReady);
                }
            }
            Stage::Focus { shutter_at_us } => {
                if shutter_at_us <= d {
                    self.fire_shutter();
                }
            }
            Stage::Exposing => {
                if a.xsync_us.is_none() && a.xsync_deadline_us.is_some_and(|t| t <= d) {
                    self.fault(d, FaultKind::MissingXsync, ShotOutcome::MissingXsync);
                } else if a.xsync_us.is_some()
                    && a.flash_fired_us.is_none()
                    && a.flash_deadline_us.is_some_and(|t| t <= d)
                {
                    self.fault(d, FaultKind::MissingFlash, ShotOutcome::MissingFlash);
                }
            }
            Stage::Settling => self.settle_if_done(d),
        }
    }

    // -----------------------------------------------------------------------------------------
    // Shots
    // -----------------------------------------------------------------------------------------

    fn group(&self, g: u32) -> Option<&ShotGroup> {
        self.plan.as_ref()?.groups.get(g as usize)
    }

    fn policy(&self) -> FaultPolicy {
        self.plan.as_ref().map_or(
            FaultPolicy {
                max_retries: 0,
                on_exhausted: ExhaustedAction::AbortSession,
            },
            |p| p.policy,
        )
    }

    fn store_attempt(&mut self, a: Attempt) {
        if let Some(run) = self.run.as_mut() {
            run.current = Some(a);
        }
    }

    fn attempt(&self) -> Option<Attempt> {
        self.run.and_then(|r| r.current)
    }

    fn flash_ready_and_interval_ok(&self, a: Attempt, t: u64) -> bool {
        match a.stage {
            Stage::WaitReady { earliest_us, .. } => {
                self.flash_ready && earliest_us <= t && self.settle_until_us() <= t
            }
            _ => false,
        }
    }

    /// Until when the ready level is not trusted ([`FLASH_READY_SETTLE_US`] after a flash).
    fn settle_until_us(&self) -> u64 {
        self.last_light_us
            .map_or(0, |f| f.saturating_add(FLASH_READY_SETTLE_US))
    }

    /// Starts the run's next attempt (or waits for ring space).
    fn start_attempt(&mut self, t: u64) {
        let Some(mut run) = self.run else { return };
        if self.ring.is_full() || self.paused {
            run.current = None;
            self.run = Some(run);
            return;
        }
        let Some(g) = self.group(run.group).cloned() else {
            return;
        };
        // Every path here has released the camera lines; make sure, so the off time below
        // is measured from a real release.
        self.set_line(Line::Shutter, false);
        self.set_line(Line::Focus, false);
        let off_until_us = self
            .camera_released_us
            .map_or(0, |r| r.saturating_add(MIN_SHUTTER_OFF_US));
        let earliest_us = self
            .last_shutter_us
            .map_or(t, |s| s.saturating_add(g.min_interval_us))
            .max(off_until_us)
            .max(t);
        let a = Attempt {
            group: run.group,
            shot: run.shot,
            attempt: run.attempt,
            role: g.role,
            started_us: t,
            stage: Stage::WaitReady {
                earliest_us,
                ready_deadline_us: earliest_us
                    .max(self.settle_until_us())
                    .saturating_add(g.flash_ready_timeout_us),
            },
            shutter_command_us: None,
            xsync_us: None,
            flash_fired_us: None,
            recycle_us: None,
            shutter_release_us: None,
            flash_trigger_release_us: None,
            xsync_deadline_us: None,
            flash_deadline_us: None,
        };
        run.current = Some(a);
        self.run = Some(run);
        if self.flash_ready_and_interval_ok(a, t) {
            self.begin_focus();
        }
    }

    fn begin_focus(&mut self) {
        let wall_us = self.wall_us;
        let Some(mut a) = self.attempt() else { return };
        let Some(g) = self.group(a.group).cloned() else {
            return;
        };
        self.set_line(Line::Focus, true);
        a.stage = Stage::Focus {
            shutter_at_us: wall_us.saturating_add(g.pre_focus_us),
        };
        self.store_attempt(a);
        if g.pre_focus_us == 0 {
            self.fire_shutter();
        }
    }

    fn fire_shutter(&mut self) {
        let wall_us = self.wall_us;
        let Some(mut a) = self.attempt() else { return };
        let Some(g) = self.group(a.group).cloned() else {
            return;
        };
        self.set_line(Line::Focus, true);
        self.set_line(Line::Shutter, true);
        a.stage = Stage::Exposing;
        a.shutter_command_us = Some(wall_us);
        a.shutter_release_us = Some(wall_us.saturating_add(g.shutter_pulse_us));
        a.xsync_deadline_us = Some(wall_us.saturating_add(g.xsync_timeout_us));
        a.recycle_us = self.last_recycle_us;
        self.last_shutter_us = Some(wall_us);
        self.store_attempt(a);
    }

    fn on_xsync(&mut self, at: u64) {
        let Some(mut a) = self.attempt() else {
            self.log(at, LogLevel::Warn, "X-sync edge outside an exposure");
            return;
        };
        let commanded = a.shutter_command_us.is_some_and(|s| s <= at);
        if a.stage != Stage::Exposing || !commanded || a.xsync_us.is_some() {
            self.log(at, LogLevel::Debug, "X-sync edge ignored");
            return;
        }
        let Some(g) = self.group(a.group).cloned() else {
            return;
        };
        a.xsync_us = Some(at);
        a.flash_deadline_us = Some(at.saturating_add(g.flash_window_us));
        if g.flash_mode == FlashMode::ControllerOnXsync {
            let pulse = self.plan.as_ref().map_or(0, |p| p.flash_trigger_pulse_us);
            self.set_line(Line::FlashTrigger, true);
            a.flash_trigger_release_us = Some(self.wall_us.saturating_add(pulse));
        }
        self.store_attempt(a);
        if a.flash_fired_us.is_some() {
            self.shot_ok(at);
        }
    }

    fn on_photodiode(&mut self, at: u64) {
        self.last_flash_us = Some(at);
        self.last_light_us = Some(at);
        self.last_recycle_us = None;
        let Some(mut a) = self.attempt() else {
            self.log(at, LogLevel::Warn, "flash seen outside an exposure");
            return;
        };
        let commanded = a.shutter_command_us.is_some_and(|s| s <= at);
        if a.stage != Stage::Exposing || !commanded || a.flash_fired_us.is_some() {
            return;
        }
        a.flash_fired_us = Some(at);
        self.store_attempt(a);
        if a.xsync_us.is_some() {
            self.shot_ok(at);
        }
    }

    fn on_flash_ready(&mut self, at: u64, ready: bool) {
        if ready == self.flash_ready {
            return;
        }
        self.flash_ready = ready;
        let mut recycle_us = None;
        if ready {
            if let Some(f) = self.last_flash_us.take() {
                recycle_us = Some(at.saturating_sub(f));
                self.last_recycle_us = recycle_us;
            }
        }
        self.push_event(Event::FlashReady {
            at_us: at,
            ready,
            recycle_us,
        });
        if let Some(a) = self.attempt() {
            if self.flash_ready_and_interval_ok(a, at) {
                self.begin_focus();
            }
        }
    }

    fn shot_ok(&mut self, t: u64) {
        let Some(mut a) = self.attempt() else { return };
        a.stage = Stage::Settling;
        self.store_attempt(a);
        self.settle_if_done(t);
    }

    fn settle_if_done(&mut self, t: u64) {
        let Some(a) = self.attempt() else { return };
        if a.stage == Stage::Settling
            && a.shutter_release_us.is_none()
            && a.flash_trigger_release_us.is_none()
        {
            self.finish_attempt(t, ShotOutcome::Ok);
        }
    }

    /// A fault: release everything now, report, record, apply the policy.
    fn fault(&mut self, t: u64, kind: FaultKind, outcome: ShotOutcome) {
        self.release_camera_and_flash();
        if let Some(mut a) = self.attempt() {
            a.shutter_release_us = None;
            a.flash_trigger_release_us = None;
            self.store_attempt(a);
        }
        self.push_event(Event::Fault(Fault {
            at_us: t,
            kind,
            index: Some(self.next_index),
        }));
        self.finish_attempt(t, outcome);
    }

    /// Emits the attempt's record and moves to the next attempt / group / end.
    fn finish_attempt(&mut self, t: u64, outcome: ShotOutcome) {
        let Some(mut run) = self.run else { return };
        let Some(a) = run.current.take() else { return };
        self.run = Some(run);
        self.emit_record(&a, outcome);
        if outcome == ShotOutcome::Aborted {
            return;
        }
        let mut advance = outcome == ShotOutcome::Ok;
        if !advance {
            let policy = self.policy();
            if run.attempt < policy.max_retries {
                run.attempt += 1;
            } else {
                self.push_event(Event::Fault(Fault {
                    at_us: t,
                    kind: FaultKind::RetriesExhausted,
                    index: Some(self.next_index.saturating_sub(1)),
                }));
                match policy.on_exhausted {
                    ExhaustedAction::AbortSession => {
                        self.abort(t, SessionOutcome::Faulted);
                        return;
                    }
                    ExhaustedAction::SkipShot => advance = true,
                }
            }
        }
        if advance {
            run.attempt = 0;
            run.shot += 1;
            let count = self.group(run.group).map_or(0, |g| g.count);
            if run.shot >= count {
                run.shot = 0;
                run.group += 1;
                self.next_group = run.group;
                if run.group > run.last_group {
                    self.end_run(t, run.last_group);
                    return;
                }
            }
        }
        self.run = Some(run);
        self.start_attempt(t);
    }

    fn end_run(&mut self, t: u64, last_group: u32) {
        self.run = None;
        self.release_all();
        self.push_event(Event::GroupsDone {
            at_us: t,
            last_group,
            next_index: self.next_index,
        });
        let groups = self.plan.as_ref().map_or(0, |p| p.groups.len());
        if self.next_group as usize >= groups {
            self.state = SessionState::Completed;
            self.push_event(Event::SessionDone {
                at_us: t,
                outcome: SessionOutcome::Completed,
                records: self.next_index,
            });
        } else {
            self.state = SessionState::Ready;
        }
    }

    fn emit_record(&mut self, a: &Attempt, outcome: ShotOutcome) {
        let record = ExposureRecord {
            index: self.next_index,
            group: a.group,
            shot: a.shot,
            attempt: a.attempt,
            role: a.role,
            started_us: a.started_us,
            shutter_command_us: a.shutter_command_us,
            xsync_us: a.xsync_us,
            flash_fired_us: a.flash_fired_us,
            recycle_us: a.recycle_us,
            outcome,
        };
        self.next_index = self.next_index.saturating_add(1);
        // Live copy, unless a resend is under way (it will include this record, in order).
        if self.resend_from.is_none() {
            self.push_event(Event::Record(record.clone()));
        }
        // `start_attempt` only starts an attempt when the ring has room.
        if self.ring.push_back(record).is_err() {
            self.dropped_messages = self.dropped_messages.saturating_add(1);
        }
    }

    /// Ends the session: the attempt in flight (if any) is recorded as `Aborted`.
    fn abort(&mut self, t: u64, outcome: SessionOutcome) {
        if let Some(run) = self.run {
            if let Some(a) = run.current {
                self.emit_record(&a, ShotOutcome::Aborted);
            }
        }
        self.run = None;
        self.release_all();
        if matches!(self.state, SessionState::Running | SessionState::Ready) {
            self.state = SessionState::Aborted;
            self.push_event(Event::SessionDone {
                at_us: t,
                outcome,
                records: self.next_index,
            });
        }
    }

    // -----------------------------------------------------------------------------------------
    // Requests
    // -----------------------------------------------------------------------------------------

    fn on_request(&mut self, req: Request) {
        self.last_request_us = self.now_us;
        let is_hello = matches!(req.body, RequestBody::Hello { .. });
        let response = match &self.last_response {
            // A retry (same seq as the last request): answer again, do not execute again.
            Some(last) if last.seq == req.seq && !is_hello => last.clone(),
            _ => {
                let response = Response {
                    seq: req.seq,
                    result: self.answer(req.body),
                };
                // A handshake starts a new conversation: no retry may reach back past it.
                self.last_response = if is_hello {
                    None
                } else {
                    Some(response.clone())
                };
                response
            }
        };
        self.push_message(DeviceMessage::Response(response));
        // Ring space may have been freed by an ack.
        if let Some(run) = self.run {
            if run.current.is_none() && !self.ring.is_full() {
                self.start_attempt(self.now_us);
            }
        }
    }

    fn answer(&mut self, body: RequestBody) -> Result<ResponseBody, DeviceError> {
        let now = self.now_us;
        if let RequestBody::Hello { protocol_version } = body {
            if protocol_version != PROTOCOL_VERSION {
                self.handshaken = false;
                return Err(DeviceError::VersionMismatch {
                    device: PROTOCOL_VERSION,
                    host: protocol_version,
                });
            }
            self.handshaken = true;
            self.link_up = true;
            if self.paused {
                // The host is back; `on_request` starts the next attempt.
                self.paused = false;
                self.log(
                    now,
                    LogLevel::Warn,
                    "link was lost: session paused, now resumed",
                );
            }
            return Ok(ResponseBody::Hello(DeviceInfo {
                protocol_version: PROTOCOL_VERSION,
                firmware_version: self.config.firmware_version.clone(),
                serial: self.config.serial.clone(),
                kind: self.config.kind,
                clock_us: now,
            }));
        }
        if !self.handshaken {
            return Err(DeviceError::HandshakeRequired);
        }
        match body {
            RequestBody::Hello { .. } => Err(DeviceError::HandshakeRequired),
            RequestBody::ReadClock => Ok(ResponseBody::Clock { device_us: now }),
            RequestBody::Ping => Ok(ResponseBody::Pong { device_us: now }),
            RequestBody::GetStatus => Ok(ResponseBody::Status(self.status())),
            RequestBody::SetWatchdog { timeout_us } => {
                self.watchdog_us = bounded_watchdog(timeout_us);
                Ok(ResponseBody::WatchdogSet {
                    timeout_us: self.watchdog_us,
                })
            }
            RequestBody::LoadPlan(plan) => self.load_plan(plan),
            RequestBody::Run {
                first_group,
                last_group,
            } => self.start_run(first_group, last_group),
            RequestBody::Abort => {
                let was_running = self.state == SessionState::Running;
                self.abort(now, SessionOutcome::Aborted);
                Ok(ResponseBody::Aborted { was_running })
            }
            RequestBody::AckRecords { next_index } => {
                if next_index > self.next_index {
                    return Err(DeviceError::AckBeyondEnd {
                        next_index: self.next_index,
                    });
                }
                while self.ring.front().is_some_and(|r| r.index < next_index) {
                    self.ring.pop_front();
                }
                Ok(ResponseBody::Acked {
                    unacked: self.unacked(),
                })
            }
            RequestBody::FetchRecords { from_index } => {
                let oldest_held = self.ring.front().map_or(self.next_index, |r| r.index);
                if from_index < oldest_held {
                    return Err(DeviceError::AlreadyAcked { oldest_held });
                }
                let count = self.ring.iter().filter(|r| r.index >= from_index).count();
                // Records already queued live are superseded by the resend (kept in order).
                self.tx
                    .retain(|m| !matches!(m, DeviceMessage::Event(Event::Record(_))));
                self.resend_from = Some(from_index);
                Ok(ResponseBody::Fetching {
                    count: u32::try_from(count).unwrap_or(u32::MAX),
                })
            }
        }
    }

    fn load_plan(&mut self, plan: Plan) -> Result<ResponseBody, DeviceError> {
        if self.state == SessionState::Running {
            return Err(DeviceError::Busy);
        }
        if !self.ring.is_empty() {
            return Err(DeviceError::UnackedRecords {
                unacked: self.unacked(),
            });
        }
        let total_shots = validate_plan(&plan)?;
        if let Some((group, off_us)) = short_off_time(&plan) {
            let mut text = heapless::String::<LOG_LINE_LEN>::new();
            let _ = write!(
                text,
                "group {group}: interval leaves {} ms between presses; spaced to {} ms",
                off_us / 1000,
                MIN_SHUTTER_OFF_US / 1000
            );
            self.push_event(Event::Log {
                at_us: self.now_us,
                level: LogLevel::Warn,
                text,
            });
        }
        self.plan = Some(plan);
        self.state = SessionState::Ready;
        self.next_group = 0;
        self.next_index = 0;
        self.resend_from = None;
        self.paused = false;
        Ok(ResponseBody::PlanLoaded { total_shots })
    }

    fn start_run(
        &mut self,
        first_group: u32,
        last_group: u32,
    ) -> Result<ResponseBody, DeviceError> {
        let groups = match (&self.plan, self.state) {
            (None, _) | (_, SessionState::Idle) => return Err(DeviceError::NoPlan),
            (_, SessionState::Running) => return Err(DeviceError::Busy),
            (_, SessionState::Aborted) => return Err(DeviceError::SessionAborted),
            (Some(p), _) => u32::try_from(p.groups.len()).unwrap_or(u32::MAX),
        };
        if self.state != SessionState::Ready
            || first_group != self.next_group
            || last_group < first_group
            || last_group >= groups
        {
            return Err(DeviceError::BadGroupRange {
                groups,
                next_group: self.next_group,
            });
        }
        self.state = SessionState::Running;
        self.set_line(Line::StatusLed, true);
        let first_index = self.next_index;
        self.run = Some(RunState {
            last_group,
            group: first_group,
            shot: 0,
            attempt: 0,
            current: None,
        });
        self.start_attempt(self.now_us);
        Ok(ResponseBody::Running { first_index })
    }

    // -----------------------------------------------------------------------------------------
    // Outputs
    // -----------------------------------------------------------------------------------------

    fn set_line(&mut self, line: Line, asserted: bool) {
        if matches!(line, Line::Focus | Line::Shutter) && !asserted && self.outputs.level(line) {
            // Driver time, not the deadline being caught up on: the line really drops when
            // the driver applies this call's outputs.
            self.camera_released_us = Some(self.wall_us);
        }
        self.outputs.set(line, asserted);
    }

    fn release_camera_and_flash(&mut self) {
        self.set_line(Line::Focus, false);
        self.set_line(Line::Shutter, false);
        self.set_line(Line::FlashTrigger, false);
    }

    fn release_all(&mut self) {
        self.release_camera_and_flash();
        self.set_line(Line::StatusLed, false);
    }

    fn push_event(&mut self, event: Event) {
        self.push_message(DeviceMessage::Event(event));
    }

    fn push_message(&mut self, msg: DeviceMessage) {
        if !self.link_up {
            return;
        }
        if self.tx.push_back(msg).is_err() {
            self.dropped_messages = self.dropped_messages.saturating_add(1);
        }
    }

    fn log(&mut self, at_us: u64, level: LogLevel, text: &str) {
        self.push_event(Event::Log {
            at_us,
            level,
            text: truncated::<LOG_LINE_LEN>(text),
        });
    }
}

/// `0` (no watchdog) and values above [`MAX_WATCHDOG_US`] become [`MAX_WATCHDOG_US`].
fn bounded_watchdog(timeout_us: u64) -> u64 {
    if timeout_us == 0 {
        MAX_WATCHDOG_US
    } else {
        timeout_us.min(MAX_WATCHDOG_US)
    }
}

/// The first group whose shots would press the shutter less than [`MIN_SHUTTER_OFF_US`] after
/// the previous press was released (within the group, or after the previous group's last
/// shot), with the off time the plan alone would give. The sequencer spaces such presses to
/// the minimum; this is for telling the host so.
///
/// A press is released `shutter_pulse_us` after its shutter command and the next attempt may
/// assert focus `min_interval_us` after that command, so the plan's off time is
/// `min_interval_us - shutter_pulse_us` of the previous press.
pub fn short_off_time(plan: &Plan) -> Option<(u32, u64)> {
    let mut prev_pulse: Option<u64> = None;
    for (i, g) in plan.groups.iter().enumerate() {
        let group = u32::try_from(i).unwrap_or(u32::MAX);
        let before = [prev_pulse, (g.count > 1).then_some(g.shutter_pulse_us)];
        for pulse in before.into_iter().flatten() {
            let off = g.min_interval_us.saturating_sub(pulse);
            if off < MIN_SHUTTER_OFF_US {
                return Some((group, off));
            }
        }
        prev_pulse = Some(g.shutter_pulse_us);
    }
    None
}

/// Checks a plan; returns its total shot count.
pub fn validate_plan(plan: &Plan) -> Result<u32, DeviceError> {
    let bad = |group: usize, problem| DeviceError::InvalidPlan {
        group: u32::try_from(group).unwrap_or(u32::MAX),
        problem,
    };
    if plan.groups.is_empty() {
        return Err(bad(0, PlanProblem::NoGroups));
    }
    for (i, g) in plan.groups.iter().enumerate() {
        if g.count == 0 {
            return Err(bad(i, PlanProblem::ZeroCount));
        }
        if g.shutter_pulse_us == 0 {
            return Err(bad(i, PlanProblem::ZeroShutterPulse));
        }
        if g.xsync_timeout_us == 0 {
            return Err(bad(i, PlanProblem::ZeroXsyncTimeout));
        }
        if g.flash_window_us == 0 {
            return Err(bad(i, PlanProblem::ZeroFlashWindow));
        }
        if g.flash_mode == FlashMode::ControllerOnXsync && plan.flash_trigger_pulse_us == 0 {
            return Err(bad(i, PlanProblem::ZeroFlashTriggerPulse));
        }
    }
    u32::try_from(plan.total_shots()).map_err(|_| bad(0, PlanProblem::TooManyShots))
}

/// Iterator over line changes, from [`Sequencer::take_pin_actions`].
#[derive(Debug, Clone)]
pub struct PinActions {
    before: Outputs,
    after: Outputs,
    next: usize,
}

impl Iterator for PinActions {
    type Item = PinAction;

    fn next(&mut self) -> Option<PinAction> {
        while let Some(&line) = Line::ALL.get(self.next) {
            self.next += 1;
            let (b, a) = (self.before.level(line), self.after.level(line));
            if b != a {
                return Some(PinAction { line, asserted: a });
            }
        }
        None
    }
}
