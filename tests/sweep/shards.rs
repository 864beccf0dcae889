//! `pheromone sweep --shard K/N` and `pheromone sweep merge`: four shards merged are the
//! unsharded sweep (sweep.csv, the paper table and the chart byte for byte, the JSON but its
//! threads and wall time, each run's wall time its shard's); a missing, duplicated or foreign
//! shard exits with status 2 naming it.

use std::path::Path;

use crate::harness::*;

/// The tiny sweep every case runs: 2 robot counts × merge on/off × 2 seeds = 8 runs.
const SWEEP: &[&str] = &[
    "sweep",
    "ias-ss",
    "--robots",
    "2,3",
    "--trials",
    "2",
    "--duration",
    "40",
    "--jobs",
    "1",
];

fn sweep(extra: &[&str]) {
    let args: Vec<&str> = SWEEP.iter().chain(extra).copied().collect();
    let o = run(&args);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// sweep.json without the two values that depend on how the runs were spread.
fn json_without_timing(path: &Path) -> serde_json::Value {
    let mut v: serde_json::Value = serde_json::from_slice(&read(path)).unwrap();
    let o = v.as_object_mut().unwrap();
    assert!(o.remove("wall_s").is_some() && o.remove("jobs").is_some());
    v
}

fn merge(dirs: &[&Path], out: &Path) -> std::process::Output {
    let mut args = vec!["sweep", "merge"];
    args.extend(dirs.iter().map(|d| d.to_str().unwrap()));
    args.extend(["--out", out.to_str().unwrap()]);
    run(&args)
}

#[test]
fn four_shards_merged_are_the_unsharded_sweep_and_bad_sets_exit_2() {
    let root = std::env::temp_dir().join(unique("sweep-shards"));
    let dir = |name: &str| root.join(name);
    sweep(&["--out", dir("whole").to_str().unwrap()]);
    let shards: Vec<_> = (0..4).map(|k| dir(&format!("s{k}"))).collect();
    for (k, d) in shards.iter().enumerate() {
        sweep(&["--shard", &format!("{k}/4"), "--out", d.to_str().unwrap()]);
    }
    // Out of order on the command line: the merge puts the rows back in plan order.
    let given: Vec<&Path> = [3, 1, 0, 2].iter().map(|&k| shards[k].as_path()).collect();
    let o = merge(&given, &dir("merged"));
    assert!(o.status.success(), "{}", stderr(&o));
    let (whole, merged) = (dir("whole"), dir("merged"));
    // The CSV holds what the runs computed: the same bytes, however the runs were spread.
    for name in ["sweep.csv", "sweep_paper.md", "sweep_robots.png"] {
        assert!(
            read(&whole.join(name)) == read(&merged.join(name)),
            "{name}"
        );
    }
    // Each run's wall time is its shard's, in sweep_times.csv beside the rows.
    let times = String::from_utf8(read(&merged.join("sweep_times.csv"))).unwrap();
    let keys = |text: &str| -> Vec<String> {
        text.lines()
            .skip(1)
            .map(|l| l.rsplit_once(',').unwrap().0.to_string())
            .collect()
    };
    let csv = String::from_utf8(read(&merged.join("sweep.csv"))).unwrap();
    let key_of_row = |l: &str| l.split(',').take(8).collect::<Vec<_>>().join(",");
    assert_eq!(
        keys(&times),
        csv.lines().skip(1).map(key_of_row).collect::<Vec<_>>()
    );
    assert_eq!(keys(&times).len(), 8);
    let record: serde_json::Value =
        serde_json::from_slice(&read(&shards[2].join("shard.json"))).unwrap();
    assert_eq!(record["runs"], serde_json::json!([2, 6]), "{record}");
    assert_eq!(record["shard"], serde_json::json!({"index": 2, "count": 4}));
    let t2: f64 = times
        .lines()
        .nth(3)
        .unwrap()
        .rsplit_once(',')
        .unwrap()
        .1
        .parse()
        .unwrap();
    assert_eq!(Some(t2), record["run_wall_s"][0].as_f64());
    for name in ["sweep_paper.md", "sweep_robots.png"] {
        assert!(
            read(&whole.join(name)) == read(&merged.join(name)),
            "{name}"
        );
    }
    assert_eq!(
        json_without_timing(&merged.join("sweep.json")),
        json_without_timing(&whole.join("sweep.json"))
    );

    let cases: Vec<(Vec<&Path>, String)> = vec![
        (given[..3].to_vec(), "missing shard(s) 2 of 4".into()),
        (
            vec![&shards[0], &shards[1], &shards[1], &shards[2], &shards[3]],
            format!("shard 1/4 given twice: {}", shards[1].display()),
        ),
    ];
    for (dirs, want) in cases {
        let o = merge(&dirs, &dir("bad"));
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{e}");
        assert!(e.contains(&want), "{want}: {e}");
    }
    // Another seed count is another sweep, named by both directories.
    let other = dir("other");
    let args: Vec<&str> = SWEEP
        .iter()
        .map(|&a| if a == "40" { "41" } else { a })
        .chain(["--shard", "3/4", "--out", other.to_str().unwrap()])
        .collect();
    assert!(run(&args).status.success());
    let o = merge(&[&shards[0], &shards[1], &shards[2], &other], &dir("bad"));
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("are shards of different sweeps") && e.contains("other"),
        "{e}"
    );
    assert!(!dir("bad").exists(), "a refused merge writes nothing");
    let o = run(&["sweep", "ias-ss", "--shard", "4/4"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--shard"), "{}", stderr(&o));
    std::fs::remove_dir_all(&root).unwrap();
}
