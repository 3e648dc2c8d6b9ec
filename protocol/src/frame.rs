//! Framing: `COBS(postcard(message) ‖ CRC-32(postcard(message)) as little-endian) ‖ 0x00`.
//!
//! * **Serialization** stacks postcard's flavors: the CRC modifier feeds every payload byte to
//!   the digest and to the COBS flavor, appends the four CRC bytes (little-endian) and the COBS
//!   flavor appends the `0x00` delimiter ([`encode`]).
//! * **CRC**: CRC-32/ISO-HDLC (the zlib/Ethernet CRC: polynomial `0x04C11DB7` reflected as
//!   `0xEDB88320`, init `0xFFFFFFFF`, final XOR `0xFFFFFFFF`, check value `0xCBF43926` for
//!   `"123456789"`), computed over the postcard bytes only.
//! * **Decoding** ([`FrameDecoder`]) accumulates bytes up to a `0x00`, COBS-decodes in place,
//!   checks the CRC, then deserializes with postcard's CRC flavor. It never panics and always
//!   resynchronises at the next `0x00`: garbage before a frame costs at most that one frame
//!   (reported as an error), an oversized frame is discarded up to its delimiter, an empty frame
//!   (two zeros in a row) is silently skipped so senders may send `0x00` to flush a partial
//!   frame at the receiver.

use serde::{de::DeserializeOwned, Serialize};

use crate::limits::MAX_FRAME_LEN;

/// The CRC used on every frame: CRC-32/ISO-HDLC.
pub static CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Bytes of CRC after the payload.
pub const CRC_LEN: usize = 4;

/// Why a message could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The frame does not fit the buffer (or [`MAX_FRAME_LEN`]).
    BufferFull,
    /// postcard refused the value (cannot happen for this crate's message types).
    Serialize,
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BufferFull => write!(f, "frame does not fit {MAX_FRAME_LEN} bytes"),
            Self::Serialize => write!(f, "postcard could not serialize the message"),
        }
    }
}

/// Encodes `msg` as one complete frame (including the trailing `0x00`) into `buf` and returns
/// the used prefix. Fails if the frame would exceed `buf` or [`MAX_FRAME_LEN`].
pub fn encode<'b, T: Serialize + ?Sized>(
    msg: &T,
    buf: &'b mut [u8],
) -> Result<&'b mut [u8], EncodeError> {
    let cap = buf.len().min(MAX_FRAME_LEN);
    let buf = &mut buf[..cap];
    let cobs = postcard::ser_flavors::Cobs::try_new(postcard::ser_flavors::Slice::new(buf))
        .map_err(|_| EncodeError::BufferFull)?;
    let flavor = postcard::ser_flavors::crc::CrcModifier::new(cobs, CRC32.digest());
    postcard::serialize_with_flavor(msg, flavor).map_err(|e| match e {
        postcard::Error::SerializeBufferFull => EncodeError::BufferFull,
        _ => EncodeError::Serialize,
    })
}

/// Encodes `msg` into a fresh fixed-capacity frame buffer.
pub fn encode_to_vec<T: Serialize + ?Sized>(
    msg: &T,
) -> Result<heapless::Vec<u8, MAX_FRAME_LEN>, EncodeError> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let used = encode(msg, &mut buf)?.len();
    heapless::Vec::from_slice(&buf[..used]).map_err(|_| EncodeError::BufferFull)
}

/// Why a received frame was rejected. After any of these the decoder is already
/// resynchronised on the next frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// More than the decoder's capacity arrived before a `0x00`; the bytes up to the next
    /// `0x00` were discarded.
    Oversized {
        /// Bytes discarded (saturating).
        discarded: usize,
    },
    /// The bytes between two delimiters are not valid COBS.
    Cobs,
    /// Too short to hold a CRC.
    TooShort {
        /// Decoded length.
        len: usize,
    },
    /// The CRC does not match: line noise, truncation or garbage.
    Crc {
        /// CRC carried by the frame.
        received: u32,
        /// CRC of the payload.
        computed: u32,
    },
    /// The CRC matched but postcard could not decode the message (unknown variant: most likely
    /// a protocol version mismatch).
    Decode,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Oversized { discarded } => {
                write!(f, "oversized frame: {discarded} bytes discarded")
            }
            Self::Cobs => write!(f, "invalid COBS encoding"),
            Self::TooShort { len } => write!(f, "frame of {len} bytes is too short for a CRC"),
            Self::Crc { received, computed } => write!(
                f,
                "CRC mismatch: frame carries {received:#010x}, payload gives {computed:#010x}"
            ),
            Self::Decode => write!(f, "CRC ok but the message does not decode (version?)"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for FrameError {}
#[cfg(feature = "std")]
impl std::error::Error for EncodeError {}

/// Counters a decoder keeps (saturating).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecoderStats {
    /// Frames decoded successfully.
    pub frames: u32,
    /// Frames rejected (any [`FrameError`]).
    pub errors: u32,
    /// Bytes discarded because a frame was oversized.
    pub discarded_bytes: u32,
}

/// Streaming frame decoder with a fixed buffer of `N` bytes (the largest encoded frame it
/// accepts, delimiter excluded).
///
/// ```
/// use skinbrdf_protocol::{encode_to_vec, FrameDecoder, Request, RequestBody};
/// let frame = encode_to_vec(&Request { seq: 7, body: RequestBody::Ping }).unwrap();
/// let mut dec = FrameDecoder::<256>::new();
/// let mut input: &[u8] = &frame;
/// let mut got = None;
/// while let Some((result, rest)) = dec.feed::<Request>(input) {
///     got = Some(result.unwrap());
///     input = rest;
/// }
/// assert_eq!(got.unwrap().seq, 7);
/// ```
#[derive(Debug)]
pub struct FrameDecoder<const N: usize = MAX_FRAME_LEN> {
    buf: [u8; N],
    len: usize,
    /// Set while skipping the rest of an oversized frame; counts skipped bytes.
    discarding: Option<usize>,
    stats: DecoderStats,
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameDecoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            discarding: None,
            stats: DecoderStats {
                frames: 0,
                errors: 0,
                discarded_bytes: 0,
            },
        }
    }

    /// Forgets any partial frame (e.g. after a reconnect).
    pub fn reset(&mut self) {
        self.len = 0;
        self.discarding = None;
    }

    /// Bytes of the partial frame held.
    pub fn pending_len(&self) -> usize {
        self.len
    }

    /// Counters since creation.
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// Feeds bytes until one frame completes. Returns `None` when all of `data` was consumed
    /// without completing a frame; otherwise the frame's result and the unconsumed rest of
    /// `data` (feed it again).
    pub fn feed<'a, T: DeserializeOwned>(
        &mut self,
        data: &'a [u8],
    ) -> Option<(Result<T, FrameError>, &'a [u8])> {
        for (i, &byte) in data.iter().enumerate() {
            if let Some(result) = self.push_byte::<T>(byte) {
                return Some((result, &data[i + 1..]));
            }
        }
        None
    }

    /// Feeds one byte; returns a result when it completed a (non-empty) frame.
    pub fn push_byte<T: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<T, FrameError>> {
        if byte != 0 {
            if let Some(skipped) = self.discarding.as_mut() {
                *skipped = skipped.saturating_add(1);
            } else if self.len < N {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.discarding = Some(self.len.saturating_add(1));
                self.len = 0;
            }
            return None;
        }
        // Delimiter.
        if let Some(discarded) = self.discarding.take() {
            self.len = 0;
            self.stats.errors = self.stats.errors.saturating_add(1);
            let d = u32::try_from(discarded).unwrap_or(u32::MAX);
            self.stats.discarded_bytes = self.stats.discarded_bytes.saturating_add(d);
            return Some(Err(FrameError::Oversized { discarded }));
        }
        if self.len == 0 {
            return None;
        }
        let len = self.len;
        self.len = 0;
        let result = decode_frame_in_place::<T>(&mut self.buf[..len]);
        match result {
            Ok(_) => self.stats.frames = self.stats.frames.saturating_add(1),
            Err(_) => self.stats.errors = self.stats.errors.saturating_add(1),
        }
        Some(result)
    }
}

/// Decodes one frame body (the bytes between delimiters, no `0x00`), overwriting it.
pub fn decode_frame_in_place<T: DeserializeOwned>(body: &mut [u8]) -> Result<T, FrameError> {
    let len = cobs::decode_in_place(body).map_err(|_| FrameError::Cobs)?;
    let decoded = body.get(..len).ok_or(FrameError::Cobs)?;
    if len < CRC_LEN + 1 {
        return Err(FrameError::TooShort { len });
    }
    let (payload, crc_bytes) = decoded.split_at(len - CRC_LEN);
    let mut le = [0u8; CRC_LEN];
    le.copy_from_slice(crc_bytes);
    let received = u32::from_le_bytes(le);
    let computed = CRC32.checksum(payload);
    if received != computed {
        return Err(FrameError::Crc { received, computed });
    }
    postcard::de_flavors::crc::from_bytes_u32(decoded, CRC32.digest())
        .map_err(|_| FrameError::Decode)
}
