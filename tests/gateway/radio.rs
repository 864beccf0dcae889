//! `sim trail-following --remote --clients N`: the antenna robots share seed 002's simulated
//! radio channel with N − 2 other thin clients (docs/gateway.md, "A radio that shares the air").
//! The air is a function of the seed, so two runs as processes give the same metrics; its
//! outcomes are the ones each robot process saw; the delivery rate falls as N grows.

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

fn remote(clients: u32, seed: &str) -> Value {
    let n = clients.to_string();
    sim(&[
        "sim",
        "trail-following",
        "--no-out",
        "--json",
        "--seed",
        seed,
        "--remote",
        "--clients",
        &n,
    ])
}

fn rate(m: &Value) -> f64 {
    m["metrics"]["radio"]["all"]["delivery_rate"]
        .as_f64()
        .unwrap_or_else(|| panic!("no metrics.radio.all: {}", m["metrics"]))
}

#[test]
fn thin_clients_on_a_shared_air_lose_requests_as_more_share_it_the_same_for_a_seed() {
    let runs: Vec<(u32, Value)> = [2, 4, 8].iter().map(|&n| (n, remote(n, "3"))).collect();
    for (n, m) in &runs {
        assert_eq!(m["mode"], "processes-remote", "{m}");
        let radio = &m["metrics"]["radio"];
        assert_eq!(radio["config"]["clients"], *n, "{radio}");
        let steps = m["steps"].as_u64().unwrap();
        assert_eq!(radio["periods"], steps);
        assert_eq!(radio["all"]["sent"], steps * *n as u64, "{radio}");
        // Each robot process saw the outcomes the metrics report for its client.
        for robot in [0u32, 1] {
            let who = format!("follower r{robot}");
            let p = m["processes"]
                .as_array()
                .and_then(|a| a.iter().find(|p| p["role"] == who.as_str()))
                .unwrap_or_else(|| panic!("no {who} in {}", m["processes"]));
            let seen = &p["summary"]["radio"];
            let reported = &radio["robots"][robot.to_string()];
            assert_eq!(
                seen["sent"], reported["sent"],
                "{who}: {seen} vs {reported}"
            );
            assert_eq!(seen["delivered"], reported["delivered"], "{who}");
            assert_eq!(seen["client"], robot);
        }
        println!(
            "N = {n}: delivered {} of {}, {} frames collided, mean latency {} s, path error {}",
            radio["all"]["delivered"],
            radio["all"]["sent"],
            radio["collided_frames"],
            radio["all"]["mean_latency_s"],
            m["metrics"]["mean_path_error_m"]
        );
    }
    let rates: Vec<f64> = runs.iter().map(|(_, m)| rate(m)).collect();
    assert!(rates[0] > rates[1] && rates[1] > rates[2], "{rates:?}");
    assert!(runs[2].1["metrics"]["radio"]["collided_frames"].as_u64() > Some(0));

    // The same seed as processes again: the same air and the same paths, to every digit.
    let again = remote(4, "3");
    assert_eq!(again["metrics"], runs[1].1["metrics"]);
    // Another seed draws another air.
    let other = remote(4, "4");
    assert_ne!(other["metrics"]["radio"], runs[1].1["metrics"]["radio"]);
}

#[test]
fn a_lone_client_gets_every_reply_and_follows_as_without_a_radio() {
    let common = [
        "sim",
        "trail-following",
        "--no-out",
        "--json",
        "--seed",
        "5",
    ];
    let one = |extra: &[&str]| {
        let mut args = common.to_vec();
        args.extend(["--robots", "1"]);
        args.extend(extra);
        sim(&args)
    };
    let single = one(&["--single-process"]);
    let air = one(&["--remote", "--clients", "1"]);
    let radio = &air["metrics"]["radio"];
    assert_eq!(radio["all"]["delivery_rate"], 1.0, "{radio}");
    assert_eq!(radio["collided_frames"], 0, "{radio}");
    // 25 + 20 bytes at 9600 bit/s and a 1 ms turnaround, after a jitter under 2 ms.
    let latency = radio["all"]["mean_latency_s"].as_f64().unwrap();
    assert!((0.0478..0.0499).contains(&latency), "{latency}");
    assert_eq!(
        air["metrics"]["mean_path_error_m"],
        single["metrics"]["mean_path_error_m"]
    );
}

#[test]
fn radio_settings_out_of_range_are_refused_by_key_and_value() {
    let o = run(&["sim", "trail-following", "--remote", "--clients", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--clients 0"), "{}", stderr(&o));
    // Both robots are clients on the air: one client is too few.
    let o = run(&["sim", "trail-following", "--remote", "--clients", "1"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("radio.clients = 1"), "{}", stderr(&o));
    let o = run(&["sim", "trail-following", "--clients", "4"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--remote"), "{}", stderr(&o));

    let dir = std::env::temp_dir().join(format!("pheromone-radio-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = include_str!("../../examples/scenarios/trail-following.toml");
    for (line, want) in [
        ("bitrate_bps = -5.0", "radio.bitrate_bps = -5"),
        ("loss_probability = 2.0", "radio.loss_probability = 2"),
        ("slot_s = 0.0", "radio.slot_s = 0"),
        ("backoff_slots = 0", "radio.backoff_slots = 0"),
    ] {
        let path = dir.join("radio.toml");
        std::fs::write(&path, format!("{text}\n[radio]\nclients = 4\n{line}\n")).unwrap();
        let o = run(&["sim", path.to_str().unwrap(), "--remote", "--no-out"]);
        assert_eq!(o.status.code(), Some(2), "{line}: {}", stderr(&o));
        assert!(stderr(&o).contains(want), "{line}: {}", stderr(&o));
    }
    // [radio] is the thin clients' air: a run without --remote is refused.
    let path = dir.join("radio.toml");
    std::fs::write(&path, format!("{text}\n[radio]\nclients = 4\n")).unwrap();
    let o = run(&["sim", path.to_str().unwrap(), "--no-out"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--remote"), "{}", stderr(&o));
    // Without `clients`, one client per robot through the gateway; --clients overrides it.
    std::fs::write(&path, format!("{text}\n[radio]\nbitrate_bps = 38400.0\n")).unwrap();
    let file = path.to_str().unwrap();
    let m = sim(&["sim", file, "--remote", "--no-out", "--json"]);
    assert_eq!(
        m["metrics"]["radio"]["config"]["clients"], 2,
        "{}",
        m["metrics"]
    );
    assert_eq!(m["metrics"]["radio"]["config"]["bitrate_bps"], 38400.0);
    let m = sim(&[
        "sim",
        file,
        "--remote",
        "--clients",
        "3",
        "--no-out",
        "--json",
    ]);
    assert_eq!(m["metrics"]["radio"]["config"]["clients"], 3);
    std::fs::remove_dir_all(&dir).unwrap();
}
