//! `pheromone field`: the field process loop.

use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, ValueEnum};
use pheromone_field::process::checkpoint;
use pheromone_field::process::run::{run_field, FieldRunOptions};
use pheromone_field::shm::{create_node, frame_pool};
use pheromone_field::{Evaporation, FieldConfig};

use super::{bad, bad_from, bad_in, read_toml};

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq, Debug)]
pub enum ModelArg {
    /// No evaporation.
    None,
    /// P' = P·e^(−K·dt).
    Exponential,
    /// Paper 000 ambient-aware: P' = P·e + (1 − e)·min(P, α·Pa).
    Ambient,
    /// Seeds 001/004: ξ' = (1 − ρ)·ξ, deposits saturate at ±1.
    Saturating,
    /// Paper 002 counters: lose Q every τ seconds.
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
/// Without --config the field has one channel, 'trail', with the paper 000 ambient-aware model
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
    #[arg(long, value_parser = super::int::<u32>(1, 65_536))]
    pub width: Option<u32>,
    /// Grid height in cells [default: 512].
    #[arg(long, value_parser = super::int::<u32>(1, 65_536))]
    pub height: Option<u32>,
    /// Cell size in metres [default: 0.05].
    #[arg(long, value_parser = super::f32_pos(1e6), value_name = "M")]
    pub cell_size: Option<f32>,
    /// World x of the grid's lower-left corner, metres [default: 0].
    #[arg(long, value_parser = super::f32_any(), value_name = "M", allow_negative_numbers = true)]
    pub origin_x: Option<f32>,
    /// World y of the grid's lower-left corner, metres [default: 0].
    #[arg(long, value_parser = super::f32_any(), value_name = "M", allow_negative_numbers = true)]
    pub origin_y: Option<f32>,
    /// Ticks per second [default: 50].
    #[arg(long, value_parser = super::f32_pos(1e5), value_name = "HZ")]
    pub tick_hz: Option<f32>,
    /// Evaporation model of the first channel (replaces the file's).
    #[arg(long, value_enum)]
    pub model: Option<ModelArg>,
    /// Evaporation rate K per second (exponential, ambient) [default: 0.0057].
    #[arg(long, value_parser = super::f32_in(0.0, 1e9), value_name = "K", visible_alias = "decay-per-sec")]
    pub decay_per_s: Option<f32>,
    /// Ambient weight α in [0, 1] (ambient) [default: 0.5].
    #[arg(long, value_parser = super::f32_in(0.0, 1.0))]
    pub alpha: Option<f32>,
    /// Radius of the ambient mean window in metres (ambient) [default: 0.5].
    #[arg(long, value_parser = super::f32_in(0.0, 1e6), value_name = "M")]
    pub ambient_radius: Option<f32>,
    /// Fraction ρ evaporated per tick (saturating) [default: 0.05].
    #[arg(long, value_parser = super::f32_in(0.0, 1.0))]
    pub rho_per_tick: Option<f32>,
    /// Counter quantum Q lost per time constant (quantum) [default: 1].
    #[arg(long, value_parser = super::f32_in(0.0, 1e9))]
    pub quantum: Option<f32>,
    /// Counter time constant τ in seconds (quantum) [default: 1].
    #[arg(long, value_parser = super::f32_pos(1e9), value_name = "SECS", visible_alias = "tau-secs")]
    pub tau_s: Option<f32>,
    /// Diffusion coefficient D in m²/s of the first channel (stability D·dt/h² ≤ ¼ is checked).
    #[arg(long, value_parser = super::f32_in(0.0, 1e9), value_name = "M2_PER_S")]
    pub diffusion: Option<f32>,
    /// Let the first channel hold negative values (anti-pheromone).
    #[arg(long)]
    pub signed: bool,
    /// Readers the frame service admits [default: 8].
    #[arg(long, value_parser = super::int::<usize>(1, 1024))]
    pub max_readers: Option<usize>,
    /// Deposit publishers the field admits [default: 64].
    #[arg(long, value_parser = super::int::<usize>(1, 4096))]
    pub max_depositors: Option<usize>,
    /// Deposits buffered between two ticks [default: 1024].
    #[arg(long, value_parser = super::int::<usize>(1, 1_048_576))]
    pub deposit_buffer: Option<usize>,
    /// Tick once per clock message of the simulated world NAME (lockstep simulation) instead of
    /// on wall time; the field stops when the world says it has finished.
    #[arg(long, value_name = "WORLD")]
    pub clock: Option<String>,
    /// Stop after this many ticks.
    #[arg(long, value_parser = super::int::<u64>(1, 1_000_000_000_000))]
    pub ticks: Option<u64>,
    /// Stop after this many seconds of wall time.
    #[arg(long, value_parser = super::secs0(), value_name = "SECS")]
    pub duration: Option<f64>,
    /// Print the configuration that would run, as TOML, and exit.
    #[arg(long)]
    pub print_config: bool,
    /// Save the current frame to FILE (header, planes and checksum; written to FILE.tmp,
    /// fsynced, then renamed) every --checkpoint-every seconds and when the field stops.
    #[arg(long, value_name = "FILE", value_parser = super::check::out_file())]
    pub checkpoint: Option<PathBuf>,
    /// Seconds between two checkpoints [default: 10].
    #[arg(long, value_parser = super::secs(), value_name = "SECS", requires = "checkpoint")]
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
    /// Publish a frame as soon as deposits arrive, no sooner than MS milliseconds after the last
    /// frame, instead of waiting for the next tick (depositors wake the field through
    /// pheromone/<NAME>/deposit-ready). Every frame then steps evaporation by the real elapsed
    /// time (at most one tick period); regular ticks go on between deposits. Not with --clock.
    #[arg(long, value_parser = super::f64_in(0.0, 1e12), value_name = "MS", conflicts_with = "clock")]
    pub publish_on_deposit_ms: Option<f64>,
    /// Threads of each tick's evaporation pass: the rows are split across N threads, each cell
    /// still read once and written once, and the frames are bit-identical to one thread's. Worth
    /// it for large grids with the ambient model; 1 (the default) keeps the tick on the field's
    /// own thread.
    #[arg(long, value_parser = super::int::<usize>(1, 256), value_name = "N", default_value_t = 1)]
    pub threads: usize,
    #[command(flatten)]
    pub rt: super::rt::RtArgs,
    /// A wall-time tick that starts more than this after its deadline counts as a missed
    /// deadline (µs; default a tenth of the period). Counted in the log and the --json summary.
    #[arg(long, value_parser = super::f64_in(0.0, 1e15), value_name = "US")]
    pub deadline_slack_us: Option<f64>,
    /// Sleep until US microseconds before each tick's deadline, then poll until it: ticks start
    /// on time (no OS wake-up delay), and with --publish-on-deposit-ms a deposit that arrives
    /// meanwhile is seen at once. Costs up to US µs of CPU per period (a spin as long as the
    /// period polls all the time: one core). 0 (the default) sleeps.
    #[arg(long, value_parser = super::f64_in(0.0, 1e7), value_name = "US", default_value_t = 0.0, conflicts_with = "clock")]
    pub spin_us: f64,
    /// Run as a mirror of the field of the same name on another host: `zenoh:tcp/HOST:PORT`,
    /// the address of its `pheromone bridge`. The mirror takes the origin's configuration,
    /// starts from a keyframe, applies each frame's deposits with the same stepper and publishes
    /// bit-identical frames with the origin's sequence numbers here; deposits made on this host
    /// go to the origin. It asks for a keyframe on a checksum mismatch, a sequence gap, an
    /// origin restart or a lost connection, and logs `stale` while it has no origin. Needs a
    /// build with `--features zenoh`. Grid flags are ignored (the origin's apply).
    #[arg(long, value_name = "zenoh:ENDPOINT", value_parser = super::check::mirror_endpoint(), conflicts_with_all = ["standby", "restore", "clock", "checkpoint"])]
    pub mirror: Option<String>,
    /// A mirror is stale after this many seconds without inputs from its origin [default: 1].
    #[arg(long, value_parser = super::secs(), value_name = "SECS", requires = "mirror")]
    pub stale_after_s: Option<f64>,
    // With --mirror: TLS, credentials and access control (docs/mirrors.md, "Security").
    #[command(flatten)]
    pub zenoh: super::zenoh_args::ZenohArgs,
    /// At exit, print one JSON summary object on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Builds the configuration from the file (if any), then the flags.
pub fn config_from_args(a: &FieldArgs) -> anyhow::Result<FieldConfig> {
    let mut c: FieldConfig = match (&a.config, &a.scenario) {
        (Some(p), _) => read_toml(p)?,
        (None, Some(s)) => super::roles::load_scenario(s)?
            .field_config_for_processes()
            .map_err(|e| bad_in(s.as_str(), e))?,
        (None, None) => FieldConfig::default(),
    };
    macro_rules! set {
        ($($flag:ident => $field:ident),*) => { $(if let Some(v) = a.$flag { c.$field = v; })* };
    }
    set!(width => width, height => height, cell_size => cell_size_m, origin_x => origin_x_m,
         origin_y => origin_y_m, tick_hz => tick_hz, max_readers => max_readers,
         max_depositors => max_depositors, deposit_buffer => deposit_buffer);
    let ch = &mut c.channels[0];
    ch.evaporation = evaporation_from_args(a, ch.evaporation)?;
    if let Some(d) = a.diffusion {
        ch.diffusion_m2_per_s = d;
    }
    if a.signed {
        ch.signed = true;
    }
    c.validate().map_err(|e| match &a.config {
        Some(p) => bad_in(p.display().to_string(), e),
        None => bad_from(e),
    })?;
    Ok(c)
}

/// The model of `--model` (by default `current`'s) with the parameters its flags give, the
/// others from `current` or the defaults; a flag of another model is refused.
fn evaporation_from_args(a: &FieldArgs, current: Evaporation) -> anyhow::Result<Evaporation> {
    let model = a.model.unwrap_or(model_of(current));
    let (k0, alpha0, radius0) = match current {
        Evaporation::Ambient {
            decay_per_s,
            alpha,
            radius_m,
        } => (decay_per_s, alpha, radius_m),
        Evaporation::Exponential { decay_per_s } => (decay_per_s, 0.5, 0.5),
        _ => (0.0057, 0.5, 0.5),
    };
    let unused = |flags: &[(&str, Option<f32>)]| unused_flags(model, flags);
    let evaporation = match model {
        ModelArg::None => {
            unused(&[
                ("decay-per-s", a.decay_per_s),
                ("alpha", a.alpha),
                ("ambient-radius", a.ambient_radius),
            ])?;
            Evaporation::None
        }
        ModelArg::Exponential => {
            unused(&[("alpha", a.alpha), ("ambient-radius", a.ambient_radius)])?;
            Evaporation::Exponential {
                decay_per_s: a.decay_per_s.unwrap_or(k0),
            }
        }
        ModelArg::Ambient => Evaporation::Ambient {
            decay_per_s: a.decay_per_s.unwrap_or(k0),
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
                Evaporation::Quantum { quantum, tau_s } => (quantum, tau_s),
                _ => (1.0, 1.0),
            };
            Evaporation::Quantum {
                quantum: a.quantum.unwrap_or(q0),
                tau_s: a.tau_s.unwrap_or(t0),
            }
        }
    };
    if model != ModelArg::Saturating {
        unused(&[("rho-per-tick", a.rho_per_tick)])?;
    }
    if model != ModelArg::Quantum {
        unused(&[("quantum", a.quantum), ("tau-s", a.tau_s)])?;
    }
    Ok(evaporation)
}

/// The first of `flags` given, refused as not applying to `model`.
fn unused_flags(model: ModelArg, flags: &[(&str, Option<f32>)]) -> anyhow::Result<()> {
    match flags.iter().find_map(|(f, v)| v.map(|v| (f, v))) {
        Some((flag, v)) => Err(bad(format!(
            "--{flag} {v} does not apply to the {model:?} model"
        ))),
        None => Ok(()),
    }
}

/// The model of an evaporation.
fn model_of(e: Evaporation) -> ModelArg {
    match e {
        Evaporation::None => ModelArg::None,
        Evaporation::Exponential { .. } => ModelArg::Exponential,
        Evaporation::Ambient { .. } => ModelArg::Ambient,
        Evaporation::Saturating { .. } => ModelArg::Saturating,
        Evaporation::Quantum { .. } => ModelArg::Quantum,
    }
}

pub fn run(a: FieldArgs) -> anyhow::Result<()> {
    // `--mirror` runs `pheromone_bridge::run_mirror` instead (dispatched by main, as this module's
    // arguments are the mirror's too).
    if a.zenoh.any() {
        return Err(bad(
            "--zenoh-config, --tls-*, --user, --password-file and --users-file are a mirror's \
             (--mirror zenoh:ENDPOINT)",
        ));
    }
    let config = config_from_args(&a)?;
    pheromone_field::shm::check_name(&a.name).map_err(bad_from)?;
    if a.print_config {
        print!("{}", toml::to_string_pretty(&config)?);
        return Ok(());
    }
    let options = run_options(&a, config)?;
    let (frames, bytes) = frame_pool(&options.config);
    eprintln!(
        "field '{}': {}×{} cells × {} channel(s), {} m cells, {} Hz; shared memory {:.1} MiB ({} frames)",
        a.name,
        options.config.width,
        options.config.height,
        options.config.channels.len(),
        options.config.cell_size_m,
        options.config.tick_hz,
        bytes as f64 / (1 << 20) as f64,
        frames
    );
    a.rt.apply(&format!("field '{}'", a.name))?;
    // SIGINT/SIGTERM stop the field as before (summary written) and set its exit status.
    super::stop::install()?;
    let node = create_node(&format!("field-{}", a.name))?;
    let summary = match run_field(&node, &options) {
        Ok(s) => s,
        Err(e) if e.is_bad_input() => return Err(bad_from(e)),
        Err(e) => return Err(e.into()),
    };
    finish(&a, summary)
}

/// The field's run options from its flags (their parsers have checked the numbers) and the
/// checkpoint to restore, read and checked against `config`.
fn run_options(a: &FieldArgs, config: FieldConfig) -> anyhow::Result<FieldRunOptions> {
    let restore = match &a.restore {
        Some(path) => {
            let cp = checkpoint::read(path).map_err(bad_from)?;
            cp.check_against(path, &config).map_err(bad_from)?;
            Some((path.clone(), cp))
        }
        None => None,
    };
    Ok(FieldRunOptions {
        name: a.name.clone(),
        config,
        clock: a.clock.clone(),
        ticks: a.ticks,
        duration: a.duration.map(Duration::from_secs_f64),
        checkpoint: a.checkpoint.clone(),
        checkpoint_every: Duration::from_secs_f64(a.checkpoint_every.unwrap_or(10.0)),
        restore,
        standby: a.standby,
        publish_on_deposit: a
            .publish_on_deposit_ms
            .map(|ms| Duration::from_secs_f64(ms / 1e3)),
        threads: a.threads,
        deadline_slack: a
            .deadline_slack_us
            .map(|us| Duration::from_secs_f64(us / 1e6)),
        spin: Duration::from_secs_f64(a.spin_us / 1e6),
    })
}

/// Prints the `--json` summary; a field stopped by SIGINT or SIGTERM then exits 130 / 143.
fn finish(
    a: &FieldArgs,
    summary: Option<pheromone_field::process::run::FieldRunSummary>,
) -> anyhow::Result<()> {
    if a.json {
        match summary {
            Some(s) => println!("{}", serde_json::to_string(&s)?),
            // A standby stopped (Ctrl-C or --duration) while the primary was alive.
            None => println!(
                "{}",
                serde_json::json!({ "field": a.name, "standby": { "took_over": false } })
            ),
        }
    }
    match super::stop::requested() {
        Some(signal) => Err(super::stop::Stopped { signal }.into()),
        None => Ok(()),
    }
}
