//! `skinbrdf fit` without the CLI: fit, smooth, draw and export one input.
//!
//! `cargo run --release -p skinbrdf-fit --example fit_file -- INPUT OUT_DIR [MODEL]`

use std::path::PathBuf;

use skinbrdf_fit::report::{fit_and_report, load_input, ReportOptions};
use skinbrdf_fit::FitConfig;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let input = PathBuf::from(args.next().ok_or("usage: fit_file INPUT OUT_DIR [MODEL]")?);
    let out = PathBuf::from(args.next().ok_or("usage: fit_file INPUT OUT_DIR [MODEL]")?);
    let model = args.next().unwrap_or_else(|| "lafortune2".into()).parse()?;
    let inp = load_input(&input)?;
    let opts = ReportOptions {
        model,
        fit: FitConfig::default(),
        merl: false,
        figures: true,
    };
    let r = fit_and_report(&inp, &out, &opts)?;
    println!("{}", skinbrdf_fit::report::markdown(&r));
    Ok(())
}
