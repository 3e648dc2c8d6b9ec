//! The streaming decoder: resynchronisation after garbage, truncation and oversized frames,
//! arbitrary splits, and no panic on any input.

use proptest::prelude::*;
use skinbrdf_protocol::*;

fn sample_messages() -> Vec<DeviceMessage> {
    let mut out = vec![
        DeviceMessage::Event(Event::Record(ExposureRecord {
            index: 9,
            group: 0,
            shot: 9,
            attempt: 1,
            role: ImageRole::LightPosition,
            started_us: u64::MAX - 5,
            shutter_command_us: None,
            xsync_us: None,
            flash_fired_us: Some(0),
            recycle_us: None,
            outcome: ShotOutcome::FlashNotReady,
        })),
        DeviceMessage::Response(Response {
            seq: u32::MAX,
            result: Ok(ResponseBody::Pong { device_us: 0 }),
        }),
        DeviceMessage::Event(Event::Log {
            at_us: 77,
            level: LogLevel::Warn,
            text: truncated("a log line with a zero byte \0 inside"),
        }),
        DeviceMessage::Event(Event::SessionDone {
            at_us: 1,
            outcome: SessionOutcome::Faulted,
            records: 3,
        }),
    ];
    out.push(DeviceMessage::Response(Response {
        seq: 4,
        result: Err(DeviceError::Busy),
    }));
    out
}

fn arb_message() -> impl Strategy<Value = DeviceMessage> {
    (
        any::<u32>(),
        any::<u64>(),
        any::<u64>(),
        0usize..5,
        proptest::option::of(any::<u64>()),
    )
        .prop_map(|(a, b, c, which, opt)| match which {
            0 => DeviceMessage::Event(Event::Record(ExposureRecord {
                index: a,
                group: a % 8,
                shot: a / 3,
                attempt: a % 4,
                role: ImageRole::ReferenceStandard,
                started_us: b,
                shutter_command_us: opt,
                xsync_us: Some(c),
                flash_fired_us: opt,
                recycle_us: Some(b ^ c),
                outcome: ShotOutcome::MissingFlash,
            })),
            1 => DeviceMessage::Response(Response {
                seq: a,
                result: Ok(ResponseBody::Clock { device_us: b }),
            }),
            2 => DeviceMessage::Event(Event::FlashReady {
                at_us: b,
                ready: a % 2 == 0,
                recycle_us: opt,
            }),
            3 => DeviceMessage::Event(Event::Fault(Fault {
                at_us: c,
                kind: FaultKind::HostSilent,
                index: Some(a),
            })),
            _ => DeviceMessage::Response(Response {
                seq: a,
                result: Err(DeviceError::AckBeyondEnd { next_index: a }),
            }),
        })
}

fn decode_all(
    dec: &mut FrameDecoder,
    mut data: &[u8],
    ok: &mut Vec<DeviceMessage>,
    errs: &mut Vec<FrameError>,
) {
    while let Some((r, rest)) = dec.feed::<DeviceMessage>(data) {
        match r {
            Ok(m) => ok.push(m),
            Err(e) => errs.push(e),
        }
        data = rest;
    }
}

#[test]
fn largest_messages_fit_max_frame_len() {
    let group = ShotGroup {
        label: truncated(&"\u{10FFFF}".repeat(LABEL_LEN)),
        role: ImageRole::StandardPosition,
        count: u32::MAX,
        min_interval_us: u64::MAX,
        pre_focus_us: u64::MAX,
        shutter_pulse_us: u64::MAX,
        xsync_timeout_us: u64::MAX,
        flash_ready_timeout_us: u64::MAX,
        flash_window_us: u64::MAX,
        flash_mode: FlashMode::ControllerOnXsync,
    };
    assert_eq!(group.label.len(), LABEL_LEN);
    let mut groups = heapless::Vec::new();
    for _ in 0..MAX_GROUPS {
        groups.push(group.clone()).expect("cap");
    }
    let plan = Request {
        seq: u32::MAX,
        body: RequestBody::LoadPlan(Plan {
            groups,
            policy: FaultPolicy {
                max_retries: u32::MAX,
                on_exhausted: ExhaustedAction::SkipShot,
            },
            flash_trigger_pulse_us: u64::MAX,
        }),
    };
    let frame = encode_to_vec(&plan).expect("largest plan fits");
    assert!(frame.len() <= MAX_FRAME_LEN);
    println!("largest LoadPlan frame: {} bytes", frame.len());

    let log = DeviceMessage::Event(Event::Log {
        at_us: u64::MAX,
        level: LogLevel::Error,
        text: truncated(&"x".repeat(LOG_LINE_LEN + 10)),
    });
    assert!(encode_to_vec(&log).expect("log fits").len() <= MAX_FRAME_LEN);
    let status = DeviceMessage::Response(Response {
        seq: u32::MAX,
        result: Ok(ResponseBody::Status(Status {
            now_us: u64::MAX,
            state: SessionState::Aborted,
            next_index: u32::MAX,
            unacked: u32::MAX,
            oldest_unacked: Some(u32::MAX),
            flash_ready: true,
            bad_frames: u32::MAX,
            dropped_messages: u32::MAX,
            watchdog_us: u64::MAX,
        })),
    });
    assert!(encode_to_vec(&status).expect("status fits").len() <= 64);
}

#[test]
fn oversized_frame_is_reported_and_next_frame_decodes() {
    let mut dec = FrameDecoder::<32>::new();
    let mut data = vec![0x55u8; 100];
    data.push(0);
    let good = encode_to_vec(&sample_messages()[1]).expect("enc");
    data.extend_from_slice(&good);
    let (mut ok, mut errs) = (vec![], vec![]);
    let mut input: &[u8] = &data;
    while let Some((r, rest)) = dec.feed::<DeviceMessage>(input) {
        match r {
            Ok(m) => ok.push(m),
            Err(e) => errs.push(e),
        }
        input = rest;
    }
    assert_eq!(errs, vec![FrameError::Oversized { discarded: 100 }]);
    assert_eq!(ok, vec![sample_messages()[1].clone()]);
    assert_eq!(dec.stats().discarded_bytes, 100);
}

#[test]
fn corrupted_byte_is_a_crc_error_not_a_wrong_message() {
    let msg = &sample_messages()[0];
    let frame = encode_to_vec(msg).expect("enc");
    for i in 0..frame.len() - 1 {
        for flip in [0x01u8, 0x80, 0xff] {
            let mut bad = frame.clone();
            bad[i] ^= flip;
            let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
            let (mut ok, mut errs) = (vec![], vec![]);
            decode_all(&mut dec, &bad, &mut ok, &mut errs);
            // A flipped byte may become 0x00 and split the frame, but no part of a corrupted
            // frame ever decodes as a message.
            assert!(ok.is_empty(), "byte {i} flip {flip:#x} decoded as {ok:?}");
            assert!(
                !errs.is_empty(),
                "byte {i} flip {flip:#x}: no error reported"
            );
        }
    }
}

#[test]
fn truncated_frame_then_good_frame() {
    let a = encode_to_vec(&sample_messages()[0]).expect("enc");
    let b = encode_to_vec(&sample_messages()[3]).expect("enc");
    // First half of `a`, its delimiter lost with the rest; then a leading 0x00 flush and `b`.
    let mut data = a[..a.len() / 2].to_vec();
    data.push(0);
    data.extend_from_slice(&b);
    let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
    let (mut ok, mut errs) = (vec![], vec![]);
    decode_all(&mut dec, &data, &mut ok, &mut errs);
    assert_eq!(errs.len(), 1);
    assert_eq!(ok, vec![sample_messages()[3].clone()]);
}

#[test]
fn unknown_variant_with_good_crc_is_a_decode_error() {
    // Request variant 200 does not exist; the CRC is valid.
    let payload = [0x01u8, 0xc8, 0x01];
    let mut raw = payload.to_vec();
    raw.extend_from_slice(&CRC32.checksum(&payload).to_le_bytes());
    let mut enc = vec![0u8; 32];
    let n = cobs::encode(&raw, &mut enc);
    enc.truncate(n);
    enc.push(0);
    let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
    let (r, _) = dec.feed::<Request>(&enc).expect("frame");
    assert_eq!(r, Err(FrameError::Decode));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn random_bytes_never_panic(data in proptest::collection::vec(any::<u8>(), 0..3000)) {
        let mut dec = FrameDecoder::<64>::new();
        let (mut ok, mut errs) = (vec![], vec![]);
        decode_all_small(&mut dec, &data, &mut ok, &mut errs);
        // Anything accepted is canonical: it re-encodes and decodes to itself.
        for m in &ok {
            let again = encode_to_vec(m).expect("re-encodes");
            let mut d = FrameDecoder::<MAX_FRAME_LEN>::new();
            let (back, _) = d.feed::<DeviceMessage>(&again).expect("one frame");
            prop_assert_eq!(&back.expect("decodes"), m);
        }
        let mut dec2 = FrameDecoder::<MAX_FRAME_LEN>::new();
        let mut input: &[u8] = &data;
        while let Some((_r, rest)) = dec2.feed::<Request>(input) { input = rest; }
        prop_assert!(dec.pending_len() <= 64);
    }

    #[test]
    fn random_splits_deliver_every_message_in_order(
        msgs in proptest::collection::vec(arb_message(), 1..20),
        cuts in proptest::collection::vec(0usize..2000, 0..30),
    ) {
        let mut stream = Vec::new();
        for m in &msgs {
            stream.extend_from_slice(&encode_to_vec(m).expect("enc"));
        }
        let mut cuts: Vec<usize> = cuts.into_iter().map(|c| c % (stream.len() + 1)).collect();
        cuts.sort_unstable();
        let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
        let (mut ok, mut errs) = (vec![], vec![]);
        let mut start = 0;
        for c in cuts.into_iter().chain(std::iter::once(stream.len())) {
            decode_all(&mut dec, &stream[start..c], &mut ok, &mut errs);
            start = c;
        }
        prop_assert!(errs.is_empty());
        prop_assert_eq!(ok, msgs);
    }

    #[test]
    fn interleaved_garbage_loses_only_the_frames_it_touches(
        msgs in proptest::collection::vec(arb_message(), 1..12),
        garbage in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 12),
        hit in proptest::collection::vec(any::<bool>(), 12),
    ) {
        // Between frames: optionally garbage terminated by a 0x00 flush (what a sender does
        // after a reconnect). Every frame not preceded by garbage must arrive intact; no
        // message arrives that was not sent.
        let mut stream = Vec::new();
        let mut expect_intact = Vec::new();
        for (i, m) in msgs.iter().enumerate() {
            if hit[i] {
                stream.extend_from_slice(&garbage[i]);
                stream.push(0);
            }
            stream.extend_from_slice(&encode_to_vec(m).expect("enc"));
            expect_intact.push(m.clone());
        }
        let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
        let (mut ok, mut errs) = (vec![], vec![]);
        decode_all(&mut dec, &stream, &mut ok, &mut errs);
        prop_assert_eq!(ok, expect_intact);
    }

    #[test]
    fn garbage_without_flush_costs_at_most_one_frame(
        msgs in proptest::collection::vec(arb_message(), 2..8),
        garbage in proptest::collection::vec(1u8..=255, 1..40),
        at in 0usize..8,
    ) {
        let at = at % msgs.len();
        let mut stream = Vec::new();
        for (i, m) in msgs.iter().enumerate() {
            if i == at {
                stream.extend_from_slice(&garbage);
            }
            stream.extend_from_slice(&encode_to_vec(m).expect("enc"));
        }
        let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
        let (mut ok, mut errs) = (vec![], vec![]);
        decode_all(&mut dec, &stream, &mut ok, &mut errs);
        let mut expected = msgs.clone();
        expected.remove(at);
        // The frame the garbage was glued to is lost (reported), every other one arrives.
        prop_assert_eq!(errs.len(), 1);
        prop_assert_eq!(ok, expected);
    }
}

fn decode_all_small(
    dec: &mut FrameDecoder<64>,
    mut data: &[u8],
    ok: &mut Vec<DeviceMessage>,
    errs: &mut Vec<FrameError>,
) {
    while let Some((r, rest)) = dec.feed::<DeviceMessage>(data) {
        match r {
            Ok(m) => ok.push(m),
            Err(e) => errs.push(e),
        }
        data = rest;
    }
}
