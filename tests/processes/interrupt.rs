//! Ctrl-C (SIGINT) and SIGTERM of `pheromone sim`: the run's outputs so far, exit 130 / 143.
//!
//! Both modes: the sim is signalled once it has computed some steps; it must write the files a
//! finished run writes, with `"interrupted": true` and a simulated time between what it had
//! reached and the scenario's duration, exit with 128 + the signal, and (as processes) stop
//! every child cleanly, leaving no node and nothing in /dev/shm.

use std::path::Path;
use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use serde_json::Value;

use super::children_with;
use crate::crash::{FrameWatch, Run, WAIT};
use crate::harness::*;

/// Long enough that no run ends by itself within the test.
const DURATION_S: f64 = 100_000.0;

/// The files every blind-leader run with `--out` writes.
const FILES: [&str; 5] = [
    "metrics.json",
    "field_final.npy",
    "field_final.png",
    "robot_0.csv",
    "leader_deposits.png",
];

/// Waits for the sim to exit after `signal`, checks status and files; its metrics and the time
/// from the signal to the exit.
fn signal_and_check(run: &Run, sim: Proc, signal: Signal, out: &Path) -> (Value, Duration) {
    let pid = nix::unistd::Pid::from_raw(sim.pid() as i32);
    let sent = Instant::now();
    nix::sys::signal::kill(pid, signal).unwrap();
    let o = sim.wait_exit(Duration::from_secs(120));
    let took = sent.elapsed();
    let log = run.log("sim");
    assert_eq!(o.status.code(), Some(128 + signal as i32), "{log}");
    for f in FILES {
        assert!(out.join(f).is_file(), "{f} not written: {log}");
    }
    let m: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(m["interrupted"], true, "{m}");
    assert!(log.contains("stopped by a signal"), "{log}");
    (m, took)
}

/// A field's sequence number `seq` was seen before the signal: the run reached at least its
/// time, and stopped well before its duration.
fn assert_partial(m: &Value, reached_s: f64) {
    let t = m["sim_time_s"].as_f64().unwrap();
    assert!(
        t >= reached_s && t < DURATION_S,
        "sim_time_s {t}: reached {reached_s} s before the signal, the duration is {DURATION_S} s"
    );
    assert!(m["ticks"].as_u64().unwrap() > 0, "{m}");
    let robot = &m["robots"][0];
    assert!(robot["distance_travelled_m"].as_f64().unwrap() > 0.0, "{m}");
}

fn interrupt_processes(signal: Signal, tag: &str) {
    let run = Run::new(tag);
    let out = run.dir.join("out");
    let d = DURATION_S.to_string();
    let sim = run.spawn(
        &[
            "sim",
            "blind-leader",
            "--duration",
            &d,
            "--out",
            out.to_str().unwrap(),
        ],
        "sim",
    );
    let sim_pid = sim.pid();
    // The run's field, read from outside: signal once it has published 50 frames (5 s).
    let watch = FrameWatch::start(&run, &format!("sim{sim_pid}x0"));
    let seen = watch.wait_newer(50, WAIT, "50 frames of the run's field");
    let children = children_with(sim_pid, "");
    assert!(
        children.len() >= 7,
        "field, 5 roles and the world: {children:?}"
    );
    let report = watch.finish();
    assert!(report.error.is_none(), "{report:?}");
    let (m, took) = signal_and_check(&run, sim, signal, &out);
    assert_partial(&m, (seen - 1) as f64 * 0.1);
    assert_eq!(m["mode"], "processes", "{m}");
    let roles: Vec<&str> = m["processes"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|p| p["role"].as_str())
        .collect();
    assert!(
        roles.contains(&"field") && roles.contains(&"world"),
        "{roles:?}"
    );
    let alive: Vec<u32> = children
        .into_iter()
        .filter(|p| Path::new(&format!("/proc/{p}")).exists())
        .collect();
    assert!(
        alive.is_empty(),
        "processes of the run still there: {alive:?}"
    );
    // Every child stopped in order: no node of theirs was left for a cleanup.
    let dead_cleaned = run.wait_nodes_gone(WAIT);
    assert_eq!(dead_cleaned, 0, "dead nodes left: {}", run.log("sim"));
    assert_eq!(run.shm_entries(), Vec::<String>::new());
    println!(
        "sim as processes, {signal:?} at frame {seen}: exit after {:.0} ms at {} s simulated",
        took.as_secs_f64() * 1e3,
        m["sim_time_s"]
    );
}

#[test]
fn sigint_of_a_sim_as_processes_writes_the_run_so_far_and_exits_130() {
    interrupt_processes(Signal::SIGINT, "si");
}

#[test]
fn sigterm_of_a_sim_as_processes_writes_the_run_so_far_and_exits_143() {
    interrupt_processes(Signal::SIGTERM, "st");
}

/// CPU time the process has used (s), from /proc/PID/stat (utime + stime, in clock ticks).
fn cpu_time_s(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map(|(_, rest)| rest.split_whitespace().collect())
        .unwrap_or_default();
    // After the comm: state is field 3, utime 14 and stime 15 (1-based).
    let ticks: u64 = [11, 12]
        .iter()
        .filter_map(|&i| fields.get(i).and_then(|v| v.parse::<u64>().ok()))
        .sum();
    ticks as f64 / 100.0
}

#[test]
fn sigint_and_sigterm_of_a_single_process_sim_write_the_run_so_far() {
    for (signal, tag) in [(Signal::SIGINT, "ssi"), (Signal::SIGTERM, "sst")] {
        let run = Run::new(tag);
        let out = run.dir.join("out");
        let d = DURATION_S.to_string();
        let sim = run.spawn(
            &[
                "sim",
                "blind-leader",
                "--single-process",
                "--duration",
                &d,
                "--out",
                out.to_str().unwrap(),
            ],
            "sim",
        );
        let pid = sim.pid();
        // Under way: it announced the run and has computed for a while.
        eventually(WAIT, "the single-process run to compute", || {
            (run.log("sim").contains("one process") && cpu_time_s(pid) > 1.0).then_some(())
        });
        let (m, took) = signal_and_check(&run, sim, signal, &out);
        assert_partial(&m, 0.1);
        assert_eq!(m["mode"], "single-process", "{m}");
        println!(
            "single-process sim, {signal:?}: exit after {:.0} ms at {} s simulated",
            took.as_secs_f64() * 1e3,
            m["sim_time_s"]
        );
    }
}

#[test]
fn sigterm_of_a_field_writes_its_summary_and_exits_143() {
    let run = Run::new("ft");
    let name = unique("ft");
    let field = run.spawn(
        &["field", "--name", &name, "--tick-hz", "50", "--json"],
        "field",
    );
    let watch = FrameWatch::start(&run, &name);
    let seen = watch.wait_newer(3, WAIT, "frames of the field");
    drop(watch);
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(field.pid() as i32),
        Signal::SIGTERM,
    )
    .unwrap();
    let out = field.wait_exit(WAIT);
    assert_eq!(out.status.code(), Some(143), "{}", run.log("field"));
    let s = json(&out);
    assert!(s["ticks"].as_u64().unwrap() >= seen, "{s}");
    run.wait_nodes_gone(WAIT);
    assert_eq!(run.shm_entries(), Vec::<String>::new());
}

/// A regions sim of many runs (the same 2 robots over and over, both strategies), signalled
/// once its first run finished: it writes the runs that finished, marked interrupted, and exits
/// with 128 + the signal, in both modes.
#[test]
fn sigint_and_sigterm_of_a_regions_sim_write_the_runs_that_finished() {
    let example = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenarios/regions.toml"),
    )
    .unwrap();
    assert!(
        example.contains("robots = [2, 3, 4]"),
        "the example changed"
    );
    // Runs of 2 robots: about 0.6 s each as processes, a few ms in one process.
    for (signal, single, counts) in [(Signal::SIGINT, false, 10), (Signal::SIGTERM, true, 2000)] {
        let robots = vec!["2"; counts].join(", ");
        let scenario = example.replace("robots = [2, 3, 4]", &format!("robots = [{robots}]"));
        let run = Run::new(if single { "rgs" } else { "rgp" });
        let file = run.dir.join("many.toml");
        std::fs::write(&file, &scenario).unwrap();
        let out = run.dir.join("out");
        let mut args = vec![
            "sim",
            file.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        if single {
            args.push("--single-process");
        }
        let mut sim = run.spawn(&args, "sim");
        // The tables of a finished run are in its log; between looks, wait on the sim's exit
        // (an early one fails at once).
        let deadline = Instant::now() + WAIT;
        while !run.log("sim").contains("wall time)") {
            assert!(
                Instant::now() < deadline && sim.runs_after(Duration::from_millis(20)),
                "no run finished while the sim ran: {}",
                run.log("sim")
            );
        }
        let pid = nix::unistd::Pid::from_raw(sim.pid() as i32);
        nix::sys::signal::kill(pid, signal).unwrap();
        let o = sim.wait_exit(Duration::from_secs(60));
        let log = run.log("sim");
        assert_eq!(
            o.status.code(),
            Some(128 + signal as i32),
            "{:?}: {log}",
            o.status
        );
        let m: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap())
                .unwrap();
        assert_eq!(m["interrupted"], true, "{m}");
        let runs = m["runs"].as_array().unwrap().len();
        assert!(
            (1..2 * counts).contains(&runs),
            "{runs} of {} runs written: {log}",
            2 * counts
        );
        assert!(out.join("tables.txt").is_file(), "{log}");
        assert_eq!(run.wait_nodes_gone(WAIT), 0, "dead nodes left: {log}");
        assert_eq!(run.shm_entries(), Vec::<String>::new());
    }
}

/// SIGTERM while a big run is still starting its children: the sim starts no more of them
/// (at most the rest of one robot's roles), stops those it started, exits 143 and leaves
/// nothing behind. Before, it went on to start every robot's roles first (issue 54, item 6).
#[test]
fn sigterm_during_a_sims_start_up_starts_no_more_children() {
    let run = Run::new("su");
    let out = run.dir.join("out");
    // ias-ss with 120 robots (the scale bench's swarm): 361 children.
    let scenario = run.dir.join("swarm120.toml");
    let swarm = pheromone_bench::scale::swarm(120, DURATION_S).expect("the swarm scenario");
    std::fs::write(&scenario, swarm.to_toml().expect("TOML")).unwrap();
    let sim = run.spawn(
        &[
            "sim",
            scenario.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        "sim",
    );
    let pid = sim.pid();
    eventually(WAIT, "the sim to start 10 children", || {
        (children_with(pid, "").len() >= 10).then_some(())
    });
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), Signal::SIGTERM).unwrap();
    // Everything started before the signal arrived is counted here (or later, if slower).
    let at_signal = children_with(pid, "").len();
    let mut sim = sim;
    let mut most = at_signal;
    let deadline = Instant::now() + Duration::from_secs(60);
    while sim.runs_after(Duration::from_millis(10)) {
        most = most.max(children_with(pid, "").len());
        assert!(
            Instant::now() < deadline,
            "the sim still runs 60 s after SIGTERM"
        );
    }
    let o = sim.wait_exit(WAIT);
    let log = run.log("sim");
    assert_eq!(o.status.code(), Some(143), "{log}");
    // One robot's roles (and the next mapper) at most.
    assert!(
        most <= at_signal + 8,
        "children after SIGTERM: {most}, {at_signal} when it was sent: {log}"
    );
    run.wait_nodes_gone(WAIT);
    assert_eq!(run.shm_entries(), Vec::<String>::new());
    println!("SIGTERM during start-up: {at_signal} children when sent, {most} at most after");
}
