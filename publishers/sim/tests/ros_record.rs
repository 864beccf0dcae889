//! `sim --record` in one process: the MCAP file holds one message per recorded row, frame and
//! applied deposit, in time order, and a file whose writer is dropped mid-run is finished.

use std::collections::BTreeMap;

use pheromone_ros2::record::McapRecorder;
use pheromone_sim::ros_record::SimMcap;
use pheromone_sim::single::{run_single_process, SingleProcessOptions};
use pheromone_world::scenario::{Overrides, Scenario};

/// Topic → log times of its messages.
fn topics(path: &std::path::Path) -> BTreeMap<String, Vec<u64>> {
    let bytes = std::fs::read(path).unwrap();
    let mut out: BTreeMap<String, Vec<u64>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.channel.message_encoding, "cdr");
        out.entry(m.channel.topic.clone())
            .or_default()
            .push(m.log_time);
    }
    out
}

#[test]
fn a_single_process_run_records_its_rows_frames_and_deposits() {
    let mut s = Scenario::load("blind-leader").unwrap();
    s.apply(&Overrides {
        duration_s: Some(22.0),
        ..Overrides::default()
    })
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let mut out = SimMcap::start(McapRecorder::create(&path).unwrap(), &s).unwrap();
    let (summary, rec) = run_single_process(
        &s,
        SingleProcessOptions {
            record: Some(&mut out),
            ..SingleProcessOptions::default()
        },
    )
    .unwrap();
    let totals = out.finish().unwrap();
    let t = topics(&path);
    assert_eq!(t["/pheromone/grid_map"].len(), rec.snapshots.len());
    assert_eq!(
        rec.snapshots.len(),
        2,
        "the snapshot at 20 s and the last frame"
    );
    let shots: Vec<u64> = rec
        .snapshots
        .iter()
        .map(|x| (x.t_s * 1e9).round() as u64)
        .collect();
    assert_eq!(t["/pheromone/grid_map"], shots);
    assert_eq!(
        t["/pheromone/deposits"].len() as u64,
        summary.field.deposits_applied
    );
    assert!(summary.field.deposits_applied > 0);
    for (id, rows) in &rec.robots {
        let want: Vec<u64> = rows.iter().map(|r| (r.t_s * 1e9).round() as u64).collect();
        assert_eq!(t[&format!("/robot_{id}/true_pose")], want);
        assert_eq!(t[&format!("/robot_{id}/estimated_pose")], want);
        assert_eq!(t[&format!("/robot_{id}/true_path")], shots);
    }
    let all: usize = t.values().map(Vec::len).sum();
    assert_eq!(totals.messages as usize, all);
    assert_eq!(totals.deposits, summary.field.deposits_applied);
}

#[test]
fn a_recording_dropped_mid_run_is_finished_with_what_it_got() {
    let s = Scenario::load("blind-leader").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dropped.mcap");
    let out = SimMcap::start(McapRecorder::create(&path).unwrap(), &s).unwrap();
    let mut out = Some(out);
    let mut rows = 0;
    // What a failing run does: its recorder is dropped, not finished.
    let mut poses = |o: &mut SimMcap, k: u64| {
        o.poses(vec![pheromone_sim::ros_record::PoseRow {
            robot: s.world.robots[0].id,
            t_s: k as f64 * 0.1,
            truth: [k as f64, 0.0, 0.0],
            estimate: None,
        }]);
        rows += 1;
    };
    for k in 1..=5 {
        poses(out.as_mut().unwrap(), k);
    }
    drop(out.take());
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    assert_eq!(summary.stats.unwrap().message_count, rows);
}
