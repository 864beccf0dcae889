//! `pheromone sweep trail-following` (seed 002's parameter study): a tiny study as processes
//! writes its CSV columns, a metric that moves with the parameter, the chart; `--single-process`
//! gives the same CSV; bad lists and the mapping sweep's flags exit with status 2; SIGTERM stops
//! it with 143.

use std::path::Path;

use crate::harness::*;

/// `sweep trail-following --omega-gain 1` (the scenario's gain is added), seed 1, into `dir`.
fn study(dir: &Path, single: bool) -> std::process::Output {
    let mut args = vec![
        "sweep",
        "trail-following",
        "--omega-gain",
        "1",
        "--trials",
        "1",
        "--out",
        dir.to_str().unwrap(),
        "--json",
    ];
    if single {
        args.push("--single-process");
    }
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    o
}

#[test]
fn a_tiny_trail_study_writes_its_columns_and_the_error_moves_with_the_gain() {
    let dir = std::env::temp_dir().join(unique("sweep-trail"));
    let o = study(&dir, false);
    let csv = std::fs::read_to_string(dir.join("sweep.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "param,value,shipped,seed,path,mean_path_error_m,turning_share"
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // 2 gains (1 and the scenario's) × 1 seed × 2 paths.
    assert_eq!(rows.len(), 4, "{csv}");
    let json = json(&o);
    let shipped = json["shipped"]["omega-gain"].as_f64().unwrap();
    assert_ne!(shipped, 1.0, "{json}");
    let error = |gain: f64, path: &str| -> f64 {
        let r = rows
            .iter()
            .find(|r| r[1].parse::<f64>().unwrap() == gain && r[4] == path)
            .unwrap_or_else(|| panic!("no row of gain {gain}, {path}: {csv}"));
        assert_eq!(r[0], "omega_gain_rad_per_s");
        assert_eq!(r[2], if gain == shipped { "true" } else { "false" });
        assert_eq!(r[3], "1");
        let share: f64 = r[6].parse().unwrap();
        assert!((0.0..=1.0).contains(&share), "{r:?}");
        r[5].parse().unwrap()
    };
    for path in ["straight", "curved"] {
        let (weak, ours) = (error(1.0, path), error(shipped, path));
        assert!(ours > 0.0 && weak > 0.0);
        assert!(
            weak > ours,
            "{path}: gain 1 {weak} m, gain {shipped} {ours} m"
        );
    }
    let png = std::fs::read(dir.join("sweep_trail.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    // The same point in one process: the same CSV, byte for byte.
    let one = std::env::temp_dir().join(unique("sweep-trail-one"));
    study(&one, true);
    let csv_one = std::fs::read_to_string(one.join("sweep.csv")).unwrap();
    assert_eq!(csv, csv_one);
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&one);
}

#[test]
fn trail_study_refuses_bad_lists_and_the_mapping_flags_with_status_2() {
    for (args, names) in [
        (&["trail-following", "--fov", "0"][..], "--fov"),
        (&["trail-following", "--speed", "fast"][..], "fast"),
        (&["trail-following", "--normalize", "-1"][..], "--normalize"),
        (&["trail-following", "--duration", "5"][..], "--duration"),
        (&["trail-following", "--rc-m", "4"][..], "--rc-m"),
        (&["ias-ss", "--omega-gain", "2"][..], "trail study"),
    ] {
        let mut argv = vec!["sweep"];
        argv.extend_from_slice(args);
        let o = run(&argv);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(names), "{args:?}: {e}");
    }
}

/// SIGTERM during a study as processes: it stops, exits 143, writes nothing and leaves nothing
/// in /dev/shm.
#[test]
fn sigterm_stops_a_trail_study_with_143_and_nothing_written() {
    use crate::crash::{Run, WAIT};
    let run = Run::new("trs");
    let out = run.dir.join("out");
    let sweep = run.spawn(
        &[
            "sweep",
            "trail-following",
            "--omega-gain",
            "1,2,4,5,6,8",
            "--trials",
            "5",
            "--out",
            out.to_str().unwrap(),
        ],
        "sweep",
    );
    eventually(WAIT, "the study to start its runs", || {
        run.log("sweep").contains("as processes").then_some(())
    });
    let pid = nix::unistd::Pid::from_raw(sweep.pid() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
    let o = sweep.wait_exit(WAIT);
    let log = run.log("sweep");
    assert_eq!(o.status.code(), Some(143), "{log}");
    assert!(!out.join("sweep.csv").exists(), "{log}");
    run.wait_nodes_gone(WAIT);
    assert_eq!(run.shm_entries(), Vec::<String>::new(), "{log}");
}
