//! `pheromone field`: the field process loop.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::{Args, ValueEnum};
use field::checkpoint;
use field::deposit::RejectReason;
use field::link::{LinkOptions, Receiver};
use field::messages::ClockMsg;
use field::shm::{
    cleanup_dead_nodes, create_node, frame_pool, FieldServer, ShmError, Standby, StandbyEvent,
    Takeover,
};
use field::{Evaporation, FieldConfig};

use super::{bad, read_toml};

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq, Debug)]
pub enum ModelArg {
    /// No evaporation.
    None,
    /// P' = P·e^(−K·dt).
    Exponential,
    /// Seed 000 ambient-aware: P' = P·e + (1 − e)·min(P, α·Pa).
    Ambient,
    /// Seeds 001/004: ξ' = (1 − ρ)·ξ, deposits saturate at ±1.
    Saturating,
    /// Seed 002 counters: lose Q every τ seconds.
    Quantum,
}

/// Run a field process: the only writer of the grid.
///
/// Each tick it drains the deposits that arrived, computes the next frame from the previous one
/// (evaporation, optional diffusion, deposits) straight into shared memory and publishes it. Once
/// a second it logs the tick rate, compute time and deposit counts to stderr. Ctrl-C stops it.
///
/// Shared memory: (max-readers + 1) × 3 + 2 frames of width × height × channels × 4 bytes; the
/// default 512 × 512 × 1 grid with 8 readers uses 29 MiB of /dev/shm. The field refuses to start
/// if /dev/shm has less free space.
///
/// Without --config the field has one channel, 'trail', with the seed 000 ambient-aware model
/// (K = 0.0057/s, α = 0.5, ambient radius 0.5 m). Flags override the file.
///
/// Reliability: --checkpoint FILE saves the frame every --checkpoint-every seconds and at exit
/// (atomically); --restore FILE resumes from such a file (same grid required). --standby mirrors
/// the running field of the same name and takes over publishing, from its last frame, when that
/// field's process dies. Clients killed at any instant are cleaned up once a second.
#[derive(Args, Debug)]
pub struct FieldArgs {
    /// Field name: services are pheromone/<NAME>/frame, …/deposit, …/frame-ready.
    #[arg(long, default_value = "main")]
    pub name: String,
    /// TOML file with the field configuration (unknown keys are errors).
    #[arg(long, value_name = "FILE", conflicts_with = "scenario")]
    pub config: Option<PathBuf>,
    /// Take the field configuration from a scenario (built-in name or TOML file).
    #[arg(long)]
    pub scenario: Option<String>,
    /// Grid width in cells [default: 512].
    #[arg(long)]
    pub width: Option<u32>,
    /// Grid height in cells [default: 512].
    #[arg(long)]
    pub height: Option<u32>,
    /// Cell size in metres [default: 0.05].
    #[arg(long, value_name = "M")]
    pub cell_size: Option<f32>,
    /// World x of the grid's lower-left corner, metres [default: 0].
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    pub origin_x: Option<f32>,
    /// World y of the grid's lower-left corner, metres [default: 0].
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    pub origin_y: Option<f32>,
    /// Ticks per second [default: 50].
    #[arg(long, value_name = "HZ")]
    pub tick_hz: Option<f32>,
    /// Evaporation model of the first channel (replaces the file's).
    #[arg(long, value_enum)]
    pub model: Option<ModelArg>,
    /// Evaporation rate K per second (exponential, ambient) [default: 0.0057].
    #[arg(long, value_name = "K")]
    pub decay_per_sec: Option<f32>,
    /// Ambient weight α in [0, 1] (ambient) [default: 0.5].
    #[arg(long)]
    pub alpha: Option<f32>,
    /// Radius of the ambient mean window in metres (ambient) [default: 0.5].
    #[arg(long, value_name = "M")]
    pub ambient_radius: Option<f32>,
    /// Fraction ρ evaporated per tick (saturating) [default: 0.05].
    #[arg(long)]
    pub rho_per_tick: Option<f32>,
    /// Counter quantum Q lost per time constant (quantum) [default: 1].
    #[arg(long)]
    pub quantum: Option<f32>,
    /// Counter time constant τ in seconds (quantum) [default: 1].
    #[arg(long, value_name = "SECS")]
    pub tau_secs: Option<f32>,
    /// Diffusion coefficient D in m²/s of the first channel (stability D·dt/h² ≤ ¼ is checked).
    #[arg(long, value_name = "M2_PER_SEC")]
    pub diffusion: Option<f32>,
    /// Let the first channel hold negative values (anti-pheromone).
    #[arg(long)]
    pub signed: bool,
    /// Readers the frame service admits [default: 8].
    #[arg(long)]
    pub max_readers: Option<usize>,
    /// Deposit publishers the field admits [default: 64].
    #[arg(long)]
    pub max_depositors: Option<usize>,
    /// Deposits buffered between two ticks [default: 1024].
    #[arg(long)]
    pub deposit_buffer: Option<usize>,
    /// Tick once per clock message of the simulated world NAME (lockstep simulation) instead of
    /// on wall time; the field stops when the world says it has finished.
    #[arg(long, value_name = "WORLD")]
    pub clock: Option<String>,
    /// Stop after this many ticks.
    #[arg(long)]
    pub ticks: Option<u64>,
    /// Stop after this many seconds of wall time.
    #[arg(long, value_name = "SECS")]
    pub duration: Option<f64>,
    /// Print the configuration that would run, as TOML, and exit.
    #[arg(long)]
    pub print_config: bool,
    /// Save the current frame to FILE (header, planes and checksum; written to FILE.tmp,
    /// fsynced, then renamed) every --checkpoint-every seconds and when the field stops.
    #[arg(long, value_name = "FILE")]
    pub checkpoint: Option<PathBuf>,
    /// Seconds between two checkpoints [default: 10].
    #[arg(long, value_name = "SECS", requires = "checkpoint")]
    pub checkpoint_every: Option<f64>,
    /// Resume from a checkpoint file: its cells, sequence number, field time and counters. The
    /// grid (size, cell size, origin, channels) must be the configuration's; a truncated or
    /// corrupted file is refused (exit status 2).
    #[arg(long, value_name = "FILE")]
    pub restore: Option<PathBuf>,
    /// Run as the standby of the field NAME: mirror its frames and deposits, and when its process
    /// dies (no frame for two tick periods and its process gone) take over publishing from the
    /// last frame, losing at most one tick of deposits. Give it the primary's configuration.
    #[arg(long, conflicts_with_all = ["restore", "clock"])]
    pub standby: bool,
    /// At exit, print one JSON summary object on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Builds the configuration from the file (if any), then the flags.
pub fn config_from_args(a: &FieldArgs) -> anyhow::Result<FieldConfig> {
    let mut c: FieldConfig = match (&a.config, &a.scenario) {
        (Some(p), _) => read_toml(p)?,
        (None, Some(s)) => super::roles::load_scenario(s)?.field,
        (None, None) => FieldConfig::default(),
    };
    macro_rules! set {
        ($($flag:ident => $field:ident),*) => { $(if let Some(v) = a.$flag { c.$field = v; })* };
    }
    set!(width => width, height => height, cell_size => cell_size_m, origin_x => origin_x_m,
         origin_y => origin_y_m, tick_hz => tick_hz, max_readers => max_readers,
         max_depositors => max_depositors, deposit_buffer => deposit_buffer);
    let ch = &mut c.channels[0];
    let current = ch.evaporation;
    let model = a.model.unwrap_or(match current {
        Evaporation::None => ModelArg::None,
        Evaporation::Exponential { .. } => ModelArg::Exponential,
        Evaporation::Ambient { .. } => ModelArg::Ambient,
        Evaporation::Saturating { .. } => ModelArg::Saturating,
        Evaporation::Quantum { .. } => ModelArg::Quantum,
    });
    let (k0, alpha0, radius0) = match current {
        Evaporation::Ambient {
            decay_per_sec,
            alpha,
            radius_m,
        } => (decay_per_sec, alpha, radius_m),
        Evaporation::Exponential { decay_per_sec } => (decay_per_sec, 0.5, 0.5),
        _ => (0.0057, 0.5, 0.5),
    };
    let unused = |flag: &str, v: Option<f32>| -> anyhow::Result<()> {
        match v {
            Some(v) => Err(bad(format!(
                "--{flag} {v} does not apply to the {model:?} model"
            ))),
            None => Ok(()),
        }
    };
    ch.evaporation = match model {
        ModelArg::None => {
            for (f, v) in [
                ("decay-per-sec", a.decay_per_sec),
                ("alpha", a.alpha),
                ("ambient-radius", a.ambient_radius),
            ] {
                unused(f, v)?;
            }
            Evaporation::None
        }
        ModelArg::Exponential => {
            unused("alpha", a.alpha)?;
            unused("ambient-radius", a.ambient_radius)?;
            Evaporation::Exponential {
                decay_per_sec: a.decay_per_sec.unwrap_or(k0),
            }
        }
        ModelArg::Ambient => Evaporation::Ambient {
            decay_per_sec: a.decay_per_sec.unwrap_or(k0),
            alpha: a.alpha.unwrap_or(alpha0),
            radius_m: a.ambient_radius.unwrap_or(radius0),
        },
        ModelArg::Saturating => Evaporation::Saturating {
            rho_per_tick: a.rho_per_tick.unwrap_or(match current {
                Evaporation::Saturating { rho_per_tick } => rho_per_tick,
                _ => 0.05,
            }),
        },
        ModelArg::Quantum => {
            let (q0, t0) = match current {
                Evaporation::Quantum { quantum, tau_secs } => (quantum, tau_secs),
                _ => (1.0, 1.0),
            };
            Evaporation::Quantum {
                quantum: a.quantum.unwrap_or(q0),
                tau_secs: a.tau_secs.unwrap_or(t0),
            }
        }
    };
    if model != ModelArg::Saturating {
        unused("rho-per-tick", a.rho_per_tick)?;
    }
    if model != ModelArg::Quantum {
        unused("quantum", a.quantum)?;
        unused("tau-secs", a.tau_secs)?;
    }
    if let Some(d) = a.diffusion {
        ch.diffusion_m2_per_sec = d;
    }
    if a.signed {
        ch.signed = true;
    }
    let origin = a
        .config
        .as_ref()
        .map(|p| format!("{}: ", p.display()))
        .unwrap_or_default();
    c.validate().map_err(|e| bad(format!("{origin}{e}")))?;
    Ok(c)
}

pub fn run(a: FieldArgs) -> anyhow::Result<()> {
    let config = config_from_args(&a)?;
    field::shm::check_name(&a.name).map_err(|e| bad(e.to_string()))?;
    if a.print_config {
        print!("{}", toml::to_string_pretty(&config)?);
        return Ok(());
    }
    let every = a.checkpoint_every.unwrap_or(10.0);
    if !(every.is_finite() && every > 0.0) {
        return Err(bad(format!(
            "--checkpoint-every {every}: must be a positive number of seconds"
        )));
    }
    let restore = match &a.restore {
        Some(path) => {
            let cp = checkpoint::read(path).map_err(|e| bad(e.to_string()))?;
            cp.check_against(path, &config)
                .map_err(|e| bad(e.to_string()))?;
            Some(cp)
        }
        None => None,
    };
    let (frames, bytes) = frame_pool(&config);
    eprintln!(
        "field '{}': {}×{} cells × {} channel(s), {} m cells, {} Hz; shared memory {:.1} MiB ({} frames)",
        a.name,
        config.width,
        config.height,
        config.channels.len(),
        config.cell_size_m,
        config.tick_hz,
        bytes as f64 / (1 << 20) as f64,
        frames
    );
    let node = create_node(&format!("field-{}", a.name))?;
    let clock = match &a.clock {
        Some(world) => {
            let (service, wake) = field::messages::clock_services(world);
            Some(Receiver::<ClockMsg>::create(
                &node,
                &service,
                &wake,
                LinkOptions {
                    keep_latest: false,
                    buffer: 1024,
                    ..LinkOptions::default()
                },
            )?)
        }
        None => None,
    };
    let started = Instant::now();
    let mut standby_summary = serde_json::Value::Null;
    let (mut server, mut longest_gap_ns) = if a.standby {
        let Some((server, takeover, mirrored)) = run_standby(&a, &node, &config)? else {
            // Stopped (Ctrl-C or --duration) while the primary was alive.
            if a.json {
                println!(
                    "{}",
                    serde_json::json!({ "field": a.name, "standby": { "took_over": false } })
                );
            }
            return Ok(());
        };
        let gap_ns = takeover
            .first_stamp_ns
            .saturating_sub(takeover.last_mirrored_stamp_ns);
        let ms = |ns: u64| ns as f64 / 1e6;
        eprintln!(
            "field '{}': the primary is gone; took over after frame {} ({:.1} ms without a frame: \
             found gone after {:.1} ms, first own frame {:.1} ms later), {} deposit(s) carried over",
            a.name,
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
        standby_summary = serde_json::json!({
            "took_over": true,
            "mirrored_frames": mirrored,
            "last_mirrored_sequence": takeover.last_mirrored_sequence,
            "takeover_gap_ms": gap_ns as f64 / 1e6,
            "deposits_carried": takeover.deposits_carried,
        });
        (server, gap_ns)
    } else {
        let restore = restore.as_ref().map(|c| (c.header, c.cells.as_slice()));
        if let Some((h, _)) = &restore {
            eprintln!(
                "field '{}': restored frame {} (t = {:.3} s, {} deposits applied) from {}",
                a.name,
                h.sequence,
                h.sim_time_s,
                h.deposits_applied,
                a.restore
                    .as_ref()
                    .map(|p| p.display().to_string())
                    .unwrap_or_default()
            );
        }
        (
            FieldServer::start(&node, &a.name, config.clone(), restore)?,
            0,
        )
    };
    let mut checkpointer = a.checkpoint.as_ref().map(|path| Checkpointer {
        path: path.clone(),
        every: Duration::from_secs_f64(every),
        last: Instant::now(),
        writing: None,
        written: 0,
        failed: 0,
    });
    let period = Duration::from_secs_f64(1.0 / config.tick_hz as f64);
    let mut deadline = Instant::now() + period;
    let mut window = Window::new(Instant::now());
    let mut max_compute_ns = 0u64;
    let mut ticks = 0u64;
    let mut dead_nodes_cleaned = 0u64;
    let mut last_clock_step: Option<u64> = None;
    let mut last_frame_at = Instant::now();
    loop {
        if let Some(clock) = &clock {
            // Lockstep: one tick per world step.
            match clock.recv_timeout(Duration::from_millis(20))? {
                Some(msg) if msg.finished != 0 => break,
                // The world re-sends a step nobody answered yet: tick once per step.
                Some(msg) if last_clock_step.is_some_and(|s| msg.step <= s) => continue,
                Some(msg) => last_clock_step = Some(msg.step),
                None => {
                    if node.wait(Duration::ZERO).is_err() {
                        break;
                    }
                    // Idle between steps: late readers still get the current frame.
                    server.serve_new_readers()?;
                    continue;
                }
            }
        } else {
            let now = Instant::now();
            let wait = deadline.saturating_duration_since(now);
            if node.wait(wait).is_err() {
                break; // SIGINT / SIGTERM
            }
            deadline += period;
            if deadline + period < Instant::now() {
                deadline = Instant::now() + period; // fell behind: don't burst to catch up
            }
        }
        if clock.is_some() && node.wait(Duration::ZERO).is_err() {
            break;
        }
        let out = server.tick()?;
        let now = Instant::now();
        let gap_ns = now.duration_since(last_frame_at).as_nanos() as u64;
        last_frame_at = now;
        longest_gap_ns = longest_gap_ns.max(gap_ns);
        ticks += 1;
        max_compute_ns = max_compute_ns.max(out.compute_ns);
        window.add(&out, gap_ns);
        if let Some(c) = &mut checkpointer {
            c.maybe_write(&server);
        }
        if window.started.elapsed() >= Duration::from_secs(1) {
            // Clients killed since the last second: free their ports and the frames they held.
            let cleaned = cleanup_dead_nodes(&node);
            dead_nodes_cleaned += cleaned;
            window.log(&a.name, server.stepper(), cleaned);
            window = Window::new(Instant::now());
        }
        if a.ticks.is_some_and(|n| ticks >= n)
            || a.duration
                .is_some_and(|d| started.elapsed().as_secs_f64() >= d)
        {
            break;
        }
    }
    let checkpoint_summary = match &mut checkpointer {
        Some(c) => {
            c.finish(&server)?;
            serde_json::json!({ "file": c.path.display().to_string(), "written": c.written, "failed": c.failed })
        }
        None => serde_json::Value::Null,
    };
    let _ = &mut server;
    let stepper = server.stepper();
    let counters = stepper.counters;
    let rejected: serde_json::Map<String, serde_json::Value> = RejectReason::ALL
        .iter()
        .map(|r| (r.name().to_string(), counters.rejected[*r as usize].into()))
        .collect();
    let (mass, max): (Vec<f64>, Vec<f32>) = match server.latest() {
        Some((_, view)) => (0..view.channels)
            .map(|c| (view.total(c), view.max(c)))
            .unzip(),
        None => (vec![], vec![]),
    };
    eprintln!(
        "field '{}' stopped after {ticks} ticks ({:.1} s): {} deposits applied, {} rejected, longest tick {:.3} ms, longest gap between frames {:.3} ms",
        a.name,
        started.elapsed().as_secs_f64(),
        counters.applied,
        counters.rejected_total(),
        max_compute_ns as f64 / 1e6,
        longest_gap_ns as f64 / 1e6
    );
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "field": a.name,
                "ticks": ticks,
                "sequence": stepper.sequence,
                "sim_time_s": stepper.sim_time_s,
                "deposits_applied": counters.applied,
                "deposits_rejected": rejected,
                "total_mass": mass,
                "max": max,
                "max_tick_compute_ms": max_compute_ns as f64 / 1e6,
                "longest_tick_gap_ms": longest_gap_ns as f64 / 1e6,
                "dead_nodes_cleaned": dead_nodes_cleaned,
                "restored_sequence": restore.as_ref().map(|c| c.header.sequence),
                "checkpoint": checkpoint_summary,
                "standby": standby_summary,
            })
        );
    }
    Ok(())
}

/// The standby phase: mirror the primary until it dies, then take over. `None` when stopped
/// first (Ctrl-C, --duration).
fn run_standby(
    a: &FieldArgs,
    node: &iceoryx2::prelude::Node<field::shm::Svc>,
    config: &FieldConfig,
) -> anyhow::Result<Option<(FieldServer, Takeover, u64)>> {
    let started = Instant::now();
    let period = Duration::from_secs_f64(1.0 / config.tick_hz as f64);
    let mut standby =
        Standby::attach_within(node, &a.name, config.clone(), Duration::from_secs(30)).map_err(
            |e| match e {
                ShmError::StandbyMismatch { .. } => bad(e.to_string()),
                e => e.into(),
            },
        )?;
    eprintln!(
        "field '{}': standby, mirroring the primary (frame {})",
        a.name,
        standby.latest().map(|h| h.sequence).unwrap_or(0)
    );
    loop {
        if node.wait(Duration::ZERO).is_err()
            || a.duration
                .is_some_and(|d| started.elapsed().as_secs_f64() >= d)
        {
            eprintln!(
                "field '{}': standby stopped after mirroring {} frames",
                a.name, standby.mirrored
            );
            return Ok(None);
        }
        let event = standby.poll(period).map_err(|e| match e {
            ShmError::StandbyMismatch { .. } => bad(e.to_string()),
            e => e.into(),
        })?;
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
    writing: Option<std::thread::JoinHandle<Result<u64, checkpoint::CheckpointError>>>,
    written: u64,
    failed: u64,
}

impl Checkpointer {
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
    fn finish(&mut self, server: &FieldServer) -> anyhow::Result<()> {
        self.collect(true);
        if let Some((header, view)) = server.latest() {
            checkpoint::write_atomic(&self.path, header, server.config(), view.cells)?;
            self.written += 1;
        }
        Ok(())
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
        }
    }

    fn add(&mut self, out: &field::shm::TickOutcome, gap_ns: u64) {
        self.ticks += 1;
        self.longest_gap_ns = self.longest_gap_ns.max(gap_ns);
        self.compute_ns += out.compute_ns;
        self.max_compute_ns = self.max_compute_ns.max(out.compute_ns);
        self.applied += out.report.deposits_applied as u64;
        self.rejected += out.rejected;
    }

    fn log(&self, name: &str, stepper: &field::Stepper, dead_nodes_cleaned: u64) {
        let secs = self.started.elapsed().as_secs_f64();
        let c = stepper.counters;
        let reasons: Vec<String> = RejectReason::ALL
            .iter()
            .filter(|r| c.rejected[**r as usize] > 0)
            .map(|r| format!("{} {}", r.name(), c.rejected[*r as usize]))
            .collect();
        eprintln!(
            "field '{name}': {:.1} ticks/s, tick {:.3} ms mean / {:.3} ms max, longest_tick_gap_ms {:.3}, \
             deposits +{} applied +{} rejected (total {} applied, {} rejected{}{}){}",
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
            }
        );
    }
}
