//! `skinbrdf capture`: run a capture plan on a trigger controller and write `capture.json`.

use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use skinbrdf_capture::protocol::{ExposureRecord, Fault, LogLevel};
use skinbrdf_capture::session::fault_text;
use skinbrdf_capture::{
    load_plan, run_capture, CaptureError, CaptureObserver, CaptureOptions, ClientError,
    GroupDecision, RunSummary, SerialConnector,
};
use skinbrdf_session::capture::{CaptureRecord, Exposure, ShotGroup, ShotOutcome};

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

/// True while the operator prompt waits on stdin (Ctrl-C then exits at once: nothing runs).
static AT_PROMPT: AtomicBool = AtomicBool::new(false);
/// Exposures written so far (for the Ctrl-C message at the prompt).
static SHOTS: AtomicUsize = AtomicUsize::new(0);

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
            if AT_PROMPT.load(Ordering::SeqCst) || abort.load(Ordering::SeqCst) {
                eprintln!(
                    "\naborted; {} keeps {} exposures",
                    out.join("capture.json").display(),
                    SHOTS.load(Ordering::SeqCst)
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
    let mut observer = CliObserver {
        bar: bar.clone(),
        prompt: !args.yes,
        groups: plan.groups.len(),
    };
    let connector = SerialConnector {
        path: args.port.clone(),
    };
    let path = args.out.join("capture.json");
    let result = run_capture(connector, &plan, &options, &mut observer);
    bar.finish_and_clear();
    match result {
        Ok(record) => {
            summary(&record);
            println!("wrote {}", path.display());
            Ok(())
        }
        Err(e @ (CaptureError::Plan(_) | CaptureError::Client(_)))
            if SHOTS.load(Ordering::SeqCst) == 0 =>
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

fn summary(record: &CaptureRecord) {
    let faults = record
        .exposures
        .iter()
        .filter(|e| e.outcome != ShotOutcome::Ok)
        .count();
    println!(
        "{} exposures ({} faulted) from {} {} (firmware {}, serial {})",
        record.exposures.len(),
        faults,
        record.device.kind,
        if record.complete {
            "complete"
        } else {
            "incomplete"
        },
        record.device.firmware_version,
        record.device.serial
    );
    println!(
        "clock model: drift {:+.2} ppm, residual {:.1} us RMS over {} round-trip reads",
        record.clock.drift_ppm, record.clock.residual_rms_us, record.clock.samples
    );
}

struct CliObserver {
    bar: ProgressBar,
    prompt: bool,
    groups: usize,
}

impl CliObserver {
    /// A line above the bar (plain stdout when the bar is hidden, e.g. output to a file).
    fn line(&self, text: String) {
        if self.bar.is_hidden() {
            println!("{text}");
        } else {
            self.bar.println(text);
        }
    }
}

fn ms(us: u64) -> f64 {
    us as f64 / 1000.0
}

impl CaptureObserver for CliObserver {
    fn connected(&mut self, record: &CaptureRecord) {
        self.line(format!(
            "connected: {} (firmware {}, serial {}, protocol {})",
            record.device.kind,
            record.device.firmware_version,
            record.device.serial,
            record.device.protocol_version
        ));
    }

    fn before_group(&mut self, index: usize, group: &ShotGroup, shots: usize) -> GroupDecision {
        let line = format!(
            "group {}/{}: `{}`, {} shot{} ({})",
            index + 1,
            self.groups,
            group.label,
            group.count,
            if group.count == 1 { "" } else { "s" },
            group.role.name()
        );
        if !self.prompt {
            self.line(line);
            return GroupDecision::Continue;
        }
        self.bar.suspend(|| {
            print!("{line}: set up, then press Enter to shoot (q + Enter aborts; {shots} taken) ");
            if !std::io::IsTerminal::is_terminal(&std::io::stdin()) {
                println!();
            }
            let _ = std::io::stdout().flush();
            AT_PROMPT.store(true, Ordering::SeqCst);
            let mut answer = String::new();
            let read = std::io::stdin().lock().read_line(&mut answer);
            AT_PROMPT.store(false, Ordering::SeqCst);
            match read {
                Ok(0) | Err(_) => GroupDecision::Abort,
                Ok(_) if answer.trim().eq_ignore_ascii_case("q") => GroupDecision::Abort,
                Ok(_) => GroupDecision::Continue,
            }
        })
    }

    fn exposure(&mut self, e: &Exposure, r: &ExposureRecord) {
        SHOTS.store(e.index as usize + 1, Ordering::SeqCst);
        let lag = match (r.shutter_command_us, r.xsync_us) {
            (Some(s), Some(x)) => format!("lag {:7.2} ms", ms(x.saturating_sub(s))),
            _ => "lag       -   ".into(),
        };
        let flash = match (r.xsync_us, r.flash_fired_us) {
            (Some(x), Some(f)) => format!("flash +{:6.3} ms", ms(f.saturating_sub(x))),
            _ => "flash       -   ".into(),
        };
        let recycle = r.recycle_us.map_or_else(
            || "recycle    -  ".into(),
            |u| format!("recycle {:5.2} s", u as f64 / 1e6),
        );
        let outcome = match e.outcome {
            ShotOutcome::Ok => "ok".to_string(),
            other => format!("FAULT {}", other.describe()),
        };
        self.line(format!(
            "#{:<3} g{} shot {:<2} try {}  {lag}  {flash}  {recycle}  {outcome}",
            e.index, r.group, r.shot, r.attempt
        ));
        if e.outcome == ShotOutcome::Ok || r.attempt == 0 {
            // Count planned shots, not retries.
            if e.outcome == ShotOutcome::Ok {
                self.bar.inc(1);
            }
        }
    }

    fn fault(&mut self, fault: &Fault) {
        self.line(format!(
            "  fault: {}{}",
            fault_text(fault.kind),
            fault
                .index
                .map_or_else(String::new, |i| format!(" (record {i})"))
        ));
    }

    fn flash_ready(&mut self, ready: bool, _recycle_us: Option<u64>) {
        self.bar.set_message(if ready {
            "flash ready"
        } else {
            "flash recycling"
        });
    }

    fn log(&mut self, level: LogLevel, text: &str) {
        match level {
            LogLevel::Warn => self.line(format!("  warning: {text}")),
            LogLevel::Error => self.line(format!("  error: {text}")),
            LogLevel::Info => tracing::info!("device: {text}"),
            LogLevel::Debug => tracing::debug!("device: {text}"),
        }
    }

    fn link_lost(&mut self, error: &ClientError) {
        self.line(format!("  link lost ({error}); reconnecting ..."));
    }

    fn finished(&mut self, s: &RunSummary) {
        self.line(format!(
            "run: {} exposures in {:.1} s; link: {} requests, {} reconnects, {} records refetched, \
             {} duplicates dropped, {} bad frames",
            s.exposures, s.elapsed_s, s.requests, s.reconnects, s.fetched, s.duplicates, s.bad_frames
        ));
    }

    fn reconnected(&mut self, fetched: u32) {
        self.line(format!(
            "  reconnected; recovered {fetched} record{} taken meanwhile",
            if fetched == 1 { "" } else { "s" }
        ));
    }
}
