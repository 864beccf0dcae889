//! Peer processes: the bench starts each measured party as a separate process (the same binary,
//! a hidden subcommand), hands it a `PeerSpec` as JSON, and reads two lines from its stdout:
//! `ready` once its ports exist, then one JSON `PeerResult` when it is done.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use pheromone_supervisor::{ChildId, ChildSpec, Supervisor};
use serde::{Deserialize, Serialize};

use crate::BenchError;

/// How to start a peer: the program and the arguments before the spec (e.g. the current
/// executable and `bench-peer --spec`).
#[derive(Debug, Clone)]
pub struct Launcher {
    pub program: PathBuf,
    pub args: Vec<String>,
}

/// Transport a frame reader receives on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum FrameTransport {
    /// `pheromone_field::shm::FieldReader`: the frame in shared memory, no copy.
    Ours,
    /// The plane serialized with serde (postcard) over a Unix domain socket.
    UdsSerde,
    /// The plane as bytes over Zenoh on loopback TCP.
    Zenoh,
    /// The reference: the same `[f32]` slice over plain iceoryx2 (`raw_frames`).
    RawIceoryx,
    /// libpheromone's C ABI (`pheromone_wait_frame`, `pheromone_frame_borrow`): the field's
    /// frame as a C reader sees it (issue 29).
    CAbi,
}

/// How a frame reader waits for the next frame (`pheromone_field::shm::WaitPolicy` on the wire).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum ReaderWait {
    /// Sleeps on the frame event.
    Event,
    /// A reader paced to the frames, as a controller running at the field's rate: after each
    /// frame it sleeps until half the spin before the next frame is due (one interval between
    /// the last two stamps after the last), then polls for up to `spin_us`, then sleeps on the
    /// event.
    Spin { spin_us: u32 },
    /// Polls until the frame comes.
    BusyPoll,
}

impl ReaderWait {
    pub fn policy(self) -> pheromone_field::shm::WaitPolicy {
        match self {
            ReaderWait::Event => pheromone_field::shm::WaitPolicy::Event,
            ReaderWait::Spin { spin_us, .. } => {
                pheromone_field::shm::WaitPolicy::Spin(Duration::from_micros(spin_us as u64))
            }
            ReaderWait::BusyPoll => pheromone_field::shm::WaitPolicy::BusyPoll,
        }
    }

    /// For a paced reader: how long to sleep, now (`now_ns`), after frames stamped
    /// `previous_ns` and then `last_ns`, before it starts to spin for the next one.
    pub fn pause_after(self, previous_ns: u64, last_ns: u64, now_ns: u64) -> Duration {
        match self {
            ReaderWait::Spin { spin_us } if previous_ns > 0 && last_ns > previous_ns => {
                let due_ns = last_ns + (last_ns - previous_ns);
                let start_ns = due_ns.saturating_sub(spin_us as u64 * 500);
                Duration::from_nanos(start_ns.saturating_sub(now_ns))
            }
            _ => Duration::ZERO,
        }
    }

    /// For progress lines.
    pub fn label(self) -> String {
        match self {
            ReaderWait::Event => "wait".into(),
            ReaderWait::Spin { spin_us, .. } => format!("paced, spin {spin_us} µs then wait"),
            ReaderWait::BusyPoll => "busy-poll".into(),
        }
    }
}

/// What a peer process does.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum PeerSpec {
    /// Answers every ping on `ping` with the same message on `pong`, `count` times.
    HopEcho {
        raw: bool,
        busy: bool,
        ping: String,
        pong: String,
        count: usize,
        core: Option<usize>,
    },
    /// Receives frames; records (receive time − publish stamp) for `count` frames after skipping
    /// `skip`.
    FrameReader {
        transport: FrameTransport,
        /// Field name, socket path or Zenoh endpoint.
        source: String,
        wait: ReaderWait,
        skip: usize,
        count: usize,
        core: Option<usize>,
    },
    /// Runs a field ticking at `tick_hz` until terminated.
    Field {
        name: String,
        width: u32,
        tick_hz: f32,
        core: Option<usize>,
        /// Run `pheromone_field::process::run::run_field` with `publish_on_deposit` (0 ms): a frame as soon as
        /// deposits arrive.
        #[serde(default)]
        on_deposit: bool,
        /// `SCHED_FIFO` priority of the field (with `on_deposit`).
        #[serde(default)]
        rt_priority: Option<i32>,
        /// The field's spin before each deadline, µs (with `on_deposit`).
        #[serde(default)]
        spin_us: u32,
    },
    /// A core's worth of work for `seconds` (`timing`).
    Busy { seconds: f64 },
    /// A plain Zenoh publisher (`ros2`): a buffer of each size on its own key, `rate_hz` times
    /// a second, through a peer session connected to `connect`, until terminated.
    PlainZenoh {
        connect: String,
        topic_bytes: Vec<u64>,
        rate_hz: f64,
    },
    /// `run_field` for `seconds`, then its tick timing (`timing`).
    TimedField {
        name: String,
        width: u32,
        tick_hz: f32,
        seconds: f64,
        rt_priority: Option<i32>,
        spin_us: u32,
    },
}

/// What a peer reports when done.
impl PeerSpec {
    /// The kind of peer, to name it in messages.
    pub fn kind(&self) -> &'static str {
        match self {
            PeerSpec::HopEcho { .. } => "hop-echo",
            PeerSpec::FrameReader { .. } => "frame-reader",
            PeerSpec::Field { .. } => "field",
            PeerSpec::Busy { .. } => "busy loop",
            PeerSpec::TimedField { .. } => "timed field",
            PeerSpec::PlainZenoh { .. } => "plain zenoh publisher",
        }
    }
}

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct PeerResult {
    pub samples_ns: Vec<u64>,
    /// The peer's CPU time over the wall time of its recording (share of one core), where it
    /// measured it (frame readers: what a wait policy costs).
    #[serde(default)]
    pub cpu_share: Option<f64>,
    /// A timed field's tick timing.
    #[serde(default)]
    pub field_timing: Option<FieldTimingResult>,
}

/// One peer process, under the project's supervisor (`supervisor`): stopped with
/// SIGTERM (then SIGKILL) when dropped, its stderr passed through.
pub struct Peer {
    sup: Supervisor,
    id: ChildId,
}

impl Peer {
    /// Starts `launcher` with `spec` as its last argument.
    pub fn spawn(launcher: &Launcher, spec: &PeerSpec) -> Result<Self, BenchError> {
        let json = serde_json::to_string(spec).map_err(|e| BenchError::Peer(e.to_string()))?;
        let mut sup = Supervisor::new(&launcher.program);
        sup.echo_stderr = true;
        let mut args = launcher.args.clone();
        args.push(json);
        let id = sup.spawn(ChildSpec::new(&format!("peer {}", spec.kind()), None, args))?;
        Ok(Self { sup, id })
    }

    /// The peer's process id.
    pub fn pid(&self) -> u32 {
        self.sup.pid(self.id)
    }

    /// The peer's next stdout line, waiting until `deadline`.
    fn next_line(&mut self, deadline: Instant) -> Result<String, BenchError> {
        let left = deadline.saturating_duration_since(Instant::now());
        match self.sup.next_line(self.id, left)? {
            Some(l) => Ok(l),
            None => Err(BenchError::Peer(format!(
                "{} did not answer in time",
                self.sup.spec(self.id).who()
            ))),
        }
    }

    /// Waits for the peer's `ready` line.
    pub fn wait_ready(&mut self, timeout: Duration) -> Result<(), BenchError> {
        let line = self.next_line(Instant::now() + timeout)?;
        if line.trim() == "ready" {
            Ok(())
        } else {
            Err(BenchError::Peer(format!(
                "{} said '{line}' instead of 'ready'",
                self.sup.spec(self.id).who()
            )))
        }
    }

    /// The peer's result, if it has printed it (does not wait).
    pub fn try_result(&mut self) -> Result<Option<PeerResult>, BenchError> {
        match self.sup.next_line(self.id, Duration::ZERO)? {
            Some(l) => parse_result(&l).map(Some),
            None => Ok(None),
        }
    }

    /// Waits for the peer's result.
    pub fn result(&mut self, timeout: Duration) -> Result<PeerResult, BenchError> {
        let line = self.next_line(Instant::now() + timeout)?;
        parse_result(&line)
    }
}

fn parse_result(line: &str) -> Result<PeerResult, BenchError> {
    serde_json::from_str(line)
        .map_err(|e| BenchError::Peer(format!("peer printed '{line}' instead of a result: {e}")))
}

/// Tells the parent this peer is ready.
pub fn say_ready() {
    println!("ready");
}

/// Prints the result line.
pub fn say_result(r: &PeerResult) {
    println!(
        "{}",
        serde_json::to_string(r).expect("a list of integers serializes")
    );
}

/// What the field process reports back.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FieldTimingResult {
    pub ticks: u64,
    pub missed_deadlines: u64,
    pub lateness: pheromone_field::process::run::Lateness,
    pub longest_gap_periods: f64,
    /// The field process's CPU over its run (share of one core).
    pub cpu_share: f64,
    /// What the OS refused of the real-time scheduling asked for (the run went on without it).
    pub rt_refused: Vec<String>,
}
