//! Tests of the lockstep graph runs (`run.rs`).

#[cfg(test)]
mod runs {
    use super::super::*;
    use crate::tables::tables_text;

    fn who(r: &RunReport, name: &str) -> u32 {
        r.captures.iter().find(|c| c.region == name).unwrap().robot
    }

    #[test]
    fn corridor_distances_follow_the_paper_order() {
        let sc = RegionsScenario::paper_corridor();
        let s = sc.state().unwrap();
        let dock = sc.dock_node(&s.graph).unwrap();
        let d = s.graph.distances_from(dock, None);
        let mut names: Vec<(f32, &str)> = s
            .regions
            .regions()
            .iter()
            .map(|r| (d[r.node], r.name.as_str()))
            .collect();
        names.sort_by(|a, b| a.0.total_cmp(&b.0));
        let order: Vec<&str> = names.iter().map(|x| x.1).collect();
        assert_eq!(order, ["B", "C", "A", "D", "E"]);
    }

    #[test]
    fn two_robots_split_like_table_2() {
        let sc = RegionsScenario::paper_corridor();
        let r = simulate(&sc, GraphStrategy::Pheromone, 2, 1).unwrap();
        // Table 2, two robots: R1 serves B then A; R2 serves C, D, E.
        assert_eq!(
            ["A", "B", "C", "D", "E"].map(|n| who(&r, n)),
            [1, 1, 2, 2, 2],
            "{:?}",
            r.captures
        );
        assert!(r.finish_s.is_some());
        assert!(r.max_holders.values().all(|&h| h <= 1));
    }

    #[test]
    fn four_robots_first_round_like_table_2() {
        let sc = RegionsScenario::paper_corridor();
        let r = simulate(&sc, GraphStrategy::Pheromone, 4, 1).unwrap();
        // Table 2, four robots, Tw1: A R3, B R1, C R2, D R4.
        assert_eq!(["A", "B", "C", "D"].map(|n| who(&r, n)), [3, 1, 2, 4]);
    }

    /// Fig. 4c in simulated time: region capture finishes before shortest path with conflict
    /// resolution, which spends time in conflicts the capture avoids.
    #[test]
    fn capture_beats_shortest_path_in_simulated_time() {
        let sc = RegionsScenario::paper_corridor();
        for n in 2..=4 {
            let ph = simulate(&sc, GraphStrategy::Pheromone, n, 1).unwrap();
            let sp = simulate(&sc, GraphStrategy::ShortestPath, n, 1).unwrap();
            assert!(
                ph.finish_s.unwrap() < sp.finish_s.unwrap(),
                "{n}: {ph:?} {sp:?}"
            );
            assert!(ph.conflicts < sp.conflicts, "{n}: {ph:?} {sp:?}");
        }
    }

    #[test]
    fn every_run_finishes_within_max_r_and_marks_dead_ends() {
        let sc = RegionsScenario::paper_corridor();
        for strategy in [GraphStrategy::Pheromone, GraphStrategy::ShortestPath] {
            for n in 1..=4 {
                let r = simulate(&sc, strategy, n, 1).unwrap();
                assert!(r.finish_s.is_some(), "{strategy:?} {n}: {r:?}");
                assert!(r.areas.iter().all(|a| a.served), "{r:?}");
                assert!(r.max_holders.values().all(|&h| h <= 1), "{r:?}");
                assert_eq!(r.updates_rejected, 0);
            }
        }
        let r = simulate(&sc, GraphStrategy::Pheromone, 2, 1).unwrap();
        let j1 = r.links.iter().find(|l| l.node == "j1").unwrap();
        assert_eq!(j1.up, "-inf", "the side passage s1 is a dead end: {j1:?}");
        let text = tables_text(&r);
        assert!(text.contains("Table 2") && text.contains("-inf"), "{text}");
    }

    #[test]
    fn a_run_is_deterministic_for_a_seed() {
        let sc = RegionsScenario::paper_corridor();
        let a = simulate(&sc, GraphStrategy::Pheromone, 3, 7).unwrap();
        let b = simulate(&sc, GraphStrategy::Pheromone, 3, 7).unwrap();
        assert_eq!(a, b);
    }
}

#[cfg(test)]
mod backup_tests {
    use super::super::*;
    use crate::tables::tables_text;

    /// Sec. 6.2: R2, told nothing, follows R1's positive pheromone to E node by node; with
    /// anti-pheromone instead it finds nothing to follow and stays at the dock.
    #[test]
    fn a_robot_follows_positive_pheromone_to_the_leaders_goal() {
        let mut sc = RegionsScenario::builtin("regions-backup").unwrap();
        let r = simulate(&sc, GraphStrategy::Pheromone, 2, 1).unwrap();
        // until = "time": the goal is the end of max_time_s (60 s), reached on its last step.
        assert_eq!(r.finish_s, Some(60.0), "{}", tables_text(&r));
        assert!(tables_text(&r).contains("the end of max_time_s when reached: 60.0 s"));
        let (r1, r2) = (&r.robot_reports[0], &r.robot_reports[1]);
        assert_eq!(r1.path.last().map(String::as_str), Some("E"), "{r1:?}");
        assert_eq!(r2.path, r1.path, "{}", tables_text(&r));
        let e = r.links.iter().find(|l| l.node == "D").unwrap();
        assert_eq!(e.right, "1", "R1 deposited +1, R2 nothing: {e:?}");
        sc.robot_roles[0].link_deposit = Some(-1.0);
        let r = simulate(&sc, GraphStrategy::Pheromone, 2, 1).unwrap();
        assert_eq!(r.robot_reports[1].path, ["dock"], "{}", tables_text(&r));
    }
}

#[cfg(test)]
mod skeleton_tests {
    use super::super::*;
    use crate::tables::tables_text;

    /// Fig. 7 / Table 4: on the skeletonized map, 8 robots fill the 7 regions (C with two) and
    /// capture does it with fewer conflicts and sooner than the shortest-path baseline.
    #[test]
    fn eight_robots_capture_every_region_of_the_skeleton_map() {
        let sc = RegionsScenario::paper_skeleton();
        let ph = simulate(&sc, GraphStrategy::Pheromone, 8, 1).unwrap();
        let sp = simulate(&sc, GraphStrategy::ShortestPath, 8, 1).unwrap();
        for r in [&ph, &sp] {
            assert!(r.finish_s.is_some(), "{}", tables_text(r));
            for a in &r.areas {
                assert_eq!(a.held_by.len() as u32, a.max_r, "{a:?}");
            }
            let c = r.areas.iter().find(|a| a.region == "C").unwrap();
            assert_eq!(c.max_r, 2);
            assert!(r
                .max_holders
                .iter()
                .all(|(n, &h)| h <= r.areas.iter().find(|a| &a.region == n).unwrap().max_r));
        }
        assert!(ph.finish_s < sp.finish_s, "{ph:?}\n{sp:?}");
        assert!(ph.conflicts < sp.conflicts);
        // Eight robots, eight places: everyone holds one.
        let mut holders: Vec<u32> = ph.areas.iter().flat_map(|a| a.held_by.clone()).collect();
        holders.sort();
        assert_eq!(holders, (1..=8).collect::<Vec<u32>>());
    }
}

#[cfg(test)]
mod loop_tests {
    use super::super::*;
    use crate::localize::{graph_landmarks, LocalizeConfig};

    /// Every built-in scenario loads and validates (`regions-sparse` and `regions-loop` are
    /// built in, not only files).
    #[test]
    fn every_builtin_regions_scenario_validates() {
        for (name, _) in crate::agent::BUILTIN_REGIONS {
            let sc = RegionsScenario::builtin(name).unwrap();
            assert_eq!(sc.name, name);
            sc.validate().unwrap();
        }
    }

    /// `regions-loop` is what it is for: from the node the robots enter by, both ways round
    /// reach every region (so a link's value chooses between two routes), and its bottom
    /// stretch has no landmark.
    #[test]
    fn the_loop_has_two_routes_to_every_region_and_an_unlit_stretch() {
        let sc = RegionsScenario::builtin("regions-loop").unwrap();
        let s = sc.validate().unwrap();
        let g = &s.graph;
        let entry = g.find("S").unwrap();
        let ways: Vec<usize> = g
            .node(entry)
            .unwrap()
            .links()
            .map(|(_, l)| l.to)
            .filter(|&n| n != sc.dock_node(g).unwrap())
            .collect();
        assert_eq!(ways.len(), 2);
        for r in s.regions.regions() {
            for &w in &ways {
                let d = g.distances_from(w, Some(entry));
                assert!(
                    d[r.node].is_finite(),
                    "{} from {}",
                    r.name,
                    g.nodes()[w].name
                );
            }
        }
        let config = sc.localize.unwrap();
        let lit = graph_landmarks(g, &LocalizeConfig::default());
        let marks = graph_landmarks(g, &config);
        assert!(marks.len() < lit.len());
        assert!(marks.iter().all(|m| m.y_m > 4.0), "{marks:?}");
    }
}
