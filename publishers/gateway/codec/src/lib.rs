//! Seed 002's DLE/CRC frames: the wire contract of MODELS.md M3, as a pure codec.
//!
//! No I/O, no allocation, `#![no_std]`: a thin client on a microcontroller can link it, and the
//! gateway process uses the same code. The full contract, with a hex test vector per opcode, is
//! `docs/gateway-wire.md`; `tests/vectors.rs` checks those bytes.
//!
//! # Frame
//!
//! ```text
//! 0x10 0x02 | CLIENT ID u8 | OPCODE u8 | DATA | CRC lo, CRC hi | 0x10 0x03
//! ```
//!
//! The *body* is everything between the delimiters: client ID, opcode, DATA and CRC. Every 0x10 of
//! the body is sent twice (DLE stuffing). The CRC is CRC-16/ARC ([`crc::CRC_16_ARC`]: poly 0x8005
//! reflected, init 0x0000, no final xor; check value 0xBB3D) over the unstuffed client ID, opcode
//! and DATA, sent little-endian. Numbers in DATA are little-endian, `f32` is IEEE 754 binary32.
//! A reply carries the client's ID and the request's opcode `| 0x80`.
//!
//! | op | DATA | bytes |
//! |---|---|---|
//! | `0x01` PIR | `x_m` f32, `y_m` f32, `theta_rad` f32, `half_wheel_base_m` f32, `channel` u8 | 17 |
//! | `0x81` PIR reply | `p_left` f32, `p_right` f32, `frame_seq` u32 | 12 |
//! | `0x02` DEPOSIT | `seq` u8, `x_m` f32, `y_m` f32, `amount` f32, `channel` u8 | 14 |
//! | `0x82` deposit reply | `seq` u8, `status` u8 | 2 |
//! | `0x03` PING | — | 0 |
//! | `0x83` status | `frame_seq` u32, `field_time_s` f32, `channels` u8 | 9 |
//! | `0xFF` error | `reason` u8 | 1 |
//!
//! # Decisions where M3 is silent
//!
//! - **Frame bound.** M3 bounds a frame at 255 unstuffed body bytes; the body is, as in the paper,
//!   client ID, opcode, DATA *and* CRC ([`MAX_FRAME_BYTES`] = 255, so DATA ≤ 251). The decoder
//!   keeps bodies up to that bound (not just up to the longest message), so a frame of a wrong
//!   length with a valid CRC is answered as M3 asks (reason 2), not dropped as too long.
//! - **Lengths are exact.** DATA must be exactly the opcode's length; shorter or longer is
//!   [`Rejection::BadLength`].
//! - **Values.** Every `f32` must be finite ([`Rejection::NonFinite`], reply reason 3); the codec
//!   checks no ranges (the field's extent, its channels and its limits are the server's to check,
//!   with reasons 3 and 4). The error reason must be 1–6 and the deposit status 0–6, else
//!   [`Rejection::BadValue`] (reply reason 3).
//! - **Deposit status.** 0 = applied or queued (also the answer to a retry whose `seq` was already
//!   applied); a non-zero status is an [`ErrorReason`] code (3 out of range, 4 unknown channel,
//!   5 rate limited, 6 client not allowed).
//! - **Client IDs.** All 256 values are valid frames, 0x10 included (it is stuffed); which IDs are
//!   served is the server's allow-list, which should not hold 0x00: CRC-16/ARC's zero initial
//!   value leaves a leading 0x00 of the body unprotected (one inserted after DLE STX, or a leading
//!   client ID 0x00 deleted, keeps the CRC valid), and every such confusion involves ID 0x00.
//! - **Both directions decode.** The decoder returns requests and replies alike; a server that
//!   receives a reply opcode, or a client that receives a request, decides what to do with it.
//! - **Framing errors.** Inside a frame, DLE STX drops the partial frame ([`Rejection::Truncated`])
//!   and starts a new one; DLE followed by a byte other than DLE, STX, ETX is
//!   [`Rejection::StrayDle`]; DLE ETX before 4 body bytes is [`Rejection::TooShort`]. None of these
//!   (nor a bad CRC) gets a reply: [`DecodeError::reply`] says which rejections do.
//! - **Between frames** any bytes are skipped; a run of DLEs followed by STX starts a frame.
//!
//! # Use
//!
//! ```
//! use pheromone_gateway_codec::{decode, encode, Decoder, Message, PirRequest, MAX_ENCODED_BYTES};
//!
//! let pir = Message::Pir(PirRequest {
//!     x_m: 1.5,
//!     y_m: -2.0,
//!     theta_rad: 0.25,
//!     half_wheel_base_m: 0.1,
//!     channel: 0,
//! });
//! let mut buf = [0u8; MAX_ENCODED_BYTES];
//! let n = encode(&pir, 0x10, &mut buf).unwrap();
//!
//! // A datagram holds one frame:
//! let frame = decode(&buf[..n]).unwrap().unwrap();
//! assert_eq!((frame.client_id, frame.message), (0x10, pir));
//!
//! // A serial line delivers a few bytes at a time:
//! let mut decoder = Decoder::new();
//! let mut got = None;
//! for chunk in buf[..n].chunks(3) {
//!     decoder.feed(chunk, |outcome| got = Some(outcome));
//! }
//! assert_eq!(got.unwrap().unwrap().message, pir);
//! assert_eq!(decoder.counters().frames, 1);
//! ```
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

mod decode;
mod encode;
mod message;

pub use decode::{decode, Counters, DecodeError, Decoder, Frame, Rejection, REJECTIONS};
pub use encode::{encode, encoded_len, EncodeError};
pub use message::{
    data_len, opcode, DepositReply, DepositRequest, DepositStatus, ErrorReason, Message, PirReply,
    PirRequest, StatusReply,
};

/// Data link escape: starts a delimiter; inside the body it is sent twice.
pub const DLE: u8 = 0x10;
/// Start of text: `DLE STX` starts a frame.
pub const STX: u8 = 0x02;
/// End of text: `DLE ETX` ends a frame.
pub const ETX: u8 = 0x03;

/// The longest frame the decoder accepts, counted as M3 counts it: unstuffed body bytes (client
/// ID, opcode, DATA, CRC), without the delimiters and the stuffing. A longer one is rejected
/// ([`Rejection::TooLong`]).
pub const MAX_FRAME_BYTES: usize = 255;

/// The longest frame of [`MAX_FRAME_BYTES`] on the wire: delimiters, and every body byte a DLE.
pub const MAX_WIRE_BYTES: usize = 4 + 2 * MAX_FRAME_BYTES;

/// A buffer this long holds any frame [`encode`] writes: the longest message's body (client ID,
/// opcode, 17 bytes of PIR data, CRC) with every byte stuffed, and the delimiters.
pub const MAX_ENCODED_BYTES: usize = 4 + 2 * (2 + data_len::MAX + 2);

/// CRC-16/ARC, computed over the unstuffed client ID, opcode and DATA.
pub const CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_ARC);
