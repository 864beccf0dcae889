//! `pheromone bench`: the field's figures measured side by side with the alternatives, in one run,
//! with separate processes.
//!
//! - `tick_vs_memcpy`: one tick of the plain (exponential) and ambient models against a same-size
//!   memcpy, in this process (the ambient model's fast pass beside its reference pass);
//! - `merge_vs_memcpy` (issue 33): seed 004's map merge against a memcpy of its two planes, in
//!   this process, beside the reference merge;
//! - `hop_ns`: a small message between two processes, ping-pong / 2: ours (`pheromone_field::process::link`,
//!   a 128-byte `PoseMsg`) against raw iceoryx2 publish-subscribe of a `u64`; wait and busy-poll;
//! - `frame_ns`: a 1 MiB (512²) and a 16 MiB (2048²) frame from publish to "a reader holds it",
//!   to 1 and to 8 reader processes: ours against a Unix socket with serde (postcard) and Zenoh
//!   on loopback (feature `zenoh`);
//! - `deposit_to_visible_us`: a deposit published → a follower holds a frame containing it, with
//!   the field ticking as its own process;
//! - `gateway_pir`: seed 002's PIR round trip over UDP loopback to a `pheromone gateway` process
//!   beside a direct shared-memory read of the same two antenna values, and the PIRs per second
//!   one gateway serves (flooded by one client) with its CPU time;
//! - `c_abi` (issue 29): libpheromone's C reader against the Rust `FieldReader` — frame latency
//!   and sampling cost, as ratios measured in the same run;
//! - `mirror` (feature `zenoh`): a field mirrored over Zenoh to a second iceoryx2 domain — bytes
//!   on the wire against raw frames at 10 and 1000 deposits/s, origin-to-mirror lag, keyframe size
//!   and catch-up;
//! - `ros2` (feature `zenoh`, issue 46): CPU per published megabyte of `pheromone ros2` against a
//!   plain Zenoh publisher of the same bytes ([`ros2`]).
//!
//! - `peers` (issue 53): the ambient tick against OpenCV's box
//!   filter and SciPy's `uniform_filter`, the merge against OpenCV's `warpAffine` and the same
//!   rule in NumPy, through a Python process ([`peers`]).
//! - `scale` (issue 52, only when named: `--only scale`): `ias-ss` with 8 … 256 robots as
//!   processes and in one process: start-up, wall time per simulated second, memory, `/dev/shm`,
//!   processes, services, and each one's growth exponent ([`scale`]).
//!
//! `Options::only` runs a subset of these sections (`pheromone bench --only mirror`).
//!
//! Percentiles come from HdrHistogram. Performance is measured and reported, never asserted.
//! The processes are started through a [`peer::Launcher`] (the `pheromone` binary passes itself
//! and its hidden `bench-peer` subcommand); [`run_peer`] is what that subcommand runs.

pub mod c_abi;
mod frame_run;
pub mod frames;
pub mod gateway;
pub mod hop;
pub mod machine;
pub mod merge;
#[cfg(feature = "zenoh")]
pub mod mirror;
pub mod peer;
pub mod peers;
pub mod raw_frames;
pub mod ros2;
pub mod scale;
pub mod scale_probe;
mod sections;
pub mod stats;
pub mod targets;
pub mod tick;
pub mod timing;
pub mod visible;

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use serde::Serialize;

pub use machine::Machine;
pub use merge::MergeRow;
pub use peer::{FrameTransport, Launcher, PeerSpec, ReaderWait};
pub use stats::Latency;
pub use tick::TickRow;

use sections::{
    measure_c_abi, measure_frames, measure_gateway, measure_hops, measure_mirror, measure_timing,
    measure_visible, Ctx, FrameSize,
};

/// Everything that can stop a bench run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Shm(#[from] pheromone_field::shm::ShmError),
    #[error("{what}: {source}")]
    Io {
        what: String,
        source: std::io::Error,
    },
    /// A peer process failed, answered something unexpected or did not answer in time.
    #[error("{0}")]
    Peer(String),
    /// The peer specification given to `bench-peer` is not valid.
    #[error("invalid peer spec '{spec}': {reason}")]
    Spec { spec: String, reason: String },
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("this build has no Zenoh baseline (build with --features zenoh)")]
    NoZenoh,
    #[error("interrupted")]
    Interrupted,
    #[error(transparent)]
    Child(#[from] pheromone_supervisor::SupervisorError),
}

pheromone_field::from_shm_errors!(BenchError);

/// How much to measure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// A few minutes: the figures for the README.
    Full,
    /// Well under a minute.
    Quick,
    /// A few samples of everything (tests): checks that each measurement runs, nothing more.
    Smoke,
}

/// Samples and sizes of a mode.
#[derive(Debug, Clone, Copy)]
struct Plan {
    tick_widths: &'static [u32],
    tick_reps: usize,
    /// Map sides of the merge section (its repetitions: `tick_reps`).
    merge_sides: &'static [u32],
    /// The `peers` section: grid sides, radii (cells) and map sides.
    peer_sides: &'static [u32],
    peer_radii: &'static [u32],
    peer_merge_sides: &'static [u32],
    peer_reps: usize,
    hop_warmup: usize,
    hop_count: usize,
    /// (frames recorded, frames skipped) at 1 MiB and 16 MiB.
    frames_1mib: (usize, usize),
    frames_16mib: (usize, usize),
    visible_count: usize,
    /// How long the field's CPU is measured at each deposit rate.
    cpu_window: Duration,
    /// (PIRs timed, warm-up) and how long the gateway is flooded.
    pir_count: (usize, usize),
    flood: Duration,
    /// The mirror's field side and how long deposits go at each rate.
    mirror_width: u32,
    mirror_window: Duration,
    /// The C ABI section: (frames, skipped) per reader and round, rounds, (points, reps).
    c_abi_frames: (usize, usize),
    c_abi_rounds: usize,
    c_abi_points: (usize, usize),
    /// How long the field runs in each tick-timing configuration.
    timing_run: Duration,
}

impl Mode {
    fn plan(self) -> Plan {
        match self {
            Mode::Full => Plan {
                tick_widths: &[512, 1024, 2048, 4096],
                tick_reps: 31,
                merge_sides: &[256, 512, 1024],
                peer_sides: &[512, 1024, 2048, 4096],
                peer_radii: &[1, 10, 40],
                peer_merge_sides: &[256, 512, 1024],
                peer_reps: 15,
                hop_warmup: 2_000,
                hop_count: 50_000,
                frames_1mib: (300, 5),
                frames_16mib: (100, 3),
                visible_count: 1_000,
                cpu_window: Duration::from_secs(3),
                pir_count: (20_000, 1_000),
                flood: Duration::from_secs(5),
                mirror_width: 1024,
                mirror_window: Duration::from_secs(10),
                c_abi_frames: (150, 5),
                c_abi_rounds: 3,
                c_abi_points: (10_000, 21),
                timing_run: Duration::from_secs(30),
            },
            Mode::Quick => Plan {
                tick_widths: &[512, 1024, 2048, 4096],
                tick_reps: 7,
                merge_sides: &[256, 512, 1024],
                peer_sides: &[512, 2048],
                peer_radii: &[1, 10, 40],
                peer_merge_sides: &[256, 1024],
                peer_reps: 5,
                hop_warmup: 500,
                hop_count: 5_000,
                frames_1mib: (60, 3),
                frames_16mib: (15, 2),
                visible_count: 200,
                cpu_window: Duration::from_secs(1),
                pir_count: (5_000, 500),
                flood: Duration::from_secs(2),
                mirror_width: 1024,
                mirror_window: Duration::from_secs(3),
                c_abi_frames: (60, 3),
                c_abi_rounds: 2,
                c_abi_points: (2_000, 9),
                timing_run: Duration::from_secs(5),
            },
            Mode::Smoke => Plan {
                tick_widths: &[512],
                tick_reps: 3,
                merge_sides: &[256],
                peer_sides: &[96],
                peer_radii: &[1, 10],
                peer_merge_sides: &[96],
                peer_reps: 1,
                hop_warmup: 20,
                hop_count: 200,
                frames_1mib: (4, 1),
                frames_16mib: (3, 1),
                visible_count: 20,
                cpu_window: Duration::from_millis(200),
                pir_count: (100, 10),
                flood: Duration::from_millis(200),
                mirror_width: 256,
                mirror_window: Duration::from_millis(400),
                c_abi_frames: (4, 1),
                c_abi_rounds: 1,
                c_abi_points: (200, 3),
                timing_run: Duration::from_millis(500),
            },
        }
    }
}

/// A part of the run (`pheromone bench --only SECTION,…`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Section {
    /// `tick_vs_memcpy`.
    Tick,
    /// `hop_ns`.
    Hop,
    /// `frame_ns`.
    Frames,
    /// `deposit_to_visible_us` and `deposit_to_visible_on_deposit_us`.
    Visible,
    /// `gateway_pir`.
    Gateway,
    /// `mirror` (a build with `--features zenoh`).
    Mirror,
    /// `c_abi`: libpheromone's C reader against the Rust reader.
    #[serde(rename = "c-abi")]
    CAbi,
    /// `tick_timing`: the field's tick-start lateness beside busy loops, with and without
    /// real-time scheduling.
    Timing,
    /// `merge_vs_memcpy`: seed 004's map merge against a same-size memcpy.
    Merge,
    /// `scale`: the cost of a bigger swarm (not in a run without `--only`: it takes long).
    Scale,
    /// `ros2`: CPU per published MB of `pheromone ros2` against plain Zenoh (feature `zenoh`).
    Ros2,
    /// `peers`: the ambient tick and the merge against OpenCV, SciPy and NumPy (through a
    /// Python process; without it or its modules, rows that say so).
    Peers,
}

impl Section {
    pub const ALL: [Section; 12] = [
        Section::Tick,
        Section::Hop,
        Section::Frames,
        Section::Visible,
        Section::Gateway,
        Section::Mirror,
        Section::CAbi,
        Section::Timing,
        Section::Merge,
        Section::Ros2,
        Section::Scale,
        Section::Peers,
    ];
}

/// Options of one run.
#[derive(Debug, Clone)]
pub struct Options {
    pub mode: Mode,
    /// The sections to run; empty: all of them.
    pub only: Vec<Section>,
    /// Pin this process to core 0 and single peers to core 1 (when there are 2 cores or more).
    pub pin: bool,
    /// Tick rate of the field in the deposit-to-visible measurement.
    pub tick_hz: f32,
    /// Cells per side of the field in the deposit-to-visible measurement.
    pub visible_width: u32,
    /// Progress lines on stderr.
    pub progress: bool,
    pub launcher: Launcher,
    /// The `scale` section's sizes and chart.
    pub scale: scale::ScaleOptions,
    /// The Python interpreter of the `peers` section.
    pub peers_python: String,
}

/// Hop latency, ns.
#[derive(Debug, Clone, Serialize)]
pub struct HopReport {
    /// Wait mode (the receiver sleeps until notified).
    pub ours: Latency,
    pub raw_iceoryx2: Latency,
    pub busy_poll: HopPair,
    pub message_bytes: HopBytes,
    pub method: &'static str,
}

#[derive(Debug, Clone, Serialize)]
pub struct HopPair {
    pub ours: Latency,
    pub raw_iceoryx2: Latency,
}

#[derive(Debug, Clone, Serialize)]
pub struct HopBytes {
    pub ours: usize,
    pub raw_iceoryx2: usize,
}

/// Frame delivery to a number of readers, ns; `zenoh` is `None` in a build without it.
#[derive(Debug, Clone, Serialize)]
pub struct FrameSet {
    pub ours: Latency,
    pub uds_serde: Latency,
    pub zenoh: Option<Latency>,
}

/// Frame delivery at one frame size, ns. The top-level figures are one reader, wait mode.
#[derive(Debug, Clone, Serialize)]
pub struct FrameReport {
    pub width: u32,
    pub frame_bytes: u64,
    pub ours: Latency,
    pub uds_serde: Latency,
    pub zenoh: Option<Latency>,
    pub readers_8: FrameSet,
    /// Ours with the reader busy-polling instead of waiting for the frame event.
    pub ours_busy_poll: Latency,
    /// The reference: the same slice over plain iceoryx2 (`raw_frames`), 1 reader, waiting.
    pub raw_iceoryx2: Latency,
    pub raw_iceoryx2_busy_poll: Latency,
    /// A reader paced to the period that wakes half of `spin_us` before the frame is due and
    /// spins (`WaitPolicy::Spin`): ours and the reference.
    pub ours_spin: Latency,
    pub raw_iceoryx2_spin: Latency,
    pub spin_us: u32,
    pub period_ms: f64,
    /// What each wait policy costs the reader: its process's CPU time over the wall time of its
    /// recording, as a share of one core (1 reader).
    pub reader_cpu_share: ReaderCpu,
}

/// A frame reader's CPU (share of one core) under each wait policy, ours and the reference.
#[derive(Debug, Clone, Serialize)]
pub struct ReaderCpu {
    pub ours_wait: Option<f64>,
    pub ours_spin: Option<f64>,
    pub ours_busy_poll: Option<f64>,
    pub raw_iceoryx2_wait: Option<f64>,
    pub raw_iceoryx2_spin: Option<f64>,
    pub raw_iceoryx2_busy_poll: Option<f64>,
}

/// Deposit-to-visible latency, µs.
#[derive(Debug, Clone, Serialize)]
pub struct VisibleReport {
    #[serde(flatten)]
    pub latency: Latency,
    pub tick_hz: f32,
    pub width: u32,
    /// The field's tick compute time, µs.
    pub tick_compute_us: Latency,
    /// Where the time goes: deposit sent → the field starts the tick that applies it, µs.
    pub to_field_us: Latency,
    /// Where the time goes: the frame published → the follower holds it, µs.
    pub to_reader_us: Latency,
    /// Of `to_field_us`: the depositor's send call (the sample and the wake-up event), µs.
    pub send_us: Latency,
    /// The three stages' means over the slowest 1 % of the samples (those at or above p99).
    pub slowest_1pct_us: visible::Stages,
    /// The target for p99: one tick period + 1.2 × the tick compute (p99) + 50 µs; publishing
    /// on deposit, the tick compute (p99) + 100 µs.
    pub target_p99_us: f64,
    /// The field process's CPU (share of one core) while deposits arrive at 10, 100 and 1000
    /// per second.
    pub field_cpu: Vec<visible::CpuAtRate>,
}

pub use targets::{targets, Target};

/// The whole run: what `--json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub machine: Machine,
    pub mode: Mode,
    pub pinned: bool,
    pub zenoh_built: bool,
    /// The sections this run measured (`--only`); a section left out is empty or null.
    pub sections: Vec<Section>,
    /// Keyed by the grid size, e.g. `"1024x1024"`.
    pub tick_vs_memcpy: BTreeMap<String, TickRow>,
    /// Keyed by the map size, e.g. `"256x256"`.
    pub merge_vs_memcpy: BTreeMap<String, MergeRow>,
    pub hop_ns: Option<HopReport>,
    /// Keyed `"1MiB"` and `"16MiB"`.
    pub frame_ns: BTreeMap<String, FrameReport>,
    pub deposit_to_visible_us: Option<VisibleReport>,
    /// The same with the field publishing as soon as deposits arrive (issue 18).
    pub deposit_to_visible_on_deposit_us: Option<VisibleReport>,
    /// Publishing on deposit with real-time scheduling, the field spinning (`--spin-us` of a
    /// period) and the follower busy-polling (issue 33).
    pub deposit_to_visible_on_deposit_rt_us: Option<VisibleReport>,
    /// Issue 33: tick-start lateness beside busy loops, with and without real-time scheduling.
    pub tick_timing: Vec<timing::TimingRow>,
    pub gateway_pir: Option<gateway::GatewayReport>,
    /// Issue 33: the PIR round trip beside 2 busy loops, gateway and client at `SCHED_FIFO`.
    pub gateway_pir_loaded_rt: Option<gateway::LoadedPirReport>,
    /// Issue 15's field mirror over Zenoh; null in a build without Zenoh.
    pub mirror: Option<MirrorSection>,
    /// Issue 29: libpheromone's C reader against the Rust reader.
    pub c_abi: Option<c_abi::CAbiReport>,
    /// Issue 52: the cost of a bigger swarm; null unless `--only scale`.
    pub scale: Option<scale::ScaleReport>,
    /// Issue 46: `pheromone ros2`'s CPU per published MB against plain Zenoh; null without Zenoh.
    pub ros2: Option<ros2::Ros2Report>,
    /// Issue 53: the ambient tick and the merge beside OpenCV, SciPy and NumPy.
    pub peers: Option<peers::PeersReport>,
    pub targets: Vec<Target>,
    pub elapsed_s: f64,
}

/// How long a paced reader spins before it sleeps on the frame event (`ReaderWait::Spin`).
pub const SPIN_US: u32 = 500;

/// Whether this build has the Zenoh baseline.
pub const ZENOH_BUILT: bool = cfg!(feature = "zenoh");

#[cfg(feature = "zenoh")]
pub use mirror::MirrorReport as MirrorSection;
/// A build without Zenoh has no mirror section (always `None`).
#[cfg(not(feature = "zenoh"))]
#[derive(Debug, Clone, Serialize)]
pub enum MirrorSection {}

fn latency(samples: &[u64], what: &str) -> Result<Latency, BenchError> {
    Latency::from_ns(samples).ok_or_else(|| BenchError::Peer(format!("{what}: no samples")))
}

/// Runs every measurement and returns the report.
pub fn run(opts: &Options) -> Result<Report, BenchError> {
    let started = Instant::now();
    let plan = opts.mode.plan();
    let machine = Machine::detect();
    let pin = opts.pin && machine.cores >= 2 && machine::pin_to_core(0);
    let mut cx = Ctx {
        opts,
        plan,
        pin,
        started,
        serial: 0,
    };
    cx.say(&format!(
        "machine: {} ({} cores){}",
        machine.cpu_model,
        machine.cores,
        if pin { ", pinned" } else { "" }
    ));
    let sections: Vec<Section> = Section::ALL.into_iter().filter(|s| cx.runs(*s)).collect();
    let (tick_vs_memcpy, merge_vs_memcpy) = sections::measure_in_process(&cx)?;
    let hop_ns = match cx.runs(Section::Hop) {
        true => Some(measure_hops(&mut cx)?),
        false => None,
    };
    let mut frame_ns = BTreeMap::new();
    let frame_sizes = [
        ("1MiB", 512u32, plan.frames_1mib, 20u64),
        ("16MiB", 2048u32, plan.frames_16mib, 100u64),
    ];
    let run_frames = cx.runs(Section::Frames);
    for (key, width, (count, skip), period_ms) in frame_sizes.into_iter().filter(|_| run_frames) {
        let size = FrameSize {
            key,
            width,
            count,
            skip,
            period_ms,
        };
        frame_ns.insert(key.to_string(), measure_frames(&mut cx, size)?);
    }
    let visible = match cx.runs(Section::Visible) {
        true => Some(measure_visible(&mut cx)?),
        false => None,
    };
    let (gateway_pir, gateway_pir_loaded_rt) = match cx.runs(Section::Gateway) {
        true => {
            let (g, loaded) = measure_gateway(&mut cx)?;
            (Some(g), Some(loaded))
        }
        false => (None, None),
    };
    let mirror = match cx.runs(Section::Mirror) {
        true => measure_mirror(&mut cx)?,
        false => None,
    };
    let c_abi = match cx.runs(Section::CAbi) {
        true => Some(measure_c_abi(&mut cx)?),
        false => None,
    };
    let tick_timing = match cx.runs(Section::Timing) {
        true => measure_timing(&mut cx)?,
        false => Vec::new(),
    };
    if pin {
        machine::unpin();
    }
    let mut report = Report {
        machine,
        mode: opts.mode,
        pinned: pin,
        zenoh_built: ZENOH_BUILT,
        sections,
        tick_vs_memcpy,
        merge_vs_memcpy,
        hop_ns,
        frame_ns,
        deposit_to_visible_us: visible.as_ref().map(|v| v.on_tick.clone()),
        deposit_to_visible_on_deposit_us: visible.as_ref().map(|v| v.on_deposit.clone()),
        deposit_to_visible_on_deposit_rt_us: visible.map(|v| v.on_deposit_rt),
        tick_timing,
        gateway_pir,
        gateway_pir_loaded_rt,
        mirror,
        c_abi,
        scale: scale::section(opts, &mut |m| cx.say(m))?,
        ros2: sections::measure_ros2(&mut cx)?,
        peers: sections::measure_peers(&cx)?,
        targets: Vec::new(),
        elapsed_s: 0.0,
    };
    report.targets = targets(&report);
    report.elapsed_s = (started.elapsed().as_secs_f64() * 10.0).round() / 10.0;
    cx.say("done");
    Ok(report)
}

/// What the hidden `bench-peer` subcommand runs: one peer process of a measurement.
pub fn run_peer(spec_json: &str) -> Result<(), BenchError> {
    let spec: PeerSpec = serde_json::from_str(spec_json).map_err(|e| BenchError::Spec {
        spec: spec_json.to_string(),
        reason: e.to_string(),
    })?;
    let place = |core: Option<usize>| match core {
        Some(c) => {
            machine::pin_to_core(c);
        }
        None => {
            machine::unpin();
        }
    };
    match spec {
        PeerSpec::HopEcho {
            raw,
            busy,
            ping,
            pong,
            count,
            core,
        } => {
            place(core);
            hop::echo(raw, busy, &ping, &pong, count)
        }
        PeerSpec::FrameReader {
            transport,
            source,
            wait,
            skip,
            count,
            core,
        } => {
            place(core);
            match transport {
                // The C reader lives with its section (c_abi drives frames::measure).
                FrameTransport::CAbi => c_abi::read(&source, wait, skip, count),
                _ => frames::read(transport, &source, wait, skip, count),
            }
        }
        PeerSpec::Field {
            name,
            width,
            tick_hz,
            core,
            on_deposit,
            rt_priority,
            spin_us,
        } => {
            place(core);
            let wall = visible::WallField {
                on_deposit,
                rt_priority,
                spin_us,
            };
            visible::field(&name, width, tick_hz, wall)
        }
        PeerSpec::Busy { seconds } => timing::busy(seconds),
        PeerSpec::PlainZenoh {
            connect,
            topic_bytes,
            rate_hz,
        } => ros2::plain_publisher(&connect, &topic_bytes, rate_hz),
        PeerSpec::TimedField {
            name,
            width,
            tick_hz,
            seconds,
            rt_priority,
            spin_us,
        } => timing::timed_field(&name, (width, tick_hz), seconds, rt_priority, spin_us),
    }
}
