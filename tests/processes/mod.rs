//! Every scenario as processes equals `--single-process`; a failed or killed child stops the run.
//!
//! Scenarios as separate processes, the default mode of `pheromone sim`: the same metrics as
//! `--single-process` for a seed, key by key, for every built-in scenario and every file in
//! `examples/scenarios/`; eight robots; a child that fails, and one that is killed, stop the
//! whole run with an error naming it, and leave nothing behind.

use std::path::Path;
use std::time::Duration;

use serde_json::Value;

use crate::crash::{Run, WAIT};

mod filters;
mod interrupt;
use crate::harness::*;

/// Keys whose values are wall-time measurements, or describe the mode: everything else must
/// be equal.
const WALL_KEYS: [&str; 5] = [
    "wall_time_s",
    "sim_time_per_wall_time",
    "mode",
    "processes",
    "startup_s",
];

/// The paths where two metrics objects differ (wall-time keys at the top level left out).
pub(crate) fn differences(a: &Value, b: &Value, path: &str, out: &mut Vec<String>) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                if path.is_empty() && WALL_KEYS.contains(&k.as_str()) {
                    continue;
                }
                match (x.get(k), y.get(k)) {
                    (Some(p), Some(q)) => differences(p, q, &format!("{path}/{k}"), out),
                    _ => out.push(format!("{path}/{k}: only in one")),
                }
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                differences(p, q, &format!("{path}[{i}]"), out);
            }
        }
        _ if a != b => out.push(format!("{path}: {a} vs {b}")),
        _ => {}
    }
}

fn sim_json(args: &[&str]) -> Value {
    let o = run(args);
    assert!(
        o.status.success(),
        "pheromone {}: {:?}\n{}",
        args.join(" "),
        o.status,
        stderr(&o)
    );
    json(&o)
}

/// Runs `scenario` both ways and asserts the metrics agree key by key.
pub(crate) fn assert_same_in_both_modes(scenario: &str, extra: &[&str]) -> Value {
    let mut args = vec!["sim", scenario, "--no-out", "--json"];
    args.extend_from_slice(extra);
    let processes = sim_json(&args);
    args.push("--single-process");
    let single = sim_json(&args);
    assert_eq!(processes["mode"], "processes", "{processes}");
    assert_eq!(processes["interrupted"], false, "{processes}");
    let mut diffs = Vec::new();
    differences(&processes, &single, "", &mut diffs);
    assert!(
        diffs.is_empty(),
        "{scenario} {extra:?}: processes and --single-process differ at {} key(s): {diffs:#?}",
        diffs.len()
    );
    processes
}

/// Short enough to keep the suite quick, long enough that robots meet the field.
fn duration_for(name: &str) -> &'static str {
    match name {
        "ias-ss" => "30",
        "evaporation" => "60",
        _ => "12",
    }
}

#[test]
fn every_built_in_scenario_as_processes_gives_the_single_process_metrics() {
    for name in [
        "blind-leader",
        "trail-following",
        "ias-ss",
        "evaporation",
        "trail",
    ] {
        let m = assert_same_in_both_modes(name, &["--duration", duration_for(name), "--seed", "5"]);
        assert!(m["startup_s"].as_f64().is_some_and(|s| s > 0.0), "{m}");
        assert!(m["steps"].as_u64().unwrap() > 0, "{m}");
        assert_eq!(m["ticks"], m["steps"], "one tick per step: {m}");
    }
}

#[test]
fn ukf_and_particle_filter_localizers_as_processes_give_the_single_process_metrics() {
    // `--filter pf` turns the world's laser on: the localizers read its scans in both modes.
    for filter in ["ukf", "pf"] {
        let m = assert_same_in_both_modes(
            "trail-following",
            &[
                "--duration",
                "12",
                "--seed",
                "5",
                "--filter",
                filter,
                "--particles",
                "200",
            ],
        );
        assert!(m["steps"].as_u64().unwrap() > 0, "{m}");
    }
}

#[test]
fn every_example_scenario_file_as_processes_gives_the_single_process_metrics() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenarios");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 8, "{files:?}");
    for f in files {
        let name = f.file_stem().unwrap().to_string_lossy().to_string();
        let path = f.to_string_lossy().to_string();
        if name.starts_with("regions") {
            // Node-graph runs have no --duration: they end when every robot is done.
            assert_same_in_both_modes(&path, &[]);
        } else {
            assert_same_in_both_modes(&path, &["--duration", duration_for(&name)]);
        }
    }
}

#[test]
fn ias_ss_with_eight_robots_runs_as_25_processes_with_the_single_process_answer() {
    let m = assert_same_in_both_modes("ias-ss", &["--robots", "8", "--duration", "20"]);
    assert_eq!(m["robots"].as_array().unwrap().len(), 8, "{m}");
    // field + 8 × (localizer, depositor, follower) + world
    assert_eq!(m["processes"].as_array().unwrap().len(), 26, "{m}");
    let explored = m["metrics"]["exploration"]["per_robot"].as_array();
    assert!(explored.is_some_and(|v| v.len() == 8), "{m}");
}

/// The `t_s` and `deposit_peak` columns of a robot CSV, rows with a deposit only.
fn deposits_in(csv: &Path) -> Vec<(String, String)> {
    let text = std::fs::read_to_string(csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "deposit_peak").unwrap();
    lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|r| !r[col].is_empty())
        .map(|r| (r[0].to_string(), r[col].to_string()))
        .collect()
}

#[test]
fn the_leader_deposits_chart_draws_the_same_deposits_as_processes_and_in_one_process() {
    // As processes the observer records what each depositor sent by running a copy of it on
    // the same poses: the leader's deposits, and so its chart, equal the single-process run's.
    let base = std::env::temp_dir().join(unique("plots-modes"));
    let (a, b) = (base.join("processes"), base.join("single"));
    for (dir, extra) in [(&a, None), (&b, Some("--single-process"))] {
        let d = dir.display().to_string();
        let mut args = vec!["sim", "blind-leader", "--duration", "30", "--out", &d];
        args.extend(extra);
        let o = run(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        assert!(dir.join("leader_deposits.png").is_file(), "{args:?}");
        assert!(dir.join("summary.png").is_file(), "{args:?}");
    }
    let (pa, pb) = (
        deposits_in(&a.join("robot_0.csv")),
        deposits_in(&b.join("robot_0.csv")),
    );
    assert!(pa.len() > 20, "{} deposits", pa.len());
    assert_eq!(pa, pb);
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn wrong_area_as_processes_gives_the_single_process_metrics() {
    // Issue 48: the leader's loss comes from its own particle filter, no script. Aware: Alice
    // gives the fading trail up, explores, reaches B; constant: both followers end in A.
    let aware = assert_same_in_both_modes("wrong-area", &["--seed", "1"]);
    let w = &aware["metrics"]["wrong_area"];
    assert_eq!(w["scripted_loss"], false, "{w}");
    assert_eq!(w["checkpoints"].as_array().map(Vec::len), Some(15), "{w}");
    assert!(w["leader"]["lost_at_s"].is_number(), "{w}");
    let b = &aware["metrics"]["blind_leader"];
    assert_eq!(b["leader_lost_at_s"], w["leader"]["lost_at_s"], "{b}");
    assert!(w["followers"][0]["exploring_from_s"].is_number(), "{w}");
    assert_eq!(w["followers"][0]["reached_b"], true, "{w}");
    assert_eq!(w["followers_ended_in_a"], 0, "{w}");
    let constant = assert_same_in_both_modes("wrong-area", &["--seed", "1", "--constant"]);
    let w = &constant["metrics"]["wrong_area"];
    assert_eq!(w["scripted_loss"], false, "{w}");
    assert_eq!(w["followers_ended_in_a"], 2, "{w}");
}

#[test]
fn wrong_area_with_its_loss_script_as_processes_gives_the_single_process_metrics() {
    // `--scripted-loss`: the old EKF leader lost at 20 s; Alice's switch to exploring, both
    // followers' arrival at B; with --constant both end in A.
    let aware = assert_same_in_both_modes("wrong-area", &["--seed", "1", "--scripted-loss"]);
    let w = &aware["metrics"]["wrong_area"];
    assert_eq!(w["scripted_loss"], true, "{w}");
    assert!(w["followers"][0]["exploring_from_s"].is_number(), "{w}");
    assert_eq!(w["followers_reached_b"], 2, "{w}");
    let args = ["--seed", "1", "--scripted-loss", "--constant"];
    let constant = assert_same_in_both_modes("wrong-area", &args);
    let w = &constant["metrics"]["wrong_area"];
    assert_eq!(w["followers_ended_in_a"], 2, "{w}");
}

#[test]
fn followers_that_spin_or_busy_poll_for_their_frame_give_the_single_process_metrics() {
    // trail-following: two followers read the field every step.
    let base = [
        "sim",
        "trail-following",
        "--no-out",
        "--json",
        "--duration",
        "12",
        "--seed",
        "2",
    ];
    let single = sim_json(&[&base[..], &["--single-process"]].concat());
    for wait in ["spin:200", "busy-poll"] {
        let p = sim_json(&[&base[..], &["--follower-wait", wait]].concat());
        assert_eq!(p["mode"], "processes", "{p}");
        let mut diffs = Vec::new();
        differences(&p, &single, "", &mut diffs);
        assert!(diffs.is_empty(), "--follower-wait {wait}: {diffs:#?}");
    }
    for bad in ["spin:0", "spin:abc", "poll"] {
        let o = run(&["sim", "trail-following", "--no-out", "--follower-wait", bad]);
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", stderr(&o));
        assert!(
            stderr(&o).contains("--follower-wait") && stderr(&o).contains(bad),
            "{bad}: {}",
            stderr(&o)
        );
    }
}

/// A scenario file whose robot 0 localizer is refused by `--slam` (a landmark region restricts
/// a map that EKF-SLAM does not have): that process exits with an error at once.
fn failing_scenario(run: &Run) -> String {
    let trail = include_str!("../../examples/scenarios/trail.toml");
    let text = trail.replacen(
        "[[robot]]\nid = 0\n",
        "[[robot]]\nid = 0\n[robot.localizer]\nlandmark_region_m = [0.0, 0.0, 5.0, 5.0]\n",
        1,
    );
    assert_ne!(text, trail, "trail.toml's first [[robot]] moved");
    let path = run.dir.join("trail-failing.toml");
    std::fs::write(&path, text).unwrap();
    path.to_string_lossy().into_owned()
}

#[test]
fn a_child_that_exits_with_an_error_is_reported_by_role_and_robot_and_nothing_is_left() {
    let run = Run::new("f");
    let scenario = failing_scenario(&run);
    let out = run.run(&["sim", &scenario, "--slam", "--no-out"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("localizer r0 failed (exit status") && err.contains("no map to restrict"),
        "the error names the role, the robot and its cause: {err}"
    );
    run.wait_nodes_gone(WAIT);
    assert_eq!(run.shm_entries(), Vec::<String>::new(), "{err}");
}

/// Pids of the children of `parent` whose command line has `needle`.
fn children_with(parent: u32, needle: &str) -> Vec<u32> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        // "pid (comm) state ppid …": the comm may hold spaces, so split after its ')'.
        let ppid = stat
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().nth(1))
            .and_then(|p| p.parse::<u32>().ok());
        let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
        if ppid == Some(parent) && cmdline.contains(needle) {
            found.push(pid);
        }
    }
    found
}

#[test]
fn a_sigkilled_child_stops_the_whole_run_with_a_clear_error_and_no_leftovers() {
    let run = Run::new("k");
    let sim = run.spawn(
        &[
            "sim",
            "ias-ss",
            "--robots",
            "3",
            "--duration",
            "100000",
            "--no-out",
        ],
        "sim",
    );
    let sim_pid = sim.pid();
    // Once the run is under way (its followers steer), kill robot 1's follower.
    let follower = eventually(WAIT, "robot 1's follower process", || {
        children_with(sim_pid, "follower").into_iter().find(|&p| {
            let cmd = std::fs::read(format!("/proc/{p}/cmdline")).unwrap_or_default();
            String::from_utf8_lossy(&cmd).contains("--robot\u{0}1")
        })
    });
    eventually(WAIT, "the run to step", || {
        run.log("sim").contains("separate processes").then_some(())
    });
    // The sim starts its children one after another: wait until all are there (robot 2's roles
    // may still be starting when robot 1's follower already steers).
    let children = eventually(WAIT, "field, world and 3 × 3 roles", || {
        let c = children_with(sim_pid, "");
        (c.len() >= 10).then_some(c)
    });
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(follower as i32),
        nix::sys::signal::Signal::SIGKILL,
    )
    .unwrap();
    let out = sim.wait_exit(Duration::from_secs(60));
    let err = run.log("sim");
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("follower r1 failed (killed by SIGKILL)"),
        "the error names the killed process: {err}"
    );
    let alive: Vec<u32> = children
        .into_iter()
        .filter(|p| Path::new(&format!("/proc/{p}")).exists())
        .collect();
    assert!(
        alive.is_empty(),
        "processes of the run still there: {alive:?}"
    );
    run.wait_nodes_gone(WAIT);
    assert_eq!(run.shm_entries(), Vec::<String>::new(), "{err}");
}

#[test]
fn a_sigkilled_sim_takes_every_child_with_it() {
    let run = Run::new("d");
    let sim = run.spawn(
        &["sim", "blind-leader", "--duration", "100000", "--no-out"],
        "sim",
    );
    let sim_pid = sim.pid();
    eventually(WAIT, "the run to step", || {
        run.log("sim").contains("separate processes").then_some(())
    });
    // blind-leader: the field, two localizers, a depositor, two followers, then the world.
    let children = eventually(WAIT, "the field, 5 roles and the world", || {
        let c = children_with(sim_pid, "");
        (c.len() >= 7 && !children_with(sim_pid, "world").is_empty()).then_some(c)
    });
    // The scenario file every child reads lies in a private directory: 0700, a random name.
    let cmdline = std::fs::read(format!("/proc/{}/cmdline", children[0])).unwrap();
    let argv: Vec<String> = String::from_utf8_lossy(&cmdline)
        .split('\0')
        .map(str::to_string)
        .collect();
    let at = argv
        .iter()
        .position(|a| a == "--scenario")
        .expect("--scenario");
    let dir = Path::new(&argv[at + 1]).parent().unwrap().to_path_buf();
    let meta = std::fs::metadata(&dir).unwrap();
    let mode = std::os::unix::fs::PermissionsExt::mode(&meta.permissions());
    assert_eq!(mode & 0o777, 0o700, "{}", dir.display());
    let dir_name = dir.file_name().unwrap().to_string_lossy().into_owned();
    assert!(
        dir_name.starts_with(&format!("pheromone-sim{sim_pid}x")) && dir_name.len() > 20,
        "not a private random name: {dir_name}"
    );
    // SIGKILL: the sim runs no handler; its children must go by themselves (PR_SET_PDEATHSIG).
    sim.kill();
    let killed = std::time::Instant::now();
    let gone = |p: &u32| !Path::new(&format!("/proc/{p}")).exists();
    eventually(WAIT, "every child of the killed sim to exit", || {
        children.iter().all(gone).then_some(())
    });
    println!(
        "sim SIGKILLed: its {} children gone after {:.0} ms",
        children.len(),
        killed.elapsed().as_secs_f64() * 1e3
    );
    // The sim's own node died with it; the children's nodes went with their orderly exit.
    let dead_cleaned = run.wait_nodes_gone(WAIT);
    assert!(
        dead_cleaned <= 1,
        "dead nodes left besides the sim's: {dead_cleaned}"
    );
    eventually(WAIT, "the run's /dev/shm entries to go", || {
        run.shm_entries().is_empty().then_some(())
    });
    // A killed sim cannot remove its scenario directory: the next sim of the same user does
    // (issue 54 item 9), as it makes its own (a sim of a test running beside this one may be
    // that next sim).
    let o = run.run(&["sim", "evaporation", "--duration", "0.5", "--no-out"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!dir.exists(), "the killed sim's {} is left", dir.display());
    // A service the sim was creating when it died is left half-made (its static config only,
    // which iceoryx2 removes in no cleanup): the next pheromone process removes it once it is
    // older than twice iceoryx2's creation timeout.
    let tag = format!("sim{sim_pid}x");
    eventually(WAIT, "no service file of the killed run", || {
        let o = crate::harness::run(&["list"]);
        assert!(o.status.success(), "{}", stderr(&o));
        service_files_naming(&tag).is_empty().then_some(())
    });
}

/// A sim starts its children without a fork of itself (`posix_spawn`, issue 52): each asks for
/// its death signal itself, first thing, naming its supervisor in `PHEROMONE_DIE_WITH_PARENT`.
/// A child whose supervisor is already gone (it is someone else's child by then) does not start.
#[test]
fn a_child_whose_supervisor_is_gone_before_it_starts_does_not_run() {
    let with_parent = |pid: String| {
        std::process::Command::new(bin())
            .arg("--version")
            .env(pheromone_supervisor::DIE_WITH_PARENT_ENV, pid)
            .output()
            .unwrap()
    };
    // This test's process is the child's parent: it runs.
    let o = with_parent(std::process::id().to_string());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("pheromone"), "{}", stdout(&o));
    // PID 1 is not its parent: as if its supervisor died and it was re-parented.
    let o = with_parent("1".to_string());
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("the supervising process 1 ended before this process started"),
        "{}",
        stderr(&o)
    );
}

/// The static config files in iceoryx2's service directory that name `tag`: the finished
/// services, and the half-made ones no listing shows.
fn service_files_naming(tag: &str) -> Vec<String> {
    let dir = iceoryx2::config::Config::global_config()
        .global
        .service_dir()
        .to_string();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    entries
        .flatten()
        .filter(|e| std::fs::read_to_string(e.path()).is_ok_and(|t| t.contains(tag)))
        .map(|e| e.path().display().to_string())
        .collect()
}

#[test]
fn ias_ss_with_merging_as_processes_gives_the_single_process_metrics() {
    // Exchanges start after iteration 100 (100 s): 130 s leaves three chances per pair.
    let m = assert_same_in_both_modes(
        "ias-ss",
        &[
            "--merge",
            "--rc-m",
            "30",
            "--robots",
            "4",
            "--duration",
            "130",
        ],
    );
    let metrics = &m["metrics"];
    assert!(
        metrics["merges"].as_u64().is_some_and(|n| n > 0),
        "{metrics}"
    );
    assert!(
        metrics["exploration_known"]["mean"]
            .as_f64()
            .is_some_and(|e| e > 0.0),
        "{metrics}"
    );
    // The mapper processes merged from each other's frames in shared memory: the same merges,
    // with the same alignment errors, as the single-process mapping team.
    let mappers: Vec<&Value> = m["processes"]
        .as_array()
        .expect("process reports")
        .iter()
        .filter(|r| r["role"].as_str().is_some_and(|n| n.starts_with("mapper")))
        .map(|r| &r["summary"])
        .collect();
    assert_eq!(mappers.len(), 4, "{}", m["processes"]);
    let errors: Vec<f64> = mappers
        .iter()
        .flat_map(|s| s["merges"].as_array().expect("merges").iter())
        .map(|e| e["alignment_error_m"].as_f64().expect("alignment error"))
        .collect();
    assert_eq!(Some(errors.len() as u64), metrics["merges"].as_u64());
    let max = errors.iter().copied().fold(0.0, f64::max);
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    let want = &metrics["merge_alignment_error_m"];
    assert!(
        (max - want["max"].as_f64().unwrap()).abs() < 1e-12,
        "{max} vs {want}"
    );
    assert!(
        (mean - want["mean"].as_f64().unwrap()).abs() < 1e-12,
        "{mean} vs {want}"
    );
    for s in &mappers {
        assert_eq!(
            s["counters"]["merges_rejected"],
            serde_json::json!({}),
            "{s}"
        );
        assert_eq!(s["missing_poses"], 0, "{s}");
    }
}

#[test]
fn ias_ss_steering_on_own_maps_with_merging_as_processes_gives_the_single_process_metrics() {
    // Each follower reads its own mapper's map frame in shared memory (`<W>-map-r<ID>`), merged
    // maps included: the same motion, step for step, as the single-process run.
    let m = assert_same_in_both_modes(
        "ias-ss",
        &[
            "--merge",
            "--steer",
            "own-map",
            "--rc-m",
            "30",
            "--robots",
            "3",
            "--duration",
            "130",
            "--seed",
            "2",
        ],
    );
    let metrics = &m["metrics"];
    assert_eq!(metrics["steer_on"], "own-map", "{metrics}");
    assert!(
        metrics["merges"].as_u64().is_some_and(|n| n > 0),
        "{metrics}"
    );
    assert!(
        metrics["exploration_merged"]["mean"]
            .as_f64()
            .is_some_and(|e| e >= metrics["exploration"]["mean"].as_f64().unwrap()),
        "{metrics}"
    );
}

#[test]
fn steering_on_own_maps_without_local_maps_is_refused_with_exit_status_2() {
    let o = run(&[
        "sim",
        "ias-ss",
        "--steer",
        "own-map",
        "--no-out",
        "--single-process",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("mapping.steer_on = own-map") && err.contains("--merge"),
        "{err}"
    );
}

#[test]
fn a_mapper_map_frame_is_readable_while_it_runs_and_a_sigkilled_mapper_leaves_nothing() {
    let run = Run::new("m");
    let sim = run.spawn(
        &[
            "sim",
            "ias-ss",
            "--merge",
            "--robots",
            "2",
            "--duration",
            "100000",
            "--no-out",
        ],
        "sim",
    );
    let sim_pid = sim.pid();
    let mapper = eventually(WAIT, "robot 1's mapper process", || {
        children_with(sim_pid, "mapper").into_iter().find(|&p| {
            let cmd = std::fs::read(format!("/proc/{p}/cmdline")).unwrap_or_default();
            String::from_utf8_lossy(&cmd).contains("--robot\u{0}1")
        })
    });
    // The run's tag is `sim<PID>x0`: robot 1's map is field `sim<PID>x0-map-r1`, read by the
    // ordinary field reader, while the run steps.
    let map = format!("sim{sim_pid}x0-map-r1");
    let probe = || run.run(&["probe", "--field", &map, "--json", "--timeout", "30"]);
    let first = eventually(WAIT, "a frame of the map after step 10", || {
        let o = probe();
        let v: Value = serde_json::from_slice(&o.stdout).ok()?;
        (v["sequence"].as_u64()? > 10).then_some(v)
    });
    assert_eq!(first["channels"], 2, "{first}");
    assert_eq!(first["width"], first["height"], "{first}");
    let later = eventually(WAIT, "a newer frame of the map", || {
        let v: Value = serde_json::from_slice(&probe().stdout).ok()?;
        (v["sequence"].as_u64()? > first["sequence"].as_u64()?).then_some(v)
    });
    // At the robot (its frame's origin, where it started) the map knows the cell: its scans
    // cleared it (log-odds < 0).
    assert!(
        later["value"].as_f64().is_some_and(|v| v < 0.0),
        "occupancy log-odds at the start pose: {later}"
    );
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(mapper as i32),
        nix::sys::signal::Signal::SIGKILL,
    )
    .unwrap();
    let out = sim.wait_exit(Duration::from_secs(60));
    let err = run.log("sim");
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("mapper r1 failed (killed by SIGKILL)"),
        "the error names the killed mapper: {err}"
    );
    let alive: Vec<u32> = children_with(sim_pid, "")
        .into_iter()
        .filter(|p| Path::new(&format!("/proc/{p}")).exists())
        .collect();
    assert!(
        alive.is_empty(),
        "processes of the run still there: {alive:?}"
    );
    run.wait_nodes_gone(WAIT);
    assert_eq!(run.shm_entries(), Vec::<String>::new(), "{err}");
}
