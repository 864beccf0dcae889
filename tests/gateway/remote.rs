//! `sim trail-following --remote`: robots reading through a gateway track the shared-memory run.
//!
//! `pheromone sim trail-following --remote`: the antenna robots read the field only through a
//! `pheromone gateway` the sim starts (PIR over UDP loopback), in lockstep; their mean path
//! error stays within 10 % of the shared-memory run's for the same seed.

use serde_json::Value;

use crate::harness::*;

fn sim(args: &[&str]) -> Value {
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

/// The process report of `who` ("gateway", "follower r0") in a run's metrics.
fn report<'a>(m: &'a Value, who: &str) -> &'a Value {
    m["processes"]
        .as_array()
        .and_then(|a| a.iter().find(|p| p["role"] == who))
        .map(|p| &p["summary"])
        .unwrap_or_else(|| panic!("no report of {who} in {}", m["processes"]))
}

#[test]
fn remote_antenna_robots_follow_through_a_gateway_as_well_as_in_shared_memory() {
    let common = [
        "sim",
        "trail-following",
        "--no-out",
        "--json",
        "--seed",
        "3",
    ];
    let mut args = common.to_vec();
    args.push("--single-process");
    let shm = sim(&args);
    let mut args = common.to_vec();
    args.push("--remote");
    let remote = sim(&args);
    assert_eq!(remote["mode"], "processes-remote", "{remote}");
    assert_eq!(remote["steps"], shm["steps"]);

    // The gateway served every antenna reading; the robots asked nothing of shared memory.
    let gateway = report(&remote, "gateway");
    let steps = remote["steps"].as_u64().unwrap();
    for robot in ["follower r0", "follower r1"] {
        let f = report(&remote, robot);
        assert_eq!(f["role"]["steps"].as_u64(), Some(steps), "{robot}: {f}");
        assert!(
            f["source"]["source"]
                .as_str()
                .is_some_and(|s| s.starts_with("udp://127.0.0.1:")),
            "{robot}: {f}"
        );
        assert!(
            f["source"]["reads"].as_u64().is_some_and(|n| n >= steps),
            "{robot}: a PIR for every step: {f}"
        );
    }
    assert!(
        gateway["pirs"].as_u64().is_some_and(|n| n >= 2 * steps),
        "the gateway served both robots' PIRs: {gateway}"
    );
    assert_eq!(gateway["dropped"], 0, "{gateway}");

    for path in ["straight", "curved"] {
        let a = shm["metrics"]["mean_path_error_m"][path].as_f64().unwrap();
        let b = remote["metrics"]["mean_path_error_m"][path]
            .as_f64()
            .unwrap();
        println!("{path}: mean path error {a:.4} m in shared memory, {b:.4} m remote");
        assert!(a > 0.0 && b > 0.0, "{path}: {a} {b}");
        // A PIR reply carries the readings a shared-memory follower reads from the same frame
        // (on the scenario's source channels, the gateway's directional eq. 4 is the follower's).
        assert_eq!(a, b, "{path}: remote {b} m vs shared memory {a} m");
    }
}

#[test]
fn remote_is_refused_in_one_process_and_without_antenna_robots() {
    let o = run(&["sim", "trail-following", "--single-process", "--remote"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--remote"), "{}", stderr(&o));

    let o = run(&["sim", "ias-ss", "--remote", "--no-out"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--remote") && stderr(&o).contains("antenna"),
        "{}",
        stderr(&o)
    );
}
