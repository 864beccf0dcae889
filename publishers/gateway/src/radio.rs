//! The shared air between a gateway and its thin clients (seed 002, Sec. 3B): one half-duplex
//! radio channel, listen-before-talk with a random back-off, and a loss/latency model that is a
//! pure function of its seed.
//!
//! The paper's clients share one channel ("only one network peer is allowed to use the
//! communication medium at any given time, otherwise a data collision occurs"): a client that
//! hears a frame waits for its end "plus a random time delay" before it talks. Over UDP there is
//! no such air, so [`SharedAir`] simulates it, and each thin client asks it whether its request of
//! a control period got its reply, and when. Every process that builds a [`SharedAir`] from the
//! same [`RadioConfig`], seed and period computes the same outcomes (nothing is read from the
//! clock or the real run), so the robots, the sim's metrics and a test agree to the event.
//!
//! **The model.** `clients` thin clients each run a control loop of period `period_s` from their
//! own phase (drawn from the seed, uniform in one period); a client's request of period `k` is
//! ready `k · period_s + phase` plus a jitter uniform in `[0, jitter_s)`, and must have its reply
//! before the next period's tick (its deadline). An exchange:
//!
//! 1. **Listen.** The client senses the channel. A frame is heard `sense_s` after it starts (the
//!    modem's carrier detection); a client that hears one waits for its end, then a back-off of
//!    `1..=backoff_slots` slots of `slot_s` (uniform, from the seed), and listens again.
//! 2. **Talk.** On a quiet channel it sends its PIR (`request_bytes`, 10 bits a byte as on an
//!    8N1 line, at `bitrate_bps`). Two frames that overlap in time collide: both are lost (the
//!    CRC catches it). Two clients whose back-offs end in the same slot, or who start within
//!    `sense_s` of each other, collide.
//! 3. **Reply.** A request that arrived whole (not collided, and not lost: each frame is lost
//!    with `loss_probability`, from the seed) is answered `turnaround_s` after its end by the
//!    server, which does not listen first (it owns the answer); the reply (`reply_bytes`) can
//!    collide with a client that talked into the gap.
//! 4. **Retry.** A client whose reply did not come (at the end the reply would have had) backs
//!    off and listens again; it starts no exchange that could not end before its deadline, and a
//!    request that did not get its reply by then is missed (the robot keeps its last command).
//!
//! Latency is the time from a request's ready time to the end of its reply. Times are integer
//! nanoseconds, so the model is exact and the same on every machine.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};

use pheromone_gateway_codec::data_len;
use serde::{Deserialize, Serialize};

/// Bits on the air per byte: 8N1 (a start bit, 8 data bits, a stop bit), as the paper's modems.
pub const BITS_PER_BYTE: u64 = 10;

/// Bytes of an unstuffed frame around `data` bytes: DLE STX, client ID, opcode, CRC (2), DLE ETX.
pub const FRAME_OVERHEAD_BYTES: u32 = 8;

/// The shared air's parameters (`[radio]` in a scenario file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RadioConfig {
    /// Thin clients on the channel. A scenario's robots through the gateway are clients
    /// 0..R−1 (by robot ID); the rest send the same PIRs at the same rate (air traffic only).
    /// A scenario's `[radio]` without it has one client per robot through the gateway.
    pub clients: u32,
    /// The channel's rate (bits/s); the paper's modems ran at 9600 baud.
    pub bitrate_bps: f64,
    /// The back-off slot (s).
    pub slot_s: f64,
    /// A back-off is 1 to this many slots, uniform.
    pub backoff_slots: u32,
    /// How long after a frame starts a listening client hears it (s): carrier detection.
    pub sense_s: f64,
    /// The server's time from a request's end to its reply's start (s).
    pub turnaround_s: f64,
    /// Each frame (request or reply) is lost with this probability, independently of the others.
    pub loss_probability: f64,
    /// A request leaves up to this long after its client's tick (s), uniform.
    pub jitter_s: f64,
    /// A PIR's length on the air without DLE stuffing (bytes).
    pub request_bytes: u32,
    /// A PIR reply's length on the air without DLE stuffing (bytes).
    pub reply_bytes: u32,
}

impl Default for RadioConfig {
    fn default() -> Self {
        Self {
            clients: 1,
            bitrate_bps: 9600.0,
            slot_s: 0.002,
            backoff_slots: 8,
            sense_s: 0.0005,
            turnaround_s: 0.001,
            loss_probability: 0.0,
            jitter_s: 0.002,
            request_bytes: FRAME_OVERHEAD_BYTES + data_len::PIR as u32,
            reply_bytes: FRAME_OVERHEAD_BYTES + data_len::PIR_REPLY as u32,
        }
    }
}

/// A [`RadioConfig`] value out of range, named by its key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("radio.{key} = {value}: {expected}")]
pub struct RadioConfigError {
    pub key: &'static str,
    pub value: String,
    pub expected: &'static str,
}

impl RadioConfig {
    /// Refuses a value out of range, naming the key and the value.
    pub fn validate(&self) -> Result<(), RadioConfigError> {
        let bad = |key, value: String, expected| {
            Err(RadioConfigError {
                key,
                value,
                expected,
            })
        };
        if !(1..=1024).contains(&self.clients) {
            return bad("clients", self.clients.to_string(), "1 to 1024 clients");
        }
        if !(1..=1 << 16).contains(&self.backoff_slots) {
            return bad(
                "backoff_slots",
                self.backoff_slots.to_string(),
                "1 to 65536 slots",
            );
        }
        for (key, v) in [
            ("request_bytes", self.request_bytes),
            ("reply_bytes", self.reply_bytes),
        ] {
            if !(1..=4096).contains(&v) {
                return bad(key, v.to_string(), "1 to 4096 bytes");
            }
        }
        if !(self.bitrate_bps.is_finite() && (1.0..=1e9).contains(&self.bitrate_bps)) {
            return bad(
                "bitrate_bps",
                self.bitrate_bps.to_string(),
                "1 to 1e9 bits/s",
            );
        }
        let times = [
            ("slot_s", self.slot_s, f64::MIN_POSITIVE),
            ("sense_s", self.sense_s, 0.0),
            ("turnaround_s", self.turnaround_s, 0.0),
            ("jitter_s", self.jitter_s, 0.0),
        ];
        for (key, v, min) in times {
            if !(v.is_finite() && v >= min && v <= 10.0) {
                let expected = if min > 0.0 {
                    "more than 0 and at most 10 s"
                } else {
                    "0 to 10 s"
                };
                return bad(key, v.to_string(), expected);
            }
        }
        if !(0.0..=1.0).contains(&self.loss_probability) {
            return bad(
                "loss_probability",
                self.loss_probability.to_string(),
                "a probability in [0, 1]",
            );
        }
        Ok(())
    }

    /// How long `bytes` take on the air (ns).
    pub fn airtime_ns(&self, bytes: u32) -> u64 {
        secs_ns(bytes as f64 * BITS_PER_BYTE as f64 / self.bitrate_bps)
    }
}

fn secs_ns(s: f64) -> u64 {
    (s * 1e9).round() as u64
}

/// One client's request of one period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Exchange {
    /// The reply came before the deadline.
    pub delivered: bool,
    /// From the request's ready time to the end of its reply (ns); 0 when missed.
    pub latency_ns: u64,
    /// Requests sent (1 + retries).
    pub attempts: u32,
    /// Times the client heard the channel busy and backed off.
    pub deferrals: u32,
}

/// Totals over the periods a [`SharedAir`] has resolved.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct AirStats {
    /// Requests (one per client and period).
    pub requests: u64,
    /// Requests answered before their deadline.
    pub delivered: u64,
    /// Frames (requests and replies) that overlapped another frame.
    pub collided_frames: u64,
    /// Frames lost to `loss_probability`.
    pub lost_frames: u64,
    /// Frames sent (requests and replies).
    pub frames: u64,
    /// Sum of the delivered requests' latencies (ns).
    pub latency_sum_ns: u64,
    /// Times a client heard the channel busy and backed off.
    pub deferrals: u64,
}

impl AirStats {
    /// Delivered / sent requests (1 when none was sent).
    pub fn delivery_rate(&self) -> f64 {
        if self.requests == 0 {
            1.0
        } else {
            self.delivered as f64 / self.requests as f64
        }
    }

    /// Mean latency of the delivered requests (s), `None` when none was delivered.
    pub fn mean_latency_s(&self) -> Option<f64> {
        (self.delivered > 0).then(|| self.latency_sum_ns as f64 / self.delivered as f64 / 1e9)
    }
}

/// SplitMix64: a small, fixed generator, so outcomes never change with a library's version.
#[derive(Debug, Clone)]
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `lo..=hi`.
    fn range(&mut self, lo: u64, hi: u64) -> u64 {
        lo + self.next_u64() % (hi - lo + 1)
    }
}

/// What happens next on the air; `period` names the request a client event belongs to (an
/// event of a request already resolved is ignored).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Event {
    /// The client's request of `period` is ready (its tick).
    Ready { client: u32, period: u64 },
    /// The client listens.
    Listen { client: u32, period: u64 },
    /// The client's request (frame `tx`) ends.
    RequestEnd { client: u32, period: u64, tx: u64 },
    /// The server starts its reply to the client.
    ReplyStart { client: u32, period: u64 },
    /// The reply to the client (frame `tx`) ends.
    ReplyEnd { client: u32, period: u64, tx: u64 },
    /// The client got no reply by now.
    NoReply { client: u32, period: u64 },
}

impl Event {
    /// The client and the period of a client's event (`None` for [`Event::Ready`]).
    fn request(self) -> Option<(u32, u64)> {
        match self {
            Event::Ready { .. } => None,
            Event::Listen { client, period }
            | Event::RequestEnd { client, period, .. }
            | Event::ReplyStart { client, period }
            | Event::ReplyEnd { client, period, .. }
            | Event::NoReply { client, period } => Some((client, period)),
        }
    }
}

/// A frame on the air.
#[derive(Debug, Clone, Copy)]
struct Tx {
    start_ns: u64,
    end_ns: u64,
    collided: bool,
}

#[derive(Debug, Clone, Copy, Default)]
struct Pending {
    period: u64,
    ready_ns: u64,
    deadline_ns: u64,
    exchange: Exchange,
    /// Resolved (delivered or given up).
    done: bool,
}

/// The shared air of [`RadioConfig`] for a control loop of `period_s`, from a seed: see the
/// module's documentation. [`SharedAir::next_period`] resolves the periods in order.
#[derive(Debug, Clone)]
pub struct SharedAir {
    config: RadioConfig,
    period_ns: u64,
    rng: SplitMix64,
    phases_ns: Vec<u64>,
    queue: BinaryHeap<Reverse<(u64, u64, Event)>>,
    /// Events pushed so far: the tie-break of events at the same time.
    pushed: u64,
    /// Frames on the air or recently ended, in the order they started; `txs[0]` is frame
    /// `first_tx`.
    txs: VecDeque<Tx>,
    first_tx: u64,
    /// The time of the last event handled (ns).
    now_ns: u64,
    pending: Vec<Pending>,
    /// Resolved exchanges of periods not returned yet: `(period, client, exchange)`.
    resolved: Vec<(u64, u32, Exchange)>,
    /// How many of `resolved` belong to period `next`.
    resolved_next: usize,
    next: u64,
    stats: AirStats,
}

impl SharedAir {
    /// The air of `config` (validated) for a control period of `period_s` (> 0), from `seed`.
    pub fn new(config: &RadioConfig, period_s: f64, seed: u64) -> Result<Self, RadioConfigError> {
        config.validate()?;
        if !(period_s.is_finite() && period_s > 0.0 && period_s <= 3600.0) {
            return Err(RadioConfigError {
                key: "period_s",
                value: period_s.to_string(),
                expected: "a control period of more than 0 and at most 3600 s",
            });
        }
        let period_ns = secs_ns(period_s).max(1);
        let mut rng = SplitMix64(seed ^ 0x5EED_0002_A1B0_0000);
        let phases_ns: Vec<u64> = (0..config.clients)
            .map(|_| (rng.unit() * period_ns as f64) as u64)
            .collect();
        let mut air = Self {
            config: config.clone(),
            period_ns,
            rng,
            queue: BinaryHeap::new(),
            pushed: 0,
            txs: VecDeque::new(),
            first_tx: 0,
            now_ns: 0,
            pending: vec![
                Pending {
                    done: true,
                    ..Pending::default()
                };
                config.clients as usize
            ],
            resolved: Vec::new(),
            resolved_next: 0,
            next: 0,
            stats: AirStats::default(),
            phases_ns,
        };
        for client in 0..config.clients {
            let at = air.phases_ns[client as usize];
            air.push(at, Event::Ready { client, period: 0 });
        }
        Ok(air)
    }

    pub fn config(&self) -> &RadioConfig {
        &self.config
    }

    /// Totals over the requests resolved so far (those of the periods returned, and any of
    /// the next period resolved on the way).
    pub fn stats(&self) -> AirStats {
        self.stats
    }

    /// Every client's exchange of the next period (0, 1, 2, …), indexed by client.
    pub fn next_period(&mut self) -> Vec<Exchange> {
        let k = self.next;
        let n = self.config.clients as usize;
        while self.resolved_next < n {
            let Some(Reverse((t, _, event))) = self.queue.pop() else {
                break;
            };
            self.now_ns = t;
            self.handle(t, event);
        }
        let mut out = vec![Exchange::default(); n];
        self.resolved.retain(|&(p, c, e)| {
            if p == k {
                out[c as usize] = e;
                false
            } else {
                true
            }
        });
        self.next += 1;
        self.resolved_next = self.resolved.iter().filter(|r| r.0 == self.next).count();
        // Frames that ended before now matter to no one any more (their end events are past).
        while self.txs.front().is_some_and(|tx| tx.end_ns < self.now_ns) {
            self.txs.pop_front();
            self.first_tx += 1;
        }
        out
    }

    fn push(&mut self, t: u64, e: Event) {
        self.pushed += 1;
        self.queue.push(Reverse((t, self.pushed, e)));
    }

    fn tx(&self, id: u64) -> Tx {
        self.txs[(id - self.first_tx) as usize]
    }

    fn handle(&mut self, t: u64, event: Event) {
        if let Some((client, period)) = event.request() {
            let p = &self.pending[client as usize];
            if p.done || p.period != period {
                return;
            }
        }
        match event {
            Event::Ready { client, period } => self.ready(t, client, period),
            Event::Listen { client, period } => self.listen(t, client, period),
            Event::RequestEnd { client, period, tx } => {
                let lost = self.frame_lost(tx);
                if self.tx(tx).collided || lost {
                    let wait = self.ns(self.config.turnaround_s)
                        + self.config.airtime_ns(self.config.reply_bytes);
                    self.push(t + wait, Event::NoReply { client, period });
                } else {
                    let at = t + self.ns(self.config.turnaround_s);
                    self.push(at, Event::ReplyStart { client, period });
                }
            }
            Event::ReplyStart { client, period } => {
                let tx = self.transmit(t, self.config.reply_bytes);
                let end = self.tx(tx).end_ns;
                self.push(end, Event::ReplyEnd { client, period, tx });
            }
            Event::ReplyEnd { client, period, tx } => {
                let lost = self.frame_lost(tx);
                if self.tx(tx).collided || lost {
                    self.back_off(t, client, period);
                } else {
                    let p = &mut self.pending[client as usize];
                    p.exchange.delivered = true;
                    p.exchange.latency_ns = t - p.ready_ns;
                    self.resolve(client);
                }
            }
            Event::NoReply { client, period } => self.back_off(t, client, period),
        }
    }

    fn ns(&self, s: f64) -> u64 {
        secs_ns(s)
    }

    fn ready(&mut self, t: u64, client: u32, period: u64) {
        // The last period's request, if still open, is missed: its deadline is this tick.
        if !self.pending[client as usize].done {
            self.resolve(client);
        }
        let jitter = (self.rng.unit() * self.ns(self.config.jitter_s) as f64) as u64;
        self.pending[client as usize] = Pending {
            period,
            ready_ns: t + jitter,
            deadline_ns: t + self.period_ns,
            exchange: Exchange::default(),
            done: false,
        };
        let next = Event::Ready {
            client,
            period: period + 1,
        };
        self.push(t + self.period_ns, next);
        self.push(t + jitter, Event::Listen { client, period });
    }

    fn listen(&mut self, t: u64, client: u32, period: u64) {
        let sense = self.ns(self.config.sense_s);
        let heard_end = self
            .txs
            .iter()
            .filter(|tx| tx.start_ns + sense <= t && t < tx.end_ns)
            .map(|tx| tx.end_ns)
            .max();
        if let Some(end) = heard_end {
            self.pending[client as usize].exchange.deferrals += 1;
            self.stats.deferrals += 1;
            let slots = self.rng.range(1, self.config.backoff_slots as u64);
            let at = end + slots * self.ns(self.config.slot_s);
            self.push(at, Event::Listen { client, period });
            return;
        }
        // No exchange that cannot end before the deadline (the next tick).
        let exchange_ns = self.config.airtime_ns(self.config.request_bytes)
            + self.ns(self.config.turnaround_s)
            + self.config.airtime_ns(self.config.reply_bytes);
        if t + exchange_ns >= self.pending[client as usize].deadline_ns {
            self.resolve(client);
            return;
        }
        self.pending[client as usize].exchange.attempts += 1;
        let tx = self.transmit(t, self.config.request_bytes);
        let end = self.tx(tx).end_ns;
        self.push(end, Event::RequestEnd { client, period, tx });
    }

    fn back_off(&mut self, t: u64, client: u32, period: u64) {
        let slots = self.rng.range(1, self.config.backoff_slots as u64);
        let at = t + slots * self.ns(self.config.slot_s);
        self.push(at, Event::Listen { client, period });
    }

    /// Puts a frame of `bytes` on the air at `t`; it and every frame still on the air collide.
    fn transmit(&mut self, t: u64, bytes: u32) -> u64 {
        let end_ns = t + self.config.airtime_ns(bytes);
        let mut collided = false;
        for tx in self
            .txs
            .iter_mut()
            .filter(|tx| tx.start_ns <= t && t < tx.end_ns)
        {
            if !tx.collided {
                tx.collided = true;
                self.stats.collided_frames += 1;
            }
            collided = true;
        }
        if collided {
            self.stats.collided_frames += 1;
        }
        self.stats.frames += 1;
        self.txs.push_back(Tx {
            start_ns: t,
            end_ns,
            collided,
        });
        self.first_tx + self.txs.len() as u64 - 1
    }

    /// Draws whether frame `tx` is lost to noise (not drawn for a collided frame).
    fn frame_lost(&mut self, tx: u64) -> bool {
        if self.tx(tx).collided || self.config.loss_probability == 0.0 {
            return false;
        }
        let lost = self.rng.unit() < self.config.loss_probability;
        self.stats.lost_frames += u64::from(lost);
        lost
    }

    fn resolve(&mut self, client: u32) {
        let p = &mut self.pending[client as usize];
        p.done = true;
        self.stats.requests += 1;
        if p.exchange.delivered {
            self.stats.delivered += 1;
            self.stats.latency_sum_ns += p.exchange.latency_ns;
        }
        if p.period == self.next {
            self.resolved_next += 1;
        }
        self.resolved.push((p.period, client, p.exchange));
    }
}

#[cfg(test)]
mod tests;
