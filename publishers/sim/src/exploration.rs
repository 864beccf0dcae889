//! Seed 004's exploration as the paper counts it, the share of the sectors a robot *knows*,
//! in two figures:
//! - `exploration_merged` (the paper's count): a sector counts for a robot when the robot
//!   visited it or received it through a merge, transitively (a merge of robot i's map at step
//!   k hands on every sector i counted at the end of step k − 1, received ones included);
//! - `exploration_known` (sensor-mapped): a sector is known when at least `known_share` of its
//!   free cells are mapped (|log-odds| ≥ `known_logodds`) in the robot's final map. The free
//!   cells of a sector are the points of a grid of the map's cell size over the sector that lie
//!   neither in a wall nor within half a cell of one in the true world; each is looked up in the
//!   robot's map through the robot's true start pose (the frame of its map).

use serde::Serialize;

use crate::recording::Recording;
use pheromone_roles::mapper::{pose_in_frame, MappingConfig};
use pheromone_world::scenario::{ExplorationMetric, Scenario};
use pheromone_world::team::{MappingRecord, MergeEvent, RobotMap};
use pheromone_world::World;

/// `exploration_known`, shaped like `exploration`.
#[derive(Debug, Clone, Serialize)]
pub struct KnownExploration {
    pub sectors: u32,
    /// Share of the sectors each robot knows, by robot id order.
    pub per_robot: Vec<f64>,
    pub mean: f64,
    /// Share known by at least one robot.
    pub team: f64,
}

/// The free points of each sector (world metres), on a grid of `step_m`.
pub fn free_points(m: &ExplorationMetric, world: &World, step_m: f64) -> Vec<Vec<[f64; 2]>> {
    let n = (m.cols * m.rows) as usize;
    let mut out = vec![Vec::new(); n];
    let (w, h) = (m.max_m[0] - m.min_m[0], m.max_m[1] - m.min_m[1]);
    let (nx, ny) = ((w / step_m).floor() as usize, (h / step_m).floor() as usize);
    for iy in 0..ny {
        for ix in 0..nx {
            let p = [
                m.min_m[0] + (ix as f64 + 0.5) * step_m,
                m.min_m[1] + (iy as f64 + 0.5) * step_m,
            ];
            if world.in_wall(p[0], p[1], 0.5 * step_m) {
                continue;
            }
            if let Some(s) = m.sector_index(p[0], p[1]) {
                out[s].push(p);
            }
        }
    }
    out
}

/// Which sectors a map knows.
pub fn known_sectors(map: &RobotMap, free: &[Vec<[f64; 2]>], c: &MappingConfig) -> Vec<bool> {
    let g = &map.geometry;
    free.iter()
        .map(|points| {
            if points.is_empty() {
                return false;
            }
            let mapped = points
                .iter()
                .filter(|p| {
                    let q = pose_in_frame(map.start, [p[0], p[1], 0.0]);
                    g.cell_at(q[0] as f32, q[1] as f32)
                        .is_some_and(|(x, y)| map.occupancy[g.index(x, y)].abs() >= c.known_logodds)
                })
                .count();
            mapped as f64 >= c.known_share * points.len() as f64
        })
        .collect()
}

/// `exploration_known` of a run.
pub fn exploration_known(
    scenario: &Scenario,
    m: &ExplorationMetric,
    rec: &MappingRecord,
) -> Option<KnownExploration> {
    let c = scenario.mapping()?;
    let world = World::new(scenario.world.clone(), scenario.seed).ok()?;
    let free = free_points(m, &world, c.cell_size_m as f64);
    let n = free.len();
    let mut team = vec![false; n];
    let per_robot: Vec<f64> = rec
        .maps
        .values()
        .map(|map| {
            let known = known_sectors(map, &free, c);
            for (t, k) in team.iter_mut().zip(&known) {
                *t |= *k;
            }
            known.iter().filter(|k| **k).count() as f64 / n as f64
        })
        .collect();
    let mean = if per_robot.is_empty() {
        0.0
    } else {
        per_robot.iter().sum::<f64>() / per_robot.len() as f64
    };
    Some(KnownExploration {
        sectors: n as u32,
        team: team.iter().filter(|k| **k).count() as f64 / n as f64,
        per_robot,
        mean,
    })
}

/// Per robot (id order), the sectors it counts: visited, or received through a merge.
type SectorSets = Vec<Vec<bool>>;

/// `exploration_merged`: seed 004's count (see the module's documentation). The robots'
/// samples (one per world step, at `t_s` = step · `dt_s`) give their visits; `merges` the
/// hand-overs.
pub fn exploration_merged(
    m: &ExplorationMetric,
    rec: &Recording,
    merges: &[MergeEvent],
    dt_s: f64,
) -> KnownExploration {
    let n = (m.cols * m.rows) as usize;
    let ids: Vec<u32> = rec.robots.keys().copied().collect();
    let mut counted: SectorSets = vec![vec![false; n]; ids.len()];
    let mut next = vec![0usize; ids.len()];
    // Every sample up to step `last` of every robot marks its sector.
    let visit = |counted: &mut SectorSets, next: &mut [usize], last: u64| {
        for (r, rows) in rec.robots.values().enumerate() {
            while let Some(row) = rows
                .get(next[r])
                .filter(|row| (row.t_s / dt_s).round() as u64 <= last)
            {
                if let Some(s) = m.sector_index(row.true_pose[0], row.true_pose[1]) {
                    counted[r][s] = true;
                }
                next[r] += 1;
            }
        }
    };
    let mut order: Vec<&MergeEvent> = merges.iter().collect();
    order.sort_by_key(|e| e.step);
    for group in order.chunk_by(|a, b| a.step == b.step) {
        let k = group[0].step;
        visit(&mut counted, &mut next, k.saturating_sub(1));
        // Every merge of step k hands on what its source counted at the end of step k − 1.
        let before = counted.clone();
        for e in group {
            let at = |id| ids.iter().position(|&i| i == id);
            if let (Some(d), Some(s)) = (at(e.dst), at(e.src)) {
                for (x, y) in counted[d].iter_mut().zip(&before[s]) {
                    *x |= *y;
                }
            }
        }
    }
    visit(&mut counted, &mut next, u64::MAX);
    let share = |v: &[bool]| v.iter().filter(|x| **x).count() as f64 / n.max(1) as f64;
    let per_robot: Vec<f64> = counted.iter().map(|v| share(v)).collect();
    let team: Vec<bool> = (0..n).map(|s| counted.iter().any(|v| v[s])).collect();
    KnownExploration {
        sectors: n as u32,
        mean: per_robot.iter().sum::<f64>() / per_robot.len().max(1) as f64,
        team: share(&team),
        per_robot,
    }
}

/// Where merged maps landed against where they belong (m).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct AlignmentError {
    pub mean: f64,
    pub max: f64,
}

/// The metrics of a run with `[mapping]` on; in the JSON they sit beside the scenario's other
/// metrics.
#[derive(Debug, Clone, Serialize)]
pub struct MappingMetrics {
    /// Sectors visited or received through a merge, transitively: the paper's count (with an
    /// exploration metric).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exploration_merged: Option<KnownExploration>,
    /// Sectors mapped by the sensor in the final map, own scans or merged (with an exploration
    /// metric).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exploration_known: Option<KnownExploration>,
    /// What the sector followers steered on: `shared` or `own-map`.
    pub steer_on: &'static str,
    pub known_threshold: f64,
    pub known_logodds: f32,
    pub merge: bool,
    pub rc_m: f64,
    pub merges: usize,
    pub merges_rejected: u64,
    pub exchanges_refused_lost: u64,
    /// `None` (null) without merges.
    pub merge_alignment_error_m: Option<AlignmentError>,
}

/// The mapping metrics; `None` when the scenario maps nothing.
pub fn mapping_metrics(scenario: &Scenario, run: &Recording) -> Option<MappingMetrics> {
    let c = scenario.mapping()?;
    let rec = run.mapping.as_ref()?;
    let errors: Vec<f64> = rec.merges.iter().map(|e| e.alignment_error_m).collect();
    Some(MappingMetrics {
        exploration_merged: scenario
            .metrics
            .exploration
            .as_ref()
            .map(|m| exploration_merged(m, run, &rec.merges, scenario.world.dt_s)),
        steer_on: c.steer_on.name(),
        exploration_known: scenario
            .metrics
            .exploration
            .as_ref()
            .and_then(|m| exploration_known(scenario, m, rec)),
        known_threshold: c.known_share,
        known_logodds: c.known_logodds,
        merge: c.merge,
        rc_m: c.rc_m,
        merges: rec.merges.len(),
        merges_rejected: rec
            .counters
            .values()
            .flat_map(|k| k.merges_rejected.values())
            .sum(),
        exchanges_refused_lost: rec.counters.values().map(|k| k.refused_lost).sum(),
        merge_alignment_error_m: (!errors.is_empty()).then(|| AlignmentError {
            mean: errors.iter().sum::<f64>() / errors.len() as f64,
            max: errors.iter().copied().fold(0.0, f64::max),
        }),
    })
}
