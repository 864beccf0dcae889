//! Seed 004's mapper (MODELS.md M4): each robot keeps a [`LocalMap`] — an occupancy grid
//! (log-odds) and a pheromone map in its own frame, origin = its start pose — from its pose
//! estimate and its range scans, and merges the maps of the robots it meets
//! ([`merge`], eqs. 7–10, Algorithm 1). [`Mapper`] is one robot's mapper, the same type in the
//! single-process runner and in `pheromone mapper`.
//!
//! - `config.rs` `[mapping]` ([`MappingConfig`]);
//! - `map.rs` [`LocalMap`]: scan integration, the robot's own deposits, frames;
//! - `merge.rs` the transform of eqs. 7–10 ([`MergeTransform`]) and the merge pass;
//!   `merge_simd.rs` its runs eight cells at a time (AVX2); `merge_logodds.rs` the `average`
//!   rule's mean of two log-odds, one cell and eight lanes at a time, and its error bound;
//! - `run.rs` the process loop (`pheromone mapper`): the map as a frame in shared memory, and
//!   the exchanges merged zero-copy from the peers' frames.

pub mod config;
pub mod map;
pub mod merge;
mod merge_logodds;
mod merge_simd;
#[cfg(test)]
mod tests;

use std::collections::BTreeMap;

pub use config::{MappingConfig, MappingConfigError, MergeRule, SteerOn};
pub use map::MapView;
pub use map::{pose_in_frame, pose_msg_in_frame, LocalMap, Pose2, MAP_CHANNELS};
pub use merge::{
    alignment_error_m, merge_planes, true_transform, MergeEvent, MergeStats, MergeTransform,
};

use crate::depositor::Depositor;
use pheromone_messages::{PeerObs, PoseMsg, ScanMsg};

/// Why a scan, a deposit or a map to merge was refused. Each names the value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapError {
    #[error("{0}")]
    Config(#[source] MappingConfigError),
    #[error("local map geometry: {0}")]
    Field(#[source] pheromone_field::ConfigError),
    #[error("map frame: header says {channels} channels of {width} × {height} cells, but the frame holds {len} cells")]
    Length {
        channels: u32,
        width: u32,
        height: u32,
        len: usize,
    },
    #[error("map frame: {channel} cell {index} is {value}")]
    NonFiniteCell {
        channel: &'static str,
        index: usize,
        value: f32,
    },
    #[error("merge transform: {name} = {value} is absurd (limit {limit_m} m)")]
    Transform {
        name: &'static str,
        value: f64,
        limit_m: f64,
    },
    #[error("scan: pose {pose:?} is not finite")]
    NonFinitePose { pose: Pose2 },
    #[error("scan: ray {ray} has bearing {bearing_rad} rad, range {range_m} m")]
    BadRay {
        ray: usize,
        bearing_rad: f32,
        range_m: f32,
    },
    #[error("deposit refused by the local pheromone map: {0}")]
    Deposit(&'static str),
}

impl MapError {
    /// Short name of the reason, for counters.
    pub fn name(&self) -> &'static str {
        match self {
            MapError::Config(_) | MapError::Field(_) => "config",
            MapError::Length { .. } => "length",
            MapError::NonFiniteCell { .. } => "non_finite_cell",
            MapError::Transform { .. } => "transform",
            MapError::NonFinitePose { .. } => "non_finite_pose",
            MapError::BadRay { .. } => "bad_ray",
            MapError::Deposit(_) => "deposit",
        }
    }
}

/// det Σxy of an estimate (m⁴).
fn det_xy(pose: &PoseMsg) -> f64 {
    let [xx, xy, yy] = pose.cov_xy();
    xx * yy - xy * xy
}

/// What a mapper counted.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct MapperCounters {
    pub scans: u64,
    pub merges: u64,
    /// Maps refused, by reason ([`MapError::name`]).
    pub merges_rejected: BTreeMap<String, u64>,
    /// Exchanges not made because this robot or its peer was lost.
    pub refused_lost: u64,
}

/// One robot's mapper: its local map and what it needs to exchange it.
#[derive(Debug, Clone)]
pub struct Mapper {
    pub id: u32,
    config: MappingConfig,
    /// The robot's start pose in the world: the origin of its map's frame Σ, and of its
    /// estimate's frame (the localizer starts from it).
    start: Pose2,
    pub map: LocalMap,
    /// The latest estimate, in Σ, and its det Σxy.
    pose: Option<(Pose2, f64)>,
    /// The last iteration this robot exchanged with each peer.
    last_exchange: BTreeMap<u32, u64>,
    steps_per_iteration: u64,
    /// A copy of the robot's depositor fed the same poses: the robot's own deposits.
    depositor: Option<Depositor>,
    pub counters: MapperCounters,
}

impl Mapper {
    /// `channel`: the field channel the robot deposits on (its evaporation model), `dt_s` the
    /// world step (= the field's tick).
    pub fn new(
        id: u32,
        config: &MappingConfig,
        start: Pose2,
        channel: &pheromone_field::ChannelSpec,
        dt_s: f64,
        depositor: Option<Depositor>,
    ) -> Result<Self, MapError> {
        Ok(Self {
            id,
            map: LocalMap::new(config, channel, dt_s)?,
            config: config.clone(),
            start,
            pose: None,
            last_exchange: BTreeMap::new(),
            steps_per_iteration: config.steps_per_iteration(dt_s),
            depositor,
            counters: MapperCounters::default(),
        })
    }

    pub fn start(&self) -> Pose2 {
        self.start
    }

    /// The latest estimate in the map's frame.
    pub fn pose(&self) -> Option<Pose2> {
        self.pose.map(|p| p.0)
    }

    /// Lost: det Σxy beyond `loss_det_m4` (or no estimate yet, or a non-finite one).
    pub fn lost(&self) -> bool {
        self.pose.is_none_or(|(_, det)| self.lost_det(det))
    }

    /// Whether an estimate (this robot's or a peer's, as received) is lost by this mapper's
    /// threshold: the test [`Mapper::lost`] applies, for the peers of the mapper process.
    pub fn lost_estimate(&self, pose: &PoseMsg) -> bool {
        self.lost_det(det_xy(pose))
    }

    fn lost_det(&self, det_m4: f64) -> bool {
        !(det_m4.is_finite() && det_m4 <= self.config.loss_det_m4)
    }

    /// The iteration world step `step` belongs to.
    pub fn iteration(&self, step: u64) -> u64 {
        step / self.steps_per_iteration
    }

    /// Whether `step` is one where Algorithm 1 runs: an iteration boundary after
    /// `start_iteration`.
    pub fn exchange_step(&self, step: u64) -> bool {
        step.is_multiple_of(self.steps_per_iteration)
            && self.iteration(step) > self.config.start_iteration
    }

    /// Whether this robot would exchange with `peer` at `step` (the pair's interval elapsed;
    /// losses are checked by the caller on both robots).
    pub fn due(&self, peer: u32, step: u64) -> bool {
        self.config.merge
            && self.exchange_step(step)
            && self
                .last_exchange
                .get(&peer)
                .is_none_or(|last| self.iteration(step) >= last + self.config.every_iterations)
    }

    /// One world step: the estimate (world frame) moves into Σ, the robot's deposit of this pose
    /// (if its depositor makes one) goes to the pheromone map, the scan is integrated, and on
    /// an iteration boundary the pheromone map steps. A refused scan is counted in the map.
    pub fn on_step(&mut self, step: u64, pose: &PoseMsg, scan: &ScanMsg) {
        let p = pose_in_frame(self.start, [pose.x_m, pose.y_m, pose.theta_rad]);
        self.pose = Some((p, det_xy(pose)));
        if let Some(d) = self.depositor.as_mut() {
            if let Ok(Some(m)) = d.process(pose) {
                // A deposit the field refuses is refused here too (and counted by the stepper).
                let _ = self.map.deposit(self.start, &m);
            }
        }
        self.counters.scans += 1;
        let _ = self.map.integrate_scan(p, scan);
        if step.is_multiple_of(self.steps_per_iteration) {
            self.map.step_pheromone();
        }
    }

    /// Merges the map of `peer` (`src`, with the peer's estimate of itself in its own frame,
    /// `src_pose`) measured as `obs`; records the exchange. Returns the transform used.
    pub fn accept(
        &mut self,
        step: u64,
        src: &MapView<'_>,
        src_pose: Pose2,
        obs: &PeerObs,
    ) -> Result<MergeTransform, MapError> {
        let me = self.pose().unwrap_or([f64::NAN; 3]);
        let t = MergeTransform::from_measurement(me, src_pose, obs);
        self.last_exchange
            .insert(obs.robot_id, self.iteration(step));
        match self.map.merge(src, &t) {
            Ok(_) => {
                self.counters.merges += 1;
                Ok(t)
            }
            Err(e) => {
                *self
                    .counters
                    .merges_rejected
                    .entry(e.name().to_string())
                    .or_default() += 1;
                Err(e)
            }
        }
    }

    /// Merges a peer's map frame as the mapper process receives it (`header`, `cells`: the
    /// frame in shared memory, borrowed): a frame whose header disagrees with its length (or
    /// describes no valid geometry) is refused and counted under its [`MapError::name`] without
    /// touching the map; a valid one goes through [`Mapper::accept`], which validates it further.
    pub fn accept_frame(
        &mut self,
        step: u64,
        header: &pheromone_field::FrameHeader,
        cells: &[f32],
        src_pose: Pose2,
        obs: &PeerObs,
    ) -> Result<MergeTransform, MapError> {
        match MapView::from_frame(header, cells) {
            Ok(view) => self.accept(step, &view, src_pose, obs),
            Err(e) => {
                self.count_rejected(e.name());
                Err(e)
            }
        }
    }

    /// Counts a peer map refused before it reached [`Mapper::accept`] (`reason`: e.g. a frame
    /// whose header disagrees with its length, [`MapError::name`]).
    pub fn count_rejected(&mut self, reason: &str) {
        *self
            .counters
            .merges_rejected
            .entry(reason.to_string())
            .or_default() += 1;
    }

    /// Counts an exchange not made because this robot or its peer is lost (the pair tries again
    /// at the next iteration).
    pub fn refuse_lost(&mut self) {
        self.counters.refused_lost += 1;
    }
}
