//! Robot processes on a primary and a backup gateway, the primary killed or stopped mid-run.
//!
//! The real robot processes with a primary and a backup gateway: `pheromone follower --strategy
//! antenna --gateway … --backup …` (trail-following's two antenna robots, in lockstep with the
//! world, field and localizers), robot 0 also depositing through the gateway. The primary is
//! SIGKILLed, or SIGSTOPped (silent), mid-run: both robots switch to the backup, answer every
//! step and stay on their trails, and every deposit is applied at most once.

use std::path::PathBuf;
use std::time::Duration;

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use pheromone_field::shm::{create_node, FieldReader};
use pheromone_world::scenario::Scenario;
use serde_json::Value;

use super::free_port;
use crate::harness::*;

/// trail-following, 15 s: robot 0 (0.4 m/s at most) is still on its 7 m trail at the end.
fn scenario_file(tag: &str) -> PathBuf {
    let mut s = Scenario::load("trail-following").unwrap();
    s.duration_s = 15.0;
    let dir = std::env::temp_dir().join(format!("pheromone-test-{tag}"));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("scenario.toml");
    std::fs::write(&path, s.to_toml().unwrap()).unwrap();
    path
}

/// The last non-empty stdout line as JSON (a gateway with --print-address prints two lines).
fn last_json(o: &std::process::Output) -> Value {
    let out = stdout(o);
    let line = out
        .lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("");
    serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {out}\n{}", stderr(o)))
}

// A test reads as one scenario, top to bottom (the line limit is for non-test code).
#[allow(clippy::too_many_lines)]
fn primary_goes_away(signal: Signal) {
    let tag = unique("gw-fb");
    let path = scenario_file(&tag);
    let scenario = path.display().to_string();
    let (field_name, world) = (tag.clone(), tag.clone());
    let role = |name: &str, robot: Option<u32>, extra: &[&str]| {
        let mut cmd = Cmd::new(name)
            .opt("--scenario", &scenario)
            .opt("--world", &world)
            .opt("--field", &field_name)
            .json();
        if let Some(r) = robot {
            cmd = cmd.opt("--robot", r);
        }
        cmd.args(extra)
    };
    let spawn = |cmd: Cmd| Proc::spawn(&cmd.argv());

    let field_proc = Proc::spawn(
        &Cmd::field(&field_name)
            .opt("--scenario", &scenario)
            .opt("--clock", &world)
            .json()
            .argv(),
    );
    let (p_port, b_port) = (free_port(), free_port());
    let gateway = |port: u16| {
        let udp = format!("127.0.0.1:{port}");
        Proc::spawn(&[
            "gateway",
            "--field",
            &field_name,
            "--udp",
            &udp,
            "--rate-hz",
            "0",
            "--json",
        ])
    };
    let primary = gateway(p_port);
    let backup = gateway(b_port);
    let (p_url, b_url) = (
        format!("udp://127.0.0.1:{p_port}"),
        format!("udp://127.0.0.1:{b_port}"),
    );
    // Both gateways serve before the robots start (a robot fails when neither answers).
    for port in [p_port, b_port] {
        let mut probe = pheromone_gateway::client::GatewayClient::new(
            pheromone_gateway::client::Transport::udp(&format!("127.0.0.1:{port}")).unwrap(),
            pheromone_gateway::client::ClientConfig {
                client_id: 200,
                ..Default::default()
            },
        );
        eventually(
            Duration::from_secs(30),
            "a gateway to answer a ping",
            || probe.ping().ok(),
        );
    }
    let localizers: Vec<Proc> = (0..2)
        .map(|r| spawn(role("localizer", Some(r), &[])))
        .collect();
    let follower = |r: u32, extra: &[&str]| {
        let mut e = vec![
            "--gateway",
            p_url.as_str(),
            "--backup",
            b_url.as_str(),
            "--gateway-timeout-ms",
            "100",
            "--gateway-retries",
            "1",
        ];
        e.extend_from_slice(extra);
        spawn(role("follower", Some(r), &e))
    };
    let f0 = follower(0, &["--deposit-amount", "1", "--deposit-every", "5"]);
    let f1 = follower(1, &[]);
    let world_proc = spawn(role("world", None, &["--stall-timeout", "60"]));

    // Mid-run: once the field has ticked 30 of the 150 steps.
    let node = create_node(&format!("{tag}-test")).unwrap();
    let mut reader =
        FieldReader::attach_within(&node, &field_name, Duration::from_secs(30)).unwrap();
    let at = reader
        .wait_until(Duration::from_secs(60), |f| f.header.sequence >= 30)
        .unwrap()
        .map(|f| f.header.sequence)
        .expect("the run reaches step 30");
    kill(Pid::from_raw(primary.pid() as i32), signal).unwrap();

    let world_out = world_proc.wait_exit(Duration::from_secs(120));
    assert!(world_out.status.success(), "world: {}", stderr(&world_out));
    let world_summary = json(&world_out);
    let steps = world_summary["steps"].as_u64().unwrap();
    assert!(
        at < steps,
        "the primary went away mid-run (step {at} of {steps})"
    );

    let mut robot0 = Value::Null;
    for (r, f) in [(0, f0), (1, f1)] {
        let out = f.wait_exit(Duration::from_secs(60));
        assert!(out.status.success(), "follower r{r}: {}", stderr(&out));
        let s = json(&out);
        assert_eq!(
            s["role"]["steps"].as_u64(),
            Some(steps),
            "r{r} answered every step: {s}"
        );
        assert_eq!(s["role"]["rejected"], 0, "r{r}: {s}");
        assert!(
            s["source"]["switches"].as_u64().is_some_and(|n| n >= 1),
            "r{r}: {s}"
        );
        assert_eq!(
            s["source"]["active"],
            b_url.as_str(),
            "r{r} ends on the backup: {s}"
        );
        if r == 0 {
            robot0 = s;
        }
    }
    for l in localizers {
        assert!(l.wait_exit(Duration::from_secs(60)).status.success());
    }
    let field_out = field_proc.wait_exit(Duration::from_secs(60));
    assert!(field_out.status.success(), "field: {}", stderr(&field_out));
    let field_summary = json(&field_out);

    // Robot 0 kept following its straight trail (y = 1.5 m from x = 0.5 to 7.5 m).
    let r0 = &world_summary["robots"][0]["true_pose"];
    let (x, y) = (r0[0].as_f64().unwrap(), r0[1].as_f64().unwrap());
    assert!(
        x > 4.0 && (y - 1.5).abs() < 0.2,
        "robot 0 left its trail: ({x:.2}, {y:.2})"
    );

    // Deposits: the field applied the world's scripted ones plus those of the gateways, and
    // the gateways' never exceed the distinct deposits robot 0 made (each applied at most once).
    if signal == Signal::SIGSTOP {
        kill(Pid::from_raw(primary.pid() as i32), Signal::SIGCONT).unwrap();
    }
    let mut gateway_deposits = 0;
    for (who, g) in [("primary", primary), ("backup", backup)] {
        if signal == Signal::SIGKILL && who == "primary" {
            drop(g);
            continue;
        }
        g.interrupt();
        let out = g.wait_exit(Duration::from_secs(30));
        assert!(out.status.success(), "{who}: {}", stderr(&out));
        let c = last_json(&out);
        assert_eq!(c["deposits_repeated"], 0, "{who}: {c}");
        if who == "backup" {
            assert!(
                c["deposits"].as_u64().is_some_and(|n| n >= 1),
                "backup: {c}"
            );
            assert!(c["pirs"].as_u64().is_some_and(|n| n > 0), "backup: {c}");
        }
        gateway_deposits += c["deposits"].as_u64().unwrap();
    }
    let applied = robot0["source"]["deposits_applied"].as_u64().unwrap();
    let failed = robot0["source"]["deposits_failed"].as_u64().unwrap();
    assert_eq!(
        applied + failed,
        steps.div_ceil(5),
        "one deposit every 5 steps: {robot0}"
    );
    let through_gateways = field_summary["deposits_applied"].as_u64().unwrap()
        - world_summary["deposits_sent"].as_u64().unwrap();
    println!(
        "primary {signal:?} at step {at}: robot 0 deposits {applied} applied, {failed} unanswered; \
         the field applied {through_gateways} through the gateways"
    );
    assert!(
        applied <= through_gateways && through_gateways <= applied + failed,
        "field applied {through_gateways} gateway deposits; robot 0 made {applied} + {failed} \
         unanswered: {field_summary}"
    );
    if signal == Signal::SIGSTOP {
        assert!(
            gateway_deposits <= applied + failed,
            "{gateway_deposits} forwarded"
        );
    }
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

#[test]
fn the_follower_keeps_following_when_the_primary_gateway_is_killed() {
    primary_goes_away(Signal::SIGKILL);
}

#[test]
fn the_follower_keeps_following_when_the_primary_gateway_is_stopped() {
    primary_goes_away(Signal::SIGSTOP);
}
