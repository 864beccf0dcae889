//! Unit tests of the decoder: each rejection reason, resynchronisation, the length bound.

use pheromone_gateway_codec::{
    decode, encode, DecodeError, Decoder, EncodeError, ErrorReason, Frame, Message, PirRequest,
    Rejection, CRC, MAX_ENCODED_BYTES, MAX_FRAME_BYTES, MAX_WIRE_BYTES,
};

/// A frame around `covered` (client ID, opcode, DATA) with its CRC, stuffed.
fn raw_frame(covered: &[u8]) -> Vec<u8> {
    let mut body = covered.to_vec();
    body.extend(CRC.checksum(covered).to_le_bytes());
    stuffed(&body)
}

/// `DLE STX`, `body` with each DLE doubled, `DLE ETX`.
fn stuffed(body: &[u8]) -> Vec<u8> {
    let mut out = vec![0x10, 0x02];
    for &b in body {
        out.push(b);
        if b == 0x10 {
            out.push(0x10);
        }
    }
    out.extend([0x10, 0x03]);
    out
}

fn ping(client_id: u8) -> Vec<u8> {
    let mut buf = [0u8; MAX_ENCODED_BYTES];
    let n = encode(&Message::Ping, client_id, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn pir() -> Message {
    Message::Pir(PirRequest {
        x_m: 1.0,
        y_m: 2.0,
        theta_rad: 0.0,
        half_wheel_base_m: 0.1,
        channel: 0,
    })
}

fn run(decoder: &mut Decoder, bytes: &[u8]) -> Vec<Result<Frame, DecodeError>> {
    let mut out = Vec::new();
    decoder.feed(bytes, |o| out.push(o));
    out
}

fn ping_frame(client_id: u8) -> Result<Frame, DecodeError> {
    Ok(Frame {
        client_id,
        message: Message::Ping,
    })
}

#[test]
fn garbage_before_a_frame_is_skipped() {
    let mut d = Decoder::new();
    let mut bytes = vec![0x00, 0xFF, 0x03, 0x10, 0x03, 0x10, 0x41, 0x02, 0x10];
    bytes.extend(ping(5));
    assert_eq!(run(&mut d, &bytes), vec![ping_frame(5)]);
    assert_eq!(d.counters().total_rejected(), 0);
    assert_eq!(d.counters().skipped_bytes, 9);
}

#[test]
fn a_run_of_dles_before_stx_still_starts_a_frame() {
    let mut d = Decoder::new();
    let mut bytes = vec![0x10, 0x10, 0x10];
    bytes.extend(ping(1));
    assert_eq!(run(&mut d, &bytes), vec![ping_frame(1)]);
}

#[test]
fn dle_stx_inside_a_frame_drops_it_and_starts_the_next() {
    let mut d = Decoder::new();
    let mut bytes = ping(1);
    bytes.truncate(4); // DLE STX, id, opcode
    bytes.extend(ping(2));
    assert_eq!(
        run(&mut d, &bytes),
        vec![Err(DecodeError::Truncated { len: 2 }), ping_frame(2)]
    );
    assert_eq!(d.counters().get(Rejection::Truncated), 1);
}

#[test]
fn a_stray_dle_sequence_rejects_the_frame_and_the_decoder_resyncs() {
    let mut d = Decoder::new();
    let mut bytes = vec![0x10, 0x02, 0x01, 0x10, 0x41, 0x03, 0x00];
    bytes.extend(ping(3));
    assert_eq!(
        run(&mut d, &bytes),
        vec![Err(DecodeError::StrayDle { byte: 0x41 }), ping_frame(3)]
    );
    assert_eq!(d.counters().get(Rejection::StrayDle), 1);
}

#[test]
fn a_lone_dle_at_the_end_of_garbage_costs_at_most_one_frame_and_a_preamble_saves_it() {
    // Garbage that starts a frame and ends with an unpaired DLE.
    let garbage = [0x10, 0x02, 0x55, 0x10];
    let mut d = Decoder::new();
    let mut bytes = garbage.to_vec();
    bytes.extend(ping(1));
    bytes.extend(ping(2));
    let out = run(&mut d, &bytes);
    assert_eq!(out.len(), 2);
    assert!(out[0].is_err());
    assert_eq!(out[1], ping_frame(2));

    // One non-DLE byte before DLE STX rules the loss out.
    let mut d = Decoder::new();
    let mut bytes = garbage.to_vec();
    bytes.push(0x00);
    bytes.extend(ping(1));
    assert_eq!(
        run(&mut d, &bytes),
        vec![Err(DecodeError::StrayDle { byte: 0x00 }), ping_frame(1)]
    );
}

#[test]
fn a_bad_crc_is_rejected_without_a_reply() {
    let mut wire = ping(7);
    wire[4] ^= 0x01; // CRC low byte (0x07, 0x03 hold no DLE)
    let mut d = Decoder::new();
    let out = run(&mut d, &wire);
    assert_eq!(out, vec![Err(DecodeError::BadCrc)]);
    assert_eq!(out[0].unwrap_err().reply(), None);
    assert_eq!(d.counters().get(Rejection::BadCrc), 1);
}

#[test]
fn a_body_under_four_bytes_is_too_short() {
    for body in [&[][..], &[0x01], &[0x01, 0x03], &[0x01, 0x03, 0x00]] {
        let mut d = Decoder::new();
        assert_eq!(
            run(&mut d, &stuffed(body)),
            vec![Err(DecodeError::TooShort { len: body.len() })]
        );
        assert_eq!(d.counters().get(Rejection::TooShort), 1);
    }
}

#[test]
fn the_longest_body_is_accepted_as_a_frame_and_one_more_byte_is_too_long() {
    // 255 body bytes with a valid CRC: framing accepts it; PING with 251 data bytes is a bad
    // length, which gets a reply.
    let mut covered = vec![0x09, 0x03];
    covered.resize(MAX_FRAME_BYTES - 2, 0x10);
    let wire = raw_frame(&covered);
    assert!(wire.len() > 4 + MAX_FRAME_BYTES && wire.len() <= MAX_WIRE_BYTES);
    let out = decode(&wire).unwrap();
    let err = out.unwrap_err();
    assert_eq!(
        err,
        DecodeError::BadLength {
            client_id: 0x09,
            opcode: 0x03,
            data_len: MAX_FRAME_BYTES - 4
        }
    );
    assert_eq!(err.reply(), Some((0x09, ErrorReason::BadLength)));

    // One byte more: too long, counted, then the decoder resyncs on the next DLE STX.
    covered.push(0x00);
    let mut bytes = raw_frame(&covered);
    bytes.extend(ping(4));
    let mut d = Decoder::new();
    assert_eq!(
        run(&mut d, &bytes),
        vec![Err(DecodeError::TooLong), ping_frame(4)]
    );
    assert_eq!(d.counters().get(Rejection::TooLong), 1);
    assert_eq!(d.counters().frames, 1);
}

#[test]
fn an_endless_frame_is_cut_at_the_bound_and_the_next_frame_decodes() {
    let mut d = Decoder::new();
    let mut bytes = vec![0x10, 0x02];
    bytes.extend(std::iter::repeat_n(0x42, 10_000));
    bytes.extend(ping(6));
    let out = run(&mut d, &bytes);
    assert_eq!(out, vec![Err(DecodeError::TooLong), ping_frame(6)]);
    assert_eq!(
        d.counters().skipped_bytes,
        10_000 - MAX_FRAME_BYTES as u64 - 1
    );
}

#[test]
fn an_unknown_opcode_is_rejected_with_the_reply_reason() {
    for op in [0x00u8, 0x04, 0x7F, 0x80, 0x84, 0xFE] {
        let err = decode(&raw_frame(&[0x22, op])).unwrap().unwrap_err();
        assert_eq!(
            err,
            DecodeError::UnknownOpcode {
                client_id: 0x22,
                opcode: op
            }
        );
        assert_eq!(err.reply(), Some((0x22, ErrorReason::UnknownOpcode)));
    }
}

#[test]
fn every_opcode_refuses_a_data_length_off_by_one() {
    let opcodes = [
        (0x01u8, 17usize),
        (0x81, 12),
        (0x02, 14),
        (0x82, 2),
        (0x03, 0),
        (0x83, 9),
        (0xFF, 1),
    ];
    for (op, len) in opcodes {
        for bad in [len.wrapping_sub(1), len + 1] {
            if bad > len + 1 {
                continue; // PING has no shorter length
            }
            let mut covered = vec![0x01, op];
            covered.resize(2 + bad, 0x01);
            let err = decode(&raw_frame(&covered)).unwrap().unwrap_err();
            assert_eq!(
                err,
                DecodeError::BadLength {
                    client_id: 0x01,
                    opcode: op,
                    data_len: bad
                },
                "opcode {op:#04x}"
            );
        }
    }
}

#[test]
fn a_non_finite_number_never_decodes() {
    let nan = f32::NAN.to_le_bytes();
    let inf = f32::INFINITY.to_le_bytes();
    let neg_inf = f32::NEG_INFINITY.to_le_bytes();
    for bad in [nan, inf, neg_inf] {
        // PIR: each of the four f32 in turn.
        for at in [0usize, 4, 8, 12] {
            let mut covered = vec![0x01, 0x01];
            covered.extend([0u8; 17]);
            covered[2 + at..2 + at + 4].copy_from_slice(&bad);
            let err = decode(&raw_frame(&covered)).unwrap().unwrap_err();
            assert_eq!(
                err,
                DecodeError::NonFinite {
                    client_id: 1,
                    opcode: 0x01
                }
            );
            assert_eq!(err.reply(), Some((1, ErrorReason::BadValue)));
        }
        // DEPOSIT's three f32, the PIR reply's two and the status's one.
        for (op, len, offsets) in [
            (0x02u8, 14usize, &[1usize, 5, 9][..]),
            (0x81, 12, &[0, 4][..]),
            (0x83, 9, &[4][..]),
        ] {
            for &at in offsets {
                let mut covered = vec![0x01, op];
                covered.resize(2 + len, 0);
                covered[2 + at..2 + at + 4].copy_from_slice(&bad);
                let err = decode(&raw_frame(&covered)).unwrap().unwrap_err();
                assert_eq!(
                    err.rejection(),
                    Rejection::NonFinite,
                    "opcode {op:#04x} at {at}"
                );
            }
        }
    }
}

#[test]
fn undefined_codes_are_bad_values() {
    for reason in [0u8, 7, 0xFF] {
        let err = decode(&raw_frame(&[0x01, 0xFF, reason]))
            .unwrap()
            .unwrap_err();
        assert_eq!(
            err,
            DecodeError::BadValue {
                client_id: 1,
                opcode: 0xFF
            }
        );
        assert_eq!(err.reply(), Some((1, ErrorReason::BadValue)));
    }
    for status in [7u8, 0x10, 0xFF] {
        let err = decode(&raw_frame(&[0x01, 0x82, 0x05, status]))
            .unwrap()
            .unwrap_err();
        assert_eq!(err.rejection(), Rejection::BadValue);
    }
    for status in 0u8..=6 {
        assert!(decode(&raw_frame(&[0x01, 0x82, 0x05, status]))
            .unwrap()
            .is_ok());
    }
}

#[test]
fn the_encoder_refuses_non_finite_numbers() {
    let mut buf = [0u8; MAX_ENCODED_BYTES];
    let Message::Pir(mut p) = pir() else {
        unreachable!()
    };
    p.theta_rad = f32::NAN;
    assert_eq!(
        encode(&Message::Pir(p), 1, &mut buf),
        Err(EncodeError::NonFinite)
    );
}

#[test]
fn every_rejection_is_counted_once_under_its_reason() {
    let mut d = Decoder::new();
    let mut bytes = Vec::new();
    let mut bad_crc = ping(1);
    bad_crc[3] ^= 0x40;
    bytes.extend(&bad_crc); // bad CRC
    bytes.extend(stuffed(&[0x01])); // too short
    bytes.extend([0x10, 0x02, 0x01]); // truncated by the next frame's DLE STX
    bytes.extend([0x10, 0x02, 0x10, 0x20]); // stray DLE
    bytes.extend(raw_frame(&[0x01, 0x05])); // unknown opcode
    bytes.extend(raw_frame(&[0x01, 0x03, 0x00])); // bad length
    let mut nan_pir = vec![0x01, 0x01];
    nan_pir.extend(f32::NAN.to_le_bytes());
    nan_pir.extend([0u8; 13]);
    bytes.extend(raw_frame(&nan_pir)); // non-finite
    bytes.extend(raw_frame(&[0x01, 0xFF, 0x09])); // bad value
    bytes.push(0x10);
    bytes.push(0x02);
    bytes.extend([0x55; MAX_FRAME_BYTES + 1]); // too long
    bytes.extend(ping(9));
    let out = run(&mut d, &bytes);
    assert_eq!(out.last(), Some(&ping_frame(9)));
    let c = d.counters();
    for reason in Rejection::ALL {
        assert_eq!(c.get(reason), 1, "{}", reason.name());
        let seen = out
            .iter()
            .filter(|o| matches!(o, Err(e) if e.rejection() == reason))
            .count();
        assert_eq!(seen, 1, "{}", reason.name());
    }
    assert_eq!(c.total_rejected(), 9);
    assert_eq!(c.frames, 1);
    assert_eq!(c.iter().count(), Rejection::ALL.len());
}

#[test]
fn reset_drops_a_partial_frame_uncounted() {
    let mut d = Decoder::new();
    run(&mut d, &[0x10, 0x02, 0x01, 0x03]);
    assert!(d.in_frame());
    d.reset();
    assert!(!d.in_frame());
    assert_eq!(run(&mut d, &ping(2)), vec![ping_frame(2)]);
    assert_eq!(d.counters().total_rejected(), 0);
}

#[test]
fn errors_display_their_reason() {
    let text = DecodeError::BadLength {
        client_id: 3,
        opcode: 0x01,
        data_len: 4,
    }
    .to_string();
    assert!(text.contains("client 3") && text.contains("0x01"), "{text}");
    assert!(EncodeError::BufferTooSmall { needed: 9 }
        .to_string()
        .contains('9'));
    assert_eq!(
        Rejection::ALL.map(Rejection::name),
        [
            "bad_crc",
            "too_long",
            "too_short",
            "truncated",
            "stray_dle",
            "unknown_opcode",
            "bad_length",
            "non_finite",
            "bad_value"
        ]
    );
}

#[test]
fn a_buffer_of_max_encoded_bytes_holds_the_worst_case() {
    // PIR from client 0x10 whose every byte is 0x10: all 21 body bytes but the CRC stuffed.
    let dle = f32::from_bits(0x1010_1010);
    let m = Message::Pir(PirRequest {
        x_m: dle,
        y_m: dle,
        theta_rad: dle,
        half_wheel_base_m: dle,
        channel: 0x10,
    });
    let mut buf = [0u8; MAX_ENCODED_BYTES];
    let n = encode(&m, 0x10, &mut buf).unwrap();
    assert!(n >= 4 + 21 + 18, "{n}");
    assert!(n <= MAX_ENCODED_BYTES);
}

/// Why client ID 0x00 should stay off the allow-list (docs/gateway-wire.md): CRC-16/ARC starts at
/// zero, so a 0x00 inserted in front of the body keeps the CRC valid.
#[test]
fn a_zero_inserted_in_front_of_the_body_keeps_the_crc_valid() {
    let mut wire = ping(0xFF);
    wire.insert(2, 0x00);
    assert_eq!(
        decode(&wire).unwrap(),
        Ok(Frame {
            client_id: 0x00,
            message: Message::Error(ErrorReason::BadValue)
        })
    );
}
