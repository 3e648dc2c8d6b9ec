//! `skinbrdf capture`: run a capture plan on a trigger controller and write `capture.json`.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use skinbrdf_capture::{load_plan, run_capture, CaptureError, CaptureOptions, SerialConnector};

use crate::print::capture as print;

/// Flags of `skinbrdf capture`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Serial port of the controller (`/dev/ttyACM0`, `COM3`, or the path `skinbrdf sim` prints).
    #[arg(long)]
    port: String,
    /// Capture plan (see `plans/method.toml`).
    #[arg(long)]
    plan: PathBuf,
    /// Session directory; `capture.json` is written there after every shot.
    #[arg(long)]
    out: PathBuf,
    /// Do not prompt between groups (unattended run).
    #[arg(long)]
    yes: bool,
    /// Host watchdog in seconds: the device stops the session after this long without the host.
    #[arg(long, default_value_t = 10.0)]
    watchdog_s: f64,
    /// How long to keep trying to reconnect after the link fails, seconds.
    #[arg(long, default_value_t = 30.0)]
    reconnect_s: f64,
    /// Replace a `capture.json` already in `--out` (without it, the capture refuses to start:
    /// that file may hold the only copy of an interrupted session's exposures).
    #[arg(long)]
    overwrite: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let plan = load_plan(&args.plan)?;
    if !(args.watchdog_s >= 0.0 && args.watchdog_s.is_finite()) {
        anyhow::bail!("--watchdog-s must be a non-negative number of seconds");
    }
    if !(args.reconnect_s >= 0.0 && args.reconnect_s.is_finite()) {
        anyhow::bail!("--reconnect-s must be a non-negative number of seconds");
    }
    let existing = args.out.join("capture.json");
    if existing.exists() && !args.overwrite {
        let what = match skinbrdf_capture::read_capture(&existing) {
            Ok(r) if r.complete => format!("a complete session ({} exposures)", r.exposures.len()),
            Ok(r) => format!(
                "an interrupted session ({} exposures, \"complete\": false)",
                r.exposures.len()
            ),
            Err(_) => "a file that is not a readable capture record".to_string(),
        };
        anyhow::bail!(
            "{} holds {what}; a new capture would overwrite it. Resuming is not supported: \
             move it away, choose another --out, or pass --overwrite to replace it",
            existing.display()
        );
    }
    let abort = Arc::new(AtomicBool::new(false));
    {
        let abort = abort.clone();
        let out = args.out.clone();
        ctrlc::set_handler(move || {
            if print::AT_PROMPT.load(Ordering::SeqCst) || abort.load(Ordering::SeqCst) {
                eprintln!(
                    "\naborted; {} keeps {} exposures",
                    out.join("capture.json").display(),
                    print::SHOTS.load(Ordering::SeqCst)
                );
                std::process::exit(130);
            }
            // Ctrl-C, SIGTERM and SIGHUP alike (ctrlc's `termination` feature): a killed or
            // hung-up capture must still stop the controller.
            eprintln!("\ninterrupted: aborting (the device releases every output) ...");
            abort.store(true, Ordering::SeqCst);
        })
        .context("cannot install the Ctrl-C / SIGTERM handler")?;
    }
    let options = CaptureOptions {
        out_dir: Some(args.out.clone()),
        watchdog_us: Some((args.watchdog_s * 1e6).round() as u64),
        reconnect_window: Duration::from_secs_f64(args.reconnect_s),
        overwrite: args.overwrite,
        abort,
        ..CaptureOptions::default()
    };
    let total: u64 = plan.groups.iter().map(|g| u64::from(g.count)).sum();
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} shots  {elapsed_precise}  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut observer = print::CliObserver::new(bar.clone(), !args.yes, plan.groups.len());
    let connector = SerialConnector {
        path: args.port.clone(),
    };
    let path = args.out.join("capture.json");
    let result = run_capture(connector, &plan, &options, &mut observer);
    bar.finish_and_clear();
    match result {
        Ok(record) => {
            print::summary(&record);
            println!("wrote {}", path.display());
            Ok(())
        }
        Err(e @ (CaptureError::Plan(_) | CaptureError::Client(_)))
            if print::SHOTS.load(Ordering::SeqCst) == 0 =>
        {
            Err(e.into())
        }
        Err(e) => {
            if path.exists() {
                eprintln!("{} keeps every exposure taken", path.display());
            }
            Err(e.into())
        }
    }
}
