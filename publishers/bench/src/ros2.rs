//! What `pheromone ros2` costs (issue 46, feature `zenoh`): CPU time per megabyte it publishes,
//! against a plain Zenoh publisher of the same bytes, in the same run.
//!
//! - **Field:** a field peer of `width`² cells, one channel, ticking at `rate_hz`.
//! - **Subscriber:** a Zenoh peer session of this process, listening on a loopback port the
//!   system picks; one subscriber on `0/**` counts the payload bytes of every sample it gets
//!   (liveliness tokens and zenoh-ext's `@adv` keys are not samples of `0/**`).
//! - **`pheromone ros2`:** the real node, `pheromone ros2 --field F --rate-hz R --connect
//!   <subscriber>` (otherwise rmw_zenoh's default session settings), publishing the field's
//!   GridMap and OccupancyGrid. First `idle` with nobody subscribed (its CPU: what serializing
//!   nothing but the transient-local cache's refresh, default 1 Hz, costs), then with the
//!   subscriber for `window`.
//! - **Plain Zenoh:** a peer process of this bench: one plain publisher (`declare_publisher`, the
//!   default QoS) per topic the node published, each sample a fresh buffer of that topic's size
//!   (a copy of a template: a new frame's bytes), at the frame rate the node kept, for `window`.
//!
//! CPU is the publisher process's CPU time over the window, every thread (each thread's
//! `/proc/PID/task/TID/schedstat`, in ns: `/proc/PID/stat`'s utime + stime count 10 ms ticks,
//! too coarse for a few seconds at a few % of a core), per MB (10⁶ bytes) of payload the
//! subscriber got in the window.

use std::collections::BTreeMap;
use std::time::Duration;

use serde::Serialize;

use crate::Mode;

/// One measurement of the section.
#[derive(Debug, Clone, Copy)]
pub struct Ros2Run {
    pub width: u32,
    /// The field's tick rate and the node's `--rate-hz`.
    pub rate_hz: f64,
    /// How long the node runs with nobody subscribed.
    pub idle: Duration,
    /// The CPU window of each publisher.
    pub window: Duration,
}

impl Ros2Run {
    /// A 512² field at 20 Hz; windows by mode.
    pub fn of(mode: Mode) -> Self {
        let (idle_ms, window_ms) = match mode {
            Mode::Full => (3_000, 10_000),
            Mode::Quick => (2_000, 3_000),
            Mode::Smoke => (500, 1_000),
        };
        Self {
            width: 512,
            rate_hz: 20.0,
            idle: Duration::from_millis(idle_ms),
            window: Duration::from_millis(window_ms),
        }
    }
}

/// One publisher over its window.
#[derive(Debug, Clone, Serialize)]
pub struct PublisherCpu {
    pub window_s: f64,
    /// Frames (a message on every topic) per second the subscriber got.
    pub frames_per_s: f64,
    /// Payload megabytes (10⁶ bytes) per second the subscriber got.
    pub mb_per_s: f64,
    /// The publisher process's CPU time over the window, as a share of one core.
    pub cpu_share: f64,
    /// CPU milliseconds per megabyte the subscriber got.
    pub cpu_ms_per_mb: f64,
}

/// `pheromone ros2` with nobody subscribed.
#[derive(Debug, Clone, Serialize)]
pub struct Idle {
    pub seconds: f64,
    /// The node's CPU time as a share of one core.
    pub cpu_share: f64,
    /// From the node's `--json` summary at exit: frames due while no subscriber matched and
    /// not serialized, and the ones serialized for the transient-local cache.
    pub frames_without_subscribers: Option<u64>,
    pub frames_for_cache: Option<u64>,
}

/// The `ros2` section of the report.
#[derive(Debug, Clone, Serialize)]
pub struct Ros2Report {
    pub width: u32,
    pub rate_hz: f64,
    /// Each topic's payload bytes (one frame), as the subscriber got them from the node.
    pub topic_bytes: Vec<u64>,
    pub ros2: PublisherCpu,
    pub plain_zenoh: PublisherCpu,
    /// `ros2.cpu_ms_per_mb` / `plain_zenoh.cpu_ms_per_mb`.
    pub cpu_per_mb_ratio: f64,
    pub idle: Idle,
    pub method: &'static str,
}

/// The CPU time (ns) of each thread of process `pid` so far, by thread id
/// (`/proc/PID/task/TID/schedstat`'s first field).
pub fn thread_cpu_ns(pid: u32) -> Result<BTreeMap<u32, u64>, crate::BenchError> {
    let dir = format!("/proc/{pid}/task");
    let io = |what: String| move |source| crate::BenchError::Io { what, source };
    let mut cpu = BTreeMap::new();
    for entry in std::fs::read_dir(&dir).map_err(io(format!("list {dir}")))? {
        let entry = entry.map_err(io(format!("list {dir}")))?;
        let Some(tid) = entry
            .file_name()
            .to_str()
            .and_then(|t| t.parse::<u32>().ok())
        else {
            continue;
        };
        // A thread that ended since the listing is skipped (its time is lost, not wrong).
        if let Ok(text) = std::fs::read_to_string(entry.path().join("schedstat")) {
            if let Some(ns) = text.split_whitespace().next().and_then(|v| v.parse().ok()) {
                cpu.insert(tid, ns);
            }
        }
    }
    Ok(cpu)
}

/// The CPU time (s) the threads of `now` used since `before` (a thread started since: all of
/// its time; one that ended meanwhile is not counted).
pub fn cpu_since(before: &BTreeMap<u32, u64>, now: &BTreeMap<u32, u64>) -> f64 {
    now.iter()
        .map(|(tid, ns)| ns.saturating_sub(before.get(tid).copied().unwrap_or(0)))
        .sum::<u64>() as f64
        * 1e-9
}

#[cfg(feature = "zenoh")]
pub use with_zenoh::{measure, plain_publisher};

#[cfg(not(feature = "zenoh"))]
pub fn plain_publisher(
    _connect: &str,
    _topic_bytes: &[u64],
    _rate_hz: f64,
) -> Result<(), crate::BenchError> {
    Err(crate::BenchError::NoZenoh)
}

#[cfg(feature = "zenoh")]
#[path = "ros2_zenoh.rs"]
mod with_zenoh;
