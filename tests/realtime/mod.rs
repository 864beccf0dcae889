//! `--rt-priority` (field, gateway, roles): refused with the missing permission named, best effort on request, and
//! missed deadlines counted when a tick is held up on purpose.

use std::process::Command;
use std::time::Duration;

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;

use pheromone_field::shm::{create_node, FieldReader};

use crate::harness::*;

/// `pheromone ARGS` with RLIMIT_RTPRIO 0 and without CAP_SYS_NICE (dropped from the bounding
/// set, so even root lacks it): a robot computer's unprivileged user. CAP_IPC_LOCK stays, so
/// only the scheduler is refused.
fn without_rt_permission(args: &[&str]) -> std::process::Output {
    Command::new("prlimit")
        .args(["--rtprio=0", "setpriv", "--bounding-set=-sys_nice"])
        .arg(bin())
        .args(args)
        .output()
        .expect("run prlimit/setpriv (util-linux)")
}

#[test]
fn sched_fifo_without_the_permission_is_refused_naming_it_unless_best_effort() {
    let name = unique("rt-refused");
    let o = without_rt_permission(&Cmd::field(&name).ticks(5).opt("--rt-priority", 10).argv());
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("SCHED_FIFO priority 10 refused")
            && err.contains("CAP_SYS_NICE")
            && err.contains("RLIMIT_RTPRIO of at least 10")
            && err.contains("here 0"),
        "{err}"
    );
    let o = without_rt_permission(
        &Cmd::field(&name)
            .ticks(5)
            .opt("--rt-priority", 10)
            .arg("--rt-best-effort")
            .json()
            .argv(),
    );
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("going on without it (--rt-best-effort)"),
        "{err}"
    );
    assert!(err.contains("SCHED_FIFO refused, memory locked"), "{err}");
    assert_eq!(json(&o)["ticks"], 5);
    let o = run(&Cmd::field(&name).ticks(5).opt("--rt-priority", 0).argv());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--rt-priority 0"), "{}", stderr(&o));
}

#[test]
fn a_tick_held_up_on_purpose_is_a_missed_deadline_in_list_and_the_summary() {
    let name = unique("rt-late");
    let field = Proc::spawn(
        &Cmd::field(&name)
            .grid(64, 64)
            .tick_hz(100)
            .duration(120)
            .opt("--deadline-slack-us", 50_000)
            .json()
            .argv(),
    );
    let pid = Pid::from_raw(field.pid() as i32);
    let node = create_node(&unique("rt-late-reader")).unwrap();
    let mut reader = FieldReader::attach_within(&node, &name, Duration::from_secs(30)).unwrap();
    // Ticks on its metronome (the frame published at creation comes before the first deadline).
    let mut ticked_past = |sequence: u64| {
        eventually(Duration::from_secs(30), "the field to tick", || {
            reader.wait_frame(Duration::from_millis(100)).unwrap();
            let seq = reader.frame().map_or(0, |f| f.header.sequence);
            (seq > sequence).then_some(seq)
        })
    };
    let before = ticked_past(5);
    // Stop the process for 300 ms (as Ctrl-Z and `fg` would): the tick due meanwhile starts
    // late, and the field goes on (SIGCONT is no request to stop).
    kill(pid, Signal::SIGSTOP).unwrap();
    eventually(Duration::from_secs(10), "the field to be stopped", || {
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        let state = stat
            .rsplit_once(')')
            .and_then(|(_, r)| r.split_whitespace().next());
        (state == Some("T")).then_some(())
    });
    std::thread::sleep(Duration::from_millis(300));
    kill(pid, Signal::SIGCONT).unwrap();
    ticked_past(before + 5);
    // `pheromone list` shows them while the field runs.
    let o = run(&["list", "--json", "--window-s", "0.2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let listed = json(&o);
    let f = listed["fields"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["name"] == name.as_str())
        .cloned()
        .unwrap_or_else(|| panic!("{name} not listed: {listed}"));
    let t = &f["timing"];
    assert!(t["missed_deadlines"].as_u64().unwrap() >= 1, "{f}");
    assert!(t["longest_tick_gap_ms"].as_f64().unwrap() >= 250.0, "{f}");
    assert!(t["max_tick_lateness_ms"].as_f64().unwrap() >= 50.0, "{f}");
    assert_eq!(t["deadline_slack_ms"], 50.0, "{f}");
    let text = run(&["list", "--window-s", "0.2"]);
    let row = stdout(&text)
        .lines()
        .find(|l| l.starts_with(name.as_str()))
        .map(str::to_string)
        .unwrap_or_else(|| panic!("no row for {name}: {}", stdout(&text)));
    let columns: Vec<&str> = row.split_whitespace().collect();
    // field grid ch cell_m tick_hz sequence readers depositors missed gap_ms state
    let missed: u64 = columns[8]
        .parse()
        .unwrap_or_else(|e| panic!("missed: {e}\n{}", stdout(&text)));
    let gap_ms: f64 = columns[9]
        .parse()
        .unwrap_or_else(|e| panic!("gap_ms: {e}\n{}", stdout(&text)));
    assert!(missed >= 1, "{row}");
    assert!(gap_ms >= 250.0, "{row}");
    field.interrupt();
    let out = field.wait_exit(Duration::from_secs(60));
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    let s = json(&out);
    let missed = s["missed_deadlines"].as_u64().expect("missed_deadlines");
    let late_ms = s["max_tick_lateness_ms"]
        .as_f64()
        .expect("max_tick_lateness_ms");
    println!("held 300 ms: {missed} missed deadline(s), latest tick {late_ms:.1} ms late");
    assert!(missed >= 1 && late_ms >= 50.0, "{s}");
    // The lateness histogram and the gap in periods (10 ms) saw the held tick.
    assert!(
        s["tick_lateness"]["max_us"].as_u64().unwrap() >= 50_000,
        "{s}"
    );
    let l = &s["tick_lateness"];
    assert!(l["p50_us"].as_u64() <= l["p99_us"].as_u64(), "{s}");
    assert!(
        s["longest_tick_gap_periods"].as_f64().unwrap() >= 25.0,
        "{s}"
    );
}

/// `--spin-us` longer than the period: the field polls all the time and still ticks at its rate
/// and stops at its end; publishing on deposit, a deposit is applied.
#[test]
fn a_field_that_spins_longer_than_its_period_ticks_at_its_rate_and_stops() {
    let name = unique("rt-spin");
    let field = Proc::spawn(
        &Cmd::field(&name)
            .grid(64, 64)
            .tick_hz(100)
            .duration(1)
            .opt("--spin-us", 20_000)
            .opt("--publish-on-deposit-ms", 0)
            .json()
            .argv(),
    );
    let node = create_node(&unique("rt-spin-depositor")).unwrap();
    let mut reader = FieldReader::attach_within(&node, &name, Duration::from_secs(30)).unwrap();
    let mut depositor = pheromone_field::shm::DepositPublisher::attach_within(
        &node,
        &name,
        1,
        Duration::from_secs(10),
    )
    .unwrap();
    depositor
        .send(pheromone_field::DepositMsg::from(
            pheromone_field::Deposit {
                channel: 0,
                x_m: 1.0,
                y_m: 1.0,
                kernel: pheromone_field::Kernel::Ellipse {
                    tau: 0.01,
                    cov_m2: [0.01, 0.0, 0.01],
                    range_m: 0.5,
                    gamma_max: 100.0,
                },
            },
        ))
        .unwrap();
    eventually(Duration::from_secs(10), "the deposit in a frame", || {
        reader.wait_frame(Duration::from_millis(100)).unwrap();
        reader
            .frame()
            .is_some_and(|f| f.header.deposits_applied >= 1)
            .then_some(())
    });
    drop((reader, depositor, node));
    let out = field.wait_exit(Duration::from_secs(30));
    assert!(out.status.success(), "{}", stderr(&out));
    let s = json(&out);
    let ticks = s["ticks"].as_u64().unwrap();
    // Never ahead of its period (a spin that ended early would tick faster); some ticks at all.
    assert!(
        (10..=105).contains(&ticks),
        "{ticks} ticks in 1 s at 100 Hz: {s}"
    );
    assert!(s["tick_lateness"]["p99_us"].as_u64().is_some(), "{s}");
}

/// The gateway and every robot role take the same options: refused with the missing permission
/// named before they attach to anything, applied (as root here) and said so, as the field does.
#[test]
fn the_gateway_and_the_roles_take_rt_priority_and_are_refused_the_same_way() {
    let name = unique("rt-roles");
    // Each ends at once after the scheduling: no such field, no such scenario.
    let cases: [&[&str]; 3] = [
        &[
            "gateway",
            "--field",
            &name,
            "--udp",
            "127.0.0.1:0",
            "--attach-timeout",
            "0",
        ],
        &[
            "depositor",
            "--robot",
            "0",
            "--scenario",
            "no-such-scenario",
        ],
        &["follower", "--robot", "0", "--scenario", "no-such-scenario"],
    ];
    for head in cases {
        let mut args = head.to_vec();
        args.extend(["--rt-priority", "10"]);
        let o = without_rt_permission(&args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{head:?}: {err}");
        assert!(
            err.contains("SCHED_FIFO priority 10 refused") && err.contains("CAP_SYS_NICE"),
            "{head:?}: {err}"
        );
        // With the permission (root here): applied and said, before the missing field or
        // scenario ends it.
        let mut args = head.to_vec();
        args.extend(["--rt-priority", "5", "--rt-best-effort"]);
        let o = run(&args);
        let err = stderr(&o);
        assert!(
            err.contains(": real-time: SCHED_FIFO priority 5, memory locked"),
            "{head:?}: {err}"
        );
        assert_ne!(
            o.status.code(),
            Some(0),
            "{head:?}: nothing to run, yet {err}"
        );
    }
}

/// `sim --rt-priority N` (as root here) starts the field, the world and every role at
/// SCHED_FIFO N, read from `/proc` while the run goes on, and the run's metrics are those of
/// `--single-process` (real-time scheduling changes when a process runs, never what lockstep
/// computes).
#[test]
fn sim_gives_its_control_loops_the_rt_priority_and_the_same_metrics() {
    let args = [
        "sim",
        "trail-following",
        "--no-out",
        "--json",
        "--duration",
        "12",
        "--seed",
        "3",
    ];
    let mut child = Command::new(bin())
        .args(args)
        .args(["--rt-priority", "7"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start pheromone sim");
    let sim_pid = child.id();
    let node = create_node(&unique("rt-sim-watch")).unwrap();
    let mut seen: std::collections::BTreeMap<u32, (String, u32, u32)> = Default::default();
    while child.try_wait().unwrap().is_none() {
        for (pid, role, policy, prio) in children_scheduling(sim_pid) {
            // The latest sighting that shows a policy: the first may precede its setting. And
            // the latest role that shows one: a child seen between fork and exec still has
            // `sim`'s command line (an exited child, a zombie, has none).
            let e = seen.entry(pid).or_insert((role.clone(), policy, prio));
            if !role.is_empty() {
                e.0 = role;
            }
            if policy != 0 {
                (e.1, e.2) = (policy, prio);
            }
        }
        // A child's policy is read while the run goes on: /proc tells no one of a change.
        let _ = pheromone_field::shm::node_wait(&node, Duration::from_millis(5));
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let roles: std::collections::BTreeSet<&str> = seen.values().map(|v| v.0.as_str()).collect();
    for role in ["field", "world", "localizer", "follower"] {
        assert!(roles.contains(role), "no {role} child seen: {seen:?}");
    }
    for (pid, (role, policy, prio)) in &seen {
        // 1 = SCHED_FIFO, at the priority asked; 0 only if never seen after it applied it.
        if *policy != 0 {
            assert_eq!((*policy, *prio), (1, 7), "{role} ({pid}): {seen:?}");
        }
    }
    for role in ["field", "world", "localizer", "follower"] {
        assert!(
            seen.values().any(|v| v.0 == role && v.1 == 1),
            "no {role} child seen at SCHED_FIFO: {seen:?}"
        );
    }
    let processes = json(&out);
    let mut single_args = args.to_vec();
    single_args.push("--single-process");
    let single = json(&run(&single_args));
    let mut diffs = Vec::new();
    crate::processes::differences(&processes, &single, "", &mut diffs);
    assert!(diffs.is_empty(), "with --rt-priority: {diffs:#?}");
}

/// (pid, role, policy, rt priority) of each child of `parent` (`/proc/PID/stat` fields 4, 41 and
/// 40; the role is the first argument of its command line).
fn children_scheduling(parent: u32) -> Vec<(u32, String, u32, u32)> {
    let mut out = Vec::new();
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return out;
    };
    for e in dir.flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else {
            continue;
        };
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        let Some(after) = stat.rfind(')').map(|i| &stat[i + 2..]) else {
            continue;
        };
        let f: Vec<&str> = after.split_whitespace().collect();
        if f.len() < 39 || f[1].parse::<u32>().ok() != Some(parent) {
            continue;
        }
        let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        let role = cmdline
            .split(|&b| b == 0)
            .nth(1)
            .map(|r| String::from_utf8_lossy(r).into_owned())
            .unwrap_or_default();
        let (prio, policy) = (f[37].parse().unwrap_or(0), f[38].parse().unwrap_or(0));
        out.push((pid, role, policy, prio));
    }
    out
}
