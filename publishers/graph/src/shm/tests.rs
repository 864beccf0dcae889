use super::*;
use crate::{Graph, GraphConfig, RegionConfig, RegionShape, RegionTable};

use pheromone_testkit::unique;

fn state() -> GraphState {
    let cfg: GraphConfig = toml::from_str(
        r#"
        node = [{ name = "a", x_m = 0.0, y_m = 0.0 }, { name = "b", x_m = 3.0, y_m = 0.0 }]
        link = [{ from = "a", to = "b" }]
        "#,
    )
    .unwrap();
    let graph = Graph::explicit(&cfg).unwrap();
    let regions = RegionTable::new(
        &[RegionConfig {
            name: "R".into(),
            node: "b".into(),
            at_m: None,
            shape: RegionShape::Polygon {
                vertices_m: vec![[2.0, -1.0], [4.0, -1.0], [4.0, 1.0], [2.0, 1.0]],
            },
            max_r: 1,
        }],
        |n| graph.find(n).ok(),
    )
    .unwrap();
    GraphState { graph, regions }
}

#[test]
fn snapshot_round_trip() {
    let mut s = state();
    s.apply(GraphUpdate::AddToLink {
        node: 0,
        dir: Dir::Right,
        amount: -1.0,
    })
    .unwrap();
    s.apply(GraphUpdate::DeadEnd {
        node: 1,
        dir: Dir::Left,
    })
    .unwrap();
    s.apply(GraphUpdate::Capture {
        region: 0,
        robot: 7,
    })
    .unwrap();
    let snap = GraphSnapshot::from_state(&s).unwrap();
    assert_eq!(snap.apply_to(&state()).unwrap(), s);
    let w = ContendWire::encode(&ContendMsg {
        robot_id: 3,
        time_stamp_s: 1,
        battery_pct: 50,
        capture_count: 0,
        task_id: 1,
        task_priority: 1,
        lrf_range_m: 4.0,
        rgb_res: crate::RgbRes::Vga,
        region: 0,
    })
    .unwrap();
    assert_eq!(w.decode().unwrap().robot_id, 3);
}

/// Two nodes in one process: a server and a robot that deposits and captures.
#[test]
fn server_and_robot_in_two_nodes() {
    let name = unique("two-nodes");
    let server_node = pheromone_field::shm::create_node(&unique("server")).unwrap();
    let robot_node = pheromone_field::shm::create_node(&unique("robot")).unwrap();
    let mut server = GraphServer::create(&server_node, &name, state()).unwrap();
    let mut reader = GraphReader::attach(&robot_node, &name).unwrap();
    let updater = GraphUpdater::attach(&robot_node, &name, 4).unwrap();
    // The new reader makes the server publish the current state.
    server.serve_once(Duration::from_millis(1)).unwrap();
    let first = reader
        .wait_newer(0, Duration::from_secs(5))
        .unwrap()
        .expect("the current snapshot")
        .seq;
    updater
        .send(GraphUpdate::AddToLink {
            node: 0,
            dir: Dir::Right,
            amount: -1.0,
        })
        .unwrap();
    updater
        .send(GraphUpdate::Capture {
            region: 0,
            robot: 4,
        })
        .unwrap();
    // Malformed: no such link.
    updater
        .send(GraphUpdate::DeadEnd {
            node: 0,
            dir: Dir::Up,
        })
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    while server.counters().applied + server.counters().rejected < 3 {
        assert!(Instant::now() < deadline, "server never got the updates");
        server.serve_once(Duration::from_millis(200)).unwrap();
    }
    let snap = *reader
        .wait_newer(first, Duration::from_secs(5))
        .unwrap()
        .expect("a newer snapshot");
    let s = snap.apply_to(&state()).unwrap();
    assert_eq!(s.graph.link(0, Dir::Right).unwrap().value, -1.0);
    assert_eq!(s.regions.get(0).unwrap().captured_by, vec![4]);
    assert_eq!(snap.updates_rejected, 1);
    assert_eq!(snap.updates_applied, 2);
}
