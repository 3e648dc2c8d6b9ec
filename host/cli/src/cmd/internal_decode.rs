//! `skinbrdf internal-decode OP MAX_MEMORY_BYTES FILE` (hidden): the child process in which
//! `ingest` runs the raw decoder on one file, under an address-space limit (see
//! `skinbrdf_raw::Isolation`). Not for people: its output is JSON for the parent.

use std::path::PathBuf;

/// The hidden subcommand's arguments.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// `metadata` or `size`.
    op: String,
    /// The address-space limit, bytes.
    max_memory_bytes: u64,
    /// The file.
    file: PathBuf,
}

/// The subcommand's name, as `ingest` starts it.
pub const NAME: &str = "internal-decode";

/// How `ingest` runs its decoder: this program, started with [`NAME`].
pub fn isolation() -> Option<skinbrdf_raw::Isolation> {
    let exe = std::env::current_exe().ok()?;
    Some(skinbrdf_raw::Isolation::new(exe, vec![NAME.to_string()]))
}

/// Runs the operation; returns the process's exit status.
pub fn run(args: Args) -> std::process::ExitCode {
    let Some(op) = skinbrdf_raw::WorkerOp::parse(&args.op) else {
        eprintln!("unknown operation `{}` (metadata or size)", args.op);
        return std::process::ExitCode::from(2);
    };
    let code = skinbrdf_raw::worker_main(op, args.max_memory_bytes, &args.file);
    std::process::ExitCode::from(u8::try_from(code).unwrap_or(1))
}
