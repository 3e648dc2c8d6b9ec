//! A minimal, robust host for driving a [`SimDevice`] step by step: requests with retries,
//! records collected by index, recovery by `FetchRecords`.

#![allow(dead_code)]

use std::collections::BTreeMap;

use skinbrdf_protocol::*;
use skinbrdf_sim::SimDevice;

/// Step of the host's polling loop (device time).
pub const STEP_US: u64 = 1_000;
/// Host-side response timeout before a retry (device time).
pub const RESPONSE_TIMEOUT_US: u64 = 200_000;

pub struct StepHost {
    pub dev: SimDevice,
    dec: FrameDecoder,
    next_seq: u32,
    pub records: BTreeMap<u32, ExposureRecord>,
    pub duplicate_records: u32,
    pub events: Vec<Event>,
    pub frame_errors: u32,
    pending_responses: Vec<Response>,
    /// Device time to wait for a response before retrying.
    pub response_timeout_us: u64,
}

impl StepHost {
    pub fn new(dev: SimDevice) -> Self {
        Self {
            dev,
            dec: FrameDecoder::new(),
            next_seq: 1,
            records: BTreeMap::new(),
            duplicate_records: 0,
            events: Vec::new(),
            frame_errors: 0,
            pending_responses: Vec::new(),
            response_timeout_us: RESPONSE_TIMEOUT_US,
        }
    }

    /// Advances device time by `dt_us` in steps, reading everything the device sends.
    pub fn pump(&mut self, dt_us: u64) {
        let end = self.dev.now_us() + dt_us;
        while self.dev.now_us() < end {
            let t = (self.dev.now_us() + STEP_US).min(end);
            self.dev.advance_to(t);
            self.read_all();
        }
    }

    fn read_all(&mut self) {
        let bytes = self.dev.take_output(usize::MAX);
        let mut data: &[u8] = &bytes;
        while let Some((r, rest)) = self.dec.feed::<DeviceMessage>(data) {
            data = rest;
            match r {
                Ok(DeviceMessage::Response(resp)) => self.pending_responses.push(resp),
                Ok(DeviceMessage::Event(ev)) => {
                    if let Event::Record(rec) = &ev {
                        if self.records.insert(rec.index, rec.clone()).is_some() {
                            self.duplicate_records += 1;
                        }
                    }
                    self.events.push(ev);
                }
                Err(_) => self.frame_errors += 1,
            }
        }
    }

    /// Sends a request and waits for its response, retrying on timeout with the same `seq`
    /// (the device answers a retry without executing it twice), at most `tries` times.
    pub fn try_request(
        &mut self,
        body: RequestBody,
        tries: u32,
    ) -> Option<Result<ResponseBody, DeviceError>> {
        let seq = self.next_seq;
        self.next_seq += 1;
        let frame = encode_to_vec(&Request { seq, body }).expect("encode");
        // Leading 0x00: flush any partial frame at the device.
        let mut bytes = vec![0u8];
        bytes.extend_from_slice(&frame);
        for _ in 0..tries {
            self.dev.receive(&bytes);
            let deadline = self.dev.now_us() + self.response_timeout_us;
            while self.dev.now_us() < deadline {
                self.read_all();
                if let Some(i) = self.pending_responses.iter().position(|r| r.seq == seq) {
                    let r = self.pending_responses.remove(i);
                    self.pending_responses.retain(|r| r.seq != seq);
                    return Some(r.result);
                }
                self.pump(STEP_US);
            }
        }
        None
    }

    pub fn request(&mut self, body: RequestBody) -> Result<ResponseBody, DeviceError> {
        self.try_request(body.clone(), 20)
            .unwrap_or_else(|| panic!("no response to {body:?}"))
    }

    pub fn hello(&mut self) -> DeviceInfo {
        match self.request(RequestBody::Hello {
            protocol_version: PROTOCOL_VERSION,
        }) {
            Ok(ResponseBody::Hello(info)) => info,
            other => panic!("handshake failed: {other:?}"),
        }
    }

    /// Contiguous prefix of indices the host holds.
    pub fn contiguous(&self) -> u32 {
        let mut n = 0;
        while self.records.contains_key(&n) {
            n += 1;
        }
        n
    }

    pub fn status(&mut self) -> Status {
        match self.request(RequestBody::GetStatus) {
            Ok(ResponseBody::Status(s)) => s,
            Err(DeviceError::HandshakeRequired) => {
                self.hello();
                self.status()
            }
            other => panic!("status: {other:?}"),
        }
    }

    /// Runs groups until the device leaves `Running`, pinging, acking and fetching missing
    /// records like a careful host. Returns the final state.
    pub fn run_to_end(&mut self, max_device_time_us: u64) -> SessionState {
        let end = self.dev.now_us() + max_device_time_us;
        loop {
            self.pump(500_000);
            let st = self.status();
            self.sync_records(&st);
            if st.state != SessionState::Running || self.dev.now_us() > end {
                return st.state;
            }
        }
    }

    /// Fetches whatever the host is missing and acknowledges what it holds.
    pub fn sync_records(&mut self, st: &Status) {
        if self.contiguous() < st.next_index {
            let from = self.contiguous();
            if let Some(Ok(ResponseBody::Fetching { .. })) =
                self.try_request(RequestBody::FetchRecords { from_index: from }, 5)
            {
                self.pump(200_000);
            }
        }
        let have = self.contiguous();
        if have > 0 {
            let _ = self.try_request(RequestBody::AckRecords { next_index: have }, 5);
        }
    }
}

pub fn group(label: &str, role: ImageRole, count: u32, mode: FlashMode) -> ShotGroup {
    ShotGroup {
        label: truncated(label),
        role,
        count,
        min_interval_us: 500_000,
        pre_focus_us: 200_000,
        shutter_pulse_us: 100_000,
        xsync_timeout_us: 500_000,
        flash_ready_timeout_us: 5_000_000,
        flash_window_us: ShotGroup::DEFAULT_FLASH_WINDOW_US,
        flash_mode: mode,
    }
}

/// The method's session: 30 measurement, 3 light-position, 1 reference-standard, 2
/// standard-position shots.
pub fn method_plan(mode: FlashMode, max_retries: u32) -> Plan {
    Plan {
        groups: skinbrdf_protocol::heapless::Vec::from_iter([
            group("measurement", ImageRole::Measurement, 30, mode),
            group("light-position", ImageRole::LightPosition, 3, mode),
            group("reference-standard", ImageRole::ReferenceStandard, 1, mode),
            group("standard-position", ImageRole::StandardPosition, 2, mode),
        ]),
        policy: FaultPolicy {
            max_retries,
            on_exhausted: ExhaustedAction::AbortSession,
        },
        flash_trigger_pulse_us: 1_000,
    }
}

pub fn small_plan(
    count: u32,
    mode: FlashMode,
    max_retries: u32,
    on_exhausted: ExhaustedAction,
) -> Plan {
    Plan {
        groups: skinbrdf_protocol::heapless::Vec::from_iter([group(
            "m",
            ImageRole::Measurement,
            count,
            mode,
        )]),
        policy: FaultPolicy {
            max_retries,
            on_exhausted,
        },
        flash_trigger_pulse_us: 1_000,
    }
}
