//! Issue 51's command-line seams: the deposit's `--tau` (alias `--amount`), `--print-scenario`,
//! negative numbers, and run directories. Every invocation of `sim` and `sweep` writes a
//! directory of its own: by default
//! `pheromone-out/<scenario>/<run-id>/` with `run.json` and `latest` links; `--out DIR` refused
//! when it holds anything, unless `--force`.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::harness::*;

/// `pheromone ARGS` run in `dir`.
fn run_in(dir: &Path, args: &[&str]) -> Output {
    pheromone_testkit::Cli::new(&bin())
        .args(args)
        .current_dir(dir)
        .output()
}

fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(unique(tag));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run_json(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("run.json")).unwrap()).unwrap()
}

/// The run directories under `dir` (the `latest` link left out), sorted.
fn runs_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "latest")
        .collect();
    v.sort();
    v
}

#[test]
fn runs_of_one_scenario_never_share_a_directory_and_latest_is_the_newest() {
    let cwd = scratch("rundir");
    let base = ["sim", "trail", "--single-process", "--duration", "3"];
    for extra in [&[][..], &[][..], &["--seed", "3"][..]] {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        let o = run_in(&cwd, &args);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let root = cwd.join("pheromone-out");
    let runs = runs_in(&root.join("trail"));
    assert_eq!(runs.len(), 3, "{runs:?}");
    for r in &runs {
        // 20261207T153504Z-3fa2
        assert_eq!(r.len(), 21, "{r}");
        assert!(
            r.ends_with(|c: char| c.is_ascii_hexdigit()) && r.contains("Z-"),
            "{r}"
        );
        let dir = root.join("trail").join(r);
        assert!(dir.join("metrics.json").is_file(), "{r}");
        let info = run_json(&dir);
        assert_eq!(info["scenario"], "trail");
        assert_eq!(info["status"], "done");
        assert_eq!(info["version"], env!("CARGO_PKG_VERSION"));
        assert_eq!(info["command"][1], "sim");
        assert!(info["files"]
            .as_array()
            .unwrap()
            .iter()
            .any(|f| f == "metrics.json"));
    }
    // The newest: the run with --seed 3, by both links.
    let newest = run_json(&root.join("latest"));
    assert_eq!(newest["seeds"], serde_json::json!([3]));
    assert_eq!(
        newest["flags"],
        serde_json::json!([
            "trail",
            "--single-process",
            "--duration",
            "3",
            "--seed",
            "3"
        ])
    );
    let link = std::fs::read_link(root.join("trail/latest")).unwrap();
    assert_eq!(run_json(&root.join("trail").join(link)), newest);
    assert!(newest["started_utc"].as_str().unwrap() <= newest["ended_utc"].as_str().unwrap());
    std::fs::remove_dir_all(&cwd).unwrap();
}

#[test]
fn a_non_empty_out_dir_is_refused_without_force() {
    let cwd = scratch("rundir-named");
    let out = cwd.join("mine");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("notes.txt"), b"keep").unwrap();
    let out_s = out.to_str().unwrap();
    let args = [
        "sim",
        "trail",
        "--single-process",
        "--duration",
        "3",
        "--out",
        out_s,
    ];
    let o = run_in(&cwd, &args);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains(out_s) && e.contains("--force") && e.contains("not empty"),
        "{e}"
    );
    assert_eq!(runs_in(&out), ["notes.txt"], "nothing written");
    let forced: Vec<&str> = args.iter().copied().chain(["--force"]).collect();
    let o = run_in(&cwd, &forced);
    assert!(o.status.success(), "{}", stderr(&o));
    let info = run_json(&out);
    assert!(info["files"]
        .as_array()
        .unwrap()
        .iter()
        .any(|f| f == "notes.txt"));
    assert_eq!(std::fs::read(out.join("notes.txt")).unwrap(), b"keep");
    assert!(
        !cwd.join("pheromone-out").exists(),
        "--out writes nothing else"
    );
    // The same for sweep, refused before it runs.
    let o = run_in(&cwd, &["sweep", "ias-ss", "--out", out_s]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains(out_s), "{}", stderr(&o));
    std::fs::remove_dir_all(&cwd).unwrap();
}

#[test]
fn a_sweep_writes_its_own_run_directory_with_run_json() {
    let cwd = scratch("rundir-sweep");
    let args = [
        "sweep",
        "ias-ss",
        "--robots",
        "1",
        "--trials",
        "2",
        "--duration",
        "5",
        "--jobs",
        "1",
        "--no-merge",
    ];
    let o = run_in(&cwd, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let root = cwd.join("pheromone-out/sweep-ias-ss");
    assert_eq!(runs_in(&root).len(), 1);
    let latest = root.join("latest");
    assert!(latest.join("sweep.csv").is_file());
    let info = run_json(&latest);
    assert_eq!(info["scenario"], "ias-ss");
    assert_eq!(info["seeds"], serde_json::json!([1, 2]));
    assert_eq!(info["command"][1], "sweep");
    std::fs::remove_dir_all(&cwd).unwrap();
}

#[test]
fn print_scenario_prints_a_built_in_scenario_that_loads_back_as_a_file() {
    let cwd = scratch("print-scenario");
    let o = run(&["sim", "--print-scenario", "wrong-area"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let file = cwd.join("mine.toml");
    std::fs::write(&file, &o.stdout).unwrap();
    let f = file.to_str().unwrap();
    let args = [
        "sim",
        f,
        "--single-process",
        "--duration",
        "3",
        "--no-out",
        "--json",
    ];
    let o = run_in(&cwd, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(json(&o)["scenario"], "wrong-area");
    // A node-graph one prints too; an unknown name is bad input naming the built-in ones.
    let o = run(&["sim", "--print-scenario", "regions"]);
    assert!(stdout(&o).contains("dock"), "{}", stderr(&o));
    let o = run(&["sim", "--print-scenario", "nope"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("nope") && e.contains("blind-leader"), "{e}");
    std::fs::remove_dir_all(&cwd).unwrap();
}

#[test]
fn a_negative_number_is_a_value_refused_by_its_flag_not_an_unknown_argument() {
    for args in [
        &["sim", "trail", "--no-out", "--duration", "-5"][..],
        &["sweep", "ias-ss", "--duration", "-5"][..],
    ] {
        let o = run(args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(
            e.contains("--duration -5") && !e.contains("unexpected"),
            "{args:?}: {e}"
        );
    }
}

#[test]
fn deposit_help_names_tau_and_its_old_name_amount() {
    let o = run(&["deposit", "--help"]);
    let h = stdout(&o);
    assert!(h.contains("--tau <TAU>") && h.contains("--amount"), "{h}");
    assert!(h.contains("det Σxy") && h.contains("not the peak"), "{h}");
}
