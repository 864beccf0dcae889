use super::*;
use pheromone_graph::agent::{GraphStrategy, RegionsScenario};
use pheromone_graph::localize::{graph_landmarks, DepositWeight, Localization, LocalizeConfig};
use pheromone_graph::run::{simulate, simulate_with, RunReport};

fn run(weight: DepositWeight, robots: usize, seed: u64) -> RunReport {
    let sc = RegionsScenario::paper_corridor();
    let loc = Localization {
        config: LocalizeConfig::new(weight),
        make_filter: &make_graph_ekf,
    };
    simulate_with(&sc, GraphStrategy::Pheromone, robots, seed, Some(&loc)).unwrap()
}

/// A region holder matches its observations against its region's landmarks only (Algorithm 1
/// lines 10–11): per region, the comparisons it made over those it would have made against the
/// whole map are exactly l(A_i) / |LM| (the captured share), counted by the EKF itself.
#[test]
fn a_region_holder_compares_only_its_regions_landmarks() {
    let sc = RegionsScenario::paper_corridor();
    let state = sc.state().unwrap();
    let cfg = LocalizeConfig::new(DepositWeight::Rho);
    let map = graph_landmarks(&state.graph, &cfg);
    let r = run(DepositWeight::Rho, 2, 1);
    let mut regions_seen = 0;
    for rr in &r.robot_reports {
        let s = rr.localization.as_ref().unwrap();
        assert_eq!(s.landmarks, map.len());
        for (name, (in_region, w)) in &s.by_region {
            // l(A_i), counted independently from the region's shape.
            let shape = &state.regions.regions()[state.regions.find(name).unwrap()].shape;
            let expected = map
                .iter()
                .filter(|l| shape.contains(l.x_m as f32, l.y_m as f32))
                .count();
            assert_eq!(*in_region, expected, "region {name}");
            assert!(0 < expected && expected < map.len(), "region {name}");
            assert!(w.steps > 0 && w.compared > 0, "{name}: {w:?}");
            assert_eq!(w.landmarks_considered, w.steps * expected as u64);
            assert_eq!(w.landmarks_whole_map, w.steps * map.len() as u64);
            // Smaller by the captured share, exactly.
            assert_eq!(
                w.compared * map.len() as u64,
                w.compared_whole_map * expected as u64,
                "region {name}: {w:?}"
            );
            assert!(w.compared < w.compared_whole_map);
            regions_seen += 1;
        }
        // Robots without a region while others hold some skip the captured landmarks (line 13).
        assert!(s.free.steps > 0 && s.free.compared < s.free.compared_whole_map);
        // Nothing captured: the whole map.
        assert_eq!(s.open.compared, s.open.compared_whole_map);
    }
    assert_eq!(regions_seen, 5, "every region of the corridor was held");
    let l = r.localization.as_ref().unwrap();
    let eta1 = l.eta1_compared.unwrap();
    assert!(eta1 > 1.0 && l.eta2_compared.unwrap() > 1.0, "{l:?}");
    // Every region's landmarks are far fewer than the whole map's.
    assert!(l.eta1_eq13.unwrap() > 5.0, "{l:?}");
}

/// ρ_t-weighted deposits stay finite, within [link_deposit, 0) for the −1 of Sec. 4.1, and
/// the final link values stay finite (or −∞ for the dead ends).
#[test]
fn rho_weighted_deposits_are_finite_and_within_bounds() {
    for seed in [1, 2, 3] {
        let r = run(DepositWeight::Rho, 3, seed);
        for rr in &r.robot_reports {
            let s = rr.localization.as_ref().unwrap();
            assert!(s.deposits > 0, "R{}", rr.robot);
            assert!(s.rho_min > 0.0 && s.rho_max <= 1.0, "{s:?}");
            assert!(s.deposit_min >= -1.0 && s.deposit_max < 0.0, "{s:?}");
            assert!(s.position_error_max_m.is_finite() && s.position_error_max_m < 0.5);
        }
        for l in &r.links {
            for v in [&l.up, &l.down, &l.left, &l.right] {
                if v != "NA" && v != "-inf" {
                    let x: f32 = v.parse().unwrap();
                    assert!(x.is_finite() && x <= 0.0, "{}: {v}", l.node);
                }
            }
        }
        // Constant deposits are −1 exactly.
        let c = run(DepositWeight::Constant, 3, seed);
        for rr in &c.robot_reports {
            let s = rr.localization.as_ref().unwrap();
            assert_eq!((s.deposit_min, s.deposit_max), (-1.0, -1.0));
        }
    }
}

/// A localized run is deterministic for a seed (timings aside), and without localization the
/// run and its report are the existing ones.
#[test]
fn localized_runs_are_deterministic_and_off_by_default() {
    let counts = |r: &RunReport| {
        r.robot_reports
            .iter()
            .map(|rr| {
                let s = rr.localization.as_ref().unwrap();
                (
                    s.holding.compared,
                    s.free.compared,
                    s.open.compared,
                    s.observations_used,
                    s.deposit_min.to_bits(),
                )
            })
            .collect::<Vec<_>>()
    };
    let a = run(DepositWeight::Rho, 2, 5);
    let b = run(DepositWeight::Rho, 2, 5);
    assert_eq!(a.captures, b.captures);
    assert_eq!(a.links, b.links);
    assert_eq!(counts(&a), counts(&b));
    // Constant deposits with localization on: the captures of the run without it.
    let sc = RegionsScenario::paper_corridor();
    let plain = simulate(&sc, GraphStrategy::Pheromone, 2, 5).unwrap();
    assert!(plain.localization.is_none());
    assert!(plain.robot_reports.iter().all(|r| r.localization.is_none()));
    let constant = run(DepositWeight::Constant, 2, 5);
    assert_eq!(constant.captures, plain.captures);
    assert_eq!(constant.links, plain.links);
}
