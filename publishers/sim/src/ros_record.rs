//! `pheromone sim --record FILE.mcap`: the run as a ROS 2 MCAP file (profile `ros2`, `ros2msg`
//! schemas, CDR messages, written by `pheromone_ros2::record::McapRecorder` as `pheromone record --mcap`
//! writes its files), stamped with simulated time (docs/ros2.md, "pheromone sim --record"):
//!
//! - `/pheromone/grid_map` and `/pheromone/occupancy/channel_<c>`: each field frame the run
//!   records ([`Recording::snapshots`]: the scenario's `snapshots_s` and the last frame);
//! - `/robot_<id>/true_pose` and `/robot_<id>/estimated_pose` (PoseWithCovarianceStamped) at
//!   every step, the true one with a zero covariance;
//! - `/robot_<id>/true_path` and `/robot_<id>/estimated_path` (nav_msgs/Path): the trajectory so
//!   far, with each field frame;
//! - `/pheromone/deposits` (`pheromone_msgs/msg/Deposit`): every deposit the field applied, in
//!   the order it applied them, stamped with the time of its step.
//!
//! The run only hands owned values to a channel ([`SimMcap`]); a writer thread serializes and
//! writes them. It closes a chunk and flushes the file at each field frame and at most
//! [`FLUSH_AFTER`] after any message, so a run killed outright leaves a file readable up to
//! its last flush; a run that fails or is interrupted drops its [`SimMcap`], which finishes
//! the file (summary and footer) with everything sent so far.

use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use pheromone_field::{DepositMsg, GridGeometry};
use pheromone_messages::PoseMsg;
use pheromone_ros2::frames::{frame_cdr, FieldTopics};
use pheromone_ros2::grid::{FrameRef, Stamp};
use pheromone_ros2::record::{McapRecorder, RecordError};
use pheromone_ros2::robot::{
    covariance_6x6, deposit_cdr, path_cdr, pose_with_covariance_cdr, Pose2,
};
use pheromone_ros2::types::{TypeInfo, DEPOSIT, PATH, POSE_COV_STAMPED};
use pheromone_world::scenario::Scenario;
use serde::Serialize;

use crate::recording::{deposit_peak, Recording, Snapshot};

/// `header.frame_id` of every message.
pub const FRAME_ID: &str = "map";
/// The longest a written message waits before its chunk is closed and flushed.
pub const FLUSH_AFTER: Duration = Duration::from_millis(50);
/// Events the run may be ahead of the writer before it waits for it.
const QUEUE: usize = 4096;

/// One robot at one step.
#[derive(Debug, Clone, Copy)]
pub struct PoseRow {
    pub robot: u32,
    /// Simulated time of the step (s).
    pub t_s: f64,
    /// True x (m), y (m), θ (rad).
    pub truth: Pose2,
    /// The localizer's estimate of the step, with its covariance.
    pub estimate: Option<PoseMsg>,
}

enum Event {
    Poses(Vec<PoseRow>),
    /// The deposits a step's tick applied, with the step's time.
    Deposits(f64, Vec<DepositMsg>),
    Frame(Snapshot),
}

/// What a recording wrote.
#[derive(Debug, Clone, Default, Serialize)]
pub struct McapTotals {
    pub file: PathBuf,
    pub messages: u64,
    /// Bytes of CDR messages (the file adds its records, schemas and indexes).
    pub message_bytes: u64,
    pub frames: u64,
    pub poses: u64,
    pub deposits: u64,
    /// Process runs: steps where the deposits the observer expected to be applied were not as
    /// many as the field's frame says it applied (0 when the recording is exact).
    pub deposit_mismatches: u64,
}

/// The recording of a run: a channel to the writer thread.
pub struct SimMcap {
    tx: Option<SyncSender<Event>>,
    writer: Option<JoinHandle<Result<McapTotals, RecordError>>>,
    /// Snapshots of the run's [`Recording`] already sent.
    snapshots_sent: usize,
    pub(crate) deposit_mismatches: u64,
}

impl SimMcap {
    /// Adds the run's topics to `rec` (a file just created) and starts the writer.
    pub fn start(mut rec: McapRecorder, scenario: &Scenario) -> Result<Self, RecordError> {
        let geometry = scenario.field.geometry();
        let channels = scenario.field.channels.len();
        let field = FieldTopics::new("/", channels).expect("the root namespace is valid");
        let mut field_topics = Vec::new();
        for (name, t) in field.names.iter().zip(&field.types) {
            field_topics.push(rec.add_topic(name, t)?);
        }
        let deposits = rec.add_topic("/pheromone/deposits", &TypeInfo::of(DEPOSIT))?;
        let (pose_t, path_t) = (TypeInfo::of(POSE_COV_STAMPED), TypeInfo::of(PATH));
        let mut robots = Vec::new();
        for r in &scenario.world.robots {
            let topic = |what: &str| format!("/robot_{}/{what}", r.id);
            robots.push(RobotTopics {
                id: r.id,
                true_pose: rec.add_topic(&topic("true_pose"), &pose_t)?,
                estimated_pose: rec.add_topic(&topic("estimated_pose"), &pose_t)?,
                true_path: rec.add_topic(&topic("true_path"), &path_t)?,
                estimated_path: rec.add_topic(&topic("estimated_path"), &path_t)?,
                truths: Vec::new(),
                estimates: Vec::new(),
            });
        }
        let writer = Writer {
            rec,
            geometry,
            field_topics,
            deposits,
            robots,
            totals: McapTotals::default(),
            unflushed_since: None,
        };
        let (tx, rx) = mpsc::sync_channel(QUEUE);
        let writer = std::thread::Builder::new()
            .name("sim-record".into())
            .spawn(move || writer.run(rx))
            .map_err(|e| RecordError {
                path: PathBuf::new(),
                action: "start the writer thread",
                detail: e.to_string(),
            })?;
        Ok(Self {
            tx: Some(tx),
            writer: Some(writer),
            snapshots_sent: 0,
            deposit_mismatches: 0,
        })
    }

    fn send(&mut self, e: Event) {
        // A writer that stopped on an error has dropped its end: the error comes with finish.
        if let Some(tx) = &self.tx {
            if tx.send(e).is_err() {
                self.tx = None;
            }
        }
    }

    /// Every robot at one step (or several).
    pub fn poses(&mut self, rows: Vec<PoseRow>) {
        if !rows.is_empty() {
            self.send(Event::Poses(rows));
        }
    }

    /// The deposits the tick of the step at `t_s` applied, in the order it applied them.
    pub fn deposits(&mut self, t_s: f64, applied: &[DepositMsg]) {
        if !applied.is_empty() {
            self.send(Event::Deposits(t_s, applied.to_vec()));
        }
    }

    /// The snapshots `rec` took since the last call.
    pub fn frames(&mut self, rec: &Recording) {
        self.frames_up_to(rec, rec.snapshots.len());
    }

    /// The snapshots of `rec` not sent yet among its first `n`.
    pub fn frames_up_to(&mut self, rec: &Recording, n: usize) {
        while self.snapshots_sent < n.min(rec.snapshots.len()) {
            let s = rec.snapshots[self.snapshots_sent].clone();
            self.snapshots_sent += 1;
            self.send(Event::Frame(s));
        }
    }

    /// Writes what is queued, the summary and the footer.
    pub fn finish(mut self) -> Result<McapTotals, RecordError> {
        let mismatches = self.deposit_mismatches;
        self.close().map(|mut t| {
            t.deposit_mismatches = mismatches;
            t
        })
    }

    fn close(&mut self) -> Result<McapTotals, RecordError> {
        self.tx = None;
        match self.writer.take().map(JoinHandle::join) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(RecordError {
                path: PathBuf::new(),
                action: "write",
                detail: "the writer thread panicked".into(),
            }),
            None => Ok(McapTotals::default()),
        }
    }
}

impl Drop for SimMcap {
    /// A run that failed: the file is finished with what was sent.
    fn drop(&mut self) {
        if self.writer.is_some() {
            if let Err(e) = self.close() {
                eprintln!("sim --record: {e}");
            }
        }
    }
}

struct RobotTopics {
    id: u32,
    true_pose: usize,
    estimated_pose: usize,
    true_path: usize,
    estimated_path: usize,
    truths: Vec<(Stamp, Pose2)>,
    estimates: Vec<(Stamp, Pose2)>,
}

/// The writer thread's state.
struct Writer {
    rec: McapRecorder,
    geometry: GridGeometry,
    field_topics: Vec<usize>,
    deposits: usize,
    robots: Vec<RobotTopics>,
    totals: McapTotals,
    /// When the first message not yet flushed was written.
    unflushed_since: Option<Instant>,
}

impl Writer {
    fn run(mut self, rx: Receiver<Event>) -> Result<McapTotals, RecordError> {
        loop {
            let event = match self.unflushed_since {
                Some(t) => match rx.recv_timeout(FLUSH_AFTER.saturating_sub(t.elapsed())) {
                    Ok(e) => Some(e),
                    Err(RecvTimeoutError::Timeout) => None,
                    Err(RecvTimeoutError::Disconnected) => break,
                },
                None => match rx.recv() {
                    Ok(e) => Some(e),
                    Err(_) => break,
                },
            };
            match event {
                Some(e) => self.write(e)?,
                None => self.flush()?,
            }
            if self
                .unflushed_since
                .is_some_and(|t| t.elapsed() >= FLUSH_AFTER)
            {
                self.flush()?;
            }
        }
        self.totals.file = self.rec.path().to_path_buf();
        self.totals.messages = self.rec.messages;
        self.totals.message_bytes = self.rec.bytes;
        let totals = std::mem::take(&mut self.totals);
        self.rec.finish()?;
        Ok(totals)
    }

    fn flush(&mut self) -> Result<(), RecordError> {
        self.unflushed_since = None;
        self.rec.end_frame()
    }

    fn put(&mut self, topic: usize, stamp: Stamp, cdr: &[u8]) -> Result<(), RecordError> {
        self.unflushed_since.get_or_insert_with(Instant::now);
        self.rec.write(topic, stamp.as_ns().max(0) as u64, cdr)
    }

    fn robot(&mut self, id: u32) -> Option<usize> {
        self.robots.iter().position(|r| r.id == id)
    }

    fn write(&mut self, e: Event) -> Result<(), RecordError> {
        match e {
            Event::Poses(rows) => {
                for row in rows {
                    self.pose_row(&row)?;
                }
            }
            Event::Deposits(t_s, list) => {
                let stamp = Stamp::from_secs(t_s);
                for d in &list {
                    let cdr = deposit_cdr(stamp, FRAME_ID, d, deposit_peak(d));
                    self.put(self.deposits, stamp, &cdr)?;
                    self.totals.deposits += 1;
                }
            }
            Event::Frame(s) => self.frame(&s)?,
        }
        Ok(())
    }

    fn pose_row(&mut self, row: &PoseRow) -> Result<(), RecordError> {
        let Some(i) = self.robot(row.robot) else {
            return Ok(());
        };
        let stamp = Stamp::from_secs(row.t_s);
        let cdr = pose_with_covariance_cdr(stamp, FRAME_ID, row.truth, &[0.0; 36]);
        self.put(self.robots[i].true_pose, stamp, &cdr)?;
        self.robots[i].truths.push((stamp, row.truth));
        self.totals.poses += 1;
        if let Some(p) = &row.estimate {
            let est = [p.x_m, p.y_m, p.theta_rad];
            let cdr = pose_with_covariance_cdr(stamp, FRAME_ID, est, &covariance_6x6(&p.cov));
            self.put(self.robots[i].estimated_pose, stamp, &cdr)?;
            self.robots[i].estimates.push((stamp, est));
            self.totals.poses += 1;
        }
        Ok(())
    }

    /// A field frame, then each robot's paths so far; closes the chunk.
    fn frame(&mut self, s: &Snapshot) -> Result<(), RecordError> {
        let stamp = Stamp::from_secs(s.t_s);
        let f = FrameRef {
            geometry: self.geometry,
            channels: s.channels.len(),
            cells: &s.planes,
            stamp,
            frame_id: FRAME_ID,
        };
        for (topic, cdr) in self.field_topics.clone().into_iter().zip(frame_cdr(&f)) {
            self.put(topic, stamp, &cdr)?;
        }
        for i in 0..self.robots.len() {
            let r = &self.robots[i];
            let (tp, ep) = (r.true_path, r.estimated_path);
            let truths = path_cdr(stamp, FRAME_ID, &r.truths);
            let estimates = path_cdr(stamp, FRAME_ID, &r.estimates);
            self.put(tp, stamp, &truths)?;
            self.put(ep, stamp, &estimates)?;
        }
        self.totals.frames += 1;
        self.flush()
    }
}
