//! `pheromone sweep --shard K/N` and `pheromone sweep merge`: four shards merged are the
//! unsharded sweep (CSV rows byte for byte but each run's own wall time, the JSON but its
//! threads and wall time, the paper table and the chart byte for byte); a missing, duplicated or
//! foreign shard exits with status 2 naming it.

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
    "--duration-s",
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

/// A sweep.csv without its last column (wall_s: each run's own measured time).
fn without_wall_time(csv: &[u8]) -> String {
    let text = String::from_utf8(csv.to_vec()).unwrap();
    text.lines()
        .map(|l| &l[..l.rfind(',').unwrap()])
        .collect::<Vec<_>>()
        .join("\n")
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
    let csv = read(&merged.join("sweep.csv"));
    assert_eq!(
        without_wall_time(&csv),
        without_wall_time(&read(&whole.join("sweep.csv")))
    );
    // Each merged row is its shard's row, wall time included, byte for byte.
    let mut rows: Vec<String> = Vec::new();
    for d in &shards {
        let text = String::from_utf8(read(&d.join("sweep.csv"))).unwrap();
        rows.extend(text.lines().skip(1).map(str::to_string));
    }
    let merged_rows: Vec<&str> = std::str::from_utf8(&csv).unwrap().lines().skip(1).collect();
    assert_eq!(merged_rows.len(), 8);
    assert!(merged_rows.iter().all(|r| rows.iter().any(|x| x == r)));
    for name in ["sweep_paper.md", "sweep_robots.png"] {
        assert!(read(&whole.join(name)) == read(&merged.join(name)), "{name}");
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
    assert!(e.contains("are shards of different sweeps") && e.contains("other"), "{e}");
    assert!(!dir("bad").exists(), "a refused merge writes nothing");
    let o = run(&["sweep", "ias-ss", "--shard", "4/4"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--shard"), "{}", stderr(&o));
    std::fs::remove_dir_all(&root).unwrap();
}
