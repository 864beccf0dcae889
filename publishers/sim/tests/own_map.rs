//! Seed 004 as the paper ran it (issue 30): each robot steers on its own (merged) map
//! (`[mapping] steer_on = "own-map"`, `sim --steer own-map`), so merging changes where robots
//! go; on the shared field it changes only what they know. Runs in one process; that the
//! processes run equals it is tests/processes.

use pheromone_roles::mapper::{pose_in_frame, SteerOn};
use pheromone_sim::exploration::exploration_merged;
use pheromone_sim::metrics::{scenario_metrics, ScenarioMetrics};
use pheromone_sim::recording::{Recording, RobotSample};
use pheromone_sim::single::{run_single_process, SingleProcessOptions};
use pheromone_world::scenario::{ExplorationMetric, Overrides, Scenario};
use pheromone_world::team::MergeEvent;

/// ias-ss with `robots` robots for `duration_s`, mapping on (`merge`), steering on `steer`;
/// exchanges from iteration 11, the same pair every 10 iterations.
fn run(
    seed: u64,
    robots: usize,
    duration_s: f64,
    (merge, rc_m): (bool, f64),
    steer: SteerOn,
) -> (Recording, ScenarioMetrics) {
    let mut s = Scenario::load("ias-ss").unwrap();
    s.apply(&Overrides {
        seed: Some(seed),
        robots: Some(robots),
        duration_s: Some(duration_s),
        merge: Some(merge),
        rc_m: Some(rc_m),
        steer_on: Some(steer),
        ..Overrides::default()
    })
    .unwrap();
    s.mapping.start_iteration = 10;
    s.mapping.every_iterations = 10;
    let (summary, rec) = run_single_process(&s, SingleProcessOptions::default()).unwrap();
    assert_eq!(summary.field.nan_cells, 0);
    let m = scenario_metrics(&s, &rec);
    (rec, m)
}

fn visited(m: &ScenarioMetrics) -> Vec<f64> {
    m.exploration
        .as_ref()
        .expect("exploration")
        .per_robot
        .clone()
}

fn merges(m: &ScenarioMetrics) -> usize {
    m.mapping.as_ref().expect("mapping metrics").merges
}

#[test]
fn with_own_map_steering_merging_changes_where_robots_go_and_on_the_shared_field_it_does_not() {
    for seed in [1, 2] {
        let shared_on = run(seed, 3, 60.0, (true, 30.0), SteerOn::Shared).1;
        let shared_off = run(seed, 3, 60.0, (false, 30.0), SteerOn::Shared).1;
        let own_on = run(seed, 3, 60.0, (true, 30.0), SteerOn::OwnMap).1;
        let own_off = run(seed, 3, 60.0, (false, 30.0), SteerOn::OwnMap).1;
        assert!(merges(&shared_on) > 0 && merges(&own_on) > 0);
        assert_eq!(merges(&own_off), 0);
        // Shared field: the same sectors visited, seed for seed.
        assert_eq!(visited(&shared_on), visited(&shared_off), "seed {seed}");
        // Own map: merging changed the robots' motion.
        let (a, b) = (&own_on.mapping, &own_off.mapping);
        println!(
            "seed {seed}: visited own-map merge {:?} / no merge {:?}; shared {:?}; merged count {:?} / {:?}",
            visited(&own_on),
            visited(&own_off),
            visited(&shared_on),
            a.as_ref().and_then(|m| m.exploration_merged.as_ref()).map(|e| e.mean),
            b.as_ref().and_then(|m| m.exploration_merged.as_ref()).map(|e| e.mean),
        );
        assert_ne!(visited(&own_on), visited(&own_off), "seed {seed}");
        assert_eq!(a.as_ref().unwrap().steer_on, "own-map");
        assert_eq!(shared_on.mapping.as_ref().unwrap().steer_on, "shared");
    }
}

/// Every cell of robot `id`'s final pheromone map holding more than `floor` lies within `reach_m`
/// of a position its estimate went through (both in its map's frame); returns the largest
/// distance found.
fn farthest_pheromone_from_own_path_m(rec: &Recording, id: u32, floor: f32) -> f64 {
    let map = &rec.mapping.as_ref().unwrap().maps[&id];
    let path: Vec<[f64; 3]> = rec.robots[&id]
        .iter()
        .filter_map(|r| r.est_pose)
        .map(|p| pose_in_frame(map.start, p))
        .collect();
    let g = &map.geometry;
    let mut farthest: f64 = 0.0;
    for y in 0..g.height {
        for x in 0..g.width {
            if map.pheromone[g.index(x, y)] <= floor {
                continue;
            }
            let (cx, cy) = g.world_from_grid(x, y);
            let d = path
                .iter()
                .map(|p| (p[0] - cx as f64).hypot(p[1] - cy as f64))
                .fold(f64::INFINITY, f64::min);
            farthest = farthest.max(d);
        }
    }
    farthest
}

#[test]
fn a_robot_that_never_meets_another_never_sees_its_pheromone_in_its_map() {
    // Robots 0 and 1 start 29 m apart; R_C = 0.05 m: they never meet in 120 s.
    let (rec, m) = run(3, 2, 120.0, (true, 0.05), SteerOn::OwnMap);
    assert_eq!(merges(&m), 0);
    for id in [0, 1] {
        let d = farthest_pheromone_from_own_path_m(&rec, id, 1e-6);
        // The deposit kernel reaches 0.6 m; a cell centre is at most half a diagonal off.
        assert!(
            d <= 0.6 + 0.15,
            "robot {id}: pheromone {d:.2} m from its own path"
        );
    }
    // Within reach (R_C = 30 m) they merge, and each map holds the other's trail, far from
    // its own path: the check above would see it.
    let (rec, m) = run(3, 2, 120.0, (true, 30.0), SteerOn::OwnMap);
    assert!(merges(&m) > 0);
    for id in [0, 1] {
        let d = farthest_pheromone_from_own_path_m(&rec, id, 1e-6);
        assert!(
            d > 5.0,
            "robot {id}: merged pheromone only {d:.2} m from its path"
        );
    }
}

fn sample(step: u64, x_m: f64) -> RobotSample {
    RobotSample {
        t_s: step as f64 * 0.1,
        true_pose: [x_m, 1.0, 0.0],
        est_pose: None,
        est_sigma_m: None,
        v_m_per_s: 0.0,
        omega_rad_per_s: 0.0,
        state: None,
        sensed_level: None,
        deposit_peak: None,
    }
}

#[test]
fn a_sector_counts_when_visited_or_received_through_a_merge_transitively() {
    // Four sectors in a row, 1 m each; robot r sits in sector r for steps 1..=20, and robot 0
    // reaches sector 3 at step 15.
    let m = ExplorationMetric {
        min_m: [0.0, 0.0],
        max_m: [4.0, 2.0],
        cols: 4,
        rows: 1,
    };
    let mut rec = Recording::default();
    for r in 0..3u32 {
        let rows = (1..=20)
            .map(|k| {
                let x = if r == 0 && k >= 15 {
                    3.5
                } else {
                    r as f64 + 0.5
                };
                sample(k, x)
            })
            .collect();
        rec.robots.insert(r, rows);
    }
    let merge = |step, dst, src| MergeEvent {
        step,
        dst,
        src,
        alignment_error_m: 0.0,
    };
    // 1 takes 0's map at step 15 (0's state at the end of step 14: sector 0 only), then 2
    // takes 1's at step 16: sectors 0, 1 and its own 2.
    let merges = [merge(16, 2, 1), merge(15, 1, 0)];
    let e = exploration_merged(&m, &rec, &merges, 0.1);
    assert_eq!(e.sectors, 4);
    assert_eq!(e.per_robot, vec![0.5, 0.5, 0.75]);
    assert_eq!(e.team, 1.0);
    assert!((e.mean - (0.5 + 0.5 + 0.75) / 3.0).abs() < 1e-12);
    // Without merges: only what each visited.
    let e = exploration_merged(&m, &rec, &[], 0.1);
    assert_eq!(e.per_robot, vec![0.5, 0.25, 0.25]);
    // Merges of one step use the states before it: 0 ↔ 1 at step 10 swap sectors 0 and 1 only.
    let e = exploration_merged(&m, &rec, &[merge(10, 0, 1), merge(10, 1, 0)], 0.1);
    assert_eq!(e.per_robot, vec![0.75, 0.5, 0.25]);
}
