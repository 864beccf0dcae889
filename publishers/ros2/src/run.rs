//! The loops of `pheromone ros2` (feature `zenoh`: `Ros2Node::run`) and `pheromone record`
//! ([`record_field`]): stepped until Ctrl-C/SIGTERM or their end, with the shared housekeeping
//! (`pheromone_field::process::run::Housekeeping`).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::process::run::Housekeeping;
use pheromone_field::shm::{FieldReader, ShmError, Svc};
use thiserror::Error;

use crate::frames::{frame_messages, wall_now_ns, FieldTopics, TimeBase};
use crate::grid::Occupancy;
use crate::record::{McapRecorder, RecordError};
use crate::rmw_zenoh::NameError;

/// How long one step waits for a frame or a message.
const STEP: Duration = Duration::from_millis(20);

#[cfg(feature = "zenoh")]
impl crate::node::Ros2Node {
    /// Steps the node (the field's frames, the poses to deposit, `--world`'s robots) until the
    /// node is asked to stop (Ctrl-C, SIGTERM) or `duration` has passed, with a status line
    /// every 5 s, then closes it; the `--json` summary (counts, refusals, bytes, latencies).
    pub fn run(
        mut self,
        node: &Node<Svc>,
        duration: Option<Duration>,
    ) -> Result<serde_json::Value, crate::node::Ros2Error> {
        let mut chores = Housekeeping::new(Duration::from_secs(5)).until(duration);
        while chores.running(node) {
            self.step(STEP)?;
            self.step_robots(node)?;
            if chores.due(node) {
                eprintln!("{}", self.status_line());
            }
        }
        let elapsed_s = chores.elapsed().as_secs_f64();
        let summary = serde_json::json!({
            "field": self.field(),
            "ros2": self.stats,
            "refused_total": self.stats.refused_total(),
            "elapsed_s": elapsed_s,
            "bytes_per_s": self.stats.bytes_published as f64 / elapsed_s.max(1e-9),
            "latency_p50_us": self.latency_percentile_us(0.5),
            "latency_p99_us": self.latency_percentile_us(0.99),
        });
        self.close();
        Ok(summary)
    }

    /// The periodic status line.
    pub fn status_line(&self) -> String {
        let s = &self.stats;
        format!(
            "ros2 '{}': {} frames published ({} bytes), {} poses, {} deposits, {} refused, \
             {} robots ({} poses, {} paths published)",
            self.field(),
            s.frames_published,
            s.bytes_published,
            s.poses_received,
            s.deposits_sent,
            s.refused_total(),
            s.robots_found,
            s.robot_poses_published,
            s.robot_paths_published,
        )
    }
}

/// What `pheromone record` records.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    pub field: String,
    /// The MCAP file.
    pub mcap: PathBuf,
    /// Most frames recorded per second.
    pub rate_hz: f64,
    /// ROS namespace of the topics.
    pub namespace: String,
    /// frame_id of the messages.
    pub frame_id: String,
    /// How long to wait for the field and its first frame.
    pub timeout: Duration,
    /// Stop after this long.
    pub duration: Option<Duration>,
    /// Stop after this many frames.
    pub frames: Option<u64>,
    /// How the OccupancyGrids' values are scaled.
    pub occupancy: Occupancy,
}

/// Why a recording failed.
#[derive(Debug, Error)]
pub enum RecordRunError {
    #[error(transparent)]
    Shm(#[from] ShmError),
    /// The namespace, or a topic in it, is not a valid ROS name.
    #[error(transparent)]
    Name(#[from] NameError),
    /// The file cannot be created.
    #[error(transparent)]
    Create(RecordError),
    #[error(transparent)]
    Write(#[from] RecordError),
    #[error("field {field}: no frame within {timeout:?}")]
    NoFrame { field: String, timeout: Duration },
}

pheromone_field::from_shm_errors!(RecordRunError);

impl RecordRunError {
    /// The error is the user's input (a namespace, a file that cannot be created).
    pub fn is_bad_input(&self) -> bool {
        matches!(self, RecordRunError::Name(_) | RecordRunError::Create(_))
    }
}

/// What a recording holds (`pheromone record --json`).
#[derive(Debug, Clone)]
pub struct RecordSummary {
    pub frames: u64,
    pub messages: u64,
    pub bytes: u64,
    pub topics: Vec<String>,
}

impl RecordSummary {
    /// The `--json` summary of a recording of `o`.
    pub fn json(&self, o: &RecordOptions) -> serde_json::Value {
        serde_json::json!({
            "field": o.field, "mcap": o.mcap, "frames": self.frames, "messages": self.messages,
            "bytes": self.bytes, "topics": self.topics, "finished_ns": wall_now_ns(),
        })
    }
}

/// Records field `o.field` into a ROS 2 MCAP file (GridMap and OccupancyGrid messages), at most
/// `o.rate_hz` frames a second, until the node is asked to stop (Ctrl-C, SIGTERM), the
/// duration or the number of frames; each frame's messages close a chunk and are flushed.
pub fn record_field(node: &Node<Svc>, o: &RecordOptions) -> Result<RecordSummary, RecordRunError> {
    let ns = crate::rmw_zenoh::namespace(&o.namespace)?;
    let period = Duration::from_secs_f64(1.0 / o.rate_hz);
    let mut reader = FieldReader::attach_within(node, &o.field, o.timeout)?;
    let Some(channels) = reader
        .wait_until(o.timeout, |_| true)?
        .map(|f| f.header.channels as usize)
    else {
        return Err(RecordRunError::NoFrame {
            field: o.field.clone(),
            timeout: o.timeout,
        });
    };
    let topics = FieldTopics::new(&ns, channels)?;
    let mut rec = McapRecorder::create(&o.mcap).map_err(RecordRunError::Create)?;
    for (name, t) in topics.names.iter().zip(&topics.types) {
        rec.add_topic(name, t)?;
    }
    let chores = Housekeeping::new(Duration::MAX).until(o.duration);
    let mut last: Option<Instant> = None;
    let mut frames = 0u64;
    // The frame held on attaching is recorded first.
    let mut fresh = true;
    while chores.running(node) && o.frames.is_none_or(|n| frames < n) {
        if (fresh || reader.wait_frame(STEP)?) && last.is_none_or(|t| t.elapsed() >= period) {
            if let Some(fm) = frame_messages(&reader, &o.frame_id, TimeBase::Wall, &o.occupancy) {
                if fm.messages.len() == topics.names.len() {
                    let log_ns = fm.stamp.as_ns().max(0) as u64;
                    for (i, m) in fm.messages.iter().enumerate() {
                        rec.write(i, log_ns, m)?;
                    }
                    rec.end_frame()?;
                    frames += 1;
                    last = Some(Instant::now());
                }
            }
        }
        fresh = false;
    }
    let (messages, bytes) = (rec.messages, rec.bytes);
    rec.finish()?;
    eprintln!(
        "record '{}': {frames} frames, {messages} messages in {}",
        o.field,
        o.mcap.display()
    );
    Ok(RecordSummary {
        frames,
        messages,
        bytes,
        topics: topics.names,
    })
}
