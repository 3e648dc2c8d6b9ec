//! Times the smoother: `cargo run --release -p skinbrdf-fit --example loess_time -- [N] [SPAN]`.
//!
//! Fits a 3-predictor loess to `N` (default 20 000) samples of a smooth function with noise at a
//! span (default 0.2), as `skinbrdf fit` does per candidate span, and prints the time.
use skinbrdf_fit::loess::{Bandwidth, Loess, LoessConfig};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().map_or(Ok(20_000), |a| a.parse())?;
    let span: f64 = args.next().map_or(Ok(0.2), |a| a.parse())?;
    // Low-discrepancy points in (theta_i, theta_e, phi_d) and a smooth log-BRDF-like response.
    let x: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            let f = |b: f64| (i as f64 * b).fract();
            vec![
                1.4 * f(0.618_034),
                1.4 * f(0.754_878),
                std::f64::consts::PI * f(0.569_840),
            ]
        })
        .collect();
    let y: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, r)| {
            (r[0].cos() * r[1].cos()).ln_1p()
                + 0.3 * (r[2] - 3.0).powi(2) * 0.1
                + 0.01 * ((i * 7919 % 1000) as f64 / 500.0 - 1.0)
        })
        .collect();
    let cfg = LoessConfig {
        bandwidth: Bandwidth::Span(span),
        max_sigma_points: 2000,
        ..LoessConfig::default()
    };
    let t = Instant::now();
    let l = Loess::fit(&x, &y, cfg)?;
    let fit_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let grid: Vec<Vec<f64>> = (0..1000)
        .map(|k| vec![0.5, 0.001 * k as f64 * 1.3, 3.0])
        .collect();
    let pred = l.predict_many(&grid);
    let pred_s = t.elapsed().as_secs_f64();
    let ok = pred.iter().filter(|p| p.is_some()).count();
    println!(
        "n {n} span {span}: fit (2000 sigma points) {fit_s:.3} s, 1000 predictions {pred_s:.3} s ({ok} ok), sigma {:.6}, gcv {:.6e}",
        l.sigma, l.gcv
    );
    Ok(())
}
