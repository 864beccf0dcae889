//! Tick timing under load (issue 33): a field process (`pheromone_field::process::run::run_field`, as `pheromone
//! field` runs it) ticks at a rate for a while beside busy loops (processes this bench starts
//! and stops, one per core), with and without real-time scheduling (`SCHED_FIFO`, `mlockall`)
//! and with a spin before each deadline. Tick-start lateness (p50/p99/p99.9/max) comes from the
//! field's own histogram; the longest gap between frames is in periods.

use std::time::{Duration, Instant};

use pheromone_field::process::run::{run_field, FieldRunOptions};
use pheromone_field::shm::create_node;
use serde::Serialize;

pub use crate::peer::FieldTimingResult;
use crate::peer::{say_ready, say_result, Launcher, Peer, PeerResult, PeerSpec};
use crate::BenchError;

/// One configuration of the measurement.
#[derive(Debug, Clone, Copy)]
pub struct TimingRun {
    pub tick_hz: f32,
    pub width: u32,
    pub duration: Duration,
    /// `SCHED_FIFO` priority of the field (`None`: the default scheduler).
    pub rt_priority: Option<i32>,
    /// The field's spin before each deadline (µs; 0: it sleeps).
    pub spin_us: u32,
    /// Busy loops beside the field.
    pub busy_loops: usize,
}

/// One row of `tick_timing`.
#[derive(Debug, Clone, Serialize)]
pub struct TimingRow {
    pub tick_hz: f32,
    pub width: u32,
    pub seconds: f64,
    pub realtime: bool,
    pub spin_us: u32,
    pub busy_loops: usize,
    /// CPU time the hypervisor took from this VM's CPUs during the run (`steal` in
    /// /proc/stat, all CPUs; ms): a real-time priority inside the VM cannot prevent it.
    pub steal_ms: Option<f64>,
    #[serde(flatten)]
    pub field: FieldTimingResult,
}

/// Runs one configuration: starts the busy loops, then the field, and waits for its result.
pub fn measure(launcher: &Launcher, tag: &str, run: TimingRun) -> Result<TimingRow, BenchError> {
    let spare = run.duration + Duration::from_secs(30);
    let mut busy = Vec::with_capacity(run.busy_loops);
    for _ in 0..run.busy_loops {
        let mut p = Peer::spawn(
            launcher,
            &PeerSpec::Busy {
                seconds: spare.as_secs_f64(),
            },
        )?;
        p.wait_ready(Duration::from_secs(20))?;
        busy.push(p);
    }
    let mut field = Peer::spawn(
        launcher,
        &PeerSpec::TimedField {
            name: format!("bench-{tag}"),
            width: run.width,
            tick_hz: run.tick_hz,
            seconds: run.duration.as_secs_f64(),
            rt_priority: run.rt_priority,
            spin_us: run.spin_us,
        },
    )?;
    let steal0 = steal_ms();
    let result = field.result(spare)?;
    let steal_ms = steal0.zip(steal_ms()).map(|(a, b)| b - a);
    drop(busy);
    let field = result
        .field_timing
        .ok_or_else(|| BenchError::Peer("the timed field reported no timing".into()))?;
    Ok(TimingRow {
        tick_hz: run.tick_hz,
        width: run.width,
        seconds: run.duration.as_secs_f64(),
        realtime: run.rt_priority.is_some() && field.rt_refused.is_empty(),
        spin_us: run.spin_us,
        busy_loops: run.busy_loops,
        steal_ms,
        field,
    })
}

/// The machine's steal time so far (/proc/stat's first line, 8th value), ms. /proc/stat counts
/// in USER_HZ, which Linux fixes at 100 per second for user space.
fn steal_ms() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    let ticks: f64 = stat
        .lines()
        .next()?
        .split_whitespace()
        .nth(8)?
        .parse()
        .ok()?;
    Some(ticks * 10.0)
}

/// The busy-loop peer: one core's worth of work until `seconds` have passed (or SIGTERM).
pub fn busy(seconds: f64) -> Result<(), BenchError> {
    say_ready();
    let until = Instant::now() + Duration::from_secs_f64(seconds);
    let mut x = 0u64;
    while Instant::now() < until {
        for _ in 0..10_000 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
    }
    say_result(&PeerResult::default());
    Ok(())
}

/// The timed field peer: real-time scheduling if asked (what the OS refuses is reported, and
/// the row is then not a real-time one), then `run_field` for `seconds`, then its timing.
pub fn timed_field(
    name: &str,
    (width, tick_hz): (u32, f32),
    seconds: f64,
    rt_priority: Option<i32>,
    spin_us: u32,
) -> Result<(), BenchError> {
    let rt_refused = crate::machine::realtime(rt_priority, "timed field")?;
    let node = create_node(&format!("bench-timed-field-{}", std::process::id()))?;
    let options = FieldRunOptions {
        name: name.to_string(),
        config: crate::visible::config(width, tick_hz),
        clock: None,
        ticks: None,
        duration: Some(Duration::from_secs_f64(seconds)),
        checkpoint: None,
        checkpoint_every: Duration::from_secs(10),
        restore: None,
        standby: false,
        publish_on_deposit: None,
        threads: 1,
        deadline_slack: None,
        spin: Duration::from_micros(spin_us as u64),
    };
    let cpu0 = crate::machine::cpu_ns(std::process::id())?;
    let started = Instant::now();
    let s = run_field(&node, &options)
        .map_err(|e| BenchError::Peer(format!("timed field: {e}")))?
        .ok_or_else(|| BenchError::Peer("timed field: no summary".into()))?;
    let cpu_s = crate::machine::cpu_ns(std::process::id())?.saturating_sub(cpu0) as f64 * 1e-9;
    let no = |what: &str| BenchError::Peer(format!("timed field: no {what} in its summary"));
    let result = FieldTimingResult {
        ticks: s.ticks,
        missed_deadlines: s.missed_deadlines.ok_or_else(|| no("missed deadlines"))?,
        lateness: s.tick_lateness.ok_or_else(|| no("lateness"))?,
        longest_gap_periods: s.longest_tick_gap_periods.ok_or_else(|| no("gap"))?,
        cpu_share: cpu_s / started.elapsed().as_secs_f64(),
        rt_refused,
    };
    say_result(&PeerResult {
        field_timing: Some(result),
        ..PeerResult::default()
    });
    Ok(())
}
