//! Times [`skinbrdf_raw::decode_superpixel`] per file (for docs/benchmarks.md).
//!
//! ```text
//! cargo run --release -p skinbrdf-raw --example decode_time -- FILE... [--repeat N]
//! ```
//!
//! Prints one JSON line per file: the best and median wall time of N decodes (default 5).

use std::path::PathBuf;
use std::time::Instant;

use skinbrdf_raw::{decode_superpixel, RawOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut files: Vec<PathBuf> = Vec::new();
    let mut repeat = 5usize;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a == "--repeat" {
            repeat = args.next().ok_or("--repeat needs N")?.parse()?;
        } else {
            files.push(a.into());
        }
    }
    for f in files {
        let mut times: Vec<f64> = (0..repeat.max(1))
            .map(|_| {
                let t = Instant::now();
                let frame = decode_superpixel(&f, &RawOptions::default());
                let s = t.elapsed().as_secs_f64();
                frame.map(|fr| (s, fr.width_px))
            })
            .collect::<Result<Vec<_>, _>>()?
            .into_iter()
            .map(|(s, _)| s)
            .collect();
        times.sort_by(f64::total_cmp);
        println!(
            "{{\"file\": \"{}\", \"best_s\": {:.4}, \"median_s\": {:.4}, \"runs\": {}}}",
            f.display(),
            times[0],
            times[times.len() / 2],
            times.len()
        );
    }
    Ok(())
}
