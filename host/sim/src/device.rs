//! The simulated device: the firmware's sequencer, the camera and flash models, and the byte
//! link with fault injection, on a simulated clock. Deterministic and sans-IO: the caller
//! moves time ([`SimDevice::advance_to`]) and bytes ([`SimDevice::receive`],
//! [`SimDevice::take_output`]).

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinbrdf_protocol::{encode, DeviceKind, DeviceMessage, FrameDecoder, Request, MAX_FRAME_LEN};
use skinbrdf_sequencer::{Config, Input, Line, Outputs, Sequencer};

use crate::{SimConfig, SimError};

/// A scheduled hardware stimulus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Stim {
    Xsync,
    Photodiode,
    FlashReady(bool),
    LinkRestore,
}

/// Counters of what the simulation did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimStats {
    /// Shutter presses the camera received.
    pub shutter_presses: u32,
    /// X-sync edges the camera produced.
    pub xsync_edges: u32,
    /// Flashes fired (light on the photodiode).
    pub flashes: u32,
    /// Flash triggers ignored because the flash was recycling.
    pub triggers_while_recycling: u32,
    /// Misfires injected.
    pub misfires: u32,
    /// Camera failures injected.
    pub camera_failures: u32,
    /// Frames sent to the host.
    pub frames_to_host: u32,
    /// Frames corrupted on the way to the host.
    pub corrupted_to_host: u32,
    /// Frames truncated on the way to the host.
    pub truncated_to_host: u32,
    /// Host chunks corrupted on the way to the device.
    pub corrupted_to_device: u32,
    /// Requests decoded by the device.
    pub requests: u32,
    /// Frames the device could not decode.
    pub bad_frames: u32,
    /// Bytes discarded because the link was down.
    pub bytes_lost_link_down: u64,
    /// Link drops injected.
    pub link_drops: u32,
}

/// The simulated trigger controller with its camera and flash.
#[derive(Debug)]
pub struct SimDevice {
    cfg: SimConfig,
    seq: Sequencer,
    rng: ChaCha8Rng,
    now_us: u64,
    /// (time, tie-breaker, stimulus), earliest first.
    pending: BinaryHeap<Reverse<(u64, u64, Stim)>>,
    next_tiebreak: u64,
    flash_ready: bool,
    decoder: FrameDecoder<MAX_FRAME_LEN>,
    /// Device-to-host bytes not yet taken by the link.
    out: VecDeque<u8>,
    link_up: bool,
    link_dropped_once: bool,
    /// Slow-host budget (bytes), refilled at `host_bytes_per_s`.
    tx_budget: f64,
    tx_budget_at_us: u64,
    stats: SimStats,
}

impl SimDevice {
    /// A device at `cfg.start_us`, flash ready (unless `flash_never_ready`), link up.
    pub fn new(cfg: SimConfig) -> Result<Self, SimError> {
        cfg.validate()?;
        let config = Config::new(
            env!("CARGO_PKG_VERSION"),
            &cfg.serial,
            DeviceKind::Simulator,
        );
        let mut seq = Sequencer::new(config, cfg.start_us);
        let ready = !cfg.faults.flash_never_ready;
        seq.handle(
            cfg.start_us,
            Input::FlashReady {
                at_us: cfg.start_us,
                ready,
            },
        );
        let mut dev = Self {
            rng: ChaCha8Rng::seed_from_u64(cfg.seed),
            now_us: cfg.start_us,
            tx_budget: 0.0,
            tx_budget_at_us: cfg.start_us,
            cfg,
            seq,
            pending: BinaryHeap::new(),
            next_tiebreak: 0,
            flash_ready: ready,
            decoder: FrameDecoder::new(),
            out: VecDeque::new(),
            link_up: true,
            link_dropped_once: false,
            stats: SimStats::default(),
        };
        // The initial FlashReady event is not news to anyone: drop it.
        while dev.seq.pop_message().is_some() {}
        Ok(dev)
    }

    /// Device time.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// The configuration.
    pub fn config(&self) -> &SimConfig {
        &self.cfg
    }

    /// Counters.
    pub fn stats(&self) -> SimStats {
        self.stats
    }

    /// The sequencer (status, outputs, unacked records).
    pub fn sequencer(&self) -> &Sequencer {
        &self.seq
    }

    /// Output line levels.
    pub fn outputs(&self) -> Outputs {
        self.seq.outputs()
    }

    /// Whether the (simulated) link is up.
    pub fn link_up(&self) -> bool {
        self.link_up
    }

    /// The earliest device time something happens on its own (hardware, sequencer deadline,
    /// link restore).
    pub fn next_event_us(&self) -> Option<u64> {
        let stim = self.pending.peek().map(|Reverse((t, _, _))| *t);
        match (stim, self.seq.next_deadline()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Runs everything scheduled up to `t_us` in time order, then sets the clock to `t_us`.
    pub fn advance_to(&mut self, t_us: u64) {
        let t_us = t_us.max(self.now_us);
        while let Some(next) = self.next_event_us() {
            if next > t_us {
                break;
            }
            self.now_us = self.now_us.max(next);
            let stim_due = self
                .pending
                .peek()
                .is_some_and(|Reverse((t, _, _))| *t <= next);
            if stim_due {
                if let Some(Reverse((at, _, stim))) = self.pending.pop() {
                    self.deliver(at, stim);
                }
            } else {
                self.seq.tick(self.now_us);
                self.after_sequencer();
            }
        }
        self.now_us = t_us;
        self.seq.tick(t_us);
        self.after_sequencer();
    }

    /// Host-to-device bytes arriving now.
    pub fn receive(&mut self, bytes: &[u8]) {
        if !self.link_up {
            self.stats.bytes_lost_link_down += bytes.len() as u64;
            return;
        }
        let corrupted =
            if !bytes.is_empty() && self.chance(self.cfg.faults.corrupt_to_device_probability) {
                let mut v = bytes.to_vec();
                let i = self.rng.random_range(0..v.len());
                v[i] ^= self.rng.random_range(1..=255u8);
                self.stats.corrupted_to_device += 1;
                Some(v)
            } else {
                None
            };
        let mut data: &[u8] = corrupted.as_deref().unwrap_or(bytes);
        while let Some((result, rest)) = self.decoder.feed::<Request>(data) {
            data = rest;
            match result {
                Ok(req) => {
                    self.stats.requests += 1;
                    self.seq.handle(self.now_us, Input::Request(req));
                }
                Err(err) => {
                    self.stats.bad_frames += 1;
                    tracing::debug!(%err, "simulated device dropped a bad frame");
                    self.seq.handle(self.now_us, Input::BadFrame(err));
                }
            }
            self.after_sequencer();
        }
    }

    /// Takes up to `max` device-to-host bytes (fewer when a slow host is simulated).
    pub fn take_output(&mut self, max: usize) -> Vec<u8> {
        let mut n = max.min(self.out.len());
        if let Some(rate) = self.cfg.faults.host_bytes_per_s {
            let dt_s = self.now_us.saturating_sub(self.tx_budget_at_us) as f64 * 1e-6;
            self.tx_budget_at_us = self.now_us;
            // Cap the budget at one buffer: an idle link does not bank bandwidth forever.
            self.tx_budget =
                (self.tx_budget + dt_s * rate as f64).min(self.cfg.tx_buffer_bytes as f64);
            n = n.min(self.tx_budget.floor().max(0.0) as usize);
            self.tx_budget -= n as f64;
        }
        let taken: Vec<u8> = self.out.drain(..n).collect();
        // Room freed: pull waiting messages from the sequencer.
        self.pull_messages();
        taken
    }

    /// Bytes waiting for the host.
    pub fn pending_output(&self) -> usize {
        self.out.len()
    }

    /// Simulates a link drop now for `duration_us` (what [`crate::Faults::link_drop`] does
    /// automatically).
    pub fn drop_link(&mut self, duration_us: u64) {
        if !self.link_up {
            return;
        }
        self.link_up = false;
        self.stats.link_drops += 1;
        self.stats.bytes_lost_link_down += self.out.len() as u64;
        self.out.clear();
        self.decoder.reset();
        self.seq.handle(self.now_us, Input::LinkDown);
        self.after_sequencer();
        let t = self.now_us.saturating_add(duration_us);
        self.schedule(t, Stim::LinkRestore);
    }

    // -----------------------------------------------------------------------------------------

    fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.rng.random_bool(p.min(1.0))
    }

    fn schedule(&mut self, at: u64, stim: Stim) {
        self.next_tiebreak += 1;
        self.pending.push(Reverse((at, self.next_tiebreak, stim)));
    }

    fn deliver(&mut self, at: u64, stim: Stim) {
        match stim {
            Stim::Xsync => {
                self.stats.xsync_edges += 1;
                let trigger_before = self.seq.outputs().flash_trigger;
                self.seq.handle(self.now_us, Input::XsyncEdge { at_us: at });
                let controller_fired = !trigger_before && self.seq.outputs().flash_trigger;
                self.after_sequencer();
                if !controller_fired {
                    // Hot shoe: the camera fires the flash itself.
                    self.fire_flash(at);
                }
            }
            Stim::Photodiode => {
                self.seq
                    .handle(self.now_us, Input::PhotodiodeEdge { at_us: at });
                self.after_sequencer();
            }
            Stim::FlashReady(ready) => {
                self.flash_ready = ready;
                self.seq
                    .handle(self.now_us, Input::FlashReady { at_us: at, ready });
                self.after_sequencer();
            }
            Stim::LinkRestore => {
                self.link_up = true;
                self.seq.handle(self.now_us, Input::LinkUp);
                // Flush whatever partial frame the host holds.
                self.out.push_back(0);
                self.after_sequencer();
            }
        }
    }

    /// Reacts to output changes and moves messages into the output buffer.
    fn after_sequencer(&mut self) {
        let actions: Vec<_> = self.seq.take_pin_actions().collect();
        for a in actions {
            match (a.line, a.asserted) {
                (Line::Shutter, true) => self.press_shutter(),
                (Line::FlashTrigger, true) => self.fire_flash(self.now_us),
                _ => {}
            }
        }
        self.pull_messages();
        self.maybe_drop_link();
    }

    fn press_shutter(&mut self) {
        self.stats.shutter_presses += 1;
        if self.cfg.faults.camera_not_firing || self.chance(self.cfg.faults.camera_fail_probability)
        {
            self.stats.camera_failures += 1;
            return;
        }
        let (lo, hi) = (
            self.cfg.camera.shutter_lag_min_us,
            self.cfg.camera.shutter_lag_max_us,
        );
        let lag = if hi > lo {
            self.rng.random_range(lo..=hi)
        } else {
            lo
        };
        let t = self.now_us.saturating_add(lag);
        self.schedule(t, Stim::Xsync);
    }

    fn fire_flash(&mut self, t: u64) {
        if !self.flash_ready {
            self.stats.triggers_while_recycling += 1;
            return;
        }
        if self.chance(self.cfg.faults.misfire_probability) {
            self.stats.misfires += 1;
            return;
        }
        self.stats.flashes += 1;
        let f = self.cfg.flash;
        let light = t.saturating_add(f.trigger_to_light_us);
        // Mark not-ready immediately so a second trigger in the same instant is ignored.
        self.flash_ready = false;
        self.schedule(light, Stim::Photodiode);
        self.schedule(light, Stim::FlashReady(false));
        if !self.cfg.faults.flash_never_ready {
            let nominal = f.nominal_recycle_us() as f64;
            let jitter = if f.recycle_jitter > 0.0 {
                self.rng.random_range(-f.recycle_jitter..=f.recycle_jitter)
            } else {
                0.0
            };
            let recycle = (nominal * (1.0 + jitter)).max(0.0).round() as u64;
            self.schedule(light.saturating_add(recycle), Stim::FlashReady(true));
        }
    }

    fn pull_messages(&mut self) {
        while self.out.len() + MAX_FRAME_LEN <= self.cfg.tx_buffer_bytes {
            let Some(msg) = self.seq.pop_message() else {
                break;
            };
            self.emit(&msg);
        }
    }

    fn emit(&mut self, msg: &DeviceMessage) {
        if !self.link_up {
            return;
        }
        let mut buf = [0u8; MAX_FRAME_LEN];
        let frame = match encode(msg, &mut buf) {
            Ok(f) => f.to_vec(),
            Err(err) => {
                tracing::error!(%err, "simulated device could not encode a message");
                return;
            }
        };
        let mut frame = frame;
        if self.chance(self.cfg.faults.corrupt_to_host_probability) {
            let i = self.rng.random_range(0..frame.len());
            frame[i] ^= self.rng.random_range(1..=255u8);
            self.stats.corrupted_to_host += 1;
        }
        if self.chance(self.cfg.faults.truncate_to_host_probability) {
            let keep = self.rng.random_range(0..frame.len());
            frame.truncate(keep);
            self.stats.truncated_to_host += 1;
        }
        self.stats.frames_to_host += 1;
        self.out.extend(frame);
    }

    fn maybe_drop_link(&mut self) {
        let Some(drop) = self.cfg.faults.link_drop else {
            return;
        };
        if self.link_dropped_once || !self.link_up {
            return;
        }
        if self.seq.status().next_index >= drop.after_records && drop.after_records > 0 {
            self.link_dropped_once = true;
            tracing::info!(at_us = self.now_us, "simulated link drop");
            self.drop_link(drop.duration_us);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Faults, FlashModel};
    use skinbrdf_protocol::{encode_to_vec, RequestBody, PROTOCOL_VERSION};

    fn hello_bytes(seq: u32) -> Vec<u8> {
        let req = Request {
            seq,
            body: RequestBody::Hello {
                protocol_version: PROTOCOL_VERSION,
            },
        };
        encode_to_vec(&req).expect("encode").to_vec()
    }

    #[test]
    fn nominal_recycle_spans_half_to_three_seconds() {
        let f = |power| FlashModel {
            power,
            ..FlashModel::STUDIO_HALF_POWER
        };
        assert_eq!(f(0.0).nominal_recycle_us(), 500_000);
        assert_eq!(f(0.5).nominal_recycle_us(), 1_750_000);
        assert_eq!(f(1.0).nominal_recycle_us(), 3_000_000);
    }

    #[test]
    fn slow_host_budget_limits_output_per_device_second() {
        let cfg = SimConfig {
            faults: Faults {
                host_bytes_per_s: Some(10),
                ..Faults::default()
            },
            ..SimConfig::default()
        };
        let mut dev = SimDevice::new(cfg).expect("config");
        for seq in 0..5 {
            dev.receive(&hello_bytes(seq));
        }
        let queued = dev.pending_output();
        assert!(queued > 100, "five Hello responses queued: {queued}");
        assert!(dev.take_output(usize::MAX).is_empty(), "no budget yet");
        dev.advance_to(dev.now_us() + 2_000_000);
        assert_eq!(dev.take_output(usize::MAX).len(), 20, "10 B/s for 2 s");
        dev.advance_to(dev.now_us() + 1_000_000);
        assert_eq!(
            dev.take_output(3).len(),
            3,
            "the caller's limit applies too"
        );
        assert_eq!(
            dev.take_output(usize::MAX).len(),
            7,
            "the rest of the budget"
        );
    }

    #[test]
    fn a_dropped_link_loses_bytes_both_ways_then_flushes_and_recovers() {
        let mut dev = SimDevice::new(SimConfig::default()).expect("config");
        dev.drop_link(1_000_000);
        assert!(!dev.link_up());
        dev.receive(&hello_bytes(1));
        assert_eq!(dev.stats().requests, 0);
        assert_eq!(dev.pending_output(), 0);
        dev.advance_to(dev.now_us() + 1_000_000);
        assert!(dev.link_up());
        assert_eq!(
            dev.take_output(usize::MAX),
            vec![0],
            "a lone delimiter on link-up"
        );
        dev.receive(&hello_bytes(2));
        assert_eq!(dev.stats().requests, 1);
        let mut decoder = FrameDecoder::<MAX_FRAME_LEN>::new();
        let out = dev.take_output(usize::MAX);
        let (msg, _) = decoder.feed::<DeviceMessage>(&out).expect("a frame");
        assert!(matches!(msg, Ok(DeviceMessage::Response(r)) if r.seq == 2 && r.result.is_ok()));
    }
}
