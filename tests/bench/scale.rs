//! `pheromone bench --only scale` at small sizes reports every figure of every run in its JSON
//! (no figure's value is asserted, only that it is there and sane), and a run above the host's
//! open-file limit or `/dev/shm` is refused before anything starts, naming the limit (issue 52).

use std::process::Command;
use std::time::Duration;

use crate::harness::*;

#[test]
fn bench_scale_reports_every_figure_of_each_size_and_mode_in_json() {
    let out = Proc::spawn(&[
        "bench",
        "--smoke",
        "--json",
        "--no-pin",
        "--only",
        "scale",
        "--scale-robots",
        "2,3",
        "--scale-duration-s",
        "3",
    ])
    .wait_exit(Duration::from_secs(300));
    assert!(out.status.success(), "bench failed: {}", stderr(&out));
    let r = json(&out);
    assert_eq!(
        r["sections"],
        serde_json::json!(["scale"]),
        "{}",
        r["sections"]
    );
    let scale = &r["scale"];
    assert_eq!(scale["scenario"], "ias-ss");
    assert!(matches!(scale["build"].as_str(), Some("debug" | "release")));
    let rows = scale["rows"].as_array().expect("scale.rows");
    assert_eq!(rows.len(), 4, "2 sizes x 2 modes: {scale}");
    for row in rows {
        assert!(row["error"].is_null(), "a run failed: {row}");
        let n = row["robots"].as_u64().unwrap();
        let processes = row["processes"].as_u64().unwrap();
        for k in ["startup_s", "total_s", "wall_per_sim_s", "sim_time_s"] {
            assert!(row[k].as_f64().is_some_and(|v| v >= 0.0), "{k}: {row}");
        }
        for k in ["peak_rss_bytes", "peak_pss_bytes", "samples"] {
            assert!(row[k].as_u64().is_some_and(|v| v > 0), "{k}: {row}");
        }
        assert!(row["shm_bytes"].as_u64().is_some(), "{row}");
        match row["mode"].as_str() {
            // The sim, the field, the world, and each robot's localizer, depositor, follower.
            Some("processes") => {
                assert_eq!(processes, 3 + 3 * n, "{row}");
                assert!(row["services"].as_u64().unwrap() > 3 * n, "{row}");
                assert!(row["shm_bytes"].as_u64().unwrap() > 0, "{row}");
            }
            Some("single-process") => {
                assert_eq!(processes, 1, "{row}");
                assert_eq!(row["services"], 0, "{row}");
            }
            m => panic!("mode {m:?}: {row}"),
        }
    }
    let growth = scale["growth"].as_object().expect("scale.growth");
    for k in [
        "startup_s",
        "wall_per_sim_s",
        "peak_rss_bytes",
        "processes",
        "services",
    ] {
        let g = &growth[&format!("processes/{k}")];
        assert!(
            g["exponent"].as_f64().is_some_and(f64::is_finite),
            "{k}: {g}"
        );
        assert_eq!(g["points"], 2, "{k}: {g}");
    }
}

#[test]
fn a_run_above_the_open_file_limit_is_refused_naming_it_before_anything_starts() {
    // 8 robots of ias-ss: 26 processes, which need more than 200 open files in the sim.
    let out = Command::new("prlimit")
        .arg("--nofile=200:200")
        .arg(bin())
        .args([
            "sim",
            "ias-ss",
            "--robots",
            "8",
            "--duration",
            "1",
            "--no-out",
        ])
        .output()
        .expect("run prlimit (util-linux)");
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("RLIMIT_NOFILE") && err.contains(" is 200"),
        "{err}"
    );
    assert!(err.contains("nothing was started"), "{err}");
}

/// A run whose field's frames cannot fit in `/dev/shm` is refused before anything starts,
/// naming `/dev/shm`, its free bytes and the need (exit 2). The frames asked for (2 GiB each, a
/// pool for 1000 readers: about 6 TB) fit on no host. (The other refusal, more processes than
/// `MAX_PARTICIPANTS`, no scenario can reach: 256 robots at most, mappers only up to 17.)
#[test]
fn a_run_whose_frames_do_not_fit_in_dev_shm_is_refused_naming_it_before_anything_starts() {
    let mut s = pheromone_bench::scale::swarm(4, 1.0).expect("the swarm scenario");
    s.field.width = 16384;
    s.field.height = 16384;
    s.field.cell_size_m = 0.002;
    s.field.max_readers = 1000;
    let dir = std::env::temp_dir().join(unique("scale-shm"));
    std::fs::create_dir(&dir).unwrap();
    let path = dir.join("big-field.toml");
    std::fs::write(&path, s.to_toml().expect("TOML")).unwrap();
    let out = Command::new(bin())
        .args(["sim", path.to_str().unwrap(), "--duration", "1", "--no-out"])
        .output()
        .expect("run pheromone sim");
    std::fs::remove_dir_all(&dir).unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("free bytes in /dev/shm") && err.contains("the run needs "),
        "{err}"
    );
    assert!(err.contains("nothing was started"), "{err}");
}
