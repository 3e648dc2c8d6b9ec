//! End to end: the simulator on a pseudo-terminal, the capture library against it with the
//! repository's `plans/quick.toml`, and the `capture.json` it leaves behind.

use std::path::Path;

use skinbrdf_capture::{load_plan, read_capture, run_capture, SerialConnector, Unattended};
use skinbrdf_session::capture::{ImageRole, ShotOutcome, CAPTURE_FORMAT_VERSION};
use skinbrdf_tests::{Backend, BackendKind, Scenario, SimBackend};

#[test]
fn sim_pty_quick_plan_writes_capture_json() {
    let plan_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../plans/quick.toml");
    let plan = load_plan(&plan_path).expect("plans/quick.toml");
    let sim = SimBackend::start(Scenario::default()).expect("simulator");
    assert_eq!(sim.kind(), BackendKind::Sim);
    let dir = tempfile::tempdir().expect("tempdir");
    let session = dir.path().join("session-1");
    let mut options = sim.options();
    options.out_dir = Some(session.clone());
    let returned = run_capture(
        SerialConnector { path: sim.port() },
        &plan,
        &options,
        &mut Unattended,
    )
    .expect("capture against the simulator");
    let record = read_capture(&session.join("capture.json")).expect("capture.json");
    assert_eq!(record, returned);
    assert_eq!(record.format_version, CAPTURE_FORMAT_VERSION);
    assert!(record.complete);
    assert_eq!(record.plan, plan);
    assert_eq!(record.device.kind, "simulator");
    let planned: u32 = plan.groups.iter().map(|g| g.count).sum();
    assert_eq!(record.exposures.len(), planned as usize);
    for role in [
        ImageRole::Measurement,
        ImageRole::LightPosition,
        ImageRole::ReferenceStandard,
        ImageRole::StandardPosition,
    ] {
        let want: u32 = plan
            .groups
            .iter()
            .filter(|g| g.role == role)
            .map(|g| g.count)
            .sum();
        let got = record.exposures.iter().filter(|e| e.role == role).count();
        assert_eq!(got, want as usize, "{role:?}");
    }
    assert!(record
        .exposures
        .iter()
        .all(|e| e.outcome == ShotOutcome::Ok));
    // Device times are beyond 2^32 us and survive the round trip exactly.
    assert!(record
        .exposures
        .iter()
        .all(|e| e.shutter_command_us > 1 << 32));
    // The simulator runs 50x faster than the host clock, so the fitted rate is near 1/50; how
    // near depends on scheduling (a timing fact, printed, not asserted). It must be positive
    // so host times keep the device's order.
    let rate = 1.0 + record.clock.drift_ppm * 1e-6;
    assert!(rate > 0.0, "host us per device us {rate}");
    for w in record.exposures.windows(2) {
        assert!(w[1].host_time_us > w[0].host_time_us);
    }
    eprintln!(
        "clock fit: {} reads, residual {:.1} us RMS, rate {rate:.5}",
        record.clock.samples, record.clock.residual_rms_us
    );
}

#[test]
fn sim_in_process_link_runs_the_same_capture() {
    let plan = skinbrdf_tests::short_plan([3, 1, 1, 2], 200_000, 0);
    let cfg = skinbrdf_sim::SimConfig {
        time_scale: skinbrdf_tests::SIM_TIME_SCALE,
        start_us: skinbrdf_tests::SIM_START_US,
        ..Default::default()
    };
    let (handle, link) = skinbrdf_sim::spawn_in_process(cfg).expect("simulator");
    let sim_options = skinbrdf_tests::sim_options();
    let connector = skinbrdf_capture::OnceConnector::new(skinbrdf_tests::InProcess(link));
    let record = run_capture(connector, &plan, &sim_options, &mut Unattended).expect("capture");
    assert!(record.complete);
    assert_eq!(record.exposures.len(), 7);
    assert!(record
        .exposures
        .iter()
        .all(|e| e.outcome == ShotOutcome::Ok));
    let report = handle.stop().expect("simulator report");
    assert!(report.device_time_us > record.exposures[6].shutter_command_us);
}
