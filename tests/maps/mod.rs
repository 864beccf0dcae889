//! Scenarios on ROS map_server maps in both modes; malformed YAML and PGM files exit with 2.
//!
//! Scenarios on ROS map_server maps (issue 16): `pheromone sim ias-ss --map FILE.yaml` as
//! processes and `--single-process` with the same metrics, on the example map's walls; a
//! scenario's `[world] map` relative to the scenario file; malformed YAML and PGM files exit
//! with status 2 naming the file and the line or byte.

use std::path::{Path, PathBuf};

use crate::harness::*;
use crate::processes::assert_same_in_both_modes;

fn example_map() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/maps/rooms.yaml")
}

/// A `.npy` file of float32 cells: (shape, values).
fn read_npy(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let b = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&b[..8], b"\x93NUMPY\x01\x00", "{}", path.display());
    let len = u16::from_le_bytes([b[8], b[9]]) as usize;
    let header = std::str::from_utf8(&b[10..10 + len]).unwrap();
    assert!(header.contains("'descr': '<f4'"), "{header}");
    let shape = header
        .split_once("'shape': (")
        .and_then(|(_, r)| r.split_once(')'))
        .map(|(s, _)| s.split(',').filter_map(|d| d.trim().parse().ok()).collect())
        .unwrap();
    let cells = b[10 + len..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    (shape, cells)
}

#[test]
fn ias_ss_on_the_example_map_gives_the_same_metrics_as_processes_and_in_one_process() {
    let map = example_map();
    let map = map.to_str().unwrap();
    let m = assert_same_in_both_modes("ias-ss", &["--map", map, "--duration", "20", "--seed", "3"]);
    // The field covers the map (30 m × 20 m at the scenario's 0.1 m).
    assert_eq!(
        (m["field"]["width"].as_u64(), m["field"]["height"].as_u64()),
        (Some(300), Some(200)),
        "{m}"
    );
    assert!(
        m["metrics"]["exploration"]["team"]
            .as_f64()
            .is_some_and(|e| e > 0.0),
        "{m}"
    );

    // The walls marked on channel 1 are the map's: the hall's pillar, not ias-ss's own
    // wall at x = 10 m.
    let dir = std::env::temp_dir().join(unique("mapout"));
    let o = run(&[
        "sim",
        "ias-ss",
        "--map",
        map,
        "--duration",
        "2",
        "--single-process",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape, cells) = read_npy(&dir.join("field_final.npy"));
    assert_eq!(shape, vec![2, 200, 300]);
    let at = |c: usize, x_m: f64, y_m: f64| {
        cells[c * 60_000 + (y_m * 10.0) as usize * 300 + (x_m * 10.0) as usize]
    };
    assert!(at(1, 15.65, 10.0) > 0.5, "the pillar's edge is marked");
    assert!(at(1, 12.1, 8.0) > 0.5, "the wall at x = 12 m is marked");
    assert_eq!(
        at(1, 10.0, 7.0),
        0.0,
        "ias-ss's own wall at x = 10 m is not there"
    );
    assert!(cells.iter().all(|v| v.is_finite()));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A small scenario whose `[world] map` is relative to the scenario file.
fn scenario_with_map(map: &str) -> String {
    format!(
        "name = 'on-a-map'\nduration_s = 1.0\n[field]\nwidth = 300\nheight = 200\ncell_size_m = 0.1\n\
         tick_hz = 10.0\n[world]\ndt_s = 0.1\nmap = '{map}'\n[[world.robots]]\nid = 0\n\
         start = {{ x_m = 2.5, y_m = 2.5, theta_rad = 0.0 }}\n[[robot]]\nid = 0\n"
    )
}

// A test reads as one scenario, top to bottom (the line limit is for non-test code).
#[allow(clippy::too_many_lines)]
#[test]
fn a_scenario_map_is_relative_to_the_scenario_and_malformed_maps_exit_2_naming_file_and_line_or_byte(
) {
    let dir = std::env::temp_dir().join(unique("maps"));
    std::fs::create_dir_all(dir.join("maps")).unwrap();
    let src = example_map();
    let src_dir = src.parent().unwrap();
    for f in ["rooms.yaml", "rooms.pgm"] {
        std::fs::copy(src_dir.join(f), dir.join("maps").join(f)).unwrap();
    }
    let scenario = dir.join("on-a-map.toml");
    std::fs::write(&scenario, scenario_with_map("maps/rooms.yaml")).unwrap();
    // Run from elsewhere: the map is found beside the scenario.
    let o = pheromone_testkit::Cli::new(&bin())
        .args([
            "sim",
            scenario.to_str().unwrap(),
            "--single-process",
            "--no-out",
            "--json",
        ])
        .current_dir(&std::env::temp_dir())
        .output();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(json(&o)["robots"].as_array().map(|r| r.len()), Some(1));

    // A robot that starts in one of the map's walls is refused.
    std::fs::write(
        &scenario,
        scenario_with_map("maps/rooms.yaml")
            .replace("x_m = 2.5, y_m = 2.5", "x_m = 12.1, y_m = 8.0"),
    )
    .unwrap();
    let o = run(&[
        "sim",
        scenario.to_str().unwrap(),
        "--single-process",
        "--no-out",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("robot 0 starts at (12.1, 8)"),
        "{}",
        stderr(&o)
    );

    let pgm = std::fs::read(dir.join("maps/rooms.pgm")).unwrap();
    let yaml = std::fs::read_to_string(dir.join("maps/rooms.yaml")).unwrap();
    let bad_yaml_line = yaml
        .lines()
        .position(|l| l.starts_with("resolution"))
        .unwrap()
        + 1;
    let cases: Vec<(&str, Vec<u8>, String, String)> = vec![
        (
            "bad.yaml",
            yaml.replace("resolution: 0.2", "resolution: fine")
                .into_bytes(),
            "bad.yaml".into(),
            format!("line {bad_yaml_line}"),
        ),
        (
            "bad.yaml",
            yaml.replace("negate: 0", "negate 0").into_bytes(),
            "bad.yaml".into(),
            "line ".into(),
        ),
        (
            "rooms.pgm",
            pgm[..pgm.len() - 100].to_vec(),
            "rooms.pgm".into(),
            format!("byte {}", pgm.len() - 100),
        ),
        (
            "rooms.pgm",
            b"P6\n150 100\n255\n".to_vec(),
            "rooms.pgm".into(),
            "byte 0".into(),
        ),
    ];
    for (file, bytes, names, at) in cases {
        let target = dir.join("maps").join(file);
        std::fs::write(&target, &bytes).unwrap();
        let map_rel = if file.ends_with(".yaml") {
            "maps/bad.yaml"
        } else {
            "maps/rooms.yaml"
        };
        std::fs::write(&scenario, scenario_with_map(map_rel)).unwrap();
        let map_abs = dir.join(map_rel);
        for args in [
            vec![
                "sim",
                scenario.to_str().unwrap(),
                "--single-process",
                "--no-out",
            ],
            vec![
                "sim",
                "ias-ss",
                "--map",
                map_abs.to_str().unwrap(),
                "--no-out",
            ],
        ] {
            let o = run(&args);
            let e = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
            assert!(
                e.contains(&names) && e.contains(&at),
                "{args:?}: expected {names} and {at}: {e}"
            );
        }
        if file.ends_with(".pgm") {
            std::fs::write(&target, &pgm).unwrap();
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The `pheromone sim` and `pheromone sweep` lines of README.md and docs/ros-maps.md (their
/// ```sh blocks, comments dropped), each without its placeholder paths (`my/…`).
fn readme_sim_and_sweep_lines() -> Vec<Vec<String>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut lines = Vec::new();
    for doc in ["README.md", "docs/ros-maps.md"] {
        let text = std::fs::read_to_string(root.join(doc)).unwrap();
        for block in text.split("```sh\n").skip(1) {
            let block = block.split("```").next().unwrap_or_default();
            for line in block.lines() {
                let line = line.split(" #").next().unwrap_or_default().trim();
                if (line.starts_with("pheromone sim") || line.starts_with("pheromone sweep"))
                    && !line.contains(" my/")
                {
                    lines.push(line.split_whitespace().skip(1).map(String::from).collect());
                }
            }
        }
    }
    lines
}

/// Issue 51: every README command works verbatim from any directory. The README's `sim` and
/// `sweep` lines (the map a built-in name, not a path from the repository's root) run in an
/// empty working directory outside the repository, shortened (`--single-process` where it
/// applies, 1 simulated s;
/// sweeps 2 trials of 2 s), and write their runs below it.
#[test]
fn the_readmes_sim_and_sweep_lines_run_from_an_empty_directory() {
    let lines = readme_sim_and_sweep_lines();
    assert!(
        lines.iter().any(|l| l.contains(&"--map".to_string())),
        "{lines:?}"
    );
    let cwd = std::env::temp_dir().join(unique("readme-cwd"));
    std::fs::create_dir_all(&cwd).unwrap();
    for line in &lines {
        let mut args = line.clone();
        if args[0] == "sim" {
            // --remote (a gateway and its clients) runs as processes only.
            let single = ["--single-process", "--remote"];
            if !args.iter().any(|a| single.contains(&a.as_str())) {
                args.push("--single-process".into());
            }
            if !args[1].starts_with("regions") {
                args.extend(["--duration".into(), "1".into()]);
            }
        } else {
            args.extend(["--trials", "2", "--duration", "2"].map(String::from));
        }
        let o = pheromone_testkit::Cli::new(&bin())
            .args(&args)
            .current_dir(&cwd)
            .output();
        assert!(
            o.status.success(),
            "{args:?} in {}: {}",
            cwd.display(),
            stderr(&o)
        );
        let scenario = if args[0] == "sim" {
            args[1].clone()
        } else {
            format!("sweep-{}", args[1])
        };
        let latest = cwd.join("pheromone-out").join(scenario).join("latest");
        assert!(
            latest.join("run.json").is_file(),
            "{args:?}: no run.json in {}",
            latest.display()
        );
    }
    std::fs::remove_dir_all(&cwd).unwrap();
}
