//! A deterministic test bench: the sequencer plus an idealised camera and flash, driven by an
//! event loop on a simulated clock (no sleeping, no threads).

#![allow(dead_code)]

use skinbrdf_protocol::*;
use skinbrdf_sequencer::{Config, Input, Line, Outputs, PinAction, Sequencer};

/// Scheduled stimulus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stim {
    Xsync,
    Photodiode,
    Ready(bool),
}

/// Camera and flash behaviour.
#[derive(Debug, Clone, Copy)]
pub struct Hardware {
    /// Shutter command to X-sync.
    pub shutter_lag_us: u64,
    /// The camera fires when the shutter line is asserted.
    pub camera_fires: bool,
    /// X-sync (hot shoe) or flash-trigger assertion to photodiode.
    pub flash_delay_us: u64,
    /// Flash recycle time (photodiode to ready).
    pub recycle_us: u64,
    /// The flash emits light when triggered while ready.
    pub flash_fires: bool,
    /// The flash ever becomes ready after firing.
    pub becomes_ready: bool,
    /// The flash is wired as in this mode (who triggers it).
    pub mode: FlashMode,
    /// Delay of the ready line's falling edge after the light.
    pub ready_drop_delay_us: u64,
}

impl Default for Hardware {
    fn default() -> Self {
        Self {
            shutter_lag_us: 80_000,
            camera_fires: true,
            flash_delay_us: 50,
            recycle_us: 1_500_000,
            flash_fires: true,
            becomes_ready: true,
            mode: FlashMode::CameraHotShoe,
            ready_drop_delay_us: 0,
        }
    }
}

pub struct World<const RING: usize = 64> {
    pub seq: Sequencer<RING>,
    pub now: u64,
    pub hw: Hardware,
    pub flash_ready: bool,
    pub pending: Vec<(u64, Stim)>,
    pub msgs: Vec<DeviceMessage>,
    pub pin_log: Vec<(u64, PinAction)>,
    pub next_seq: u32,
    /// Extra delay between an edge and its `handle` (interrupt latency).
    pub handling_delay_us: u64,
    /// Flash triggers that found the flash recycling.
    pub triggers_while_recycling: u32,
}

impl<const RING: usize> World<RING> {
    pub fn new(start_us: u64, hw: Hardware) -> Self {
        let seq = Sequencer::new(
            Config::new("0.1.0", "TEST-1", DeviceKind::Simulator),
            start_us,
        );
        let mut w = Self {
            seq,
            now: start_us,
            hw,
            flash_ready: true,
            pending: Vec::new(),
            msgs: Vec::new(),
            pin_log: Vec::new(),
            next_seq: 1,
            handling_delay_us: 0,
            triggers_while_recycling: 0,
        };
        w.input(Input::FlashReady {
            at_us: start_us,
            ready: true,
        });
        w
    }

    /// Handshaken world.
    pub fn connected(start_us: u64, hw: Hardware) -> Self {
        let mut w = Self::new(start_us, hw);
        w.request(RequestBody::Hello {
            protocol_version: PROTOCOL_VERSION,
        })
        .expect("hello");
        w
    }

    pub fn input(&mut self, input: Input) {
        self.seq.handle(self.now, input);
        self.after_call();
    }

    fn after_call(&mut self) {
        let actions: Vec<PinAction> = self.seq.take_pin_actions().collect();
        for a in actions {
            self.pin_log.push((self.now, a));
            self.react(a);
        }
        while let Some(m) = self.seq.pop_message() {
            self.msgs.push(m);
        }
    }

    fn schedule(&mut self, at: u64, s: Stim) {
        self.pending.push((at, s));
    }

    /// The hardware's response to an output change.
    fn react(&mut self, a: PinAction) {
        match (a.line, a.asserted) {
            (Line::Shutter, true) if self.hw.camera_fires => {
                let t = self.now + self.hw.shutter_lag_us;
                self.schedule(t, Stim::Xsync);
            }
            (Line::FlashTrigger, true) if self.hw.mode == FlashMode::ControllerOnXsync => {
                self.flash_triggered(self.now);
            }
            _ => {}
        }
    }

    fn flash_triggered(&mut self, t: u64) {
        if !self.flash_ready {
            self.triggers_while_recycling += 1;
        }
        if self.flash_ready && self.hw.flash_fires {
            let fire = t + self.hw.flash_delay_us;
            self.schedule(fire, Stim::Photodiode);
            self.schedule(fire + self.hw.ready_drop_delay_us, Stim::Ready(false));
            if self.hw.becomes_ready {
                self.schedule(fire + self.hw.recycle_us, Stim::Ready(true));
            }
        }
    }

    fn deliver(&mut self, at: u64, s: Stim) {
        match s {
            Stim::Xsync => {
                self.input(Input::XsyncEdge { at_us: at });
                if self.hw.mode == FlashMode::CameraHotShoe {
                    self.flash_triggered(at);
                }
            }
            Stim::Photodiode => self.input(Input::PhotodiodeEdge { at_us: at }),
            Stim::Ready(r) => {
                self.flash_ready = r;
                self.input(Input::FlashReady {
                    at_us: at,
                    ready: r,
                });
            }
        }
    }

    /// Runs the event loop until `t_end` (inclusive) or until nothing is scheduled.
    pub fn run_until(&mut self, t_end: u64) {
        loop {
            let stim = self.pending.iter().map(|p| p.0).min();
            let dl = self.seq.next_deadline();
            let next = match (stim, dl) {
                (Some(a), Some(b)) => a.min(b),
                (Some(a), None) => a,
                (None, Some(b)) => b,
                (None, None) => break,
            };
            if next > t_end {
                break;
            }
            self.now = self.now.max(next);
            if stim == Some(next) {
                let i = self
                    .pending
                    .iter()
                    .position(|p| p.0 == next)
                    .expect("present");
                let (at, s) = self.pending.remove(i);
                self.now = self.now.max(at + self.handling_delay_us);
                self.deliver(at, s);
            } else {
                self.seq.tick(self.now);
                self.after_call();
            }
        }
        self.now = self.now.max(t_end);
        self.seq.tick(self.now);
        self.after_call();
    }

    /// Advances time without events beyond the sequencer's own deadlines.
    pub fn advance(&mut self, dt: u64) {
        let t = self.now + dt;
        self.run_until(t);
    }

    /// Sends a request now and returns its response.
    pub fn request(&mut self, body: RequestBody) -> Result<ResponseBody, DeviceError> {
        let seq = self.next_seq;
        self.next_seq += 1;
        let start = self.msgs.len();
        self.input(Input::Request(Request { seq, body }));
        let responses: Vec<&Response> = self.msgs[start..]
            .iter()
            .filter_map(|m| match m {
                DeviceMessage::Response(r) => Some(r),
                _ => None,
            })
            .collect();
        assert_eq!(responses.len(), 1, "exactly one response per request");
        assert_eq!(responses[0].seq, seq);
        responses[0].result.clone()
    }

    pub fn records(&self) -> Vec<ExposureRecord> {
        self.msgs
            .iter()
            .filter_map(|m| match m {
                DeviceMessage::Event(Event::Record(r)) => Some(r.clone()),
                _ => None,
            })
            .collect()
    }

    pub fn events(&self) -> Vec<Event> {
        self.msgs
            .iter()
            .filter_map(|m| match m {
                DeviceMessage::Event(e) => Some(e.clone()),
                _ => None,
            })
            .collect()
    }

    pub fn faults(&self) -> Vec<FaultKind> {
        self.events()
            .into_iter()
            .filter_map(|e| match e {
                Event::Fault(f) => Some(f.kind),
                _ => None,
            })
            .collect()
    }

    pub fn session_done(&self) -> Option<SessionOutcome> {
        self.events().into_iter().find_map(|e| match e {
            Event::SessionDone { outcome, .. } => Some(outcome),
            _ => None,
        })
    }

    pub fn outputs(&self) -> Outputs {
        self.seq.outputs()
    }

    /// Times a line was asserted.
    pub fn assert_times(&self, line: Line) -> Vec<u64> {
        self.pin_log
            .iter()
            .filter(|(_, a)| a.line == line && a.asserted)
            .map(|(t, _)| *t)
            .collect()
    }

    /// Times a line was released.
    pub fn release_times(&self, line: Line) -> Vec<u64> {
        self.pin_log
            .iter()
            .filter(|(_, a)| a.line == line && !a.asserted)
            .map(|(t, _)| *t)
            .collect()
    }
}

pub fn group(label: &str, role: ImageRole, count: u32, mode: FlashMode) -> ShotGroup {
    ShotGroup {
        label: truncated(label),
        role,
        count,
        min_interval_us: 1_000_000,
        pre_focus_us: 200_000,
        shutter_pulse_us: 100_000,
        xsync_timeout_us: 500_000,
        flash_ready_timeout_us: 4_000_000,
        flash_window_us: ShotGroup::DEFAULT_FLASH_WINDOW_US,
        flash_mode: mode,
    }
}

pub fn plan(groups: Vec<ShotGroup>, max_retries: u32, on_exhausted: ExhaustedAction) -> Plan {
    Plan {
        groups: heapless::Vec::from_iter(groups),
        policy: FaultPolicy {
            max_retries,
            on_exhausted,
        },
        flash_trigger_pulse_us: 1_000,
    }
}
