//! `pheromone sim --compare-filters` (seed 000 Figs. 13–18): one robot, one run per filter, as
//! processes and in one process.

use std::path::Path;

use crate::harness::*;

fn scenario() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/scenarios/filters.toml")
        .to_string_lossy()
        .into_owned()
}

#[test]
fn compare_filters_charts_each_filter_on_the_same_truth_in_both_modes() {
    let file = scenario();
    let dir = std::env::temp_dir().join(unique("compare-filters"));
    let d = dir.to_string_lossy().to_string();
    let base = [
        "sim",
        &file,
        "--compare-filters",
        "--duration",
        "20",
        "--particles",
        "100",
    ];
    let mut args = base.to_vec();
    args.extend(["--json", "--out", &d]);
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let procs = json(&o);
    let mut args = base.to_vec();
    args.extend(["--json", "--no-out", "--single-process"]);
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let single = json(&o);
    assert_eq!(procs, single, "as processes and in one process");

    let filters = procs["filters"].as_array().unwrap();
    let names: Vec<&str> = filters
        .iter()
        .map(|f| f["filter"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["ekf", "ukf", "pf"]);
    assert_eq!(procs["robot"], 0);
    assert_eq!(
        procs["truth_spread_m"], 0.0,
        "the filter changes only the estimate: {procs}"
    );
    for f in filters {
        assert_eq!(f["steps"], 200, "{f}");
        let rms = f["rms_xy_m"].as_f64().unwrap();
        assert!(rms > 0.0 && rms < 1.0, "{f}");
        assert!(f["deposits"].as_u64().unwrap() > 0, "{f}");
    }
    // The EKF of this scenario loses and regains its landmarks: its deposits fall as σ grows.
    let r = filters[0]["log_sigma_log_deposit_r"].as_f64();
    assert!(r.is_some_and(|r| r < -0.5), "{}", filters[0]);

    let csv = std::fs::read_to_string(dir.join("filters.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 3 * 200);
    for name in [
        "filter_error_phi.png",
        "filter_error_x.png",
        "filter_error_y.png",
        "filter_error_xy.png",
        "filter_deposits.png",
        "filter_sigma_deposit.png",
        "filters.json",
    ] {
        let len = std::fs::metadata(dir.join(name))
            .map(|m| m.len())
            .unwrap_or(0);
        assert!(len > 1000, "{name}: {len} bytes");
    }
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("filters.json")).unwrap()).unwrap();
    assert_eq!(written, procs);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn compare_filters_refuses_a_robot_the_scenario_does_not_have() {
    let o = run(&[
        "sim",
        &scenario(),
        "--compare-filters",
        "--compare-robot",
        "7",
        "--no-out",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--compare-robot 7"), "{}", stderr(&o));
    let o = run(&["sim", "--compare-filters", "--filter", "pf", "--no-out"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}
