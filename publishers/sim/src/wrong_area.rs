//! The `wrong_area` metric (seed 000 Figs. 1 and 24): a leader that lost its localization
//! believes it is in area A while it truly goes to B; do its followers end in A ("blind leading
//! the blind") or leave the trail and reach B? Everything is computed from the recorded true
//! and estimated poses and the follower states, the same way in both modes of a run.

use serde::Serialize;

use crate::recording::{Recording, RobotSample};
use pheromone_messages::FollowerState;
use pheromone_roles::follower::StrategyKind;
use pheromone_world::scenario::{Scenario, WrongAreaMetric};

/// The outcome of a run, for the leader and each follower. Positions are [x, y] in metres.
#[derive(Debug, Clone, Serialize)]
pub struct WrongArea {
    /// Area A and location B as configured (what a picture marks).
    pub a_min_m: [f64; 2],
    pub a_max_m: [f64; 2],
    pub b_m: [f64; 2],
    pub b_radius_m: f64,
    pub leader: LeaderOutcome,
    /// In the order of `followers` (the chain).
    pub followers: Vec<FollowerOutcome>,
    /// Followers whose final true position lies in A.
    pub followers_ended_in_a: usize,
    /// Followers that came within `b_radius_m` of B at some time.
    pub followers_reached_b: usize,
    /// Whether a localizer ran a loss script (`--scripted-loss`); false: the leader's loss
    /// came from its own filter.
    pub scripted_loss: bool,
    /// The leader at 15 points evenly spaced along its true path (seed 000 Figs. 22–23's
    /// L1–L15): its σ and the deposit it made there.
    pub checkpoints: Vec<Checkpoint>,
    /// The leader's first deposit whose peak fell below the first follower's trail threshold
    /// (its `gradient.abandon_below`; seed 000 L12: 8.15 < 10), if it follows by gradient.
    pub deposit_below_threshold: Option<ThresholdCrossing>,
}

/// Where the leader's deposit first fell below the follower's threshold.
#[derive(Debug, Clone, Serialize)]
pub struct ThresholdCrossing {
    pub threshold: f64,
    pub t_s: f64,
    /// Distance along its true path (m), as the checkpoints' `along_m`.
    pub along_m: f64,
    pub true_m: [f64; 2],
    /// Its σ then (m), as the checkpoints' `sigma_m`.
    pub sigma_m: Option<f64>,
    pub deposit_peak: f32,
}

/// The first of `rows`' deposits below `threshold`.
pub fn deposit_below_threshold(rows: &[RobotSample], threshold: f64) -> Option<ThresholdCrossing> {
    let mut along_m = 0.0;
    for (k, r) in rows.iter().enumerate() {
        if k > 0 {
            along_m += dist(xy(rows[k - 1].true_pose), xy(r.true_pose));
        }
        if let Some(peak) = r.deposit_peak.filter(|p| f64::from(*p) < threshold) {
            return Some(ThresholdCrossing {
                threshold,
                t_s: r.t_s,
                along_m,
                true_m: xy(r.true_pose),
                sigma_m: r.est_sigma_m,
                deposit_peak: peak,
            });
        }
    }
    None
}

/// The leader at one of L1–L15.
#[derive(Debug, Clone, Serialize)]
pub struct Checkpoint {
    /// `L1` … `L15`.
    pub label: String,
    pub t_s: f64,
    /// Distance along its true path (m).
    pub along_m: f64,
    pub true_m: [f64; 2],
    pub estimate_m: Option<[f64; 2]>,
    /// √ of the largest eigenvalue of its Σxy (m).
    pub sigma_m: Option<f64>,
    /// The peak of its last deposit at or before this step (γ, or γ·shrink for `intent`).
    pub deposit_peak: Option<f32>,
}

/// L1–L15: 15 points evenly spaced along `rows`' true path, first and last included.
pub fn checkpoints(rows: &[RobotSample]) -> Vec<Checkpoint> {
    let mut along = Vec::with_capacity(rows.len());
    let mut total = 0.0;
    for (k, r) in rows.iter().enumerate() {
        if k > 0 {
            total += dist(xy(rows[k - 1].true_pose), xy(r.true_pose));
        }
        along.push(total);
    }
    if rows.is_empty() {
        return Vec::new();
    }
    (0..15)
        .map(|i| {
            let s = total * f64::from(i) / 14.0;
            let k = along.partition_point(|a| *a < s).min(rows.len() - 1);
            let r = &rows[k];
            Checkpoint {
                label: format!("L{}", i + 1),
                t_s: r.t_s,
                along_m: along[k],
                true_m: xy(r.true_pose),
                estimate_m: r.est_pose.map(xy),
                sigma_m: r.est_sigma_m,
                deposit_peak: rows[..=k].iter().rev().find_map(|r| r.deposit_peak),
            }
        })
        .collect()
}

/// Where the leader truly was and where it believed it was.
#[derive(Debug, Clone, Serialize)]
pub struct LeaderOutcome {
    /// When it lost its localization (s), if it did ([`leader_lost_at_s`]: the script's start,
    /// or the first step its own σ reached `lost_sigma_m`).
    pub lost_at_s: Option<f64>,
    /// Its true position then.
    pub lost_at_m: Option<[f64; 2]>,
    pub true_final_m: Option<[f64; 2]>,
    pub estimate_final_m: Option<[f64; 2]>,
    /// Time its true position spent in A (s): 0 when the trail in A lies where it never was.
    pub true_time_in_a_s: f64,
    /// Time its estimate spent in A (s).
    pub estimate_time_in_a_s: f64,
    pub true_final_distance_to_b_m: Option<f64>,
    /// Distance from the final estimate to A (m, 0 inside).
    pub estimate_final_distance_to_a_m: Option<f64>,
}

/// One follower: where it ended, how long it was in A, whether it reached B, and where and when
/// it gave the trail up and explored on its own.
#[derive(Debug, Clone, Serialize)]
pub struct FollowerOutcome {
    pub id: u32,
    pub final_m: Option<[f64; 2]>,
    /// Distance to the leader's final true position (m).
    pub final_distance_to_leader_m: Option<f64>,
    /// Distance to A (m, 0 inside).
    pub final_distance_to_a_m: Option<f64>,
    pub ended_in_a: bool,
    pub time_in_a_s: f64,
    pub reached_b: bool,
    pub reached_b_at_s: Option<f64>,
    /// First step it reported the trail abandoned (`trail_abandoned` or `leader_lost`).
    pub abandoned_at_s: Option<f64>,
    pub abandoned_at_m: Option<[f64; 2]>,
    /// Straight-line distance from there to the leader's true position when it got lost (m);
    /// `blind_leader.follower_followed_past_loss_m` measures along the leader's path.
    pub abandoned_straight_from_loss_m: Option<f64>,
    /// First step it explored on its own (`leader_lost`).
    pub exploring_from_s: Option<f64>,
    pub exploring_from_m: Option<[f64; 2]>,
}

fn xy(p: [f64; 3]) -> [f64; 2] {
    [p[0], p[1]]
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// When `leader` lost its localization (s), the one figure `wrong_area` and `blind_leader`
/// give: where a loss script runs, when it starts; otherwise, with a `wrong_area` metric for
/// this leader, the first step its own filter's σ reaches that metric's `lost_sigma_m`;
/// otherwise never (`rows`: the leader's recorded samples).
pub fn leader_lost_at_s(scenario: &Scenario, leader: u32, rows: &[RobotSample]) -> Option<f64> {
    if let Some(t) = scenario
        .roles(leader)
        .and_then(|r| r.localizer.loss.after_s)
    {
        return Some(t);
    }
    let m = scenario
        .metrics
        .wrong_area
        .as_ref()
        .filter(|m| m.leader == leader)?;
    let lost = |r: &&RobotSample| r.est_sigma_m.is_some_and(|s| s >= m.lost_sigma_m);
    rows.iter().find(lost).map(|r| r.t_s)
}

/// The first follower's trail threshold (`gradient.abandon_below`), if it follows by gradient.
fn follower_threshold(scenario: &Scenario, m: &WrongAreaMetric) -> Option<f64> {
    let f = scenario.roles(*m.followers.first()?)?.follower.as_ref()?;
    (f.strategy == StrategyKind::Gradient).then(|| f64::from(f.gradient.abandon_below))
}

pub fn wrong_area(scenario: &Scenario, m: &WrongAreaMetric, rec: &Recording) -> WrongArea {
    let dt = scenario.world.dt_s;
    let rows = |id: u32| rec.robots.get(&id).map(Vec::as_slice).unwrap_or(&[]);
    let time_in_a = |rows: &[RobotSample], pos: fn(&RobotSample) -> Option<[f64; 2]>| {
        rows.iter().filter_map(pos).filter(|p| m.in_a(*p)).count() as f64 * dt
    };
    let truth = |r: &RobotSample| Some(xy(r.true_pose));
    let estimate = |r: &RobotSample| r.est_pose.map(xy);

    let leader = rows(m.leader);
    let lost_at_s = leader_lost_at_s(scenario, m.leader, leader);
    let lost_at_m = lost_at_s.and_then(|t| {
        leader
            .iter()
            .find(|r| r.t_s >= t - 1e-9)
            .map(|r| xy(r.true_pose))
    });
    let leader_true_final = leader.last().map(|r| xy(r.true_pose));
    let leader_est_final = leader.last().and_then(estimate);
    let leader_outcome = LeaderOutcome {
        lost_at_s,
        lost_at_m,
        true_final_m: leader_true_final,
        estimate_final_m: leader_est_final,
        true_time_in_a_s: time_in_a(leader, truth),
        estimate_time_in_a_s: time_in_a(leader, estimate),
        true_final_distance_to_b_m: leader_true_final.map(|p| dist(p, m.b_m)),
        estimate_final_distance_to_a_m: leader_est_final.map(|p| m.distance_to_a_m(p)),
    };

    let followers: Vec<FollowerOutcome> = m
        .followers
        .iter()
        .map(|&id| {
            let f = rows(id);
            let final_m = f.last().map(|r| xy(r.true_pose));
            let reached_b_at_s = f.iter().find(|r| m.in_b(xy(r.true_pose))).map(|r| r.t_s);
            let abandoned = rec.first_in_state(id, |s| {
                matches!(s, FollowerState::TrailAbandoned | FollowerState::LeaderLost)
            });
            let exploring = rec.first_in_state(id, |s| s == FollowerState::LeaderLost);
            let abandoned_at_m = abandoned.map(|r| xy(r.true_pose));
            FollowerOutcome {
                id,
                final_m,
                final_distance_to_leader_m: final_m.zip(leader_true_final).map(|(a, b)| dist(a, b)),
                final_distance_to_a_m: final_m.map(|p| m.distance_to_a_m(p)),
                ended_in_a: final_m.is_some_and(|p| m.in_a(p)),
                time_in_a_s: time_in_a(f, truth),
                reached_b: reached_b_at_s.is_some(),
                reached_b_at_s,
                abandoned_at_s: abandoned.map(|r| r.t_s),
                abandoned_at_m,
                abandoned_straight_from_loss_m: abandoned_at_m
                    .zip(lost_at_m)
                    .map(|(a, b)| dist(a, b)),
                exploring_from_s: exploring.map(|r| r.t_s),
                exploring_from_m: exploring.map(|r| xy(r.true_pose)),
            }
        })
        .collect();
    WrongArea {
        a_min_m: m.a_min_m,
        a_max_m: m.a_max_m,
        b_m: m.b_m,
        b_radius_m: m.b_radius_m,
        followers_ended_in_a: followers.iter().filter(|f| f.ended_in_a).count(),
        followers_reached_b: followers.iter().filter(|f| f.reached_b).count(),
        scripted_loss: scenario.has_scripted_loss(),
        checkpoints: checkpoints(leader),
        deposit_below_threshold: follower_threshold(scenario, m)
            .and_then(|t| deposit_below_threshold(leader, t)),
        leader: leader_outcome,
        followers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pheromone_world::scenario::Overrides;

    fn metric() -> WrongAreaMetric {
        WrongAreaMetric {
            leader: 0,
            followers: vec![1],
            a_min_m: [10.0, 3.0],
            a_max_m: [16.0, 9.0],
            b_m: [20.0, 1.5],
            b_radius_m: 2.0,
            lost_sigma_m: 1.5,
        }
    }

    #[test]
    fn distances_to_a_and_b() {
        let m = metric();
        assert_eq!(m.distance_to_a_m([12.0, 5.0]), 0.0);
        assert!(m.in_a([10.0, 9.0]));
        assert!((m.distance_to_a_m([12.0, 1.0]) - 2.0).abs() < 1e-12);
        assert!((m.distance_to_a_m([19.0, 13.0]) - 5.0).abs() < 1e-12);
        assert!(m.in_b([21.0, 2.5]) && !m.in_b([22.0, 3.0]));
    }

    fn sample(t_s: f64, x: f64, y: f64, est: [f64; 2], state: FollowerState) -> RobotSample {
        RobotSample {
            t_s,
            true_pose: [x, y, 0.0],
            est_pose: Some([est[0], est[1], 0.0]),
            est_sigma_m: Some(0.1),
            v_m_per_s: 0.0,
            omega_rad_per_s: 0.0,
            state: Some(state),
            sensed_level: Some(0.0),
            deposit_peak: None,
        }
    }

    #[test]
    fn a_follower_in_a_and_one_that_explored_to_b() {
        let mut s = Scenario::load("wrong-area").unwrap();
        s.apply(&Overrides {
            scripted_loss: true,
            ..Overrides::default()
        })
        .unwrap();
        s.world.dt_s = 1.0;
        let mut m = metric();
        m.followers = vec![1, 2];
        let lost_at = s.robots[0].localizer.loss.after_s.unwrap();
        let mut rec = Recording::default();
        let f = FollowerState::Following;
        // The leader: truly along y = 1.5 to B, its estimate in A from the loss on.
        rec.robots.insert(
            0,
            (0..4)
                .map(|k| {
                    let t = lost_at + k as f64;
                    let x = 10.0 + 3.0 * k as f64;
                    sample(t, x, 1.5, [x, 1.5 + 2.0 * k as f64], f)
                })
                .collect(),
        );
        // Robot 1 follows into A; robot 2 gives up at x = 11 and explores to B.
        let r1 = [(11.0, 1.5), (12.0, 4.0), (13.0, 6.0), (13.0, 7.0)];
        rec.robots.insert(
            1,
            r1.iter()
                .enumerate()
                .map(|(k, p)| sample(lost_at + k as f64, p.0, p.1, [p.0, p.1], f))
                .collect(),
        );
        let r2 = [
            (11.0, 1.5, FollowerState::TrailAbandoned),
            (14.0, 1.5, FollowerState::LeaderLost),
            (19.0, 1.5, FollowerState::LeaderLost),
            (20.0, 1.0, FollowerState::LeaderLost),
        ];
        rec.robots.insert(
            2,
            r2.iter()
                .enumerate()
                .map(|(k, p)| sample(lost_at + k as f64, p.0, p.1, [p.0, p.1], p.2))
                .collect(),
        );
        let w = wrong_area(&s, &m, &rec);
        assert_eq!(w.leader.true_time_in_a_s, 0.0);
        assert_eq!(w.leader.estimate_time_in_a_s, 2.0);
        assert_eq!(w.leader.lost_at_m, Some([10.0, 1.5]));
        let (a, b) = (&w.followers[0], &w.followers[1]);
        assert!(a.ended_in_a && !a.reached_b && a.abandoned_at_s.is_none());
        assert_eq!(a.time_in_a_s, 3.0);
        assert!((a.final_distance_to_leader_m.unwrap() - 6.0f64.hypot(5.5)).abs() < 1e-12);
        assert!(!b.ended_in_a && b.reached_b && b.time_in_a_s == 0.0);
        assert_eq!(b.reached_b_at_s, Some(lost_at + 2.0));
        assert_eq!(b.abandoned_at_s, Some(lost_at));
        assert_eq!(b.abandoned_straight_from_loss_m, Some(1.0));
        assert_eq!(b.exploring_from_m, Some([14.0, 1.5]));
        assert_eq!((w.followers_ended_in_a, w.followers_reached_b), (1, 1));
    }

    #[test]
    fn the_first_deposit_below_the_threshold_is_found_with_its_distance_along_the_path() {
        let peaks = [
            Some(100.0f32),
            None,
            Some(12.0),
            Some(9.5),
            Some(3.0),
            Some(11.0),
        ];
        let rows: Vec<RobotSample> = peaks
            .iter()
            .enumerate()
            .map(|(k, p)| RobotSample {
                deposit_peak: *p,
                est_sigma_m: Some(0.1 * k as f64),
                ..sample(
                    k as f64,
                    2.0 + k as f64,
                    1.5,
                    [0.0, 0.0],
                    FollowerState::Following,
                )
            })
            .collect();
        let c = deposit_below_threshold(&rows, 10.0).expect("9.5 < 10");
        assert_eq!((c.t_s, c.along_m, c.true_m), (3.0, 3.0, [5.0, 1.5]));
        assert_eq!(
            (c.deposit_peak, c.sigma_m, c.threshold),
            (9.5, Some(0.1 * 3.0), 10.0)
        );
        assert!(deposit_below_threshold(&rows, 2.0).is_none());
        // The built-in scenario's first follower rejects a trail below 10.
        let s = Scenario::load("wrong-area").unwrap();
        let m = s.metrics.wrong_area.clone().unwrap();
        assert_eq!(follower_threshold(&s, &m), Some(10.0));
    }

    /// One loss time for both metrics: the script's start where one runs; otherwise the first
    /// step the leader's σ reaches `wrong_area.lost_sigma_m` (0.24 m in `wrong-area`).
    #[test]
    fn the_leader_is_lost_when_its_script_starts_or_when_its_own_sigma_reaches_the_level() {
        let rows: Vec<RobotSample> = [0.02, 0.1, 0.23, 0.24, 0.5, 0.1]
            .iter()
            .enumerate()
            .map(|(k, sigma)| RobotSample {
                est_sigma_m: Some(*sigma),
                ..sample(
                    k as f64,
                    k as f64,
                    1.5,
                    [0.0, 0.0],
                    FollowerState::Following,
                )
            })
            .collect();
        let mut s = Scenario::load("wrong-area").unwrap();
        assert!(!s.has_scripted_loss());
        assert_eq!(leader_lost_at_s(&s, 0, &rows), Some(3.0));
        // Another robot than the metric's leader is never lost by σ.
        assert_eq!(leader_lost_at_s(&s, 1, &rows), None);
        s.apply(&Overrides {
            scripted_loss: true,
            ..Overrides::default()
        })
        .unwrap();
        assert_eq!(leader_lost_at_s(&s, 0, &rows), Some(20.0));
        let mut rec = Recording::default();
        rec.robots.insert(0, rows);
        let m = s.metrics.wrong_area.clone().unwrap();
        let b = s.metrics.blind_leader.clone().unwrap();
        let blind = crate::metrics::blind_leader(&s, &b, &rec);
        assert_eq!(
            blind.leader_lost_at_s,
            wrong_area(&s, &m, &rec).leader.lost_at_s
        );
    }
}
