//! `skinbrdf sim`: run the firmware simulator on a pseudo-terminal.
//!
//! Prints `PORT <path>` on its own line (stdout, flushed) as soon as the port exists, so a
//! script or a second terminal can run `skinbrdf capture --port <path>`; then runs until
//! Ctrl-C (or `--for-s`) and prints what the simulated hardware did.

use std::io::Write;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::Context;
use skinbrdf_sim::{spawn_pty, CameraModel, Faults, FlashModel, LinkDrop, SimConfig};

/// Flags of `skinbrdf sim`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Simulated seconds per real second (1 = real time; 20 runs a 2-minute session in 6 s).
    #[arg(long, default_value_t = 1.0)]
    time_scale: f64,
    /// Random seed of the camera/flash models and fault injection.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Flash power in [0, 1]; recycle time grows from 0.5 s (0) to 3 s (1).
    #[arg(long, default_value_t = 0.5)]
    flash_power: f64,
    /// Shortest camera shutter lag, milliseconds.
    #[arg(long, default_value_t = 60.0)]
    shutter_lag_min_ms: f64,
    /// Longest camera shutter lag, milliseconds.
    #[arg(long, default_value_t = 120.0)]
    shutter_lag_max_ms: f64,
    /// Device clock at start, microseconds (e.g. 4294000000 to cross the u32 wrap soon).
    #[arg(long, default_value_t = 1_000_000)]
    start_us: u64,
    /// Serial string reported in the handshake.
    #[arg(long, default_value = "SIM-0001")]
    serial: String,
    /// Stop after this many real seconds (default: run until Ctrl-C).
    #[arg(long)]
    for_s: Option<f64>,

    /// Fault: the flash never reports ready.
    #[arg(long)]
    flash_never_ready: bool,
    /// Fault: the camera never fires (no X-sync).
    #[arg(long)]
    camera_not_firing: bool,
    /// Fault: probability that a shutter press does not fire the camera.
    #[arg(long, default_value_t = 0.0)]
    camera_fail_prob: f64,
    /// Fault: probability that the flash misfires.
    #[arg(long, default_value_t = 0.0)]
    misfire_prob: f64,
    /// Fault: drop the link once this many records exist ...
    #[arg(long)]
    drop_link_after: Option<u32>,
    /// ... for this many simulated seconds.
    #[arg(long, default_value_t = 3.0)]
    drop_link_s: f64,
    /// Fault: probability that a device-to-host frame has a byte flipped.
    #[arg(long, default_value_t = 0.0)]
    corrupt_prob: f64,
    /// Fault: probability that a device-to-host frame is cut short.
    #[arg(long, default_value_t = 0.0)]
    truncate_prob: f64,
    /// Fault: probability that a chunk of host-to-device bytes has a byte flipped.
    #[arg(long, default_value_t = 0.0)]
    corrupt_to_device_prob: f64,
    /// Fault: slow host, the link drains at most this many bytes per simulated second.
    #[arg(long)]
    slow_host_bps: Option<u64>,
}

fn ms_to_us(field: &str, ms: f64) -> anyhow::Result<u64> {
    if !(ms.is_finite() && ms >= 0.0) {
        anyhow::bail!("--{field} must be a non-negative number of milliseconds, got {ms}");
    }
    Ok((ms * 1e3).round() as u64)
}

fn s_to_us(field: &str, s: f64) -> anyhow::Result<u64> {
    if !(s.is_finite() && s >= 0.0) {
        anyhow::bail!("--{field} must be a non-negative number of seconds, got {s}");
    }
    Ok((s * 1e6).round() as u64)
}

impl Args {
    fn config(&self) -> anyhow::Result<SimConfig> {
        let link_drop = match self.drop_link_after {
            Some(after_records) => Some(LinkDrop {
                after_records,
                duration_us: s_to_us("drop-link-s", self.drop_link_s)?,
            }),
            None => None,
        };
        let cfg = SimConfig {
            camera: CameraModel {
                shutter_lag_min_us: ms_to_us("shutter-lag-min-ms", self.shutter_lag_min_ms)?,
                shutter_lag_max_us: ms_to_us("shutter-lag-max-ms", self.shutter_lag_max_ms)?,
            },
            flash: FlashModel {
                power: self.flash_power,
                ..FlashModel::STUDIO_HALF_POWER
            },
            faults: Faults {
                flash_never_ready: self.flash_never_ready,
                camera_not_firing: self.camera_not_firing,
                camera_fail_probability: self.camera_fail_prob,
                misfire_probability: self.misfire_prob,
                link_drop,
                corrupt_to_host_probability: self.corrupt_prob,
                truncate_to_host_probability: self.truncate_prob,
                corrupt_to_device_probability: self.corrupt_to_device_prob,
                host_bytes_per_s: self.slow_host_bps,
            },
            start_us: self.start_us,
            time_scale: self.time_scale,
            seed: self.seed,
            serial: self.serial.clone(),
            ..SimConfig::default()
        };
        cfg.validate()?;
        Ok(cfg)
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let cfg = args.config()?;
    let limit = match args.for_s {
        Some(s) if s.is_finite() && s >= 0.0 => Some(Duration::from_secs_f64(s)),
        Some(s) => anyhow::bail!("--for-s must be a non-negative number of seconds, got {s}"),
        None => None,
    };
    let (sim, path) = spawn_pty(cfg.clone()).context("starting the simulator")?;
    let stop = sim.stop_flag();
    ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
        .context("installing the Ctrl-C handler")?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "PORT {path}")?;
        out.flush()?;
    }
    eprintln!(
        "simulator: {} (flash power {:.2}, recycle {:.2} s, shutter lag {}-{} ms, {}x real time); \
         Ctrl-C stops",
        cfg.serial,
        cfg.flash.power,
        cfg.flash.nominal_recycle_us() as f64 * 1e-6,
        cfg.camera.shutter_lag_min_us / 1000,
        cfg.camera.shutter_lag_max_us / 1000,
        cfg.time_scale
    );
    let t0 = Instant::now();
    let stop = sim.stop_flag();
    while !stop.load(Ordering::SeqCst) && !sim.is_finished() {
        if limit.is_some_and(|l| t0.elapsed() >= l) {
            stop.store(true, Ordering::SeqCst);
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let report = sim.stop().context("simulator run")?;
    let s = report.stats;
    eprintln!(
        "simulator stopped at device time {:.3} s: {} requests, {} shutter presses, {} X-syncs, \
         {} flashes ({} misfires, {} triggers while recycling), {} frames sent \
         ({} corrupted, {} truncated), {} bad frames received, {} link drops",
        report.device_time_us as f64 * 1e-6,
        s.requests,
        s.shutter_presses,
        s.xsync_edges,
        s.flashes,
        s.misfires,
        s.triggers_while_recycling,
        s.frames_to_host,
        s.corrupted_to_host,
        s.truncated_to_host,
        s.bad_frames,
        s.link_drops
    );
    Ok(())
}
