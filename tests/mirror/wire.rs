//! The bytes of docs/mirror-wire.md: envelopes and bodies refused when corrupted, round trips.
//!
//! The envelope and bodies of docs/mirror-wire.md, byte by byte: every flipped byte of an
//! inputs message is refused, keyframes and downsampled frames round-trip, a corrupted keyframe
//! fails its checksum.

use pheromone_bridge::codec::*;
use pheromone_field::messages::InputsHeader;
use pheromone_field::{Deposit, Kernel};
use pheromone_field::{DepositMsg, FrameHeader};
#[test]
fn every_flipped_byte_is_rejected() {
    let h = InputsHeader {
        sequence: 7,
        epoch: 99,
        dt_s: 0.02,
        dt_time_s: 0.02,
        count: 2,
        ..Default::default()
    };
    let deposits = [DepositMsg::from(Deposit {
        channel: 0,
        x_m: 1.0,
        y_m: 2.0,
        kernel: Kernel::ZShape {
            amount: 3.0,
            plateau_m: 0.1,
            slope_m: 0.1,
        },
    }); 2];
    let bytes = encode_inputs(&h, &deposits);
    assert_eq!(decode_inputs(&bytes).unwrap(), (h, deposits.to_vec()));
    for i in 0..bytes.len() {
        let mut bad = bytes.clone();
        bad[i] ^= 0x10;
        assert!(
            decode_inputs(&bad).is_err(),
            "byte {i} flipped was accepted"
        );
    }
    assert!(decode_inputs(&bytes[..bytes.len() - 1]).is_err());
}

#[test]
fn keyframes_and_frames_round_trip() {
    let header = FrameHeader {
        layout_version: pheromone_field::wire::LAYOUT_VERSION,
        channels: 1,
        width: 5,
        height: 3,
        sequence: 42,
        ..Default::default()
    };
    let cells: Vec<f32> = (0..15).map(|i| i as f32 * 0.5).collect();
    let k = encode_keyframe(3, &header, &cells);
    let (epoch, h, c) = decode_keyframe(&k).unwrap();
    assert_eq!((epoch, h, c.clone()), (3, header, cells.clone()));
    let f = decode_frame(&encode_frame(3, &header, &cells, 2)).unwrap();
    assert_eq!((f.width, f.height, f.sequence), (3, 2, 42));
    // Block (0,0): cells 0, 1, 5, 6 → mean 3 × 0.5 = 1.5.
    assert_eq!(f.cells[0], 1.5);
    let mut bad = k.clone();
    let last = bad.len() - 1;
    bad[last] ^= 1;
    assert!(matches!(
        decode_keyframe(&bad),
        Err(CodecError::Checksum { .. })
    ));
}

/// A deposit batch and its answer, built from the documented bytes alone: the mirror's id and
/// batch number in the envelope's epoch and sequence, the answer's body two u32 counts.
#[test]
fn deposit_batches_and_their_answers_are_the_documented_bytes() {
    let envelope = |kind: u8, id: u64, batch: u64, body: &[u8]| {
        let mut b = b"PHMR".to_vec();
        b.extend_from_slice(&[1, kind, 0, 0]);
        b.extend_from_slice(&id.to_le_bytes());
        b.extend_from_slice(&batch.to_le_bytes());
        b.extend_from_slice(&(body.len() as u32).to_le_bytes());
        b.extend_from_slice(&[0; 4]);
        b.extend_from_slice(&xxhash_rust::xxh3::xxh3_64(body).to_le_bytes());
        b.extend_from_slice(body);
        b
    };
    let answer = DepositAck {
        mirror_id: 0x1234_5678_9abc_def1,
        batch: 42,
        forwarded: 3,
        refused: 1,
    };
    let mut body = 3u32.to_le_bytes().to_vec();
    body.extend_from_slice(&1u32.to_le_bytes());
    let bytes = envelope(7, answer.mirror_id, 42, &body);
    assert_eq!(encode_deposit_ack(&answer), bytes);
    assert_eq!(decode_deposit_ack(&bytes).unwrap(), answer);
    for i in 0..bytes.len() {
        let mut bad = bytes.clone();
        bad[i] ^= 0x10;
        assert_ne!(decode_deposit_ack(&bad).ok(), Some(answer), "byte {i}");
    }
    let short = envelope(7, 1, 1, &[0; 4]);
    let err = decode_deposit_ack(&short).unwrap_err().to_string();
    assert!(err.contains("4 bytes, expected 8"), "{err}");

    let d = DepositMsg {
        robot_id: 5,
        amount: 2.0,
        ..DepositMsg::default()
    };
    let batch = encode_deposits(answer.mirror_id, 9, &[d, d]);
    let raw: Vec<u8> = [d, d]
        .iter()
        .flat_map(|m| pheromone_field::shm::wire_bytes(m).to_vec())
        .collect();
    assert_eq!(batch, envelope(5, answer.mirror_id, 9, &raw));
    assert_eq!(
        decode_deposits(&batch).unwrap(),
        (answer.mirror_id, 9, vec![d, d])
    );
}
