//! Measures a controller's edge-timestamp error from a train of edges on its flash-ready input
//! (the bench procedure of `docs/firmware.md`, "Calibrating the timestamps on a board").
//!
//! ```sh
//! cargo run --release -p skinbrdf-capture --example timestamp_error -- PORT SECONDS \
//!     [PERIOD_US [FIRST_EDGE_US]]
//! ```
//!
//! It handshakes, then collects every `FlashReady` event (each edge of the input, with its
//! device timestamp) for `SECONDS` of host time, keeps the rising ("ready") edges and:
//!
//! * without `FIRST_EDGE_US` (a free-running signal generator): fits `t_k = t0 + k * P` by least
//!   squares, `k` counted from the edge spacing, and prints the residuals (jitter and the
//!   phase-dependent error; a correct capture shows the +-0.5 us rounding band, RMS ~0.29 us);
//! * with `PERIOD_US` and `FIRST_EDGE_US` (edges at known device times, from a generator that
//!   shares the board's time base): the mean offset of the reported times from the true ones
//!   and the `ACK_DELAY_CYCLES` to use in `firmware/rp2040/src/capture.rs` instead of the
//!   current one, at 125 cycles per microsecond.
//!
//! Against the emulator: start `tests/emulator/harness.js --speed 1`, send it
//! `{"cmd":"configure","flash":{"neverReady":true}}`, then one
//! `{"cmd":"pulse","signal":"flash_ready","at_us":T0 + k * P,"width_us":300}` per edge, and run
//! this on its `PORT` (figures in `docs/firmware.md`).

use std::time::{Duration, Instant};

use skinbrdf_capture::client::Client;
use skinbrdf_capture::protocol::Event;
use skinbrdf_capture::transport::SerialTransport;

/// `ACK_DELAY_CYCLES` in `firmware/rp2040/src/capture.rs` (calibrated in the emulator).
const CURRENT_ACK_DELAY_CYCLES: f64 = 15.0;
/// System clock cycles per microsecond (125 MHz).
const CYCLES_PER_US: f64 = 125.0;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(port), Some(seconds)) = (args.first(), args.get(1)) else {
        return Err("usage: timestamp_error PORT SECONDS [PERIOD_US [FIRST_EDGE_US]]".into());
    };
    let seconds: f64 = seconds.parse()?;
    let period: Option<f64> = args.get(2).map(|p| p.parse()).transpose()?;
    let first: Option<f64> = args.get(3).map(|p| p.parse()).transpose()?;

    let transport = SerialTransport::open(port)?;
    let mut client = Client::connect(transport, Duration::from_secs(2))?;
    println!(
        "connected to {port}: {:?}",
        client.info().map(|i| &i.serial)
    );
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut edges: Vec<f64> = Vec::new();
    while Instant::now() < end {
        if let Some(Event::FlashReady { at_us, ready, .. }) =
            client.next_event(Duration::from_millis(100))?
        {
            if ready {
                edges.push(at_us as f64);
            }
        }
    }
    if edges.len() < 3 {
        return Err(format!("only {} rising edges in {seconds} s", edges.len()).into());
    }
    let p = period.unwrap_or_else(|| median_spacing(&edges));
    let t_first = edges[0];
    // Edge numbers from each spacing (a missed edge skips one), not from the total span: the
    // median spacing is whole microseconds and would drift off a fractional period.
    let mut k = vec![0.0];
    for w in edges.windows(2) {
        let last = k.last().copied().unwrap_or(0.0);
        k.push(last + ((w[1] - w[0]) / p).round().max(1.0));
    }
    match first {
        Some(first_us) => {
            // Edge k of the generator is at first_us + n * p, n counted from first_us.
            let n0 = ((t_first - first_us) / p).round();
            let errs: Vec<f64> = edges
                .iter()
                .zip(&k)
                .map(|(t, k)| t - (first_us + (n0 + k) * p))
                .collect();
            let (mean, rms, min, max) = stats(&errs);
            println!(
                "{} edges: error against the true times mean {mean:+.3} us, RMS {rms:.3} us, \
                 {min:+.3}..{max:+.3} us",
                errs.len()
            );
            // A reported time `offset` late means the counted latency was `offset` short:
            // subtract fewer acknowledgement cycles.
            let constant = CURRENT_ACK_DELAY_CYCLES - (mean * CYCLES_PER_US).round();
            println!(
                "ACK_DELAY_CYCLES: {constant} (now {CURRENT_ACK_DELAY_CYCLES}; mean offset \
                 {mean:+.3} us = {:+.1} cycles)",
                mean * CYCLES_PER_US
            );
        }
        None => {
            let (t0, slope) = fit_line(&k, &edges);
            let res: Vec<f64> = edges
                .iter()
                .zip(&k)
                .map(|(t, k)| t - (t0 + slope * k))
                .collect();
            let (_, rms, min, max) = stats(&res);
            println!(
                "{} edges, fitted period {slope:.4} us: residuals RMS {rms:.3} us, \
                 {min:+.3}..{max:+.3} us (the constant offset needs edges at known device \
                 times: pass PERIOD_US and FIRST_EDGE_US)",
                res.len()
            );
        }
    }
    Ok(())
}

fn median_spacing(t: &[f64]) -> f64 {
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// Least-squares `y = a + b x`.
fn fit_line(x: &[f64], y: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = x.iter().map(|x| (x - mx) * (x - mx)).sum();
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my - b * mx, b)
}

/// Mean, RMS, min, max.
fn stats(v: &[f64]) -> (f64, f64, f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let rms = (v.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    let min = v.iter().copied().fold(f64::INFINITY, f64::min);
    let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (mean, rms, min, max)
}
