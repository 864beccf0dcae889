//! Node-graph signalling (seed 001): link choice, the conflict order, Max-R under concurrent
//! capture attempts, and three robot processes contending for one region over iceoryx2.

use std::cmp::Ordering;
use std::time::{Duration, Instant};

use pheromone_graph::agent::RegionsScenario;
use pheromone_graph::shm::{GraphReader, GraphServer, GraphUpdater};
use pheromone_graph::{
    CaptureOutcome, ContendMsg, Dir, Graph, GraphState, GraphUpdate, RegionConfig, RegionShape,
    RegionTable, RgbRes, DEAD_END,
};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A node `c` with links in the given directions and values.
fn star(values: &[(Dir, f32)]) -> Graph {
    let mut g = Graph::new();
    let c = g.add_node("c", 0.0, 0.0).unwrap();
    for (k, &(d, v)) in values.iter().enumerate() {
        let (dx, dy) = match d {
            Dir::Up => (0.0, 1.0),
            Dir::Down => (0.0, -1.0),
            Dir::Left => (-1.0, 0.0),
            Dir::Right => (1.0, 0.0),
        };
        let n = g.add_node(&format!("n{k}"), dx, dy).unwrap();
        g.add_edge(c, n, Some(d), None).unwrap();
        if v == DEAD_END {
            g.set_dead_end(c, d).unwrap();
        } else {
            g.add_to_link(c, d, v).unwrap();
        }
    }
    g
}

fn link_values() -> impl Strategy<Value = Vec<(Dir, f32)>> {
    let value = prop_oneof![
        Just(0.0f32),
        Just(-1.0),
        Just(-2.0),
        Just(3.0),
        Just(DEAD_END),
    ];
    (proptest::collection::vec(value, 1..=4), Just(Dir::ALL))
        .prop_map(|(vs, dirs)| dirs.into_iter().zip(vs).collect())
}

proptest! {
    /// The same seed gives the same choice; the choice has the largest value.
    #[test]
    fn tie_breaking_is_deterministic_for_a_seed(values in link_values(), seed in any::<u64>()) {
        let g = star(&values);
        let a = g.choose_link(0, &mut ChaCha8Rng::seed_from_u64(seed)).unwrap().unwrap();
        let b = g.choose_link(0, &mut ChaCha8Rng::seed_from_u64(seed)).unwrap().unwrap();
        prop_assert_eq!(a, b);
        let max = values.iter().map(|v| v.1).fold(f32::NEG_INFINITY, f32::max);
        prop_assert_eq!(g.link(0, a).unwrap().value, max);
    }

    /// −∞ is never chosen while a finite link exists.
    #[test]
    fn dead_end_never_chosen_while_another_link_exists(values in link_values(), seed in any::<u64>()) {
        let g = star(&values);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let d = g.choose_link(0, &mut rng).unwrap().unwrap();
        let any_open = values.iter().any(|v| v.1 != DEAD_END);
        prop_assert!(!any_open || g.link(0, d).unwrap().value != DEAD_END);
    }

    /// Taking links with −1 (Sec. 4.1) spreads robots: after k choices on a node with n equal
    /// links, no link was taken twice before every link was taken once.
    #[test]
    fn anti_pheromone_disperses(n in 1usize..=4, seed in any::<u64>()) {
        let mut g = star(&Dir::ALL[..n].iter().map(|&d| (d, 0.0)).collect::<Vec<_>>());
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut taken = Vec::new();
        for _ in 0..n {
            let d = g.choose_link(0, &mut rng).unwrap().unwrap();
            prop_assert!(!taken.contains(&d));
            taken.push(d);
            g.add_to_link(0, d, -1.0).unwrap();
        }
    }
}

/// Every tied link is chosen for some seed (the tie really is random, not "first").
#[test]
fn ties_are_broken_at_random_over_seeds() {
    let g = star(&[
        (Dir::Up, 0.0),
        (Dir::Left, 0.0),
        (Dir::Right, 0.0),
        (Dir::Down, -1.0),
    ]);
    let mut seen = std::collections::HashSet::new();
    for seed in 0..64 {
        seen.insert(
            g.choose_link(0, &mut ChaCha8Rng::seed_from_u64(seed))
                .unwrap()
                .unwrap(),
        );
    }
    assert_eq!(seen.len(), 3, "{seen:?}");
    assert!(!seen.contains(&Dir::Down));
}

fn msg() -> impl Strategy<Value = ContendMsg> {
    (
        (1u32..6, any::<u64>(), 0u8..=100, 0u32..5),
        (
            0u32..3,
            0u32..3,
            prop_oneof![Just(2.0f32), Just(4.0), Just(30.0)],
        ),
        (0usize..RgbRes::ALL.len(), 0u32..4),
    )
        .prop_map(
            |((id, ts, bat, cc), (tid, pr, lrf), (rgb, region))| ContendMsg {
                robot_id: id,
                time_stamp_s: ts,
                battery_pct: bat,
                capture_count: cc,
                task_id: tid,
                task_priority: pr,
                lrf_range_m: lrf,
                rgb_res: RgbRes::ALL[rgb],
                region,
            },
        )
}

/// The first field (in the paper's order) where two messages differ, and who wins on it.
fn paper_winner(a: &ContendMsg, b: &ContendMsg) -> Option<u32> {
    let pick = |a_wins: bool| Some(if a_wins { a.robot_id } else { b.robot_id });
    if a.task_priority != b.task_priority {
        return pick(a.task_priority > b.task_priority);
    }
    if a.battery_pct != b.battery_pct {
        return pick(a.battery_pct > b.battery_pct);
    }
    if a.capture_count != b.capture_count {
        return pick(a.capture_count < b.capture_count);
    }
    if a.lrf_range_m != b.lrf_range_m {
        return pick(a.lrf_range_m > b.lrf_range_m);
    }
    if a.rgb_res != b.rgb_res {
        return pick(a.rgb_res > b.rgb_res);
    }
    if a.robot_id != b.robot_id {
        return pick(a.robot_id < b.robot_id);
    }
    None
}

proptest! {
    /// For every pair: the winner is decided by the first differing field in the paper's order
    /// (priority, battery, capture count (lower wins), sensor spec, smaller id), and the same
    /// whichever robot computes it (message order) and after a JSON round trip.
    #[test]
    fn conflict_order_matches_the_paper(a in msg(), b in msg()) {
        prop_assume!(a.robot_id != b.robot_id);
        let expected = paper_winner(&a, &b).unwrap();
        let ab = ContendMsg::winners(&[a, b], 1);
        let ba = ContendMsg::winners(&[b, a], 1);
        prop_assert_eq!(&ab, &vec![expected]);
        prop_assert_eq!(&ba, &vec![expected]);
        let wire: Vec<ContendMsg> = [b, a]
            .iter()
            .map(|m| ContendMsg::from_json(&m.to_json()).unwrap())
            .collect();
        prop_assert_eq!(ContendMsg::winners(&wire, 1), vec![expected]);
        prop_assert_eq!(a.precedence(&b), b.precedence(&a).reverse());
    }

    /// One field differs at a time, everything else equal: that field decides.
    #[test]
    fn each_field_alone_decides(base in msg(), field in 0usize..6, lo in 0u32..50) {
        let mut a = base;
        let mut b = base;
        a.robot_id = 1;
        b.robot_id = 2;
        let hi = lo + 1;
        // `a` gets the better value of the field; for the id field, a's id is the smaller.
        match field {
            0 => { a.task_priority = hi; b.task_priority = lo; }
            1 => { a.battery_pct = hi as u8; b.battery_pct = lo as u8; }
            2 => { a.capture_count = lo; b.capture_count = hi; }
            3 => { a.lrf_range_m = hi as f32; b.lrf_range_m = lo as f32; }
            4 => { a.rgb_res = RgbRes::FullHd; b.rgb_res = RgbRes::Qvga; }
            _ => {}
        }
        if field < 5 {
            // Make the id favour `b`, so only the field can make `a` win.
            a.robot_id = 2;
            b.robot_id = 1;
        }
        prop_assert_eq!(a.precedence(&b), Ordering::Less);
        prop_assert_eq!(ContendMsg::winners(&[b, a], 1), vec![a.robot_id]);
    }

    /// With several contenders, every robot sorting any permutation gets the same winners.
    #[test]
    fn same_winners_in_every_robot(msgs in proptest::collection::vec(msg(), 1..6),
                                   room in 1usize..4, rot in 0usize..6) {
        let mut other = msgs.clone();
        other.reverse();
        let k = rot % other.len();
        other.rotate_left(k);
        // Duplicated robot ids: the first message seen counts, so keep one per id.
        let mut uniq: Vec<ContendMsg> = Vec::new();
        for m in &msgs {
            if !uniq.iter().any(|u| u.robot_id == m.robot_id) {
                uniq.push(*m);
            }
        }
        let w1 = ContendMsg::winners(&uniq, room);
        let mut uniq2 = uniq.clone();
        uniq2.reverse();
        prop_assert_eq!(&w1, &ContendMsg::winners(&uniq2, room));
        prop_assert_eq!(w1.len(), room.min(uniq.len()));
    }
}

fn one_region_state(max_r: u32) -> GraphState {
    let mut sc = RegionsScenario::paper_corridor();
    sc.regions.truncate(1);
    sc.regions[0].max_r = max_r;
    sc.state().unwrap()
}

#[derive(Debug, Clone)]
enum Op {
    /// Robot decides to capture from the snapshot it saw `lag` updates ago.
    Capture {
        robot: u32,
        lag: usize,
    },
    Release {
        robot: u32,
    },
}

fn ops() -> impl Strategy<Value = Vec<Op>> {
    proptest::collection::vec(
        prop_oneof![
            3 => (1u32..7, 0usize..5).prop_map(|(robot, lag)| Op::Capture { robot, lag }),
            1 => (1u32..7).prop_map(|robot| Op::Release { robot }),
        ],
        1..60,
    )
}

proptest! {
    /// Robots decide from stale snapshots (they all may think the region is free) and their
    /// capture messages reach the one writer in any interleaving: the region never holds more
    /// than Max-R robots, and a robot's view after the writer answered agrees with the table.
    #[test]
    fn max_r_holds_under_concurrent_capture_attempts(max_r in 1u32..4, ops in ops()) {
        let mut table = one_region_state(max_r).regions;
        let mut history = vec![table.clone()];
        for op in ops {
            match op {
                Op::Capture { robot, lag } => {
                    let seen = &history[history.len().saturating_sub(1 + lag)];
                    let r = seen.get(0).unwrap();
                    // The robot only tries if its (possibly stale) view shows room.
                    if r.has_room() && !r.captured_by.contains(&robot) {
                        let out = table.capture(0, robot).unwrap();
                        let now = table.get(0).unwrap();
                        prop_assert_eq!(
                            out == CaptureOutcome::Captured || out == CaptureOutcome::AlreadyHeld,
                            now.captured_by.contains(&robot)
                        );
                    }
                }
                Op::Release { robot } => {
                    let held = table.get(0).unwrap().captured_by.contains(&robot);
                    prop_assert_eq!(table.release(0, robot).is_ok(), held);
                }
            }
            let r = table.get(0).unwrap();
            prop_assert!(r.captured_by.len() as u32 <= r.max_r);
            let mut ids = r.captured_by.clone();
            ids.sort();
            ids.dedup();
            prop_assert_eq!(ids.len(), r.captured_by.len());
            history.push(table.clone());
        }
    }
}

use pheromone_testkit::unique;

/// Six threads, each its own iceoryx2 node, fire capture attempts at one server at once; every
/// published snapshot shows at most Max-R holders.
#[test]
fn threads_capturing_at_once_never_exceed_max_r() {
    let name = unique("threads");
    let max_r = 2;
    let node = pheromone_field::shm::create_node(&unique("srv")).unwrap();
    let mut server = GraphServer::create(&node, &name, one_region_state(max_r)).unwrap();
    let mut reader = GraphReader::attach(&node, &name).unwrap();
    let robots: u32 = 6;
    let rounds = 20;
    // Samples of a publisher that is gone are dropped with it, so every robot stays attached
    // until the server has taken all updates.
    let done = std::sync::Arc::new(std::sync::Barrier::new(robots as usize + 1));
    let handles: Vec<_> = (1..=robots)
        .map(|id| {
            let name = name.clone();
            let done = done.clone();
            std::thread::spawn(move || {
                let node = pheromone_field::shm::create_node(&unique(&format!("r{id}"))).unwrap();
                let up = GraphUpdater::attach(&node, &name, id).unwrap();
                for _ in 0..rounds {
                    up.send(GraphUpdate::Capture {
                        region: 0,
                        robot: id,
                    })
                    .unwrap();
                    up.send(GraphUpdate::Release {
                        region: 0,
                        robot: id,
                    })
                    .unwrap();
                }
                done.wait();
            })
        })
        .collect();
    let total = (robots * rounds * 2) as u64;
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut snapshots = 0;
    loop {
        server.serve_once(Duration::from_millis(100)).unwrap();
        if let Some(s) = reader.poll().unwrap() {
            assert!(s.regions[0].n_captured <= max_r, "{:?}", s.regions[0]);
            snapshots += 1;
        }
        let c = server.counters();
        let r = server.state().regions.get(0).unwrap();
        assert!(r.captured_by.len() as u32 <= max_r);
        if c.applied + c.rejected + c.captures_refused == total {
            break;
        }
        assert!(Instant::now() < deadline, "updates missing: {c:?}");
    }
    done.wait();
    for h in handles {
        h.join().unwrap();
    }
    let c = server.counters();
    assert!(snapshots > 0);
    // Refused captures make their releases fail: every refusal has a rejected release.
    assert_eq!(c.captures_refused, c.rejected, "{c:?}");
    assert!(server
        .state()
        .regions
        .get(0)
        .unwrap()
        .captured_by
        .is_empty());
}

#[test]
fn region_table_refuses_beyond_max_r_with_names() {
    let cfg = [RegionConfig {
        name: "hall".into(),
        node: "x".into(),
        at_m: None,
        shape: RegionShape::Polygon {
            vertices_m: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
        },
        max_r: 1,
    }];
    let e = RegionTable::new(&cfg, |_| None).unwrap_err().to_string();
    assert!(e.contains("'hall'") && e.contains("'x'"), "{e}");
}
