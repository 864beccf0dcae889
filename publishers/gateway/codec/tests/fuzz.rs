//! Fuzz: 10^6 random bytes (uniform, and again rich in DLE, STX and ETX), and mutated valid
//! frames (bit flips, truncation, insertion, deletion, duplication), each followed by a valid
//! frame. Asserts: no panic; every outcome is counted, and every rejection under its own reason;
//! the valid frame after the garbage is decoded. Run with `--nocapture` to see the figures.

mod common;

use common::Rng;
use pheromone_gateway_codec::{
    DecodeError, Decoder, Frame, Rejection, MAX_ENCODED_BYTES, REJECTIONS,
};

/// Outcomes seen from the outside, to compare with the decoder's own counters.
#[derive(Default)]
struct Tally {
    frames: u64,
    rejected: [u64; REJECTIONS],
    markers: u64,
    markers_lost_to_a_lone_dle: u64,
}

impl Tally {
    fn add(&mut self, outcome: &Result<Frame, DecodeError>) {
        match outcome {
            Ok(_) => self.frames += 1,
            Err(e) => self.rejected[e.rejection() as usize] += 1,
        }
    }

    fn check(&self, decoder: &Decoder) {
        let c = decoder.counters();
        assert_eq!(c.frames, self.frames, "frames");
        for reason in Rejection::ALL {
            assert_eq!(
                c.get(reason),
                self.rejected[reason as usize],
                "{}",
                reason.name()
            );
        }
    }

    fn report(&self, name: &str, decoder: &Decoder, extra: &str) {
        let c = decoder.counters();
        let reasons: Vec<String> = c
            .iter()
            .filter(|&(_, n)| n > 0)
            .map(|(r, n)| format!("{}={n}", r.name()))
            .collect();
        println!(
            "{name}: frames decoded {} (valid markers {}, lost to a lone DLE {}), rejected {} \
             [{}], skipped bytes {}{extra}",
            c.frames,
            self.markers,
            self.markers_lost_to_a_lone_dle,
            c.total_rejected(),
            reasons.join(", "),
            c.skipped_bytes,
        );
    }
}

fn encoded(frame: &Frame) -> Vec<u8> {
    let mut buf = [0u8; MAX_ENCODED_BYTES];
    let n = frame.encode(&mut buf).unwrap();
    buf[..n].to_vec()
}

fn random_frame(rng: &mut Rng) -> Frame {
    Frame {
        client_id: rng.byte(),
        message: rng.message(),
    }
}

/// Feeds `bytes` in chunks of 1 to 8 bytes, tallying every outcome; returns them.
fn feed_in_chunks(
    rng: &mut Rng,
    decoder: &mut Decoder,
    tally: &mut Tally,
    bytes: &[u8],
) -> Vec<Result<Frame, DecodeError>> {
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        let end = (at + 1 + rng.below(8)).min(bytes.len());
        decoder.feed(&bytes[at..end], |o| {
            tally.add(&o);
            out.push(o);
        });
        at = end;
    }
    out
}

/// Sends a valid frame after `before` (the bytes just fed) and asserts that it is decoded: at
/// once, or — only when `before` ended with an unpaired DLE inside a frame, the one loss DLE
/// framing cannot avoid — as the next copy.
fn assert_marker_decodes(rng: &mut Rng, decoder: &mut Decoder, tally: &mut Tally, before: &[u8]) {
    let marker = random_frame(rng);
    let wire = encoded(&marker);
    let was_after_dle = decoder.in_frame() && before.last() == Some(&0x10);
    let out = feed_in_chunks(rng, decoder, tally, &wire);
    tally.markers += 1;
    if out.last() == Some(&Ok(marker)) {
        assert!(out.len() <= 2, "{out:?}");
        return;
    }
    assert!(was_after_dle, "marker lost after {before:02X?}: {out:?}");
    tally.markers_lost_to_a_lone_dle += 1;
    let again = feed_in_chunks(rng, decoder, tally, &wire);
    assert_eq!(again.last(), Some(&Ok(marker)), "{again:?}");
}

/// One stream of `total` garbage bytes drawn by `next`, in segments, each followed by a marker.
fn garbage_stream(name: &str, seed: u64, total: usize, mut next: impl FnMut(&mut Rng) -> u8) {
    let mut rng = Rng::new(seed);
    let mut decoder = Decoder::new();
    let mut tally = Tally::default();
    let mut sent = 0;
    while sent < total {
        let len = (1 + rng.below(4000)).min(total - sent);
        let garbage: Vec<u8> = (0..len).map(|_| next(&mut rng)).collect();
        feed_in_chunks(&mut rng, &mut decoder, &mut tally, &garbage);
        assert_marker_decodes(&mut rng, &mut decoder, &mut tally, &garbage);
        sent += len;
    }
    tally.check(&decoder);
    tally.report(name, &decoder, &format!(", garbage bytes {sent}"));
}

#[test]
fn a_million_uniform_random_bytes() {
    garbage_stream("uniform bytes", 0x5EED_0002, 1_000_000, |rng| rng.byte());
}

#[test]
fn a_million_random_bytes_rich_in_delimiters() {
    garbage_stream(
        "delimiter-rich bytes",
        0x5EED_0003,
        1_000_000,
        |rng| match rng.below(20) {
            0..=5 => 0x10,
            6..=7 => 0x02,
            8..=9 => 0x03,
            _ => rng.byte(),
        },
    );
}

#[derive(Clone, Copy, Debug)]
enum Mutation {
    BitFlips,
    Truncation,
    Insertion,
    Deletion,
    Duplication,
}

fn mutate(rng: &mut Rng, wire: &[u8]) -> (Mutation, Vec<u8>) {
    let mut out = wire.to_vec();
    let mutation = match rng.below(5) {
        0 => Mutation::BitFlips,
        1 => Mutation::Truncation,
        2 => Mutation::Insertion,
        3 => Mutation::Deletion,
        _ => Mutation::Duplication,
    };
    let special = |rng: &mut Rng| match rng.below(4) {
        0 => 0x10,
        1 => 0x02,
        2 => 0x03,
        _ => rng.byte(),
    };
    match mutation {
        Mutation::BitFlips => {
            for _ in 0..1 + rng.below(3) {
                let at = rng.below(out.len());
                out[at] ^= 1 << rng.below(8);
            }
        }
        Mutation::Truncation => out.truncate(rng.below(out.len())),
        Mutation::Insertion => {
            for _ in 0..1 + rng.below(3) {
                let at = rng.below(out.len() + 1);
                let byte = special(rng);
                out.insert(at, byte);
            }
        }
        Mutation::Deletion => {
            out.remove(rng.below(out.len()));
        }
        Mutation::Duplication => {
            let a = rng.below(out.len());
            let b = a + rng.below(out.len() - a) + 1;
            let piece = out[a..b].to_vec();
            let at = rng.below(out.len() + 1);
            out.splice(at..at, piece);
        }
    }
    (mutation, out)
}

#[test]
fn mutated_valid_frames() {
    const FRAMES: usize = 100_000;
    let mut rng = Rng::new(0x5EED_0004);
    let mut decoder = Decoder::new();
    let mut tally = Tally::default();
    let (mut intact, mut accepted_as_other, mut unchanged) = (0u64, 0u64, 0u64);
    for _ in 0..FRAMES {
        let original = random_frame(&mut rng);
        let wire = encoded(&original);
        let (mutation, bytes) = mutate(&mut rng, &wire);
        if bytes == wire {
            unchanged += 1;
        }
        let out = feed_in_chunks(&mut rng, &mut decoder, &mut tally, &bytes);
        for outcome in &out {
            match outcome {
                Ok(f) if *f == original => intact += 1,
                Ok(f) => {
                    accepted_as_other += 1;
                    println!("undetected: {mutation:?} {original:?} -> {f:?}");
                }
                Err(_) => {}
            }
        }
        assert_marker_decodes(&mut rng, &mut decoder, &mut tally, &bytes);
    }
    tally.check(&decoder);
    tally.report(
        "mutated frames",
        &decoder,
        &format!(
            ", mutated {FRAMES} (unchanged by the mutation {unchanged}), decoded intact \
             {intact}, accepted as another frame {accepted_as_other}"
        ),
    );
    // CRC-16 lets about 1 in 65 536 corrupted frames through; far fewer than 1 in 1000 here.
    assert!(
        accepted_as_other * 1000 <= FRAMES as u64,
        "{accepted_as_other}"
    );
}
