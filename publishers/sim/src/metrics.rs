//! Scenario-specific metrics computed from a run's [`Recording`], the same way for a
//! single-process and a multi-process run.
//! - `mean_path_error_m` (seed 002): the mean distance between the robot and the target path,
//!   sampled every 0.2 s over 10 s; `turning_share` beside it: the share of those samples at
//!   which the robot turned (|ω| > 0.01 rad/s), 0 for a robot that drives blind beside the trail.
//! - `exploration` (seed 004): the share of the map's sectors each robot has visited.
//! - `blind_leader` (seed 000): where the leader got lost, when the follower gave the trail up,
//!   and how far the follower strayed from the leader's true path.
//! - `wrong_area` (seed 000 Figs. 1, 24; [`crate::wrong_area`]): whether the followers of a
//!   lost leader end in the wrong area A or reach B, and where they gave the trail up.
//! - with `[mapping]` on (seed 004, [`crate::exploration::mapping_metrics`]):
//!   `exploration_merged` (sectors visited or received through a merge, transitively: the
//!   paper's count; `sectors`, `per_robot`, `mean`, `team`), `exploration_known` (sectors
//!   mapped by the sensor in the final map, same shape), `steer_on`, `known_threshold`, `known_logodds`, `merge`, `rc_m`, `merges`, `merges_rejected`,
//!   `exchanges_refused_lost`, `merge_alignment_error_m` (`mean`, `max`).
//! - `radio` (seed 002, `sim --remote` with `[radio]` or `--clients N`; [`crate::radio`]): the
//!   shared air's requests sent and delivered, collisions, losses and mean latency.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::exploration::MappingMetrics;
use crate::processes::ProcessReport;
use crate::recording::{ProbeReading, Recording};
use crate::ros_record::McapTotals;
use crate::single::{FieldSummary, RobotResult, RunSummary};
use crate::wrong_area::WrongArea;
use pheromone_world::scenario::{BlindLeaderMetric, ExplorationMetric, PathMetric, Scenario};

/// Every metric the scenario asks for; those it does not ask for are left out of the JSON.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ScenarioMetrics {
    /// Seed 002: each path metric's mean distance to its path (m), by the metric's name; `None`
    /// when the run has no sample in its window.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_path_error_m: Option<BTreeMap<String, Option<f64>>>,
    /// Seed 002: the share of each path metric's samples at which the robot turned
    /// (|ω| > [`TURNING_RAD_PER_S`]): a follower whose antennas saturate (both read 1) drives
    /// straight on, and its path error is then the width of that dead band.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub turning_share: Option<BTreeMap<String, Option<f64>>>,
    /// Seed 004: sectors visited.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exploration: Option<Exploration>,
    /// Seed 000's corridor.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub blind_leader: Option<BlindLeader>,
    /// Seed 000's wrong area.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wrong_area: Option<WrongArea>,
    /// `sim --remote` with `[radio]` (`--clients N`): what seed 002's shared air did to the
    /// thin clients' requests ([`crate::radio`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radio: Option<crate::radio::RadioMetrics>,
    /// With `[mapping]` on: its keys sit beside the others (`exploration_known`, `merges`…).
    #[serde(flatten)]
    pub mapping: Option<MappingMetrics>,
}

/// Every metric the scenario asks for.
pub fn scenario_metrics(scenario: &Scenario, rec: &Recording) -> ScenarioMetrics {
    let m = &scenario.metrics;
    ScenarioMetrics {
        mean_path_error_m: (!m.paths.is_empty()).then(|| {
            m.paths
                .iter()
                .map(|p| (p.name.clone(), mean_path_error_m(p, rec)))
                .collect()
        }),
        turning_share: (!m.paths.is_empty()).then(|| {
            m.paths
                .iter()
                .map(|p| (p.name.clone(), turning_share(p, rec)))
                .collect()
        }),
        exploration: m.exploration.as_ref().map(|e| exploration(e, rec)),
        blind_leader: m
            .blind_leader
            .as_ref()
            .map(|b| blind_leader(scenario, b, rec)),
        wrong_area: m
            .wrong_area
            .as_ref()
            .map(|w| crate::wrong_area::wrong_area(scenario, w, rec)),
        mapping: crate::exploration::mapping_metrics(scenario, rec),
        radio: None,
    }
}

/// How a run was made (`mode` in the metrics).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RunMode {
    SingleProcess,
    Processes,
    /// Processes, with the antenna followers as thin clients of the gateway (`--remote`).
    ProcessesRemote,
}

/// The metrics of a run (`--json`, `metrics.json`): the keys every scenario has, how the run
/// was made, and the scenario's own metrics under `metrics`.
#[derive(Debug, Clone, Serialize)]
pub struct RunMetrics {
    pub scenario: String,
    pub seed: u64,
    pub sim_time_s: f64,
    pub steps: u64,
    pub ticks: u64,
    pub field: FieldSummary,
    pub robots: Vec<RobotResult>,
    pub probes: Vec<ProbeReading>,
    pub metrics: ScenarioMetrics,
    pub mode: RunMode,
    /// Stopped early by SIGINT/SIGTERM; everything is as far as the run went.
    pub interrupted: bool,
    pub wall_time_s: f64,
    pub sim_time_per_wall_time: f64,
    /// Process runs: from the first process started until the field's first lockstep frame (s).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub startup_s: Option<f64>,
    /// Process runs: what each process reported as it stopped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub processes: Option<Vec<ProcessReport>>,
    /// `--record`: what the MCAP file holds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub record: Option<McapTotals>,
}

impl RunMetrics {
    /// The metrics of a run that took `wall_time_s`; the process facts and the record are
    /// added by whoever has them.
    pub fn new(
        scenario: &Scenario,
        s: &RunSummary,
        rec: &Recording,
        mode: RunMode,
        wall_time_s: f64,
    ) -> Self {
        Self {
            scenario: scenario.name.clone(),
            seed: scenario.seed,
            sim_time_s: s.sim_time_s,
            steps: s.steps,
            ticks: s.ticks,
            field: s.field.clone(),
            robots: s.robots.clone(),
            probes: rec.probes.clone(),
            metrics: ScenarioMetrics {
                // Only thin clients share the air.
                radio: (mode == RunMode::ProcessesRemote)
                    .then(|| {
                        let robots = scenario.antenna_robots();
                        crate::radio::radio_metrics(scenario, &robots, s.steps)
                    })
                    .flatten(),
                ..scenario_metrics(scenario, rec)
            },
            mode,
            interrupted: false,
            wall_time_s,
            sim_time_per_wall_time: s.sim_time_s / wall_time_s.max(1e-9),
            startup_s: None,
            processes: None,
            record: None,
        }
    }
}

/// Distance from a point to a polyline (m).
pub fn distance_to_polyline_m(p: [f64; 2], line: &[[f64; 2]]) -> f64 {
    project_on_polyline(p, line).0
}

/// Nearest point of a polyline: (distance to it, arc length from the polyline's start) (m).
pub fn project_on_polyline(p: [f64; 2], line: &[[f64; 2]]) -> (f64, f64) {
    let mut best = (f64::INFINITY, 0.0);
    let mut walked = 0.0;
    for w in line.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy);
        if d < best.0 {
            best = (d, walked + t * len2.sqrt());
        }
        walked += len2.sqrt();
    }
    best
}

/// The samples of a path metric: one row every `every_s` over its window.
fn path_samples<'a>(
    m: &'a PathMetric,
    rec: &'a Recording,
) -> impl Iterator<Item = &'a crate::recording::RobotSample> + 'a {
    let mut next = m.from_s;
    let end = m.from_s + m.over_s + 1e-9;
    rec.robots
        .get(&m.robot)
        .into_iter()
        .flatten()
        .filter(move |r| {
            let take = r.t_s + 1e-9 >= next && r.t_s <= end;
            if take {
                next += m.every_s;
            }
            take
        })
}

/// Seed 002's evaluation: mean distance to the path every `every_s` over the window; `None`
/// when the run has no sample in it.
pub fn mean_path_error_m(m: &PathMetric, rec: &Recording) -> Option<f64> {
    mean(
        path_samples(m, rec)
            .map(|r| distance_to_polyline_m([r.true_pose[0], r.true_pose[1]], &m.points)),
    )
}

/// A turn rate above this counts as turning (rad/s) for [`turning_share`].
pub const TURNING_RAD_PER_S: f64 = 0.01;

/// The share of a path metric's samples at which the robot turned (|ω| > [`TURNING_RAD_PER_S`]);
/// `None` when the run has no sample in the window.
pub fn turning_share(m: &PathMetric, rec: &Recording) -> Option<f64> {
    mean(
        path_samples(m, rec)
            .map(|r| f64::from(u8::from(r.omega_rad_per_s.abs() > TURNING_RAD_PER_S))),
    )
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// Sectors visited, per robot and over all robots.
#[derive(Debug, Clone, Serialize)]
pub struct Exploration {
    pub sectors: u32,
    /// Share of the sectors each robot visited, by robot id order.
    pub per_robot: Vec<f64>,
    pub mean: f64,
    /// Share visited by at least one robot.
    pub team: f64,
}

pub fn exploration(m: &ExplorationMetric, rec: &Recording) -> Exploration {
    let n = (m.cols * m.rows) as usize;
    let sector = |x: f64, y: f64| m.sector_index(x, y);
    let mut team = vec![false; n];
    let per_robot: Vec<f64> = rec
        .robots
        .values()
        .map(|rows| {
            let mut seen = vec![false; n];
            for r in rows {
                if let Some(s) = sector(r.true_pose[0], r.true_pose[1]) {
                    seen[s] = true;
                    team[s] = true;
                }
            }
            seen.iter().filter(|v| **v).count() as f64 / n as f64
        })
        .collect();
    let mean = if per_robot.is_empty() {
        0.0
    } else {
        per_robot.iter().sum::<f64>() / per_robot.len() as f64
    };
    Exploration {
        sectors: n as u32,
        team: team.iter().filter(|v| **v).count() as f64 / n as f64,
        per_robot,
        mean,
    }
}

/// Seed 000's corridor experiment, in figures. Positions along the leader's true path are arc
/// lengths from where the leader started (m).
#[derive(Debug, Clone, Serialize)]
pub struct BlindLeader {
    /// When the leader lost its localization (s), if it did: the loss script's start, or
    /// without one the first step its own σ reached `wrong_area`'s `lost_sigma_m`
    /// ([`crate::wrong_area::leader_lost_at_s`], the same figure as `wrong_area.leader`).
    pub leader_lost_at_s: Option<f64>,
    /// How far along its path the leader was then (m).
    pub leader_lost_at_m: Option<f64>,
    /// Distance between the leader's estimate and its true position at the end (m).
    pub leader_final_estimate_error_m: Option<f64>,
    /// When the follower gave the trail up (s), if it did.
    pub follower_abandoned_at_s: Option<f64>,
    /// Where along the leader's path the follower gave up (m).
    pub follower_abandoned_at_m: Option<f64>,
    /// The farthest point along the leader's path the follower reached in the whole run,
    /// exploring after it gave the trail up included (m).
    pub follower_reached_m: f64,
    /// How far along the leader's path the follower followed the trail past the point where
    /// the leader got lost (m): the farthest point it reached before it gave the trail up (in
    /// the whole run if it never did) minus `leader_lost_at_m`. ≈ 0 when it stops where the
    /// leader got lost, large when it follows the lost leader's trail. (It measured the whole
    /// run, exploring included, and so contradicted `wrong_area`'s figure for the same follower.)
    pub follower_followed_past_loss_m: Option<f64>,
    /// The follower's largest distance from the leader's true path once it had reached it (m).
    pub follower_max_off_leader_path_m: f64,
    pub follower_distance_travelled_m: f64,
}

pub fn blind_leader(scenario: &Scenario, m: &BlindLeaderMetric, rec: &Recording) -> BlindLeader {
    let leader = rec.robots.get(&m.leader).map(Vec::as_slice).unwrap_or(&[]);
    let follower = rec
        .robots
        .get(&m.follower)
        .map(Vec::as_slice)
        .unwrap_or(&[]);
    let path: Vec<[f64; 2]> = leader
        .iter()
        .map(|r| [r.true_pose[0], r.true_pose[1]])
        .collect();
    let along = |p: [f64; 3]| -> (f64, f64) {
        if path.len() < 2 {
            (f64::INFINITY, 0.0)
        } else {
            project_on_polyline([p[0], p[1]], &path)
        }
    };
    let lost_at_s = crate::wrong_area::leader_lost_at_s(scenario, m.leader, leader);
    let lost_at_m = lost_at_s.and_then(|t| {
        leader
            .iter()
            .find(|r| r.t_s >= t - 1e-9)
            .map(|r| along(r.true_pose).1)
    });
    let abandoned = rec.trail_abandoned_at_s(m.follower);
    let abandoned_at_m = abandoned.and_then(|t| {
        follower
            .iter()
            .find(|r| r.t_s >= t - 1e-9)
            .map(|r| along(r.true_pose).1)
    });
    let mut reached = 0.0f64;
    let mut reached_on_trail = 0.0f64;
    let mut off = 0.0f64;
    let mut on_path = false;
    for r in follower {
        let (d, s) = along(r.true_pose);
        on_path |= d < 0.3;
        if on_path {
            reached = reached.max(s);
            off = off.max(d);
            if abandoned.is_none_or(|t| r.t_s < t - 1e-9) {
                reached_on_trail = reached_on_trail.max(s);
            }
        }
    }
    BlindLeader {
        leader_lost_at_s: lost_at_s,
        leader_lost_at_m: lost_at_m,
        leader_final_estimate_error_m: leader.last().and_then(|r| {
            r.est_pose
                .map(|e| (e[0] - r.true_pose[0]).hypot(e[1] - r.true_pose[1]))
        }),
        follower_abandoned_at_s: abandoned,
        follower_abandoned_at_m: abandoned_at_m,
        follower_reached_m: reached,
        follower_followed_past_loss_m: lost_at_m.map(|l| reached_on_trail - l),
        follower_max_off_leader_path_m: off,
        follower_distance_travelled_m: rec.distance_travelled_m(m.follower),
    }
}

/// Mean and sample standard deviation of `v` (n − 1 in the denominator).
pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

/// Welch's t statistic and its Welch–Satterthwaite degrees of freedom for two samples of `n`.
pub fn welch_t(m1: f64, s1: f64, m2: f64, s2: f64, n: f64) -> (f64, f64) {
    let (v1, v2) = (s1 * s1 / n, s2 * s2 / n);
    let t = (m1 - m2) / (v1 + v2).sqrt();
    let df = (v1 + v2).powi(2) / (v1 * v1 / (n - 1.0) + v2 * v2 / (n - 1.0));
    (t, df)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trial_statistics_are_the_sample_mean_sd_and_welch_t() {
        let (m, sd) = mean_sd(&[1.0, 2.0, 3.0, 4.0]);
        assert!((m - 2.5).abs() < 1e-12 && (sd - 1.290_994_448_735_805_6).abs() < 1e-12);
        // Two samples of 10 with means 0.815 and 0.599 (sd 0.108, 0.093): t ≈ 4.79, df ≈ 17.6.
        let (t, df) = welch_t(0.815, 0.108, 0.599, 0.093, 10.0);
        assert!((t - 4.792).abs() < 0.01, "{t}");
        assert!((df - 17.6).abs() < 0.1, "{df}");
        assert_eq!(welch_t(0.5, 0.1, 0.5, 0.1, 10.0).0, 0.0);
    }

    #[test]
    fn distance_to_a_polyline_is_to_its_nearest_segment() {
        let line = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]];
        assert!((distance_to_polyline_m([5.0, 2.0], &line) - 2.0).abs() < 1e-12);
        assert!((distance_to_polyline_m([12.0, 5.0], &line) - 2.0).abs() < 1e-12);
        assert!((distance_to_polyline_m([-3.0, -4.0], &line) - 5.0).abs() < 1e-12);
    }
}
