//! One direction of an in-process byte link (`std` only): the pipe behind the host's in-memory
//! transport (`skinbrdf_capture::transport::memory_pair`) and the simulator's in-process link
//! (`skinbrdf_sim::memory_link`). It lives here because both crates depend on this one and on
//! nothing else they share.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

/// The pipe was closed (by either end; a poisoned lock counts as closed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PipeClosed;

impl core::fmt::Display for PipeClosed {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "the in-process link is closed")
    }
}

impl std::error::Error for PipeClosed {}

#[derive(Debug, Default)]
struct State {
    bytes: VecDeque<u8>,
    closed: bool,
}

/// A byte FIFO with a blocking, time-bounded read; share it in an `Arc` between the writer and
/// the reader.
#[derive(Debug, Default)]
pub struct Pipe {
    state: Mutex<State>,
    ready: Condvar,
}

impl Pipe {
    /// An open, empty pipe.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends `data`; fails once the pipe is closed.
    pub fn push(&self, data: &[u8]) -> Result<(), PipeClosed> {
        let mut s = self.state.lock().map_err(|_| PipeClosed)?;
        if s.closed {
            return Err(PipeClosed);
        }
        s.bytes.extend(data);
        drop(s);
        self.ready.notify_all();
        Ok(())
    }

    /// Moves up to `buf.len()` bytes out, waiting at most `timeout` for the first. `Ok(0)`:
    /// nothing arrived in time (or `buf` is empty). Bytes written before a close are still
    /// read; after them, [`PipeClosed`].
    pub fn pop(&self, buf: &mut [u8], timeout: Duration) -> Result<usize, PipeClosed> {
        let deadline = Instant::now() + timeout;
        let mut s = self.state.lock().map_err(|_| PipeClosed)?;
        loop {
            if !s.bytes.is_empty() {
                let n = buf.len().min(s.bytes.len());
                for (dst, src) in buf.iter_mut().zip(s.bytes.drain(..n)) {
                    *dst = src;
                }
                return Ok(n);
            }
            if s.closed {
                return Err(PipeClosed);
            }
            let now = Instant::now();
            if now >= deadline || buf.is_empty() {
                return Ok(0);
            }
            s = self
                .ready
                .wait_timeout(s, deadline - now)
                .map_err(|_| PipeClosed)?
                .0;
        }
    }

    /// Closes the pipe: writes fail at once, reads after the remaining bytes.
    pub fn close(&self) {
        if let Ok(mut s) = self.state.lock() {
            s.closed = true;
        }
        self.ready.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::vec::Vec;

    #[test]
    fn bytes_in_order_then_timeout_then_closed_after_draining() {
        let p = Pipe::new();
        p.push(b"abc").unwrap();
        let mut buf = [0u8; 2];
        assert_eq!(p.pop(&mut buf, Duration::ZERO), Ok(2));
        assert_eq!(&buf, b"ab");
        p.close();
        assert_eq!(p.push(b"x"), Err(PipeClosed));
        assert_eq!(p.pop(&mut buf, Duration::ZERO), Ok(1));
        assert_eq!(p.pop(&mut buf, Duration::ZERO), Err(PipeClosed));
    }

    #[test]
    fn empty_open_pipe_times_out_with_zero() {
        let p = Pipe::new();
        let mut buf = [0u8; 4];
        assert_eq!(p.pop(&mut buf, Duration::from_millis(2)), Ok(0));
    }

    #[test]
    fn a_write_from_another_thread_wakes_the_reader() {
        let p = Arc::new(Pipe::new());
        let q = p.clone();
        let t = std::thread::spawn(move || q.push(b"late"));
        let mut got = Vec::new();
        let mut buf = [0u8; 8];
        while got.len() < 4 {
            let n = p.pop(&mut buf, Duration::from_secs(5)).unwrap();
            got.extend_from_slice(&buf[..n]);
        }
        assert_eq!(got, b"late");
        assert_eq!(t.join().unwrap(), Ok(()));
    }
}
