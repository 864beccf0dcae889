//! Deposits from a mirror to its origin, at most once and never silently lost.
//!
//! A mirror numbers the batches of local deposits it sends (`codec::encode_deposits`: its id,
//! one per mirror run, and the batch number from 1) and keeps each batch in its [`Outbox`] until
//! the bridge answers it (`codec::DepositAck`). A batch not answered within [`RESEND_AFTER`] is
//! sent again, the same batch under the same number: when a Zenoh session dies (a bridge killed,
//! a partition longer than the lease) the puts in flight are lost without an error, and only an
//! answer tells the mirror its deposits reached the origin. The bridge remembers which batches
//! of which mirror it has handed to the field ([`Seen`]) and answers a batch sent again without
//! handing it over twice.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::time::{Duration, Instant};

use pheromone_field::DepositMsg;

/// A batch not answered for this long is sent again (then every `RESEND_AFTER` while live).
pub const RESEND_AFTER: Duration = Duration::from_millis(500);
/// A mirror says once (per batch) that a batch has gone unanswered this long.
pub const UNANSWERED_WARN_AFTER: Duration = Duration::from_secs(5);
/// Deposits per batch.
pub const BATCH_MAX: usize = 4096;
/// Mirrors the bridge keeps answers for (the least recently heard are forgotten first).
pub const MIRRORS_KEPT: usize = 1024;

/// One batch sent and not yet answered.
#[derive(Debug, Clone)]
struct Sent {
    deposits: Vec<DepositMsg>,
    /// When it was last sent; `None`: held, never sent (the mirror was stale).
    sent_at: Option<Instant>,
    first_sent_at: Option<Instant>,
    times_sent: u32,
    warned: bool,
}

/// What an outbox answer changed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Answered {
    pub forwarded: u64,
    pub refused: u64,
}

/// The mirror's side: batches numbered from 1, each kept until answered.
#[derive(Debug)]
pub struct Outbox {
    mirror_id: u64,
    next_batch: u64,
    unanswered: BTreeMap<u64, Sent>,
    /// Deposits in `unanswered`.
    kept: usize,
}

impl Outbox {
    /// An outbox for mirror run `mirror_id` (nonzero).
    pub fn new(mirror_id: u64) -> Self {
        assert_ne!(mirror_id, 0, "mirror id 0 means \"no answer wanted\"");
        Self {
            mirror_id,
            next_batch: 1,
            unanswered: BTreeMap::new(),
            kept: 0,
        }
    }

    pub fn mirror_id(&self) -> u64 {
        self.mirror_id
    }

    /// Deposits kept (sent and unanswered, or held).
    pub fn deposits(&self) -> usize {
        self.kept
    }

    pub fn batches(&self) -> usize {
        self.unanswered.len()
    }

    /// Takes new local deposits as numbered batches, not sent yet.
    pub fn push(&mut self, deposits: Vec<DepositMsg>) {
        self.kept += deposits.len();
        for chunk in deposits.chunks(BATCH_MAX) {
            self.unanswered.insert(
                self.next_batch,
                Sent {
                    deposits: chunk.to_vec(),
                    sent_at: None,
                    first_sent_at: None,
                    times_sent: 0,
                    warned: false,
                },
            );
            self.next_batch += 1;
        }
    }

    /// Drops the oldest deposits beyond `max` kept (whole batches first, then the oldest of the
    /// oldest batch); how many went.
    pub fn trim_to(&mut self, max: usize) -> u64 {
        let mut dropped = 0u64;
        while self.kept > max {
            let excess = self.kept - max;
            let mut oldest = self.unanswered.first_entry().expect("more than max > 0");
            let n = oldest.get().deposits.len().min(excess);
            if n == oldest.get().deposits.len() {
                oldest.remove();
            } else {
                oldest.get_mut().deposits.drain(..n);
            }
            self.kept -= n;
            dropped += n as u64;
        }
        dropped
    }

    /// The batches due at `now` (never sent, or unanswered for `RESEND_AFTER`), marked sent:
    /// (batch number, deposits, whether it is a resend).
    pub fn due(&mut self, now: Instant) -> Vec<(u64, Vec<DepositMsg>, bool)> {
        let mut out = Vec::new();
        for (&batch, s) in &mut self.unanswered {
            let due = s
                .sent_at
                .is_none_or(|t| now.saturating_duration_since(t) >= RESEND_AFTER);
            if due {
                out.push((batch, s.deposits.clone(), s.times_sent > 0));
                s.sent_at = Some(now);
                s.first_sent_at.get_or_insert(now);
                s.times_sent += 1;
            }
        }
        out
    }

    /// Batches first sent over `UNANSWERED_WARN_AFTER` ago and not reported yet: (batch,
    /// deposits, times sent).
    pub fn overdue(&mut self, now: Instant) -> Vec<(u64, usize, u32)> {
        let mut out = Vec::new();
        for (&batch, s) in &mut self.unanswered {
            let late = s
                .first_sent_at
                .is_some_and(|t| now.saturating_duration_since(t) >= UNANSWERED_WARN_AFTER);
            if late && !s.warned {
                s.warned = true;
                out.push((batch, s.deposits.len(), s.times_sent));
            }
        }
        out
    }

    /// An answer: the batch is done (`None` for an answer to another mirror, or to a batch
    /// already answered).
    pub fn answer(&mut self, ack: &super::codec::DepositAck) -> Option<Answered> {
        if ack.mirror_id != self.mirror_id {
            return None;
        }
        let done = self.unanswered.remove(&ack.batch)?;
        self.kept -= done.deposits.len();
        Some(Answered {
            forwarded: u64::from(ack.forwarded),
            refused: u64::from(ack.refused),
        })
    }
}

/// Which batches of one mirror were handed to the field: all below `below`, and those in
/// `above`.
#[derive(Debug, Default)]
struct Window {
    below: u64,
    above: BTreeSet<u64>,
    /// The answers to the batches in `above` and the newest ones below (to answer a resend).
    answers: VecDeque<(u64, u32, u32)>,
}

/// Answers kept per mirror for resends.
const ANSWERS_KEPT: usize = 4096;

impl Window {
    fn contains(&self, batch: u64) -> bool {
        batch < self.below || self.above.contains(&batch)
    }

    fn insert(&mut self, batch: u64, forwarded: u32, refused: u32) {
        if self.below == 0 {
            self.below = 1;
        }
        if batch >= self.below {
            self.above.insert(batch);
        }
        while self.above.remove(&self.below) {
            self.below += 1;
        }
        self.answers.push_back((batch, forwarded, refused));
        if self.answers.len() > ANSWERS_KEPT {
            self.answers.pop_front();
        }
    }

    /// Every batch below `below` was handed over.
    fn floor(&mut self, below: u64) {
        self.below = self.below.max(below);
        self.above.retain(|&b| b >= self.below);
        while self.above.remove(&self.below) {
            self.below += 1;
        }
    }

    fn answer(&self, batch: u64) -> (u32, u32) {
        self.answers
            .iter()
            .rev()
            .find(|a| a.0 == batch)
            .map_or((0, 0), |a| (a.1, a.2))
    }
}

/// One thing [`Seen`] knows of a mirror's batches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Known {
    /// (mirror, below): every batch below was handed over.
    Below(u64, u64),
    /// (mirror, batch, forwarded, refused): handed over, with its answer.
    Handed(u64, u64, u32, u32),
}

/// The bridge's side: the batches it has handed to the field, per mirror.
#[derive(Debug, Default)]
pub struct Seen {
    mirrors: HashMap<u64, (Window, u64)>,
    /// Bumped on every batch (least recently heard mirror: smallest stamp).
    clock: u64,
}

impl Seen {
    /// The answer already given to `batch` of `mirror_id`, if it was handed over before.
    pub fn earlier(&mut self, mirror_id: u64, batch: u64) -> Option<(u32, u32)> {
        self.clock += 1;
        let clock = self.clock;
        let (w, heard) = self.mirrors.get_mut(&mirror_id)?;
        *heard = clock;
        w.contains(batch).then(|| w.answer(batch))
    }

    /// Records that every batch of `mirror_id` below `below` was handed over (their answers
    /// unknown: a resend of one is answered with none forwarded).
    pub fn floor(&mut self, mirror_id: u64, below: u64) {
        self.heard(mirror_id).floor(below);
    }

    /// What this holds, for a compacted journal (`journal`).
    pub(crate) fn known(&self) -> Vec<Known> {
        let mut out = Vec::new();
        for (&m, (w, _)) in &self.mirrors {
            if w.below > 1 {
                out.push(Known::Below(m, w.below));
            }
            let answered: BTreeSet<u64> = w.answers.iter().map(|a| a.0).collect();
            out.extend(w.answers.iter().map(|&(b, f, r)| Known::Handed(m, b, f, r)));
            out.extend(
                w.above
                    .iter()
                    .filter(|b| !answered.contains(b))
                    .map(|&b| Known::Handed(m, b, 0, 0)),
            );
        }
        out
    }

    /// Records that `batch` of `mirror_id` was handed over.
    pub fn record(&mut self, mirror_id: u64, batch: u64, forwarded: u32, refused: u32) {
        self.heard(mirror_id).insert(batch, forwarded, refused);
    }

    /// `mirror_id`'s window, heard now (made, forgetting the least recently heard mirror when
    /// `MIRRORS_KEPT` are kept).
    fn heard(&mut self, mirror_id: u64) -> &mut Window {
        self.clock += 1;
        if !self.mirrors.contains_key(&mirror_id) && self.mirrors.len() >= MIRRORS_KEPT {
            let stalest = self
                .mirrors
                .iter()
                .min_by_key(|(_, (_, heard))| *heard)
                .map(|(id, _)| *id)
                .expect("MIRRORS_KEPT > 0");
            self.mirrors.remove(&stalest);
        }
        let entry = self
            .mirrors
            .entry(mirror_id)
            .or_insert_with(|| (Window::default(), 0));
        entry.1 = self.clock;
        &mut entry.0
    }
}

#[cfg(test)]
mod tests {
    use super::super::codec::DepositAck;
    use super::*;

    fn deposits(n: usize) -> Vec<DepositMsg> {
        (0..n)
            .map(|i| DepositMsg {
                robot_id: i as u32,
                amount: 1.0,
                ..DepositMsg::default()
            })
            .collect()
    }

    fn ack(batch: u64) -> DepositAck {
        DepositAck {
            mirror_id: 7,
            batch,
            forwarded: 1,
            refused: 0,
        }
    }

    #[test]
    fn an_unanswered_batch_is_sent_again_under_its_number_until_answered() {
        let mut o = Outbox::new(7);
        let t0 = Instant::now();
        o.push(deposits(3));
        let first = o.due(t0);
        assert_eq!(first.len(), 1);
        assert_eq!((first[0].0, first[0].1.len(), first[0].2), (1, 3, false));
        assert!(o.due(t0 + RESEND_AFTER / 2).is_empty(), "not due yet");
        let again = o.due(t0 + RESEND_AFTER);
        assert_eq!((again[0].0, again[0].2), (1, true));
        assert_eq!(o.answer(&ack(1)).map(|a| a.forwarded), Some(1));
        assert!(o.due(t0 + RESEND_AFTER * 3).is_empty());
        assert_eq!(o.answer(&ack(1)), None, "answered twice");
        let other = DepositAck {
            mirror_id: 8,
            ..ack(1)
        };
        assert_eq!(o.answer(&other), None);
    }

    #[test]
    fn batches_are_split_at_batch_max_and_trimmed_oldest_first() {
        let mut o = Outbox::new(1);
        o.push(deposits(BATCH_MAX + 5));
        assert_eq!((o.batches(), o.deposits()), (2, BATCH_MAX + 5));
        o.push(deposits(10));
        assert_eq!(o.trim_to(12), (BATCH_MAX + 3) as u64);
        assert_eq!(o.deposits(), 12);
        let due = o.due(Instant::now());
        assert_eq!(
            due.iter().map(|d| (d.0, d.1.len())).collect::<Vec<_>>(),
            vec![(2, 2), (3, 10)],
            "the oldest went: batch 1 whole, 3 of batch 2"
        );
    }

    #[test]
    fn a_batch_is_overdue_once() {
        let mut o = Outbox::new(1);
        let t0 = Instant::now();
        o.push(deposits(2));
        o.due(t0);
        assert!(o.overdue(t0 + RESEND_AFTER).is_empty());
        assert_eq!(o.overdue(t0 + UNANSWERED_WARN_AFTER), vec![(1, 2, 1)]);
        assert!(o.overdue(t0 + UNANSWERED_WARN_AFTER * 2).is_empty());
    }

    #[test]
    fn the_bridge_hands_each_batch_over_once_in_any_order() {
        let mut s = Seen::default();
        for b in [1, 3, 2, 5] {
            assert_eq!(s.earlier(9, b), None, "batch {b} is new");
            s.record(9, b, b as u32, 0);
        }
        for b in [1, 2, 3, 5] {
            assert_eq!(s.earlier(9, b), Some((b as u32, 0)), "batch {b} again");
        }
        assert_eq!(s.earlier(9, 4), None);
        assert_eq!(s.earlier(10, 1), None, "another mirror's batch 1");
    }

    #[test]
    fn the_least_recently_heard_mirror_is_forgotten_first() {
        let mut s = Seen::default();
        for id in 1..=MIRRORS_KEPT as u64 {
            s.record(id, 1, 1, 0);
        }
        assert!(s.earlier(1, 1).is_some(), "mirror 1 heard again");
        s.record(u64::MAX, 1, 1, 0);
        assert!(s.earlier(1, 1).is_some());
        assert!(s.earlier(2, 1).is_none(), "mirror 2 was the stalest");
    }
}
