//! The request/response client over a [`Transport`].
//!
//! [`Client::connect`] opens a conversation: it sends a lone `0x00` (terminating whatever
//! partial frame the device holds), then `Hello`, and turns every way that can fail into a
//! precise [`ClientError`]: silence or bytes that are not our frames (not our device), a
//! version mismatch (reported by the device, or a frame whose CRC is right but whose content
//! does not decode), a transport error.
//!
//! Every request gets a fresh sequence number (from a process-wide counter seeded from the
//! clock, so a reconnected client never reuses a number an earlier conversation may still have
//! an answer in flight for); [`Client::request`] writes it and reads until the response with
//! that number arrives, queueing the events that arrive meanwhile (read them with
//! [`Client::next_event`]).
//!
//! **Re-sends.** A frame lost either way (line noise, a truncated frame) would otherwise cost
//! the whole response timeout. While no response has arrived, the client re-sends the *same*
//! frame (same `seq`) every [`Client::resend_interval`] ([`RESEND_INTERVAL`]) until the overall
//! budget [`Client::request_timeout`] runs out. The device executes a request once and answers
//! a repeated `seq` from its cache (`docs/protocol.md`, section 3; `firmware/sequencer`,
//! `on_request`), so re-sending is safe for every request. Every copy is preceded by a lone
//! `0x00`, which ends whatever partial frame the device holds (a corrupted delimiter would
//! otherwise glue the copy to garbage); the protocol's decoder skips empty frames.
//!
//! **Stale answers.** Re-sends mean a request can be answered more than once, and an answer
//! can arrive after its request gave up. A response is matched by `seq` only: one with another
//! `seq` (a duplicate answer to an earlier request, the answer to a request that timed out) is
//! counted as stray and dropped. Frames that fail to decode are counted and skipped: the
//! protocol's decoder resynchronises on the next delimiter.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use skinbrdf_protocol::{
    encode_to_vec, DeviceError, DeviceInfo, DeviceKind, DeviceMessage, Event, FrameDecoder,
    FrameError, Request, RequestBody, ResponseBody, MAX_FRAME_LEN, PROTOCOL_VERSION,
};
use skinbrdf_session::capture::DeviceIdentity;

use crate::clock::{host_now_us, ClockRead};
use crate::transport::{Transport, TransportError};

/// Default time a request waits for its response, all re-sends included: the budget after
/// which the link counts as failed (and the session re-handshakes). 1.5 s is ~1000 round trips
/// of a healthy USB link, and 7 copies at [`RESEND_INTERVAL`].
pub const DEFAULT_REQUEST_TIMEOUT: Duration = Duration::from_millis(1500);

/// Interval between copies of a request whose response has not arrived (same `seq`; the device
/// answers a repeated `seq` from its cache without executing the request again, so this is safe
/// for every request, `docs/protocol.md` section 3).
///
/// Why 200 ms: a healthy round trip is far shorter (a pseudo-terminal well under 1 ms, USB full
/// speed 1-2 ms for its 1 ms frames, the rp2040js emulator a few ms), so a copy is almost only
/// sent when a frame was really lost, and a needless copy costs one duplicate answer that is
/// dropped. It is short enough that the 1.5 s default budget holds 7 copies: with 20 % of the
/// frames corrupted each way plus 10 % truncated (a truncated frame also costs the next one; a
/// round trip survives ~50 % of the time) all 7 fail with probability ~0.6 %, where a copy
/// every 1.5 s (3 copies, the old scheme) lost ~11 % of the requests, waited 1.5 s for every
/// lost frame and fell into reconnects.
pub const RESEND_INTERVAL: Duration = Duration::from_millis(200);

/// Handshake attempts before the device is declared silent (the first `Hello` may be lost
/// while a USB device finishes enumerating).
pub const HANDSHAKE_ATTEMPTS: u32 = 3;

/// Why talking to the device failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The link failed (no such port, disconnect, ...).
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// Nothing came back to the handshake.
    #[error(
        "{port}: not our device: no answer to the handshake after {attempts} tries \
         (is it a skinbrdf trigger controller running its firmware?)"
    )]
    Silent {
        /// The port.
        port: String,
        /// Handshake attempts made.
        attempts: u32,
    },
    /// Bytes came back, but no valid skinbrdf frame.
    #[error(
        "{port}: not our device: it answered with {bytes} bytes that are not skinbrdf frames \
         ({last_error})"
    )]
    NotOurDevice {
        /// The port.
        port: String,
        /// Bytes received.
        bytes: usize,
        /// The last frame error seen.
        last_error: String,
    },
    /// What came back is what was sent: a loopback plug, a terminal echoing its input, or a
    /// pseudo-terminal nobody serves.
    #[error(
        "{port}: not our device: the port echoes what it is sent (a loopback, or a terminal \
         in echo mode), no skinbrdf controller answers there"
    )]
    Echo {
        /// The port.
        port: String,
    },
    /// The device speaks another protocol version.
    #[error(
        "{port}: protocol version mismatch: the device speaks version {device}, this host \
         speaks {host}; update {older}"
    )]
    VersionMismatch {
        /// The port.
        port: String,
        /// The device's version (0 if unknown: its frames did not decode).
        device: u32,
        /// Ours.
        host: u32,
        /// Which side to update.
        older: &'static str,
    },
    /// The device answered a request with an error.
    #[error("{port}: the device refused {request}: {error}")]
    Device {
        /// The port.
        port: String,
        /// The request's name.
        request: &'static str,
        /// The device's error.
        error: DeviceError,
    },
    /// No response within the timeout.
    #[error("{port}: no response to {request} within {timeout_ms} ms")]
    Timeout {
        /// The port.
        port: String,
        /// The request's name.
        request: &'static str,
        /// The timeout.
        timeout_ms: u128,
    },
    /// The device answered with a response of the wrong kind.
    #[error("{port}: unexpected response to {request}: {got}")]
    Unexpected {
        /// The port.
        port: String,
        /// The request's name.
        request: &'static str,
        /// What came back.
        got: String,
    },
}

/// Counters of the host side of the link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Frames decoded.
    pub frames: u64,
    /// Frames rejected (CRC, COBS, oversized, undecodable).
    pub bad_frames: u64,
    /// Responses whose sequence number matched no outstanding request (duplicate answers to
    /// re-sent requests, answers that arrived after their request gave up).
    pub stray_responses: u64,
    /// Bytes received.
    pub bytes: u64,
    /// Requests sent (first copies).
    pub requests: u64,
    /// Extra copies of requests whose response was late (same `seq`).
    pub resends: u64,
    /// Requests that got no response within their budget.
    pub timeouts: u64,
}

/// A fresh request sequence number, unique within this process (wrapping after 2^32).
///
/// The counter starts at a clock-derived value, so a new process talking to a device whose
/// link still holds answers of an earlier conversation is unlikely to reuse their numbers.
pub fn fresh_seq() -> u32 {
    static NEXT: OnceLock<AtomicU32> = OnceLock::new();
    NEXT.get_or_init(|| {
        // Low bits of the microsecond clock mixed with the process id.
        let t = host_now_us();
        let seed = (t as u32) ^ ((t >> 32) as u32) ^ std::process::id().rotate_left(16);
        AtomicU32::new(seed)
    })
    .fetch_add(1, Ordering::Relaxed)
}

/// Name of a request for messages.
pub fn request_name(body: &RequestBody) -> &'static str {
    match body {
        RequestBody::Hello { .. } => "Hello",
        RequestBody::ReadClock => "ReadClock",
        RequestBody::LoadPlan(_) => "LoadPlan",
        RequestBody::Run { .. } => "Run",
        RequestBody::Abort => "Abort",
        RequestBody::AckRecords { .. } => "AckRecords",
        RequestBody::FetchRecords { .. } => "FetchRecords",
        RequestBody::Ping => "Ping",
        RequestBody::SetWatchdog { .. } => "SetWatchdog",
        RequestBody::GetStatus => "GetStatus",
    }
}

/// The device's identity as capture.json records it.
pub fn identity(info: &DeviceInfo) -> DeviceIdentity {
    DeviceIdentity {
        protocol_version: info.protocol_version,
        firmware_version: info.firmware_version.as_str().to_string(),
        serial: info.serial.as_str().to_string(),
        kind: match info.kind {
            DeviceKind::Board => "board",
            DeviceKind::Simulator => "simulator",
            DeviceKind::Emulator => "emulator",
        }
        .to_string(),
    }
}

/// A connected, handshaken conversation with a controller.
pub struct Client<T: Transport> {
    transport: T,
    port: String,
    decoder: Box<FrameDecoder<MAX_FRAME_LEN>>,
    pending: Vec<u8>,
    events: VecDeque<Event>,
    info: Option<DeviceInfo>,
    stats: LinkStats,
    last_frame_error: Option<FrameError>,
    /// The last request frame written (with its delimiter), to recognise an echo.
    last_sent: Vec<u8>,
    /// Raw bytes of the frame being received (up to [`MAX_FRAME_LEN`]), for the same.
    rx_frame: Vec<u8>,
    /// Frames received that were byte for byte the last request sent.
    echoes: u32,
    /// How long a request waits for its response, all copies included.
    pub request_timeout: Duration,
    /// Interval between copies of a request whose response is late (same `seq`).
    pub resend_interval: Duration,
}

impl<T: Transport> std::fmt::Debug for Client<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client")
            .field("port", &self.port)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl<T: Transport> Client<T> {
    /// Wraps a transport without handshaking (see [`Client::connect`]).
    pub fn new(transport: T) -> Self {
        let port = transport.name();
        Self {
            transport,
            port,
            decoder: Box::new(FrameDecoder::new()),
            pending: Vec::new(),
            events: VecDeque::new(),
            info: None,
            stats: LinkStats::default(),
            last_frame_error: None,
            last_sent: Vec::new(),
            rx_frame: Vec::new(),
            echoes: 0,
            request_timeout: DEFAULT_REQUEST_TIMEOUT,
            resend_interval: RESEND_INTERVAL,
        }
    }

    /// Opens a conversation: resynchronises the line and handshakes.
    pub fn connect(transport: T, request_timeout: Duration) -> Result<Self, ClientError> {
        let mut client = Self::new(transport);
        client.request_timeout = request_timeout;
        client.handshake()?;
        Ok(client)
    }

    /// The port name.
    pub fn port(&self) -> &str {
        &self.port
    }

    /// The handshake answer, once connected.
    pub fn info(&self) -> Option<&DeviceInfo> {
        self.info.as_ref()
    }

    /// Link counters.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// Gives the transport back.
    pub fn into_transport(self) -> T {
        self.transport
    }

    /// (Re-)runs the handshake on this link.
    pub fn handshake(&mut self) -> Result<DeviceInfo, ClientError> {
        self.handshake_inner().map_err(|e| self.unless_echo(e))
    }

    fn handshake_inner(&mut self) -> Result<DeviceInfo, ClientError> {
        self.echoes = 0;
        let bytes_before = self.stats.bytes;
        for _ in 0..HANDSHAKE_ATTEMPTS {
            // `request` re-sends within the attempt; `Hello` is not cached by the device but
            // is idempotent, so a copy answered twice is harmless (the second answer is stray).
            let answer = self.request(RequestBody::Hello {
                protocol_version: PROTOCOL_VERSION,
            });
            match answer {
                Ok(ResponseBody::Hello(info)) => {
                    if info.protocol_version != PROTOCOL_VERSION {
                        return Err(self.mismatch(info.protocol_version));
                    }
                    self.info = Some(info.clone());
                    return Ok(info);
                }
                Ok(other) => {
                    return Err(ClientError::Unexpected {
                        port: self.port.clone(),
                        request: "Hello",
                        got: other.name().to_string(),
                    })
                }
                Err(ClientError::Device {
                    error: DeviceError::VersionMismatch { device, .. },
                    ..
                }) => return Err(self.mismatch(device)),
                Err(ClientError::Timeout { .. }) => continue,
                Err(e) => return Err(e),
            }
        }
        let received = self.stats.bytes - bytes_before;
        if matches!(self.last_frame_error, Some(FrameError::Decode)) && self.stats.frames == 0 {
            // Frames with a good CRC that do not decode: a skinbrdf device of another version.
            return Err(self.mismatch(0));
        }
        if received > 0 {
            return Err(ClientError::NotOurDevice {
                port: self.port.clone(),
                bytes: usize::try_from(received).unwrap_or(usize::MAX),
                last_error: self
                    .last_frame_error
                    .map_or_else(|| "no frame delimiter".to_string(), |e| e.to_string()),
            });
        }
        Err(ClientError::Silent {
            port: self.port.clone(),
            attempts: HANDSHAKE_ATTEMPTS,
        })
    }

    fn mismatch(&self, device: u32) -> ClientError {
        ClientError::VersionMismatch {
            port: self.port.clone(),
            device,
            host: PROTOCOL_VERSION,
            older: if device != 0 && device < PROTOCOL_VERSION {
                "the firmware"
            } else {
                "skinbrdf on the host"
            },
        }
    }

    /// Sends a request and waits for its response (events arriving meanwhile are queued),
    /// re-sending the same frame every [`Client::resend_interval`] until the response arrives
    /// or [`Client::request_timeout`] has passed since the first copy.
    pub fn request(&mut self, body: RequestBody) -> Result<ResponseBody, ClientError> {
        let name = request_name(&body);
        let seq = fresh_seq();
        let encoded =
            encode_to_vec(&Request { seq, body }).map_err(|e| ClientError::Unexpected {
                port: self.port.clone(),
                request: name,
                got: format!("cannot encode the request: {e}"),
            })?;
        // A lone delimiter first ends whatever partial frame the device holds (see the module
        // docs); every copy is written in one piece.
        let mut frame = Vec::with_capacity(encoded.len() + 1);
        frame.push(0);
        frame.extend_from_slice(&encoded);
        self.last_sent = encoded.to_vec();
        let first = Instant::now();
        let deadline = first + self.request_timeout;
        // A zero interval would spin: at least one copy per millisecond.
        let interval = self.resend_interval.max(Duration::from_millis(1));
        self.stats.requests += 1;
        self.transport.write_all(&frame)?;
        let mut next_copy = first + interval;
        let mut copies: u32 = 1;
        loop {
            let now = Instant::now();
            if now >= deadline {
                self.stats.timeouts += 1;
                tracing::debug!(seq, copies, request = name, "no response: giving up");
                return Err(ClientError::Timeout {
                    port: self.port.clone(),
                    request: name,
                    timeout_ms: self.request_timeout.as_millis(),
                });
            }
            if now >= next_copy {
                copies += 1;
                self.stats.resends += 1;
                tracing::debug!(seq, copies, request = name, "late response: re-sending");
                self.transport.write_all(&frame)?;
                next_copy = now + interval;
                continue;
            }
            match self.read_message(next_copy.min(deadline) - now)? {
                Some(DeviceMessage::Response(r)) if r.seq == seq => {
                    return r.result.map_err(|error| ClientError::Device {
                        port: self.port.clone(),
                        request: name,
                        error,
                    });
                }
                Some(DeviceMessage::Response(r)) => {
                    self.stats.stray_responses += 1;
                    tracing::debug!(seq = r.seq, waiting_for = seq, "stale response dropped");
                }
                Some(DeviceMessage::Event(e)) => self.events.push_back(e),
                None => {}
            }
        }
    }

    /// Reads the device clock once, timing the round trip on the host clock.
    pub fn read_clock(&mut self) -> Result<ClockRead, ClientError> {
        let host_send_us = host_now_us();
        match self.request(RequestBody::ReadClock)? {
            ResponseBody::Clock { device_us } => Ok(ClockRead {
                host_send_us,
                device_us,
                host_recv_us: host_now_us(),
            }),
            other => Err(ClientError::Unexpected {
                port: self.port.clone(),
                request: "ReadClock",
                got: other.name().to_string(),
            }),
        }
    }

    /// The next event: a queued one, or one read within `timeout`.
    pub fn next_event(&mut self, timeout: Duration) -> Result<Option<Event>, ClientError> {
        if let Some(e) = self.events.pop_front() {
            return Ok(Some(e));
        }
        let deadline = Instant::now() + timeout;
        loop {
            let now = Instant::now();
            let left = deadline.saturating_duration_since(now);
            match self.read_message(left)? {
                Some(DeviceMessage::Event(e)) => return Ok(Some(e)),
                Some(DeviceMessage::Response(_)) => self.stats.stray_responses += 1,
                None if Instant::now() >= deadline => return Ok(None),
                None => {}
            }
        }
    }

    /// Writes raw bytes (tests: garbage, oversized frames).
    pub fn write_raw(&mut self, bytes: &[u8]) -> Result<(), ClientError> {
        Ok(self.transport.write_all(bytes)?)
    }

    /// Reads one decoded message, waiting at most `timeout` for bytes. `None`: nothing complete.
    fn read_message(&mut self, timeout: Duration) -> Result<Option<DeviceMessage>, ClientError> {
        if let Some(m) = self.decode_pending() {
            return Ok(Some(m));
        }
        let mut buf = [0u8; 512];
        let n = self.transport.read(&mut buf, timeout)?;
        self.stats.bytes += n as u64;
        self.note_echo(&buf[..n]);
        self.pending.extend_from_slice(&buf[..n]);
        Ok(self.decode_pending())
    }

    /// Counts received frames that equal the last request sent (an echoing port).
    fn note_echo(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if self.rx_frame.len() < MAX_FRAME_LEN {
                self.rx_frame.push(b);
            }
            if b == 0 {
                if self.rx_frame.len() > 1 && self.rx_frame == self.last_sent {
                    self.echoes += 1;
                }
                self.rx_frame.clear();
            }
        }
    }

    /// The handshake's failure, unless the port merely echoed: then that is the reason.
    fn unless_echo(&self, e: ClientError) -> ClientError {
        if self.echoes > 0 {
            ClientError::Echo {
                port: self.port.clone(),
            }
        } else {
            e
        }
    }

    fn decode_pending(&mut self) -> Option<DeviceMessage> {
        while !self.pending.is_empty() {
            match self.decoder.feed::<DeviceMessage>(&self.pending) {
                Some((result, rest)) => {
                    let consumed = self.pending.len() - rest.len();
                    self.pending.drain(..consumed);
                    match result {
                        Ok(m) => {
                            self.stats.frames += 1;
                            return Some(m);
                        }
                        Err(e) => {
                            self.stats.bad_frames += 1;
                            self.last_frame_error = Some(e);
                            tracing::debug!(error = %e, "bad frame from the device");
                        }
                    }
                }
                None => self.pending.clear(),
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_echoing_port_is_reported_as_such() {
        let (host, mut echo) = crate::transport::memory_pair();
        let t = std::thread::spawn(move || {
            let mut buf = [0u8; 256];
            while let Ok(n) = echo.read(&mut buf, Duration::from_millis(20)) {
                if n > 0 && echo.write_all(&buf[..n]).is_err() {
                    break;
                }
            }
        });
        let mut c = Client::new(host);
        c.request_timeout = Duration::from_millis(300);
        c.resend_interval = Duration::from_millis(50);
        let err = c.handshake().expect_err("an echo is no device");
        assert!(matches!(err, ClientError::Echo { .. }), "{err}");
        assert!(err.to_string().contains("echoes what it is sent"), "{err}");
        drop(c);
        t.join().expect("echo thread");
    }
    use crate::transport::memory_pair;
    use skinbrdf_protocol::{Response, Status};

    /// A scripted device: answers each decoded request with `answer(request)`.
    fn fake_device(
        mut port: crate::transport::MemoryTransport,
        mut answer: impl FnMut(&Request) -> Vec<Vec<u8>> + Send + 'static,
    ) -> std::thread::JoinHandle<()> {
        std::thread::spawn(move || {
            let mut dec: FrameDecoder<MAX_FRAME_LEN> = FrameDecoder::new();
            let mut buf = [0u8; 256];
            loop {
                let n = match port.read(&mut buf, Duration::from_millis(20)) {
                    Ok(n) => n,
                    Err(_) => return,
                };
                let mut input = &buf[..n];
                while let Some((res, rest)) = dec.feed::<Request>(input) {
                    input = rest;
                    if let Ok(req) = res {
                        for frame in answer(&req) {
                            if port.write_all(&frame).is_err() {
                                return;
                            }
                        }
                    }
                }
            }
        })
    }

    fn frame(m: &DeviceMessage) -> Vec<u8> {
        encode_to_vec(m).expect("encode").to_vec()
    }

    fn info(version: u32) -> DeviceInfo {
        DeviceInfo {
            protocol_version: version,
            firmware_version: skinbrdf_protocol::truncated("0.1.0"),
            serial: skinbrdf_protocol::truncated("TEST-1"),
            kind: DeviceKind::Simulator,
            clock_us: 5,
        }
    }

    fn respond(seq: u32, result: Result<ResponseBody, DeviceError>) -> Vec<u8> {
        frame(&DeviceMessage::Response(Response { seq, result }))
    }

    #[test]
    fn handshake_and_requests_with_interleaved_events() {
        let (host, dev) = memory_pair();
        let t = fake_device(dev, |req| match req.body {
            RequestBody::Hello { .. } => {
                vec![respond(
                    req.seq,
                    Ok(ResponseBody::Hello(info(PROTOCOL_VERSION))),
                )]
            }
            RequestBody::ReadClock => vec![
                frame(&DeviceMessage::Event(Event::FlashReady {
                    at_us: 1,
                    ready: true,
                    recycle_us: None,
                })),
                b"\x01\x02garbage\x00".to_vec(),
                respond(
                    req.seq.wrapping_add(100),
                    Ok(ResponseBody::Pong { device_us: 0 }),
                ),
                respond(req.seq, Ok(ResponseBody::Clock { device_us: 1 << 40 })),
            ],
            _ => vec![respond(req.seq, Err(DeviceError::NoPlan))],
        });
        let mut c = Client::connect(host, Duration::from_secs(2)).expect("connect");
        assert_eq!(c.info().expect("info").serial.as_str(), "TEST-1");
        let r = c.read_clock().expect("clock");
        assert_eq!(r.device_us, 1 << 40);
        assert!(r.host_recv_us >= r.host_send_us);
        assert!(matches!(
            c.next_event(Duration::ZERO).expect("event"),
            Some(Event::FlashReady { ready: true, .. })
        ));
        assert_eq!(c.stats().bad_frames, 1);
        assert_eq!(c.stats().stray_responses, 1);
        let err = c
            .request(RequestBody::Run {
                first_group: 0,
                last_group: 0,
            })
            .expect_err("refused");
        assert!(err.to_string().contains("refused Run"), "{err}");
        drop(c);
        t.join().expect("device thread");
    }

    /// The first copy of every `Ping` goes unanswered (its response "lost"); the second copy
    /// is answered twice (a duplicate); before answering the next `ReadClock` the device replays
    /// the last `Ping` answer (a late, stale response). The client must re-send after its
    /// interval, not after its whole budget, and match responses by `seq` only.
    #[test]
    fn lost_responses_are_re_sent_and_stale_answers_dropped() {
        let (host, dev) = memory_pair();
        let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::<(u32, &str)>::new()));
        let log = seen.clone();
        let mut copies = std::collections::HashMap::<u32, u32>::new();
        let mut last_ping: Option<u32> = None;
        let t = fake_device(dev, move |req| {
            let name = request_name(&req.body);
            log.lock().expect("log").push((req.seq, name));
            let n = copies.entry(req.seq).or_insert(0);
            *n += 1;
            match req.body {
                RequestBody::Hello { .. } => vec![respond(
                    req.seq,
                    Ok(ResponseBody::Hello(info(PROTOCOL_VERSION))),
                )],
                RequestBody::Ping if *n == 1 => Vec::new(),
                RequestBody::Ping => {
                    last_ping = Some(req.seq);
                    let pong = respond(req.seq, Ok(ResponseBody::Pong { device_us: 7 }));
                    vec![pong.clone(), pong]
                }
                RequestBody::ReadClock => {
                    let mut out = Vec::new();
                    if let Some(p) = last_ping.take() {
                        out.push(respond(p, Ok(ResponseBody::Pong { device_us: 8 })));
                    }
                    out.push(respond(req.seq, Ok(ResponseBody::Clock { device_us: 42 })));
                    out
                }
                _ => vec![respond(req.seq, Err(DeviceError::NoPlan))],
            }
        });
        let mut c = Client::connect(host, Duration::from_secs(5)).expect("connect");
        c.resend_interval = Duration::from_millis(50);
        let started = Instant::now();
        let pong = c.request(RequestBody::Ping).expect("ping");
        let took = started.elapsed();
        assert_eq!(pong, ResponseBody::Pong { device_us: 7 });
        assert_eq!(c.stats().resends, 1, "{:?}", c.stats());
        assert!(
            took < Duration::from_secs(1),
            "re-sent after the interval, not the budget: {took:?}"
        );
        // The duplicate Pong and the replayed stale Pong are both dropped; the clock read gets
        // its own answer, not a Pong (which would be an `Unexpected` error).
        let clock = c.read_clock().expect("clock");
        assert_eq!(clock.device_us, 42);
        assert_eq!(c.stats().stray_responses, 2, "{:?}", c.stats());
        assert_eq!(c.stats().timeouts, 0);
        drop(c);
        t.join().expect("device thread");
        let seen = seen.lock().expect("log");
        let pings: Vec<u32> = seen
            .iter()
            .filter(|(_, n)| *n == "Ping")
            .map(|(s, _)| *s)
            .collect();
        assert_eq!(pings.len(), 2, "{seen:?}");
        assert_eq!(pings[0], pings[1], "a copy keeps its seq");
        let seqs: std::collections::HashSet<u32> = seen.iter().map(|(s, _)| *s).collect();
        assert_eq!(seqs.len(), seen.len() - 1, "every new request a fresh seq");
    }

    #[test]
    fn unanswered_request_is_re_sent_until_the_budget_ends() {
        let (host, dev) = memory_pair();
        let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::<u32>::new()));
        let log = seen.clone();
        let t = fake_device(dev, move |req| match req.body {
            RequestBody::Hello { .. } => vec![respond(
                req.seq,
                Ok(ResponseBody::Hello(info(PROTOCOL_VERSION))),
            )],
            _ => {
                log.lock().expect("log").push(req.seq);
                Vec::new()
            }
        });
        let mut c = Client::connect(host, Duration::from_secs(5)).expect("connect");
        c.request_timeout = Duration::from_millis(500);
        c.resend_interval = Duration::from_millis(100);
        let started = Instant::now();
        let err = c.request(RequestBody::GetStatus).expect_err("silent");
        let took = started.elapsed();
        assert!(matches!(err, ClientError::Timeout { .. }), "{err}");
        assert!(
            took >= Duration::from_millis(500) && took < Duration::from_millis(1500),
            "{took:?}"
        );
        let stats = c.stats();
        assert!((3..=5).contains(&stats.resends), "{stats:?}");
        assert_eq!(stats.timeouts, 1);
        drop(c);
        t.join().expect("device thread");
        let seen = seen.lock().expect("log");
        assert_eq!(seen.len() as u64, stats.resends + 1);
        assert!(seen.iter().all(|&s| s == seen[0]), "same seq: {seen:?}");
    }

    #[test]
    fn version_mismatch_is_reported() {
        let (host, dev) = memory_pair();
        let t = fake_device(dev, |req| {
            vec![respond(
                req.seq,
                Err(DeviceError::VersionMismatch {
                    device: PROTOCOL_VERSION + 1,
                    host: PROTOCOL_VERSION,
                }),
            )]
        });
        let err = Client::connect(host, Duration::from_secs(2)).expect_err("mismatch");
        let msg = err.to_string();
        assert!(matches!(err, ClientError::VersionMismatch { .. }), "{msg}");
        assert!(
            msg.contains("version mismatch") && msg.contains("skinbrdf on the host"),
            "{msg}"
        );
        t.join().expect("device thread");
    }

    #[test]
    fn silent_device_is_not_ours() {
        let (host, _dev) = memory_pair();
        let err = Client::connect(host, Duration::from_millis(20)).expect_err("silent");
        assert!(matches!(err, ClientError::Silent { .. }), "{err}");
        assert!(err.to_string().contains("not our device"));
    }

    #[test]
    fn chatty_foreign_device_is_not_ours() {
        let (host, dev) = memory_pair();
        let t = fake_device(dev, |_| vec![b"AT+OK\r\nhello from a GPS\r\n\x00".to_vec()]);
        let err = Client::connect(host, Duration::from_millis(50)).expect_err("foreign");
        assert!(matches!(err, ClientError::NotOurDevice { .. }), "{err}");
        t.join().expect("device thread");
    }

    #[test]
    fn status_round_trips() {
        // Keeps the Status type in the client's vocabulary (used by the session runner).
        let s = Status {
            now_us: 1,
            state: skinbrdf_protocol::SessionState::Idle,
            next_index: 0,
            unacked: 0,
            oldest_unacked: None,
            flash_ready: true,
            bad_frames: 0,
            dropped_messages: 0,
            watchdog_us: 0,
        };
        let bytes = respond(3, Ok(ResponseBody::Status(s.clone())));
        let mut dec: FrameDecoder<MAX_FRAME_LEN> = FrameDecoder::new();
        let (m, _) = dec.feed::<DeviceMessage>(&bytes).expect("frame");
        assert_eq!(
            m.expect("decode"),
            DeviceMessage::Response(Response {
                seq: 3,
                result: Ok(ResponseBody::Status(s))
            })
        );
    }
}
