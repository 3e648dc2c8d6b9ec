//! The capture's refusals and give-ups: an interrupted session's `capture.json` is not
//! overwritten, and a link that fails after every reconnect ends the run with a report.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

use std::time::Duration;

use skinbrdf_capture::protocol::{
    encode_to_vec, DeviceInfo, DeviceKind, DeviceMessage, FrameDecoder, Request, RequestBody,
    Response, ResponseBody, MAX_FRAME_LEN,
};
use skinbrdf_capture::transport::{memory_pair, MemoryTransport, Transport, TransportError};
use skinbrdf_capture::{parse_plan, run_capture, CaptureError, CaptureOptions, Unattended};

const PLAN: &str = r#"
max_retries = 0

[[groups]]
label = "m"
role = "measurement"
count = 2
min_interval_us = 500_000
pre_focus_us = 0
shutter_pulse_us = 50_000
xsync_timeout_us = 500_000
flash_ready_timeout_us = 5_000_000
flash_mode = "controller-on-xsync"
"#;

fn plan() -> skinbrdf_session::capture::CapturePlan {
    parse_plan(PLAN, std::path::Path::new("test.toml")).unwrap()
}

#[test]
fn an_interrupted_sessions_capture_json_is_not_overwritten() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("capture.json");
    // An interrupted session's file, as `skinbrdf capture` leaves it.
    let original = {
        // Any real record will do: write one through the library's own writer.
        let writer = skinbrdf_capture::CaptureWriter::create(dir.path()).unwrap();
        let r = skinbrdf_session::capture::CaptureRecord {
            format_version: skinbrdf_session::capture::CAPTURE_FORMAT_VERSION,
            plan: plan(),
            device: skinbrdf_session::capture::DeviceIdentity {
                kind: "simulator".into(),
                protocol_version: 1,
                firmware_version: "0.1.0".into(),
                serial: "T".into(),
            },
            clock: skinbrdf_session::capture::ClockModel {
                device_ref_us: 0,
                host_ref_us: 0.0,
                drift_ppm: 0.0,
                residual_rms_us: 0.0,
                samples: 0,
            },
            exposures: Vec::new(),
            complete: false,
        };
        writer.write(&r).unwrap();
        std::fs::read(&path).unwrap()
    };
    let options = CaptureOptions {
        out_dir: Some(dir.path().to_path_buf()),
        ..CaptureOptions::default()
    };
    let never = || -> Result<Box<dyn Transport>, TransportError> {
        panic!("the refusal comes before the device is touched")
    };
    let err = run_capture(never, &plan(), &options, &mut Unattended).expect_err("refused");
    assert!(matches!(err, CaptureError::ExistingSession { .. }), "{err}");
    assert!(err.to_string().contains("--overwrite"), "{err}");
    assert_eq!(std::fs::read(&path).unwrap(), original, "file untouched");
}

/// A device that answers the handshake and nothing else: every request after it times out, so
/// every reconnect "succeeds" and fails again at once.
fn hello_only_device(mut port: MemoryTransport) {
    std::thread::spawn(move || {
        let mut dec: FrameDecoder<MAX_FRAME_LEN> = FrameDecoder::new();
        let mut buf = [0u8; 256];
        while let Ok(n) = port.read(&mut buf, Duration::from_millis(20)) {
            let mut input = &buf[..n];
            while let Some((res, rest)) = dec.feed::<Request>(input) {
                input = rest;
                if let Ok(Request {
                    seq,
                    body: RequestBody::Hello { .. },
                }) = res
                {
                    let info = DeviceInfo {
                        protocol_version: 1,
                        firmware_version: skinbrdf_capture::protocol::truncated("0.1.0"),
                        serial: skinbrdf_capture::protocol::truncated("HELLO-ONLY"),
                        kind: DeviceKind::Simulator,
                        clock_us: 1,
                    };
                    let m = DeviceMessage::Response(Response {
                        seq,
                        result: Ok(ResponseBody::Hello(info)),
                    });
                    if port.write_all(&encode_to_vec(&m).unwrap()).is_err() {
                        return;
                    }
                }
            }
        }
    });
}

#[test]
fn a_link_that_fails_after_every_reconnect_ends_with_a_report() {
    let connector = || -> Result<Box<dyn Transport>, TransportError> {
        let (host, dev) = memory_pair();
        hello_only_device(dev);
        Ok(Box::new(host))
    };
    let options = CaptureOptions {
        request_timeout: Duration::from_millis(150),
        resend_interval: Duration::from_millis(50),
        reconnect_pause: Duration::from_millis(1),
        reconnect_window: Duration::from_secs(30),
        ..CaptureOptions::default()
    };
    let err = run_capture(connector, &plan(), &options, &mut Unattended).expect_err("gives up");
    let CaptureError::LinkUnusable {
        reconnects,
        shots_kept,
        timeouts,
        ..
    } = err
    else {
        panic!("expected LinkUnusable, got {err}");
    };
    // The bound on stalled reconnects ended it (the 30 s reconnect window would have ended it
    // as `LinkLost`).
    assert_eq!(reconnects, options.max_stalled_reconnects);
    assert_eq!(shots_kept, 0);
    assert!(timeouts >= u64::from(reconnects), "{timeouts}");
}
