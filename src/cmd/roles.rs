//! `pheromone world | localizer | mapper | depositor | follower`: the robot processes. Each reads the
//! same scenario (a built-in name or a TOML file) and runs its part of it.

use clap::{Args, ValueEnum};
use pheromone_field::shm::{create_node, WaitPolicy};
use pheromone_roles::depositor::{DepositMode, DepositorConfig};
use pheromone_roles::follower::{Follower, FollowerConfig, StrategyKind};
use pheromone_roles::{
    run_depositor, run_follower, run_localizer, run_mapper, OwnMap, RoleOptions,
};
use pheromone_world::scenario::Scenario;
use pheromone_world::{run_world, WorldOptions};

use super::{bad, bad_from, seconds};

/// Options every robot process shares.
#[derive(Args, Debug, Clone)]
pub struct Common {
    /// Scenario: a built-in name (blind-leader, trail-following, ias-ss, evaporation, trail,
    /// wrong-area) or a TOML file.
    #[arg(long, default_value = pheromone_world::scenario::DEFAULT_SCENARIO)]
    pub scenario: String,
    /// Name of the simulated world (its clock is sim/<WORLD>/clock).
    #[arg(long, default_value = "sim")]
    pub world: String,
    /// Name of the field to attach to.
    #[arg(long, default_value = "main")]
    pub field: String,
    /// Print one JSON summary object on stdout at exit.
    #[arg(long)]
    pub json: bool,
    /// The world steps on wall time: nobody waits for anybody (give it to every process of the
    /// run). Default: lockstep, as fast as the slowest process, and deterministic for a seed.
    #[arg(long)]
    pub realtime: bool,
    #[command(flatten)]
    pub rt: super::rt::RtArgs,
}

impl Common {
    fn role_options(&self, robot: u32) -> RoleOptions {
        RoleOptions {
            robot,
            world: self.world.clone(),
            field: self.field.clone(),
            lockstep: !self.realtime,
            frame_wait: WaitPolicy::Event,
        }
    }
}

pub fn load_scenario(name: &str) -> anyhow::Result<Scenario> {
    Scenario::load(name).map_err(bad_from)
}

/// Checks the names, then applies --rt-priority (as `who`, e.g. "depositor r3").
fn check_names(c: &Common, who: &str) -> anyhow::Result<()> {
    for n in [&c.world, &c.field] {
        pheromone_field::shm::check_name(n).map_err(bad_from)?;
    }
    c.rt.apply(who)
}

fn print_json(json: bool, value: impl serde::Serialize) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string(&value)?);
    }
    Ok(())
}

/// Run the simulator: true poses of every robot of the scenario (differential drive, walls),
/// noisy odometry and landmark observations, scripted deposits, and the simulation clock.
///
/// Lockstep (default): the world waits until every process of the scenario has joined (the
/// field, each robot's localizer, depositor and follower; with --observed also `pheromone sim`),
/// then per step publishes sensors and truth, waits for every depositor's acknowledgement, sends
/// the clock tick, and waits for the field's tick and every follower's command before it
/// advances — as fast as the processes answer, and with the single-process answer. --realtime
/// steps every dt of wall time with the newest commands instead (give it to every role too).
/// Start the field with `--clock WORLD` so it ticks once per step.
#[derive(Args, Debug)]
pub struct WorldArgs {
    #[command(flatten)]
    pub common: Common,
    /// Lockstep: fail when a step has made no progress (no acknowledgement, no command) for
    /// this many seconds.
    #[arg(long, value_parser = super::secs(), default_value_t = 30.0, value_name = "SECS")]
    pub stall_timeout: f64,
    /// Lockstep: how long every process of the run (field, localizers, depositors, followers,
    /// observer) may take to join [default: 10 s + 0.5 s per process].
    #[arg(long, value_parser = super::secs(), value_name = "SECS")]
    pub attach_timeout: Option<f64>,
    /// An observer (`pheromone sim`) takes part in the lockstep: wait for it too.
    #[arg(long)]
    pub observed: bool,
    /// When the scenario maps ([mapping]): one `pheromone mapper` per robot takes part in the
    /// lockstep: wait for each one's map frame of every step too.
    #[arg(long)]
    pub mapped: bool,
}

pub fn run_world_cmd(a: WorldArgs) -> anyhow::Result<()> {
    check_names(&a.common, "world")?;
    let scenario = load_scenario(&a.common.scenario)?;
    let node = create_node(&format!("world-{}", a.common.world))?;
    let summary = run_world(
        &node,
        &scenario,
        &WorldOptions {
            world: a.common.world.clone(),
            field: a.common.field.clone(),
            realtime: a.common.realtime,
            stall_timeout: seconds("stall-timeout", a.stall_timeout)?,
            attach_timeout: a
                .attach_timeout
                .map(|v| seconds("attach-timeout", v))
                .transpose()?,
            observed: a.observed,
            mapped: a.mapped,
        },
    )?;
    eprintln!(
        "world '{}': {} steps, {:.1} s simulated, {} scripted deposits",
        a.common.world, summary.steps, summary.sim_time_s, summary.deposits_sent
    );
    print_json(a.common.json, &summary)
}

/// Run the localizer of one robot: the EKF of paper 001 Algorithm 1 (velocity motion model,
/// maximum-likelihood landmark association) over the world's sensor messages; publishes pose +
/// covariance (pheromone/<WORLD>/r<ID>/pose) for every step. Settings come from the scenario's
/// `[robot.localizer]` (noise α1..α4, gate, the `loss` knob that makes a robot lose its
/// localization, and `landmark_region_m`, the captured area association is restricted to).
#[derive(Args, Debug)]
pub struct LocalizerArgs {
    #[command(flatten)]
    pub common: Common,
    /// Robot id.
    #[arg(long, default_value_t = 0)]
    pub robot: u32,
    /// EKF-SLAM: ignore the scenario's landmark map; landmarks join the state as they are seen.
    #[arg(long)]
    pub slam: bool,
    /// Associate observations only with the map landmarks inside this box (m): the captured
    /// area of paper 001 Algorithm 1 lines 10–14. Overrides the scenario's
    /// `[robot.localizer] landmark_region_m`.
    #[arg(
        long,
        value_name = "XMIN,YMIN,XMAX,YMAX",
        value_parser = pheromone_roles::localizer::parse_landmark_region,
        allow_hyphen_values = true,
        conflicts_with = "slam"
    )]
    pub landmark_region: Option<[f64; 4]>,
    /// The filter: ekf (landmarks, the default), ukf (landmarks, paper 000 eqs. 6–8) or pf
    /// (particle filter with the world's laser). Overrides the scenario's `filter` of the robot.
    #[arg(long, value_name = "ekf|ukf|pf", value_parser = parse_filter, conflicts_with = "slam")]
    pub filter: Option<pheromone_roles::localizer::FilterKind>,
    /// Particles of the particle filter (10..=100000). Overrides the scenario's `pf.particles`.
    #[arg(long, value_name = "N", value_parser = parse_particles)]
    pub particles: Option<usize>,
}

/// `--filter ekf|ukf|pf`.
pub fn parse_filter(text: &str) -> Result<pheromone_roles::localizer::FilterKind, String> {
    text.parse()
}

/// `--particles N`: an integer in [10, 100000].
pub fn parse_particles(text: &str) -> Result<usize, String> {
    pheromone_roles::localizer::parse_particles(text)
}

pub fn run_localizer_cmd(a: LocalizerArgs) -> anyhow::Result<()> {
    check_names(&a.common, &format!("localizer r{}", a.robot))?;
    let mut scenario = load_scenario(&a.common.scenario)?;
    if let Some(region) = a.landmark_region {
        if let Some(r) = scenario.robots.iter_mut().find(|r| r.id == a.robot) {
            r.localizer.landmark_region_m = Some(region);
        }
    }
    if let Some(r) = scenario.robots.iter_mut().find(|r| r.id == a.robot) {
        if let Some(k) = a.filter {
            r.filter = k;
        }
        if let Some(n) = a.particles {
            r.pf.particles = n;
        }
    }
    let node = create_node(&format!("localizer-r{}-{}", a.robot, std::process::id()))?;
    let setup = scenario.localizer_setup(a.robot, a.slam)?;
    let summary = run_localizer(&node, &setup, &a.common.role_options(a.robot))?;
    eprintln!(
        "localizer r{}: {} steps, {} rejected",
        a.robot, summary.steps, summary.rejected
    );
    print_json(a.common.json, &summary)
}

/// Run the mapper of one robot (paper 004, MODELS.md M4): integrates the robot's range scans
/// (sim/<WORLD>/r<ID>/scan) at its pose estimate (pheromone/<WORLD>/r<ID>/pose) into an
/// occupancy grid (log-odds) and keeps its pheromone map, both in the robot's own frame (origin
/// = its start pose), and publishes them every step as a frame of the field
/// `<WORLD>-map-r<ID>` (channels: occupancy, pheromone; `pheromone probe --field
/// <WORLD>-map-r<ID>` reads it). At a rendezvous (sim/<WORLD>/r<ID>/rendezvous) it merges its
/// peers' maps straight from their frames in shared memory (Algorithm 1: schedule, loss
/// refusal; a frame whose header disagrees with its length or that holds a non-finite cell is
/// refused and counted). Settings come from the scenario's `[mapping]`. In lockstep start the
/// world with --mapped so it waits for every mapper.
#[derive(Args, Debug)]
pub struct MapperArgs {
    #[command(flatten)]
    pub common: Common,
    /// Robot id.
    #[arg(long, default_value_t = 0)]
    pub robot: u32,
}

pub fn run_mapper_cmd(a: MapperArgs) -> anyhow::Result<()> {
    check_names(&a.common, &format!("mapper r{}", a.robot))?;
    let scenario = load_scenario(&a.common.scenario)?;
    let node = create_node(&format!("mapper-r{}-{}", a.robot, std::process::id()))?;
    let setup = scenario.mapper_setup(a.robot)?;
    let summary = run_mapper(&node, setup, &a.common.role_options(a.robot))?;
    eprintln!(
        "mapper r{}: {} steps, {} merges, {} maps refused, {} exchanges refused (lost)",
        a.robot,
        summary.role.steps,
        summary.counters.merges,
        summary.counters.merges_rejected.values().sum::<u64>(),
        summary.counters.refused_lost
    );
    print_json(a.common.json, &summary)
}

#[derive(Clone, Copy, ValueEnum, Debug)]
pub enum ModeArg {
    /// Paper 000: γ = τ/det Σxy (capped), error-ellipse shape.
    UncertaintyAware,
    /// Seeds 001/004: saturating deposit, ρt from the covariance.
    Saturating,
    /// Traditional: the same deposit whatever the localization.
    Constant,
}

/// Run the depositor of one robot: turns each pose + covariance into deposits on the field —
/// paper 000 (amount ∝ 1/det Σxy, error-ellipse shape, only within z_rng, at intervals), or the
/// saturating M2/M4 deposit, or constant. Settings come from the scenario's `[robot.depositor]`;
/// flags override.
#[derive(Args, Debug)]
pub struct DepositorArgs {
    #[command(flatten)]
    pub common: Common,
    /// Robot id.
    #[arg(long, default_value_t = 0)]
    pub robot: u32,
    /// Deposit mode.
    #[arg(long, value_enum)]
    pub mode: Option<ModeArg>,
    /// Shorthand for --mode constant (the scheme paper 000 argues against).
    #[arg(long, conflicts_with = "mode")]
    pub constant: bool,
    /// Field channel to deposit into.
    #[arg(long, value_parser = super::int::<u32>(0, 63))]
    pub channel: Option<u32>,
    /// Deposit anti-pheromone (negative amounts; the channel must be signed).
    #[arg(long)]
    pub anti_pheromone: bool,
    /// Deposit after moving this far (m); 0 = off.
    #[arg(long, value_parser = super::f64_in(0.0, 1e6), value_name = "M")]
    pub interval_m: Option<f64>,
    /// Deposit after this much time (s); 0 = off.
    #[arg(long, value_parser = super::secs0(), value_name = "SECS")]
    pub interval_s: Option<f64>,
    /// τ of paper 000 eq. 12.
    #[arg(long, value_parser = super::f32_pos(1e9))]
    pub tau: Option<f32>,
    /// Sensor range z_rng (m).
    #[arg(long, value_parser = super::f32_pos(1e6), value_name = "M")]
    pub range: Option<f32>,
}

pub fn run_depositor_cmd(a: DepositorArgs) -> anyhow::Result<()> {
    check_names(&a.common, &format!("depositor r{}", a.robot))?;
    let scenario = load_scenario(&a.common.scenario)?;
    let mut config: DepositorConfig = scenario
        .roles(a.robot)
        .and_then(|r| r.depositor.clone())
        .unwrap_or_default();
    if let Some(m) = a.mode {
        config.mode = match m {
            ModeArg::UncertaintyAware => DepositMode::UncertaintyAware,
            ModeArg::Saturating => DepositMode::Saturating,
            ModeArg::Constant => DepositMode::Constant,
        };
    }
    if a.constant {
        config.mode = DepositMode::Constant;
    }
    if let Some(c) = a.channel {
        config.channel = c;
    }
    config.anti_pheromone |= a.anti_pheromone;
    if let Some(v) = a.interval_m {
        config.interval_m = v;
    }
    if let Some(v) = a.interval_s {
        config.interval_s = v;
    }
    if let Some(v) = a.tau {
        config.tau = v;
    }
    if let Some(v) = a.range {
        config.range_m = v;
    }
    config.validate().map_err(bad_from)?;
    let node = create_node(&format!("depositor-r{}-{}", a.robot, std::process::id()))?;
    let summary = run_depositor(&node, &a.common.role_options(a.robot), config)?;
    eprintln!(
        "depositor r{}: {} poses, {} rejected",
        a.robot, summary.steps, summary.rejected
    );
    print_json(a.common.json, &summary)
}

/// Run the follower of one robot: reads the newest frame and the robot's pose, publishes a
/// motion command (pheromone/<WORLD>/r<ID>/cmd) and a status (following / trail abandoned / exploring).
/// Strategies: gradient (paper 000: climb ∇P, trail rejection, speed table), antenna (paper 002),
/// inverse (paper 004 IAS-SS), uniform (paper 004's random baseline). Settings come from the
/// scenario's `[robot.follower]`; flags override. With --gateway an antenna robot reads its two
/// antennas only through PIR requests to `pheromone gateway` (paper 002's thin client), with an
/// optional --backup gateway. With the scenario's `[mapping] steer_on = "own-map"` (paper 004)
/// a sector follower reads its robot's map, field `<WORLD>-map-r<ID>` published by `pheromone
/// mapper`, at its estimate in the map's frame, instead of the shared field.
#[derive(Args, Debug)]
pub struct FollowerArgs {
    #[command(flatten)]
    pub common: Common,
    /// Robot id.
    #[arg(long, default_value_t = 0)]
    pub robot: u32,
    /// Strategy: gradient, antenna, inverse, uniform or route.
    #[arg(long)]
    pub strategy: Option<StrategyKind>,
    /// How to wait for the frame of each step (lockstep): `event` sleeps on the field's frame
    /// event (no CPU; a wake-up from sleep costs ~150–200 µs on a small VM), `spin:US` polls for
    /// US µs first, then sleeps (at most US µs of CPU per step), `busy-poll` polls (a whole
    /// core). The run's results do not depend on it.
    #[arg(
        long,
        default_value = "event",
        value_name = "event|spin:US|busy-poll",
        conflicts_with = "gateway"
    )]
    pub wait: WaitPolicy,
    /// Field channel to read.
    #[arg(long, value_parser = super::int::<u32>(0, 63))]
    pub channel: Option<u32>,
    /// Seed of the sector strategies' random choices.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Antenna strategy only: read the two antennas through PIR requests to the gateway at
    /// `udp://HOST:PORT` (`pheromone gateway`), with nothing of the field in shared memory (the
    /// pose, command and status services with the world stay). In lockstep a PIR answered from
    /// a frame older than the step's is sent again until the field's tick lands.
    #[arg(long, value_name = "udp://HOST:PORT")]
    pub gateway: Option<String>,
    /// A backup gateway (`udp://HOST:PORT`), asked when the active one does not answer within
    /// --gateway-timeout-ms × (1 + --gateway-retries).
    #[arg(long, value_name = "udp://HOST:PORT", requires = "gateway")]
    pub backup: Option<String>,
    /// Client ID in the gateway frames (1–255) [default: robot id + 1].
    #[arg(long, requires = "gateway")]
    pub client_id: Option<u8>,
    /// How long each PIR or deposit waits for the gateway's reply (ms).
    #[arg(long, value_parser = super::int::<u64>(1, 3_600_000), default_value_t = 100, value_name = "MS", requires = "gateway")]
    pub gateway_timeout_ms: u64,
    /// Attempts after the first on the same gateway before switching to the backup.
    #[arg(long, value_parser = super::int::<u32>(0, 1000), default_value_t = 2, requires = "gateway")]
    pub gateway_retries: u32,
    /// Deposit this amount at the robot's pose through the gateway every --deposit-every steps
    /// (a leader laying a trail remotely); a deposit is never resent to the other gateway, so
    /// it is applied at most once.
    #[arg(long, value_parser = super::f32_pos(1e9), requires = "gateway")]
    pub deposit_amount: Option<f32>,
    /// Steps between two --deposit-amount deposits.
    #[arg(
        long,
        value_parser = super::int::<u64>(1, 1_000_000_000),
        default_value_t = 10,
        value_name = "STEPS",
        requires = "deposit_amount"
    )]
    pub deposit_every: u64,
    /// Lockstep: seconds a step may wait for the frame of its step (from the gateway).
    #[arg(
        long,
        value_parser = super::secs(),
        default_value_t = 30.0,
        value_name = "SECS",
        requires = "gateway"
    )]
    pub frame_timeout: f64,
}

/// `udp://HOST:PORT` → `HOST:PORT`.
fn udp_address(flag: &str, url: &str) -> anyhow::Result<String> {
    match url.strip_prefix("udp://") {
        Some(a) if !a.is_empty() => Ok(a.to_string()),
        _ => Err(bad(format!(
            "{flag} '{url}': expected udp://HOST:PORT (e.g. udp://127.0.0.1:7402)"
        ))),
    }
}

/// The client ID of `--client-id`, else robot + 1.
fn client_id(a: &FollowerArgs) -> anyhow::Result<u8> {
    match a.client_id {
        Some(0) => Err(bad(
            "--client-id 0: use 1–255 (0 is not protected by the CRC)",
        )),
        Some(id) => Ok(id),
        None => u8::try_from(a.robot + 1).map_err(|_| {
            bad(format!(
                "robot {}: no default client ID (1–255); give --client-id",
                a.robot
            ))
        }),
    }
}

/// What reading through a gateway needs of the follower: the antenna strategy, a channel the
/// gateway can name.
fn check_remote(a: &FollowerArgs, config: &FollowerConfig) -> anyhow::Result<()> {
    if config.strategy != StrategyKind::Antenna {
        return Err(bad(format!(
            "--gateway: only the antenna strategy reads through a gateway (robot {} has '{}')",
            a.robot, config.strategy
        )));
    }
    u8::try_from(config.channel).map_err(|_| {
        bad(format!(
            "--channel {}: a gateway names channels 0–255",
            config.channel
        ))
    })?;
    Ok(())
}

/// The antenna robot of `--gateway` (`pheromone_roles::process::follower_remote`).
fn run_remote_follower(
    a: &FollowerArgs,
    scenario: &Scenario,
    config: &FollowerConfig,
    gateway: &str,
) -> anyhow::Result<()> {
    use pheromone_roles::process::follower_antenna::RemoteDeposits;
    use pheromone_roles::process::follower_remote::{run_remote_follower, RemoteFollowerOptions};
    check_remote(a, config)?;
    let client_id = client_id(a)?;
    let remote = RemoteFollowerOptions {
        gateway: udp_address("--gateway", gateway)?,
        backup: a
            .backup
            .as_deref()
            .map(|b| udp_address("--backup", b))
            .transpose()?,
        client_id,
        timeout: std::time::Duration::from_millis(a.gateway_timeout_ms),
        retries: a.gateway_retries,
        deposits: a.deposit_amount.map(|amount| RemoteDeposits {
            amount,
            every_steps: a.deposit_every,
        }),
        frame_timeout: std::time::Duration::from_secs_f64(a.frame_timeout),
        dt_s: scenario.world.dt_s,
        radio: scenario.radio.clone().map(|r| (r, scenario.seed)),
    };
    let node = create_node(&format!("follower-r{}-{}", a.robot, std::process::id()))?;
    let summary = run_remote_follower(&node, &a.common.role_options(a.robot), config, &remote)
        .map_err(|e| {
            if e.is_bad_input() {
                bad_from(e)
            } else {
                e.into()
            }
        })?;
    let s = &summary.source;
    eprintln!(
        "follower r{} (gateway {}): {} steps, {} rejected, {} PIRs ({} stale), {} switch(es), \
         {} rate-limited backoff(s), deposits {} applied / {} failed",
        a.robot,
        s.active,
        summary.role.steps,
        summary.role.rejected,
        s.reads,
        s.stale_replies,
        s.switches,
        s.rate_limited_backoffs,
        s.deposits_applied,
        s.deposits_failed
    );
    print_json(a.common.json, &summary)
}

pub fn run_follower_cmd(a: FollowerArgs) -> anyhow::Result<()> {
    check_names(&a.common, &format!("follower r{}", a.robot))?;
    let scenario = load_scenario(&a.common.scenario)?;
    let mut config: FollowerConfig = scenario.follower_config(a.robot).unwrap_or_default();
    if let Some(s) = a.strategy {
        config.strategy = s;
    }
    if let Some(c) = a.channel {
        config.channel = c;
    }
    if let Some(s) = a.seed {
        config.seed = s;
    }
    config.validate().map_err(bad_from)?;
    if let Some(g) = &a.gateway {
        return run_remote_follower(&a, &scenario, &config, g);
    }
    let follower = Follower::from_config(a.robot, &config).map_err(bad_from)?;
    let node = create_node(&format!("follower-r{}-{}", a.robot, std::process::id()))?;
    let options = RoleOptions {
        frame_wait: a.wait,
        ..a.common.role_options(a.robot)
    };
    // Own-map steering (`[mapping] steer_on`): the robot's map frame, published by its mapper.
    let own_map = scenario.own_map_start(a.robot).map(|start| OwnMap {
        field: pheromone_field::wire::map_field(&options.world, a.robot),
        start,
    });
    let summary = run_follower(
        &node,
        &options,
        follower,
        config.steer_by,
        scenario.world.dt_s,
        own_map,
    )?;
    eprintln!(
        "follower r{}: {} steps, {} rejected",
        a.robot, summary.steps, summary.rejected
    );
    print_json(a.common.json, &summary)
}
