//! `pheromone bench`: a small run prints every figure as one JSON object; speed never asserted.
//!
//! A run with a few samples of everything: each latency is ordered (p50 ≤ p99 ≤ p99.9 ≤ max) and
//! positive.

mod peers;
mod scale;

use std::time::Duration;

use serde_json::Value;

use crate::harness::*;

fn check_latency(v: &Value, what: &str) {
    let get = |k: &str| {
        v.get(k)
            .and_then(Value::as_f64)
            .unwrap_or_else(|| panic!("{what}.{k} missing or not a number: {v}"))
    };
    let (p50, p99, p999, max) = (get("p50"), get("p99"), get("p999"), get("max"));
    assert!(p50 > 0.0, "{what}: p50 {p50} is not positive");
    assert!(
        p50 <= p99 && p99 <= p999 && p999 <= max,
        "{what}: percentiles out of order: {v}"
    );
    assert!(get("samples") >= 1.0, "{what}: no samples");
}

// A test reads as one scenario, top to bottom (the line limit is for non-test code).
#[allow(clippy::too_many_lines)]
#[test]
fn bench_smoke_run_reports_every_figure_as_one_json_object() {
    let out = Proc::spawn(&[
        "bench",
        "--smoke",
        "--json",
        "--tick-hz",
        "200",
        "--visible-width",
        "256",
    ])
    .wait_exit(Duration::from_secs(300));
    assert!(out.status.success(), "bench failed: {}", stderr(&out));
    let r = json(&out);

    let machine = &r["machine"];
    assert!(
        machine["cpu_model"].as_str().is_some_and(|s| !s.is_empty()),
        "{machine}"
    );
    assert!(
        machine["cores"].as_u64().is_some_and(|c| c >= 1),
        "{machine}"
    );

    let ticks = r["tick_vs_memcpy"].as_object().expect("tick_vs_memcpy");
    assert!(!ticks.is_empty());
    for (size, row) in ticks {
        for k in ["memcpy_us", "exponential_us", "ambient_us"] {
            assert!(
                row[k].as_f64().is_some_and(|v| v > 0.0),
                "tick_vs_memcpy.{size}.{k}: {row}"
            );
        }
        for k in [
            "exponential_ratio",
            "ambient_ratio",
            "ambient_reference_ratio",
        ] {
            assert!(
                row[k].as_f64().is_some_and(|v| v > 0.0),
                "tick_vs_memcpy.{size}.{k}: {row}"
            );
        }
    }

    let hop = &r["hop_ns"];
    check_latency(&hop["ours"], "hop_ns.ours");
    check_latency(&hop["raw_iceoryx2"], "hop_ns.raw_iceoryx2");
    check_latency(&hop["busy_poll"]["ours"], "hop_ns.busy_poll.ours");
    check_latency(
        &hop["busy_poll"]["raw_iceoryx2"],
        "hop_ns.busy_poll.raw_iceoryx2",
    );

    let zenoh_built = r["zenoh_built"].as_bool().expect("zenoh_built");
    assert_eq!(zenoh_built, cfg!(feature = "zenoh"));
    for size in ["1MiB", "16MiB"] {
        let f = &r["frame_ns"][size];
        for k in [
            "ours",
            "uds_serde",
            "ours_busy_poll",
            "raw_iceoryx2",
            "raw_iceoryx2_busy_poll",
            "ours_spin",
            "raw_iceoryx2_spin",
        ] {
            check_latency(&f[k], &format!("frame_ns.{size}.{k}"));
        }
        for k in ["ours", "uds_serde"] {
            check_latency(
                &f["readers_8"][k],
                &format!("frame_ns.{size}.readers_8.{k}"),
            );
        }
        for z in [&f["zenoh"], &f["readers_8"]["zenoh"]] {
            if zenoh_built {
                check_latency(z, &format!("frame_ns.{size}.zenoh"));
            } else {
                assert!(z.is_null(), "zenoh figures without zenoh: {z}");
            }
        }
    }

    let v = &r["deposit_to_visible_us"];
    check_latency(v, "deposit_to_visible_us");
    check_latency(
        &v["tick_compute_us"],
        "deposit_to_visible_us.tick_compute_us",
    );
    assert_eq!(v["tick_hz"].as_f64(), Some(200.0));

    // Issue 33: publishing on deposit with SCHED_FIFO, the field spinning a period, the
    // follower busy-polling; and the field's tick timing beside two busy loops.
    let rt = &r["deposit_to_visible_on_deposit_rt_us"];
    check_latency(rt, "deposit_to_visible_on_deposit_rt_us");
    check_tick_timing(&r);

    // Seed 002's PIR through a gateway process beside the direct shared-memory read, and the
    // flood: replies counted, the gateway's CPU time measured.
    let g = &r["gateway_pir"];
    check_latency(&g["pir_round_trip_ns"], "gateway_pir.pir_round_trip_ns");
    check_latency(&g["shm_antennas_ns"], "gateway_pir.shm_antennas_ns");
    check_latency(
        &r["gateway_pir_loaded_rt"]["pir_round_trip_ns"],
        "gateway_pir_loaded_rt.pir_round_trip_ns",
    );
    let flood = &g["flood"];
    assert!(flood["replies"].as_u64().is_some_and(|n| n > 0), "{flood}");
    for k in ["pirs_per_s", "gateway_cpu_s", "pirs_per_cpu_s"] {
        assert!(flood[k].as_f64().is_some_and(|v| v > 0.0), "{k}: {flood}");
    }
    let names: Vec<&str> = r["targets"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|t| t["name"].as_str())
        .collect();
    assert!(
        names.iter().any(|n| n.starts_with("PIR round trip")),
        "{names:?}"
    );

    check_mirror(&r, zenoh_built);
    check_ros2(&r, zenoh_built);

    // libpheromone's C reader beside the Rust reader, as ratios of the same run.
    let c = &r["c_abi"];
    check_latency(&c["frame_rust_ns"], "c_abi.frame_rust_ns");
    check_latency(&c["frame_c_ns"], "c_abi.frame_c_ns");
    for k in [
        "frame_ratio_p50",
        "frame_ratio_p99",
        "sample_rust_ns",
        "sample_c_ns",
        "sample_ratio",
        "sample_batch_c_ns",
        "sample_batch_ratio",
    ] {
        assert!(c[k].as_f64().is_some_and(|v| v > 0.0), "c_abi.{k}: {c}");
    }
    for name in [
        "C reader frame latency p50 / Rust reader's",
        "C sampling (value + gradient) / Rust FrameView's",
        "C batch sampling (pheromone_sample_many) / Rust FrameView's",
    ] {
        assert!(names.contains(&name), "no target '{name}' in {names:?}");
    }

    let targets = r["targets"].as_array().expect("targets");
    assert!(targets.len() >= 6, "{targets:?}");
    // Issue 18's frame goals, each with a measured value.
    for name in [
        "frame p50 ours / raw iceoryx2 at 1 MiB (wait)",
        "frame p50 ours / raw iceoryx2 at 16 MiB (busy-poll)",
        "frame p50 16 MiB / 1 MiB: ours / raw iceoryx2's (busy-poll)",
    ] {
        let t = targets
            .iter()
            .find(|t| t["name"] == name)
            .unwrap_or_else(|| panic!("no target '{name}' in {targets:?}"));
        assert!(t["measured"].as_f64().is_some_and(|m| m > 0.0), "{t}");
    }
    assert!(targets.iter().all(|t| t["met"].is_boolean()));
}

/// `tick_timing`: 100 Hz and 1 kHz, each with the default scheduler, SCHED_FIFO, and SCHED_FIFO
/// with a spin; lateness percentiles ordered, gaps of at least most of a period. As root (CI),
/// the SCHED_FIFO rows got it, and each has its two targets.
fn check_tick_timing(r: &Value) {
    let rows = r["tick_timing"].as_array().expect("tick_timing");
    let configs: Vec<(f64, u64)> = rows
        .iter()
        .map(|t| {
            (
                t["tick_hz"].as_f64().unwrap(),
                t["spin_us"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        configs,
        [
            (100.0, 0),
            (100.0, 0),
            (100.0, 200),
            (1000.0, 0),
            (1000.0, 0),
            (1000.0, 200)
        ],
        "{rows:?}"
    );
    for t in rows {
        let l = &t["lateness"];
        let get = |k: &str| l[k].as_u64().unwrap_or_else(|| panic!("lateness.{k}: {t}"));
        assert!(
            get("p50_us") <= get("p99_us") && get("p99_us") <= get("max_us"),
            "{t}"
        );
        assert!(t["ticks"].as_u64().is_some_and(|n| n >= 2), "{t}");
        assert!(
            t["longest_gap_periods"].as_f64().is_some_and(|g| g > 0.5),
            "{t}"
        );
        assert_eq!(t["busy_loops"], 2, "{t}");
    }
    let is_root = std::fs::read_to_string("/proc/self/status").is_ok_and(|s| {
        s.lines()
            .any(|l| l.starts_with("Uid:") && l.split_whitespace().nth(1) == Some("0"))
    });
    if is_root {
        let realtime = rows.iter().filter(|t| t["realtime"] == true).count();
        assert_eq!(realtime, 4, "{rows:?}");
        let names: Vec<&str> = r["targets"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|t| t["name"].as_str())
            .collect();
        let timing = names
            .iter()
            .filter(|n| n.contains("SCHED_FIFO, spin"))
            .count();
        assert_eq!(timing, 8, "{names:?}");
    }
}

/// A positive finite number at `v[k]`.
fn positive(v: &Value, k: &str, what: &str) -> f64 {
    let x = v[k]
        .as_f64()
        .unwrap_or_else(|| panic!("{what}.{k} missing or not a number: {v}"));
    assert!(x.is_finite() && x > 0.0, "{what}.{k} = {x}: {v}");
    x
}

/// Issue 15's `mirror` section: present (finite figures) with Zenoh, null without.
fn check_mirror(r: &Value, zenoh_built: bool) {
    let m = &r["mirror"];
    if !zenoh_built {
        assert!(m.is_null(), "a mirror section without zenoh: {m}");
        return;
    }
    for k in [
        "raw_frame_bytes",
        "raw_bytes_per_s",
        "keyframe_bytes",
        "keyframe_ratio",
        "catch_up_ms",
        "start_to_live_ms",
        "tick_hz",
    ] {
        positive(m, k, "mirror");
    }
    let wire = m["wire"].as_array().expect("mirror.wire");
    let rates: Vec<f64> = wire
        .iter()
        .filter_map(|w| w["deposits_per_s"].as_f64())
        .collect();
    assert_eq!(rates, [10.0, 1000.0], "{m}");
    for w in wire {
        for k in [
            "frames_per_s",
            "inputs_bytes_per_s",
            "keyframe_bytes",
            "wire_bytes_per_s",
            "ratio_to_raw",
        ] {
            positive(w, k, "mirror.wire");
        }
        assert!(
            w["ratio_to_raw"].as_f64().unwrap() < 1.0,
            "a mirror sends more than the frames: {w}"
        );
    }
    check_latency(&m["lag_us"], "mirror.lag_us");
    assert_eq!(m["checksum_mismatches"], 0, "{m}");
    let names: Vec<&str> = r["targets"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|t| t["name"].as_str())
        .collect();
    assert!(
        names.iter().any(|n| n.starts_with("mirror wire bytes")),
        "{names:?}"
    );
}

/// Issue 46's `ros2` section: `pheromone ros2` and the plain Zenoh publisher each measured
/// (frames reached the subscriber, CPU used), the ratio, and its target (≤ 1.5); null without
/// Zenoh.
fn check_ros2(r: &Value, zenoh_built: bool) {
    let x = &r["ros2"];
    if !zenoh_built {
        assert!(x.is_null(), "a ros2 section without zenoh: {x}");
        return;
    }
    let topics = x["topic_bytes"].as_array().expect("ros2.topic_bytes");
    // A GridMap and one OccupancyGrid (the bench field has one channel of 512² cells).
    assert_eq!(topics.len(), 2, "{x}");
    assert!(
        topics
            .iter()
            .all(|b| b.as_u64().is_some_and(|b| b > 512 * 512)),
        "{x}"
    );
    for who in ["ros2", "plain_zenoh"] {
        for k in [
            "window_s",
            "frames_per_s",
            "mb_per_s",
            "cpu_share",
            "cpu_ms_per_mb",
        ] {
            positive(&x[who], k, &format!("ros2.{who}"));
        }
    }
    let ratio = positive(x, "cpu_per_mb_ratio", "ros2");
    let idle = &x["idle"];
    positive(idle, "seconds", "ros2.idle");
    assert!(
        idle["cpu_share"].as_f64().is_some_and(|c| c >= 0.0),
        "{idle}"
    );
    // Nobody subscribed: frames skipped, not serialized.
    assert!(
        idle["frames_without_subscribers"]
            .as_u64()
            .is_some_and(|n| n >= 1),
        "{idle}"
    );
    let targets = r["targets"].as_array().expect("targets");
    let t = targets
        .iter()
        .find(|t| {
            t["name"]
                .as_str()
                .is_some_and(|n| n.starts_with("pheromone ros2 CPU per published MB"))
        })
        .unwrap_or_else(|| panic!("no ros2 target in {targets:?}"));
    assert_eq!(t["op"], "<=", "{t}");
    assert_eq!(t["limit"].as_f64(), Some(1.5), "{t}");
    let measured = t["measured"].as_f64().expect("measured");
    assert!((measured - ratio).abs() <= 0.01 * ratio, "{t} vs {ratio}");
}

#[test]
fn bench_only_ros2_reports_its_cpu_per_mb_row() {
    let out = run(&["bench", "--smoke", "--json", "--only", "ros2"]);
    if !cfg!(feature = "zenoh") {
        assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
        assert!(stderr(&out).contains("--only ros2"), "{}", stderr(&out));
        return;
    }
    assert!(out.status.success(), "bench failed: {}", stderr(&out));
    let r = json(&out);
    assert_eq!(r["sections"], serde_json::json!(["ros2"]), "{r}");
    check_ros2(&r, true);
    assert!(r["mirror"].is_null(), "{r}");
}

#[test]
fn bench_only_runs_the_sections_it_is_given() {
    let out = run(&["bench", "--smoke", "--json", "--only", "tick"]);
    assert!(out.status.success(), "bench failed: {}", stderr(&out));
    let r = json(&out);
    assert_eq!(r["sections"], serde_json::json!(["tick"]), "{r}");
    assert!(!r["tick_vs_memcpy"].as_object().unwrap().is_empty(), "{r}");
    assert!(r["frame_ns"].as_object().unwrap().is_empty(), "{r}");
    assert!(r["merge_vs_memcpy"].as_object().unwrap().is_empty(), "{r}");
    // The merge section (issue 33): the merge and its reference against a memcpy, and a target.
    let out = run(&["bench", "--smoke", "--json", "--only", "merge"]);
    assert!(out.status.success(), "bench failed: {}", stderr(&out));
    let m = json(&out);
    let merges = m["merge_vs_memcpy"].as_object().expect("merge_vs_memcpy");
    assert!(!merges.is_empty(), "{m}");
    for (size, row) in merges {
        for k in [
            "memcpy_us",
            "merge_us",
            "merge_ratio",
            "reference_us",
            "reference_ratio",
            "average_us",
            "average_ratio",
            "average_reference_us",
            "average_reference_ratio",
        ] {
            assert!(
                row[k].as_f64().is_some_and(|v| v > 0.0),
                "{size}.{k}: {row}"
            );
        }
    }
    let names: Vec<&str> = m["targets"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|t| t["name"].as_str())
        .collect();
    assert!(
        names.iter().any(|n| n.starts_with("merge / memcpy")),
        "{names:?}"
    );
    for k in ["hop_ns", "deposit_to_visible_us", "gateway_pir", "mirror"] {
        assert!(r[k].is_null(), "{k} measured with --only tick: {r}");
    }
    // Repeated: every run, and each target's min / median / max over them.
    let out = run(&[
        "bench",
        "--smoke",
        "--json",
        "--only",
        "tick",
        "--repeats",
        "3",
    ]);
    assert!(out.status.success(), "bench failed: {}", stderr(&out));
    let r = json(&out);
    assert_eq!(r["runs"].as_array().map(Vec::len), Some(3), "{r}");
    let spread = r["targets"].as_array().expect("targets");
    assert!(!spread.is_empty(), "{r}");
    for t in spread {
        let v = |k: &str| t[k].as_f64().unwrap_or_else(|| panic!("{k}: {t}"));
        assert!(v("min") <= v("median") && v("median") <= v("max"), "{t}");
        assert_eq!(t["runs"], 3, "{t}");
    }
    let out = run(&["bench", "--only", "everything"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    if !cfg!(feature = "zenoh") {
        let out = run(&["bench", "--only", "mirror", "--json"]);
        assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
        assert!(stderr(&out).contains("zenoh"), "{}", stderr(&out));
    }
}

#[test]
fn bench_rejects_a_bad_tick_rate_with_status_2() {
    let out = run(&["bench", "--tick-hz=0", "--json"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--tick-hz"), "{}", stderr(&out));
    assert!(out.stdout.is_empty());
}
