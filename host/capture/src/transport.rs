//! Byte transports to the trigger controller: a real serial port (USB CDC-ACM or a simulator's
//! pseudo-terminal) and an in-memory pair for tests.
//!
//! A [`Transport`] moves raw bytes with bounded waits; framing and the protocol live above it.
//! `read` returning `Ok(0)` means "nothing arrived within the timeout", never end of stream: a
//! closed link is [`TransportError::Disconnected`], so the client can tell a silent device from a
//! lost one and reconnect.

use std::io::{Read, Write};
use std::sync::Arc;
use std::time::Duration;

use skinbrdf_protocol::pipe::Pipe;

/// Baud rate requested when opening a serial port. USB CDC-ACM ignores it; a UART bridge to the
/// RP2040 runs at this rate.
pub const DEFAULT_BAUD: u32 = 115_200;

/// Longest a single write may block before the link is declared stuck.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// Why a transport operation failed.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The port path does not exist.
    #[error("no such port: {path} (run `skinbrdf ports` to list serial ports)")]
    NoSuchPort {
        /// The path given.
        path: String,
    },
    /// The port exists but the user may not open it.
    #[error("permission denied opening {path} (on Linux, add yourself to the `dialout` group)")]
    PermissionDenied {
        /// The path given.
        path: String,
    },
    /// Another program holds the port.
    #[error("{path} is busy: another program has it open")]
    Busy {
        /// The path given.
        path: String,
    },
    /// The path exists but is not a serial device.
    #[error("{path} is not a serial port: {message}")]
    NotASerialPort {
        /// The path given.
        path: String,
        /// The OS's message.
        message: String,
    },
    /// Any other failure to open.
    #[error("cannot open {path}: {message}")]
    Open {
        /// The path given.
        path: String,
        /// The OS's message.
        message: String,
    },
    /// The other end went away (USB unplugged, simulator stopped, link dropped).
    #[error("{port}: the device disconnected")]
    Disconnected {
        /// Which link.
        port: String,
    },
    /// A write did not complete within [`WRITE_TIMEOUT`].
    #[error("{port}: write timed out (the device is not reading)")]
    WriteTimeout {
        /// Which link.
        port: String,
    },
    /// Any other I/O error on an open link.
    #[error("{port}")]
    Io {
        /// Which link.
        port: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
}

/// A bidirectional byte link with bounded waits.
pub trait Transport: Send {
    /// Reads whatever is available into `buf`, waiting at most `timeout` for the first byte.
    /// Returns `Ok(0)` if nothing arrived in time.
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError>;
    /// Writes all of `data`.
    fn write_all(&mut self, data: &[u8]) -> Result<(), TransportError>;
    /// A name for messages (the port path, or `memory`).
    fn name(&self) -> String;
}

impl<T: Transport + ?Sized> Transport for Box<T> {
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        (**self).read(buf, timeout)
    }
    fn write_all(&mut self, data: &[u8]) -> Result<(), TransportError> {
        (**self).write_all(data)
    }
    fn name(&self) -> String {
        (**self).name()
    }
}

/// A serial port (a USB CDC-ACM device, a UART adapter or a pseudo-terminal).
pub struct SerialTransport {
    port: Box<dyn serialport::SerialPort>,
    path: String,
    timeout: Duration,
}

impl std::fmt::Debug for SerialTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialTransport")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl SerialTransport {
    /// Opens `path` at [`DEFAULT_BAUD`], 8N1, no flow control.
    pub fn open(path: &str) -> Result<Self, TransportError> {
        if !std::path::Path::new(path).exists() && cfg!(unix) {
            return Err(TransportError::NoSuchPort { path: path.into() });
        }
        let port = serialport::new(path, DEFAULT_BAUD)
            .timeout(WRITE_TIMEOUT)
            .open()
            .map_err(|e| open_error(path, e))?;
        Ok(Self {
            port,
            path: path.to_string(),
            timeout: WRITE_TIMEOUT,
        })
    }

    /// Wraps an already open port (e.g. one end of a `TTYPort::pair()`).
    pub fn from_port(port: Box<dyn serialport::SerialPort>, name: &str) -> Self {
        Self {
            port,
            path: name.to_string(),
            timeout: WRITE_TIMEOUT,
        }
    }

    fn set_timeout(&mut self, timeout: Duration) -> Result<(), TransportError> {
        if self.timeout != timeout {
            self.port
                .set_timeout(timeout)
                .map_err(|e| io_error(&self.path, e.into()))?;
            self.timeout = timeout;
        }
        Ok(())
    }
}

fn open_error(path: &str, e: serialport::Error) -> TransportError {
    use serialport::ErrorKind as K;
    let path = path.to_string();
    match e.kind() {
        K::NoDevice => TransportError::Busy { path },
        K::Io(std::io::ErrorKind::NotFound) => TransportError::NoSuchPort { path },
        K::Io(std::io::ErrorKind::PermissionDenied) => TransportError::PermissionDenied { path },
        K::InvalidInput | K::Unknown => TransportError::NotASerialPort {
            path,
            message: e.description,
        },
        K::Io(_) => TransportError::Open {
            path,
            message: e.description,
        },
    }
}

fn io_error(port: &str, source: std::io::Error) -> TransportError {
    use std::io::ErrorKind as K;
    match source.kind() {
        K::BrokenPipe
        | K::UnexpectedEof
        | K::ConnectionReset
        | K::ConnectionAborted
        | K::NotConnected => TransportError::Disconnected { port: port.into() },
        // EIO on a tty whose other end closed, ENXIO on an unplugged USB device.
        _ if matches!(source.raw_os_error(), Some(5) | Some(6) | Some(19)) => {
            TransportError::Disconnected { port: port.into() }
        }
        // serialport maps poll's POLLERR to a bare "Input/output error" without an errno.
        K::Other if source.to_string().contains("I/O error") => {
            TransportError::Disconnected { port: port.into() }
        }
        _ => TransportError::Io {
            port: port.into(),
            source,
        },
    }
}

impl Transport for SerialTransport {
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        // serialport treats a zero timeout as "return at once"; keep at least 1 ms so a zero
        // request polls without spinning the caller.
        self.set_timeout(timeout.max(Duration::from_millis(1)))?;
        match self.port.read(buf) {
            Ok(0) => Err(TransportError::Disconnected {
                port: self.path.clone(),
            }),
            Ok(n) => Ok(n),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(0),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => Ok(0),
            Err(e) => Err(io_error(&self.path, e)),
        }
    }

    fn write_all(&mut self, data: &[u8]) -> Result<(), TransportError> {
        self.set_timeout(WRITE_TIMEOUT)?;
        match self.port.write_all(data) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                Err(TransportError::WriteTimeout {
                    port: self.path.clone(),
                })
            }
            Err(e) => Err(io_error(&self.path, e)),
        }
    }

    fn name(&self) -> String {
        self.path.clone()
    }
}

/// One end of an in-memory duplex link. Dropping or [`close`](Self::close)-ing either end makes
/// the other end's reads and writes fail with [`TransportError::Disconnected`] (after it has
/// read what was already sent).
#[derive(Debug)]
pub struct MemoryTransport {
    rx: Arc<Pipe>,
    tx: Arc<Pipe>,
    name: String,
}

/// Creates two connected in-memory endpoints.
pub fn memory_pair() -> (MemoryTransport, MemoryTransport) {
    let a_to_b = Arc::new(Pipe::new());
    let b_to_a = Arc::new(Pipe::new());
    (
        MemoryTransport {
            rx: b_to_a.clone(),
            tx: a_to_b.clone(),
            name: "memory:a".into(),
        },
        MemoryTransport {
            rx: a_to_b,
            tx: b_to_a,
            name: "memory:b".into(),
        },
    )
}

impl MemoryTransport {
    /// Closes both directions, as if the cable were pulled.
    pub fn close(&self) {
        self.rx.close();
        self.tx.close();
    }

    fn disconnected(&self) -> TransportError {
        TransportError::Disconnected {
            port: self.name.clone(),
        }
    }
}

impl Drop for MemoryTransport {
    fn drop(&mut self) {
        self.close();
    }
}

impl Transport for MemoryTransport {
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        self.rx.pop(buf, timeout).map_err(|_| self.disconnected())
    }

    fn write_all(&mut self, data: &[u8]) -> Result<(), TransportError> {
        self.tx.push(data).map_err(|_| self.disconnected())
    }

    fn name(&self) -> String {
        self.name.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_pair_moves_bytes_both_ways() {
        let (mut a, mut b) = memory_pair();
        a.write_all(b"hello").expect("write");
        let mut buf = [0u8; 16];
        let n = b.read(&mut buf, Duration::from_millis(100)).expect("read");
        assert_eq!(&buf[..n], b"hello");
        b.write_all(&[1, 2, 3]).expect("write");
        let n = a.read(&mut buf, Duration::from_millis(100)).expect("read");
        assert_eq!(&buf[..n], &[1, 2, 3]);
    }

    #[test]
    fn memory_read_times_out_with_zero() {
        let (mut a, _b) = memory_pair();
        let mut buf = [0u8; 4];
        assert_eq!(a.read(&mut buf, Duration::from_millis(1)).expect("read"), 0);
    }

    #[test]
    fn memory_drop_disconnects_after_draining() {
        let (mut a, mut b) = memory_pair();
        b.write_all(b"xy").expect("write");
        drop(b);
        let mut buf = [0u8; 4];
        assert_eq!(
            a.read(&mut buf, Duration::from_millis(1)).expect("drain"),
            2
        );
        assert!(matches!(
            a.read(&mut buf, Duration::from_millis(1)),
            Err(TransportError::Disconnected { .. })
        ));
        assert!(matches!(
            a.write_all(b"z"),
            Err(TransportError::Disconnected { .. })
        ));
    }

    #[test]
    fn memory_read_wakes_on_write_from_another_thread() {
        let (mut a, mut b) = memory_pair();
        let t = std::thread::spawn(move || {
            b.write_all(b"late").expect("write");
            b
        });
        let mut buf = [0u8; 8];
        let mut got = Vec::new();
        while got.len() < 4 {
            let n = a.read(&mut buf, Duration::from_secs(5)).expect("read");
            got.extend_from_slice(&buf[..n]);
        }
        assert_eq!(got, b"late");
        drop(t.join().expect("join"));
    }

    #[test]
    fn missing_port_is_no_such_port() {
        let err = SerialTransport::open("/dev/does-not-exist-skinbrdf").expect_err("missing");
        assert!(matches!(err, TransportError::NoSuchPort { .. }), "{err}");
        assert!(err.to_string().contains("no such port"));
    }

    #[test]
    fn regular_file_is_not_a_serial_port() {
        let f = tempfile::NamedTempFile::new().expect("tmp");
        let path = f.path().to_str().expect("utf8").to_string();
        let err = SerialTransport::open(&path).expect_err("not a tty");
        assert!(
            matches!(
                err,
                TransportError::NotASerialPort { .. } | TransportError::Open { .. }
            ),
            "{err}"
        );
    }

    #[cfg(unix)]
    #[test]
    fn pty_pair_round_trip_and_hangup() {
        let (master, slave) = serialport::TTYPort::pair().expect("pty pair");
        let mut host = SerialTransport::from_port(Box::new(slave), "pty-slave");
        let mut dev = SerialTransport::from_port(Box::new(master), "pty-master");
        dev.write_all(&[0, 1, 2, 0xff]).expect("write");
        let mut buf = [0u8; 8];
        let mut got = Vec::new();
        while got.len() < 4 {
            let n = host.read(&mut buf, Duration::from_secs(2)).expect("read");
            assert!(n > 0, "timed out");
            got.extend_from_slice(&buf[..n]);
        }
        assert_eq!(got, vec![0, 1, 2, 0xff]);
        assert_eq!(
            host.read(&mut buf, Duration::from_millis(5)).expect("idle"),
            0
        );
        drop(dev);
        assert!(matches!(
            host.read(&mut buf, Duration::from_millis(200)),
            Err(TransportError::Disconnected { .. })
        ));
    }
}
