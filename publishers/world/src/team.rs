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

use crate::scenario::Scenario;
use pheromone_messages::{PoseMsg, RendezvousMsg, ScanMsg};
pub use pheromone_roles::mapper::{alignment_error_m, true_transform, MergeEvent};
use pheromone_roles::mapper::{MapError, MapView, Mapper, MapperCounters, MappingConfig, Pose2};

/// A robot's final map, in its own frame.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotMap {
    /// The robot's true start pose in the world (the map's frame, for pictures and metrics).
    pub start: Pose2,
    pub geometry: pheromone_field::GridGeometry,
    pub occupancy: Vec<f32>,
    pub pheromone: Vec<f32>,
}

/// What the mappers of a run leave for the metrics and pictures.
#[derive(Debug, Clone, Default)]
pub struct MappingRecord {
    pub maps: BTreeMap<u32, RobotMap>,
    pub merges: Vec<MergeEvent>,
    pub counters: BTreeMap<u32, MapperCounters>,
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
            mappers.extend(scenario.mapper(r.id)?);
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
        let mut offers: Vec<Option<(pheromone_roles::mapper::LocalMap, Pose2)>> = vec![None; n];
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

    /// The mapper of robot `id`.
    /// The robots that merged a peer's map at `step` (each once, however many maps it merged).
    pub fn merged_at(&self, step: u64) -> Vec<u32> {
        let mut ids: Vec<u32> = self
            .merges
            .iter()
            .rev()
            .take_while(|e| e.step == step)
            .map(|e| e.dst)
            .collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    pub fn mapper(&self, id: u32) -> Option<&Mapper> {
        self.mappers.iter().find(|m| m.id == id)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Overrides;
    use crate::wrap_angle;
    use pheromone_messages::PeerObs;

    /// Three robots of `ias-ss` with merging, exchanges from iteration 2 (step 20; 10 steps an
    /// iteration), the same pair at most every 3 iterations.
    fn three_robots() -> Scenario {
        let mut s = Scenario::load("ias-ss").unwrap();
        s.apply(&Overrides {
            robots: Some(3),
            merge: Some(true),
            ..Overrides::default()
        })
        .unwrap();
        s.mapping.start_iteration = 1;
        s.mapping.every_iterations = 3;
        s
    }

    /// Robot `r` standing at its start pose, with det Σxy = `var_m2`².
    fn pose(r: &crate::RobotConfig, step: u64, var_m2: f64) -> PoseMsg {
        let mut p = PoseMsg {
            step,
            robot_id: r.id,
            x_m: r.start.x_m,
            y_m: r.start.y_m,
            theta_rad: r.start.theta_rad,
            ..PoseMsg::default()
        };
        p.cov[0] = var_m2;
        p.cov[4] = var_m2;
        p.cov[8] = 1e-4;
        p
    }

    /// A fan of rays, some hitting a wall 2 m away: every map knows cells of its own.
    fn scan(id: u32, step: u64) -> ScanMsg {
        let mut s = ScanMsg {
            step,
            robot_id: id,
            count: 9,
            angle_min_rad: -std::f32::consts::FRAC_PI_2,
            angle_step_rad: std::f32::consts::PI / 8.0,
            range_max_m: 3.0,
            hits: 0b1_0101_0101,
            ..ScanMsg::default()
        };
        s.ranges_m[..9].copy_from_slice(&[2.0, 3.0, 2.0, 3.0, 2.0, 3.0, 2.0, 3.0, 2.0]);
        s
    }

    /// Each robot's exact measurement of every other (the world frame is the truth here).
    fn rendezvous(s: &Scenario, i: usize, step: u64) -> RendezvousMsg {
        let robots = &s.world.robots;
        let p = robots[i].start;
        let mut rv = RendezvousMsg {
            step,
            robot_id: robots[i].id,
            ..RendezvousMsg::default()
        };
        for q in robots.iter().filter(|q| q.id != robots[i].id) {
            let q_start = q.start;
            rv.peers[rv.count as usize] = PeerObs {
                robot_id: q.id,
                _pad: 0,
                range_m: (q_start.x_m - p.x_m).hypot(q_start.y_m - p.y_m),
                bearing_rad: wrap_angle(
                    (q_start.y_m - p.y_m).atan2(q_start.x_m - p.x_m) - p.theta_rad,
                ),
                heading_rad: wrap_angle(q_start.theta_rad - p.theta_rad),
            };
            rv.count += 1;
        }
        rv
    }

    #[test]
    fn a_lost_robot_neither_offers_nor_accepts_maps_while_a_localized_pair_merges() {
        let s = three_robots();
        let loss = s.mapping().unwrap().loss_det_m4;
        let (found, lost) = (1e-3, 1.0); // det Σxy 1e-6 and 1 m⁴
        assert!(found * found <= loss && lost * lost > loss);
        let mut team = MappingTeam::new(&s).unwrap().expect("maps");
        let ids: Vec<u32> = s.world.robots.iter().map(|r| r.id).collect();
        // Robot 0's mapper alone, fed the same inputs: what it maps with no merge.
        let mut solo = s.mapper(ids[0]).unwrap().unwrap();
        let feed = |team: &mut MappingTeam,
                    solo: &mut Mapper,
                    steps: std::ops::RangeInclusive<u64>,
                    lost_0: bool| {
            for k in steps {
                let poses: Vec<PoseMsg> = s
                    .world
                    .robots
                    .iter()
                    .enumerate()
                    .map(|(i, r)| pose(r, k, if i == 0 && lost_0 { lost } else { found }))
                    .collect();
                let sensed: Vec<_> = (0..ids.len())
                    .map(|i| (scan(ids[i], k), rendezvous(&s, i, k)))
                    .collect();
                team.step(k, &poses, &sensed);
                solo.on_step(k, &poses[0], &sensed[0].0);
            }
        };
        // Robot 0 lost through step 20: at step 20, the first exchange step, on the state of
        // step 19. Localized again from step 21, before the next exchange step (30).
        feed(&mut team, &mut solo, 1..=20, true);
        assert!(team.mappers[0].lost() && !team.mappers[1].lost());
        feed(&mut team, &mut solo, 21..=29, false);
        assert!(!team.mappers[0].lost());
        let pairs: Vec<(u64, u32, u32)> =
            team.merges.iter().map(|e| (e.step, e.dst, e.src)).collect();
        assert_eq!(pairs, [(20, ids[1], ids[2]), (20, ids[2], ids[1])]);
        // Robot 0 refused both its peers' maps; each peer refused robot 0's.
        let c: Vec<&MapperCounters> = team.mappers.iter().map(|m| &m.counters).collect();
        assert_eq!(
            [c[0].refused_lost, c[1].refused_lost, c[2].refused_lost],
            [2, 1, 1]
        );
        assert_eq!([c[0].merges, c[1].merges, c[2].merges], [0, 1, 1]);
        assert!(c.iter().all(|c| c.merges_rejected.is_empty()));
        // Its map holds only what it mapped itself; the others' maps took each other's.
        assert_eq!(team.mappers[0].map.occupancy, solo.map.occupancy);
        assert_eq!(team.mappers[0].map.pheromone, solo.map.pheromone);
        let mut solo_1 = s.mapper(ids[1]).unwrap().unwrap();
        for k in 1..=29 {
            solo_1.on_step(k, &pose(&s.world.robots[1], k, found), &scan(ids[1], k));
        }
        assert_ne!(team.mappers[1].map.occupancy, solo_1.map.occupancy);

        // At the next exchange step robot 0 exchanges with both (the refused pairs were not
        // marked as exchanged); the pair 1–2 waits for its interval.
        feed(&mut team, &mut solo, 30..=30, false);
        let pairs: Vec<(u32, u32)> = team.merges[2..].iter().map(|e| (e.dst, e.src)).collect();
        assert_eq!(
            pairs,
            [
                (ids[0], ids[1]),
                (ids[0], ids[2]),
                (ids[1], ids[0]),
                (ids[2], ids[0])
            ]
        );
        assert!(team.merges[2..].iter().all(|e| e.step == 30));
        assert_ne!(team.mappers[0].map.occupancy, solo.map.occupancy);
        let rec = team.finish();
        assert_eq!(
            rec.counters[&ids[0]].refused_lost, 2,
            "no refusal once localized"
        );
        let refused_lost: u64 = rec.counters.values().map(|k| k.refused_lost).sum();
        assert_eq!(refused_lost, 4, "{:?}", rec.counters);
        assert_eq!(rec.merges.len(), 6);
    }
}
