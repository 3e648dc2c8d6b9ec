//! Matching cost: sessions of 36 (the method's plan), 100 and 200 exposures 2.0-2.6 s apart,
//! one file each plus 5 test shots before the session, with 1 s and with 10 ms time stamps.
//!
//! ```text
//! cargo bench -p skinbrdf-ingest --bench matching
//! ```

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use skinbrdf_ingest::matching::{
    file_number_from_name, match_shots, CameraShot, CameraTime, ExposureInput, MatchOptions,
};
use skinbrdf_session::capture::{ImageRole, ShotOutcome};

const START_S: f64 = 1_700_000_000.0;

/// Exposure host times (seconds after `START_S`) from a fixed linear congruential sequence.
fn host_times(n: usize) -> Vec<f64> {
    let mut state: u64 = 0x5EED;
    let mut t = 0.0;
    (0..n)
        .map(|k| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            if k > 0 {
                t += 2.0 + 0.6 * ((state >> 11) as f64 / (1u64 << 53) as f64);
            }
            t
        })
        .collect()
}

fn camera_time(camera_s: f64, subsec: bool) -> CameraTime {
    let t = START_S + camera_s;
    let whole = t.floor();
    CameraTime {
        naive_local_s: whole as i64,
        subsec_s: subsec.then(|| ((t - whole) * 100.0).floor().min(99.0) / 100.0),
        utc_offset_s: None,
    }
}

fn session(n: usize, subsec: bool) -> (Vec<CameraShot>, Vec<ExposureInput>) {
    let offset_s = 37.4;
    let times = host_times(n);
    let exposures: Vec<ExposureInput> = times
        .iter()
        .enumerate()
        .map(|(k, &h)| ExposureInput {
            index: k as u32,
            role: ImageRole::Measurement,
            outcome: ShotOutcome::Ok,
            host_time_us: (START_S + h) * 1e6,
        })
        .collect();
    let mut shots: Vec<CameraShot> = (0..5)
        .map(|k| (format!("SKB_{:04}.DNG", k + 1), -60.0 + 7.0 * k as f64))
        .chain(
            times
                .iter()
                .enumerate()
                .map(|(k, &h)| (format!("SKB_{:04}.DNG", k + 6), h)),
        )
        .map(|(file, h)| CameraShot {
            time: camera_time(h + offset_s, subsec),
            shutter_count: None,
            file_number: file_number_from_name(&file),
            body_serial: None,
            file,
        })
        .collect();
    shots.reverse();
    (shots, exposures)
}

fn bench(c: &mut Criterion) {
    let opts = MatchOptions::default();
    for n in [36, 100, 200] {
        for subsec in [false, true] {
            let (shots, exposures) = session(n, subsec);
            let label = format!(
                "match {n} exposures, {}",
                if subsec { "10 ms" } else { "1 s" }
            );
            c.bench_function(&label, |b| {
                b.iter(|| match_shots(black_box(&shots), black_box(&exposures), &opts))
            });
        }
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
