//! Integration tests that run the real `pheromone` binary as separate processes.

#[cfg(feature = "bench")]
mod bench;
mod confirm;
mod crash;
mod examples;
mod flags;
mod gateway;
mod graph;
mod harness;
mod hostile;
mod inspect;
mod maps;
#[cfg(feature = "zenoh")]
mod mirror;
mod on_deposit;
mod processes;
mod realtime;
mod reliability;
mod rundir;
mod soak;
mod sweep;
mod view;

use std::time::Duration;

use harness::*;

#[test]
fn a_deposit_from_another_process_arrives_in_a_frame_then_evaporates() {
    let name = unique("e2e");
    let field = Proc::spawn(
        &Cmd::field(&name)
            .grid(128, 128)
            .cell_size(0.1)
            .model("exponential")
            // The old spelling of --decay-per-s, still accepted.
            .opt("--decay-per-sec", 1)
            .tick_hz(50)
            .duration(60)
            .json()
            .argv(),
    );
    // A third process reads frames until the deposit is visible: started first, so that a slow
    // start on a loaded machine does not miss the peak (γmax 100, K = 1/s: above 10 for 2.3 s)…
    let probe = Cmd::probe(&name).at(6.4, 6.4);
    let watching = Proc::spawn(&probe.clone().opt("--above", 10).timeout(30).json().argv());
    // The depositor is its own process; it waits for the field to exist.
    let dep = run(&Cmd::deposit(&name)
        .at(6.4, 6.4)
        .amount(0.5)
        .opt("--cov", "0.01,0,0.01")
        .argv());
    assert!(dep.status.success(), "deposit failed: {}", stderr(&dep));
    let seen = watching.wait_exit(Duration::from_secs(40));
    assert!(
        seen.status.success(),
        "deposit never seen: {}",
        stderr(&seen)
    );
    let seen = json(&seen);
    assert_eq!(seen["deposits_applied"], 1);
    assert!(seen["value"].as_f64().unwrap() > 10.0);
    // …and until it has evaporated (K = 1/s: below 1 within 5 s).
    let gone = run(&probe.opt("--below", 1).timeout(20).json().argv());
    assert!(
        gone.status.success(),
        "deposit never evaporated: {}",
        stderr(&gone)
    );
    let gone = json(&gone);
    assert!(gone["sequence"].as_u64().unwrap() > seen["sequence"].as_u64().unwrap());
    assert!(gone["sim_time_s"].as_f64().unwrap() > seen["sim_time_s"].as_f64().unwrap());
    // Ctrl-C stops the field cleanly, with its summary, and exit status 130 (128 + SIGINT).
    field.interrupt();
    let out = field.wait_exit(Duration::from_secs(10));
    assert!(
        out.status.code() == Some(130),
        "field exit: {:?} {}",
        out.status,
        stderr(&out)
    );
    let summary = json(&out);
    assert_eq!(summary["deposits_applied"], 1);
    assert_eq!(summary["field"], name.as_str());
}

#[test]
fn rejected_deposits_are_counted_by_reason() {
    let name = unique("reject");
    let field = Proc::spawn(&Cmd::field(&name).grid(64, 64).duration(60).json().argv());
    // Not positive semi-definite (|xy| > √(xx·yy)), outside the grid, negative on an unsigned channel.
    // Each is refused by the field's receipt: exit 2, naming the value.
    let deposit = Cmd::deposit(&name);
    for (args, says) in [
        (
            deposit
                .clone()
                .at(1, 1)
                .amount(1)
                .opt("--cov", "0.01,0.5,0.01"),
            "not positive semi-definite",
        ),
        (deposit.clone().at(500, 1).amount(1), "outside_grid"),
        (deposit.at(1, 1).amount(-1), "negative_on_unsigned"),
    ] {
        let o = run(&args.argv());
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(says), "{}", stderr(&o));
    }
    let probe = run(&Cmd::probe(&name).json().argv());
    assert!(probe.status.success(), "{}", stderr(&probe));
    field.interrupt();
    let summary = json(&field.wait_exit(Duration::from_secs(10)));
    let r = &summary["deposits_rejected"];
    assert_eq!(r["not_psd"], 1, "{summary}");
    assert_eq!(r["outside_grid"], 1, "{summary}");
    assert_eq!(r["negative_on_unsigned"], 1, "{summary}");
    assert_eq!(summary["deposits_applied"], 0);
    assert_eq!(summary["total_mass"][0], 0.0);
}

#[test]
fn a_reader_attaching_late_to_a_slow_field_gets_its_current_frame_before_the_next_tick() {
    // One tick every 50 s: the next tick is far beyond the probes' 10 s timeout.
    let name = unique("slow");
    let field = Proc::spawn(
        &Cmd::field(&name)
            .grid(16, 16)
            .tick_hz(0.02)
            .duration(60)
            .argv(),
    );
    for _ in 0..2 {
        // The first reader may meet the first frame; the second attaches after it.
        let probe = run(&Cmd::probe(&name).json().timeout(10).argv());
        assert!(probe.status.success(), "{}", stderr(&probe));
    }
    field.interrupt();
    field.wait_exit(Duration::from_secs(10));
}

#[test]
fn tune_reproduces_the_papers_check() {
    let threshold = Cmd::new("tune")
        .arg("threshold")
        .opt("--p0", 35)
        .opt("--k", 0.0057);
    let o = run(&threshold.opt("--level", 18).json().argv());
    assert!(o.status.success(), "{}", stderr(&o));
    let t = json(&o)["time_to_threshold_s"].as_f64().unwrap();
    assert!((t - 116.0).abs() < 1.0, "t = {t}");
    let k = Cmd::new("tune")
        .arg("k")
        .opt("--p0", 35)
        .opt("--ptm", 18)
        .opt("--tm", 116.66);
    let o = run(&k.clone().json().argv());
    let k_per_s = json(&o)["k_per_s"].as_f64().unwrap();
    assert!((k_per_s - 0.0057).abs() < 1e-5, "k = {k_per_s}");
    let o = run(&k.argv());
    assert!(stdout(&o).contains("K = 0.0057"), "{}", stdout(&o));
}

#[test]
fn impossible_tuning_exits_2_and_says_why() {
    let o = run(&Cmd::new("tune")
        .arg("threshold")
        .opt("--p0", 35)
        .opt("--k", 0.0057)
        .opt("--level", 3)
        .opt("--pa", 5)
        .argv());
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("level = 3") && stderr(&o).contains("ambient"),
        "{}",
        stderr(&o)
    );
    let o = run(&Cmd::new("tune")
        .arg("k")
        .opt("--p0", 35)
        .opt("--ptm", 40)
        .opt("--tm", 10)
        .argv());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("ptm = 40"), "{}", stderr(&o));
}

#[test]
fn a_malformed_config_exits_2_naming_file_line_and_key() {
    let dir = std::env::temp_dir().join(unique("cfg"));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("field.toml");
    std::fs::write(&path, "width = 64\nheight = 64\ncell_sise_m = 0.1\n").unwrap();
    let with_config = || {
        Cmd::field(&unique("cfg"))
            .opt("--config", path.display())
            .ticks(1)
    };
    let o = run(&with_config().argv());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("field.toml") && e.contains("line 3") && e.contains("cell_sise_m"),
        "{e}"
    );
    // A value out of range names the setting and the value.
    std::fs::write(&path, "width = 64\nheight = 64\ntick_hz = -5\n").unwrap();
    let o = run(&with_config().argv());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("tick_hz = -5"), "{}", stderr(&o));
    // An unstable diffusion is refused before anything starts.
    let o = run(&Cmd::field(&unique("cfg"))
        .opt("--diffusion", 10)
        .ticks(1)
        .argv());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("unstable"), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn field_threads_are_checked_and_a_threaded_ambient_field_ticks() {
    for bad in ["0", "257"] {
        let o = run(&Cmd::field(&unique("thr"))
            .opt("--threads", bad)
            .ticks(1)
            .argv());
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        let e = stderr(&o);
        assert!(e.contains(&format!("--threads {bad}")), "{e}");
    }
    let o = run(&Cmd::field(&unique("thr"))
        .grid(300, 200)
        .model("ambient")
        .opt("--threads", 2)
        .ticks(5)
        .json()
        .argv());
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(summary["ticks"], 5, "{summary}");
}

#[test]
fn a_config_file_round_trips_through_print_config() {
    let o = run(&Cmd::new("field")
        .model("saturating")
        .opt("--rho-per-tick", 0.1)
        .arg("--signed")
        .arg("--print-config")
        .argv());
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    let dir = std::env::temp_dir().join(unique("print"));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("f.toml");
    std::fs::write(&path, &text).unwrap();
    let again = run(&Cmd::new("field")
        .opt("--config", path.display())
        .arg("--print-config")
        .argv());
    assert!(again.status.success(), "{}", stderr(&again));
    assert_eq!(stdout(&again), text);
    assert!(
        text.contains("saturating") && text.contains("rho_per_tick = 0.1"),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn world_field_and_one_robots_three_processes_follow_a_scripted_trail() {
    run_trail_as_processes(&[]);
}

#[test]
fn the_robot_also_follows_the_trail_with_an_ekf_slam_localizer() {
    run_trail_as_processes(&["--slam"]);
}

fn run_trail_as_processes(localizer_flags: &[&'static str]) {
    let field_name = unique("rf");
    let world = unique("rw");
    let role = |name: &str| {
        Cmd::new(name)
            .opt("--scenario", "trail")
            .opt("--world", &world)
            .opt("--field", &field_name)
            .json()
    };
    let field = Proc::spawn(
        &Cmd::field(&field_name)
            .opt("--scenario", "trail")
            .opt("--clock", &world)
            .json()
            .argv(),
    );
    let localizer = Proc::spawn(&role("localizer").args(localizer_flags).argv());
    let depositor = Proc::spawn(&role("depositor").argv());
    let follower = Proc::spawn(&role("follower").argv());
    let world_out = Proc::spawn(&role("world").argv()).wait_exit(Duration::from_secs(120));
    if !world_out.status.success() {
        let mut report = format!("world: {}", stderr(&world_out));
        for p in [localizer, depositor, follower, field] {
            let what = p.what.clone();
            let o = p.wait_exit(Duration::from_secs(30));
            report += &format!("\n{what}: {:?}\n{}", o.status, stderr(&o));
        }
        panic!("{report}");
    }
    let w = json(&world_out);
    assert_eq!(w["steps"], 80);
    let pose = &w["robots"][0]["true_pose"];
    let (x, y) = (pose[0].as_f64().unwrap(), pose[1].as_f64().unwrap());
    // The trail runs along y = 2.5 m from x = 0.5 m; the robot starts at x = 1 m. Over 8 s it
    // must have moved along it (Table 2 speed ≤ 1 m/s), staying on it.
    assert!(
        x > 4.0,
        "robot did not follow the trail: ended at ({x:.2}, {y:.2})"
    );
    assert!(
        (y - 2.5).abs() < 0.3,
        "robot left the trail: ended at ({x:.2}, {y:.2})"
    );
    // Every role saw every step and stopped by itself when the world ended.
    for p in [localizer, depositor, follower] {
        let what = p.what.clone();
        let o = p.wait_exit(Duration::from_secs(30));
        assert!(o.status.success(), "{what}: {}", stderr(&o));
        let s = json(&o);
        assert_eq!(s["last_step"], 79, "{what}: {s}");
        assert_eq!(s["rejected"], 0, "{what}: {s}");
    }
    let f = json(&field.wait_exit(Duration::from_secs(30)));
    assert_eq!(f["ticks"], 80, "one field tick per world step: {f}");
    // 106 scripted trail deposits plus the robot's own (one every 0.25 m).
    let applied = f["deposits_applied"].as_u64().unwrap();
    assert!(applied > 106 + 10, "robot deposits missing: {f}");
    assert_eq!(f["deposits_rejected"]["non_finite"], 0);
}

#[test]
fn every_role_explains_itself_in_help() {
    for role in [
        "field",
        "world",
        "localizer",
        "depositor",
        "follower",
        "probe",
        "deposit",
        "tune",
        "graph",
        "graph-robot",
        "view",
    ] {
        let o = run(&[role, "--help"]);
        assert!(o.status.success(), "{role} --help");
        let text = stdout(&o);
        assert!(text.len() > 300, "{role} --help is too thin:\n{text}");
    }
    let o = run(&["follower", "--strategy", "sideways"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("sideways"), "{}", stderr(&o));
}

/// Names of the iceoryx2 services whose name contains `tag`.
fn services_named(tag: &str) -> Vec<String> {
    use iceoryx2::prelude::*;
    pheromone_field::shm::set_verbose(false);
    let mut names = Vec::new();
    <pheromone_field::shm::Svc as iceoryx2::service::Service>::list(
        iceoryx2::config::Config::global_config(),
        |s| {
            let n = s.static_details.name().to_string();
            if n.contains(tag) {
                names.push(n);
            }
            CallbackProgression::Continue
        },
    )
    .expect("list the iceoryx2 services");
    names
}

#[test]
fn sim_runs_a_scenario_as_processes_writes_its_outputs_and_leaves_nothing_behind() {
    let dir = std::env::temp_dir().join(unique("sim-out"));
    let dir_s = dir.display().to_string();
    let p = Proc::spawn(
        &Cmd::new("sim")
            .arg("trail")
            .json()
            .opt("--out", &dir_s)
            .argv(),
    );
    // The run's services are named after the sim process (sim<PID>x<N>).
    let tag = format!("sim{}x", p.pid());
    let o = p.wait_exit(Duration::from_secs(300));
    assert!(o.status.success(), "{}", stderr(&o));
    let m = json(&o);
    assert_eq!(m["scenario"], "trail");
    assert_eq!(m["mode"], "processes");
    assert_eq!(m["ticks"], 80);
    assert_eq!(m["sim_time_s"], 8.0);
    for key in [
        "width",
        "height",
        "cell_size_m",
        "channels",
        "total_mass",
        "max",
        "nan_cells",
        "deposits_applied",
        "deposits_rejected",
    ] {
        assert!(!m["field"][key].is_null(), "field.{key} missing: {m}");
    }
    assert_eq!(m["field"]["nan_cells"], 0);
    assert!(m["field"]["deposits_applied"].as_u64().unwrap() > 106);
    let robot = &m["robots"][0];
    for key in [
        "id",
        "role",
        "true_pose",
        "estimated_pose",
        "distance_travelled_m",
        "trail_abandoned_at_s",
    ] {
        assert!(robot.get(key).is_some(), "robots[0].{key} missing: {robot}");
    }
    assert!(robot["true_pose"][0].as_f64().unwrap() > 4.0, "{robot}");
    let est = robot["estimated_pose"][0].as_f64().unwrap();
    assert!(
        (est - robot["true_pose"][0].as_f64().unwrap()).abs() < 0.5,
        "{robot}"
    );
    // Field, localizer, depositor, follower and world reported.
    assert_eq!(m["processes"].as_array().unwrap().len(), 5, "{m}");
    // The outputs: metrics.json (the same object), a CSV per robot with a row per step the
    // observer saw, and the pictures.
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(written["scenario"], "trail");
    let csv = std::fs::read_to_string(dir.join("robot_0.csv")).unwrap();
    assert!(csv.starts_with("t_s,true_x_m,true_y_m"), "{csv}");
    assert!(csv.lines().count() > 40, "{} rows", csv.lines().count());
    assert!(dir.join("field_final.png").is_file());
    // Nothing of the run is left: no process (they were reaped by sim) and no service.
    let left = services_named(&tag);
    assert!(left.is_empty(), "services of the run left behind: {left:?}");
    let _ = std::fs::remove_dir_all(&dir);
    // A scenario that does not exist is bad input.
    let o = run(&["sim", "no-such-scenario", "--no-out"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no-such-scenario"), "{}", stderr(&o));
}

#[test]
fn sim_single_process_prints_the_metrics_of_the_default_scenario() {
    let o = run(&Cmd::new("sim")
        .arg("--single-process")
        .json()
        .arg("--no-out")
        .duration(40)
        .argv());
    assert!(o.status.success(), "{}", stderr(&o));
    let m = json(&o);
    assert_eq!(m["scenario"], "blind-leader");
    assert_eq!(m["mode"], "single-process");
    assert_eq!(m["seed"], 0);
    assert_eq!(m["robots"].as_array().unwrap().len(), 2);
    assert_eq!(m["robots"][0]["role"], "leader+depositor");
    assert!(
        m["metrics"]["blind_leader"]["follower_abandoned_at_s"].is_number(),
        "{m}"
    );
    // Bad flags are bad input.
    let o = run(&["sim", "ias-ss", "--robots", "99", "--single-process"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--robots 99"), "{}", stderr(&o));
}

#[test]
fn every_time_flag_refuses_nan_infinity_negative_and_absurd_values_with_exit_2_naming_it() {
    // (the command line before the flag, the flag): each fails before it opens anything.
    let cases: [(&[&str], &str); 10] = [
        (
            &["probe", "--field", "nf", "--x", "0", "--y", "0"],
            "--timeout",
        ),
        (
            &[
                "deposit", "--field", "nf", "--x", "0", "--y", "0", "--amount", "1",
            ],
            "--timeout",
        ),
        (&["list"], "--window-s"),
        (&["field", "--name", "nf"], "--duration"),
        (&["field", "--name", "nf"], "--checkpoint-every"),
        (&["field", "--name", "nf"], "--publish-on-deposit-ms"),
        (&["sim", "--no-out"], "--timeout"),
        (&["sim", "--no-out"], "--stall-timeout"),
        (
            &["export", "--field", "nf", "--out", "fz-never-written.npy"],
            "--timeout-s",
        ),
        (&["gateway", "--field", "nf"], "--attach-timeout"),
    ];
    let mut failures = Vec::new();
    for (head, flag) in cases {
        for value in ["nan", "inf", "-1", "1e300", "", "junk"] {
            let mut args: Vec<String> = head.iter().map(|s| s.to_string()).collect();
            args.push(format!("{flag}={value}"));
            let argv: Vec<&str> = args.iter().map(String::as_str).collect();
            let o = run(&argv);
            let err = stderr(&o);
            if o.status.code() != Some(2) || !err.contains(flag) || err.contains("panicked") {
                failures.push(format!(
                    "pheromone {}: {:?}: {err}",
                    argv.join(" "),
                    o.status
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
