//! Property tests: `decode(encode(m)) == m` for every message type, bit for bit, with payloads
//! and client IDs full of 0x10, fed whole or a few bytes at a time.

mod common;

use common::*;
use pheromone_gateway_codec::{
    decode, encode, encoded_len, Decoder, EncodeError, Frame, Message, DLE, MAX_ENCODED_BYTES,
};
use proptest::prelude::*;

fn round_trip(message: Message, client_id: u8) -> Result<(), TestCaseError> {
    let mut buf = [0u8; MAX_ENCODED_BYTES];
    let n = encode(&message, client_id, &mut buf).unwrap();
    prop_assert_eq!(n, encoded_len(&message, client_id));
    let wire = &buf[..n];
    // The delimiters are the only unpaired DLEs.
    prop_assert_eq!(&wire[..2], &[0x10, 0x02]);
    prop_assert_eq!(&wire[n - 2..], &[0x10, 0x03]);
    let inner = &wire[2..n - 2];
    let mut i = 0;
    while i < inner.len() {
        if inner[i] == DLE {
            prop_assert_eq!(inner.get(i + 1), Some(&DLE));
            i += 1;
        }
        i += 1;
    }
    let frame = decode(wire).unwrap().unwrap();
    prop_assert_eq!(frame, Frame { client_id, message });
    prop_assert!(same_bits(&frame.message, &message));
    Ok(())
}

fn cases() -> ProptestConfig {
    ProptestConfig {
        cases: 2_000,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(cases())]

    #[test]
    fn pir_round_trips(m in pir(), id in byte()) {
        round_trip(Message::Pir(m), id)?;
    }

    #[test]
    fn pir_reply_round_trips(m in pir_reply(), id in byte()) {
        round_trip(Message::PirReply(m), id)?;
    }

    #[test]
    fn deposit_round_trips(m in deposit(), id in byte()) {
        round_trip(Message::Deposit(m), id)?;
    }

    #[test]
    fn deposit_reply_round_trips(m in deposit_reply(), id in byte()) {
        round_trip(Message::DepositReply(m), id)?;
    }

    #[test]
    fn ping_round_trips(id in any::<u8>()) {
        round_trip(Message::Ping, id)?;
    }

    #[test]
    fn status_round_trips(m in status(), id in byte()) {
        round_trip(Message::Status(m), id)?;
    }

    #[test]
    fn error_round_trips(reason in error_reason(), id in byte()) {
        round_trip(Message::Error(reason), id)?;
    }

    /// Client ID 0x10 with DATA made only of 0x10 bytes wherever the type allows it.
    #[test]
    fn all_dle_payloads_round_trip(m in message()) {
        let dle_f32 = f32::from_bits(0x1010_1010);
        let m = match m {
            Message::Pir(_) => Message::Pir(pheromone_gateway_codec::PirRequest {
                x_m: dle_f32, y_m: dle_f32, theta_rad: dle_f32, half_wheel_base_m: dle_f32,
                channel: 0x10,
            }),
            Message::PirReply(_) => Message::PirReply(pheromone_gateway_codec::PirReply {
                p_left: dle_f32, p_right: dle_f32, frame_seq: 0x1010_1010,
            }),
            Message::Deposit(_) => Message::Deposit(pheromone_gateway_codec::DepositRequest {
                seq: 0x10, x_m: dle_f32, y_m: dle_f32, amount: dle_f32, channel: 0x10,
            }),
            Message::DepositReply(r) => Message::DepositReply(pheromone_gateway_codec::DepositReply {
                seq: 0x10, status: r.status,
            }),
            Message::Status(_) => Message::Status(pheromone_gateway_codec::StatusReply {
                frame_seq: 0x1010_1010, field_time_s: dle_f32, channels: 0x10,
            }),
            other => other,
        };
        round_trip(m, 0x10)?;
    }

    /// A stream of frames split into chunks of 1 to 5 bytes decodes to the same frames in order.
    #[test]
    fn a_stream_in_small_chunks_decodes_every_frame(
        frames in prop::collection::vec((message(), byte()), 1..20),
        chunk in 1usize..6,
    ) {
        let mut stream = Vec::new();
        for (m, id) in &frames {
            let mut buf = [0u8; MAX_ENCODED_BYTES];
            let n = encode(m, *id, &mut buf).unwrap();
            stream.extend_from_slice(&buf[..n]);
        }
        let mut decoder = Decoder::new();
        let mut got = Vec::new();
        for part in stream.chunks(chunk) {
            decoder.feed(part, |outcome| got.push(outcome.unwrap()));
        }
        let expected: Vec<Frame> =
            frames.iter().map(|&(message, client_id)| Frame { client_id, message }).collect();
        prop_assert_eq!(got, expected);
        prop_assert_eq!(decoder.counters().frames, frames.len() as u64);
        prop_assert_eq!(decoder.counters().total_rejected(), 0);
        prop_assert!(!decoder.in_frame());
    }

    /// A buffer one byte short is refused with the exact length needed, and nothing else fails.
    #[test]
    fn a_short_buffer_is_refused_with_the_length_needed(m in message(), id in byte()) {
        let needed = encoded_len(&m, id);
        let mut buf = [0u8; MAX_ENCODED_BYTES];
        prop_assert_eq!(
            encode(&m, id, &mut buf[..needed - 1]),
            Err(EncodeError::BufferTooSmall { needed })
        );
        prop_assert_eq!(encode(&m, id, &mut buf[..needed]), Ok(needed));
    }
}
