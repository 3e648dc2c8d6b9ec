//! Golden byte vectors: they pin the wire format. The expected bytes were computed
//! independently of this crate (postcard layout by hand, `zlib.crc32`, a reference COBS
//! encoder) and are reproduced in `docs/protocol.md`. If one of these fails, the wire format
//! changed: bump `PROTOCOL_VERSION` and update the document.

use skinbrdf_protocol::*;

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).expect("hex byte"))
        .collect()
}

fn check<T>(msg: &T, payload: &str, frame: &str)
where
    T: serde::Serialize + serde::de::DeserializeOwned + PartialEq + std::fmt::Debug,
{
    let payload = hex(payload);
    let frame = hex(frame);
    // postcard layout
    let mut buf = [0u8; MAX_FRAME_LEN];
    let raw = postcard::to_slice(msg, &mut buf).expect("ser");
    assert_eq!(&raw[..], payload.as_slice(), "postcard payload of {msg:?}");
    // full frame
    let encoded = encode_to_vec(msg).expect("encode");
    assert_eq!(encoded.as_slice(), frame.as_slice(), "frame of {msg:?}");
    // and back, through the streaming decoder
    let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
    let (got, rest) = dec.feed::<T>(&frame).expect("one frame");
    assert!(rest.is_empty());
    assert_eq!(&got.expect("decode"), msg);
}

#[test]
fn ping_request() {
    check(
        &Request {
            seq: 1,
            body: RequestBody::Ping,
        },
        "01 07",
        "07 01 07 1d b6 a6 c6 00",
    );
}

#[test]
fn hello_request() {
    check(
        &Request {
            seq: 0,
            body: RequestBody::Hello {
                protocol_version: 1,
            },
        },
        "00 00 01",
        "01 01 06 01 84 e9 46 88 00",
    );
}

#[test]
fn read_clock_request_with_two_byte_varint_seq() {
    check(
        &Request {
            seq: 300,
            body: RequestBody::ReadClock,
        },
        "ac 02 01",
        "08 ac 02 01 02 2f 12 6a 00",
    );
}

#[test]
fn hello_response() {
    let msg = DeviceMessage::Response(Response {
        seq: 0,
        result: Ok(ResponseBody::Hello(DeviceInfo {
            protocol_version: 1,
            firmware_version: truncated("0.1.0"),
            serial: truncated("SIM-0001"),
            kind: DeviceKind::Simulator,
            clock_us: 1234,
        })),
    });
    check(
        &msg,
        "00 00 00 00 01 05 30 2e 31 2e 30 08 53 49 4d 2d 30 30 30 31 01 d2 09",
        "01 01 01 01 18 01 05 30 2e 31 2e 30 08 53 49 4d 2d 30 30 30 31 01 d2 09 31 db c3 7d 00",
    );
}

#[test]
fn version_mismatch_response() {
    let msg = DeviceMessage::Response(Response {
        seq: 0,
        result: Err(DeviceError::VersionMismatch { device: 1, host: 2 }),
    });
    check(
        &msg,
        "00 00 01 00 01 02",
        "01 01 02 01 07 01 02 ab 96 6b fe 00",
    );
}

#[test]
fn exposure_record_event_beyond_u32_clock() {
    let msg = DeviceMessage::Event(Event::Record(ExposureRecord {
        index: 5,
        group: 1,
        shot: 2,
        attempt: 0,
        role: ImageRole::Measurement,
        started_us: 5_000_000_000,
        shutter_command_us: Some(5_000_100_000),
        xsync_us: Some(5_000_180_000),
        flash_fired_us: Some(5_000_180_050),
        recycle_us: Some(1_500_000),
        outcome: ShotOutcome::Ok,
    }));
    check(
        &msg,
        "01 00 05 01 02 00 00 80 e4 97 d0 12 01 a0 f1 9d d0 12 01 a0 e2 a2 d0 12 01 d2 e2 a2 d0 12 01 e0 c6 5b 00",
        "02 01 04 05 01 02 01 1c 80 e4 97 d0 12 01 a0 f1 9d d0 12 01 a0 e2 a2 d0 12 01 d2 e2 a2 d0 12 01 e0 c6 5b 05 72 55 ff 15 00",
    );
}

#[test]
fn flash_ready_event() {
    let msg = DeviceMessage::Event(Event::FlashReady {
        at_us: (1u64 << 32) + 7,
        ready: true,
        recycle_us: Some(1_500_000),
    });
    check(
        &msg,
        "01 01 87 80 80 80 10 01 01 e0 c6 5b",
        "11 01 01 87 80 80 80 10 01 01 e0 c6 5b 85 4c ae d6 00",
    );
}

#[test]
fn load_plan_request() {
    let mut groups = heapless::Vec::new();
    groups
        .push(ShotGroup {
            label: truncated("m"),
            role: ImageRole::Measurement,
            count: 30,
            min_interval_us: 2_000_000,
            pre_focus_us: 300_000,
            shutter_pulse_us: 100_000,
            xsync_timeout_us: 500_000,
            flash_ready_timeout_us: 5_000_000,
            flash_window_us: 20_000,
            flash_mode: FlashMode::ControllerOnXsync,
        })
        .expect("capacity");
    let msg = Request {
        seq: 2,
        body: RequestBody::LoadPlan(Plan {
            groups,
            policy: FaultPolicy {
                max_retries: 2,
                on_exhausted: ExhaustedAction::SkipShot,
            },
            flash_trigger_pulse_us: 1000,
        }),
    };
    check(
        &msg,
        "02 02 01 01 6d 00 1e 80 89 7a e0 a7 12 a0 8d 06 a0 c2 1e c0 96 b1 02 a0 9c 01 01 02 01 e8 07",
        "06 02 02 01 01 6d 1e 1e 80 89 7a e0 a7 12 a0 8d 06 a0 c2 1e c0 96 b1 02 a0 9c 01 01 02 01 e8 07 7f 9b dc ff 00",
    );
}

#[test]
fn crc_is_crc32_iso_hdlc() {
    assert_eq!(CRC32.checksum(b"123456789"), 0xCBF4_3926);
}
