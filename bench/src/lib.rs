//! `pheromone bench`: the field's figures measured side by side with the alternatives, in one run,
//! with separate processes.
//!
//! - `tick_vs_memcpy`: one tick of the plain (exponential) and ambient models against a same-size
//!   memcpy, in this process;
//! - `hop_ns`: a small message between two processes, ping-pong / 2: ours (`field::link`,
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
//!   and catch-up.
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
#[cfg(feature = "zenoh")]
pub mod mirror;
pub mod peer;
pub mod raw_frames;
pub mod stats;
pub mod targets;
pub mod tick;
pub mod visible;

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use serde::Serialize;

pub use machine::Machine;
pub use peer::{FrameTransport, Launcher, PeerSpec, ReaderWait};
pub use stats::Latency;
pub use tick::TickRow;

/// Everything that can stop a bench run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Shm(#[from] field::shm::ShmError),
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
    Child(#[from] supervisor::SupervisorError),
}

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
}

impl Mode {
    fn plan(self) -> Plan {
        match self {
            Mode::Full => Plan {
                tick_widths: &[512, 1024, 2048, 4096],
                tick_reps: 31,
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
            },
            Mode::Quick => Plan {
                tick_widths: &[512, 1024, 2048, 4096],
                tick_reps: 7,
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
            },
            Mode::Smoke => Plan {
                tick_widths: &[512],
                tick_reps: 3,
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
}

impl Section {
    pub const ALL: [Section; 7] = [
        Section::Tick,
        Section::Hop,
        Section::Frames,
        Section::Visible,
        Section::Gateway,
        Section::Mirror,
        Section::CAbi,
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
    pub hop_ns: Option<HopReport>,
    /// Keyed `"1MiB"` and `"16MiB"`.
    pub frame_ns: BTreeMap<String, FrameReport>,
    pub deposit_to_visible_us: Option<VisibleReport>,
    /// The same with the field publishing as soon as deposits arrive (issue 18).
    pub deposit_to_visible_on_deposit_us: Option<VisibleReport>,
    pub gateway_pir: Option<gateway::GatewayReport>,
    /// Issue 15's field mirror over Zenoh; null in a build without Zenoh.
    pub mirror: Option<MirrorSection>,
    /// Issue 29: libpheromone's C reader against the Rust reader.
    pub c_abi: Option<c_abi::CAbiReport>,
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

/// What every section of a run uses: the options, the mode's plan, whether this process is
/// pinned, the progress log and the unique tags of the peers' services.
struct Ctx<'a> {
    opts: &'a Options,
    plan: Plan,
    pin: bool,
    started: Instant,
    serial: u32,
}

impl Ctx<'_> {
    /// A progress line on stderr (`Options::progress`), stamped with the time since the start.
    fn say(&self, msg: &str) {
        if self.opts.progress {
            eprintln!("[{:>6.1}s] {msg}", self.started.elapsed().as_secs_f64());
        }
    }

    /// A tag no other measurement of this run (or process) uses.
    fn tag(&mut self) -> String {
        self.serial += 1;
        format!("{}-{}", std::process::id(), self.serial)
    }

    fn runs(&self, s: Section) -> bool {
        self.opts.only.is_empty() || self.opts.only.contains(&s)
    }
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
    let mut tick_vs_memcpy = BTreeMap::new();
    for &w in plan.tick_widths.iter().filter(|_| cx.runs(Section::Tick)) {
        cx.say(&format!("tick vs memcpy at {w}x{w}"));
        tick_vs_memcpy.insert(format!("{w}x{w}"), tick::measure(w, plan.tick_reps)?);
    }
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
    let (deposit_to_visible_us, deposit_to_visible_on_deposit_us) = match cx.runs(Section::Visible)
    {
        true => {
            let (on_tick, on_deposit) = measure_visible(&mut cx)?;
            (Some(on_tick), Some(on_deposit))
        }
        false => (None, None),
    };
    let gateway_pir = match cx.runs(Section::Gateway) {
        true => Some(measure_gateway(&mut cx)?),
        false => None,
    };
    let mirror = match cx.runs(Section::Mirror) {
        true => measure_mirror(&mut cx)?,
        false => None,
    };
    let c_abi = match cx.runs(Section::CAbi) {
        true => Some(measure_c_abi(&mut cx)?),
        false => None,
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
        hop_ns,
        frame_ns,
        deposit_to_visible_us,
        deposit_to_visible_on_deposit_us,
        gateway_pir,
        mirror,
        c_abi,
        targets: Vec::new(),
        elapsed_s: 0.0,
    };
    report.targets = targets(&report);
    report.elapsed_s = (started.elapsed().as_secs_f64() * 10.0).round() / 10.0;
    cx.say("done");
    Ok(report)
}

/// The `c_abi` section: libpheromone's C reader against the Rust reader.
fn measure_c_abi(cx: &mut Ctx) -> Result<c_abi::CAbiReport, BenchError> {
    let plan = cx.plan;
    cx.say(&format!(
        "C ABI: 1 MiB frames to a Rust and a C reader ({} rounds of {} frames each), \
         sampling {} points x {}",
        plan.c_abi_rounds, plan.c_abi_frames.0, plan.c_abi_points.0, plan.c_abi_points.1
    ));
    let run = c_abi::CAbiRun {
        width: 512,
        count: plan.c_abi_frames.0,
        skip: plan.c_abi_frames.1,
        rounds: plan.c_abi_rounds,
        points: plan.c_abi_points.0,
        reps: plan.c_abi_points.1,
        pin: cx.pin,
    };
    let launcher = &cx.opts.launcher;
    let mut serial = cx.serial;
    let report = c_abi::measure(
        launcher,
        &mut || {
            serial += 1;
            format!("{}-{}", std::process::id(), serial)
        },
        run,
    );
    cx.serial = serial;
    report
}

/// The `hop_ns` section: ours and raw iceoryx2, waiting and busy-polling.
fn measure_hops(cx: &mut Ctx) -> Result<HopReport, BenchError> {
    let mut hop = |raw: bool, busy: bool| -> Result<Latency, BenchError> {
        cx.say(&format!(
            "hop: {} {} ({} ping-pongs)",
            if raw {
                "raw iceoryx2 u64"
            } else {
                "ours (PoseMsg link)"
            },
            if busy { "busy-poll" } else { "wait" },
            cx.plan.hop_count
        ));
        let s = hop::measure(
            &cx.opts.launcher,
            &cx.tag(),
            hop::HopRun {
                raw,
                busy,
                warmup: cx.plan.hop_warmup,
                count: cx.plan.hop_count,
                pin: cx.pin,
            },
        )?;
        latency(&s, "hop")
    };
    Ok(HopReport {
        ours: hop(false, false)?,
        raw_iceoryx2: hop(true, false)?,
        busy_poll: HopPair {
            ours: hop(false, true)?,
            raw_iceoryx2: hop(true, true)?,
        },
        message_bytes: HopBytes {
            ours: std::mem::size_of::<messages::PoseMsg>(),
            raw_iceoryx2: std::mem::size_of::<u64>(),
        },
        method: "ping-pong between two processes, one-way = round trip / 2",
    })
}

/// One frame size of the `frame_ns` section.
struct FrameSize {
    key: &'static str,
    width: u32,
    /// Frames recorded and skipped.
    count: usize,
    skip: usize,
    period_ms: u64,
}

/// One frame size of the `frame_ns` section: every transport and wait policy.
fn measure_frames(cx: &mut Ctx, size: FrameSize) -> Result<FrameReport, BenchError> {
    let FrameSize {
        key,
        width,
        count,
        skip,
        period_ms,
    } = size;
    let period = Duration::from_millis(period_ms);
    const EVENT: ReaderWait = ReaderWait::Event;
    const BUSY: ReaderWait = ReaderWait::BusyPoll;
    let spin = ReaderWait::Spin { spin_us: SPIN_US };
    let mut cpu: BTreeMap<(FrameTransport, ReaderWait), f64> = BTreeMap::new();
    let mut frames = |transport: FrameTransport,
                      readers: usize,
                      wait: ReaderWait|
     -> Result<Option<Latency>, BenchError> {
        if transport == FrameTransport::Zenoh && !ZENOH_BUILT {
            return Ok(None);
        }
        cx.say(&format!(
            "frames {key}: {transport:?} to {readers} reader(s), {} ({count} frames)",
            wait.label()
        ));
        let s = frames::measure(
            &cx.opts.launcher,
            &cx.tag(),
            frames::FrameRun {
                transport,
                width,
                readers,
                wait,
                count,
                skip,
                period,
                pin: cx.pin,
            },
        )?;
        if let (1, Some(share)) = (readers, s.reader_cpu_share) {
            cpu.insert((transport, wait), share);
        }
        latency(&s.samples_ns, "frames").map(Some)
    };
    let need = |l: Option<Latency>| l.ok_or(BenchError::NoZenoh);
    let ours = need(frames(FrameTransport::Ours, 1, EVENT)?)?;
    let uds_serde = need(frames(FrameTransport::UdsSerde, 1, EVENT)?)?;
    let zenoh = frames(FrameTransport::Zenoh, 1, EVENT)?;
    let readers_8 = FrameSet {
        ours: need(frames(FrameTransport::Ours, 8, EVENT)?)?,
        uds_serde: need(frames(FrameTransport::UdsSerde, 8, EVENT)?)?,
        zenoh: frames(FrameTransport::Zenoh, 8, EVENT)?,
    };
    let ours_busy_poll = need(frames(FrameTransport::Ours, 1, BUSY)?)?;
    let raw_iceoryx2 = need(frames(FrameTransport::RawIceoryx, 1, EVENT)?)?;
    let raw_iceoryx2_busy_poll = need(frames(FrameTransport::RawIceoryx, 1, BUSY)?)?;
    let ours_spin = need(frames(FrameTransport::Ours, 1, spin)?)?;
    let raw_iceoryx2_spin = need(frames(FrameTransport::RawIceoryx, 1, spin)?)?;
    let share = |t: FrameTransport, w: ReaderWait| cpu.get(&(t, w)).copied();
    Ok(FrameReport {
        width,
        frame_bytes: width as u64 * width as u64 * 4,
        ours,
        uds_serde,
        zenoh,
        readers_8,
        ours_busy_poll,
        raw_iceoryx2,
        raw_iceoryx2_busy_poll,
        ours_spin,
        raw_iceoryx2_spin,
        spin_us: SPIN_US,
        period_ms: period_ms as f64,
        reader_cpu_share: ReaderCpu {
            ours_wait: share(FrameTransport::Ours, EVENT),
            ours_spin: share(FrameTransport::Ours, spin),
            ours_busy_poll: share(FrameTransport::Ours, BUSY),
            raw_iceoryx2_wait: share(FrameTransport::RawIceoryx, EVENT),
            raw_iceoryx2_spin: share(FrameTransport::RawIceoryx, spin),
            raw_iceoryx2_busy_poll: share(FrameTransport::RawIceoryx, BUSY),
        },
    })
}

/// The `deposit_to_visible_us` section: the field ticking, then publishing on deposit.
fn measure_visible(cx: &mut Ctx) -> Result<(VisibleReport, VisibleReport), BenchError> {
    let opts = cx.opts;
    cx.say(&format!(
        "deposit to visible: {w}x{w} field at {} Hz ({} deposits)",
        opts.tick_hz,
        cx.plan.visible_count,
        w = opts.visible_width
    ));
    let visible_run = visible::VisibleRun {
        width: opts.visible_width,
        tick_hz: opts.tick_hz,
        warmup: (cx.plan.visible_count / 20).max(2),
        count: cx.plan.visible_count,
        pin: cx.pin,
        on_deposit: false,
        cpu_window: cx.plan.cpu_window,
    };
    let v = visible::measure(&opts.launcher, &cx.tag(), visible_run)?;
    let on_tick = visible_report(opts, v, |compute_p99_us| {
        1e6 / opts.tick_hz as f64 + 1.2 * compute_p99_us + 50.0
    })?;
    cx.say(&format!(
        "deposit to visible, publishing on deposit: {w}x{w} field ({} deposits), then its CPU \
         at 10, 100 and 1000 deposits/s",
        cx.plan.visible_count,
        w = opts.visible_width
    ));
    let v = visible::measure(
        &opts.launcher,
        &cx.tag(),
        visible::VisibleRun {
            on_deposit: true,
            ..visible_run
        },
    )?;
    let on_deposit = visible_report(opts, v, |compute_p99_us| compute_p99_us + 100.0)?;
    Ok((on_tick, on_deposit))
}

/// A deposit-to-visible report from its samples; `target_p99_us` of the tick compute's p99 (µs).
fn visible_report(
    opts: &Options,
    v: visible::VisibleResult,
    target_p99_us: impl Fn(f64) -> f64,
) -> Result<VisibleReport, BenchError> {
    let no_samples = || BenchError::Peer("deposit to visible: no samples".into());
    let compute = Latency::from_ns_as_us(&v.compute_ns).ok_or_else(no_samples)?;
    Ok(VisibleReport {
        latency: Latency::from_ns_as_us(&v.samples_ns).ok_or_else(no_samples)?,
        tick_hz: opts.tick_hz,
        width: opts.visible_width,
        target_p99_us: target_p99_us(compute.p99),
        tick_compute_us: compute,
        field_cpu: v.cpu,
    })
}

/// The `gateway_pir` section.
fn measure_gateway(cx: &mut Ctx) -> Result<gateway::GatewayReport, BenchError> {
    let plan = cx.plan;
    cx.say(&format!(
        "gateway: {} PIR round trips over UDP loopback, {} direct reads, {:.1} s flood",
        plan.pir_count.0,
        plan.pir_count.0,
        plan.flood.as_secs_f64()
    ));
    gateway::measure(
        &cx.opts.launcher,
        &cx.tag(),
        gateway::GatewayRun {
            warmup: plan.pir_count.1,
            count: plan.pir_count.0,
            flood: plan.flood,
            window: 32,
            pin: cx.pin,
        },
    )
}

/// The `mirror` section: an origin of `plan.mirror_width`² at 100 Hz, a bridge and a mirror.
#[cfg(feature = "zenoh")]
fn measure_mirror(cx: &mut Ctx) -> Result<Option<MirrorSection>, BenchError> {
    let w = cx.plan.mirror_width;
    cx.say(&format!(
        "mirror: {w}x{w} origin at 100 Hz, bridge and mirror over Zenoh on loopback, \
         {:.1} s at 10 and at 1000 deposits/s, then a mirror started afresh",
        cx.plan.mirror_window.as_secs_f64()
    ));
    mirror::measure(
        &cx.opts.launcher,
        &cx.tag(),
        mirror::MirrorRun {
            width: w,
            tick_hz: 100.0,
            window: cx.plan.mirror_window,
            keyframe_every: Duration::from_secs(5),
            pin: cx.pin,
        },
    )
    .map(Some)
}

#[cfg(not(feature = "zenoh"))]
fn measure_mirror(cx: &mut Ctx) -> Result<Option<MirrorSection>, BenchError> {
    cx.say(&format!(
        "mirror ({w}x{w}, {:.1} s per deposit rate): not built (--features zenoh)",
        cx.plan.mirror_window.as_secs_f64(),
        w = cx.plan.mirror_width
    ));
    Ok(None)
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
        } => {
            place(core);
            visible::field(&name, width, tick_hz, on_deposit)
        }
    }
}
