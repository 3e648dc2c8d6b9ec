//! The simulator on its thread, through a real pseudo-terminal and the in-process link, at
//! 50x real time.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

use skinbrdf_protocol::*;
use skinbrdf_sim::{spawn_in_process, spawn_pty, EndReason, FlashModel, SimConfig};

/// Upper bound on a whole test's wall time, only so a broken simulator cannot hang CI.
const WALL_LIMIT: Duration = Duration::from_secs(60);

struct Client<T: Read + Write> {
    io: T,
    dec: FrameDecoder,
    seq: u32,
    records: Vec<ExposureRecord>,
    events: Vec<Event>,
}

impl<T: Read + Write> Client<T> {
    fn new(io: T) -> Self {
        Self {
            io,
            dec: FrameDecoder::new(),
            seq: 0,
            records: vec![],
            events: vec![],
        }
    }

    fn poll(&mut self) -> Vec<Response> {
        let mut buf = [0u8; 512];
        let mut out = vec![];
        let n = match self.io.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::WouldBlock => 0,
            Err(e) => panic!("read: {e}"),
        };
        let mut data = &buf[..n];
        while let Some((r, rest)) = self.dec.feed::<DeviceMessage>(data) {
            data = rest;
            match r.expect("clean link") {
                DeviceMessage::Response(resp) => out.push(resp),
                DeviceMessage::Event(ev) => {
                    if let Event::Record(rec) = &ev {
                        self.records.push(rec.clone());
                    }
                    self.events.push(ev);
                }
            }
        }
        out
    }

    fn request(&mut self, body: RequestBody) -> Result<ResponseBody, DeviceError> {
        self.seq += 1;
        let seq = self.seq;
        let mut bytes = vec![0u8];
        bytes.extend_from_slice(&encode_to_vec(&Request { seq, body }).expect("encode"));
        self.io.write_all(&bytes).expect("write");
        let t0 = Instant::now();
        while t0.elapsed() < WALL_LIMIT {
            if let Some(r) = self.poll().into_iter().find(|r| r.seq == seq) {
                return r.result;
            }
        }
        panic!("no response");
    }

    fn session(&mut self, shots: u32) {
        let info = match self.request(RequestBody::Hello {
            protocol_version: PROTOCOL_VERSION,
        }) {
            Ok(ResponseBody::Hello(info)) => info,
            other => panic!("{other:?}"),
        };
        assert_eq!(info.kind, DeviceKind::Simulator);
        assert_eq!(
            self.request(RequestBody::Hello {
                protocol_version: 99
            }),
            Err(DeviceError::VersionMismatch {
                device: PROTOCOL_VERSION,
                host: 99
            })
        );
        self.request(RequestBody::Hello {
            protocol_version: PROTOCOL_VERSION,
        })
        .expect("hello");
        let plan = Plan {
            groups: skinbrdf_protocol::heapless::Vec::from_iter([ShotGroup {
                label: truncated("m"),
                role: ImageRole::Measurement,
                count: shots,
                min_interval_us: 100_000,
                pre_focus_us: 50_000,
                shutter_pulse_us: 100_000,
                xsync_timeout_us: 500_000,
                flash_ready_timeout_us: 5_000_000,
                flash_window_us: ShotGroup::DEFAULT_FLASH_WINDOW_US,
                flash_mode: FlashMode::ControllerOnXsync,
            }]),
            policy: FaultPolicy {
                max_retries: 0,
                on_exhausted: ExhaustedAction::AbortSession,
            },
            flash_trigger_pulse_us: 1_000,
        };
        assert_eq!(
            self.request(RequestBody::LoadPlan(plan)),
            Ok(ResponseBody::PlanLoaded { total_shots: shots })
        );
        self.request(RequestBody::Run {
            first_group: 0,
            last_group: 0,
        })
        .expect("run");
        let t0 = Instant::now();
        while !self
            .events
            .iter()
            .any(|e| matches!(e, Event::SessionDone { .. }))
        {
            assert!(t0.elapsed() < WALL_LIMIT, "session did not finish");
            self.poll();
        }
        let n = self.records.len() as u32;
        assert_eq!(
            self.request(RequestBody::AckRecords { next_index: n }),
            Ok(ResponseBody::Acked { unacked: 0 })
        );
        assert!(matches!(
            self.events
                .iter()
                .find(|e| matches!(e, Event::SessionDone { .. })),
            Some(Event::SessionDone {
                outcome: SessionOutcome::Completed,
                ..
            })
        ));
        assert_eq!(n, shots);
        for (i, r) in self.records.iter().enumerate() {
            assert_eq!(r.index, i as u32);
            assert_eq!(r.outcome, ShotOutcome::Ok);
            let lag = r.xsync_us.unwrap() - r.shutter_command_us.unwrap();
            assert!((60_000..=120_000).contains(&lag), "lag {lag}");
        }
    }
}

fn fast_config() -> SimConfig {
    SimConfig {
        time_scale: 50.0,
        flash: FlashModel {
            power: 0.0,
            ..FlashModel::STUDIO_HALF_POWER
        },
        ..SimConfig::default()
    }
}

#[test]
fn session_over_a_pseudo_terminal() {
    let (sim, path) = spawn_pty(fast_config()).expect("pty");
    assert!(path.starts_with("/dev/"), "{path}");
    let port = serialport::new(&path, 115_200)
        .timeout(Duration::from_millis(20))
        .open_native()
        .expect("open the simulator's port like a serial device");
    let mut c = Client::new(port);
    c.session(4);
    let report = sim.stop().expect("stops");
    assert_eq!(report.ended_by, EndReason::Stopped);
    assert_eq!(report.stats.flashes, 4);
}

#[test]
fn session_over_the_in_process_link() {
    let (sim, mut link) = spawn_in_process(fast_config()).expect("spawn");
    link.read_timeout = Duration::from_millis(20);
    let mut c = Client::new(link);
    c.session(3);
    let outputs = sim.with_device(|d| d.outputs()).expect("device");
    assert!(outputs.camera_and_flash_released());
    drop(c); // closes the link: the simulator ends by itself
    let mut sim = sim;
    let report = sim.join().expect("ends");
    assert_eq!(report.ended_by, EndReason::HostClosed);
}
