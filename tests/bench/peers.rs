//! `pheromone bench --only peers` (issue 53) without its peers: an interpreter that does not
//! exist, or one whose OpenCV and SciPy cannot be imported, gives rows and targets that say so
//! (the run still measures ours and exits 0). The peers' agreement with ours is checked with the
//! `peers` extra installed, in python/tests/test_bench_peers.py.

use std::os::unix::fs::PermissionsExt;
use std::time::Duration;

use serde_json::Value;

use crate::harness::*;

fn bench_peers(python: &str) -> Value {
    let out = Proc::spawn(&[
        "bench",
        "--smoke",
        "--json",
        "--no-pin",
        "--only",
        "peers",
        "--peers-python",
        python,
    ])
    .wait_exit(Duration::from_secs(300));
    assert!(out.status.success(), "bench failed: {}", stderr(&out));
    json(&out)
}

/// Every figure of every row is unavailable with a reason containing each of `words`, our time
/// is measured, and each row has its target, unmet, with the reason.
fn check_unavailable(r: &Value, words: &[&str]) {
    assert_eq!(r["sections"], serde_json::json!(["peers"]), "{r}");
    let p = &r["peers"];
    let ambient = p["ambient"].as_array().expect("peers.ambient");
    let merge = p["merge"].as_array().expect("peers.merge");
    assert_eq!(ambient.len(), 2, "{p}");
    assert_eq!(merge.len(), 2, "{p}");
    let mut figures = Vec::new();
    for a in ambient {
        figures.extend([&a["opencv_box"], &a["scipy_uniform"]]);
    }
    figures.extend(merge.iter().map(|m| &m["opencv_numpy"]));
    for row in ambient.iter().chain(merge) {
        assert!(row["ours_us"].as_f64().is_some_and(|v| v > 0.0), "{row}");
    }
    for f in figures {
        let why = f["unavailable"].as_str().unwrap_or_else(|| panic!("{f}"));
        for w in words {
            assert!(why.contains(w), "'{w}' not in '{why}'");
        }
        assert!(f["ratio"].is_null() && f["us"].is_null(), "{f}");
    }
    let targets: Vec<&Value> = r["targets"]
        .as_array()
        .expect("targets")
        .iter()
        .filter(|t| {
            t["name"]
                .as_str()
                .is_some_and(|n| n.contains("OpenCV") || n.contains("SciPy"))
        })
        .collect();
    assert_eq!(targets.len(), 6, "{targets:?}");
    for t in targets {
        assert_eq!(t["met"], false, "{t}");
        assert!(t["measured"].is_null(), "{t}");
        assert!(t["unavailable"].as_str().is_some(), "{t}");
    }
}

#[test]
fn bench_peers_without_python_says_so_in_every_row() {
    let missing = "/nonexistent/pheromone-test/python3";
    let r = bench_peers(missing);
    check_unavailable(&r, &[missing, "--peers-python"]);
    assert!(
        r["peers"]["missing"]["python"].as_str().is_some(),
        "{}",
        r["peers"]
    );
}

#[test]
fn bench_peers_without_opencv_names_the_missing_module() {
    // python3 with a cv2 and a scipy that fail to import, first on its path.
    let dir = std::env::temp_dir().join(unique("peers-shadow"));
    for m in ["cv2", "scipy"] {
        let pkg = dir.join("shadow").join(m);
        std::fs::create_dir_all(&pkg).unwrap();
        std::fs::write(
            pkg.join("__init__.py"),
            "raise ImportError('shadowed by the test')\n",
        )
        .unwrap();
    }
    let python = dir.join("python");
    std::fs::write(
        &python,
        format!(
            "#!/bin/sh\nPYTHONPATH={} exec python3 \"$@\"\n",
            dir.join("shadow").display()
        ),
    )
    .unwrap();
    std::fs::set_permissions(&python, std::fs::Permissions::from_mode(0o755)).unwrap();
    let r = bench_peers(python.to_str().unwrap());
    std::fs::remove_dir_all(&dir).unwrap();
    // Without NumPy every peer names it; with it, OpenCV's and SciPy's rows name their module.
    let missing = &r["peers"]["missing"];
    let numpy_missing = missing["numpy"].is_string();
    check_unavailable(&r, &["not importable", "pip install ./python[peers]"]);
    assert!(
        missing["cv2"].is_string() && missing["scipy.ndimage"].is_string(),
        "{missing}"
    );
    if !numpy_missing {
        let a = &r["peers"]["ambient"][0];
        let cv = a["opencv_box"]["unavailable"].as_str().unwrap();
        let sp = a["scipy_uniform"]["unavailable"].as_str().unwrap();
        assert!(cv.contains("cv2") && sp.contains("scipy.ndimage"), "{a}");
    }
}
