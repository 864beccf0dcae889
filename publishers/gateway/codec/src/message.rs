//! The typed messages of MODELS.md M3 and their DATA layouts.
//!
//! Every number is little-endian; every `f32` is IEEE 754 binary32 and must be finite (a non-finite
//! value is refused by the encoder and rejected by the decoder, so it never reaches the field).

/// The opcodes of MODELS.md M3. A reply carries the request's opcode with
/// [`REPLY_BIT`](opcode::REPLY_BIT) set.
pub mod opcode {
    /// Pheromone information request (client → server).
    pub const PIR: u8 = 0x01;
    /// Deposit (client → server).
    pub const DEPOSIT: u8 = 0x02;
    /// Ping (client → server).
    pub const PING: u8 = 0x03;
    /// Set on a request's opcode to make its reply's opcode.
    pub const REPLY_BIT: u8 = 0x80;
    /// The antenna readings (server → client), answers [`PIR`].
    pub const PIR_REPLY: u8 = PIR | REPLY_BIT;
    /// The deposit's outcome (server → client), answers [`DEPOSIT`].
    pub const DEPOSIT_REPLY: u8 = DEPOSIT | REPLY_BIT;
    /// The server's status (server → client), answers [`PING`].
    pub const STATUS: u8 = PING | REPLY_BIT;
    /// An error reply with a reason (server → client), answers any invalid frame with a valid CRC.
    pub const ERROR: u8 = 0xFF;
}

/// Length of each opcode's DATA, in bytes.
pub mod data_len {
    /// [`super::PirRequest`]: four `f32` and a `u8`.
    pub const PIR: usize = 17;
    /// [`super::PirReply`]: two `f32` and a `u32`.
    pub const PIR_REPLY: usize = 12;
    /// [`super::DepositRequest`]: a `u8`, three `f32` and a `u8`.
    pub const DEPOSIT: usize = 14;
    /// [`super::DepositReply`]: two `u8`.
    pub const DEPOSIT_REPLY: usize = 2;
    /// Ping: no data.
    pub const PING: usize = 0;
    /// [`super::StatusReply`]: a `u32`, an `f32` and a `u8`.
    pub const STATUS: usize = 9;
    /// Error reply: the reason `u8`.
    pub const ERROR: usize = 1;
    /// The longest DATA of any message.
    pub const MAX: usize = PIR;
}

/// `0x01` PIR: the client's pose and half wheel base; the server answers with the readings of the
/// two virtual antennas at `(x, y) ± half_wheel_base_m · (−sin θ, cos θ)` (left is `+`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PirRequest {
    /// Robot position, world x, metres.
    pub x_m: f32,
    /// Robot position, world y, metres.
    pub y_m: f32,
    /// Robot heading, radians, counter-clockwise from world +x.
    pub theta_rad: f32,
    /// Half the wheel base b/2: the distance of each antenna from the robot's centre, metres
    /// (M3's `half_base_m`).
    pub half_wheel_base_m: f32,
    /// Pheromone channel (plane) to read.
    pub channel: u8,
}

/// `0x81` PIR reply: the two antenna readings, in the field's units, and the frame they were read
/// from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PirReply {
    /// Reading of the left antenna (M3's `p_left`), field units.
    pub p_left: f32,
    /// Reading of the right antenna (M3's `p_right`), field units.
    pub p_right: f32,
    /// Sequence number of the field frame the readings come from.
    pub frame_seq: u32,
}

/// `0x02` DEPOSIT: add `amount` at `(x, y)` on `channel`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepositRequest {
    /// Per-client sequence number: a retried deposit carries the same `seq` and is applied at most
    /// once (the server remembers the last 16 per client).
    pub seq: u8,
    /// Deposit position, world x, metres.
    pub x_m: f32,
    /// Deposit position, world y, metres.
    pub y_m: f32,
    /// Amount to deposit, field units.
    pub amount: f32,
    /// Pheromone channel (plane) to deposit on.
    pub channel: u8,
}

/// `0x82` deposit reply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DepositReply {
    /// The request's `seq`.
    pub seq: u8,
    /// What became of the deposit.
    pub status: DepositStatus,
}

/// `0x83` status reply to a ping.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StatusReply {
    /// Sequence number of the newest field frame.
    pub frame_seq: u32,
    /// The field's simulated time, seconds.
    pub field_time_s: f32,
    /// Number of channels (planes) of the field.
    pub channels: u8,
}

/// The reason codes of the `0xFF` error reply (MODELS.md M3), also used as the non-zero status of
/// a deposit reply.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ErrorReason {
    /// 1: the opcode is not one of M3's requests.
    UnknownOpcode = 1,
    /// 2: the DATA length does not match the opcode.
    BadLength = 2,
    /// 3: a number is non-finite or out of range.
    BadValue = 3,
    /// 4: the channel names no channel of the field.
    UnknownChannel = 4,
    /// 5: the client sent more than its rate limit allows.
    RateLimited = 5,
    /// 6: the client ID is not on the server's allow-list.
    ClientNotAllowed = 6,
}

impl ErrorReason {
    /// Every reason, in code order.
    pub const ALL: [ErrorReason; 6] = [
        ErrorReason::UnknownOpcode,
        ErrorReason::BadLength,
        ErrorReason::BadValue,
        ErrorReason::UnknownChannel,
        ErrorReason::RateLimited,
        ErrorReason::ClientNotAllowed,
    ];

    /// The byte sent on the wire.
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// The reason of a wire byte; `None` for a code M3 does not define (0 or above 6).
    pub const fn from_code(code: u8) -> Option<ErrorReason> {
        match code {
            1 => Some(ErrorReason::UnknownOpcode),
            2 => Some(ErrorReason::BadLength),
            3 => Some(ErrorReason::BadValue),
            4 => Some(ErrorReason::UnknownChannel),
            5 => Some(ErrorReason::RateLimited),
            6 => Some(ErrorReason::ClientNotAllowed),
            _ => None,
        }
    }
}

/// The status byte of a deposit reply: 0 = applied or queued, else an [`ErrorReason`] code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DepositStatus {
    /// 0: applied or queued (also the answer to a retry of a deposit already applied).
    Applied,
    /// The deposit was not applied, for this reason.
    Rejected(ErrorReason),
}

impl DepositStatus {
    /// The byte sent on the wire.
    pub const fn code(self) -> u8 {
        match self {
            DepositStatus::Applied => 0,
            DepositStatus::Rejected(reason) => reason.code(),
        }
    }

    /// The status of a wire byte; `None` for an undefined code (above 6).
    pub const fn from_code(code: u8) -> Option<DepositStatus> {
        if code == 0 {
            return Some(DepositStatus::Applied);
        }
        match ErrorReason::from_code(code) {
            Some(reason) => Some(DepositStatus::Rejected(reason)),
            None => None,
        }
    }
}

/// One message of MODELS.md M3, request or reply.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Message {
    /// `0x01` pheromone information request.
    Pir(PirRequest),
    /// `0x81` the antenna readings.
    PirReply(PirReply),
    /// `0x02` deposit.
    Deposit(DepositRequest),
    /// `0x82` the deposit's outcome.
    DepositReply(DepositReply),
    /// `0x03` ping (no data).
    Ping,
    /// `0x83` the server's status.
    Status(StatusReply),
    /// `0xFF` error reply.
    Error(ErrorReason),
}

/// Why a DATA field could not be turned into a message (the frame's CRC was valid).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PayloadError {
    UnknownOpcode,
    BadLength,
    NonFinite,
    BadValue,
}

impl Message {
    /// The message's opcode.
    pub const fn opcode(&self) -> u8 {
        match self {
            Message::Pir(_) => opcode::PIR,
            Message::PirReply(_) => opcode::PIR_REPLY,
            Message::Deposit(_) => opcode::DEPOSIT,
            Message::DepositReply(_) => opcode::DEPOSIT_REPLY,
            Message::Ping => opcode::PING,
            Message::Status(_) => opcode::STATUS,
            Message::Error(_) => opcode::ERROR,
        }
    }

    /// Whether the message goes from the server to a client (its opcode has [`opcode::REPLY_BIT`]).
    pub const fn is_reply(&self) -> bool {
        self.opcode() & opcode::REPLY_BIT != 0
    }

    /// Length of the message's DATA, in bytes.
    pub const fn data_len(&self) -> usize {
        match self {
            Message::Pir(_) => data_len::PIR,
            Message::PirReply(_) => data_len::PIR_REPLY,
            Message::Deposit(_) => data_len::DEPOSIT,
            Message::DepositReply(_) => data_len::DEPOSIT_REPLY,
            Message::Ping => data_len::PING,
            Message::Status(_) => data_len::STATUS,
            Message::Error(_) => data_len::ERROR,
        }
    }

    /// Whether every `f32` of the message is finite.
    pub fn is_finite(&self) -> bool {
        match self {
            Message::Pir(m) => [m.x_m, m.y_m, m.theta_rad, m.half_wheel_base_m]
                .iter()
                .all(|v| v.is_finite()),
            Message::PirReply(m) => m.p_left.is_finite() && m.p_right.is_finite(),
            Message::Deposit(m) => [m.x_m, m.y_m, m.amount].iter().all(|v| v.is_finite()),
            Message::Status(m) => m.field_time_s.is_finite(),
            Message::DepositReply(_) | Message::Ping | Message::Error(_) => true,
        }
    }

    /// Writes the DATA into `out[..self.data_len()]` (`out` is at least [`data_len::MAX`] long).
    pub(crate) fn write_data(&self, out: &mut [u8]) {
        let mut w = Writer { out, at: 0 };
        match self {
            Message::Pir(m) => {
                w.f32(m.x_m);
                w.f32(m.y_m);
                w.f32(m.theta_rad);
                w.f32(m.half_wheel_base_m);
                w.u8(m.channel);
            }
            Message::PirReply(m) => {
                w.f32(m.p_left);
                w.f32(m.p_right);
                w.u32(m.frame_seq);
            }
            Message::Deposit(m) => {
                w.u8(m.seq);
                w.f32(m.x_m);
                w.f32(m.y_m);
                w.f32(m.amount);
                w.u8(m.channel);
            }
            Message::DepositReply(m) => {
                w.u8(m.seq);
                w.u8(m.status.code());
            }
            Message::Ping => {}
            Message::Status(m) => {
                w.u32(m.frame_seq);
                w.f32(m.field_time_s);
                w.u8(m.channels);
            }
            Message::Error(reason) => w.u8(reason.code()),
        }
        debug_assert_eq!(w.at, self.data_len());
    }

    /// Parses the DATA of `opcode`: the opcode must be M3's, the length exactly the opcode's,
    /// every `f32` finite and every code defined.
    pub(crate) fn parse(opcode: u8, data: &[u8]) -> Result<Message, PayloadError> {
        let expected = match opcode {
            opcode::PIR => data_len::PIR,
            opcode::PIR_REPLY => data_len::PIR_REPLY,
            opcode::DEPOSIT => data_len::DEPOSIT,
            opcode::DEPOSIT_REPLY => data_len::DEPOSIT_REPLY,
            opcode::PING => data_len::PING,
            opcode::STATUS => data_len::STATUS,
            opcode::ERROR => data_len::ERROR,
            _ => return Err(PayloadError::UnknownOpcode),
        };
        if data.len() != expected {
            return Err(PayloadError::BadLength);
        }
        let mut r = Reader { data, at: 0 };
        let message = match opcode {
            opcode::PIR => Message::Pir(PirRequest {
                x_m: r.f32()?,
                y_m: r.f32()?,
                theta_rad: r.f32()?,
                half_wheel_base_m: r.f32()?,
                channel: r.u8(),
            }),
            opcode::PIR_REPLY => Message::PirReply(PirReply {
                p_left: r.f32()?,
                p_right: r.f32()?,
                frame_seq: r.u32(),
            }),
            opcode::DEPOSIT => Message::Deposit(DepositRequest {
                seq: r.u8(),
                x_m: r.f32()?,
                y_m: r.f32()?,
                amount: r.f32()?,
                channel: r.u8(),
            }),
            opcode::DEPOSIT_REPLY => Message::DepositReply(DepositReply {
                seq: r.u8(),
                status: DepositStatus::from_code(r.u8()).ok_or(PayloadError::BadValue)?,
            }),
            opcode::PING => Message::Ping,
            opcode::STATUS => Message::Status(StatusReply {
                frame_seq: r.u32(),
                field_time_s: r.f32()?,
                channels: r.u8(),
            }),
            _ => Message::Error(ErrorReason::from_code(r.u8()).ok_or(PayloadError::BadValue)?),
        };
        Ok(message)
    }
}

struct Writer<'a> {
    out: &'a mut [u8],
    at: usize,
}

impl Writer<'_> {
    fn bytes<const N: usize>(&mut self, bytes: [u8; N]) {
        self.out[self.at..self.at + N].copy_from_slice(&bytes);
        self.at += N;
    }
    fn u8(&mut self, v: u8) {
        self.bytes([v]);
    }
    fn u32(&mut self, v: u32) {
        self.bytes(v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.bytes(v.to_le_bytes());
    }
}

/// Reads a DATA field whose length was checked against the opcode.
struct Reader<'a> {
    data: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn bytes<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0; N];
        out.copy_from_slice(&self.data[self.at..self.at + N]);
        self.at += N;
        out
    }
    fn u8(&mut self) -> u8 {
        self.bytes::<1>()[0]
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.bytes())
    }
    fn f32(&mut self) -> Result<f32, PayloadError> {
        let v = f32::from_le_bytes(self.bytes());
        if v.is_finite() {
            Ok(v)
        } else {
            Err(PayloadError::NonFinite)
        }
    }
}
