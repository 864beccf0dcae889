//! Seed 004's mapping team of a run: every robot's [`Mapper`] and Algorithm 1's exchanges at
//! rendezvous, the same step by step in the single-process runner and (one mapper per
//! process) in `pheromone mapper`.
//!
//! Step k of a mapper: (1) on an exchange step, it merges the maps its peers had at the end of
//! step k − 1, placed by the rendezvous measurement of step k − 1 and both robots' estimates of
//! step k − 1 (everything one instant, and what every process has by then); (2) it takes its
//! estimate, its deposit and its scan of step k. A pair exchanges when both robots are within
//! R_C (true distance), neither is lost (det Σxy ≤ `loss_det_m4`), exchanges have started and
//! the pair's interval has elapsed; each then merges the other's map.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::messages::{PoseMsg, RendezvousMsg, ScanMsg};
use crate::roles::depositor::Depositor;
use crate::roles::mapper::{
    MapError, MapView, Mapper, MapperCounters, MappingConfig, MergeTransform, Pose2,
};
use crate::sim::scenario::Scenario;

/// A robot's final map, in its own frame.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotMap {
    /// The robot's true start pose in the world (the map's frame, for pictures and metrics).
    pub start: Pose2,
    pub geometry: field::GridGeometry,
    pub occupancy: Vec<f32>,
    pub pheromone: Vec<f32>,
}

/// One merge: robot `dst` merged the map of `src` at world step `step`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MergeEvent {
    pub step: u64,
    pub dst: u32,
    pub src: u32,
    /// Alignment error (m): the largest displacement, between the transform measured and the
    /// true one, of the source map's origin and of the source robot's position.
    pub alignment_error_m: f64,
}

/// What the mappers of a run leave for the metrics and pictures.
#[derive(Debug, Clone, Default)]
pub struct MappingRecord {
    pub maps: BTreeMap<u32, RobotMap>,
    pub merges: Vec<MergeEvent>,
    pub counters: BTreeMap<u32, MapperCounters>,
}

/// Robot `id`'s mapper as the scenario sets it up: its start pose is the world's, its depositor
/// copy the scenario's.
pub fn mapper_for(scenario: &Scenario, id: u32) -> Result<Option<Mapper>, MapError> {
    let Some(config) = scenario.mapping() else {
        return Ok(None);
    };
    let Some(r) = scenario.world.robots.iter().find(|r| r.id == id) else {
        return Ok(None);
    };
    let depositor = scenario
        .roles(id)
        .and_then(|x| x.depositor.clone())
        .and_then(|c| Depositor::new(c).ok());
    Mapper::new(
        id,
        config,
        [r.start.x_m, r.start.y_m, r.start.theta_rad],
        &scenario.mapping_channel(id),
        scenario.world.dt_s,
        depositor,
    )
    .map(Some)
}

/// The true transform from `src`'s map frame into `dst`'s (their true start poses).
pub fn true_transform(src_start: Pose2, dst_start: Pose2) -> MergeTransform {
    MergeTransform::between_frames(src_start, dst_start)
}

/// Alignment error of a merge (see [`MergeEvent::alignment_error_m`]).
pub fn alignment_error_m(measured: &MergeTransform, truth: &MergeTransform) -> f64 {
    measured
        .displacement_m(truth, [0.0, 0.0])
        .max(measured.displacement_m(truth, measured.src_robot_m))
}

/// Every robot's mapper in one process.
pub struct MappingTeam {
    config: MappingConfig,
    mappers: Vec<Mapper>,
    /// The rendezvous measurements of the previous step, by robot.
    previous: Vec<Option<RendezvousMsg>>,
    merges: Vec<MergeEvent>,
}

impl MappingTeam {
    /// The team of a scenario that maps (`None` otherwise), robots in world order.
    pub fn new(scenario: &Scenario) -> Result<Option<Self>, MapError> {
        let Some(config) = scenario.mapping() else {
            return Ok(None);
        };
        let mut mappers = Vec::new();
        for r in &scenario.world.robots {
            mappers.extend(mapper_for(scenario, r.id)?);
        }
        Ok(Some(Self {
            config: config.clone(),
            previous: vec![None; mappers.len()],
            mappers,
            merges: Vec::new(),
        }))
    }

    /// World step `step`: the exchanges due (on the maps of the end of the last step), then every
    /// robot's pose, deposit and scan of this step. `poses` and `sensed` in world order.
    pub fn step(&mut self, step: u64, poses: &[PoseMsg], sensed: &[(ScanMsg, RendezvousMsg)]) {
        if self.config.merge {
            self.exchange(step);
        }
        for (i, m) in self.mappers.iter_mut().enumerate() {
            if let (Some(p), Some((scan, rv))) = (poses.get(i), sensed.get(i)) {
                m.on_step(step, p, scan);
                self.previous[i] = Some(*rv);
            }
        }
    }

    fn exchange(&mut self, step: u64) {
        let n = self.mappers.len();
        // What each robot offers: its map and estimate at the end of the last step.
        let mut offers: Vec<Option<(crate::roles::mapper::LocalMap, Pose2)>> = vec![None; n];
        let mut merges = Vec::new();
        for j in 0..n {
            let Some(rv) = self.previous[j] else { continue };
            for obs in rv.peers() {
                let Some(i) = self.mappers.iter().position(|m| m.id == obs.robot_id) else {
                    continue;
                };
                if !self.mappers[j].due(obs.robot_id, step) {
                    continue;
                }
                if self.mappers[j].lost() || self.mappers[i].lost() {
                    self.mappers[j].refuse_lost();
                    continue;
                }
                if offers[i].is_none() {
                    let src = &self.mappers[i];
                    offers[i] = Some((src.map.clone(), src.pose().expect("not lost")));
                }
                merges.push((j, i, *obs));
            }
        }
        for (j, i, obs) in merges {
            let (map, src_pose) = offers[i].as_ref().expect("offered");
            let view: MapView<'_> = map.view();
            let (src_start, dst_start) = (self.mappers[i].start(), self.mappers[j].start());
            let (src_id, dst) = (self.mappers[i].id, &mut self.mappers[j]);
            // A refused map is counted by the mapper.
            if let Ok(t) = dst.accept(step, &view, *src_pose, &obs) {
                self.merges.push(MergeEvent {
                    step,
                    dst: dst.id,
                    src: src_id,
                    alignment_error_m: alignment_error_m(&t, &true_transform(src_start, dst_start)),
                });
            }
        }
    }

    /// The final maps, the merges and the counters.
    pub fn finish(self) -> MappingRecord {
        let mut rec = MappingRecord {
            merges: self.merges,
            ..MappingRecord::default()
        };
        for m in self.mappers {
            rec.counters.insert(m.id, m.counters.clone());
            rec.maps.insert(
                m.id,
                RobotMap {
                    start: m.start(),
                    geometry: *m.map.geometry(),
                    occupancy: m.map.occupancy,
                    pheromone: m.map.pheromone,
                },
            );
        }
        rec
    }
}
