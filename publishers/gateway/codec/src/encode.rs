//! The encoder: a message and a client ID into one stuffed frame in the caller's buffer.

use core::fmt;

use crate::message::{data_len, Message};
use crate::{CRC, DLE, ETX, STX};

/// Why [`encode`] wrote no frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncodeError {
    /// The buffer is shorter than the frame; `needed` bytes would have been enough.
    BufferTooSmall {
        /// Length of the whole stuffed frame.
        needed: usize,
    },
    /// A number of the message is NaN or infinite: the decoder would reject the frame.
    NonFinite,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::BufferTooSmall { needed } => {
                write!(f, "buffer too small for the frame ({needed} bytes needed)")
            }
            EncodeError::NonFinite => f.write_str("a number of the message is not finite"),
        }
    }
}

impl core::error::Error for EncodeError {}

/// The unstuffed body of a message: client ID, opcode, DATA, CRC (little-endian).
struct Body {
    bytes: [u8; 2 + data_len::MAX + 2],
    len: usize,
}

impl Body {
    fn new(message: &Message, client_id: u8) -> Body {
        let mut bytes = [0u8; 2 + data_len::MAX + 2];
        bytes[0] = client_id;
        bytes[1] = message.opcode();
        let data_end = 2 + message.data_len();
        message.write_data(&mut bytes[2..]);
        let crc = CRC.checksum(&bytes[..data_end]);
        bytes[data_end..data_end + 2].copy_from_slice(&crc.to_le_bytes());
        Body {
            bytes,
            len: data_end + 2,
        }
    }

    fn as_slice(&self) -> &[u8] {
        &self.bytes[..self.len]
    }

    /// Length on the wire: the delimiters, and each DLE of the body twice.
    fn frame_len(&self) -> usize {
        let dles = self.as_slice().iter().filter(|&&b| b == DLE).count();
        4 + self.len + dles
    }
}

/// Encodes `message` from (or to) `client_id` as one frame into `out`, and returns the frame's
/// length: `DLE STX | client_id | opcode | DATA | CRC lo, CRC hi | DLE ETX`, every DLE between the
/// delimiters doubled, the CRC-16/ARC computed over the unstuffed client ID, opcode and DATA.
///
/// A buffer of [`crate::MAX_ENCODED_BYTES`] always suffices. Nothing is allocated; on an error
/// `out` is left untouched.
pub fn encode(message: &Message, client_id: u8, out: &mut [u8]) -> Result<usize, EncodeError> {
    if !message.is_finite() {
        return Err(EncodeError::NonFinite);
    }
    let body = Body::new(message, client_id);
    let needed = body.frame_len();
    if out.len() < needed {
        return Err(EncodeError::BufferTooSmall { needed });
    }
    out[0] = DLE;
    out[1] = STX;
    let mut at = 2;
    for &byte in body.as_slice() {
        out[at] = byte;
        at += 1;
        if byte == DLE {
            out[at] = DLE;
            at += 1;
        }
    }
    out[at] = DLE;
    out[at + 1] = ETX;
    at += 2;
    debug_assert_eq!(at, needed);
    Ok(at)
}

/// Length of the frame [`encode`] would write for `message` and `client_id` (stuffing included).
pub fn encoded_len(message: &Message, client_id: u8) -> usize {
    Body::new(message, client_id).frame_len()
}
