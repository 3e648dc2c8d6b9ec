//! `skinbrdf compare`: overlay several sessions' smoothed incidence-plane curves and say which
//! pairs differ beyond their confidence bands.

use std::path::PathBuf;

use skinbrdf_fit::report::{compare, load_input};

/// Flags of `skinbrdf compare`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Two or more inputs (sample files, Cornell .brdf files or session directories).
    #[arg(required = true, num_args = 2..)]
    pub inputs: Vec<PathBuf>,
    /// Incident angle of the compared incidence-plane curves, degrees.
    #[arg(long, default_value_t = 30.0)]
    pub theta_i_deg: f64,
    /// Output directory.
    #[arg(long, default_value = "compare-out")]
    pub out: PathBuf,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !(0.0..90.0).contains(&args.theta_i_deg) {
        anyhow::bail!("--theta-i-deg must be in [0, 90), got {}", args.theta_i_deg);
    }
    let inputs = args
        .inputs
        .iter()
        .map(|p| load_input(p))
        .collect::<Result<Vec<_>, _>>()?;
    let report = compare(&inputs, args.theta_i_deg, &args.out)?;
    if args.json {
        super::print_json(&report)?;
        return Ok(());
    }
    for d in &report.differences {
        println!(
            "{} vs {}: {} (max |z| {:.2} vs threshold {:.2}; bands disjoint at {:.0}% of angles)",
            d.a,
            d.b,
            if d.differ {
                "DIFFER beyond their 95% bands"
            } else {
                "no difference beyond the bands"
            },
            d.max_z,
            d.z_threshold,
            100.0 * d.fraction_disjoint
        );
    }
    println!("wrote {}", args.out.display());
    Ok(())
}
