//! Node-graph runs (seed 001) as processes: `graph`, `graph-robot` and `sim regions…`.

use std::time::Duration;

use super::harness::*;

/// One region at the dock, three robots leaving at once: all claim it in the same step.
fn one_region_scenario(max_r: u32) -> std::path::PathBuf {
    let path = std::env::temp_dir().join(format!("{}.toml", unique("one-region")));
    std::fs::write(
        &path,
        format!(
            r#"
name = "one-region"
seed = 3
robots = [3]
dock = "dock"

[graph]
node = [{{ name = "dock", x_m = 0.0, y_m = 0.0 }}, {{ name = "far", x_m = 3.0, y_m = 0.0 }}]
link = [{{ from = "dock", to = "far" }}]

[[region]]
name = "R"
node = "dock"
max_r = {max_r}
shape = {{ polygon = {{ vertices_m = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]] }} }}

[regions_sim]
start_interval_s = 0.0
work_s_per_m2 = 1000.0
max_time_s = 60.0
until = "captured"
"#
        ),
    )
    .unwrap();
    path
}

/// Three robot processes contend for one region: each announces the paper's JSON message over
/// iceoryx2, collects the others' and decides. Equal priority, battery and capture count: the
/// smaller id wins. The writer's table shows exactly the winners, never more than Max-R.
#[test]
fn three_robot_processes_contend_for_one_region() {
    for (max_r, winners) in [(1u32, vec![1u64]), (2, vec![1, 2])] {
        let file = one_region_scenario(max_r);
        let f = file.display().to_string();
        let name = unique("contend");
        let writer = Proc::spawn(&[
            "graph",
            "--scenario",
            &f,
            "--name",
            &name,
            "--robots",
            "3",
            "--json",
        ]);
        let robots: Vec<Proc> = (1..=3)
            .map(|id| {
                Proc::spawn(&[
                    "graph-robot",
                    "--scenario",
                    &f,
                    "--name",
                    &name,
                    "--robot",
                    &id.to_string(),
                    "--robots",
                    "3",
                    "--json",
                ])
            })
            .collect();
        let o = writer.wait_exit(Duration::from_secs(60));
        assert!(o.status.success(), "writer: {}", stderr(&o));
        let r = json(&o);
        let area = &r["areas"][0];
        let held: Vec<u64> = area["held_by"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(held, winners, "max_r {max_r}: {r}");
        assert_eq!(r["captures"].as_array().unwrap().len(), winners.len());
        assert_eq!(r["conflicts"], 1, "three claimants, room {max_r}: {r}");
        assert_eq!(r["captures_refused"], 0);
        assert_eq!(r["updates_rejected"], 0);
        for p in robots {
            let what = p.what.clone();
            let o = p.wait_exit(Duration::from_secs(30));
            assert!(o.status.success(), "{what}: {}", stderr(&o));
            let s = json(&o);
            // Every claimant saw the same three messages and the same conflict.
            assert_eq!(s["conflicts"], 1, "{what}: {s}");
            assert_eq!(s["refused"], 0, "{what}: {s}");
        }
        std::fs::remove_file(&file).unwrap();
    }
}

fn runs(v: &serde_json::Value) -> Vec<serde_json::Value> {
    let mut runs = v["runs"].as_array().unwrap().clone();
    for r in &mut runs {
        let mut rr = r["robot_reports"].as_array().unwrap().clone();
        rr.sort_by_key(|x| x["robot"].as_u64());
        r["robot_reports"] = serde_json::Value::Array(rr);
    }
    runs
}

/// `sim regions` as processes gives the same runs as in one process, region capture beats the
/// shortest-path baseline, and nothing of the run is left behind.
#[test]
fn sim_regions_as_processes_matches_one_process_and_beats_shortest_path() {
    let p = Proc::spawn(&["sim", "regions", "--robots", "3", "--json", "--no-out"]);
    let tag = format!("sim{}g", p.pid());
    let o = p.wait_exit(Duration::from_secs(300));
    assert!(o.status.success(), "{}", stderr(&o));
    let procs = json(&o);
    assert_eq!(procs["mode"], "processes");
    let o = run(&[
        "sim",
        "regions",
        "--robots",
        "3",
        "--json",
        "--no-out",
        "--single-process",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let single = json(&o);
    assert_eq!(runs(&procs), runs(&single));
    let c = &procs["comparison"][0];
    assert_eq!(c["robots"], 3);
    let ph = c["pheromone_finish_s"].as_f64().unwrap();
    let sp = c["shortest_path_finish_s"].as_f64().unwrap();
    assert!(ph < sp, "capture {ph} s, shortest path {sp} s: {c}");
    assert_eq!(c["pheromone_conflicts"], 0, "{c}");
    let text = stderr(&o);
    assert!(
        text.contains("Table 2") && text.contains("Table 3") && text.contains("Table 4"),
        "{text}"
    );
    let left = super::services_named(&tag);
    assert!(left.is_empty(), "services left behind: {left:?}");
}

/// Fig. 7 / Table 4 as nine processes: 8 robots fill the 7 regions of the skeletonized map,
/// C (Max-R 2) with two.
#[test]
fn eight_robot_processes_capture_the_skeleton_map() {
    let dir = std::env::temp_dir().join(unique("skeleton-out"));
    let o = Proc::spawn(&[
        "sim",
        "regions-skeleton",
        "--strategy",
        "pheromone",
        "--json",
        "--out",
        &dir.display().to_string(),
    ])
    .wait_exit(Duration::from_secs(600));
    assert!(o.status.success(), "{}", stderr(&o));
    let m = json(&o);
    let r = &m["runs"][0];
    assert_eq!(r["robots"], 8);
    assert!(r["finish_s"].as_f64().is_some(), "{r}");
    for a in r["areas"].as_array().unwrap() {
        assert_eq!(
            a["held_by"].as_array().unwrap().len() as u64,
            a["max_r"].as_u64().unwrap(),
            "{a}"
        );
    }
    let c = r["areas"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["region"] == "C")
        .unwrap();
    assert_eq!(c["max_r"], 2);
    // Held regions are never released: each robot still counts the one it captured.
    let reports = r["robot_reports"].as_array().unwrap();
    assert_eq!(reports.len(), 8, "{r}");
    for rr in reports {
        assert_eq!(rr["capture_count"], 1, "{rr}");
    }
    let tables = std::fs::read_to_string(dir.join("tables.txt")).unwrap();
    assert!(!tables.contains("0 capture(s)"), "{tables}");
    assert!(tables.contains("-inf"), "dead ends marked: {tables}");
    assert!(dir.join("metrics.json").is_file());
    let png = std::fs::read(dir.join("graph_pheromone_8robots.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG"), "a PNG picture of the graph");
    let summary = std::fs::read(dir.join("summary.png")).unwrap();
    assert!(summary.starts_with(b"\x89PNG"), "the run's summary picture");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_regions_input_exits_with_status_2_and_names_it() {
    let o = run(&["sim", "regions", "--robots", "0", "--no-out"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("robots 0"), "{}", stderr(&o));
    let o = run(&["sim", "regions", "--strategy", "random", "--no-out"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("'random'"), "{}", stderr(&o));
    let o = run(&["sim", "regions", "--slam", "--no-out"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--slam"), "{}", stderr(&o));
    // The localizer's captured-area option (Algorithm 1 lines 10–14).
    let o = run(&["localizer", "--landmark-region", "5,0,1,3"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--landmark-region") && stderr(&o).contains("5,0,1,3"),
        "{}",
        stderr(&o)
    );
    // Grid robots have their own localizers.
    let o = run(&["sim", "trail", "--localize", "rho", "--no-out"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--localize"), "{}", stderr(&o));
    let o = run(&["sim", "regions", "--localize", "sometimes", "--no-out"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("sometimes"), "{}", stderr(&o));
    let o = run(&["graph-robot", "--robot", "5", "--robots", "3"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--robot 5"), "{}", stderr(&o));
    let path = std::env::temp_dir().join(format!("{}.toml", unique("bad-regions")));
    std::fs::write(
        &path,
        "name = \"x\"\ndock = \"nowhere\"\n[graph]\nnode = [{ name = \"a\", x_m = 0.0, y_m = 0.0 }]\n[[region]]\nname = \"R\"\nnode = \"a\"\nshape = { polygon = { vertices_m = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]] } }\n",
    )
    .unwrap();
    let p = path.display().to_string();
    let o = run(&["sim", &p, "--no-out"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("nowhere"), "{}", stderr(&o));
    std::fs::write(&path, "name = \"x\"\ndock = \"a\"\n[graph]\nnode = 3\n").unwrap();
    let o = run(&["sim", &p, "--no-out"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains(&p), "{}", stderr(&o));
    std::fs::remove_file(&path).unwrap();
}

/// `--localize rho` (seed 001 Algorithm 1 coupled to capture): the run reports the landmark
/// comparisons and η1, η2; a bad `[localize]` setting is bad input naming its key.
#[test]
fn sim_regions_localize_reports_the_landmark_work() {
    let o = run(&[
        "sim",
        "regions",
        "--single-process",
        "--localize",
        "rho",
        "--robots",
        "2",
        "--strategy",
        "pheromone",
        "--no-out",
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("η1 = 16.67 (eq. 13)"), "{}", stderr(&o));
    // The timed ratio is labelled as the wall-clock figure it is, in the tables and the JSON.
    assert!(stderr(&o).contains("wall clock"), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let l = &runs(&v)[0]["localization"];
    assert_eq!(l["config"]["deposit"], "rho");
    assert_eq!(l["all"]["landmarks"], 50);
    assert!(l["eta1_compared"].as_f64().unwrap() > 1.0, "{l}");
    assert!(
        l.get("eta1_time").is_none() && l["eta1_wall_clock"].is_number(),
        "{l}"
    );
    let held = &l["all"]["holding"];
    assert!(held["compared"].as_u64().unwrap() < held["compared_whole_map"].as_u64().unwrap());
    let path = std::env::temp_dir().join(format!("{}.toml", unique("bad-localize")));
    let text =
        pheromone_graph::agent::PAPER_CORRIDOR.to_string() + "\n[localize]\nrho_ref_m = -1.0\n";
    std::fs::write(&path, text).unwrap();
    let p = path.display().to_string();
    for mode in [&["--single-process"][..], &[]] {
        let mut args = vec!["sim", &p, "--localize", "rho", "--no-out"];
        args.extend_from_slice(mode);
        let o = run(&args);
        assert_eq!(o.status.code(), Some(2), "{mode:?}: {}", stderr(&o));
        assert!(stderr(&o).contains("`rho_ref_m` = -1"), "{}", stderr(&o));
    }
    std::fs::remove_file(&path).unwrap();
}

/// Drops the wall-clock measurements of a localized run (the step times and the η measured
/// from them: `*_ns`, `eta1_wall_clock`, `eta2_wall_clock`), which differ from run to run.
fn without_step_times(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Object(m) => {
            m.retain(|k, _| !(k.ends_with("_ns") || k.ends_with("_wall_clock")));
            m.values_mut().for_each(without_step_times);
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(without_step_times),
        _ => {}
    }
}

/// The iceoryx2 nodes, alive or dead, whose names contain `tag`.
fn nodes_named(tag: &str) -> Vec<String> {
    use iceoryx2::node::NodeView;
    use iceoryx2::prelude::*;
    let mut names = Vec::new();
    Node::<pheromone_field::shm::Svc>::list(iceoryx2::config::Config::global_config(), |state| {
        let name = |d: &Option<iceoryx2::node::NodeDetails>| {
            d.as_ref().map(|d| d.name().as_str().to_string())
        };
        let name = match &state {
            NodeState::Alive(v) => name(v.details()),
            NodeState::Dead(v) => name(v.details()),
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => None,
        };
        names.extend(name.filter(|n| n.contains(tag)));
        CallbackProgression::Continue
    })
    .expect("list the iceoryx2 nodes");
    names
}

/// `--localize` as processes (each `graph-robot` owns its localizer) gives the runs of
/// `--single-process` key by key: captures, link values, paths, deposits, ρ_t, landmark counts,
/// comparisons and η1, η2 by count (all but the step times), for both deposit weights, on the
/// built-in corridors and on the loop; and the run leaves no service and no node behind.
#[test]
fn sim_regions_localize_as_processes_matches_one_process() {
    let cases: [(&str, &str, &[&str]); 5] = [
        ("regions-sparse", "rho", &[]),
        ("regions-sparse", "constant", &[]),
        (
            "regions",
            "rho",
            &["--robots", "3", "--strategy", "pheromone"],
        ),
        ("regions-loop", "rho", &["--seed", LOOP_SEED]),
        ("regions-loop", "constant", &["--seed", LOOP_SEED]),
    ];
    for (scenario, weight, extra) in cases {
        let mut args = vec!["sim", scenario, "--localize", weight, "--json", "--no-out"];
        args.extend_from_slice(extra);
        let p = Proc::spawn(&args);
        let tag = format!("sim{}g", p.pid());
        let o = p.wait_exit(Duration::from_secs(300));
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        let procs = json(&o);
        assert_eq!(procs["mode"], "processes");
        args.push("--single-process");
        let o = run(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        let single = json(&o);
        let (mut a, mut b) = (runs(&procs), runs(&single));
        assert!(!a.is_empty());
        for r in &a {
            let l = &r["localization"];
            assert_eq!(l["config"]["deposit"], weight, "{l}");
            assert!(l["all"]["deposits"].as_u64().unwrap() > 0, "{l}");
            assert!(l["eta1_compared"].as_f64().is_some(), "{l}");
            for rr in r["robot_reports"].as_array().unwrap() {
                assert!(
                    rr["localization"]["holding"]["steps"].as_u64().is_some(),
                    "{rr}"
                );
            }
        }
        a.iter_mut().for_each(without_step_times);
        b.iter_mut().for_each(without_step_times);
        let mut diffs = Vec::new();
        let (a, b) = (serde_json::Value::Array(a), serde_json::Value::Array(b));
        crate::processes::differences(&a, &b, "runs", &mut diffs);
        assert!(diffs.is_empty(), "{args:?}: {diffs:#?}");
        let left = super::services_named(&tag);
        assert!(left.is_empty(), "services left behind: {left:?}");
        let left = nodes_named(&tag);
        assert!(left.is_empty(), "nodes left behind: {left:?}");
    }
}

/// Sec. 6.2 as processes: R2, told nothing, follows R1's positive pheromone to E.
#[test]
fn a_robot_process_follows_the_pheromone_of_another_to_its_goal() {
    let o = Proc::spawn(&["sim", "regions-backup", "--json", "--no-out"])
        .wait_exit(Duration::from_secs(300));
    assert!(o.status.success(), "{}", stderr(&o));
    let m = json(&o);
    let rr = m["runs"][0]["robot_reports"].as_array().unwrap().clone();
    let path = |id: u64| {
        rr.iter()
            .find(|r| r["robot"] == id)
            .unwrap_or_else(|| panic!("robot {id} missing: {m}"))["path"]
            .clone()
    };
    assert_eq!(path(1).as_array().unwrap().last().unwrap(), "E", "{m}");
    assert_eq!(path(2), path(1), "{m}");
}

/// A seed of `regions-loop` on which `--localize rho` changes the captures (tested below).
const LOOP_SEED: &str = "1";

/// `regions-loop` (two routes to every target, the left half unlit): ρ_t-weighted deposits
/// change which robot captures what, and when, against constant ones on the same seed; `sim
/// --trials` pairs the two weights per seed and reports the paired t; `--trials` with
/// `--localize` is bad input.
#[test]
fn on_the_loop_rho_changes_a_capture_result_and_trials_report_the_paired_t() {
    let captures = |weight: &str| {
        let args = [
            "sim",
            "regions-loop",
            "--single-process",
            "--localize",
            weight,
            "--seed",
            LOOP_SEED,
            "--json",
            "--no-out",
        ];
        let o = run(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        let r = runs(&json(&o))[0].clone();
        (r["captures"].clone(), r["finish_s"].clone())
    };
    let (constant, rho) = (captures("constant"), captures("rho"));
    assert_ne!(constant.0, rho.0, "the same captures with both weights");
    let o = run(&[
        "sim",
        "regions-loop",
        "--single-process",
        "--trials",
        "2",
        "--seed",
        LOOP_SEED,
        "--json",
        "--no-out",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = json(&o);
    let p = &v["trials"]["points"][0];
    let seeds = p["per_seed"].as_array().unwrap();
    assert_eq!(seeds.len(), 2, "{v}");
    assert_eq!(seeds[0]["seed"].as_u64().unwrap().to_string(), LOOP_SEED);
    // The trial's runs are the runs above.
    assert_eq!(seeds[0]["constant"]["finish_s"], constant.1, "{v}");
    assert_eq!(seeds[0]["rho"]["finish_s"], rho.1, "{v}");
    assert_eq!(seeds[0]["captures_differ"], true, "{v}");
    assert!(p["captures_differ"].as_u64().unwrap() >= 1, "{v}");
    assert_eq!(p["finish_s"]["pairs"], 2, "{v}");
    assert!(stderr(&o).contains("paired t") || stderr(&o).contains("no difference"));
    let o = run(&[
        "sim",
        "regions-loop",
        "--trials",
        "2",
        "--localize",
        "rho",
        "--no-out",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--localize"), "{}", stderr(&o));
}
