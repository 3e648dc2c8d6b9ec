//! Sequencer behaviour: handshake, shot timing, recycle wait, timeouts, faults and policy,
//! abort, watchdog, safe state, ack / no loss, u64 clock.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

mod world;

use skinbrdf_protocol::*;
use skinbrdf_sequencer::{Input, Line, Outputs, MAX_WATCHDOG_US, MIN_SHUTTER_OFF_US};
use world::{group, plan, Hardware, World};

const T0: u64 = 1_000;
/// Beyond the u32 microsecond wrap (71.6 minutes).
const T_BIG: u64 = (1u64 << 32) + 123_456;

fn load_and_run<const R: usize>(w: &mut World<R>, p: Plan) {
    let groups = p.groups.len() as u32;
    w.request(RequestBody::LoadPlan(p)).expect("plan loads");
    w.request(RequestBody::Run {
        first_group: 0,
        last_group: groups - 1,
    })
    .expect("runs");
}

fn assert_contiguous(records: &[ExposureRecord]) {
    for (i, r) in records.iter().enumerate() {
        assert_eq!(r.index, i as u32, "record indices are contiguous from 0");
    }
}

#[test]
fn handshake_required_then_version_checked() {
    let mut w: World = World::new(T0, Hardware::default());
    assert_eq!(
        w.request(RequestBody::ReadClock),
        Err(DeviceError::HandshakeRequired)
    );
    assert_eq!(
        w.request(RequestBody::Hello {
            protocol_version: PROTOCOL_VERSION + 1
        }),
        Err(DeviceError::VersionMismatch {
            device: PROTOCOL_VERSION,
            host: PROTOCOL_VERSION + 1
        })
    );
    assert_eq!(
        w.request(RequestBody::Ping),
        Err(DeviceError::HandshakeRequired)
    );
    match w.request(RequestBody::Hello {
        protocol_version: PROTOCOL_VERSION,
    }) {
        Ok(ResponseBody::Hello(info)) => {
            assert_eq!(info.protocol_version, PROTOCOL_VERSION);
            assert_eq!(info.serial.as_str(), "TEST-1");
            assert_eq!(info.firmware_version.as_str(), "0.1.0");
            assert_eq!(check_version(&info), Ok(()));
        }
        other => panic!("unexpected {other:?}"),
    }
    w.advance(250);
    assert_eq!(
        w.request(RequestBody::ReadClock),
        Ok(ResponseBody::Clock {
            device_us: T0 + 250
        })
    );
    // A new connection needs a new handshake.
    w.input(Input::LinkDown);
    w.input(Input::LinkUp);
    assert_eq!(
        w.request(RequestBody::Ping),
        Err(DeviceError::HandshakeRequired)
    );
}

#[test]
fn full_plan_hot_shoe_timing_and_records() {
    let hw = Hardware::default();
    let mut w: World = World::connected(T0, hw);
    let p = plan(
        vec![
            group(
                "measurement",
                ImageRole::Measurement,
                3,
                FlashMode::CameraHotShoe,
            ),
            group(
                "standard",
                ImageRole::ReferenceStandard,
                2,
                FlashMode::CameraHotShoe,
            ),
        ],
        0,
        ExhaustedAction::AbortSession,
    );
    let g = p.groups[0].clone();
    load_and_run(&mut w, p);
    w.advance(60_000_000);
    assert_eq!(w.session_done(), Some(SessionOutcome::Completed));
    assert_eq!(w.seq.state(), SessionState::Completed);
    let recs = w.records();
    assert_eq!(recs.len(), 5);
    assert_contiguous(&recs);
    let mut prev_shutter: Option<u64> = None;
    for (i, r) in recs.iter().enumerate() {
        assert_eq!(r.outcome, ShotOutcome::Ok);
        assert_eq!(r.group, if i < 3 { 0 } else { 1 });
        assert_eq!(r.shot, if i < 3 { i as u32 } else { i as u32 - 3 });
        assert_eq!(
            r.role,
            if i < 3 {
                ImageRole::Measurement
            } else {
                ImageRole::ReferenceStandard
            }
        );
        let s = r.shutter_command_us.expect("shutter");
        assert!(
            s >= r.started_us + g.pre_focus_us,
            "focus held before shutter"
        );
        assert_eq!(r.xsync_us, Some(s + hw.shutter_lag_us));
        assert_eq!(
            r.flash_fired_us,
            Some(s + hw.shutter_lag_us + hw.flash_delay_us)
        );
        if let Some(p) = prev_shutter {
            // The recycle (1.5 s) is longer than the min interval (1 s): the flash gates.
            assert!(s - p >= g.min_interval_us);
            assert!(s - p >= hw.recycle_us);
            assert_eq!(r.recycle_us, Some(hw.recycle_us));
        } else {
            assert_eq!(r.recycle_us, None, "no flash before the first shot");
        }
        prev_shutter = Some(s);
    }
    // Focus asserted pre_focus before each shutter; shutter pulse width exact.
    let sh_on = w.assert_times(Line::Shutter);
    let sh_off = w.release_times(Line::Shutter);
    let fo_on = w.assert_times(Line::Focus);
    assert_eq!(sh_on.len(), 5);
    assert_eq!(sh_off.len(), 5);
    for i in 0..5 {
        assert_eq!(sh_off[i] - sh_on[i], g.shutter_pulse_us);
        assert_eq!(sh_on[i] - fo_on[i], g.pre_focus_us);
    }
    assert!(
        w.assert_times(Line::FlashTrigger).is_empty(),
        "hot-shoe mode never drives the flash"
    );
    assert_eq!(w.outputs(), Outputs::SAFE);
}

#[test]
fn controller_fires_flash_on_xsync() {
    let hw = Hardware {
        mode: FlashMode::ControllerOnXsync,
        recycle_us: 500_000,
        ..Hardware::default()
    };
    let mut w: World = World::connected(T0, hw);
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            4,
            FlashMode::ControllerOnXsync,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    let pulse = p.flash_trigger_pulse_us;
    load_and_run(&mut w, p);
    w.advance(30_000_000);
    let recs = w.records();
    assert_eq!(recs.len(), 4);
    let trig_on = w.assert_times(Line::FlashTrigger);
    let trig_off = w.release_times(Line::FlashTrigger);
    assert_eq!(trig_on.len(), 4);
    for (i, r) in recs.iter().enumerate() {
        assert_eq!(r.outcome, ShotOutcome::Ok);
        assert_eq!(
            trig_on[i],
            r.xsync_us.expect("xsync"),
            "trigger asserted at the X-sync edge"
        );
        assert_eq!(trig_off[i] - trig_on[i], pulse);
        assert_eq!(r.flash_fired_us, Some(trig_on[i] + hw.flash_delay_us));
    }
    // Min interval (1 s) is longer than recycle (0.5 s) here: the interval gates.
    for pair in recs.windows(2) {
        let d = pair[1].shutter_command_us.unwrap() - pair[0].shutter_command_us.unwrap();
        assert!(d >= 1_000_000);
        assert_eq!(pair[1].recycle_us, Some(500_000));
    }
    assert_eq!(w.outputs(), Outputs::SAFE);
}

#[test]
fn recycle_wait_waits_for_ready_and_times_out() {
    // Flash not ready at the start; becomes ready after 2 s (< 4 s timeout).
    let mut w: World = World::connected(T0, Hardware::default());
    w.input(Input::FlashReady {
        at_us: T0,
        ready: false,
    });
    w.flash_ready = false;
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            1,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    w.advance(1_000_000);
    assert!(!w.outputs().focus, "no focus before the flash is ready");
    w.flash_ready = true;
    w.input(Input::FlashReady {
        at_us: w.now,
        ready: true,
    });
    let ready_at = w.now;
    w.advance(5_000_000);
    let recs = w.records();
    assert_eq!(recs.len(), 1);
    assert_eq!(recs[0].outcome, ShotOutcome::Ok);
    assert_eq!(recs[0].shutter_command_us, Some(ready_at + 200_000));
}

#[test]
fn flash_never_ready_is_a_fault_with_retries_then_abort() {
    let mut w: World = World::connected(T0, Hardware::default());
    w.input(Input::FlashReady {
        at_us: T0,
        ready: false,
    });
    w.flash_ready = false;
    w.request(RequestBody::SetWatchdog { timeout_us: 0 })
        .expect("set");
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            3,
            FlashMode::CameraHotShoe,
        )],
        2,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    w.advance(60_000_000);
    let recs = w.records();
    assert_eq!(recs.len(), 3, "first try + 2 retries, each recorded");
    assert_contiguous(&recs);
    for (i, r) in recs.iter().enumerate() {
        assert_eq!(r.outcome, ShotOutcome::FlashNotReady);
        assert_eq!(r.attempt, i as u32);
        assert_eq!(r.shot, 0);
        assert_eq!(r.shutter_command_us, None);
    }
    assert_eq!(
        w.faults(),
        vec![
            FaultKind::FlashNotReady,
            FaultKind::FlashNotReady,
            FaultKind::FlashNotReady,
            FaultKind::RetriesExhausted
        ]
    );
    assert_eq!(w.session_done(), Some(SessionOutcome::Faulted));
    assert_eq!(w.seq.state(), SessionState::Aborted);
    assert!(
        w.pin_log.iter().all(|(_, a)| a.line == Line::StatusLed),
        "camera never touched"
    );
    assert_eq!(w.outputs(), Outputs::SAFE);
    assert_eq!(
        w.request(RequestBody::Run {
            first_group: 0,
            last_group: 0
        }),
        Err(DeviceError::SessionAborted)
    );
}

#[test]
fn camera_not_firing_releases_lines_at_the_xsync_timeout_and_skips() {
    let hw = Hardware {
        camera_fires: false,
        ..Hardware::default()
    };
    let mut w: World = World::connected(T0, hw);
    let mut g = group("m", ImageRole::Measurement, 2, FlashMode::CameraHotShoe);
    g.shutter_pulse_us = 800_000; // longer than the X-sync timeout: the fault cuts it short
    let p = plan(vec![g.clone()], 1, ExhaustedAction::SkipShot);
    load_and_run(&mut w, p);
    w.advance(60_000_000);
    let recs = w.records();
    assert_eq!(recs.len(), 4, "2 shots x (try + 1 retry)");
    assert_contiguous(&recs);
    for r in &recs {
        assert_eq!(r.outcome, ShotOutcome::MissingXsync);
        assert_eq!(r.xsync_us, None);
    }
    assert_eq!(
        w.session_done(),
        Some(SessionOutcome::Completed),
        "skip policy completes the plan"
    );
    let on = w.assert_times(Line::Shutter);
    let off = w.release_times(Line::Shutter);
    for i in 0..4 {
        assert_eq!(
            off[i] - on[i],
            g.xsync_timeout_us,
            "released when the fault is detected"
        );
    }
    assert_eq!(w.outputs(), Outputs::SAFE);
}

#[test]
fn camera_recovers_on_retry() {
    let hw = Hardware {
        camera_fires: false,
        ..Hardware::default()
    };
    let mut w: World = World::connected(T0, hw);
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            1,
            FlashMode::CameraHotShoe,
        )],
        3,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    w.advance(900_000); // first attempt's shutter is out (focus 200 ms) and times out at 700 ms
    assert_eq!(w.records().len(), 1);
    w.hw.camera_fires = true;
    w.advance(20_000_000);
    let recs = w.records();
    assert_eq!(
        recs.iter().map(|r| r.outcome).collect::<Vec<_>>(),
        vec![ShotOutcome::MissingXsync, ShotOutcome::Ok]
    );
    assert_eq!(recs[1].attempt, 1);
    assert_eq!(w.session_done(), Some(SessionOutcome::Completed));
}

#[test]
fn misfire_is_missing_flash() {
    for mode in [FlashMode::CameraHotShoe, FlashMode::ControllerOnXsync] {
        let hw = Hardware {
            flash_fires: false,
            mode,
            ..Hardware::default()
        };
        let mut w: World = World::connected(T0, hw);
        let p = plan(
            vec![group("m", ImageRole::Measurement, 1, mode)],
            0,
            ExhaustedAction::AbortSession,
        );
        load_and_run(&mut w, p);
        w.advance(10_000_000);
        let recs = w.records();
        assert_eq!(recs.len(), 1);
        let r = &recs[0];
        assert_eq!(r.outcome, ShotOutcome::MissingFlash);
        assert!(r.xsync_us.is_some());
        assert_eq!(r.flash_fired_us, None);
        assert_eq!(
            w.faults(),
            vec![FaultKind::MissingFlash, FaultKind::RetriesExhausted]
        );
        assert_eq!(w.session_done(), Some(SessionOutcome::Faulted));
        assert_eq!(w.outputs(), Outputs::SAFE);
    }
}

#[test]
fn abort_mid_shot_releases_everything_and_records_the_attempt() {
    let mut w: World = World::connected(T0, Hardware::default());
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            5,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    w.advance(250_000); // focus at 0, shutter at 200 ms, X-sync due at 280 ms
    assert!(w.outputs().shutter && w.outputs().focus);
    assert_eq!(
        w.request(RequestBody::Abort),
        Ok(ResponseBody::Aborted { was_running: true })
    );
    assert_eq!(w.outputs(), Outputs::SAFE);
    let recs = w.records();
    assert_eq!(recs.len(), 1);
    assert_eq!(recs[0].outcome, ShotOutcome::Aborted);
    assert!(recs[0].shutter_command_us.is_some());
    assert_eq!(w.session_done(), Some(SessionOutcome::Aborted));
    // Late edges after the abort change nothing.
    w.advance(10_000_000);
    assert_eq!(w.records().len(), 1);
    assert_eq!(w.outputs(), Outputs::SAFE);
    assert_eq!(
        w.request(RequestBody::Abort),
        Ok(ResponseBody::Aborted { was_running: false })
    );
}

#[test]
fn host_silence_aborts_a_running_session() {
    let mut w: World = World::connected(T0, Hardware::default());
    w.request(RequestBody::SetWatchdog {
        timeout_us: 3_000_000,
    })
    .expect("set");
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            30,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    let started = w.now;
    w.advance(20_000_000);
    assert!(w.faults().contains(&FaultKind::HostSilent));
    assert_eq!(w.session_done(), Some(SessionOutcome::Faulted));
    assert_eq!(w.outputs(), Outputs::SAFE);
    let last_release = w.pin_log.iter().map(|(t, _)| *t).max().unwrap();
    assert_eq!(
        last_release,
        started + 3_000_000,
        "released exactly at the watchdog deadline"
    );
    assert!(w.records().len() < 30);
}

#[test]
fn pings_keep_the_session_alive() {
    let mut w: World = World::connected(T0, Hardware::default());
    w.request(RequestBody::SetWatchdog {
        timeout_us: 1_000_000,
    })
    .expect("set");
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            6,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    for _ in 0..40 {
        w.advance(500_000);
        w.request(RequestBody::Ping).expect("pong");
    }
    assert_eq!(w.session_done(), Some(SessionOutcome::Completed));
    assert!(!w.faults().contains(&FaultKind::HostSilent));
}

#[test]
fn groups_run_one_at_a_time_for_operator_prompts() {
    let mut w: World = World::connected(T0, Hardware::default());
    let p = plan(
        vec![
            group("a", ImageRole::Measurement, 2, FlashMode::CameraHotShoe),
            group("b", ImageRole::LightPosition, 1, FlashMode::CameraHotShoe),
        ],
        0,
        ExhaustedAction::AbortSession,
    );
    assert_eq!(
        w.request(RequestBody::Run {
            first_group: 0,
            last_group: 0
        }),
        Err(DeviceError::NoPlan)
    );
    assert_eq!(
        w.request(RequestBody::LoadPlan(p)),
        Ok(ResponseBody::PlanLoaded { total_shots: 3 })
    );
    assert_eq!(
        w.request(RequestBody::Run {
            first_group: 1,
            last_group: 1
        }),
        Err(DeviceError::BadGroupRange {
            groups: 2,
            next_group: 0
        })
    );
    assert_eq!(
        w.request(RequestBody::Run {
            first_group: 0,
            last_group: 0
        }),
        Ok(ResponseBody::Running { first_index: 0 })
    );
    w.advance(30_000_000);
    assert!(w.events().iter().any(|e| matches!(
        e,
        Event::GroupsDone {
            last_group: 0,
            next_index: 2,
            ..
        }
    )));
    assert_eq!(w.session_done(), None);
    assert_eq!(w.seq.state(), SessionState::Ready);
    assert_eq!(w.records().len(), 2);
    assert_eq!(
        w.request(RequestBody::Run {
            first_group: 1,
            last_group: 1
        }),
        Ok(ResponseBody::Running { first_index: 2 })
    );
    w.advance(30_000_000);
    assert_eq!(w.session_done(), Some(SessionOutcome::Completed));
    assert_eq!(w.records().len(), 3);
}

#[test]
fn invalid_plans_are_refused_with_the_reason() {
    let mut w: World = World::connected(T0, Hardware::default());
    let mut g = group("a", ImageRole::Measurement, 0, FlashMode::CameraHotShoe);
    let r = w.request(RequestBody::LoadPlan(plan(
        vec![g.clone()],
        0,
        ExhaustedAction::AbortSession,
    )));
    assert_eq!(
        r,
        Err(DeviceError::InvalidPlan {
            group: 0,
            problem: PlanProblem::ZeroCount
        })
    );
    g.count = 1;
    let mut p = plan(
        vec![
            g.clone(),
            group("b", ImageRole::Measurement, 1, FlashMode::ControllerOnXsync),
        ],
        0,
        ExhaustedAction::AbortSession,
    );
    p.flash_trigger_pulse_us = 0;
    assert_eq!(
        w.request(RequestBody::LoadPlan(p)),
        Err(DeviceError::InvalidPlan {
            group: 1,
            problem: PlanProblem::ZeroFlashTriggerPulse
        })
    );
    assert_eq!(
        w.request(RequestBody::LoadPlan(plan(
            vec![],
            0,
            ExhaustedAction::AbortSession
        ))),
        Err(DeviceError::InvalidPlan {
            group: 0,
            problem: PlanProblem::NoGroups
        })
    );
}

#[test]
fn full_ring_pauses_until_ack_and_nothing_is_lost() {
    let mut w: World<4> = World::connected(T0, Hardware::default());
    // This host is silent for long stretches: no watchdog.
    w.request(RequestBody::SetWatchdog { timeout_us: 0 })
        .expect("set");
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            10,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    w.advance(60_000_000);
    assert_eq!(w.records().len(), 4, "stops at a full ring");
    assert_eq!(w.seq.state(), SessionState::Running);
    assert!(w.outputs().camera_and_flash_released());
    assert_eq!(
        w.request(RequestBody::AckRecords { next_index: 9 }),
        Err(DeviceError::AckBeyondEnd { next_index: 4 })
    );
    // Ack in steps; each ack lets more shots happen.
    let mut acked = 0;
    while w.session_done().is_none() {
        acked = w.records().len() as u32;
        w.request(RequestBody::AckRecords { next_index: acked })
            .expect("ack");
        w.advance(20_000_000);
    }
    let recs = w.records();
    assert_eq!(recs.len(), 10);
    assert_contiguous(&recs);
    assert!(acked <= 10);
    // Shutter commands respect the interval even across the pause.
    assert!(recs
        .windows(2)
        .all(|p| p[1].shutter_command_us > p[0].shutter_command_us));
}

#[test]
fn link_drop_and_fetch_recovers_every_record_once() {
    let mut w: World = World::connected(T0, Hardware::default());
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            8,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    w.advance(4_000_000);
    let before = w.records();
    assert!(!before.is_empty());
    w.request(RequestBody::AckRecords {
        next_index: before.len() as u32,
    })
    .expect("ack");
    w.input(Input::LinkDown);
    let during_start = w.msgs.len();
    w.advance(5_000_000); // shorter than the 10 s default watchdog: the session pauses
    assert_eq!(
        w.msgs.len(),
        during_start,
        "nothing is sent while the link is down"
    );
    w.input(Input::LinkUp);
    w.request(RequestBody::Hello {
        protocol_version: PROTOCOL_VERSION,
    })
    .expect("hello");
    assert_eq!(
        w.request(RequestBody::FetchRecords { from_index: 0 }),
        Err(DeviceError::AlreadyAcked {
            oldest_held: before.len() as u32
        })
    );
    let r = w.request(RequestBody::FetchRecords {
        from_index: before.len() as u32,
    });
    let Ok(ResponseBody::Fetching { count }) = r else {
        panic!("{r:?}")
    };
    // The session paused at the link drop: only the shot in flight (if any) was taken.
    assert!(count <= 1, "{count}");
    w.advance(30_000_000);
    let mut seen = std::collections::BTreeMap::new();
    for r in w.records() {
        seen.entry(r.index).or_insert(r);
    }
    assert_eq!(seen.len(), 8);
    assert_eq!(
        seen.keys().copied().collect::<Vec<_>>(),
        (0..8).collect::<Vec<_>>()
    );
    // The resend and the live records after it come in index order, without duplicates.
    let after: Vec<u32> = w.records()[before.len()..]
        .iter()
        .map(|r| r.index)
        .collect();
    assert_eq!(after, (before.len() as u32..8).collect::<Vec<_>>());
    assert_eq!(w.session_done(), Some(SessionOutcome::Completed));
}

#[test]
fn load_plan_refused_while_records_unacked_or_running() {
    let mut w: World = World::connected(T0, Hardware::default());
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            2,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p.clone());
    assert_eq!(
        w.request(RequestBody::LoadPlan(p.clone())),
        Err(DeviceError::Busy)
    );
    w.advance(20_000_000);
    assert_eq!(
        w.request(RequestBody::LoadPlan(p.clone())),
        Err(DeviceError::UnackedRecords { unacked: 2 })
    );
    w.request(RequestBody::AckRecords { next_index: 2 })
        .expect("ack");
    assert_eq!(
        w.request(RequestBody::LoadPlan(p)),
        Ok(ResponseBody::PlanLoaded { total_shots: 2 })
    );
    assert_eq!(
        w.seq.status().next_index,
        0,
        "a new session restarts indices"
    );
}

#[test]
fn clock_beyond_u32_range() {
    let hw = Hardware::default();
    let mut w: World = World::connected(T_BIG, hw);
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            3,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    w.advance(30_000_000);
    let recs = w.records();
    assert_eq!(recs.len(), 3);
    for r in &recs {
        let s = r.shutter_command_us.unwrap();
        assert!(s > u32::MAX as u64);
        assert_eq!(r.xsync_us, Some(s + hw.shutter_lag_us));
    }
    assert_eq!(
        w.request(RequestBody::ReadClock),
        Ok(ResponseBody::Clock { device_us: w.now })
    );
}

#[test]
fn late_handled_edges_use_their_capture_time() {
    // Every edge is handled 300 ms after it happened: the X-sync (80 ms after the shutter)
    // arrives after the 200 ms timeout would have passed by handling time, but its capture
    // time is in time, so no fault.
    let mut w: World = World::connected(T0, Hardware::default());
    w.handling_delay_us = 300_000;
    let mut g = group("m", ImageRole::Measurement, 2, FlashMode::CameraHotShoe);
    g.xsync_timeout_us = 200_000;
    g.flash_window_us = 1_000;
    let p = plan(vec![g], 0, ExhaustedAction::AbortSession);
    load_and_run(&mut w, p);
    w.advance(20_000_000);
    let recs = w.records();
    assert_eq!(recs.len(), 2);
    assert!(
        recs.iter().all(|r| r.outcome == ShotOutcome::Ok),
        "{recs:?}"
    );
}

#[test]
fn stray_edges_outside_a_shot_are_logged_not_recorded() {
    let mut w: World = World::connected(T0, Hardware::default());
    w.input(Input::XsyncEdge { at_us: T0 });
    w.input(Input::PhotodiodeEdge { at_us: T0 });
    assert!(w.records().is_empty());
    assert!(w.events().iter().any(|e| matches!(
        e,
        Event::Log {
            level: LogLevel::Warn,
            ..
        }
    )));
    assert_eq!(w.outputs(), Outputs::SAFE);
}

#[test]
fn bad_frames_are_counted() {
    let mut w: World = World::connected(T0, Hardware::default());
    w.input(Input::BadFrame(FrameError::Cobs));
    w.input(Input::BadFrame(FrameError::Crc {
        received: 1,
        computed: 2,
    }));
    assert_eq!(w.seq.status().bad_frames, 2);
}

#[test]
fn a_retry_with_the_same_seq_is_answered_not_executed() {
    let mut w: World = World::connected(T0, Hardware::default());
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            2,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    w.request(RequestBody::LoadPlan(p)).expect("plan");
    let run = Request {
        seq: 77,
        body: RequestBody::Run {
            first_group: 0,
            last_group: 0,
        },
    };
    w.input(Input::Request(run.clone()));
    w.advance(10_000);
    // The response was lost; the host retries with the same seq.
    let before = w.msgs.len();
    w.input(Input::Request(run.clone()));
    let again: Vec<_> = w.msgs[before..]
        .iter()
        .filter_map(|m| match m {
            DeviceMessage::Response(r) => Some(r.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(
        again,
        vec![Response {
            seq: 77,
            result: Ok(ResponseBody::Running { first_index: 0 })
        }]
    );
    // A new seq executes: now it is busy.
    assert_eq!(
        w.request(RequestBody::Run {
            first_group: 0,
            last_group: 0
        }),
        Err(DeviceError::Busy)
    );
    // A handshake clears the cache.
    w.request(RequestBody::Hello {
        protocol_version: PROTOCOL_VERSION,
    })
    .expect("hello");
    w.input(Input::Request(run));
    assert!(matches!(
        w.msgs.last(),
        Some(DeviceMessage::Response(Response {
            seq: 77,
            result: Err(DeviceError::Busy)
        }))
    ));
}

#[test]
fn ready_level_is_not_trusted_right_after_a_flash() {
    // The ready line drops 2 ms after the light; with no interval and no pre-focus the next
    // shot would otherwise start while the flash is already recycling.
    let hw = Hardware {
        ready_drop_delay_us: 2_000,
        shutter_lag_us: 80_000,
        ..Hardware::default()
    };
    let mut w: World = World::connected(T0, hw);
    let mut g = group("m", ImageRole::Measurement, 4, FlashMode::CameraHotShoe);
    g.min_interval_us = 0;
    g.pre_focus_us = 0;
    g.shutter_pulse_us = 10_000;
    let p = plan(vec![g], 0, ExhaustedAction::AbortSession);
    load_and_run(&mut w, p);
    w.advance(30_000_000);
    let recs = w.records();
    assert_eq!(recs.len(), 4);
    assert!(
        recs.iter().all(|r| r.outcome == ShotOutcome::Ok),
        "{recs:?}"
    );
    assert_eq!(w.triggers_while_recycling, 0);
    for pair in recs.windows(2) {
        let gap = pair[1].shutter_command_us.unwrap() - pair[0].flash_fired_us.unwrap();
        assert!(gap >= hw.recycle_us, "waited for the recycle: {gap}");
    }
}

/// The plan that merged two presses into one on the firmware image: no pre-focus, a 100 ms
/// shutter pulse, and a next group whose 10 ms interval is shorter than that pulse. The shot
/// ended (pulse over, flash recycled) and the next one started in the same step, so the
/// shutter line never dropped and the camera took one picture for two shots.
fn merged_press_plan() -> Plan {
    let mut a = group("a", ImageRole::Measurement, 1, FlashMode::ControllerOnXsync);
    a.pre_focus_us = 0;
    a.shutter_pulse_us = 100_000;
    a.min_interval_us = 10_000;
    let mut b = a.clone();
    b.label = truncated("b");
    plan(vec![a, b], 0, ExhaustedAction::AbortSession)
}

#[test]
fn a_plan_shorter_than_its_pulses_still_gets_two_clean_presses() {
    let hw = Hardware {
        shutter_lag_us: 20_000,
        recycle_us: 30_000,
        mode: FlashMode::ControllerOnXsync,
        ..Hardware::default()
    };
    let mut w: World = World::connected(T0, hw);
    load_and_run(&mut w, merged_press_plan());
    // The device says it spaced the presses.
    assert!(
        w.events().iter().any(|e| matches!(e,
            Event::Log { level: LogLevel::Warn, text, .. } if text.contains("group 1"))),
        "{:?}",
        w.events()
    );
    w.advance(2_000_000);
    let presses = w.assert_times(Line::Shutter);
    let releases = w.release_times(Line::Shutter);
    assert_eq!(presses.len(), 2, "two presses: {:?}", w.pin_log);
    assert_eq!(releases.len(), 2);
    assert!(releases[0] < presses[1]);
    assert!(presses[1] - releases[0] >= MIN_SHUTTER_OFF_US);
    let recs = w.records();
    assert_eq!(recs.len(), 2);
    assert!(
        recs.iter().all(|r| r.outcome == ShotOutcome::Ok),
        "{recs:?}"
    );
    assert_eq!(w.session_done(), Some(SessionOutcome::Completed));
}

#[test]
fn a_fault_and_its_retry_are_separate_presses() {
    // The X-sync timeout (30 ms) ends the attempt before the 100 ms pulse would: the retry
    // must not re-press at the same instant the fault released the line.
    let hw = Hardware {
        camera_fires: false,
        ..Hardware::default()
    };
    let mut w: World = World::connected(T0, hw);
    let mut g = group("m", ImageRole::Measurement, 1, FlashMode::CameraHotShoe);
    g.pre_focus_us = 0;
    g.min_interval_us = 0;
    g.xsync_timeout_us = 30_000;
    load_and_run(&mut w, plan(vec![g], 2, ExhaustedAction::SkipShot));
    w.advance(2_000_000);
    let presses = w.assert_times(Line::Shutter);
    let releases = w.release_times(Line::Shutter);
    assert_eq!(presses.len(), 3);
    for (r, p) in releases.iter().zip(&presses[1..]) {
        assert!(p - r >= MIN_SHUTTER_OFF_US, "released {r}, pressed {p}");
    }
}

#[test]
fn link_loss_finishes_the_shot_in_flight_then_pauses_until_the_host_is_back() {
    let mut w: World = World::connected(T0, Hardware::default());
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            6,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    // Into the first shot's exposure: focus 200 ms, then the shutter.
    w.advance(250_000);
    assert!(w.outputs().shutter);
    w.input(Input::LinkDown);
    assert!(w.seq.paused());
    w.advance(5_000_000);
    // The shot in flight finished cleanly; nothing else was pressed; everything is released.
    assert_eq!(w.assert_times(Line::Shutter).len(), 1);
    assert!(w.outputs().camera_and_flash_released());
    assert_eq!(w.seq.state(), SessionState::Running);
    assert_eq!(w.seq.status().unacked, 1);
    let held: Vec<ShotOutcome> = w.seq.unacked_records().map(|r| r.outcome).collect();
    assert_eq!(held, vec![ShotOutcome::Ok]);
    // The host returns: handshake, fetch, and the session goes on.
    w.input(Input::LinkUp);
    w.request(RequestBody::Hello {
        protocol_version: PROTOCOL_VERSION,
    })
    .expect("hello");
    assert!(!w.seq.paused());
    w.request(RequestBody::FetchRecords { from_index: 0 })
        .expect("fetch");
    w.advance(9_000_000);
    let mut seen = std::collections::BTreeSet::new();
    for r in w.records() {
        seen.insert(r.index);
    }
    assert_eq!(seen.len(), 6);
    assert_eq!(w.session_done(), Some(SessionOutcome::Completed));
}

#[test]
fn a_host_that_never_returns_is_ended_by_the_watchdog_and_zero_is_bounded() {
    let mut w: World = World::connected(T0, Hardware::default());
    let r = w.request(RequestBody::SetWatchdog { timeout_us: 0 });
    assert_eq!(
        r,
        Ok(ResponseBody::WatchdogSet {
            timeout_us: MAX_WATCHDOG_US
        })
    );
    let r = w.request(RequestBody::SetWatchdog {
        timeout_us: u64::MAX,
    });
    assert_eq!(
        r,
        Ok(ResponseBody::WatchdogSet {
            timeout_us: MAX_WATCHDOG_US
        })
    );
    let p = plan(
        vec![group(
            "m",
            ImageRole::Measurement,
            100,
            FlashMode::CameraHotShoe,
        )],
        0,
        ExhaustedAction::AbortSession,
    );
    load_and_run(&mut w, p);
    w.advance(1_500_000);
    w.input(Input::LinkDown);
    let presses = w.assert_times(Line::Shutter).len();
    w.advance(MAX_WATCHDOG_US + 1_000_000);
    assert_eq!(w.assert_times(Line::Shutter).len(), presses, "paused");
    assert_eq!(w.seq.state(), SessionState::Aborted);
    assert_eq!(w.outputs(), Outputs::SAFE);
    assert_eq!(w.seq.next_deadline(), None);
}
