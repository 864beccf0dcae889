//! The field process's loop (`pheromone field`): ticks on wall time, or once per clock message
//! of a simulated world (lockstep), with periodic checkpoints, a standby phase and the
//! once-a-second statistics line. The binary only parses arguments and calls [`run_field`].

use std::path::PathBuf;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::deposit::RejectReason;
use crate::process::checkpoint::{self, Checkpoint, CheckpointError};
use crate::process::lockstep::{self, Participant};
use crate::shm::{
    wait_or_stop, FieldServer, ShmError, Standby, StandbyError, StandbyEvent, StartError, Svc,
    Takeover, TickError, TickOutcome,
};
use crate::FieldConfig;

mod housekeeping;
pub use housekeeping::{Housekeeping, CLEANUP_EVERY};
mod pace;
mod spin;
mod stats;
use iceoryx2::node::Node;
use pace::{pace, DepositWake, Next};
pub use stats::Lateness;
use stats::TickStats;

/// How a field process runs.
#[derive(Debug, Clone)]
pub struct FieldRunOptions {
    /// The field's name (`F` of its services `pheromone/F/…`).
    pub name: String,
    /// The field's configuration (validated when the server starts).
    pub config: FieldConfig,
    /// Tick once per clock message of this simulated world (lockstep) instead of on wall time.
    pub clock: Option<String>,
    /// Stop after this many ticks.
    pub ticks: Option<u64>,
    /// Stop after this much wall time.
    pub duration: Option<Duration>,
    /// Save the frame to this file every `checkpoint_every` and at exit.
    pub checkpoint: Option<PathBuf>,
    /// Wall time between two periodic checkpoints.
    pub checkpoint_every: Duration,
    /// Resume from this checkpoint (already read and checked against the configuration).
    pub restore: Option<(PathBuf, Checkpoint)>,
    /// Mirror the running field of this name and take over when its process dies.
    pub standby: bool,
    /// Publish a frame as soon as deposits arrive, no sooner than this after the last frame
    /// (wall-time fields only); every frame then steps by the real elapsed time.
    pub publish_on_deposit: Option<Duration>,
    /// Threads of each tick's evaporation pass (1..=`engine::MAX_THREADS`; rows split across
    /// threads, the frames bit-identical to one thread's).
    pub threads: usize,
    /// A wall-time tick that starts later than this after its deadline is a missed deadline
    /// (`None`: a tenth of the period).
    pub deadline_slack: Option<Duration>,
    /// Sleep until this long before each deadline, then poll until it (`spin`): ticks start on
    /// time, and publishing on deposit sees a deposit at once, for up to this much CPU a period.
    pub spin: Duration,
}

/// Why a field process stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum FieldRunError {
    /// Starting, ticking, attaching to the clock, or a standby's mirroring failed.
    #[error(transparent)]
    Shm(#[from] ShmError),
    /// The final checkpoint could not be written.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
}

crate::from_shm_errors!(FieldRunError);

impl FieldRunError {
    /// The error is the user's input (a standby whose configuration is not the primary's).
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            FieldRunError::Shm(ShmError::Standby(StandbyError::Mismatch { .. }))
        )
    }
}

/// The checkpoints written during a run.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CheckpointSummary {
    /// The checkpoint file.
    pub file: String,
    /// Checkpoints written, the one at exit included.
    pub written: u64,
    /// Periodic checkpoints that failed (each logged as a warning).
    pub failed: u64,
}

/// What a standby did.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StandbySummary {
    /// Whether the standby took over from its primary.
    pub took_over: bool,
    /// Frames mirrored from the primary before the takeover.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mirrored_frames: Option<u64>,
    /// Sequence of the last frame mirrored from the primary.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_mirrored_sequence: Option<u64>,
    /// Time without a frame across the takeover: from the primary's last frame to the
    /// standby's first (ms).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub takeover_gap_ms: Option<f64>,
    /// Deposits received after the last mirrored frame and applied to the first own frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deposits_carried: Option<u64>,
}

/// What a field process reports at exit (`pheromone field --json`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FieldRunSummary {
    /// The field's name.
    pub field: String,
    /// Frames this process published.
    pub ticks: u64,
    /// Sequence number of the last frame (counts from a restored or mirrored frame on).
    pub sequence: u64,
    /// Field time of the last frame (s).
    pub sim_time_s: f64,
    /// Deposits applied, cumulative like the frame header's counter.
    pub deposits_applied: u64,
    /// Rejected deposits by reason name.
    pub deposits_rejected: std::collections::BTreeMap<String, u64>,
    /// Sum of the cells of each channel in the last frame.
    pub total_mass: Vec<f64>,
    /// Largest cell of each channel in the last frame.
    pub max: Vec<f32>,
    /// The longest tick compute (ms).
    pub max_tick_compute_ms: f64,
    /// The longest wall time between two published frames (ms).
    pub longest_tick_gap_ms: f64,
    /// iceoryx2 nodes of dead processes removed during the run.
    pub dead_nodes_cleaned: u64,
    /// Sequence of the checkpoint the run resumed from, if it was restored.
    pub restored_sequence: Option<u64>,
    /// The checkpoints written, if the run had a checkpoint file.
    pub checkpoint: Option<CheckpointSummary>,
    /// What the standby phase did, if the process started as a standby.
    pub standby: Option<StandbySummary>,
    /// Wall time from the start to the stop (s).
    pub wall_time_s: f64,
    /// Frames published between ticks because deposits arrived (`publish_on_deposit`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_on_deposit: Option<u64>,
    /// Wall-time ticks that started later than the slack after their deadline (not in lockstep).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub missed_deadlines: Option<u64>,
    /// The latest a wall-time tick started after its deadline (ms).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_tick_lateness_ms: Option<f64>,
    /// Wall-time ticks' start after their deadline: percentiles (µs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tick_lateness: Option<Lateness>,
    /// The longest gap between frames in tick periods (wall-time fields).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub longest_tick_gap_periods: Option<f64>,
}

/// Runs a field until its end (ticks, duration, the world's end, Ctrl-C/SIGTERM); `Ok(None)`
/// for a standby stopped before it took over.
pub fn run_field(
    node: &Node<Svc>,
    o: &FieldRunOptions,
) -> Result<Option<FieldRunSummary>, FieldRunError> {
    let started = Instant::now();
    let config = &o.config;
    // The deposit-ready event exists before the deposit service does, so that a depositor that
    // attaches as soon as it finds the field also finds the event to wake it (a standby creates
    // it when it takes over, as the primary's is still there until then).
    let wakes_on_deposit = o.publish_on_deposit.filter(|_| o.clock.is_none());
    let deposit_wake = match wakes_on_deposit {
        Some(min_interval) if !o.standby => {
            Some(DepositWake::new(node, &o.name, config, min_interval)?)
        }
        _ => None,
    };
    let Some(Started {
        mut server,
        longest_gap_ns,
        standby,
    }) = start(node, o)?
    else {
        return Ok(None);
    };
    server
        .set_threads(o.threads)
        .map_err(|source| StartError::Config {
            field: o.name.clone(),
            source,
        })?;
    // Each frame's inputs, for `pheromone bridge` (mirrors on other hosts).
    server.publish_inputs(node)?;
    // Lockstep: join the world's run once every port exists.
    let clock = match &o.clock {
        Some(world) => Some(Participant::join(node, world)?),
        None => None,
    };
    let mut checkpointer = o
        .checkpoint
        .as_ref()
        .map(|path| Checkpointer::new(path.clone(), o.checkpoint_every));
    let period = Duration::from_secs_f64(1.0 / config.tick_hz as f64);
    let slack = o.deadline_slack.unwrap_or(period / 10);
    let mut stats = TickStats::new(longest_gap_ns, slack);
    stats.keep_timing_board(node, &o.name);
    let deposit_wake = match (wakes_on_deposit, deposit_wake) {
        (Some(min_interval), None) => Some(DepositWake::new(node, &o.name, config, min_interval)?),
        (_, wake) => wake,
    };
    // The first deadline and the first gap count from here, after the set-up above (a start,
    // not a tick; a standby's takeover gap is in `longest_gap_ns`).
    stats.last_frame_at = Instant::now();
    let mut pace = pace(o, period, clock, deposit_wake);
    while pace.next_tick(node, &server, stats.last_frame_at)? == Next::Tick {
        let out = pace.tick(&mut server, stats.last_frame_at)?;
        stats.count(&out, pace.lateness());
        if let Some(c) = &mut checkpointer {
            c.maybe_write(&server);
        }
        stats.every_second(node, &o.name, server.stepper());
        if o.ticks.is_some_and(|n| stats.ticks >= n)
            || o.duration.is_some_and(|d| started.elapsed() >= d)
        {
            break;
        }
    }
    let checkpoint = match &mut checkpointer {
        Some(c) => {
            c.finish(&server)?;
            Some(c.summary())
        }
        None => None,
    };
    Ok(Some(summarize(
        o,
        started,
        &server,
        &stats,
        Extras {
            checkpoint,
            standby,
            frames_on_deposit: pace.frames_on_deposit(),
        },
    )))
}

/// The field's server at the start of the loop, and what taking over (for a standby) measured.
struct Started {
    server: FieldServer,
    /// The gap between the primary's last frame and the standby's first (0 for a primary).
    longest_gap_ns: u64,
    standby: Option<StandbySummary>,
}

/// Starts the field's server: a new one (restored from a checkpoint if asked), or a standby's
/// once it took over (`None`: stopped before).
fn start(node: &Node<Svc>, o: &FieldRunOptions) -> Result<Option<Started>, FieldRunError> {
    if o.standby {
        let Some((server, takeover, mirrored)) = run_standby(node, o)? else {
            return Ok(None);
        };
        let gap_ns = takeover
            .first_stamp_ns
            .saturating_sub(takeover.last_mirrored_stamp_ns);
        let ms = |ns: u64| ns as f64 / 1e6;
        eprintln!(
            "field '{}': the primary is gone; took over after frame {} ({:.1} ms without a frame: \
             found gone after {:.1} ms, first own frame {:.1} ms later), {} deposit(s) carried over",
            o.name,
            takeover.last_mirrored_sequence,
            ms(gap_ns),
            ms(takeover
                .detected_stamp_ns
                .saturating_sub(takeover.last_mirrored_stamp_ns)),
            ms(takeover
                .first_stamp_ns
                .saturating_sub(takeover.detected_stamp_ns)),
            takeover.deposits_carried
        );
        return Ok(Some(Started {
            server,
            longest_gap_ns: gap_ns,
            standby: Some(StandbySummary {
                took_over: true,
                mirrored_frames: Some(mirrored),
                last_mirrored_sequence: Some(takeover.last_mirrored_sequence),
                takeover_gap_ms: Some(ms(gap_ns)),
                deposits_carried: Some(takeover.deposits_carried as u64),
            }),
        }));
    }
    let restore = o
        .restore
        .as_ref()
        .map(|(_, c)| (c.header, c.cells.as_slice()));
    if let Some((path, c)) = &o.restore {
        eprintln!(
            "field '{}': restored frame {} (t = {:.3} s, {} deposits applied) from {}",
            o.name,
            c.header.sequence,
            c.header.sim_time_s,
            c.header.deposits_applied,
            path.display()
        );
    }
    Ok(Some(Started {
        server: FieldServer::start(node, &o.name, o.config.clone(), restore)?,
        longest_gap_ns: 0,
        standby: None,
    }))
}

/// The parts of the summary that only some runs have.
struct Extras {
    checkpoint: Option<CheckpointSummary>,
    standby: Option<StandbySummary>,
    frames_on_deposit: Option<u64>,
}

/// Logs the run's last line and returns its summary.
fn summarize(
    o: &FieldRunOptions,
    started: Instant,
    server: &FieldServer,
    stats: &TickStats,
    extras: Extras,
) -> FieldRunSummary {
    let stepper = server.stepper();
    let counters = stepper.counters;
    let (total_mass, max): (Vec<f64>, Vec<f32>) = match server.latest() {
        Some((_, view)) => (0..view.channels)
            .map(|c| (view.total(c), view.max(c)))
            .unzip(),
        None => (vec![], vec![]),
    };
    eprintln!(
        "field '{}' stopped after {} ticks ({:.1} s): {} deposits applied, {} rejected, longest tick {:.3} ms, longest gap between frames {:.3} ms",
        o.name,
        stats.ticks,
        started.elapsed().as_secs_f64(),
        counters.applied,
        counters.rejected_total(),
        stats.max_compute_ns as f64 / 1e6,
        stats.longest_gap_ns as f64 / 1e6
    );
    FieldRunSummary {
        field: o.name.clone(),
        ticks: stats.ticks,
        sequence: stepper.sequence,
        sim_time_s: stepper.sim_time_s,
        deposits_applied: counters.applied,
        deposits_rejected: RejectReason::ALL
            .iter()
            .map(|r| (r.name().to_string(), counters.rejected[*r as usize]))
            .collect(),
        total_mass,
        max,
        max_tick_compute_ms: stats.max_compute_ns as f64 / 1e6,
        missed_deadlines: stats.max_lateness_ns.map(|_| stats.missed_deadlines),
        max_tick_lateness_ms: stats.max_lateness_ns.map(|ns| ns as f64 / 1e6),
        tick_lateness: stats.lateness(),
        longest_tick_gap_periods: stats
            .max_lateness_ns
            .map(|_| stats.longest_gap_ns as f64 * o.config.tick_hz as f64 / 1e9),
        frames_on_deposit: extras.frames_on_deposit,
        longest_tick_gap_ms: stats.longest_gap_ns as f64 / 1e6,
        dead_nodes_cleaned: stats.dead_nodes_cleaned_total(),
        restored_sequence: o.restore.as_ref().map(|(_, c)| c.header.sequence),
        checkpoint: extras.checkpoint,
        standby: extras.standby,
        wall_time_s: started.elapsed().as_secs_f64(),
    }
}

/// The standby phase: mirror the primary until it dies, then take over. `None` when stopped
/// first (Ctrl-C, the duration).
fn run_standby(
    node: &Node<Svc>,
    o: &FieldRunOptions,
) -> Result<Option<(FieldServer, Takeover, u64)>, FieldRunError> {
    let started = Instant::now();
    let period = Duration::from_secs_f64(1.0 / o.config.tick_hz as f64);
    let mut standby =
        Standby::attach_within(node, &o.name, o.config.clone(), Duration::from_secs(30))?;
    eprintln!(
        "field '{}': standby, mirroring the primary (frame {})",
        o.name,
        standby.latest().map(|h| h.sequence).unwrap_or(0)
    );
    loop {
        if crate::shm::should_stop(node) || o.duration.is_some_and(|d| started.elapsed() >= d) {
            eprintln!(
                "field '{}': standby stopped after mirroring {} frames",
                o.name, standby.mirrored
            );
            return Ok(None);
        }
        let event = match standby.poll(period) {
            // The program's own handler ran; the check above sees its stop flag.
            Err(StandbyError::Interrupted { .. }) => continue,
            other => other?,
        };
        if event == StandbyEvent::PrimaryGone {
            let mirrored = standby.mirrored;
            let (server, takeover) = standby.take_over(node)?;
            return Ok(Some((server, takeover, mirrored)));
        }
    }
}

/// Periodic checkpoints: the frame is copied on the tick thread (one memcpy) and written,
/// fsynced and renamed on a background thread, so a slow disk does not stall the ticks.
struct Checkpointer {
    path: PathBuf,
    every: Duration,
    last: Instant,
    writing: Option<std::thread::JoinHandle<Result<u64, CheckpointError>>>,
    written: u64,
    failed: u64,
}

impl Checkpointer {
    fn new(path: PathBuf, every: Duration) -> Self {
        Self {
            path,
            every,
            last: Instant::now(),
            writing: None,
            written: 0,
            failed: 0,
        }
    }

    fn summary(&self) -> CheckpointSummary {
        CheckpointSummary {
            file: self.path.display().to_string(),
            written: self.written,
            failed: self.failed,
        }
    }

    fn collect(&mut self, wait: bool) {
        if let Some(h) = self.writing.take() {
            if !wait && !h.is_finished() {
                self.writing = Some(h);
                return;
            }
            match h.join() {
                Ok(Ok(_)) => self.written += 1,
                Ok(Err(e)) => {
                    self.failed += 1;
                    eprintln!("warning: {e}");
                }
                Err(_) => self.failed += 1,
            }
        }
    }

    fn maybe_write(&mut self, server: &FieldServer) {
        if self.last.elapsed() < self.every {
            return;
        }
        self.collect(false);
        if self.writing.is_some() {
            return; // the previous one is still being written
        }
        if let Some((header, view)) = server.latest() {
            let (header, cells, config) = (*header, view.cells.to_vec(), server.config().clone());
            let path = self.path.clone();
            self.writing = Some(std::thread::spawn(move || {
                checkpoint::write_atomic(&path, &header, &config, &cells)
            }));
            self.last = Instant::now();
        }
    }

    /// Waits for a write in flight, then writes the last frame.
    fn finish(&mut self, server: &FieldServer) -> Result<(), CheckpointError> {
        self.collect(true);
        if let Some((header, view)) = server.latest() {
            checkpoint::write_atomic(&self.path, header, server.config(), view.cells)?;
            self.written += 1;
        }
        Ok(())
    }
}
