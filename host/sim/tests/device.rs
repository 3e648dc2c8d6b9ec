//! The simulated device driven step by step (deterministic device time, no threads).

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

mod common;

use common::*;
use skinbrdf_protocol::*;
use skinbrdf_sim::{Faults, FlashModel, LinkDrop, SimConfig, SimDevice};

fn host(cfg: SimConfig) -> StepHost {
    let mut h = StepHost::new(SimDevice::new(cfg).expect("valid config"));
    let info = h.hello();
    assert_eq!(info.kind, DeviceKind::Simulator);
    assert_eq!(check_version(&info), Ok(()));
    h
}

fn start(h: &mut StepHost, plan: Plan) {
    let last = plan.groups.len() as u32 - 1;
    h.request(RequestBody::LoadPlan(plan)).expect("plan");
    h.request(RequestBody::Run {
        first_group: 0,
        last_group: last,
    })
    .expect("run");
}

fn assert_all_once(h: &StepHost, n: u32) {
    assert_eq!(h.records.len() as u32, n);
    assert_eq!(h.contiguous(), n, "every index 0..{n} present");
}

#[test]
fn method_session_completes_with_realistic_timing() {
    for mode in [FlashMode::CameraHotShoe, FlashMode::ControllerOnXsync] {
        let cfg = SimConfig::default();
        let nominal = cfg.flash.nominal_recycle_us() as f64;
        let jitter = cfg.flash.recycle_jitter;
        let cam = cfg.camera;
        let mut h = host(cfg);
        start(&mut h, method_plan(mode, 0));
        assert_eq!(h.run_to_end(600_000_000), SessionState::Completed);
        assert_all_once(&h, 36);
        assert_eq!(h.duplicate_records, 0);
        let roles: Vec<ImageRole> = h.records.values().map(|r| r.role).collect();
        assert_eq!(
            roles
                .iter()
                .filter(|r| **r == ImageRole::Measurement)
                .count(),
            30
        );
        assert_eq!(
            roles
                .iter()
                .filter(|r| **r == ImageRole::StandardPosition)
                .count(),
            2
        );
        for r in h.records.values() {
            assert_eq!(r.outcome, ShotOutcome::Ok, "{r:?}");
            let lag = r.xsync_us.unwrap() - r.shutter_command_us.unwrap();
            assert!(
                (cam.shutter_lag_min_us..=cam.shutter_lag_max_us).contains(&lag),
                "lag {lag}"
            );
            let light = r.flash_fired_us.unwrap() - r.xsync_us.unwrap();
            assert_eq!(light, SimConfig::default().flash.trigger_to_light_us);
            if r.index > 0 {
                let rc = r.recycle_us.expect("recycle measured") as f64;
                assert!(
                    (rc - nominal).abs() <= nominal * jitter + 1.0,
                    "recycle {rc} vs {nominal}"
                );
            }
        }
        // Shots are gated by the recycle (1.75 s > 0.5 s interval).
        let shutters: Vec<u64> = h
            .records
            .values()
            .map(|r| r.shutter_command_us.unwrap())
            .collect();
        for w in shutters.windows(2) {
            assert!(w[1] - w[0] >= (nominal * (1.0 - jitter)) as u64);
        }
        let stats = h.dev.stats();
        assert_eq!(stats.flashes, 36);
        assert_eq!(stats.triggers_while_recycling, 0);
        assert!(h.dev.outputs().camera_and_flash_released());
    }
}

#[test]
fn recycle_time_follows_flash_power() {
    let mut means = Vec::new();
    for power in [0.0, 1.0] {
        let mut cfg = SimConfig::default();
        cfg.flash.power = power;
        cfg.flash.recycle_jitter = 0.0;
        let expected = cfg.flash.nominal_recycle_us();
        let mut h = host(cfg);
        start(
            &mut h,
            small_plan(
                4,
                FlashMode::CameraHotShoe,
                0,
                ExhaustedAction::AbortSession,
            ),
        );
        assert_eq!(h.run_to_end(60_000_000), SessionState::Completed);
        let rc: Vec<u64> = h.records.values().filter_map(|r| r.recycle_us).collect();
        assert_eq!(rc.len(), 3);
        assert!(rc.iter().all(|&r| r == expected), "{rc:?} vs {expected}");
        means.push(expected);
    }
    assert_eq!(means, vec![500_000, 3_000_000]);
}

#[test]
fn flash_never_ready_faults_the_session() {
    let cfg = SimConfig {
        faults: Faults {
            flash_never_ready: true,
            ..Faults::default()
        },
        ..SimConfig::default()
    };
    let mut h = host(cfg);
    start(
        &mut h,
        small_plan(
            3,
            FlashMode::CameraHotShoe,
            1,
            ExhaustedAction::AbortSession,
        ),
    );
    assert_eq!(h.run_to_end(60_000_000), SessionState::Aborted);
    assert_all_once(&h, 2);
    assert!(h
        .records
        .values()
        .all(|r| r.outcome == ShotOutcome::FlashNotReady));
    assert_eq!(h.dev.stats().shutter_presses, 0);
    assert!(h.events.iter().any(|e| matches!(
        e,
        Event::SessionDone {
            outcome: SessionOutcome::Faulted,
            ..
        }
    )));
}

#[test]
fn camera_not_firing_is_missing_xsync() {
    let cfg = SimConfig {
        faults: Faults {
            camera_not_firing: true,
            ..Faults::default()
        },
        ..SimConfig::default()
    };
    let mut h = host(cfg);
    start(
        &mut h,
        small_plan(2, FlashMode::CameraHotShoe, 0, ExhaustedAction::SkipShot),
    );
    assert_eq!(h.run_to_end(60_000_000), SessionState::Completed);
    assert_all_once(&h, 2);
    assert!(h
        .records
        .values()
        .all(|r| r.outcome == ShotOutcome::MissingXsync));
    assert_eq!(h.dev.stats().camera_failures, 2);
}

#[test]
fn misfire_is_missing_flash_and_retry_recovers() {
    // Every flash misfires: faults.
    let cfg = SimConfig {
        faults: Faults {
            misfire_probability: 1.0,
            ..Faults::default()
        },
        ..SimConfig::default()
    };
    let mut h = host(cfg);
    start(
        &mut h,
        small_plan(
            1,
            FlashMode::ControllerOnXsync,
            0,
            ExhaustedAction::AbortSession,
        ),
    );
    assert_eq!(h.run_to_end(60_000_000), SessionState::Aborted);
    assert_eq!(h.records[&0].outcome, ShotOutcome::MissingFlash);
    // Half the flashes misfire, 5 retries: the plan completes, every misfire is on record.
    let cfg = SimConfig {
        seed: 7,
        faults: Faults {
            misfire_probability: 0.5,
            ..Faults::default()
        },
        ..SimConfig::default()
    };
    let mut h = host(cfg);
    start(
        &mut h,
        small_plan(
            6,
            FlashMode::CameraHotShoe,
            5,
            ExhaustedAction::AbortSession,
        ),
    );
    assert_eq!(h.run_to_end(300_000_000), SessionState::Completed);
    let misfires = h.dev.stats().misfires;
    let missing: u32 = h
        .records
        .values()
        .filter(|r| r.outcome == ShotOutcome::MissingFlash)
        .count() as u32;
    assert!(misfires > 0);
    assert_eq!(missing, misfires, "every misfire is a record");
    assert_eq!(
        h.records
            .values()
            .filter(|r| r.outcome == ShotOutcome::Ok)
            .count(),
        6
    );
    assert_all_once(&h, h.records.len() as u32);
}

#[test]
fn link_drop_mid_session_loses_no_record() {
    let cfg = SimConfig {
        faults: Faults {
            link_drop: Some(LinkDrop {
                after_records: 5,
                duration_us: 2_000_000,
            }),
            ..Faults::default()
        },
        ..SimConfig::default()
    };
    let mut h = host(cfg);
    start(&mut h, method_plan(FlashMode::CameraHotShoe, 0));
    assert_eq!(h.run_to_end(600_000_000), SessionState::Completed);
    assert_eq!(h.dev.stats().link_drops, 1);
    assert!(h.dev.stats().bytes_lost_link_down > 0 || h.dev.stats().frames_to_host > 0);
    assert_all_once(&h, 36);
    assert!(h.records.values().all(|r| r.outcome == ShotOutcome::Ok));
}

#[test]
fn corrupted_and_truncated_bytes_are_survivable() {
    let cfg = SimConfig {
        seed: 3,
        faults: Faults {
            corrupt_to_host_probability: 0.15,
            truncate_to_host_probability: 0.1,
            corrupt_to_device_probability: 0.1,
            ..Faults::default()
        },
        ..SimConfig::default()
    };
    let mut h = host(cfg);
    start(
        &mut h,
        small_plan(
            12,
            FlashMode::CameraHotShoe,
            0,
            ExhaustedAction::AbortSession,
        ),
    );
    assert_eq!(h.run_to_end(300_000_000), SessionState::Completed);
    let s = h.dev.stats();
    assert!(
        s.corrupted_to_host > 0 && s.truncated_to_host > 0 && s.corrupted_to_device > 0,
        "{s:?}"
    );
    assert!(h.frame_errors > 0, "the host saw bad frames");
    assert!(
        h.dev.sequencer().status().bad_frames > 0,
        "the device saw bad frames"
    );
    assert_all_once(&h, 12);
    // No corrupted record slipped through as a valid one.
    for r in h.records.values() {
        assert_eq!(r.outcome, ShotOutcome::Ok);
        assert!(r.xsync_us.unwrap() > r.shutter_command_us.unwrap());
    }
}

#[test]
fn slow_host_drops_events_but_not_records() {
    let cfg = SimConfig {
        faults: Faults {
            host_bytes_per_s: Some(100),
            ..Faults::default()
        },
        tx_buffer_bytes: 1024,
        // 0.5 s recycle: ~3 frames (~110 bytes) per 0.6 s shot outrun 100 B/s.
        flash: FlashModel {
            power: 0.0,
            ..FlashModel::STUDIO_HALF_POWER
        },
        ..SimConfig::default()
    };
    let mut h = StepHost::new(SimDevice::new(cfg).expect("valid config"));
    // At 100 B/s a full 1 KiB buffer takes 10 s to drain: this host waits that long.
    h.response_timeout_us = 12_000_000;
    h.hello();
    h.request(RequestBody::SetWatchdog {
        timeout_us: 60_000_000,
    })
    .expect("watchdog");
    let mut p = small_plan(
        20,
        FlashMode::CameraHotShoe,
        0,
        ExhaustedAction::AbortSession,
    );
    p.groups[0].min_interval_us = 0;
    p.groups[0].pre_focus_us = 0;
    start(&mut h, p);
    let end = h.run_to_end(600_000_000);
    let faults: Vec<_> = h
        .events
        .iter()
        .filter(|e| matches!(e, Event::Fault(_) | Event::SessionDone { .. }))
        .collect();
    assert_eq!(
        end,
        SessionState::Completed,
        "{faults:?} {:?}",
        h.dev.stats()
    );
    assert_all_once(&h, 20);
    let st = h.status();
    assert!(
        st.dropped_messages > 0,
        "the slow host made the device drop events: {st:?}"
    );
}

#[test]
fn u64_clock_beyond_u32_range() {
    let cfg = SimConfig {
        start_us: u32::MAX as u64 - 2_000_000,
        ..SimConfig::default()
    };
    let mut h = host(cfg);
    start(
        &mut h,
        small_plan(
            4,
            FlashMode::CameraHotShoe,
            0,
            ExhaustedAction::AbortSession,
        ),
    );
    assert_eq!(h.run_to_end(60_000_000), SessionState::Completed);
    let last = h.records.values().last().unwrap();
    assert!(last.flash_fired_us.unwrap() > u32::MAX as u64);
    assert!(h.records.values().all(|r| r.outcome == ShotOutcome::Ok));
}

#[test]
fn same_seed_same_session() {
    let run = |seed| {
        let mut h = host(SimConfig {
            seed,
            ..SimConfig::default()
        });
        start(
            &mut h,
            small_plan(
                5,
                FlashMode::CameraHotShoe,
                0,
                ExhaustedAction::AbortSession,
            ),
        );
        h.run_to_end(60_000_000);
        h.records
            .values()
            .map(|r| r.xsync_us.unwrap() - r.shutter_command_us.unwrap())
            .collect::<Vec<_>>()
    };
    assert_eq!(run(11), run(11));
    assert_ne!(run(11), run(12));
}

#[test]
fn config_errors_name_the_field() {
    let mut cfg = SimConfig::default();
    cfg.flash.power = 1.5;
    let err = SimDevice::new(cfg).unwrap_err().to_string();
    assert!(err.contains("flash.power"), "{err}");
    let cfg = SimConfig {
        time_scale: 0.0,
        ..SimConfig::default()
    };
    assert!(SimDevice::new(cfg)
        .unwrap_err()
        .to_string()
        .contains("time_scale"));
    let mut cfg = SimConfig::default();
    cfg.faults.misfire_probability = -0.1;
    assert!(SimDevice::new(cfg)
        .unwrap_err()
        .to_string()
        .contains("misfire"));
}

#[test]
fn a_host_gone_for_good_pauses_the_session_then_its_watchdog_ends_it() {
    let mut h = host(SimConfig::default());
    h.request(RequestBody::SetWatchdog {
        timeout_us: 10_000_000,
    })
    .expect("watchdog");
    start(&mut h, method_plan(FlashMode::CameraHotShoe, 0));
    // Until the second shot's shutter is down: a shot in flight when the host goes.
    while !h.dev.outputs().shutter || h.records.is_empty() {
        h.pump(1_000);
    }
    let taken = h.dev.sequencer().status().next_index;
    // The host dies without unplugging: its port closes, the link goes down and stays down.
    h.dev.drop_link(u64::MAX / 4);
    h.dev.advance_to(h.dev.now_us() + 1_000_000);
    // The shot in flight was finished and recorded; no other started; every line released.
    assert_eq!(h.dev.sequencer().status().next_index, taken + 1);
    assert!(h.dev.sequencer().paused());
    assert_eq!(h.dev.sequencer().state(), SessionState::Running);
    assert!(h.dev.outputs().camera_and_flash_released());
    // Nobody comes back: the host watchdog ends the session, nothing more was shot.
    h.dev.advance_to(h.dev.now_us() + 10_000_000);
    assert_eq!(h.dev.sequencer().state(), SessionState::Aborted);
    assert_eq!(h.dev.sequencer().status().next_index, taken + 1);
    assert_eq!(h.dev.outputs(), skinbrdf_sequencer::Outputs::SAFE);
    // The records (none acknowledged here) stay in the ring for a host that comes back later.
    assert_eq!(h.dev.sequencer().unacked(), taken + 1);
}
