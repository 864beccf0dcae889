//! The hex test vectors of `docs/gateway-wire.md`, one per opcode, as byte literals copied from
//! the page: decoding them gives the documented message, and encoding the message gives them back.
//! A client that knows only the page's bytes agrees with this codec.

use pheromone_gateway_codec::{
    decode, encode, Decoder, DepositReply, DepositRequest, DepositStatus, ErrorReason, Message,
    PirReply, PirRequest, StatusReply, CRC, MAX_ENCODED_BYTES,
};

struct Vector {
    name: &'static str,
    client_id: u8,
    message: Message,
    crc: u16,
    body: &'static [u8],
    wire: &'static [u8],
}

#[rustfmt::skip]
const VECTORS: &[Vector] = &[
    Vector {
        name: "0x01 PIR",
        client_id: 0x10,
        message: Message::Pir(PirRequest {
            x_m: 1.5, y_m: 2.25, theta_rad: 0.5, half_wheel_base_m: 0.125, channel: 0,
        }),
        crc: 0x2B29,
        body: &[0x10, 0x01, 0x00, 0x00, 0xC0, 0x3F, 0x00, 0x00, 0x10, 0x40, 0x00, 0x00, 0x00, 0x3F,
                0x00, 0x00, 0x00, 0x3E, 0x00, 0x29, 0x2B],
        wire: &[0x10, 0x02, 0x10, 0x10, 0x01, 0x00, 0x00, 0xC0, 0x3F, 0x00, 0x00, 0x10, 0x10, 0x40,
                0x00, 0x00, 0x00, 0x3F, 0x00, 0x00, 0x00, 0x3E, 0x00, 0x29, 0x2B, 0x10, 0x03],
    },
    Vector {
        name: "0x81 PIR reply",
        client_id: 0x10,
        message: Message::PirReply(PirReply { p_left: 0.75, p_right: 0.25, frame_seq: 4096 }),
        crc: 0x75CC,
        body: &[0x10, 0x81, 0x00, 0x00, 0x40, 0x3F, 0x00, 0x00, 0x80, 0x3E, 0x00, 0x10, 0x00, 0x00,
                0xCC, 0x75],
        wire: &[0x10, 0x02, 0x10, 0x10, 0x81, 0x00, 0x00, 0x40, 0x3F, 0x00, 0x00, 0x80, 0x3E, 0x00,
                0x10, 0x10, 0x00, 0x00, 0xCC, 0x75, 0x10, 0x03],
    },
    Vector {
        name: "0x02 DEPOSIT",
        client_id: 0x07,
        message: Message::Deposit(DepositRequest {
            seq: 16, x_m: 3.0, y_m: -4.5, amount: 1.0, channel: 1,
        }),
        crc: 0x27D6,
        body: &[0x07, 0x02, 0x10, 0x00, 0x00, 0x40, 0x40, 0x00, 0x00, 0x90, 0xC0, 0x00, 0x00, 0x80,
                0x3F, 0x01, 0xD6, 0x27],
        wire: &[0x10, 0x02, 0x07, 0x02, 0x10, 0x10, 0x00, 0x00, 0x40, 0x40, 0x00, 0x00, 0x90, 0xC0,
                0x00, 0x00, 0x80, 0x3F, 0x01, 0xD6, 0x27, 0x10, 0x03],
    },
    Vector {
        name: "0x82 deposit reply",
        client_id: 0x07,
        message: Message::DepositReply(DepositReply { seq: 16, status: DepositStatus::Applied }),
        crc: 0x9CAC,
        body: &[0x07, 0x82, 0x10, 0x00, 0xAC, 0x9C],
        wire: &[0x10, 0x02, 0x07, 0x82, 0x10, 0x10, 0x00, 0xAC, 0x9C, 0x10, 0x03],
    },
    Vector {
        name: "0x03 PING",
        client_id: 0xC3,
        message: Message::Ping,
        crc: 0xF110,
        body: &[0xC3, 0x03, 0x10, 0xF1],
        wire: &[0x10, 0x02, 0xC3, 0x03, 0x10, 0x10, 0xF1, 0x10, 0x03],
    },
    Vector {
        name: "0x83 status",
        client_id: 0xC3,
        message: Message::Status(StatusReply { frame_seq: 1234, field_time_s: 61.5, channels: 2 }),
        crc: 0x4DD1,
        body: &[0xC3, 0x83, 0xD2, 0x04, 0x00, 0x00, 0x00, 0x00, 0x76, 0x42, 0x02, 0xD1, 0x4D],
        wire: &[0x10, 0x02, 0xC3, 0x83, 0xD2, 0x04, 0x00, 0x00, 0x00, 0x00, 0x76, 0x42, 0x02, 0xD1,
                0x4D, 0x10, 0x03],
    },
    Vector {
        name: "0xFF error reply",
        client_id: 0x07,
        message: Message::Error(ErrorReason::BadLength),
        crc: 0xF071,
        body: &[0x07, 0xFF, 0x02, 0x71, 0xF0],
        wire: &[0x10, 0x02, 0x07, 0xFF, 0x02, 0x71, 0xF0, 0x10, 0x03],
    },
];

#[test]
fn there_is_one_vector_per_opcode() {
    let mut opcodes: Vec<u8> = VECTORS.iter().map(|v| v.message.opcode()).collect();
    opcodes.sort_unstable();
    assert_eq!(opcodes, [0x01, 0x02, 0x03, 0x81, 0x82, 0x83, 0xFF]);
}

#[test]
fn the_documented_bytes_decode_to_the_documented_messages() {
    for v in VECTORS {
        let frame = decode(v.wire)
            .unwrap_or_else(|| panic!("{}: no frame", v.name))
            .unwrap_or_else(|e| panic!("{}: {e}", v.name));
        assert_eq!(frame.client_id, v.client_id, "{}", v.name);
        assert_eq!(frame.message, v.message, "{}", v.name);
    }
}

#[test]
fn the_documented_bytes_arrive_one_at_a_time() {
    let mut decoder = Decoder::new();
    let mut frames = Vec::new();
    for v in VECTORS {
        for &b in v.wire {
            if let Some(outcome) = decoder.push(b) {
                frames.push(outcome.unwrap());
            }
        }
    }
    let expected: Vec<_> = VECTORS.iter().map(|v| (v.client_id, v.message)).collect();
    let got: Vec<_> = frames.iter().map(|f| (f.client_id, f.message)).collect();
    assert_eq!(got, expected);
    assert_eq!(decoder.counters().total_rejected(), 0);
}

#[test]
fn encoding_the_documented_messages_gives_the_documented_bytes() {
    for v in VECTORS {
        let mut buf = [0u8; MAX_ENCODED_BYTES];
        let n = encode(&v.message, v.client_id, &mut buf).unwrap();
        assert_eq!(&buf[..n], v.wire, "{}", v.name);
    }
}

#[test]
fn the_documented_bodies_and_crcs_agree_with_the_wire_bytes() {
    for v in VECTORS {
        let (covered, crc) = v.body.split_at(v.body.len() - 2);
        assert_eq!(CRC.checksum(covered), v.crc, "{}", v.name);
        assert_eq!(u16::from_le_bytes([crc[0], crc[1]]), v.crc, "{}", v.name);
        assert_eq!(
            covered[..2],
            [v.client_id, v.message.opcode()],
            "{}",
            v.name
        );
        let mut stuffed = vec![0x10, 0x02];
        for &b in v.body {
            stuffed.push(b);
            if b == 0x10 {
                stuffed.push(0x10);
            }
        }
        stuffed.extend([0x10, 0x03]);
        assert_eq!(stuffed, v.wire, "{}", v.name);
    }
}

#[test]
fn the_crc_is_crc16_arc() {
    assert_eq!(CRC.checksum(b"123456789"), 0xBB3D);
}

/// The literals above are the page's: each vector's body and wire bytes appear on it verbatim.
#[test]
fn the_literals_are_the_ones_on_the_page() {
    let page = include_str!("../../../../docs/gateway-wire.md");
    let hex = |bytes: &[u8]| {
        bytes
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    for v in VECTORS {
        let body = format!("body: {}\n", hex(v.body));
        let wire = format!("wire: {}\n", hex(v.wire));
        assert!(page.contains(&body), "{}: {body} not on the page", v.name);
        assert!(page.contains(&wire), "{}: {wire} not on the page", v.name);
        assert!(
            page.contains(&format!("CRC `0x{:04X}`", v.crc)),
            "{}",
            v.name
        );
    }
}
