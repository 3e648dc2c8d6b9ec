//! Writes the 1M-sample benchmark data set as a sample file and times skinbrdf's fits on it, for
//! the SciPy comparison in `scripts/peers/scipy_least_squares.py`.
//!
//! `cargo run --release -p skinbrdf-fit --example peer_fit -- OUT.skbs`

use std::time::Instant;

use skinbrdf_brdf::{ChannelModel, LafortuneFit, StartHint};
use skinbrdf_fit::fit::auto_floor;
use skinbrdf_fit::lm::{self, ChannelData, LmConfig, ResidualKind};
use skinbrdf_fit::{fit_data, FitConfig, FitData};

/// Timed runs of each variant (the median is reported).
const REPEATS: usize = 5;

/// CPU time (user + system, all threads) of this process so far, from `/proc/self/stat`
/// (Linux; `None` elsewhere). On an idle machine with `T` cores the wall time of a well
/// parallelised run approaches `cpu / T`: this is the load-independent figure.
fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    // USER_HZ is 100 on every Linux configuration in use.
    Some(ticks / 100.0)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "bench_1m.skbs".into());
    let n: usize = std::env::args()
        .nth(2)
        .map_or(Ok(1_000_000), |s| s.parse())?;
    let (_, samples) = skinbrdf_fit::synthetic::lafortune2_samples(n, 0.05, 7);
    skinbrdf_samples::write_samples(
        &out,
        &skinbrdf_samples::SampleHeader::new(
            "synthetic",
            "lafortune2 benchmark, 5% log-normal noise, seed 7",
        ),
        &samples,
    )?;
    let data = FitData::from_samples(&samples)?;
    let model = LafortuneFit::standard(2);
    let grey: Vec<f64> = (0..data.len())
        .map(|i| (data.y[0][i] + data.y[1][i] + data.y[2][i]) / 3.0)
        .collect();
    let floor = auto_floor(&grey, skinbrdf_fit::fit::LOG_FLOOR_REL_MEDIAN);
    let residual = ResidualKind::Log { floor_rho: floor };
    let target = lm::transform_target(residual, &data.geom, &data.y[0]);
    let cd = ChannelData {
        geom: &data.geom,
        target: &target,
        sqrt_w: &data.sqrt_w,
        residual,
    };
    let y = &data.y[0];
    let mut sorted = y.clone();
    sorted.sort_by(f64::total_cmp);
    let hint = StartHint {
        diffuse_rho: sorted[sorted.len() / 4],
        peak_rho: sorted[(sorted.len() as f64 * 0.999) as usize],
    };
    let start = model.starting_points(&hint)[1].clone();
    // Median of REPEATS runs of each (the machine is shared; the median is robust to a burst).
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut times = Vec::new();
    let mut o = None;
    for _ in 0..REPEATS {
        let t = Instant::now();
        o = Some(lm::solve(&model, &start, &cd, &LmConfig::default()).ok_or("no finite cost")?);
        times.push(t.elapsed().as_secs_f64());
    }
    let o = o.ok_or("no run")?;
    let single = median(times);
    let mut times = Vec::new();
    let mut full = None;
    let cpu0 = process_cpu_s();
    for _ in 0..REPEATS {
        let t = Instant::now();
        full = Some(fit_data(&model, &data, &FitConfig::default())?);
        times.push(t.elapsed().as_secs_f64());
    }
    let full = full.ok_or("no run")?;
    let pipeline = median(times);
    let pipeline_cpu = cpu0
        .zip(process_cpu_s())
        .map(|(a, b)| (b - a) / REPEATS as f64);
    println!(
        "{}",
        serde_json::json!({
            "samples": n,
            "floor": floor,
            "start": start,
            "single_start_red": {"seconds": single, "cost": o.cost, "iterations": o.iterations, "evaluations": o.evaluations, "params": o.params},
            "repeats": REPEATS,
            "threads": rayon::current_num_threads(),
            "pipeline_rgb": {"seconds": pipeline, "cpu_seconds": pipeline_cpu, "cost_red": full.channels[0].cost, "params_red": full.channels[0].params, "costs": full.channels.iter().map(|c| c.cost).collect::<Vec<_>>(), "stages": full.channels.iter().map(|c| &c.stages).collect::<Vec<_>>()},
        })
    );
    Ok(())
}
