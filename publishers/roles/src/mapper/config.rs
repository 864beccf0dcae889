//! `[mapping]` of a scenario (seed 004's local maps and their merging, MODELS.md M4): the range
//! sensor, the local map, the rendezvous exchange and the `exploration_known` metric. Off by
//! default; `pheromone sim --merge` / `--no-merge` turn it on (with / without exchanges).

use serde::{Deserialize, Serialize};

use pheromone_messages::MAX_RAYS;

/// Seed 004's mapping settings. Every length in metres, every angle in radians; one
/// *iteration* is `iteration_s` of simulated time (one decision of the sector strategy).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MappingConfig {
    /// Range scans, local maps and `exploration_known` are computed.
    pub enabled: bool,
    /// Robots within `rc_m` exchange and merge their maps (integration); false: each robot
    /// knows only what it mapped itself (the paper's "integration inactive").
    pub merge: bool,
    /// R_D: the range sensor's maximum range.
    pub range_max_m: f64,
    /// Rays of one scan, spread evenly over the field of view [−90°, 90°] (≤ `MAX_RAYS`).
    pub rays: u32,
    /// Standard deviation of the Gaussian range noise.
    pub range_sigma_m: f64,
    /// R_C: the communication radius (true distance between two robots).
    pub rc_m: f64,
    /// Noise of the relative-pose measurement the world provides at a rendezvous.
    pub relpose_range_sigma_m: f64,
    pub relpose_bearing_sigma_rad: f64,
    pub relpose_heading_sigma_rad: f64,
    /// Simulated time of one iteration.
    pub iteration_s: f64,
    /// Exchanges start after this iteration (Algorithm 1's it_begin_threshold).
    pub start_iteration: u64,
    /// The same pair exchanges at most every this many iterations (Algorithm 1's it_interval).
    pub every_iterations: u64,
    /// A sector is known when this share of its free cells is mapped.
    pub known_share: f64,
    /// A map cell is mapped when |log-odds| ≥ this.
    pub known_logodds: f32,
    /// A robot whose det Σxy (m⁴) exceeds this is lost: it neither offers nor accepts maps.
    pub loss_det_m4: f64,
    /// Side of a local map cell.
    pub cell_size_m: f32,
    /// Side of the square local map, centred on the robot's start pose.
    pub extent_m: f32,
    /// Log-odds added to a cell a ray passes through (negative: free).
    pub logodds_free: f32,
    /// Log-odds added to the cell a ray ends in when it hit a wall.
    pub logodds_occupied: f32,
    /// Log-odds are clamped to ±this.
    pub logodds_max: f32,
    /// What the sector strategies (`inverse`, `uniform`) steer on: the shared field (every
    /// robot's deposits, at any range) or each robot's own (merged) map, seed 004's setting.
    pub steer_on: SteerOn,
    /// How a merge combines two maps.
    pub merge_rule: MergeRule,
    /// The cost of an integration (seed 004's ablation): a robot that merged a peer's map
    /// stands still for this many iterations, from the step of the merge (0: merging is free).
    /// Single-process runs only (`pheromone sweep`, `sim --single-process`).
    pub merge_idle_iterations: u32,
}

/// `[mapping] steer_on` / `pheromone sim --steer`: the map a sector strategy reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SteerOn {
    /// The shared field: τ_s from every robot's deposits, walls from the scenario's wall channel.
    #[default]
    Shared,
    /// The robot's own local map (seed 004, Algorithm 2): τ_s from its pheromone plane (its
    /// own deposits and what it merged), walls from its occupancy grid, at its estimate in its
    /// own frame.
    OwnMap,
}

impl SteerOn {
    pub fn name(self) -> &'static str {
        match self {
            SteerOn::Shared => "shared",
            SteerOn::OwnMap => "own-map",
        }
    }
}

impl std::str::FromStr for SteerOn {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "shared" => Ok(SteerOn::Shared),
            "own-map" => Ok(SteerOn::OwnMap),
            _ => Err(format!("'{s}': expected own-map or shared")),
        }
    }
}

/// `[mapping] merge_rule`: how the cells of two maps combine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MergeRule {
    /// Seed 004: every cell of the overlap is averaged, occupancy as probabilities (an unknown
    /// cell is p = 0.5) and pheromone as levels.
    #[default]
    Average,
    /// A cell unknown in one map (log-odds 0) takes the other's occupancy and pheromone; a cell
    /// known in both averages both, occupancy in log-odds.
    AdoptUnknown,
    /// Seed 004's ablation, the maximum instead of the mean: a cell unknown in one map (log-odds
    /// 0) takes the other's occupancy, a cell known in both the larger log-odds (an obstacle
    /// wins); pheromone the larger level.
    Max,
}

impl MergeRule {
    pub fn name(self) -> &'static str {
        match self {
            MergeRule::Average => "average",
            MergeRule::AdoptUnknown => "adopt-unknown",
            MergeRule::Max => "max",
        }
    }
}

impl std::str::FromStr for MergeRule {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "average" => Ok(MergeRule::Average),
            "adopt-unknown" => Ok(MergeRule::AdoptUnknown),
            "max" => Ok(MergeRule::Max),
            _ => Err(format!("'{s}': expected average, adopt-unknown or max")),
        }
    }
}

impl Default for MappingConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            merge: true,
            range_max_m: 4.0,
            rays: 37,
            range_sigma_m: 0.02,
            rc_m: 8.0,
            relpose_range_sigma_m: 0.05,
            relpose_bearing_sigma_rad: 0.02,
            relpose_heading_sigma_rad: 0.02,
            iteration_s: 1.0,
            start_iteration: 100,
            every_iterations: 50,
            known_share: 0.5,
            known_logodds: 0.4,
            loss_det_m4: 0.01,
            cell_size_m: 0.2,
            extent_m: 72.0,
            logodds_free: -0.4,
            logodds_occupied: 0.85,
            logodds_max: 4.0,
            steer_on: SteerOn::Shared,
            merge_rule: MergeRule::Average,
            merge_idle_iterations: 0,
        }
    }
}

/// A `[mapping]` value out of range: names the key and the value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("mapping.{key} = {value} is invalid ({expected})")]
pub struct MappingConfigError {
    pub key: &'static str,
    pub value: f64,
    pub expected: &'static str,
}

impl MappingConfig {
    /// Checks every value; the error names the key and the value.
    pub fn validate(&self) -> Result<(), MappingConfigError> {
        let bad = |key, value: f64, expected| MappingConfigError {
            key,
            value,
            expected,
        };
        for (key, v) in [
            ("range_max_m", self.range_max_m),
            ("rc_m", self.rc_m),
            ("iteration_s", self.iteration_s),
            ("loss_det_m4", self.loss_det_m4),
            ("cell_size_m", self.cell_size_m as f64),
            ("extent_m", self.extent_m as f64),
            ("logodds_occupied", self.logodds_occupied as f64),
            ("logodds_max", self.logodds_max as f64),
            ("known_logodds", self.known_logodds as f64),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(key, v, "finite and > 0"));
            }
        }
        for (key, v) in [
            ("range_sigma_m", self.range_sigma_m),
            ("relpose_range_sigma_m", self.relpose_range_sigma_m),
            ("relpose_bearing_sigma_rad", self.relpose_bearing_sigma_rad),
            ("relpose_heading_sigma_rad", self.relpose_heading_sigma_rad),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(key, v, "finite and ≥ 0"));
            }
        }
        if !(self.logodds_free.is_finite() && self.logodds_free < 0.0) {
            return Err(bad(
                "logodds_free",
                self.logodds_free as f64,
                "finite and < 0",
            ));
        }
        if !(self.known_share.is_finite() && self.known_share > 0.0 && self.known_share <= 1.0) {
            return Err(bad("known_share", self.known_share, "in (0, 1]"));
        }
        if self.rays < 2 || self.rays as usize > MAX_RAYS {
            return Err(bad("rays", self.rays as f64, "between 2 and MAX_RAYS = 64"));
        }
        if self.every_iterations == 0 {
            return Err(bad("every_iterations", 0.0, "≥ 1"));
        }
        let side = (self.extent_m / self.cell_size_m).round();
        if !(2.0..=4096.0).contains(&side) {
            return Err(bad(
                "extent_m",
                self.extent_m as f64,
                "extent_m / cell_size_m must be between 2 and 4096 cells",
            ));
        }
        Ok(())
    }

    /// Cells of a side of the local map.
    pub fn side_cells(&self) -> u32 {
        (self.extent_m / self.cell_size_m).round() as u32
    }

    /// World steps a robot stands still after a merge (`merge_idle_iterations` iterations).
    pub fn idle_steps_per_merge(&self, dt_s: f64) -> u64 {
        self.merge_idle_iterations as u64 * self.steps_per_iteration(dt_s)
    }

    /// World steps in one iteration (at least 1).
    pub fn steps_per_iteration(&self, dt_s: f64) -> u64 {
        ((self.iteration_s / dt_s).round() as u64).max(1)
    }
}
