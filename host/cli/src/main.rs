//! `skinbrdf`: measure the BRDF of living human skin.
//!
//! Thin by design (ripgrep's shape): `main` maps the result of [`run`] to an exit code; each
//! subcommand lives in `cmd/`, validates its raw flags into a library config and calls into the
//! library crates, which do the work and return typed errors; what a command prints beyond a
//! line or two is formatted in `print/`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cmd;
mod print;

/// Measure how living human skin reflects light: capture, synthesize, derender, fit, report.
#[derive(Debug, Parser)]
#[command(name = "skinbrdf", version, about)]
struct Cli {
    /// More log output (-v: info, -vv: debug, -vvv: trace).
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the whole system on the built-in default scene and write a report.
    Demo(cmd::demo::Args),
    /// Write a synthetic measurement session with ground truth.
    Synth(cmd::synth::Args),
    /// Turn a camera card, the controller's record, a rig file and a scan into a session.
    Ingest(cmd::ingest::Args),
    /// Start the firmware simulator on a pseudo-terminal and print its port.
    Sim(cmd::sim::Args),
    /// List serial ports, marking skinbrdf trigger controllers.
    Ports(cmd::ports::Args),
    /// Run a timed capture plan on a trigger controller.
    Capture(cmd::capture::Args),
    /// Write printable target sheets and their layout files.
    Targets(cmd::targets::Args),
    /// Survey the target placements nobody measured and register the headdress to the scan.
    Survey(cmd::survey::Args),
    /// Recover camera, head, flash and standard poses from a session's images.
    Poses(cmd::poses::Args),
    /// Turn a session's images into calibrated BRDF samples.
    Derender(cmd::derender::Args),
    /// Smooth and fit BRDF models to samples; write parameters, report and figures.
    Fit(cmd::fit::Args),
    /// Overlay several sessions' BRDFs and test whether they differ.
    Compare(cmd::compare::Args),
    /// Run the planned pipeline (poses, derender, smooth, fit) on a session.
    Process(cmd::process::Args),
    /// Render a head mesh with a Lambertian and the measured BRDF side by side.
    Render(cmd::render::Args),
    /// Sweep accuracy/run-time settings and write the error-against-run-time table.
    Bench(cmd::bench::Args),
    /// The raw decoder's child process (started by `ingest`).
    #[command(name = "internal-decode", hide = true)]
    InternalDecode(cmd::internal_decode::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(cli.verbose);
    quiet_third_party_panics();
    if let Command::InternalDecode(a) = cli.command {
        return cmd::internal_decode::run(a);
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            // `{:#}` joins the error and its causes with ": "; each error either names its cause
            // or exposes it as its source, never both, so no cause is printed twice.
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

/// A panic inside a third-party crate (a decoder reaching `todo!()` on a damaged file) is
/// caught where it is called and becomes one error naming the file; its own text and
/// backtrace go to the log (`-v`), not to the terminal. A panic in skinbrdf's own code is a
/// bug and is printed as usual.
fn quiet_third_party_panics() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let third_party = info.location().is_some_and(|l| {
            let f = l.file();
            f.contains("/registry/src/") || f.contains("/git/checkouts/")
        });
        if third_party {
            let what = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_default();
            let at = info
                .location()
                .map(|l| format!("{}:{}", l.file(), l.line()))
                .unwrap_or_default();
            tracing::info!("a library panicked (caught; its error follows): {what} at {at}");
        } else {
            default(info);
        }
    }));
}

fn init_logging(verbose: u8) {
    let level = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    // Colour codes only on a terminal: a log redirected to a file stays plain text.
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(ansi)
        .try_init();
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Demo(a) => cmd::demo::run(a),
        Command::Synth(a) => cmd::synth::run(a),
        Command::Ingest(a) => cmd::ingest::run(a),
        Command::Sim(a) => cmd::sim::run(a),
        Command::Ports(a) => cmd::ports::run(a),
        Command::Capture(a) => cmd::capture::run(a),
        Command::Targets(a) => cmd::targets::run(a),
        Command::Survey(a) => cmd::survey::run(a),
        Command::Poses(a) => cmd::poses::run(a),
        Command::Derender(a) => cmd::derender::run(a),
        Command::Fit(a) => cmd::fit::run(a),
        Command::Compare(a) => cmd::compare::run(a),
        Command::Process(a) => cmd::process::run(a),
        Command::Bench(a) => cmd::bench::run(a),
        Command::Render(a) => cmd::render::run(a),
        Command::InternalDecode(a) => {
            let _ = cmd::internal_decode::run(a);
            Ok(())
        }
    }
}
