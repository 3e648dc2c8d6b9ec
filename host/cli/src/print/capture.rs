//! `skinbrdf capture`: the run's live output (one line per event above the progress bar, the
//! operator's prompt between groups) and the summary of the record written.

use std::io::{BufRead, Write};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use indicatif::ProgressBar;
use skinbrdf_capture::protocol::{ExposureRecord, Fault, LogLevel};
use skinbrdf_capture::session::fault_text;
use skinbrdf_capture::{CaptureObserver, ClientError, GroupDecision, RunSummary};
use skinbrdf_session::capture::{CaptureRecord, Exposure, ShotGroup, ShotOutcome};

/// True while the operator prompt waits on stdin (Ctrl-C then exits at once: nothing runs).
pub(crate) static AT_PROMPT: AtomicBool = AtomicBool::new(false);
/// Exposures written so far (for the Ctrl-C message at the prompt).
pub(crate) static SHOTS: AtomicUsize = AtomicUsize::new(0);

/// The record's summary: exposures, faults, device and clock model.
pub fn summary(record: &CaptureRecord) {
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

/// Draws the capture's events above the progress bar and asks the operator before each group.
pub struct CliObserver {
    bar: ProgressBar,
    prompt: bool,
    groups: usize,
}

impl CliObserver {
    /// An observer drawing on `bar`, prompting the operator before each of the `groups` groups
    /// when `prompt`.
    pub fn new(bar: ProgressBar, prompt: bool, groups: usize) -> Self {
        Self {
            bar,
            prompt,
            groups,
        }
    }

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
