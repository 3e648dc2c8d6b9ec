//! Third-party decoding in a child process, so that a file can fail only itself.
//!
//! A panic inside the raw decoder is caught ([`crate::decode`]), but an allocation failure
//! aborts the process and an endless loop hangs it; neither can be caught in-process. With an
//! [`Isolation`], [`read_metadata_with`] and [`decoded_size_with`] run the decoder in a child
//! process (the same program, started with a hidden subcommand that calls [`worker_main`]),
//! under an address-space limit ([`Isolation::max_memory_bytes`], `RLIMIT_AS`) and a time limit
//! ([`Isolation::timeout`]); the result comes back as JSON on its standard output. A child that
//! is killed, aborts or runs out of time becomes [`RawError::Decode`] naming the file, and the
//! run goes on. Without an isolation (a library caller, a test), they call the decoder
//! in-process.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::{decode_superpixel, read_metadata, ExposureMeta, RawError, RawOptions};

/// How a child decoder is run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Isolation {
    /// The program to start (the `skinbrdf` binary itself).
    pub program: PathBuf,
    /// The arguments before the operation (the hidden subcommand, e.g. `internal-decode`).
    pub args: Vec<String>,
    /// The child's address-space limit, bytes.
    pub max_memory_bytes: u64,
    /// The longest one file may take.
    pub timeout: Duration,
}

/// The default address-space limit of a child decoder: room for the largest camera's raw image
/// decoded (a 100-megapixel sensor as 16-bit photosites and float superpixels is well under a
/// gigabyte) with the program's own mappings.
pub const DEFAULT_MAX_MEMORY_BYTES: u64 = 3 << 30;
/// The default time limit per file (a large raw decodes in about a second).
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(60);

impl Isolation {
    /// Children of `program args...` with the default limits.
    pub fn new(program: PathBuf, args: Vec<String>) -> Self {
        Self {
            program,
            args,
            max_memory_bytes: DEFAULT_MAX_MEMORY_BYTES,
            timeout: DEFAULT_TIMEOUT,
        }
    }
}

/// What a child decoder does with a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WorkerOp {
    /// [`read_metadata`].
    Metadata,
    /// [`decode_superpixel`]'s image size.
    Size,
}

impl WorkerOp {
    /// Its name on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Metadata => "metadata",
            Self::Size => "size",
        }
    }

    /// The operation a command-line name stands for.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "metadata" => Some(Self::Metadata),
            "size" => Some(Self::Size),
            _ => None,
        }
    }
}

/// [`read_metadata`], in a child process when `iso` is given.
pub fn read_metadata_with(iso: Option<&Isolation>, path: &Path) -> Result<ExposureMeta, RawError> {
    match iso {
        None => read_metadata(path),
        Some(iso) => {
            let out = run_child(iso, WorkerOp::Metadata, path)?;
            serde_json::from_str(&out).map_err(|e| child_failed(path, format!("its answer: {e}")))
        }
    }
}

/// The size of a raw file as loaded (superpixels), decoding it, in a child process when `iso`
/// is given.
pub fn decoded_size_with(iso: Option<&Isolation>, path: &Path) -> Result<(u32, u32), RawError> {
    match iso {
        None => {
            let f = decode_superpixel(path, &RawOptions::default())?;
            Ok((f.width_px, f.height_px))
        }
        Some(iso) => {
            let out = run_child(iso, WorkerOp::Size, path)?;
            serde_json::from_str(&out).map_err(|e| child_failed(path, format!("its answer: {e}")))
        }
    }
}

fn child_failed(path: &Path, reason: String) -> RawError {
    RawError::Decode {
        path: path.to_path_buf(),
        reason: format!("the decoder's child process failed: {reason}"),
    }
}

/// The last line of a child's error output that says something.
fn last_line(text: &str) -> Option<&str> {
    text.lines().rev().map(str::trim).find(|l| !l.is_empty())
}

/// Runs one operation in a child and returns its standard output.
fn run_child(iso: &Isolation, op: WorkerOp, path: &Path) -> Result<String, RawError> {
    let mut child = Command::new(&iso.program)
        .args(&iso.args)
        .arg(op.name())
        .arg(iso.max_memory_bytes.to_string())
        .arg(path)
        // One decoding thread and few malloc arenas: the address-space limit counts their
        // reservations.
        .env("RAYON_NUM_THREADS", "1")
        .env("MALLOC_ARENA_MAX", "2")
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| child_failed(path, format!("cannot start {}: {e}", iso.program.display())))?;
    // Drain both pipes on their own threads so a chatty child never blocks on a full pipe.
    let drain = |r: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut s = Vec::new();
            if let Some(mut r) = r {
                let _ = r.read_to_end(&mut s);
            }
            String::from_utf8_lossy(&s).into_owned()
        })
    };
    let stdout = drain(
        child
            .stdout
            .take()
            .map(|r| Box::new(r) as Box<dyn Read + Send>),
    );
    let stderr = drain(
        child
            .stderr
            .take()
            .map(|r| Box::new(r) as Box<dyn Read + Send>),
    );
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(s)) => break Some(s),
            Ok(None) if start.elapsed() > iso.timeout => {
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(5)),
            Err(e) => return Err(child_failed(path, e.to_string())),
        }
    };
    let Some(status) = status else {
        // The pipes' readers are left to finish on their own: a grandchild may hold them open.
        return Err(RawError::Decode {
            path: path.to_path_buf(),
            reason: format!(
                "the decoder took longer than {:.1} s and was stopped",
                iso.timeout.as_secs_f64()
            ),
        });
    };
    let out = stdout.join().unwrap_or_default();
    let err = stderr.join().unwrap_or_default();
    if status.success() {
        return Ok(out);
    }
    let said = last_line(&err).unwrap_or("no message");
    let reason = match status.code() {
        // The child's own error: one line naming the file.
        Some(WORKER_REFUSED) => {
            return Err(RawError::Decode {
                path: path.to_path_buf(),
                reason: said
                    .strip_prefix(&format!("{}: ", path.display()))
                    .unwrap_or(said)
                    .to_string(),
            })
        }
        Some(code) => format!("it exited with status {code} ({said})"),
        None => format!(
            "it was stopped by a signal, within a {} MiB memory limit ({said})",
            iso.max_memory_bytes >> 20
        ),
    };
    Err(child_failed(path, reason))
}

/// A child's exit status when the decoder refused the file (its error is on standard error).
pub const WORKER_REFUSED: i32 = 3;

/// The child's side: limits its own address space, runs `op` on `path` and prints the result as
/// JSON (exit 0), or the error in one line (exit [`WORKER_REFUSED`]). Returns the exit status.
pub fn worker_main(op: WorkerOp, max_memory_bytes: u64, path: &Path) -> i32 {
    if let Err(e) = limit_address_space(max_memory_bytes) {
        eprintln!("{}: cannot limit the decoder's memory: {e}", path.display());
        return WORKER_REFUSED;
    }
    let result = match op {
        WorkerOp::Metadata => read_metadata(path).and_then(|m| {
            serde_json::to_string(&m).map_err(|e| RawError::Decode {
                path: path.to_path_buf(),
                reason: e.to_string(),
            })
        }),
        WorkerOp::Size => decoded_size_with(None, path).and_then(|s| {
            serde_json::to_string(&s).map_err(|e| RawError::Decode {
                path: path.to_path_buf(),
                reason: e.to_string(),
            })
        }),
    };
    match result {
        Ok(json) => {
            println!("{json}");
            0
        }
        Err(e) => {
            eprintln!("{}", skinbrdf_core::error_text(&e));
            WORKER_REFUSED
        }
    }
}

#[cfg(target_os = "linux")]
fn limit_address_space(max_bytes: u64) -> std::io::Result<()> {
    use rustix::process::{setrlimit, Resource, Rlimit};
    setrlimit(
        Resource::As,
        Rlimit {
            current: Some(max_bytes),
            maximum: Some(max_bytes),
        },
    )
    .map_err(std::io::Error::from)
}

#[cfg(not(target_os = "linux"))]
fn limit_address_space(_max_bytes: u64) -> std::io::Result<()> {
    Ok(())
}
