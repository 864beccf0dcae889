//! Strategies and helpers shared by the codec's tests.
#![allow(dead_code)]

use pheromone_gateway_codec::{
    DepositReply, DepositRequest, DepositStatus, ErrorReason, Message, PirReply, PirRequest,
    StatusReply,
};
use proptest::prelude::*;

/// Finite `f32`s, with extra weight on bit patterns full of 0x10 bytes (stuffed on the wire).
pub fn finite_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        3 => any::<f32>().prop_filter("finite", |v| v.is_finite()),
        1 => prop::sample::select(vec![
            0x1010_1010u32, 0x0000_1010, 0x1000_0010, 0x4010_0000, 0x0010_0000, 0x8010_1010,
        ])
        .prop_map(f32::from_bits),
        1 => (any::<[bool; 4]>(), any::<u32>()).prop_map(|(dle, bits)| {
            let mut b = bits.to_le_bytes();
            for (byte, d) in b.iter_mut().zip(dle) {
                if d {
                    *byte = 0x10;
                }
            }
            let v = f32::from_le_bytes(b);
            if v.is_finite() { v } else { 0.0 }
        }),
        1 => prop::sample::select(vec![0.0f32, -0.0, f32::MIN_POSITIVE, f32::MAX, f32::MIN, 1e-45]),
    ]
}

/// `u8`s that are often 0x10.
pub fn byte() -> impl Strategy<Value = u8> {
    prop_oneof![2 => any::<u8>(), 1 => Just(0x10u8)]
}

/// `u32`s that are often made of 0x10 bytes.
pub fn word() -> impl Strategy<Value = u32> {
    prop_oneof![
        2 => any::<u32>(),
        1 => prop::sample::select(vec![0x1010_1010u32, 0x0000_0010, 0x1000_0000, 0x0010_1000]),
    ]
}

pub fn error_reason() -> impl Strategy<Value = ErrorReason> {
    prop::sample::select(ErrorReason::ALL.to_vec())
}

pub fn deposit_status() -> impl Strategy<Value = DepositStatus> {
    prop_oneof![
        Just(DepositStatus::Applied),
        error_reason().prop_map(DepositStatus::Rejected)
    ]
}

pub fn pir() -> impl Strategy<Value = PirRequest> {
    (
        finite_f32(),
        finite_f32(),
        finite_f32(),
        finite_f32(),
        byte(),
    )
        .prop_map(
            |(x_m, y_m, theta_rad, half_wheel_base_m, channel)| PirRequest {
                x_m,
                y_m,
                theta_rad,
                half_wheel_base_m,
                channel,
            },
        )
}

pub fn pir_reply() -> impl Strategy<Value = PirReply> {
    (finite_f32(), finite_f32(), word()).prop_map(|(p_left, p_right, frame_seq)| PirReply {
        p_left,
        p_right,
        frame_seq,
    })
}

pub fn deposit() -> impl Strategy<Value = DepositRequest> {
    (byte(), finite_f32(), finite_f32(), finite_f32(), byte()).prop_map(
        |(seq, x_m, y_m, amount, channel)| DepositRequest {
            seq,
            x_m,
            y_m,
            amount,
            channel,
        },
    )
}

pub fn deposit_reply() -> impl Strategy<Value = DepositReply> {
    (byte(), deposit_status()).prop_map(|(seq, status)| DepositReply { seq, status })
}

pub fn status() -> impl Strategy<Value = StatusReply> {
    (word(), finite_f32(), byte()).prop_map(|(frame_seq, field_time_s, channels)| StatusReply {
        frame_seq,
        field_time_s,
        channels,
    })
}

/// Any message of any opcode.
pub fn message() -> impl Strategy<Value = Message> {
    prop_oneof![
        pir().prop_map(Message::Pir),
        pir_reply().prop_map(Message::PirReply),
        deposit().prop_map(Message::Deposit),
        deposit_reply().prop_map(Message::DepositReply),
        Just(Message::Ping),
        status().prop_map(Message::Status),
        error_reason().prop_map(Message::Error),
    ]
}

/// Bit-exact comparison (`-0.0` and `0.0` differ), so a round trip must keep every bit.
pub fn same_bits(a: &Message, b: &Message) -> bool {
    let mut x = [0u8; pheromone_gateway_codec::MAX_ENCODED_BYTES];
    let mut y = [0u8; pheromone_gateway_codec::MAX_ENCODED_BYTES];
    let n = pheromone_gateway_codec::encode(a, 0, &mut x).unwrap();
    let m = pheromone_gateway_codec::encode(b, 0, &mut y).unwrap();
    x[..n] == y[..m]
}

/// A small deterministic generator (xorshift64*), so the fuzz figures are reproducible.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed.max(1))
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
    pub fn byte(&mut self) -> u8 {
        (self.next_u64() >> 56) as u8
    }
    pub fn f32_finite(&mut self) -> f32 {
        loop {
            let v = f32::from_bits((self.next_u64() >> 32) as u32);
            if v.is_finite() {
                return v;
            }
        }
    }
    /// A random valid message of a random opcode.
    pub fn message(&mut self) -> Message {
        match self.below(7) {
            0 => Message::Pir(PirRequest {
                x_m: self.f32_finite(),
                y_m: self.f32_finite(),
                theta_rad: self.f32_finite(),
                half_wheel_base_m: self.f32_finite(),
                channel: self.byte(),
            }),
            1 => Message::PirReply(PirReply {
                p_left: self.f32_finite(),
                p_right: self.f32_finite(),
                frame_seq: self.next_u64() as u32,
            }),
            2 => Message::Deposit(DepositRequest {
                seq: self.byte(),
                x_m: self.f32_finite(),
                y_m: self.f32_finite(),
                amount: self.f32_finite(),
                channel: self.byte(),
            }),
            3 => Message::DepositReply(DepositReply {
                seq: self.byte(),
                status: DepositStatus::from_code(self.below(7) as u8).unwrap(),
            }),
            4 => Message::Ping,
            5 => Message::Status(StatusReply {
                frame_seq: self.next_u64() as u32,
                field_time_s: self.f32_finite(),
                channels: self.byte(),
            }),
            _ => Message::Error(ErrorReason::ALL[self.below(6)]),
        }
    }
}
