//! What the field's loop counts: the run's totals ([`TickStats`]) and the current second's
//! [`Window`] behind the log line.

use std::time::{Duration, Instant};

use super::housekeeping::Housekeeping;
use crate::deposit::RejectReason;
use crate::messages::FieldTiming;
use crate::shm::{cleanup_dead_nodes, Svc, TickOutcome, TimingWriter};
use crate::Stepper;
use iceoryx2::node::Node;

/// The period of the field's log line.
const LOG_EVERY: Duration = Duration::from_secs(1);

/// What the loop counts: the run's totals and the current second's [`Window`].
pub(crate) struct TickStats {
    pub(crate) ticks: u64,
    pub(crate) max_compute_ns: u64,
    pub(crate) longest_gap_ns: u64,
    pub(crate) dead_nodes_cleaned: u64,
    /// A tick later than this after its deadline is a missed deadline.
    pub(crate) slack: Duration,
    pub(crate) missed_deadlines: u64,
    /// The latest tick start after its deadline (`None`: no tick had a deadline).
    pub(crate) max_lateness_ns: Option<u64>,
    /// Every wall-time tick's start after its deadline, µs.
    pub(crate) lateness_us: hdrhistogram::Histogram<u64>,
    /// When the last frame was published (the start, before the first).
    pub(crate) last_frame_at: Instant,
    window: Window,
    /// The totals for `pheromone list` (`pheromone/F/timing`), updated after every frame.
    board: Option<TimingWriter>,
    /// The log line's period, and the cleanup after dead clients off the tick thread (started
    /// by `keep_timing_board`).
    housekeeping: Housekeeping,
}

impl TickStats {
    /// `longest_gap_ns`: a gap before the first tick (a standby's takeover).
    pub(crate) fn new(longest_gap_ns: u64, slack: Duration) -> Self {
        Self {
            ticks: 0,
            max_compute_ns: 0,
            longest_gap_ns,
            dead_nodes_cleaned: 0,
            slack,
            missed_deadlines: 0,
            max_lateness_ns: None,
            // 1 µs to 1000 s at 3 significant digits (≈ 160 KiB).
            lateness_us: hdrhistogram::Histogram::new_with_bounds(1, 1_000_000_000, 3)
                .expect("valid histogram bounds"),
            last_frame_at: Instant::now(),
            window: Window::new(Instant::now()),
            board: None,
            housekeeping: Housekeeping::new(LOG_EVERY),
        }
    }

    /// Keeps the totals on field `field`'s timing board from now on. Monitoring only: a field
    /// that cannot create it (e.g. a dead primary's is still there) runs without it, and says so.
    pub(crate) fn keep_timing_board(&mut self, node: &Node<Svc>, field: &str) {
        if !crate::shm::cleaned_by_supervisor() {
            cleanup_dead_nodes(node);
        }
        self.housekeeping = Housekeeping::new(LOG_EVERY).with_cleanup_thread(node);
        self.window = Window::new(Instant::now());
        self.board = TimingWriter::create(node, field)
            .map_err(|e| eprintln!("field '{field}': `pheromone list` will show no timing: {e}"))
            .ok();
        if let Some(b) = &self.board {
            b.set(self.timing());
        }
    }

    /// Counts a frame just published, `late` after its deadline if it had one.
    pub(crate) fn count(&mut self, out: &TickOutcome, late: Option<Duration>) {
        if let Some(late) = late {
            let ns = late.as_nanos() as u64;
            self.max_lateness_ns = Some(self.max_lateness_ns.unwrap_or(0).max(ns));
            self.lateness_us.saturating_record(ns / 1000);
            if late > self.slack {
                self.missed_deadlines += 1;
                self.window.missed += 1;
            }
        }
        let now = Instant::now();
        let gap_ns = now.duration_since(self.last_frame_at).as_nanos() as u64;
        self.last_frame_at = now;
        self.longest_gap_ns = self.longest_gap_ns.max(gap_ns);
        self.ticks += 1;
        self.max_compute_ns = self.max_compute_ns.max(out.compute_ns);
        self.window.add(out, gap_ns);
        if let Some(b) = &self.board {
            b.set(self.timing());
        }
    }

    /// The run's timing so far, as `pheromone list` reads it (`pheromone/F/timing`).
    pub(crate) fn timing(&self) -> FieldTiming {
        FieldTiming {
            ticks: self.ticks,
            missed_deadlines: self.missed_deadlines,
            max_lateness_ns: self.max_lateness_ns.unwrap_or(u64::MAX),
            longest_gap_ns: self.longest_gap_ns,
            max_compute_ns: self.max_compute_ns,
            slack_ns: self.slack.as_nanos().try_into().unwrap_or(u64::MAX),
        }
    }

    /// Once a second: logs the window's line (with what the housekeeping thread freed of
    /// clients killed meanwhile: their ports and frames) and starts the next window.
    pub(crate) fn every_second(&mut self, node: &Node<Svc>, field: &str, stepper: &Stepper) {
        if self.housekeeping.due(node) {
            let cleaned = self.housekeeping.take_cleaned();
            self.dead_nodes_cleaned += cleaned;
            self.window.log(field, stepper, cleaned);
            self.window = Window::new(Instant::now());
        }
    }
}

/// Per-second statistics for the log line.
struct Window {
    started: Instant,
    ticks: u64,
    compute_ns: u64,
    max_compute_ns: u64,
    applied: u64,
    rejected: u64,
    longest_gap_ns: u64,
    /// Ticks that started later than the slack after their deadline.
    missed: u64,
}

impl Window {
    fn new(started: Instant) -> Self {
        Self {
            started,
            ticks: 0,
            compute_ns: 0,
            max_compute_ns: 0,
            applied: 0,
            rejected: 0,
            longest_gap_ns: 0,
            missed: 0,
        }
    }

    fn add(&mut self, out: &TickOutcome, gap_ns: u64) {
        self.ticks += 1;
        self.longest_gap_ns = self.longest_gap_ns.max(gap_ns);
        self.compute_ns += out.compute_ns;
        self.max_compute_ns = self.max_compute_ns.max(out.compute_ns);
        self.applied += out.report.deposits_applied as u64;
        self.rejected += out.rejected;
    }

    fn log(&self, name: &str, stepper: &Stepper, dead_nodes_cleaned: u64) {
        let secs = self.started.elapsed().as_secs_f64();
        let c = stepper.counters;
        let reasons: Vec<String> = RejectReason::ALL
            .iter()
            .filter(|r| c.rejected[**r as usize] > 0)
            .map(|r| format!("{} {}", r.name(), c.rejected[*r as usize]))
            .collect();
        eprintln!(
            "field '{name}': {:.1} ticks/s, tick {:.3} ms mean / {:.3} ms max, longest_tick_gap_ms {:.3}, \
             deposits +{} applied +{} rejected (total {} applied, {} rejected{}{}){}{}",
            self.ticks as f64 / secs,
            self.compute_ns as f64 / self.ticks.max(1) as f64 / 1e6,
            self.max_compute_ns as f64 / 1e6,
            self.longest_gap_ns as f64 / 1e6,
            self.applied,
            self.rejected,
            c.applied,
            c.rejected_total(),
            if reasons.is_empty() { "" } else { ": " },
            reasons.join(", "),
            if dead_nodes_cleaned > 0 {
                format!("; cleaned {dead_nodes_cleaned} dead node(s)")
            } else {
                String::new()
            },
            if self.missed > 0 {
                format!("; missed {} deadline(s)", self.missed)
            } else {
                String::new()
            }
        );
    }
}

/// Tick-start lateness over a run (µs), for the `--json` summary.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Lateness {
    /// Median lateness (µs).
    pub p50_us: u64,
    /// 99th percentile (µs).
    pub p99_us: u64,
    /// 99.9th percentile (µs).
    pub p999_us: u64,
    /// Largest lateness of any tick (µs).
    pub max_us: u64,
}

impl TickStats {
    /// Dead nodes removed over the run, including what the housekeeping thread removed since
    /// the last log line.
    pub(crate) fn dead_nodes_cleaned_total(&self) -> u64 {
        self.dead_nodes_cleaned + self.housekeeping.take_cleaned()
    }

    /// The lateness percentiles (`None` when no tick had a wall-time deadline).
    pub(crate) fn lateness(&self) -> Option<Lateness> {
        let h = &self.lateness_us;
        (!h.is_empty()).then(|| Lateness {
            p50_us: h.value_at_quantile(0.5),
            p99_us: h.value_at_quantile(0.99),
            p999_us: h.value_at_quantile(0.999),
            max_us: h.max(),
        })
    }
}
