//! The streaming decoder: bytes in, a few at a time; frames or counted rejections out.

use core::fmt;

use crate::message::{ErrorReason, Message, PayloadError};
use crate::{CRC, DLE, ETX, MAX_FRAME_BYTES, STX};

/// A decoded frame: who sent it (or whom it answers) and what it says.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// The frame's CLIENT ID byte.
    pub client_id: u8,
    /// The message.
    pub message: Message,
}

impl Frame {
    /// Encodes the frame into `out`; see [`crate::encode`].
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, crate::EncodeError> {
        crate::encode(&self.message, self.client_id, out)
    }
}

/// Why a frame was rejected: the key of [`Counters`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Rejection {
    /// The CRC does not match the body. The client ID cannot be trusted: no reply.
    BadCrc = 0,
    /// The body grew past [`MAX_FRAME_BYTES`] before its DLE ETX.
    TooLong = 1,
    /// DLE ETX came before a body that holds at least a client ID, an opcode and a CRC.
    TooShort = 2,
    /// DLE STX came inside a frame: the partial frame is dropped and the new one starts.
    Truncated = 3,
    /// Inside a frame, a DLE was followed by a byte other than DLE, STX or ETX.
    StrayDle = 4,
    /// Valid CRC, but the opcode is none of M3's.
    UnknownOpcode = 5,
    /// Valid CRC, but the DATA length is not the opcode's.
    BadLength = 6,
    /// Valid CRC, but an `f32` of the DATA is NaN or infinite.
    NonFinite = 7,
    /// Valid CRC, but a code of the DATA (an error reason, a deposit status) is undefined.
    BadValue = 8,
}

/// Number of [`Rejection`] reasons.
pub const REJECTIONS: usize = 9;

impl Rejection {
    /// Every reason, in counter order.
    pub const ALL: [Rejection; REJECTIONS] = [
        Rejection::BadCrc,
        Rejection::TooLong,
        Rejection::TooShort,
        Rejection::Truncated,
        Rejection::StrayDle,
        Rejection::UnknownOpcode,
        Rejection::BadLength,
        Rejection::NonFinite,
        Rejection::BadValue,
    ];

    /// A short stable name, for logs and counters (`bad_crc`, `too_long`, …).
    pub const fn name(self) -> &'static str {
        match self {
            Rejection::BadCrc => "bad_crc",
            Rejection::TooLong => "too_long",
            Rejection::TooShort => "too_short",
            Rejection::Truncated => "truncated",
            Rejection::StrayDle => "stray_dle",
            Rejection::UnknownOpcode => "unknown_opcode",
            Rejection::BadLength => "bad_length",
            Rejection::NonFinite => "non_finite",
            Rejection::BadValue => "bad_value",
        }
    }
}

/// A rejected frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// See [`Rejection::BadCrc`].
    BadCrc,
    /// See [`Rejection::TooLong`].
    TooLong,
    /// See [`Rejection::TooShort`]; `len` unstuffed body bytes were received.
    TooShort {
        /// Unstuffed body bytes received.
        len: usize,
    },
    /// See [`Rejection::Truncated`]; `len` unstuffed body bytes were dropped.
    Truncated {
        /// Unstuffed body bytes dropped.
        len: usize,
    },
    /// See [`Rejection::StrayDle`]; `byte` followed the DLE.
    StrayDle {
        /// The byte after the DLE.
        byte: u8,
    },
    /// See [`Rejection::UnknownOpcode`].
    UnknownOpcode {
        /// The frame's client ID (its CRC was valid).
        client_id: u8,
        /// The opcode.
        opcode: u8,
    },
    /// See [`Rejection::BadLength`].
    BadLength {
        /// The frame's client ID (its CRC was valid).
        client_id: u8,
        /// The opcode.
        opcode: u8,
        /// The DATA length received.
        data_len: usize,
    },
    /// See [`Rejection::NonFinite`].
    NonFinite {
        /// The frame's client ID (its CRC was valid).
        client_id: u8,
        /// The opcode.
        opcode: u8,
    },
    /// See [`Rejection::BadValue`].
    BadValue {
        /// The frame's client ID (its CRC was valid).
        client_id: u8,
        /// The opcode.
        opcode: u8,
    },
}

impl DecodeError {
    /// The counter this rejection is counted under.
    pub const fn rejection(&self) -> Rejection {
        match self {
            DecodeError::BadCrc => Rejection::BadCrc,
            DecodeError::TooLong => Rejection::TooLong,
            DecodeError::TooShort { .. } => Rejection::TooShort,
            DecodeError::Truncated { .. } => Rejection::Truncated,
            DecodeError::StrayDle { .. } => Rejection::StrayDle,
            DecodeError::UnknownOpcode { .. } => Rejection::UnknownOpcode,
            DecodeError::BadLength { .. } => Rejection::BadLength,
            DecodeError::NonFinite { .. } => Rejection::NonFinite,
            DecodeError::BadValue { .. } => Rejection::BadValue,
        }
    }

    /// The error reply M3 prescribes: the client ID to answer and the reason, for a frame whose
    /// CRC was valid; `None` for a frame that gets no reply (bad CRC or broken framing: its
    /// client ID cannot be trusted).
    pub const fn reply(&self) -> Option<(u8, ErrorReason)> {
        match *self {
            DecodeError::UnknownOpcode { client_id, .. } => {
                Some((client_id, ErrorReason::UnknownOpcode))
            }
            DecodeError::BadLength { client_id, .. } => Some((client_id, ErrorReason::BadLength)),
            DecodeError::NonFinite { client_id, .. } | DecodeError::BadValue { client_id, .. } => {
                Some((client_id, ErrorReason::BadValue))
            }
            _ => None,
        }
    }
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            DecodeError::BadCrc => f.write_str("frame rejected: bad CRC"),
            DecodeError::TooLong => write!(
                f,
                "frame rejected: longer than {MAX_FRAME_BYTES} unstuffed body bytes"
            ),
            DecodeError::TooShort { len } => {
                write!(f, "frame rejected: {len} body bytes, at least 4 needed")
            }
            DecodeError::Truncated { len } => {
                write!(f, "frame rejected: DLE STX after {len} body bytes")
            }
            DecodeError::StrayDle { byte } => {
                write!(f, "frame rejected: stray DLE sequence 0x10 0x{byte:02X}")
            }
            DecodeError::UnknownOpcode { client_id, opcode } => write!(
                f,
                "frame from client {client_id} rejected: unknown opcode 0x{opcode:02X}"
            ),
            DecodeError::BadLength {
                client_id,
                opcode,
                data_len,
            } => write!(
                f,
                "frame from client {client_id} rejected: {data_len} data bytes are a bad length \
                 for opcode 0x{opcode:02X}"
            ),
            DecodeError::NonFinite { client_id, opcode } => write!(
                f,
                "frame from client {client_id} rejected: non-finite number in opcode \
                 0x{opcode:02X}"
            ),
            DecodeError::BadValue { client_id, opcode } => write!(
                f,
                "frame from client {client_id} rejected: undefined code in opcode 0x{opcode:02X}"
            ),
        }
    }
}

impl core::error::Error for DecodeError {}

/// What a decoder has seen since it was made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Frames decoded.
    pub frames: u64,
    /// Rejections, indexed by `Rejection as usize`.
    pub rejected: [u64; REJECTIONS],
    /// Bytes outside any frame, skipped while looking for DLE STX.
    pub skipped_bytes: u64,
}

impl Counters {
    /// Rejections for one reason.
    pub const fn get(&self, reason: Rejection) -> u64 {
        self.rejected[reason as usize]
    }

    /// Rejections for every reason.
    pub fn total_rejected(&self) -> u64 {
        self.rejected.iter().sum()
    }

    /// Each reason with its count, in counter order.
    pub fn iter(&self) -> impl Iterator<Item = (Rejection, u64)> + '_ {
        Rejection::ALL.iter().map(|&r| (r, self.get(r)))
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Outside a frame, looking for DLE STX.
    Hunt,
    /// Outside a frame, after a DLE.
    HuntDle,
    /// Inside a frame.
    Body,
    /// Inside a frame, after a DLE.
    BodyDle,
}

/// The streaming decoder: a state machine fed one byte at a time ([`Decoder::push`]) or a slice
/// at a time ([`Decoder::feed`]). It holds one unstuffed body of at most [`MAX_FRAME_BYTES`] and
/// allocates nothing.
///
/// Outside a frame it skips every byte until DLE STX (a run of DLEs before STX still starts a
/// frame). Inside a frame, DLE DLE is one data DLE, DLE ETX ends the frame, DLE STX drops the
/// partial frame ([`Rejection::Truncated`]) and starts a new one, and DLE followed by anything
/// else is a [`Rejection::StrayDle`]. A body that grows past [`MAX_FRAME_BYTES`] is a
/// [`Rejection::TooLong`]. After a rejection the decoder looks for the next DLE STX.
///
/// One ambiguity is inherent in DLE framing: if garbage leaves the decoder inside a frame just
/// after a DLE, the next frame's DLE STX reads as a data DLE followed by 0x02, so that frame is
/// lost (rejected at its own DLE ETX) and the one after it is decoded. A sender can rule this
/// out by sending any byte other than DLE (e.g. 0x00) before DLE STX: bytes between frames are
/// skipped.
#[derive(Clone, Debug)]
pub struct Decoder {
    state: State,
    body: [u8; MAX_FRAME_BYTES],
    len: usize,
    counters: Counters,
}

impl Default for Decoder {
    fn default() -> Self {
        Decoder::new()
    }
}

impl Decoder {
    /// A decoder looking for DLE STX, with zero counters.
    pub const fn new() -> Decoder {
        Decoder {
            state: State::Hunt,
            body: [0; MAX_FRAME_BYTES],
            len: 0,
            counters: Counters {
                frames: 0,
                rejected: [0; REJECTIONS],
                skipped_bytes: 0,
            },
        }
    }

    /// What the decoder has seen.
    pub const fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Whether the decoder is inside a frame (after DLE STX, before its end).
    pub const fn in_frame(&self) -> bool {
        matches!(self.state, State::Body | State::BodyDle)
    }

    /// Drops any partial frame, uncounted, and looks for DLE STX again; the counters are kept.
    /// For datagrams (one frame per datagram): reset before each one.
    pub fn reset(&mut self) {
        self.state = State::Hunt;
        self.len = 0;
    }

    /// Feeds one byte; returns the outcome of the frame this byte ended, if it ended one.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame, DecodeError>> {
        match self.state {
            State::Hunt => {
                if byte == DLE {
                    self.state = State::HuntDle;
                } else {
                    self.counters.skipped_bytes += 1;
                }
                None
            }
            State::HuntDle => {
                match byte {
                    STX => self.start(),
                    // Stay after a DLE: the last DLE of a run may start a frame.
                    DLE => self.counters.skipped_bytes += 1,
                    _ => {
                        self.counters.skipped_bytes += 2;
                        self.state = State::Hunt;
                    }
                }
                None
            }
            State::Body => {
                if byte == DLE {
                    self.state = State::BodyDle;
                    None
                } else {
                    self.append(byte)
                }
            }
            State::BodyDle => match byte {
                DLE => {
                    self.state = State::Body;
                    self.append(DLE)
                }
                ETX => {
                    self.state = State::Hunt;
                    Some(self.finish())
                }
                STX => {
                    let len = self.len;
                    self.start();
                    Some(self.reject(DecodeError::Truncated { len }))
                }
                _ => {
                    self.state = State::Hunt;
                    self.counters.skipped_bytes += 1;
                    Some(self.reject(DecodeError::StrayDle { byte }))
                }
            },
        }
    }

    /// Feeds a slice; calls `on_outcome` for each frame ended in it, in order.
    pub fn feed(&mut self, bytes: &[u8], mut on_outcome: impl FnMut(Result<Frame, DecodeError>)) {
        for &byte in bytes {
            if let Some(outcome) = self.push(byte) {
                on_outcome(outcome);
            }
        }
    }

    fn start(&mut self) {
        self.state = State::Body;
        self.len = 0;
    }

    fn append(&mut self, byte: u8) -> Option<Result<Frame, DecodeError>> {
        if self.len == MAX_FRAME_BYTES {
            self.state = State::Hunt;
            return Some(self.reject(DecodeError::TooLong));
        }
        self.body[self.len] = byte;
        self.len += 1;
        None
    }

    fn reject(&mut self, error: DecodeError) -> Result<Frame, DecodeError> {
        self.counters.rejected[error.rejection() as usize] += 1;
        Err(error)
    }

    fn finish(&mut self) -> Result<Frame, DecodeError> {
        let len = self.len;
        if len < 4 {
            return self.reject(DecodeError::TooShort { len });
        }
        let (covered, crc) = self.body[..len].split_at(len - 2);
        if CRC.checksum(covered) != u16::from_le_bytes([crc[0], crc[1]]) {
            return self.reject(DecodeError::BadCrc);
        }
        let (client_id, opcode, data) = (covered[0], covered[1], &covered[2..]);
        match Message::parse(opcode, data) {
            Ok(message) => {
                self.counters.frames += 1;
                Ok(Frame { client_id, message })
            }
            Err(e) => {
                let error = match e {
                    PayloadError::UnknownOpcode => DecodeError::UnknownOpcode { client_id, opcode },
                    PayloadError::BadLength => DecodeError::BadLength {
                        client_id,
                        opcode,
                        data_len: data.len(),
                    },
                    PayloadError::NonFinite => DecodeError::NonFinite { client_id, opcode },
                    PayloadError::BadValue => DecodeError::BadValue { client_id, opcode },
                };
                self.reject(error)
            }
        }
    }
}

/// Decodes the first frame of `bytes` with a fresh decoder: its outcome, or `None` if no frame
/// ends in `bytes`. For a datagram that holds one frame.
pub fn decode(bytes: &[u8]) -> Option<Result<Frame, DecodeError>> {
    let mut decoder = Decoder::new();
    bytes.iter().find_map(|&b| decoder.push(b))
}
