//! Property tests: random hardware behaviour, random host traffic and random timing never
//! leave a camera or flash line held outside a running session, and abort / watchdog always
//! end in the safe state.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

mod world;

use proptest::prelude::*;
use skinbrdf_protocol::*;
use skinbrdf_sequencer::{Input, Line, Outputs, MIN_SHUTTER_OFF_US};
use world::{Hardware, World};

#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
enum Op {
    Advance(u64),
    Xsync,
    Photodiode,
    Ready(bool),
    Req(RequestBody),
    LinkDown,
    LinkUp,
    BadFrame,
    CameraFires(bool),
    FlashFires(bool),
}

fn arb_group() -> impl Strategy<Value = ShotGroup> {
    (
        1u32..4,
        0u64..300_000,
        1u64..400_000,
        1u64..600_000,
        0u64..3_000_000,
        1u64..30_000,
        0u64..2_000_000,
        any::<bool>(),
    )
        .prop_map(
            |(count, pre, pulse, xs, ready_to, window, interval, ctrl)| ShotGroup {
                label: truncated("g"),
                role: ImageRole::Measurement,
                count,
                min_interval_us: interval,
                pre_focus_us: pre,
                shutter_pulse_us: pulse,
                xsync_timeout_us: xs,
                flash_ready_timeout_us: ready_to,
                flash_window_us: window,
                flash_mode: if ctrl {
                    FlashMode::ControllerOnXsync
                } else {
                    FlashMode::CameraHotShoe
                },
            },
        )
}

fn arb_plan() -> impl Strategy<Value = Plan> {
    (
        proptest::collection::vec(arb_group(), 1..4),
        0u32..3,
        any::<bool>(),
        1u64..5_000,
    )
        .prop_map(|(groups, retries, skip, pulse)| Plan {
            groups: heapless::Vec::from_iter(groups),
            policy: FaultPolicy {
                max_retries: retries,
                on_exhausted: if skip {
                    ExhaustedAction::SkipShot
                } else {
                    ExhaustedAction::AbortSession
                },
            },
            flash_trigger_pulse_us: pulse,
        })
}

fn arb_request() -> impl Strategy<Value = RequestBody> {
    prop_oneof![
        Just(RequestBody::Hello {
            protocol_version: PROTOCOL_VERSION
        }),
        Just(RequestBody::Ping),
        Just(RequestBody::Abort),
        Just(RequestBody::GetStatus),
        Just(RequestBody::ReadClock),
        (0u32..20).prop_map(|n| RequestBody::AckRecords { next_index: n }),
        (0u32..20).prop_map(|n| RequestBody::FetchRecords { from_index: n }),
        (0u32..3, 0u32..3).prop_map(|(a, b)| RequestBody::Run {
            first_group: a,
            last_group: b
        }),
        arb_plan().prop_map(RequestBody::LoadPlan),
        (0u64..5_000_000).prop_map(|t| RequestBody::SetWatchdog { timeout_us: t }),
    ]
}

fn arb_op() -> impl Strategy<Value = Op> {
    prop_oneof![
        6 => (0u64..3_000_000).prop_map(Op::Advance),
        1 => Just(Op::Xsync),
        1 => Just(Op::Photodiode),
        1 => any::<bool>().prop_map(Op::Ready),
        6 => arb_request().prop_map(Op::Req),
        1 => Just(Op::LinkDown),
        1 => Just(Op::LinkUp),
        1 => Just(Op::BadFrame),
        1 => any::<bool>().prop_map(Op::CameraFires),
        1 => any::<bool>().prop_map(Op::FlashFires),
    ]
}

fn check_invariants(w: &World<8>) -> Result<(), TestCaseError> {
    let o = w.outputs();
    if w.seq.state() != SessionState::Running {
        prop_assert!(
            o.camera_and_flash_released(),
            "line held outside a run: {o:?} state {:?}",
            w.seq.state()
        );
        prop_assert!(!o.status_led);
    }
    if o.shutter {
        prop_assert!(o.focus, "shutter without focus");
    }
    prop_assert!(w.seq.status().unacked <= 8);
    if let Some(d) = w.seq.next_deadline() {
        // Every deadline up to now has fired.
        prop_assert!(d > w.now, "deadline {d} left in the past (now {})", w.now);
    }
    Ok(())
}

/// The shutter (and focus) output is released for at least [`MIN_SHUTTER_OFF_US`] between any
/// two presses, as the pins saw it: the log holds the level changes after each driver call,
/// so a release and a press issued by the same call would leave no release in it at all.
fn check_off_times<const R: usize>(w: &World<R>) -> Result<(), TestCaseError> {
    for line in [Line::Shutter, Line::Focus] {
        let mut released_at: Option<u64> = None;
        let mut asserted = false;
        for &(t, a) in w.pin_log.iter().filter(|(_, a)| a.line == line) {
            if a.asserted {
                prop_assert!(!asserted, "{line:?} asserted twice without a release");
                if let Some(r) = released_at {
                    prop_assert!(
                        t - r >= MIN_SHUTTER_OFF_US,
                        "{line:?} released at {r} and pressed again at {t}: off {} us",
                        t - r
                    );
                }
            } else {
                released_at = Some(t);
            }
            asserted = a.asserted;
        }
    }
    Ok(())
}

fn send(w: &mut World<8>, body: RequestBody) {
    let seq = w.next_seq;
    w.next_seq += 1;
    let link = w.seq.link_up();
    let start = w.msgs.len();
    w.input(Input::Request(Request { seq, body }));
    let n = w.msgs[start..]
        .iter()
        .filter(|m| matches!(m, DeviceMessage::Response(r) if r.seq == seq))
        .count();
    // Exactly one response per request while the link is up (Hello brings the link up).
    if link {
        assert_eq!(n, 1);
    }
}

fn run_ops(w: &mut World<8>, ops: &[Op]) -> Result<(), TestCaseError> {
    for op in ops {
        match op.clone() {
            Op::Advance(dt) => w.advance(dt),
            Op::Xsync => w.input(Input::XsyncEdge { at_us: w.now }),
            Op::Photodiode => w.input(Input::PhotodiodeEdge { at_us: w.now }),
            Op::Ready(r) => {
                w.flash_ready = r;
                w.input(Input::FlashReady {
                    at_us: w.now,
                    ready: r,
                });
            }
            Op::Req(b) => send(w, b),
            Op::LinkDown => w.input(Input::LinkDown),
            Op::LinkUp => w.input(Input::LinkUp),
            Op::BadFrame => w.input(Input::BadFrame(FrameError::Cobs)),
            Op::CameraFires(b) => w.hw.camera_fires = b,
            Op::FlashFires(b) => w.hw.flash_fires = b,
        }
        check_invariants(w)?;
    }
    check_off_times(w)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn abort_always_ends_in_the_safe_state(
        start in prop_oneof![Just(0u64), Just((1u64 << 32) - 1_000_000)],
        plan in arb_plan(),
        ops in proptest::collection::vec(arb_op(), 0..60),
    ) {
        let mut w: World<8> = World::connected(start, Hardware::default());
        send(&mut w, RequestBody::LoadPlan(plan));
        send(&mut w, RequestBody::Run { first_group: 0, last_group: 0 });
        run_ops(&mut w, &ops)?;
        // Whatever happened: the host reconnects and aborts.
        w.input(Input::LinkUp);
        send(&mut w, RequestBody::Hello { protocol_version: PROTOCOL_VERSION });
        send(&mut w, RequestBody::Abort);
        prop_assert_eq!(w.outputs(), Outputs::SAFE);
        prop_assert_ne!(w.seq.state(), SessionState::Running);
        prop_assert_eq!(w.seq.next_deadline(), None);
        // And stays safe whatever the hardware does afterwards.
        w.input(Input::XsyncEdge { at_us: w.now });
        w.input(Input::PhotodiodeEdge { at_us: w.now });
        w.advance(10_000_000);
        prop_assert_eq!(w.outputs(), Outputs::SAFE);
    }

    #[test]
    fn host_silence_always_ends_in_the_safe_state(
        plan in arb_plan(),
        ops in proptest::collection::vec(arb_op(), 0..40),
        watchdog in 1u64..5_000_000,
    ) {
        let mut w: World<8> = World::connected(0, Hardware::default());
        send(&mut w, RequestBody::LoadPlan(plan));
        let ops: Vec<Op> = ops
            .into_iter()
            .filter(|o| !matches!(o, Op::Req(RequestBody::SetWatchdog { .. })))
            .collect();
        send(&mut w, RequestBody::SetWatchdog { timeout_us: watchdog });
        send(&mut w, RequestBody::Run { first_group: 0, last_group: 0 });
        run_ops(&mut w, &ops)?;
        // The host goes silent (link down); the hardware keeps doing whatever it does.
        w.input(Input::LinkDown);
        w.advance(watchdog + 1);
        prop_assert_eq!(w.outputs(), Outputs::SAFE);
        prop_assert_ne!(w.seq.state(), SessionState::Running);
    }

    #[test]
    fn every_attempt_is_recorded_once_with_contiguous_indices(
        plan in arb_plan(),
        camera in any::<bool>(),
        flash in any::<bool>(),
        ready_at_start in any::<bool>(),
    ) {
        let hw = Hardware { camera_fires: camera, flash_fires: flash, ..Hardware::default() };
        let mut w: World<8> = World::connected(0, hw);
        if !ready_at_start {
            w.flash_ready = false;
            w.input(Input::FlashReady { at_us: 0, ready: false });
        }
        send(&mut w, RequestBody::SetWatchdog { timeout_us: 0 });
        let groups = plan.groups.len() as u32;
        send(&mut w, RequestBody::LoadPlan(plan));
        send(&mut w, RequestBody::Run { first_group: 0, last_group: groups - 1 });
        for _ in 0..200 {
            w.advance(5_000_000);
            let n = w.records().len() as u32;
            send(&mut w, RequestBody::AckRecords { next_index: n });
            if w.seq.state() != SessionState::Running {
                break;
            }
        }
        prop_assert_ne!(w.seq.state(), SessionState::Running);
        let recs = w.records();
        for (i, r) in recs.iter().enumerate() {
            prop_assert_eq!(r.index, i as u32);
        }
        prop_assert_eq!(w.seq.status().next_index, recs.len() as u32);
        prop_assert_eq!(w.outputs(), Outputs::SAFE);
        check_off_times(&w)?;
        if w.seq.state() == SessionState::Completed {
            let ok_or_skipped = recs.iter().filter(|r| r.attempt == 0).count() as u64;
            prop_assert!(ok_or_skipped >= 1);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Plans of any interval (most shorter than their pulses, across group boundaries too),
    /// with or without pre-focus, against a camera and a flash fast enough that nothing else
    /// holds the next shot back: every press still comes after a full off time, and every shot
    /// is a clean exposure.
    #[test]
    fn the_shutter_is_released_for_the_minimum_off_time_between_presses(
        plan in arb_plan(),
        lag in 0u64..60_000,
        recycle in 0u64..50_000,
        handling_delay in 0u64..3_000,
        no_pre_focus in any::<bool>(),
    ) {
        let mut plan = plan;
        for g in plan.groups.iter_mut() {
            if no_pre_focus {
                g.pre_focus_us = 0;
            }
            // Room for the camera's lag and the flash: each shot can succeed.
            g.xsync_timeout_us = g.xsync_timeout_us.max(lag + 1);
            g.flash_window_us = g.flash_window_us.max(1_000);
            g.flash_ready_timeout_us = g.flash_ready_timeout_us.max(1_000_000);
        }
        let hw = Hardware {
            shutter_lag_us: lag,
            recycle_us: recycle,
            ..Hardware::default()
        };
        let mut w: World<8> = World::connected(0, hw);
        w.handling_delay_us = handling_delay;
        let groups = plan.groups.len() as u32;
        let shots: u64 = plan.total_shots();
        send(&mut w, RequestBody::LoadPlan(plan));
        send(&mut w, RequestBody::Run { first_group: 0, last_group: groups - 1 });
        for _ in 0..100 {
            w.advance(1_000_000);
            let n = w.records().len() as u32;
            send(&mut w, RequestBody::AckRecords { next_index: n });
            if w.seq.state() != SessionState::Running {
                break;
            }
        }
        prop_assert_eq!(w.seq.state(), SessionState::Completed);
        check_off_times(&w)?;
        let presses = w.assert_times(Line::Shutter).len() as u64;
        let recs = w.records();
        prop_assert_eq!(presses, recs.len() as u64, "one press per attempt");
        prop_assert!(recs.iter().all(|r| r.outcome == ShotOutcome::Ok), "{:?}", recs);
        prop_assert_eq!(recs.len() as u64, shots);
    }
}
