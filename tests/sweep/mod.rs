//! `pheromone sweep ias-ss`: a tiny sweep's CSV, JSON and charts; bad lists exit with status 2.
//!
//! `pheromone sweep ias-ss` (seed 004's grid of experiments): a tiny sweep writes a CSV row per
//! run, the JSON points and comparisons, and the robots chart (no R_C chart for one radius);
//! bad lists exit with status 2 naming the option and the value.

use std::path::Path;

use crate::harness::*;

mod shards;
mod trail;

fn is_png(path: &Path) -> bool {
    let b = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    // Signature, then the IHDR chunk with a non-zero width and height.
    b.len() > 33
        && &b[..8] == b"\x89PNG\r\n\x1a\n"
        && &b[12..16] == b"IHDR"
        && u32::from_be_bytes([b[16], b[17], b[18], b[19]]) > 0
        && u32::from_be_bytes([b[20], b[21], b[22], b[23]]) > 0
}

#[test]
fn a_tiny_sweep_writes_a_row_per_run_the_points_and_the_robots_chart() {
    let dir = std::env::temp_dir().join(unique("sweep"));
    let out = dir.to_str().unwrap();
    let o = run(&[
        "sweep",
        "ias-ss",
        "--robots",
        "1,2",
        "--trials",
        "2",
        // The old name of --duration, still taken (hidden).
        "--duration-s",
        "120",
        "--jobs",
        "2",
        "--out",
        out,
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // 2 robot counts × merge {on, off} × 2 seeds.
    let csv = std::fs::read_to_string(dir.join("sweep.csv")).unwrap();
    let mut lines = csv.lines();
    assert!(lines
        .next()
        .unwrap()
        .starts_with("robots,rc_m,merge,strategy,steer_on,merge_rule,merge_idle_iterations,seed,"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 8, "{csv}");
    let seeds: Vec<&str> = rows.iter().map(|r| r[7]).collect();
    assert_eq!(seeds, ["1", "2", "1", "2", "1", "2", "1", "2"]);
    for r in &rows {
        // ias-ss steers on the shared field unless --steer says otherwise.
        assert_eq!(r[4], "shared", "{r:?}");
        // The scenario's merge rule and cost unless --merge-rule / --merge-idle say otherwise.
        assert_eq!((r[5], r[6]), ("average", "0"), "{r:?}");
        let known: f64 = r[8].parse().unwrap();
        assert!((0.0..=1.0).contains(&known), "{r:?}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("sweep.json")).unwrap()).unwrap();
    let points = json["points"].as_array().unwrap();
    assert_eq!(points.len(), 4, "{json}");
    for p in points {
        assert_eq!(p["known_mean"]["n"], 2, "{p}");
        assert!(p["known_mean"]["mean"].as_f64().is_some(), "{p}");
        assert!(p["visited_mean"]["sd"].as_f64().is_some(), "{p}");
    }
    // Merge on vs off at each robot count.
    let comparisons = json["comparisons"].as_array().unwrap();
    assert_eq!(comparisons.len(), 2, "{json}");
    assert!(comparisons.iter().all(|c| c["kind"] == "merge"));
    // --json prints the same object.
    assert_eq!(crate::harness::json(&o)["points"], json["points"]);
    assert!(is_png(&dir.join("sweep_robots.png")));
    // The paper's values beside ours, each citing its table.
    let md = std::fs::read_to_string(dir.join("sweep_paper.md")).unwrap();
    assert!(md.contains("| 6 | mean 80 %"), "{md}");
    // One R_C (the scenario's): no R_C chart, and the summary says why.
    assert!(!dir.join("sweep_rc.png").exists());
    assert!(
        stderr(&o).contains("no sweep_rc.png: the sweep has one R_C (8 m)"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_lists_exit_with_status_2_naming_the_option_and_the_value() {
    for (args, option, value) in [
        (&["--robots", "0"][..], "--robots", "0"),
        (&["--robots", "1,x"][..], "--robots", "x"),
        (&["--robots", "12"][..], "--robots", "12"),
        (&["--rc-m", "-1"][..], "--rc-m", "-1"),
        (&["--rc-m", "abc"][..], "--rc-m", "abc"),
        (&["--strategies", "route"][..], "--strategies", "route"),
        (&["--steer", "own-map,theirs"][..], "--steer", "theirs"),
        (&["--trials", "0"][..], "--trials", "0"),
        (
            &["--merge-rule", "average,mean"][..],
            "--merge-rule",
            "mean",
        ),
        (&["--merge-idle", "-1"][..], "--merge-idle", "-1"),
        (&["--merge-idle", "5,5"][..], "--merge-idle", "5"),
    ] {
        let dir = std::env::temp_dir().join(unique("sweep-bad"));
        let mut all = vec!["sweep", "ias-ss", "--duration-s", "5", "--out"];
        all.push(dir.to_str().unwrap());
        all.extend_from_slice(args);
        let o = run(&all);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(option) && e.contains(value), "{args:?}: {e}");
        assert!(!dir.exists(), "{args:?}: nothing written");
    }
}

#[test]
fn sim_trials_reports_each_strategy_over_the_same_seeds_as_single_runs_measure_them() {
    let dir = std::env::temp_dir().join(unique("trials"));
    let out = dir.to_str().unwrap();
    let common = ["--robots", "2", "--duration", "30", "--single-process"];
    let mut args = vec!["sim", "ias-ss", "--trials", "2", "--seed", "7", "--json"];
    args.extend(common);
    args.extend(["--out", out]);
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let t = crate::harness::json(&o);
    let file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("trials.json")).unwrap()).unwrap();
    assert_eq!(file, t, "trials.json is what --json prints");
    assert_eq!(t["trials"], 2);
    assert_eq!(t["seeds"], serde_json::json!([7, 8]));
    assert_eq!(t["robots"], 2);
    let strategies: Vec<&str> = t["exploration"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["strategy"].as_str().unwrap())
        .collect();
    assert_eq!(strategies, ["inverse", "uniform"], "{t}");
    assert!(t["welch_t"].as_f64().unwrap().is_finite(), "{t}");
    // Each trial is the run `sim --seed S` would make with that strategy.
    for (k, strategy) in strategies.iter().enumerate() {
        let e = &t["exploration"][k];
        let per_trial = e["per_trial"].as_array().unwrap();
        for (i, seed) in ["7", "8"].into_iter().enumerate() {
            let mut single = vec!["sim", "ias-ss", "--seed", seed, "--strategy", strategy];
            single.extend(common);
            single.extend(["--no-out", "--json"]);
            let o = run(&single);
            assert!(o.status.success(), "{}", stderr(&o));
            let m = crate::harness::json(&o);
            assert_eq!(
                per_trial[i], m["metrics"]["exploration"]["mean"],
                "{strategy}, seed {seed}"
            );
        }
        let mean = (per_trial[0].as_f64().unwrap() + per_trial[1].as_f64().unwrap()) / 2.0;
        assert!((e["mean"].as_f64().unwrap() - mean).abs() < 1e-12, "{e}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_cost_of_a_merge_runs_in_one_process_and_is_refused_as_processes() {
    let dir = std::env::temp_dir().join(unique("merge-idle"));
    std::fs::create_dir_all(&dir).unwrap();
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenarios/ias-ss-open.toml");
    let text = std::fs::read_to_string(base).unwrap();
    let file = dir.join("idle.toml");
    let text = text.replace("[mapping]\n", "[mapping]\nmerge_idle_iterations = 5\n");
    std::fs::write(&file, text).unwrap();
    let f = file.to_str().unwrap();
    let o = run(&["sim", f, "--duration", "5", "--robots", "2"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("mapping.merge_idle_iterations = 5") && e.contains("--single-process"),
        "{e}"
    );
    let o = run(&[
        "sim",
        f,
        "--duration",
        "5",
        "--robots",
        "2",
        "--single-process",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).unwrap();
}
