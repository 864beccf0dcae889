//! The robot stack stands on its own: `pheromone-roles` reaches neither the simulated world nor
//! the scenario runner through its dependencies (direct or through another crate of the
//! workspace). Read from the workspace's `Cargo.toml` files, as cargo resolves them; only the
//! `[dependencies]` count (a dev-dependency is a test's, not the library's).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Every workspace member's name and its normal dependencies among the workspace's crates.
fn workspace_graph() -> BTreeMap<String, BTreeSet<String>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let read = |p: PathBuf| -> toml::Table {
        let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        toml::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    };
    let workspace = read(root.join("Cargo.toml"));
    let members = workspace["workspace"]["members"].as_array().unwrap();
    let mut manifests = vec![root.join("Cargo.toml")];
    manifests.extend(
        members
            .iter()
            .map(|m| root.join(m.as_str().unwrap()).join("Cargo.toml")),
    );
    let mut graph = BTreeMap::new();
    for path in manifests {
        let manifest = read(path);
        let name = manifest["package"]["name"].as_str().unwrap().to_string();
        let deps = manifest
            .get("dependencies")
            .and_then(|d| d.as_table())
            .map(|d| d.keys().cloned().collect())
            .unwrap_or_default();
        graph.insert(name, deps);
    }
    graph
}

/// Every crate of the workspace that `from` reaches through normal dependencies.
fn reachable(graph: &BTreeMap<String, BTreeSet<String>>, from: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut todo = vec![from.to_string()];
    while let Some(c) = todo.pop() {
        for d in graph.get(&c).into_iter().flatten() {
            if graph.contains_key(d) && seen.insert(d.clone()) {
                todo.push(d.clone());
            }
        }
    }
    seen
}

#[test]
fn the_robot_stack_depends_on_neither_the_world_nor_the_sim() {
    let graph = workspace_graph();
    assert!(graph.contains_key("pheromone-world"), "{:?}", graph.keys());
    let reached = reachable(&graph, "pheromone-roles");
    for sim_side in [
        "pheromone-world",
        "pheromone-sim",
        "pheromone-report",
        "pheromone",
    ] {
        assert!(
            !reached.contains(sim_side),
            "pheromone-roles reaches {sim_side}: {reached:?}"
        );
    }
    // The check sees real edges: the world does build on the robot stack.
    assert!(reachable(&graph, "pheromone-world").contains("pheromone-roles"));
}
