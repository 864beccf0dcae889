use super::*;
use crate::sweep::{plan, run_sweep, run_sweep_shard};
use pheromone_roles::follower::StrategyKind;

fn grid() -> SweepGrid {
    SweepGrid {
        robots: vec![2, 3],
        rc_m: vec![],
        merge: vec![true, false],
        strategies: vec![StrategyKind::Inverse],
        steer: vec![],
        integration: vec![],
        trials: 2,
        duration_s: 15.0,
        figure: Figure::Known,
    }
}

#[test]
fn shards_parse_from_zero_and_cover_every_run_once() {
    assert_eq!("0/4".parse::<Shard>(), Ok(Shard { index: 0, count: 4 }));
    assert_eq!("3/4".parse::<Shard>(), Ok(Shard { index: 3, count: 4 }));
    for bad in ["4/4", "1/0", "-1/4", "1", "a/4", "1/x", "", "0/100001"] {
        let e = bad.parse::<Shard>().unwrap_err();
        assert!(e.contains(&format!("{bad:?}")), "{e}");
    }
    for count in 1..6 {
        let mut seen = vec![0; 17];
        for index in 0..count {
            for i in (Shard { index, count }).indices(17) {
                seen[i] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "{count}: {seen:?}");
    }
}

#[test]
fn the_sweep_id_names_every_setting_but_not_the_threads() {
    let base = Scenario::load("ias-ss").unwrap();
    let id = sweep_id(&base, &grid());
    assert_eq!(id.len(), 16);
    assert_eq!(id, sweep_id(&base, &grid()));
    let other = SweepGrid {
        trials: 3,
        ..grid()
    };
    assert_ne!(id, sweep_id(&base, &other));
    let mut longer = base.clone();
    longer.world.dt_s *= 2.0;
    assert_ne!(id, sweep_id(&longer, &grid()));
}

fn shard_runs(base: &Scenario, k: usize, n: usize) -> ShardRuns {
    let shard = Shard { index: k, count: n };
    let total = plan(base, &grid()).unwrap().len();
    let r = run_sweep_shard(base, &grid(), shard, 1, &|_, _| {}).unwrap();
    ShardRuns {
        dir: PathBuf::from(format!("dir{k}")),
        record: ShardRecord::new(sweep_id(base, &grid()), shard, total, &r),
        runs: r.runs,
    }
}

/// Every value of a run but its wall time, as JSON.
fn values(r: &SweepResult) -> Vec<serde_json::Value> {
    r.runs
        .iter()
        .map(|x| {
            let mut v = serde_json::to_value(x).unwrap();
            v.as_object_mut().unwrap().remove("wall_s");
            v
        })
        .collect()
}

#[test]
fn merged_shards_are_the_unsharded_sweep_and_bad_sets_are_named() {
    let base = Scenario::load("ias-ss").unwrap();
    let whole = run_sweep(&base, &grid(), 2, &|_, _| {}).unwrap();
    let shards: Vec<ShardRuns> = (0..3).map(|k| shard_runs(&base, k, 3)).collect();
    assert_eq!(shards.iter().map(|s| s.runs.len()).sum::<usize>(), 8);
    let mut reversed = shards.clone();
    reversed.reverse();
    let merged = merge(reversed).unwrap();
    assert_eq!(values(&merged), values(&whole));
    let json = |r: &SweepResult| {
        let mut v = serde_json::to_value(r).unwrap();
        let o = v.as_object_mut().unwrap();
        o.remove("wall_s");
        o.remove("jobs");
        v
    };
    assert_eq!(json(&merged), json(&whole));
    assert_eq!(merged.jobs, 3);
    let times = |r: &SweepResult| r.runs.iter().map(|x| x.wall_s).collect::<Vec<_>>();
    assert_eq!(times(&merged)[1], shards[1].record.run_wall_s[0]);
    assert_eq!(times(&merged)[4], shards[1].record.run_wall_s[1]);

    let e = merge(shards[..2].to_vec()).unwrap_err().to_string();
    assert!(e.contains("missing shard(s) 2 of 3"), "{e}");
    let e = merge(vec![
        shards[0].clone(),
        shards[1].clone(),
        shards[1].clone(),
    ])
    .unwrap_err()
    .to_string();
    assert!(e.contains("shard 1/3 given twice: dir1 and dir1"), "{e}");
    let mut other = shards.clone();
    other[2].record.sweep = "0123456789abcdef".into();
    let e = merge(other).unwrap_err().to_string();
    assert!(
        e.contains("dir0 and dir2 are shards of different sweeps")
            && e.contains("0123456789abcdef"),
        "{e}"
    );
    let mut short = shards.clone();
    short[1].runs.pop();
    let e = merge(short).unwrap_err().to_string();
    assert!(
        e.contains("dir1: sweep.csv has 2 row(s), shard.json lists 3"),
        "{e}"
    );
    assert!(matches!(merge(Vec::new()), Err(MergeError::Empty)));
}
