//! One test per claim of the shared-air model (module documentation).

use super::*;
use pheromone_gateway_codec::{encoded_len, Message, PirReply, PirRequest};

const PERIOD_S: f64 = 0.1;

fn config(clients: u32) -> RadioConfig {
    RadioConfig {
        clients,
        ..RadioConfig::default()
    }
}

fn run(config: &RadioConfig, seed: u64, periods: u64) -> (Vec<Vec<Exchange>>, AirStats) {
    let mut air = SharedAir::new(config, PERIOD_S, seed).unwrap();
    let out = (0..periods).map(|_| air.next_period()).collect();
    (out, air.stats())
}

#[test]
fn frame_lengths_are_the_codecs_unstuffed_pir_and_reply() {
    let c = RadioConfig::default();
    let pir = Message::Pir(PirRequest {
        x_m: 1.0,
        y_m: 2.0,
        theta_rad: 0.5,
        half_wheel_base_m: 0.15,
        channel: 0,
    });
    let reply = Message::PirReply(PirReply {
        p_left: 0.5,
        p_right: 0.25,
        frame_seq: 7,
    });
    assert_eq!(c.request_bytes as usize, encoded_len(&pir, 1));
    assert_eq!(c.reply_bytes as usize, encoded_len(&reply, 1));
    // 25 bytes of 10 bits at 9600 bit/s.
    assert_eq!(c.airtime_ns(25), 26_041_667);
}

#[test]
fn a_lone_client_gets_every_reply_after_request_turnaround_and_reply() {
    let (out, stats) = run(&config(1), 1, 50);
    let c = RadioConfig::default();
    let exchange = c.airtime_ns(c.request_bytes) + 1_000_000 + c.airtime_ns(c.reply_bytes);
    for (k, p) in out.iter().enumerate() {
        assert!(p[0].delivered, "period {k}: {p:?}");
        assert_eq!(p[0].attempts, 1);
        assert_eq!(p[0].latency_ns, exchange, "period {k}");
    }
    assert_eq!(stats.requests, 50);
    assert_eq!(stats.delivery_rate(), 1.0);
    assert_eq!(stats.collided_frames, 0);
}

#[test]
fn listen_before_talk_defers_while_the_channel_is_busy() {
    let c = config(1);
    let mut air = SharedAir::new(&c, PERIOD_S, 3).unwrap();
    air.next_period();
    // A frame (another network's, say) on the air from now for 30 ms.
    let t0 = air.now_ns + 1_000_000;
    let busy_end = t0 + 30_000_000;
    air.txs.push_back(Tx {
        start_ns: t0,
        end_ns: busy_end,
        collided: false,
    });
    let frames = air.stats.frames;
    let period = air.pending[0].period;
    // The client listens 5 ms into that frame (heard: it started more than sense_s ago).
    air.pending[0].done = false;
    air.pending[0].exchange = Exchange::default();
    air.pending[0].deadline_ns = t0 + 1_000_000_000;
    air.listen(t0 + 5_000_000, 0, period);
    assert_eq!(
        air.stats.frames, frames,
        "it did not talk over the busy channel"
    );
    assert_eq!(air.pending[0].exchange.deferrals, 1);
    let Reverse((at, _, next)) = *air
        .queue
        .iter()
        .filter(|Reverse((_, _, e))| matches!(e, Event::Listen { .. }))
        .max_by_key(|Reverse((t, s, _))| (*t, *s))
        .unwrap();
    assert_eq!(next, Event::Listen { client: 0, period });
    // It listens again at the frame's end plus 1..=backoff_slots slots.
    let slot = air.ns(c.slot_s);
    assert!(at >= busy_end + slot && at <= busy_end + c.backoff_slots as u64 * slot);
    assert_eq!((at - busy_end) % slot, 0);
    // A frame started less than sense_s ago is not heard yet: the client talks (and collides).
    air.txs.clear();
    let t1 = at + 10_000_000;
    air.txs.push_back(Tx {
        start_ns: t1,
        end_ns: t1 + 30_000_000,
        collided: false,
    });
    air.listen(t1 + air.ns(c.sense_s) - 1, 0, period);
    assert_eq!(air.pending[0].exchange.attempts, 1);
    assert!(air.txs.iter().all(|tx| tx.collided), "{:?}", air.txs);
}

#[test]
fn overlapping_frames_collide_and_frames_apart_do_not() {
    let c = config(2);
    let mut air = SharedAir::new(&c, PERIOD_S, 1).unwrap();
    let a = air.transmit(0, 25);
    let b = air.transmit(10_000_000, 20); // starts while `a` (26 ms) is on the air
    let d = air.transmit(40_000_000, 20); // after both ended
    assert!(air.tx(a).collided && air.tx(b).collided);
    assert!(!air.tx(d).collided);
    assert_eq!(air.stats.collided_frames, 2);
    // Back to back is no overlap.
    let e = air.transmit(air.tx(d).end_ns, 20);
    assert!(!air.tx(d).collided && !air.tx(e).collided);
}

#[test]
fn clients_that_collide_retry_after_a_back_off() {
    // Eight clients on a 38 400 bit/s channel (an exchange takes 12 ms of the 100 ms period):
    // collisions happen, and some requests are delivered on a later attempt.
    let c = RadioConfig {
        bitrate_bps: 38_400.0,
        ..config(8)
    };
    let (out, stats) = run(&c, 5, 200);
    assert!(stats.collided_frames > 0, "{stats:?}");
    assert!(stats.deferrals > 0, "{stats:?}");
    let retried = out
        .iter()
        .flatten()
        .filter(|e| e.delivered && e.attempts > 1);
    assert!(retried.count() > 0);
    for e in out.iter().flatten() {
        assert!(e.delivered || e.latency_ns == 0);
        assert!(
            !e.delivered || e.latency_ns < 100_000_000,
            "within the period: {e:?}"
        );
    }
    assert_eq!(stats.requests, 200 * 8);
}

#[test]
fn the_back_off_and_the_outcomes_are_the_same_for_a_seed() {
    let c = RadioConfig {
        loss_probability: 0.1,
        ..config(4)
    };
    let (a, sa) = run(&c, 42, 300);
    let (b, sb) = run(&c, 42, 300);
    assert_eq!(a, b);
    assert_eq!(sa, sb);
    let (other, so) = run(&c, 43, 300);
    assert_ne!(a, other, "another seed draws other phases and back-offs");
    assert_ne!(sa, so);
    // Stepping one air to period 300 in any pieces gives the same outcomes (no clock is read).
    let mut air = SharedAir::new(&c, PERIOD_S, 42).unwrap();
    let again: Vec<Vec<Exchange>> = (0..300).map(|_| air.next_period()).collect();
    assert_eq!(a, again);
}

#[test]
fn the_delivery_rate_falls_as_clients_are_added() {
    let rates: Vec<f64> = [1, 2, 4, 8, 16]
        .iter()
        .map(|&n| run(&config(n), 7, 300).1.delivery_rate())
        .collect();
    assert_eq!(rates[0], 1.0, "{rates:?}");
    for w in rates.windows(2) {
        assert!(w[1] < w[0], "{rates:?}");
    }
    // An exchange takes 48 ms of a 100 ms period: at most two fit per period.
    assert!(rates[3] <= 2.0 / 8.0 + 1e-9, "{rates:?}");
}

#[test]
fn lost_frames_are_retried_and_counted() {
    let c = RadioConfig {
        loss_probability: 0.2,
        ..config(1)
    };
    let (out, stats) = run(&c, 9, 500);
    let share = stats.lost_frames as f64 / stats.frames as f64;
    assert!((0.12..0.28).contains(&share), "{stats:?}");
    // An exchange takes 48 ms of the 100 ms period: a lone client retries at most once, and
    // its retry rarely fits, so about (1 − 0.2)² of its requests get their reply.
    assert!(out.iter().flatten().any(|e| e.attempts == 2));
    assert!(out.iter().flatten().all(|e| e.attempts <= 2));
    let rate = stats.delivery_rate();
    assert!((0.55..0.75).contains(&rate), "{stats:?}");
}

#[test]
fn bad_values_are_refused_by_key_and_value() {
    let cases: Vec<(RadioConfig, &str)> = vec![
        (config(0), "radio.clients = 0"),
        (
            RadioConfig {
                bitrate_bps: f64::NAN,
                ..config(1)
            },
            "radio.bitrate_bps = NaN",
        ),
        (
            RadioConfig {
                slot_s: 0.0,
                ..config(1)
            },
            "radio.slot_s = 0",
        ),
        (
            RadioConfig {
                sense_s: -1.0,
                ..config(1)
            },
            "radio.sense_s = -1",
        ),
        (
            RadioConfig {
                loss_probability: 1.5,
                ..config(1)
            },
            "radio.loss_probability = 1.5",
        ),
        (
            RadioConfig {
                backoff_slots: 0,
                ..config(1)
            },
            "radio.backoff_slots = 0",
        ),
        (
            RadioConfig {
                request_bytes: 0,
                ..config(1)
            },
            "radio.request_bytes = 0",
        ),
    ];
    for (c, want) in cases {
        let e = c.validate().unwrap_err().to_string();
        assert!(e.starts_with(want), "{e}");
        assert!(SharedAir::new(&c, PERIOD_S, 1).is_err());
    }
    let e = SharedAir::new(&config(1), 0.0, 1).unwrap_err().to_string();
    assert!(e.starts_with("radio.period_s = 0"), "{e}");
    assert!(RadioConfig::default().validate().is_ok());
}

#[test]
fn the_most_clients_are_resolved_every_period() {
    let (out, stats) = run(&config(1024), 11, 3);
    assert!(out.iter().all(|p| p.len() == 1024));
    // Two exchanges fit in a period: most of 1024 clients get nothing, none is lost track of.
    let delivered: usize = out.iter().flatten().filter(|e| e.delivered).count();
    assert!(delivered <= 3 * 2, "{delivered}");
    assert!(stats.requests >= 3 * 1024, "{stats:?}");
}
