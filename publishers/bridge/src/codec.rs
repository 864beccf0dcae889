//! The bytes a bridge and its mirrors exchange over Zenoh (docs/mirror-wire.md): every message is
//! an envelope (magic, version, kind, flags, origin epoch, sequence, body length, XXH3-64 of the
//! body) followed by its body. A message whose envelope or checksum does not hold is rejected
//! whole, with an error naming what was wrong.

use pheromone_field::messages::InputsHeader;
use pheromone_field::shm::wire_vec_from_bytes;
use pheromone_field::shm::{f32s_from_bytes, wire_bytes, wire_from_bytes, wire_slice_bytes};
use pheromone_field::{DepositMsg, FrameHeader};
use xxhash_rust::xxh3::xxh3_64;

/// First bytes of every message.
pub const MAGIC: [u8; 4] = *b"PHMR";
/// Version of the envelope and of every body; a mirror refuses any other.
pub const VERSION: u8 = 1;
/// Bytes of the envelope.
pub const ENVELOPE_BYTES: usize = 40;
/// Flag: the body's payload part is zstd-compressed.
pub const FLAG_ZSTD: u16 = 1;
/// zstd level of keyframes and frames: level 1 is the fastest and already removes the zeros and
/// smooth gradients of a pheromone field.
pub const ZSTD_LEVEL: i32 = 1;
/// Largest decompressed keyframe or frame accepted (the field's own limit).
pub const MAX_DECOMPRESSED_BYTES: usize = pheromone_field::engine::MAX_FRAME_BYTES as usize;

/// What a message carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Kind {
    /// One frame's inputs: `InputsHeader` + the deposits applied, in order.
    Inputs = 1,
    /// The field's configuration, TOML.
    Config = 2,
    /// XXH3-64 of one frame's cells (u64) and the interval in frames (u32) + 4 zero bytes.
    Checksum = 3,
    /// A whole frame: `FrameHeader` + zstd of the cells (little-endian f32).
    Keyframe = 4,
    /// Deposits made on a mirror's host, for the origin: n × `DepositMsg`. Envelope epoch: the
    /// sending mirror's id; sequence: the batch's number in that mirror's run (from 1).
    Deposit = 5,
    /// A downsampled frame for consumers without a mirror: width, height, channels, downsample
    /// (4 × u32), then zstd of the cells (f32 little-endian, channel-major).
    Frame = 6,
    /// The bridge's answer to a deposit batch (envelope epoch and sequence: the mirror id and
    /// batch number it answers): deposits handed to the origin's field (u32), refused (u32).
    DepositAck = 7,
}

impl Kind {
    fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            1 => Kind::Inputs,
            2 => Kind::Config,
            3 => Kind::Checksum,
            4 => Kind::Keyframe,
            5 => Kind::Deposit,
            6 => Kind::Frame,
            7 => Kind::DepositAck,
            _ => return None,
        })
    }
}

/// Why a message was rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CodecError {
    #[error("message of {0} bytes is shorter than the {ENVELOPE_BYTES}-byte envelope")]
    Short(usize),
    #[error("bad magic {0:02x?} (expected \"PHMR\")")]
    Magic([u8; 4]),
    #[error("envelope version {0}, this build speaks {VERSION}")]
    Version(u8),
    #[error("unknown message kind {0}")]
    Kind(u8),
    #[error("expected a {expected:?} message, got {got:?}")]
    WrongKind { expected: Kind, got: Kind },
    #[error("body length {said} in the envelope, {got} bytes follow")]
    Length { said: u32, got: usize },
    #[error("body checksum {got:016x} does not match the envelope's {said:016x}")]
    Checksum { said: u64, got: u64 },
    #[error("{kind:?} body: {detail}")]
    Body { kind: Kind, detail: String },
    #[error("unknown envelope flags {0:#06x} (only bit 0, zstd, is defined)")]
    Flags(u16),
    #[error("envelope bytes 28..32 are {0:#010x}, must be 0")]
    Reserved(u32),
}

/// A checked envelope and its body.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Message<'a> {
    pub kind: Kind,
    pub flags: u16,
    /// The origin field's run (`InputsHeader::epoch`): a restarted origin has another.
    pub epoch: u64,
    pub sequence: u64,
    pub body: &'a [u8],
}

/// Wraps `body` in an envelope.
pub fn encode(kind: Kind, flags: u16, epoch: u64, sequence: u64, body: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(ENVELOPE_BYTES + body.len());
    out.extend_from_slice(&MAGIC);
    out.push(VERSION);
    out.push(kind as u8);
    out.extend_from_slice(&flags.to_le_bytes());
    out.extend_from_slice(&epoch.to_le_bytes());
    out.extend_from_slice(&sequence.to_le_bytes());
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&xxh3_64(body).to_le_bytes());
    out.extend_from_slice(body);
    out
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

/// Checks the envelope (magic, version, kind, length, checksum) and returns the message.
pub fn decode(bytes: &[u8]) -> Result<Message<'_>, CodecError> {
    if bytes.len() < ENVELOPE_BYTES {
        return Err(CodecError::Short(bytes.len()));
    }
    let magic: [u8; 4] = bytes[..4].try_into().expect("4 bytes");
    if magic != MAGIC {
        return Err(CodecError::Magic(magic));
    }
    if bytes[4] != VERSION {
        return Err(CodecError::Version(bytes[4]));
    }
    let kind = Kind::from_u8(bytes[5]).ok_or(CodecError::Kind(bytes[5]))?;
    let flags = u16::from_le_bytes([bytes[6], bytes[7]]);
    if flags & !FLAG_ZSTD != 0 {
        return Err(CodecError::Flags(flags));
    }
    let reserved = u32_at(bytes, 28);
    if reserved != 0 {
        return Err(CodecError::Reserved(reserved));
    }
    let said = u32_at(bytes, 24);
    let body = &bytes[ENVELOPE_BYTES..];
    if said as usize != body.len() {
        return Err(CodecError::Length {
            said,
            got: body.len(),
        });
    }
    let sum = u64_at(bytes, 32);
    let got = xxh3_64(body);
    if sum != got {
        return Err(CodecError::Checksum { said: sum, got });
    }
    Ok(Message {
        kind,
        flags,
        epoch: u64_at(bytes, 8),
        sequence: u64_at(bytes, 16),
        body,
    })
}

/// As `decode`, requiring kind `expected`.
pub fn decode_kind(bytes: &[u8], expected: Kind) -> Result<Message<'_>, CodecError> {
    let m = decode(bytes)?;
    if m.kind != expected {
        return Err(CodecError::WrongKind {
            expected,
            got: m.kind,
        });
    }
    Ok(m)
}

fn body_err(kind: Kind, detail: impl Into<String>) -> CodecError {
    CodecError::Body {
        kind,
        detail: detail.into(),
    }
}

/// XXH3-64 of a frame's cells (their bytes in memory: little-endian f32 on every supported
/// architecture).
pub fn frame_checksum(cells: &[f32]) -> u64 {
    xxh3_64(wire_slice_bytes(cells))
}

pub fn encode_inputs(header: &InputsHeader, deposits: &[DepositMsg]) -> Vec<u8> {
    let mut body = Vec::with_capacity(64 * (deposits.len() + 1));
    body.extend_from_slice(wire_bytes(header));
    body.extend_from_slice(wire_slice_bytes(deposits));
    encode(Kind::Inputs, 0, header.epoch, header.sequence, &body)
}

pub fn decode_inputs(bytes: &[u8]) -> Result<(InputsHeader, Vec<DepositMsg>), CodecError> {
    let m = decode_kind(bytes, Kind::Inputs)?;
    let n = std::mem::size_of::<InputsHeader>();
    let header: InputsHeader =
        wire_from_bytes(m.body).ok_or_else(|| body_err(Kind::Inputs, "shorter than its header"))?;
    let deposits: Vec<DepositMsg> = wire_vec_from_bytes(&m.body[n..])
        .ok_or_else(|| body_err(Kind::Inputs, "deposits are not whole 64-byte messages"))?;
    if deposits.len() != header.count as usize
        || header.sequence != m.sequence
        || header.epoch != m.epoch
    {
        return Err(body_err(
            Kind::Inputs,
            format!(
                "header says {} deposits, seq {}, epoch {:x}; the message has {}, seq {}, epoch {:x}",
                header.count,
                header.sequence,
                header.epoch,
                deposits.len(),
                m.sequence,
                m.epoch
            ),
        ));
    }
    if !(header.dt_s.is_finite() && header.dt_s > 0.0 && header.dt_time_s.is_finite()) {
        return Err(body_err(Kind::Inputs, format!("bad dt_s {}", header.dt_s)));
    }
    Ok((header, deposits))
}

pub fn encode_config(epoch: u64, toml: &str) -> Vec<u8> {
    encode(Kind::Config, 0, epoch, 0, toml.as_bytes())
}

pub fn decode_config(bytes: &[u8]) -> Result<(u64, String), CodecError> {
    let m = decode_kind(bytes, Kind::Config)?;
    let text = std::str::from_utf8(m.body)
        .map_err(|e| body_err(Kind::Config, format!("not UTF-8: {e}")))?;
    Ok((m.epoch, text.to_string()))
}

pub fn encode_checksum(epoch: u64, sequence: u64, checksum: u64, every: u32) -> Vec<u8> {
    let mut body = Vec::with_capacity(16);
    body.extend_from_slice(&checksum.to_le_bytes());
    body.extend_from_slice(&every.to_le_bytes());
    body.extend_from_slice(&0u32.to_le_bytes());
    encode(Kind::Checksum, 0, epoch, sequence, &body)
}

/// (epoch, sequence, checksum, every).
pub fn decode_checksum(bytes: &[u8]) -> Result<(u64, u64, u64, u32), CodecError> {
    let m = decode_kind(bytes, Kind::Checksum)?;
    if m.body.len() != 16 {
        return Err(body_err(
            Kind::Checksum,
            format!("{} bytes, not 16", m.body.len()),
        ));
    }
    Ok((
        m.epoch,
        m.sequence,
        u64_at(m.body, 0),
        u32_at(m.body, 8).max(1),
    ))
}

fn compress(bytes: &[u8]) -> Vec<u8> {
    // Compressing into memory fails only on allocation failure.
    zstd::bulk::compress(bytes, ZSTD_LEVEL).expect("zstd compresses into memory")
}

fn decompress(kind: Kind, bytes: &[u8], expected: usize) -> Result<Vec<u8>, CodecError> {
    if expected > MAX_DECOMPRESSED_BYTES {
        return Err(body_err(
            kind,
            format!("{expected} bytes exceed the frame limit"),
        ));
    }
    let out = zstd::bulk::decompress(bytes, expected)
        .map_err(|e| body_err(kind, format!("zstd: {e}")))?;
    if out.len() != expected {
        return Err(body_err(
            kind,
            format!("{} bytes decompressed, {expected} expected", out.len()),
        ));
    }
    Ok(out)
}

pub fn encode_keyframe(epoch: u64, header: &FrameHeader, cells: &[f32]) -> Vec<u8> {
    let mut body = Vec::new();
    body.extend_from_slice(wire_bytes(header));
    body.extend_from_slice(&compress(wire_slice_bytes(cells)));
    encode(Kind::Keyframe, FLAG_ZSTD, epoch, header.sequence, &body)
}

/// (epoch, header, cells); the cells are finite and as many as the header says.
pub fn decode_keyframe(bytes: &[u8]) -> Result<(u64, FrameHeader, Vec<f32>), CodecError> {
    let m = decode_kind(bytes, Kind::Keyframe)?;
    let n = std::mem::size_of::<FrameHeader>();
    let header: FrameHeader = wire_from_bytes(m.body)
        .ok_or_else(|| body_err(Kind::Keyframe, "shorter than its header"))?;
    if header.sequence != m.sequence
        || header.layout_version != pheromone_field::wire::LAYOUT_VERSION
    {
        return Err(body_err(
            Kind::Keyframe,
            format!(
                "header seq {} layout v{} (message seq {}, this build v{})",
                header.sequence,
                header.layout_version,
                m.sequence,
                pheromone_field::wire::LAYOUT_VERSION
            ),
        ));
    }
    let len = header.len();
    let raw = decompress(Kind::Keyframe, &m.body[n..], len * 4)?;
    let cells = f32s_from_bytes(&raw).expect("a multiple of 4 bytes");
    if let Some(i) = cells.iter().position(|v| !v.is_finite()) {
        return Err(body_err(
            Kind::Keyframe,
            format!("cell {i} is {}", cells[i]),
        ));
    }
    Ok((m.epoch, header, cells))
}

/// A batch of a mirror's deposits: `mirror_id` (nonzero, one per mirror run) and `batch` (its
/// number, from 1) let the bridge answer it and apply a batch sent again only once.
pub fn encode_deposits(mirror_id: u64, batch: u64, deposits: &[DepositMsg]) -> Vec<u8> {
    encode(
        Kind::Deposit,
        0,
        mirror_id,
        batch,
        wire_slice_bytes(deposits),
    )
}

/// A deposit batch: (mirror id, batch number, deposits). Id 0 is a sender that wants no answer.
pub fn decode_deposits(bytes: &[u8]) -> Result<(u64, u64, Vec<DepositMsg>), CodecError> {
    let m = decode_kind(bytes, Kind::Deposit)?;
    let deposits = wire_vec_from_bytes(m.body)
        .ok_or_else(|| body_err(Kind::Deposit, "not whole 64-byte deposit messages"))?;
    Ok((m.epoch, m.sequence, deposits))
}

/// What the bridge did with one batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DepositAck {
    pub mirror_id: u64,
    pub batch: u64,
    /// Handed to the origin's field (now, or when the batch first came).
    pub forwarded: u32,
    /// Refused by the origin's deposit service (no field, or its queue refused them).
    pub refused: u32,
}

pub fn encode_deposit_ack(a: &DepositAck) -> Vec<u8> {
    let mut body = Vec::with_capacity(8);
    body.extend_from_slice(&a.forwarded.to_le_bytes());
    body.extend_from_slice(&a.refused.to_le_bytes());
    encode(Kind::DepositAck, 0, a.mirror_id, a.batch, &body)
}

pub fn decode_deposit_ack(bytes: &[u8]) -> Result<DepositAck, CodecError> {
    let m = decode_kind(bytes, Kind::DepositAck)?;
    if m.body.len() != 8 {
        return Err(body_err(
            Kind::DepositAck,
            format!("{} bytes, expected 8", m.body.len()),
        ));
    }
    Ok(DepositAck {
        mirror_id: m.epoch,
        batch: m.sequence,
        forwarded: u32_at(m.body, 0),
        refused: u32_at(m.body, 4),
    })
}

/// A frame for dashboards: `cells` (channel-major, `width × height` per channel) averaged over
/// `downsample × downsample` blocks (the last block of a row or column may be smaller).
pub fn encode_frame(epoch: u64, header: &FrameHeader, cells: &[f32], downsample: u32) -> Vec<u8> {
    let (w, h, c) = (
        header.width as usize,
        header.height as usize,
        header.channels as usize,
    );
    let d = downsample.max(1) as usize;
    let (ow, oh) = (w.div_ceil(d), h.div_ceil(d));
    let mut out = Vec::with_capacity(ow * oh * c * 4);
    for ch in 0..c {
        let plane = &cells[ch * w * h..(ch + 1) * w * h];
        for by in 0..oh {
            for bx in 0..ow {
                let (mut sum, mut n) = (0.0f64, 0u32);
                for y in by * d..((by + 1) * d).min(h) {
                    for x in bx * d..((bx + 1) * d).min(w) {
                        sum += plane[y * w + x] as f64;
                        n += 1;
                    }
                }
                out.extend_from_slice(&((sum / n as f64) as f32).to_le_bytes());
            }
        }
    }
    let mut body = Vec::with_capacity(16 + out.len() / 4);
    for v in [ow as u32, oh as u32, c as u32, d as u32] {
        body.extend_from_slice(&v.to_le_bytes());
    }
    body.extend_from_slice(&compress(&out));
    encode(Kind::Frame, FLAG_ZSTD, epoch, header.sequence, &body)
}

/// A decoded `Frame` message: size after downsampling and the cells.
#[derive(Debug, Clone, PartialEq)]
pub struct DownsampledFrame {
    pub sequence: u64,
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub downsample: u32,
    pub cells: Vec<f32>,
}

pub fn decode_frame(bytes: &[u8]) -> Result<DownsampledFrame, CodecError> {
    let m = decode_kind(bytes, Kind::Frame)?;
    if m.body.len() < 16 {
        return Err(body_err(Kind::Frame, "shorter than its 16-byte header"));
    }
    let (width, height, channels, downsample) = (
        u32_at(m.body, 0),
        u32_at(m.body, 4),
        u32_at(m.body, 8),
        u32_at(m.body, 12),
    );
    let len = width as usize * height as usize * channels as usize;
    let raw = decompress(Kind::Frame, &m.body[16..], len * 4)?;
    Ok(DownsampledFrame {
        sequence: m.sequence,
        width,
        height,
        channels,
        downsample,
        cells: f32s_from_bytes(&raw).expect("a multiple of 4 bytes"),
    })
}
