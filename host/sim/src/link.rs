//! Running a [`SimDevice`] against a byte link in (scaled) real time: a pseudo-terminal that
//! any serial client opens by path, or an in-process pipe for tests.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use skinbrdf_protocol::pipe::{Pipe, PipeClosed};

use crate::{SimConfig, SimDevice, SimError, SimStats};

/// Longest wait in the run loop: bounds stop latency and slow-host budget granularity.
const MAX_POLL_WAIT: Duration = Duration::from_millis(5);
/// Bytes taken from the device per loop iteration.
const CHUNK: usize = 8192;

/// The device's side of a byte link.
pub trait DevicePort: Send {
    /// Reads available bytes, waiting at most `timeout` for the first; `Ok(0)` on timeout.
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;
    /// Writes some of `data` without blocking long; `Ok(0)` if the link cannot take any now.
    fn write(&mut self, data: &[u8]) -> io::Result<usize>;
}

// ---------------------------------------------------------------------------------------------
// Pseudo-terminal
// ---------------------------------------------------------------------------------------------

/// The master side of a pseudo-terminal; the host opens the slave by path.
pub struct PtyPort {
    master: serialport::TTYPort,
    /// Held open so the master never sees EIO while no host has the port open.
    _slave: serialport::TTYPort,
    path: String,
}

impl std::fmt::Debug for PtyPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PtyPort").field("path", &self.path).finish()
    }
}

impl PtyPort {
    /// Opens a new pseudo-terminal pair (raw mode).
    pub fn open() -> Result<Self, SimError> {
        let (master, slave) = serialport::TTYPort::pair().map_err(|e| SimError::Pty {
            problem: e.to_string(),
        })?;
        let path = serialport::SerialPort::name(&slave).ok_or_else(|| SimError::Pty {
            problem: "the pseudo-terminal has no name".into(),
        })?;
        Ok(Self {
            master,
            _slave: slave,
            path,
        })
    }

    /// The path a host opens (e.g. `/dev/pts/5`).
    pub fn path(&self) -> &str {
        &self.path
    }
}

fn timeout_to_zero(r: io::Result<usize>) -> io::Result<usize> {
    match r {
        Err(e)
            if matches!(
                e.kind(),
                io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
            ) =>
        {
            Ok(0)
        }
        Err(e) if e.kind() == io::ErrorKind::Interrupted => Ok(0),
        other => other,
    }
}

impl DevicePort for PtyPort {
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        serialport::SerialPort::set_timeout(
            &mut self.master,
            timeout.max(Duration::from_micros(1)),
        )
        .map_err(io::Error::other)?;
        timeout_to_zero(self.master.read(buf))
    }

    fn write(&mut self, data: &[u8]) -> io::Result<usize> {
        serialport::SerialPort::set_timeout(&mut self.master, Duration::from_millis(1))
            .map_err(io::Error::other)?;
        timeout_to_zero(self.master.write(data))
    }
}

// ---------------------------------------------------------------------------------------------
// In-process pipe
// ---------------------------------------------------------------------------------------------

/// A closed in-process link, as the `io` error the run loop and [`HostLink`] report.
fn closed(_: PipeClosed) -> io::Error {
    io::Error::new(io::ErrorKind::BrokenPipe, "simulator link closed")
}

/// The device end of an in-process link.
#[derive(Debug)]
pub struct MemoryDevicePort {
    to_host: Arc<Pipe>,
    to_device: Arc<Pipe>,
}

/// The host end of an in-process link to a running simulator: a byte stream with read
/// timeouts, like a serial port. Dropping it closes the link.
#[derive(Debug)]
pub struct HostLink {
    to_host: Arc<Pipe>,
    to_device: Arc<Pipe>,
    /// Timeout of the `std::io::Read` impl.
    pub read_timeout: Duration,
}

/// Creates a connected (device, host) in-process pair.
pub fn memory_link() -> (MemoryDevicePort, HostLink) {
    let to_host = Arc::new(Pipe::new());
    let to_device = Arc::new(Pipe::new());
    (
        MemoryDevicePort {
            to_host: to_host.clone(),
            to_device: to_device.clone(),
        },
        HostLink {
            to_host,
            to_device,
            read_timeout: Duration::from_millis(100),
        },
    )
}

impl HostLink {
    /// Reads available bytes, waiting at most `timeout` for the first; `Ok(0)` on timeout,
    /// `Err(BrokenPipe)` once the simulator stopped and everything was read.
    pub fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        self.to_host.pop(buf, timeout).map_err(closed)
    }

    /// Sends bytes to the device.
    pub fn send(&mut self, data: &[u8]) -> io::Result<()> {
        self.to_device.push(data).map_err(closed)
    }

    /// Closes both directions.
    pub fn close(&self) {
        self.to_host.close();
        self.to_device.close();
    }
}

impl Drop for HostLink {
    fn drop(&mut self) {
        self.close();
    }
}

impl Read for HostLink {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self.to_host.pop(buf, self.read_timeout).map_err(closed)? {
            0 if !buf.is_empty() => Err(io::Error::new(io::ErrorKind::TimedOut, "no data")),
            n => Ok(n),
        }
    }
}

impl Write for HostLink {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.to_device.push(buf).map_err(closed)?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl DevicePort for MemoryDevicePort {
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        self.to_device.pop(buf, timeout).map_err(closed)
    }

    fn write(&mut self, data: &[u8]) -> io::Result<usize> {
        self.to_host.push(data).map_err(closed)?;
        Ok(data.len())
    }
}

impl Drop for MemoryDevicePort {
    fn drop(&mut self) {
        self.to_host.close();
        self.to_device.close();
    }
}

// ---------------------------------------------------------------------------------------------
// Runner
// ---------------------------------------------------------------------------------------------

/// What a finished run reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimReport {
    /// Simulation counters.
    pub stats: SimStats,
    /// Device time at the end.
    pub device_time_us: u64,
    /// Why it ended.
    pub ended_by: EndReason,
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndReason {
    /// [`SimHandle::stop`] (or Ctrl-C in the CLI).
    Stopped,
    /// The host closed an in-process link.
    HostClosed,
}

/// A simulator running on its own thread.
#[derive(Debug)]
pub struct SimHandle {
    stop: Arc<AtomicBool>,
    device: Arc<Mutex<SimDevice>>,
    thread: Option<JoinHandle<Result<SimReport, SimError>>>,
}

impl SimHandle {
    /// Runs `f` on the device (inspect stats and outputs, inject a link drop, ...).
    pub fn with_device<R>(&self, f: impl FnOnce(&mut SimDevice) -> R) -> Result<R, SimError> {
        let mut dev = self.device.lock().map_err(|_| SimError::Poisoned)?;
        Ok(f(&mut dev))
    }

    /// The stop flag (set it from a Ctrl-C handler).
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// True once the run loop has ended.
    pub fn is_finished(&self) -> bool {
        self.thread.as_ref().is_none_or(|t| t.is_finished())
    }

    /// Stops the run loop and returns its report.
    pub fn stop(mut self) -> Result<SimReport, SimError> {
        self.stop.store(true, Ordering::SeqCst);
        self.join()
    }

    /// Waits for the run loop to end (after the stop flag was set elsewhere).
    pub fn join(&mut self) -> Result<SimReport, SimError> {
        match self.thread.take() {
            Some(t) => t.join().map_err(|_| SimError::Poisoned)?,
            None => Err(SimError::Poisoned),
        }
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Starts a simulator on a new pseudo-terminal; returns the handle and the port path.
pub fn spawn_pty(cfg: SimConfig) -> Result<(SimHandle, String), SimError> {
    let port = PtyPort::open()?;
    let path = port.path().to_string();
    let handle = spawn(cfg, port)?;
    Ok((handle, path))
}

/// Starts a simulator on an in-process link; returns the handle and the host end.
pub fn spawn_in_process(cfg: SimConfig) -> Result<(SimHandle, HostLink), SimError> {
    let (dev_port, host) = memory_link();
    let handle = spawn(cfg, dev_port)?;
    Ok((handle, host))
}

/// Starts a simulator on any [`DevicePort`].
pub fn spawn<P: DevicePort + 'static>(cfg: SimConfig, port: P) -> Result<SimHandle, SimError> {
    let device = Arc::new(Mutex::new(SimDevice::new(cfg)?));
    let stop = Arc::new(AtomicBool::new(false));
    let (d, s) = (device.clone(), stop.clone());
    let thread = std::thread::Builder::new()
        .name("skinbrdf-sim".into())
        .spawn(move || run_loop(&d, port, &s))
        .map_err(|e| SimError::Io {
            what: "spawning the simulator thread",
            source: e,
        })?;
    Ok(SimHandle {
        stop,
        device,
        thread: Some(thread),
    })
}

/// The run loop: device time = start + wall time elapsed × `time_scale`.
fn run_loop<P: DevicePort>(
    device: &Mutex<SimDevice>,
    mut port: P,
    stop: &AtomicBool,
) -> Result<SimReport, SimError> {
    let lock = || device.lock().map_err(|_| SimError::Poisoned);
    let (start_us, scale) = {
        let d = lock()?;
        (d.now_us(), d.config().time_scale)
    };
    let wall0 = Instant::now();
    let sim_now = || start_us + (wall0.elapsed().as_secs_f64() * 1e6 * scale) as u64;
    let mut outbuf: VecDeque<u8> = VecDeque::new();
    let mut inbuf = vec![0u8; 4096];
    let io_err = |what: &'static str| move |source: io::Error| SimError::Io { what, source };
    let ended_by = loop {
        if stop.load(Ordering::SeqCst) {
            break EndReason::Stopped;
        }
        let next_event = {
            let mut d = lock()?;
            d.advance_to(sim_now());
            if outbuf.is_empty() {
                outbuf.extend(d.take_output(CHUNK));
            }
            d.next_event_us()
        };
        if !outbuf.is_empty() {
            let (a, _) = outbuf.as_slices();
            match port.write(a) {
                Ok(n) => {
                    outbuf.drain(..n);
                }
                Err(e) if e.kind() == io::ErrorKind::BrokenPipe => break EndReason::HostClosed,
                Err(e) => return Err(io_err("writing to the host")(e)),
            }
        }
        let wait = if !outbuf.is_empty() {
            Duration::from_millis(1)
        } else {
            match next_event {
                Some(t) => {
                    let dt_us = t.saturating_sub(sim_now()) as f64 / scale;
                    Duration::from_secs_f64(dt_us * 1e-6).min(MAX_POLL_WAIT)
                }
                None => MAX_POLL_WAIT,
            }
        };
        match port.read(&mut inbuf, wait) {
            Ok(0) => {}
            Ok(n) => {
                let mut d = lock()?;
                d.advance_to(sim_now());
                d.receive(&inbuf[..n]);
            }
            Err(e) if e.kind() == io::ErrorKind::BrokenPipe => break EndReason::HostClosed,
            Err(e) => return Err(io_err("reading from the host")(e)),
        }
    };
    let d = lock()?;
    Ok(SimReport {
        stats: d.stats(),
        device_time_us: d.now_us(),
        ended_by,
    })
}
