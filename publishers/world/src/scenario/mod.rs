//! Scenarios: one TOML file describes the field, the world, each robot's roles and scripted
//! deposits. Every process of a run reads the scenario and takes its own part (in a run as
//! processes a robot's roles read only their robot's part, `part.rs`). Built-in scenarios are
//! embedded in the binary and shipped under `examples/scenarios/`.

use std::path::Path;

use pheromone_field::{DepositMsg, FieldConfig, KernelKind};
use serde::{Deserialize, Serialize};

use crate::WorldConfig;
use pheromone_roles::depositor::{DepositMode, DepositorConfig};
use pheromone_roles::follower::{FollowerConfig, StrategyKind};
use pheromone_roles::localizer::{EkfConfig, FilterKind, PfConfig, UkfConfig};

mod error;
pub use scripted_loss::ScriptedLoss;
mod map;
mod mapping;
mod part;
mod scripted_loss;
mod setup;
mod starts;
mod validate;

pub use error::{DepositError, ScenarioError};
pub use starts::StartArea;

/// The robot id the world's scripted deposits carry: after every robot's in a tick's
/// canonical order (`pheromone_field::shm::FieldServer::tick`).
pub const WORLD_DEPOSITOR_ID: u32 = u32::MAX;

/// Built-in scenarios: (name, TOML text).
pub const BUILTIN: &[(&str, &str)] = &[
    (
        "blind-leader",
        include_str!("../../../../examples/scenarios/blind-leader.toml"),
    ),
    (
        "trail-following",
        include_str!("../../../../examples/scenarios/trail-following.toml"),
    ),
    (
        "ias-ss",
        include_str!("../../../../examples/scenarios/ias-ss.toml"),
    ),
    (
        "ias-ss-open",
        include_str!("../../../../examples/scenarios/ias-ss-open.toml"),
    ),
    (
        "ias-ss-rooms",
        include_str!("../../../../examples/scenarios/ias-ss-rooms.toml"),
    ),
    (
        "evaporation",
        include_str!("../../../../examples/scenarios/evaporation.toml"),
    ),
    (
        "trail",
        include_str!("../../../../examples/scenarios/trail.toml"),
    ),
    (
        "wrong-area",
        include_str!("../../../../examples/scenarios/wrong-area.toml"),
    ),
];

/// The scenario `pheromone sim` runs when none is named.
pub const DEFAULT_SCENARIO: &str = "blind-leader";

/// Every built-in scenario name: the grid ones, then the node-graph (`regions`) ones.
pub(super) fn builtin_names() -> String {
    BUILTIN
        .iter()
        .chain(pheromone_graph::agent::BUILTIN_REGIONS.iter())
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

/// A whole run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    #[serde(default)]
    pub seed: u64,
    /// Simulated time the run lasts (s).
    pub duration_s: f64,
    #[serde(default)]
    pub field: FieldConfig,
    #[serde(default)]
    pub world: WorldConfig,
    /// The roles of each robot (`[[robot]]`).
    #[serde(default, rename = "robot")]
    pub robots: Vec<RobotRoles>,
    /// Scripted deposits (`[[deposit]]`).
    #[serde(default, rename = "deposit")]
    pub deposits: Vec<ScriptedDeposit>,
    /// Robots taking part: the first N of `[[world.robots]]` (all if unset); `--robots` sets it.
    #[serde(default)]
    pub active_robots: Option<usize>,
    /// Mark every wall of the world on a channel at t = 0 (seed 004: pheromone builds up along
    /// walls, so the sector strategies steer away from them).
    #[serde(default)]
    pub mark_walls: Option<MarkWalls>,
    /// Points whose field values are recorded at given times (`[[probe]]`).
    #[serde(default, rename = "probe")]
    pub probes: Vec<ProbeSpec>,
    /// Times (s) at which the field is pictured; the end of the run is always pictured.
    #[serde(default)]
    pub snapshots_s: Vec<f64>,
    /// Scenario-specific metrics.
    #[serde(default)]
    pub metrics: MetricsConfig,
    /// Seed 004's local maps and their merging (`scenario/mapping.rs`); off by default.
    #[serde(default)]
    pub mapping: pheromone_roles::mapper::MappingConfig,
    /// Robots start at random poses in this rectangle, drawn from the seed (`starts.rs`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_area: Option<StartArea>,
    /// The loss script `--scripted-loss` applies (`scripted_loss.rs`); unused without it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scripted_loss: Option<ScriptedLoss>,
    /// Seed 002's shared air between the gateway and its thin clients
    /// (`pheromone_gateway::radio`; `sim --remote` only, `--clients N` sets it); none: an ideal
    /// link.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radio: Option<pheromone_roles::radio::RadioConfig>,
}

/// `mark_walls`: deposits every `spacing_m` along every wall segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkWalls {
    pub channel: u32,
    #[serde(default = "default_wall_amount")]
    pub amount: f32,
    #[serde(default = "default_wall_spacing_m")]
    pub spacing_m: f32,
    /// Half-width of the mark's plateau (m).
    #[serde(default = "default_wall_plateau_m")]
    pub plateau_m: f32,
}

fn default_wall_amount() -> f32 {
    1.0
}
fn default_wall_spacing_m() -> f32 {
    0.1
}
fn default_wall_plateau_m() -> f32 {
    0.1
}

/// A probe: the value of `channel` at (x, y) at each of `times_s`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProbeSpec {
    pub x_m: f32,
    pub y_m: f32,
    #[serde(default)]
    pub channel: u32,
    pub times_s: Vec<f64>,
}

/// Scenario-specific metrics (`[metrics]`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MetricsConfig {
    /// Seed 002: mean distance between a robot and a target path (`[[metrics.paths]]`).
    pub paths: Vec<PathMetric>,
    /// Seed 004: share of the map's sectors each robot visited.
    pub exploration: Option<ExplorationMetric>,
    /// Seed 000: where the follower of a leader that got lost ends up.
    pub blind_leader: Option<BlindLeaderMetric>,
    /// Seed 000 Figs. 1 and 24: whether the followers of a lost leader end in the wrong area A
    /// or reach B, where the leader truly is.
    pub wrong_area: Option<WrongAreaMetric>,
}

/// `mean_path_error_m`: the distance from `robot`'s true position to the polyline `points`,
/// sampled every `every_s` over [`from_s`, `from_s + over_s`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PathMetric {
    /// Name of the path in the metrics (`mean_path_error_m.<name>`).
    pub name: String,
    #[serde(default)]
    pub robot: u32,
    pub points: Vec<[f64; 2]>,
    #[serde(default = "default_every_s")]
    pub every_s: f64,
    #[serde(default)]
    pub from_s: f64,
    pub over_s: f64,
}

fn default_every_s() -> f64 {
    0.2
}

/// `exploration`: the rectangle split into `cols` × `rows` sectors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExplorationMetric {
    pub min_m: [f64; 2],
    pub max_m: [f64; 2],
    pub cols: u32,
    pub rows: u32,
}

impl ExplorationMetric {
    /// The sector a point falls in (row-major from `min_m`), if it is inside the map.
    pub fn sector_index(&self, x: f64, y: f64) -> Option<usize> {
        let fx = (x - self.min_m[0]) / (self.max_m[0] - self.min_m[0]);
        let fy = (y - self.min_m[1]) / (self.max_m[1] - self.min_m[1]);
        if !(0.0..1.0).contains(&fx) || !(0.0..1.0).contains(&fy) {
            return None;
        }
        Some(
            (fy * self.rows as f64) as usize * self.cols as usize
                + (fx * self.cols as f64) as usize,
        )
    }
}

/// `blind_leader`: the leader's and the follower's ids.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlindLeaderMetric {
    pub leader: u32,
    pub follower: u32,
}

/// `wrong_area`: the leader, the followers (in chain order), area A (the rectangle where the lost
/// leader believes it is) and location B (where it truly goes, reached within `b_radius_m`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WrongAreaMetric {
    pub leader: u32,
    pub followers: Vec<u32>,
    /// Area A: corners [x, y] (m), min and max.
    pub a_min_m: [f64; 2],
    pub a_max_m: [f64; 2],
    /// Location B [x, y] (m) and the radius within which a robot has reached it.
    pub b_m: [f64; 2],
    pub b_radius_m: f64,
    /// Without a loss script, the leader counts as lost from the first step its own filter's σ
    /// (√ of the largest eigenvalue of Σxy) reaches this (m; default 1.5: the 1σ ellipse is
    /// wider than a 3 m corridor, seed 000 Fig. 22).
    #[serde(default = "default_lost_sigma_m")]
    pub lost_sigma_m: f64,
}

fn default_lost_sigma_m() -> f64 {
    1.5
}

impl WrongAreaMetric {
    /// Distance from `p` to area A (m, 0 inside or on its edge).
    pub fn distance_to_a_m(&self, p: [f64; 2]) -> f64 {
        let d = |v: f64, lo: f64, hi: f64| (lo - v).max(v - hi).max(0.0);
        d(p[0], self.a_min_m[0], self.a_max_m[0]).hypot(d(p[1], self.a_min_m[1], self.a_max_m[1]))
    }

    pub fn in_a(&self, p: [f64; 2]) -> bool {
        self.distance_to_a_m(p) == 0.0
    }

    pub fn in_b(&self, p: [f64; 2]) -> bool {
        (p[0] - self.b_m[0]).hypot(p[1] - self.b_m[1]) <= self.b_radius_m
    }

    fn validate(&self) -> Result<(), ScenarioError> {
        let bad = |reason: String| ScenarioError::Metric {
            metric: "metrics.wrong_area".into(),
            reason,
        };
        let (lo, hi) = (self.a_min_m, self.a_max_m);
        if !(lo.iter().chain(&hi).all(|v| v.is_finite()) && lo[0] < hi[0] && lo[1] < hi[1]) {
            return Err(bad(format!(
                "a_min_m = {lo:?}, a_max_m = {hi:?} is not a rectangle (finite, min < max)"
            )));
        }
        if !(self.b_m.iter().all(|v| v.is_finite())
            && self.b_radius_m.is_finite()
            && self.b_radius_m > 0.0)
        {
            return Err(bad(format!(
                "b_m = {:?}, b_radius_m = {} must be finite with a radius > 0",
                self.b_m, self.b_radius_m
            )));
        }
        if self.followers.is_empty() {
            return Err(bad("followers = [] names no follower".into()));
        }
        Ok(())
    }
}

/// Changes `pheromone sim` makes to a scenario from its flags.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overrides {
    pub seed: Option<u64>,
    pub robots: Option<usize>,
    pub duration_s: Option<f64>,
    /// Every follower that is not a `route` leader uses this strategy.
    pub strategy: Option<StrategyKind>,
    /// Every depositor deposits with `constant` strength (seed 000's baseline).
    pub constant: bool,
    /// A ROS map_server map (`map.yaml`) whose walls replace the scenario's; the field and the
    /// exploration sectors are fitted to it (`scenario/map.rs`).
    pub map: Option<std::path::PathBuf>,
    /// `--merge` (true) / `--no-merge` (false): turn seed 004's mapping on, with or without
    /// exchanges at rendezvous (`scenario/mapping.rs`).
    pub merge: Option<bool>,
    /// `--rc-m R`: the communication radius R_C (m) of the exchanges.
    pub rc_m: Option<f64>,
    /// `--filter`: every robot's localizer runs this filter; `pf` turns the world's laser on
    /// (seed 000 Table 1) when the scenario has none.
    pub filter: Option<FilterKind>,
    /// `--particles N`: every robot's particle count (`pf.particles`).
    pub particles: Option<usize>,
    /// `--no-scripted-loss`: every localizer's loss script (`localizer.loss.after_s`) is off.
    pub no_scripted_loss: bool,
    /// `--scripted-loss`: the scenario's `[scripted_loss]` replaces its leader's own loss.
    pub scripted_loss: bool,
    /// `--steer own-map|shared`: what the sector followers steer on (`[mapping] steer_on`).
    pub steer_on: Option<pheromone_roles::mapper::SteerOn>,
    /// `--clients N`: N thin clients share the air (`[radio]`, its defaults if the scenario
    /// has none).
    pub clients: Option<u32>,
}

/// What runs for one robot: a localizer always, a depositor and a follower if configured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotRoles {
    pub id: u32,
    #[serde(default)]
    pub localizer: EkfConfig,
    /// The localizer's filter (`ekf`, `ukf`, `pf`); its noise, limits and gate are
    /// `localizer`'s. `pf` needs the world's laser (`[world.laser]`).
    #[serde(default)]
    pub filter: FilterKind,
    /// The UKF's scaling parameters (`filter = "ukf"`).
    #[serde(default)]
    pub ukf: UkfConfig,
    /// The particle filter's settings (`filter = "pf"`).
    #[serde(default)]
    pub pf: PfConfig,
    /// Standard deviation of the localizer's initial position estimate (m).
    #[serde(default = "default_initial_sigma_m")]
    pub initial_sigma_m: f64,
    #[serde(default)]
    pub depositor: Option<DepositorConfig>,
    #[serde(default)]
    pub follower: Option<FollowerConfig>,
}

fn default_initial_sigma_m() -> f64 {
    0.05
}

/// A deposit made by the world at time `t_s`; with `to_x_m`/`to_y_m`/`spacing_m` it is a line of
/// deposits every `spacing_m` from (x, y) to (to_x, to_y).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptedDeposit {
    #[serde(default)]
    pub t_s: f64,
    #[serde(default = "default_kernel")]
    pub kernel: String,
    #[serde(default)]
    pub channel: u32,
    pub x_m: f32,
    pub y_m: f32,
    #[serde(default)]
    pub to_x_m: Option<f32>,
    #[serde(default)]
    pub to_y_m: Option<f32>,
    #[serde(default)]
    pub spacing_m: Option<f32>,
    pub amount: f32,
    #[serde(default = "default_cov")]
    pub cov: [f32; 3],
    #[serde(default = "default_range_m")]
    pub range_m: f32,
    #[serde(default = "default_gamma_max")]
    pub gamma_max: f32,
    #[serde(default = "default_sigma_m")]
    pub sigma_m: f32,
    #[serde(default)]
    pub plateau_m: f32,
    #[serde(default)]
    pub slope_m: f32,
}

fn default_kernel() -> String {
    "ellipse".into()
}
fn default_cov() -> [f32; 3] {
    [0.01, 0.0, 0.01]
}
fn default_range_m() -> f32 {
    1.0
}
fn default_gamma_max() -> f32 {
    100.0
}
fn default_sigma_m() -> f32 {
    0.1
}

impl ScriptedDeposit {
    /// The deposit messages this entry stands for.
    pub fn messages(&self) -> Result<Vec<DepositMsg>, DepositError> {
        let kernel = self
            .kernel
            .parse::<KernelKind>()
            .map_err(|e| DepositError::Kernel(e.into()))?;
        let params = pheromone_field::KernelParams {
            cov_m2: self.cov,
            range_m: self.range_m,
            gamma_max: self.gamma_max,
            sigma_m: self.sigma_m,
            plateau_m: self.plateau_m,
            slope_m: self.slope_m,
        };
        let one = |x_m: f32, y_m: f32| {
            DepositMsg::from(pheromone_field::Deposit {
                channel: self.channel,
                x_m,
                y_m,
                kernel: pheromone_field::Kernel::from_params(kernel, self.amount, &params),
            })
        };
        match (self.to_x_m, self.to_y_m, self.spacing_m) {
            (None, None, None) => Ok(vec![one(self.x_m, self.y_m)]),
            (Some(tx), Some(ty), Some(sp)) => {
                if !(sp.is_finite() && sp > 0.0) {
                    return Err(DepositError::Spacing { spacing_m: sp });
                }
                let len = ((tx - self.x_m).powi(2) + (ty - self.y_m).powi(2)).sqrt();
                let n = (len / sp).floor() as usize;
                if n > 1_000_000 {
                    return Err(DepositError::TooLong { n, spacing_m: sp });
                }
                Ok((0..=n)
                    .map(|i| {
                        let f = if len > 0.0 { i as f32 * sp / len } else { 0.0 };
                        one(
                            self.x_m + f * (tx - self.x_m),
                            self.y_m + f * (ty - self.y_m),
                        )
                    })
                    .collect())
            }
            _ => Err(DepositError::IncompleteLine),
        }
    }
}

impl Scenario {
    /// Loads a built-in scenario by name, or a TOML file by path.
    pub fn load(name_or_path: &str) -> Result<Self, ScenarioError> {
        let path = Path::new(name_or_path);
        if path.is_file() {
            let text = pheromone_field::infile::read_text_bounded(
                path,
                pheromone_field::infile::MAX_TEXT_BYTES,
            )
            .map_err(|source| ScenarioError::Read {
                origin: path.display().to_string(),
                source,
            })?;
            let dir = path.parent().unwrap_or_else(|| Path::new("."));
            return Self::parse_in(&text, &path.display().to_string(), dir);
        }
        match BUILTIN.iter().find(|(n, _)| *n == name_or_path) {
            Some((n, text)) => Self::parse(text, &format!("built-in scenario '{n}'")),
            None => Err(ScenarioError::Unknown(name_or_path.to_string())),
        }
    }

    /// Parses and validates; `origin` names the source in errors. A relative `[world] map` is
    /// relative to the current directory.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ScenarioError> {
        Self::parse_in(text, origin, Path::new("."))
    }

    /// Parses, loads `[world] map` (relative to `base_dir`) and validates.
    pub fn parse_in(text: &str, origin: &str, base_dir: &Path) -> Result<Self, ScenarioError> {
        let mut s: Scenario = toml::from_str(text).map_err(|e| ScenarioError::Parse {
            origin: origin.to_string(),
            source: Box::new(e),
        })?;
        // It parsed as a scenario, so it parses as a table.
        let table: toml::Table = toml::from_str(text).unwrap_or_default();
        // `[radio]` without `clients`: one client per robot through the gateway.
        let antenna_robots = s.antenna_robots().len().max(1) as u32;
        if let Some(r) = &mut s.radio {
            let radio = table.get("radio").and_then(|t| t.as_table());
            if !radio.is_some_and(|t| t.contains_key("clients")) {
                r.clients = antenna_robots;
            }
        }
        check_numbers(&table, "")
            .and_then(|()| s.load_world_map(base_dir))
            .and_then(|()| s.place_random_starts())
            .and_then(|()| s.validate())
            .map_err(|e| ScenarioError::Invalid {
                origin: origin.to_string(),
                source: Box::new(e),
            })?;
        Ok(s)
    }

    /// Applies `pheromone sim`'s flags and re-validates. Keeps only the active robots.
    pub fn apply(&mut self, o: &Overrides) -> Result<(), ScenarioError> {
        if let Some(map) = &o.map {
            self.use_map(map)?;
        }
        if let Some(seed) = o.seed {
            self.seed = seed;
            self.place_random_starts()?;
        }
        if let Some(d) = o.duration_s {
            if !(d.is_finite() && d > 0.0) {
                return Err(ScenarioError::Flag {
                    flag: "--duration",
                    value: d.to_string(),
                    reason: "must be > 0",
                });
            }
            self.duration_s = d;
        }
        self.apply_mapping(o)?;
        if let Some(n) = o.robots {
            if n == 0 || n > self.world.robots.len() {
                return Err(ScenarioError::Robots {
                    n,
                    scenario: self.name.clone(),
                    robots: self.world.robots.len(),
                });
            }
            self.active_robots = Some(n);
        }
        if let Some(n) = self.active_robots.take() {
            self.world.robots.truncate(n);
            let ids: Vec<u32> = self.world.robots.iter().map(|r| r.id).collect();
            self.robots.retain(|r| ids.contains(&r.id));
        }
        for r in &mut self.robots {
            if let Some(f) = &mut r.follower {
                if let Some(k) = o.strategy {
                    if f.strategy != StrategyKind::Route {
                        f.strategy = k;
                    }
                }
            }
            if o.constant {
                if let Some(d) = &mut r.depositor {
                    d.mode = DepositMode::Constant;
                }
            }
        }
        if o.scripted_loss {
            self.apply_scripted_loss()?;
        }
        if let Some(n) = o.clients {
            self.radio.get_or_insert_with(Default::default).clients = n;
        }
        self.apply_localizers(o);
        self.validate()
    }

    /// `--filter`, `--particles` and `--no-scripted-loss` on every robot's localizer.
    fn apply_localizers(&mut self, o: &Overrides) {
        for r in &mut self.robots {
            if let Some(k) = o.filter {
                r.filter = k;
            }
            if let Some(n) = o.particles {
                r.pf.particles = n;
            }
            if o.no_scripted_loss {
                r.localizer.loss.after_s = None;
            }
        }
        if o.filter == Some(FilterKind::Pf) && self.world.laser.is_none() {
            self.world.laser = Some(crate::LaserConfig::default());
        }
    }

    /// The follower settings of a robot, its RNG seed mixed with the scenario's seed so that
    /// every seed of a run gives other random draws.
    pub fn follower_config(&self, robot: u32) -> Option<FollowerConfig> {
        let mut f = self.roles(robot)?.follower.clone()?;
        f.seed = f
            .seed
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(self.seed.rotate_left(17))
            .wrapping_add(robot as u64);
        self.steer_on_own_map(&mut f);
        f.antenna.sources = self
            .field
            .channels
            .get(f.channel as usize)
            .and_then(|c| c.sources);
        Some(f)
    }

    /// Every scripted deposit (walls first, at t = 0), sorted by time.
    pub fn scripted(
        &self,
        walls: &[crate::Segment],
    ) -> Result<Vec<(f64, DepositMsg)>, ScenarioError> {
        let mut out = Vec::new();
        if let Some(m) = &self.mark_walls {
            for w in walls {
                let d = ScriptedDeposit {
                    t_s: 0.0,
                    kernel: "z-shape".into(),
                    channel: m.channel,
                    x_m: w.a_m[0] as f32,
                    y_m: w.a_m[1] as f32,
                    to_x_m: Some(w.b_m[0] as f32),
                    to_y_m: Some(w.b_m[1] as f32),
                    spacing_m: Some(m.spacing_m),
                    amount: m.amount,
                    cov: default_cov(),
                    range_m: default_range_m(),
                    gamma_max: default_gamma_max(),
                    sigma_m: default_sigma_m(),
                    plateau_m: m.plateau_m,
                    slope_m: 0.0,
                };
                let msgs = d.messages().map_err(ScenarioError::WallMark)?;
                out.extend(msgs.into_iter().map(|m| (0.0, m)));
            }
        }
        for (i, d) in self.deposits.iter().enumerate() {
            let msgs = d.messages().map_err(|source| ScenarioError::Deposit {
                index: i + 1,
                source,
            })?;
            out.extend(msgs.into_iter().map(|m| (d.t_s, m)));
        }
        out.sort_by(|a, b| a.0.total_cmp(&b.0));
        // The world sends them: its id orders them in a tick, in both modes.
        for (_, m) in &mut out {
            m.robot_id = WORLD_DEPOSITOR_ID;
        }
        Ok(out)
    }

    /// The field configuration of a run of this scenario as processes: the scenario's, with
    /// the limits that are only defaults raised to fit the run, so no process is refused and no
    /// deposit is dropped. Readers: every follower, the observer and two spare. Deposit queue:
    /// the largest number of deposits one step can bring (the scripted ones due at that step,
    /// one per depositor) and 64 spare.
    pub fn field_config_for_processes(&self) -> Result<FieldConfig, ScenarioError> {
        let mut c = self.field.clone();
        let followers = self.robots.iter().filter(|r| r.follower.is_some()).count();
        let depositors = self.robots.iter().filter(|r| r.depositor.is_some()).count();
        c.max_readers = c.max_readers.max(followers + 3);
        c.max_depositors = c.max_depositors.max(depositors + 2);
        let world =
            crate::World::new(self.world.clone(), self.seed).map_err(ScenarioError::World)?;
        let dt = self.world.dt_s;
        let mut per_step = std::collections::BTreeMap::<u64, usize>::new();
        for (t, _) in self.scripted(world.wall_segments())? {
            // The world sends a deposit of time t at the first step whose end reaches it.
            let step = ((t - 1e-9) / dt).ceil().max(1.0) as u64 - 1;
            *per_step.entry(step).or_default() += 1;
        }
        let burst = per_step.values().copied().max().unwrap_or(0);
        c.deposit_buffer = c.deposit_buffer.max(burst + depositors + 64);
        c.validate().map_err(ScenarioError::FieldLimits)?;
        Ok(c)
    }

    /// Every probe reading to take, as (time, index into `probes`), sorted by time.
    pub fn probe_schedule(&self) -> Vec<(f64, usize)> {
        let mut probes: Vec<(f64, usize)> = self
            .probes
            .iter()
            .enumerate()
            .flat_map(|(i, p)| p.times_s.iter().map(move |t| (*t, i)))
            .collect();
        probes.sort_by(|a, b| a.0.total_cmp(&b.0));
        probes
    }

    /// The scenario as TOML (what `--print-config`-style dumps and sub-processes read).
    pub fn to_toml(&self) -> Result<String, ScenarioError> {
        toml::to_string(self).map_err(ScenarioError::Serialize)
    }

    /// Number of world steps the run lasts.
    pub fn steps(&self) -> u64 {
        (self.duration_s / self.world.dt_s).round() as u64
    }

    pub fn roles(&self, robot_id: u32) -> Option<&RobotRoles> {
        self.robots.iter().find(|r| r.id == robot_id)
    }
}

/// The largest magnitude a number in a scenario may have: beyond it a value is a mistake
/// (`1e300` metres, seconds, amounts), as for the command line's numbers.
pub const MAX_SCENARIO_MAGNITUDE: f64 = 1e9;

/// Every float of a scenario file is finite and at most [`MAX_SCENARIO_MAGNITUDE`] in size (TOML
/// allows `nan` and `inf`): the error names the key (`robots[1].start.x_m`) and the value.
fn check_numbers(table: &toml::Table, prefix: &str) -> Result<(), ScenarioError> {
    for (key, value) in table {
        let path = if prefix.is_empty() {
            key.clone()
        } else {
            format!("{prefix}.{key}")
        };
        check_value(value, &path)?;
    }
    Ok(())
}

fn check_value(value: &toml::Value, path: &str) -> Result<(), ScenarioError> {
    match value {
        toml::Value::Float(x) if !x.is_finite() => {
            Err(ScenarioError::value(path, x, "must be a finite number"))
        }
        toml::Value::Float(x) if x.abs() > MAX_SCENARIO_MAGNITUDE => Err(ScenarioError::value(
            path,
            format!("{x:e}"),
            "must be at most 1e9 in size",
        )),
        toml::Value::Table(t) => check_numbers(t, path),
        toml::Value::Array(items) => items
            .iter()
            .enumerate()
            .try_for_each(|(i, v)| check_value(v, &format!("{path}[{i}]"))),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests;
