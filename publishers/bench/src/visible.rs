//! Deposit-to-visible latency: a deposit is published (this process), the field (a separate
//! process ticking at a fixed rate) applies it in its next tick, and a follower (this process's
//! `FieldReader`) holds a frame that contains it. With `on_deposit`, the field is
//! `pheromone_field::process::run::run_field` publishing as soon as deposits arrive (`--publish-on-deposit-ms 0`),
//! and its CPU time (`/proc/PID/schedstat`) is measured while deposits arrive at 10, 100 and
//! 1000 per second.

use std::time::{Duration, Instant};

use pheromone_field::process::run::run_field;
use pheromone_field::shm::{create_node, now_ns, DepositPublisher, FieldReader, FieldServer};
use pheromone_field::{ChannelSpec, DepositMsg, Evaporation, FieldConfig};
use pheromone_field::{Deposit, Kernel};

use crate::peer::{say_ready, say_result, Launcher, Peer, PeerResult, PeerSpec, ReaderWait};
use crate::BenchError;

#[derive(Debug, Clone, Copy)]
pub struct VisibleRun {
    pub width: u32,
    pub tick_hz: f32,
    pub warmup: usize,
    pub count: usize,
    /// Pin the field process to core 1 (this process is on core 0).
    pub pin: bool,
    /// The field publishes as soon as deposits arrive.
    pub on_deposit: bool,
    /// How long the field's CPU is measured at each deposit rate.
    pub cpu_window: Duration,
    /// `SCHED_FIFO` priority of the field process (with `on_deposit`).
    pub rt_priority: Option<i32>,
    /// The field's spin before each deadline (µs, with `on_deposit`): deposits seen at once.
    pub spin_us: u32,
    /// How this process (the follower) waits for the frame: `Event` or `BusyPoll`.
    pub reader_wait: ReaderWait,
}

/// How the bench's field process runs on wall time.
#[derive(Debug, Clone, Copy)]
pub struct WallField {
    /// Publish as soon as deposits arrive (`run_field` with `publish_on_deposit` 0 ms).
    pub on_deposit: bool,
    pub rt_priority: Option<i32>,
    pub spin_us: u32,
}

/// The field process's CPU while deposits arrive at a rate.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct CpuAtRate {
    pub deposits_per_s: f64,
    /// CPU time of the field process over the window / the window (1.0 = one core).
    pub cpu_share: f64,
    /// Frames the field published over the window per second.
    pub frames_per_s: f64,
}

#[derive(Debug, Clone, Default)]
pub struct VisibleResult {
    /// Deposit sent → frame holding it received, ns.
    pub samples_ns: Vec<u64>,
    /// The field's tick compute time of the frames that carried the deposits, ns.
    pub compute_ns: Vec<u64>,
    /// Deposit sent → the field starts the tick that applies it (the frame's publish stamp −
    /// its compute time − the send stamp), ns: the field's wake-up and its wait for the tick.
    pub to_field_ns: Vec<u64>,
    /// The frame's publish stamp → the follower holds it, ns: the follower's wake-up.
    pub to_reader_ns: Vec<u64>,
    /// The depositor's `send` (the sample and the field's wake-up event), ns: part of
    /// `to_field_ns`.
    pub send_ns: Vec<u64>,
    pub cpu: Vec<CpuAtRate>,
}

/// Mean time of each stage of a deposit's way to the follower, µs.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Stages {
    /// Deposit sent → the field starts the tick that applies it.
    pub to_field: f64,
    /// The tick's compute.
    pub compute: f64,
    /// The frame published → the follower holds it.
    pub to_reader: f64,
    /// Samples averaged.
    pub samples: usize,
}

impl VisibleResult {
    /// The stages' means over the samples whose whole latency is at least `p99_us`.
    pub fn slowest_stages(&self, p99_us: f64) -> Stages {
        let mut sum = Stages::default();
        for (i, &total) in self.samples_ns.iter().enumerate() {
            if (total as f64) * 1e-3 < p99_us {
                continue;
            }
            let stage = |v: &[u64]| v.get(i).copied().unwrap_or(0) as f64 * 1e-3;
            sum.to_field += stage(&self.to_field_ns);
            sum.compute += stage(&self.compute_ns);
            sum.to_reader += stage(&self.to_reader_ns);
            sum.samples += 1;
        }
        let n = sum.samples.max(1) as f64;
        let round = |v: f64| (v / n * 10.0).round() / 10.0;
        Stages {
            to_field: round(sum.to_field),
            compute: round(sum.compute),
            to_reader: round(sum.to_reader),
            samples: sum.samples,
        }
    }
}

/// The bench's field: `width`² cells, one exponential channel, 2 readers.
pub(crate) fn config(width: u32, tick_hz: f32) -> FieldConfig {
    FieldConfig {
        width,
        height: width,
        tick_hz,
        max_readers: 2,
        channels: vec![ChannelSpec::new(
            "trail",
            Evaporation::Exponential {
                decay_per_s: 0.0057,
            },
        )],
        ..FieldConfig::default()
    }
}

pub fn measure(
    launcher: &Launcher,
    tag: &str,
    run: VisibleRun,
) -> Result<VisibleResult, BenchError> {
    let node = create_node(&format!("bench-visible-{tag}"))?;
    let name = format!("bench-{tag}");
    let mut field = Peer::spawn(
        launcher,
        &PeerSpec::Field {
            name: name.clone(),
            width: run.width,
            tick_hz: run.tick_hz,
            core: run.pin.then_some(1),
            on_deposit: run.on_deposit,
            rt_priority: run.rt_priority,
            spin_us: run.spin_us,
        },
    )?;
    field.wait_ready(Duration::from_secs(20))?;
    let field_pid = field.pid();
    let mut reader = FieldReader::attach_within(&node, &name, Duration::from_secs(10))?;
    let mut depositor = DepositPublisher::attach_within(&node, &name, 1, Duration::from_secs(10))?;
    let mut result = deposits_to_visible(&node, &name, &mut reader, &mut depositor, run)?;
    for rate in [10.0, 100.0, 1000.0] {
        result.cpu.push(cpu_at_rate(
            &node,
            &mut reader,
            &mut depositor,
            field_pid,
            rate,
            run.cpu_window,
            centre(run),
        )?);
    }
    drop(depositor);
    drop(field);
    Ok(result)
}

/// The centre of the bench's field (m), where every deposit goes.
fn centre(run: VisibleRun) -> (f32, f32) {
    let c = config(run.width, run.tick_hz);
    (
        c.width as f32 * c.cell_size_m / 2.0,
        c.height as f32 * c.cell_size_m / 2.0,
    )
}

/// `run.warmup + run.count` deposits, each sent at a phase of the tick, timed until the follower
/// holds a frame containing it (the last `count` recorded, with their stages).
fn deposits_to_visible(
    node: &iceoryx2::prelude::Node<pheromone_field::shm::Svc>,
    name: &str,
    reader: &mut FieldReader,
    depositor: &mut DepositPublisher,
    run: VisibleRun,
) -> Result<VisibleResult, BenchError> {
    let period = Duration::from_secs_f32(1.0 / run.tick_hz);
    let timeout = period * 10 + Duration::from_secs(2);
    let (x_m, y_m) = centre(run);
    let mut result = VisibleResult::default();
    // The follower at the field's priority too: a busy-polling reader preempted by the rest of
    // the machine sees the frame late however fast the field published it.
    let follower_rt = FollowerPriority::set(run.rt_priority);
    for i in 0..run.warmup + run.count {
        let last = reader.frame().map(|f| f.header.sequence).unwrap_or(0);
        if reader
            .wait_until(timeout, |f| f.header.sequence > last)?
            .is_none()
        {
            return Err(BenchError::Peer(format!(
                "field '{name}' sent no frame within {timeout:?}"
            )));
        }
        // Deposits land at every phase of the tick: spread them over the period.
        let phase = period.mul_f64(((i * 37) % 100) as f64 / 100.0);
        pheromone_field::shm::node_wait(node, phase).map_err(|_| BenchError::Interrupted)?;
        reader.update()?;
        let before = reader
            .frame()
            .map(|f| f.header.deposits_applied)
            .unwrap_or(0);
        let sent = now_ns();
        depositor.send(small_deposit(x_m, y_m))?;
        let send_ns = now_ns().saturating_sub(sent);
        let frame = wait_for(reader, run.reader_wait, timeout, |f| {
            f.header.deposits_applied > before
        })?
        .ok_or_else(|| BenchError::Peer(format!("the deposit did not show within {timeout:?}")))?;
        let seen = now_ns();
        if i >= run.warmup {
            let h = &frame.header;
            result.samples_ns.push(seen.saturating_sub(sent));
            result.compute_ns.push(h.tick_compute_ns);
            let started = h.stamp_ns.saturating_sub(h.tick_compute_ns);
            result.to_field_ns.push(started.saturating_sub(sent));
            result.send_ns.push(send_ns);
            result.to_reader_ns.push(seen.saturating_sub(h.stamp_ns));
        }
    }
    drop(follower_rt);
    Ok(result)
}

/// This thread at `SCHED_FIFO` until dropped (then back on the default scheduler).
struct FollowerPriority(bool);

impl FollowerPriority {
    /// Best effort, as the bench's field: a refusal is said and the run goes on without it.
    fn set(priority: Option<i32>) -> Self {
        let Some(p) = priority else {
            return Self(false);
        };
        match pheromone_field::process::realtime::fifo_for_this_thread(p) {
            Ok(()) => Self(true),
            Err(e) => {
                eprintln!("bench follower: going on without it: {e}");
                Self(false)
            }
        }
    }
}

impl Drop for FollowerPriority {
    fn drop(&mut self) {
        if self.0 {
            pheromone_field::process::realtime::default_scheduling_for_this_thread();
        }
    }
}

/// Waits (up to `timeout`, as `wait`) until a frame satisfies `pred`; returns it, or `None`.
fn wait_for<'r>(
    reader: &'r mut FieldReader,
    wait: ReaderWait,
    timeout: Duration,
    mut pred: impl FnMut(&pheromone_field::shm::Frame<'_>) -> bool,
) -> Result<Option<pheromone_field::shm::Frame<'r>>, BenchError> {
    if wait == ReaderWait::Event {
        return Ok(reader.wait_until(timeout, pred)?);
    }
    let deadline = Instant::now() + timeout;
    while !reader.frame().as_ref().is_some_and(&mut pred) {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Ok(None);
        }
        reader.wait_frame_with(wait.policy(), left.min(Duration::from_millis(100)))?;
    }
    Ok(reader.frame())
}

/// The deposit both measurements send: small, at the field's centre.
fn small_deposit(x_m: f32, y_m: f32) -> DepositMsg {
    DepositMsg::from(Deposit {
        channel: 0,
        x_m,
        y_m,
        kernel: Kernel::Ellipse {
            tau: 0.001,
            cov_m2: [0.01, 0.0, 0.01],
            range_m: 0.5,
            gamma_max: 100.0,
        },
    })
}

/// Sends deposits at `rate` per second for `window` and measures the field's CPU meanwhile.
fn cpu_at_rate(
    node: &iceoryx2::prelude::Node<pheromone_field::shm::Svc>,
    reader: &mut FieldReader,
    depositor: &mut DepositPublisher,
    field_pid: u32,
    rate: f64,
    window: Duration,
    (x_m, y_m): (f32, f32),
) -> Result<CpuAtRate, BenchError> {
    reader.update()?;
    let seq0 = reader.frame().map(|f| f.header.sequence).unwrap_or(0);
    let cpu0 = crate::machine::cpu_ns(field_pid)?;
    let started = Instant::now();
    let interval = Duration::from_secs_f64(1.0 / rate);
    let mut next = started;
    while started.elapsed() < window {
        depositor.send(small_deposit(x_m, y_m))?;
        next += interval;
        let now = Instant::now();
        if next > now {
            pheromone_field::shm::node_wait(node, next - now)
                .map_err(|_| BenchError::Interrupted)?;
        }
    }
    let elapsed_s = started.elapsed().as_secs_f64();
    let cpu_s = crate::machine::cpu_ns(field_pid)?.saturating_sub(cpu0) as f64 * 1e-9;
    reader.update()?;
    let seq1 = reader.frame().map(|f| f.header.sequence).unwrap_or(seq0);
    Ok(CpuAtRate {
        deposits_per_s: rate,
        cpu_share: cpu_s / elapsed_s,
        frames_per_s: (seq1 - seq0) as f64 / elapsed_s,
    })
}

/// The field process: ticks at `tick_hz` until terminated (with `on_deposit`, also publishes
/// as soon as deposits arrive: `pheromone_field::process::run::run_field` as `pheromone field` runs it).
pub fn field(name: &str, width: u32, tick_hz: f32, wall: WallField) -> Result<(), BenchError> {
    crate::machine::realtime(wall.rt_priority, "bench field")?;
    let node = create_node(&format!("bench-field-{}", std::process::id()))?;
    if wall.on_deposit {
        let options = pheromone_field::process::run::FieldRunOptions {
            name: name.to_string(),
            config: config(width, tick_hz),
            clock: None,
            ticks: None,
            duration: None,
            checkpoint: None,
            checkpoint_every: Duration::from_secs(10),
            restore: None,
            standby: false,
            publish_on_deposit: Some(Duration::ZERO),
            threads: 1,
            deadline_slack: None,
            spin: Duration::from_micros(wall.spin_us as u64),
        };
        // The services exist once the first frame is out; say ready from a thread that sees it.
        let ready_name = name.to_string();
        let announcer = std::thread::spawn(move || -> Result<(), BenchError> {
            let node = create_node(&format!("bench-field-ready-{}", std::process::id()))?;
            FieldReader::attach_within(&node, &ready_name, Duration::from_secs(20))?;
            say_ready();
            Ok(())
        });
        run_field(&node, &options).map_err(|e| BenchError::Peer(format!("field: {e}")))?;
        announcer
            .join()
            .map_err(|_| BenchError::Peer("the field's ready announcer panicked".into()))??;
        say_result(&PeerResult::default());
        return Ok(());
    }
    let mut server = FieldServer::start(&node, name, config(width, tick_hz), None)?;
    say_ready();
    let period = Duration::from_secs_f32(1.0 / tick_hz);
    let mut next = Instant::now();
    loop {
        next += period;
        let now = Instant::now();
        if next < now {
            next = now;
        }
        if pheromone_field::shm::node_wait(&node, next - now).is_err() {
            break;
        }
        server.tick()?;
    }
    say_result(&PeerResult::default());
    Ok(())
}
