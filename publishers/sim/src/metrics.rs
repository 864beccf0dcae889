//! Scenario-specific metrics computed from a run's [`Recording`], the same way for a
//! single-process and a multi-process run.
//! - `mean_path_error_m` (seed 002): the mean distance between the robot and the target path,
//!   sampled every 0.2 s over 10 s.
//! - `exploration` (seed 004): the share of the map's sectors each robot has visited.
//! - `blind_leader` (seed 000): where the leader got lost, when the follower gave the trail up,
//!   and how far the follower strayed from the leader's true path.
//! - `wrong_area` (seed 000 Figs. 1, 24; [`crate::wrong_area`]): whether the followers of a
//!   lost leader end in the wrong area A or reach B, and where they gave the trail up.
//! - with `[mapping]` on (seed 004, [`crate::exploration::mapping_metrics`]):
//!   `exploration_known` (sectors known, visited or merged: `sectors`, `per_robot`, `mean`,
//!   `team`), `known_threshold`, `known_logodds`, `merge`, `rc_m`, `merges`, `merges_rejected`,
//!   `exchanges_refused_lost`, `merge_alignment_error_m` (`mean`, `max`).

use serde::Serialize;

use crate::record::Recording;
use roles::scenario::{BlindLeaderMetric, ExplorationMetric, PathMetric, Scenario};

/// Every metric the scenario asks for, as one JSON object.
pub fn scenario_metrics(scenario: &Scenario, rec: &Recording) -> serde_json::Value {
    let mut out = serde_json::Map::new();
    if !scenario.metrics.paths.is_empty() {
        let by_name: serde_json::Map<String, serde_json::Value> = scenario
            .metrics
            .paths
            .iter()
            .map(|p| (p.name.clone(), serde_json::json!(mean_path_error_m(p, rec))))
            .collect();
        out.insert("mean_path_error_m".into(), by_name.into());
    }
    if let Some(e) = &scenario.metrics.exploration {
        out.insert(
            "exploration".into(),
            serde_json::to_value(exploration(e, rec)).unwrap_or_default(),
        );
    }
    if let Some(b) = &scenario.metrics.blind_leader {
        out.insert(
            "blind_leader".into(),
            serde_json::to_value(blind_leader(scenario, b, rec)).unwrap_or_default(),
        );
    }
    if let Some(w) = &scenario.metrics.wrong_area {
        out.insert(
            "wrong_area".into(),
            serde_json::to_value(crate::wrong_area::wrong_area(scenario, w, rec))
                .unwrap_or_default(),
        );
    }
    if let Some(m) = &rec.mapping {
        out.extend(crate::exploration::mapping_metrics(scenario, m));
    }
    serde_json::Value::Object(out)
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

/// Seed 002's evaluation: mean distance to the path every `every_s` over the window; `None`
/// when the run has no sample in it.
pub fn mean_path_error_m(m: &PathMetric, rec: &Recording) -> Option<f64> {
    let rows = rec.robots.get(&m.robot)?;
    let mut sum = 0.0;
    let mut n = 0usize;
    let mut next = m.from_s;
    let end = m.from_s + m.over_s + 1e-9;
    for r in rows {
        if r.t_s + 1e-9 >= next && r.t_s <= end {
            sum += distance_to_polyline_m([r.true_pose[0], r.true_pose[1]], &m.points);
            n += 1;
            next += m.every_s;
        }
    }
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
    /// When the leader's localizer was made to lose its localization (s), if it was.
    pub leader_lost_at_s: Option<f64>,
    /// How far along its path the leader was then (m).
    pub leader_lost_at_m: Option<f64>,
    /// Distance between the leader's estimate and its true position at the end (m).
    pub leader_final_estimate_error_m: Option<f64>,
    /// When the follower gave the trail up (s), if it did.
    pub follower_abandoned_at_s: Option<f64>,
    /// Where along the leader's path the follower gave up (m).
    pub follower_abandoned_at_m: Option<f64>,
    /// The farthest point along the leader's path the follower reached (m).
    pub follower_reached_m: f64,
    /// How far the follower went past the point where the leader got lost (m): ≈ 0 when it
    /// stops where the leader got lost, large when it follows the lost leader's trail.
    pub follower_beyond_loss_m: Option<f64>,
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
    let lost_at_s = scenario
        .roles(m.leader)
        .and_then(|r| r.localizer.loss.after_s);
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
    let mut off = 0.0f64;
    let mut on_path = false;
    for r in follower {
        let (d, s) = along(r.true_pose);
        on_path |= d < 0.3;
        if on_path {
            reached = reached.max(s);
            off = off.max(d);
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
        follower_beyond_loss_m: lost_at_m.map(|l| reached - l),
        follower_max_off_leader_path_m: off,
        follower_distance_travelled_m: rec.distance_travelled_m(m.follower),
    }
}

/// The metrics object of a run: the keys every scenario has, then the scenario's own.
pub fn metrics_json(
    scenario: &Scenario,
    s: &crate::single::RunSummary,
    rec: &Recording,
) -> serde_json::Value {
    serde_json::json!({
        "scenario": scenario.name,
        "seed": scenario.seed,
        "sim_time_s": s.sim_time_s,
        "steps": s.steps,
        "ticks": s.ticks,
        "field": s.field,
        "robots": s.robots,
        "probes": rec.probes,
        "metrics": scenario_metrics(scenario, rec),
    })
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
