//! Why a scenario is refused: loading it (the file, its TOML), the cross-checks of
//! `Scenario::validate`, the flags `Scenario::apply` takes, and the scripted deposits. Each
//! variant names the setting and the value; the error it stems from is its source.

use pheromone_field::ConfigError;

use crate::{MapError, WorldError};
use pheromone_roles::depositor::DepositorConfigError;
use pheromone_roles::follower::FollowerConfigError;
use pheromone_roles::localizer::LocalizerError;

/// Why a scenario could not be loaded, validated or changed.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("{origin}: cannot read: {source}")]
    Read {
        origin: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{origin}: {source}")]
    Parse {
        origin: String,
        #[source]
        source: Box<toml::de::Error>,
    },
    /// A scenario that parsed but does not pass `Scenario::validate`; `origin` names the file or
    /// built-in.
    #[error("{origin}: {source}")]
    Invalid {
        origin: String,
        #[source]
        source: Box<ScenarioError>,
    },
    #[error("unknown scenario '{0}': not a file, and not a built-in ({builtins})", builtins = super::builtin_names())]
    Unknown(String),
    /// `[mapping]` is refused.
    #[error("{0}")]
    Mapping(#[source] pheromone_roles::mapper::MappingConfigError),
    /// `[field]` is refused.
    #[error("field: {0}")]
    Field(#[source] ConfigError),
    /// The field configuration of a run as processes (the scenario's, limits raised) is refused.
    #[error("{0}")]
    FieldLimits(#[source] ConfigError),
    /// The world (`[world]`) cannot be built.
    #[error("{0}")]
    World(#[source] WorldError),
    /// A value out of range: `{key} = {value}: {reason}`.
    #[error("{key} = {value}: {reason}")]
    Value {
        key: String,
        value: String,
        reason: &'static str,
    },
    /// A flag of `pheromone sim` out of range: `{flag} {value}: {reason}`.
    #[error("{flag} {value}: {reason}")]
    Flag {
        flag: &'static str,
        value: String,
        reason: &'static str,
    },
    /// A list of times with one out of range: `{key} has {value}: must be ≥ 0`.
    #[error("{key} has {value}: must be ≥ 0")]
    NegativeTime { key: String, value: f64 },
    #[error(
        "field.tick_hz = {tick_hz} gives dt = {field_dt} s but world.dt_s = {world_dt}: in lockstep the field ticks once per world step"
    )]
    ClockMismatch {
        tick_hz: f32,
        field_dt: f64,
        world_dt: f64,
    },
    #[error("robot id = {robot}: no [[world.robots]] entry with that id")]
    NoWorldRobot { robot: u32 },
    #[error("robot id = {robot}: more than one [[robots]] entry with that id")]
    DuplicateRobot { robot: u32 },
    #[error(
        "robot {robot}: its start ({x_m}, {y_m}) m lies outside the field, which spans \
         x {x0_m}..{x1_m} m, y {y0_m}..{y1_m} m"
    )]
    StartOutsideField {
        robot: u32,
        x_m: f64,
        y_m: f64,
        x0_m: f64,
        x1_m: f64,
        y0_m: f64,
        y1_m: f64,
    },
    #[error("robot {robot} localizer: {source}")]
    Localizer {
        robot: u32,
        #[source]
        source: LocalizerError,
    },
    #[error("robot {robot}: filter = \"pf\" needs the world's laser ([world.laser]; --filter pf turns it on)")]
    PfWithoutLaser { robot: u32 },
    #[error("robot {robot} depositor: {source}")]
    Depositor {
        robot: u32,
        #[source]
        source: DepositorConfigError,
    },
    #[error("robot {robot} follower: {source}")]
    Follower {
        robot: u32,
        #[source]
        source: FollowerConfigError,
    },
    /// Scripted deposit `index` (from 1) cannot be made.
    #[error("deposit {index}: {source}")]
    Deposit {
        index: usize,
        #[source]
        source: DepositError,
    },
    /// A scripted deposit from `mark_walls` cannot be made.
    #[error(transparent)]
    WallMark(DepositError),
    #[error("active_robots = {n}: the world has {robots} robot(s); choose 1 to {robots}")]
    ActiveRobots { n: usize, robots: usize },
    #[error("--robots {n}: scenario '{scenario}' places {robots} robot(s); choose 1 to {robots}")]
    Robots {
        n: usize,
        scenario: String,
        robots: usize,
    },
    /// A channel index beyond the field's channels: `{key} = {channel}: ...`.
    #[error("{key} = {channel}: the field has {channels} channel(s)")]
    Channel {
        key: String,
        channel: u32,
        channels: u32,
    },
    /// A metric (`[metrics]`) that cannot be computed: `{metric}: {reason}`.
    #[error("{metric}: {reason}")]
    Metric { metric: String, reason: String },
    #[error("{0}")]
    Serialize(#[source] toml::ser::Error),
    /// `[world] map` or `--map` cannot be loaded; the error names the file and the line (YAML)
    /// or byte (PGM).
    #[error("{key}: {source}")]
    Map {
        key: &'static str,
        #[source]
        source: MapError,
    },
}

/// Why a scripted deposit (`[[deposit]]`, `mark_walls`) cannot be turned into messages.
#[derive(Debug, thiserror::Error)]
pub enum DepositError {
    /// The kernel's name is not one the field knows.
    #[error("{0}")]
    Kernel(#[source] Box<dyn std::error::Error + Send + Sync>),
    #[error("spacing_m = {spacing_m}: must be > 0")]
    Spacing { spacing_m: f32 },
    #[error("a line of {n} deposits is too long (spacing_m = {spacing_m})")]
    TooLong { n: usize, spacing_m: f32 },
    #[error("a line needs all of to_x_m, to_y_m and spacing_m")]
    IncompleteLine,
    /// The field would refuse it (NaN, a covariance that is not positive definite, a channel
    /// the field lacks, outside the grid…).
    #[error("the field would refuse it: {0}")]
    Refused(#[source] pheromone_field::Rejection),
}

impl ScenarioError {
    /// A value out of range.
    pub(crate) fn value(
        key: impl Into<String>,
        value: impl std::fmt::Display,
        reason: &'static str,
    ) -> Self {
        Self::Value {
            key: key.into(),
            value: value.to_string(),
            reason,
        }
    }
}
