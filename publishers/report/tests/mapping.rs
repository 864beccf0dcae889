//! Seed 004's local maps and their merging, run in one process (`pheromone sim ias-ss --merge
//! --single-process`): what a user relies on in the metrics.

use pheromone_sim::metrics::scenario_metrics;
use pheromone_sim::single::{run_single_process, SingleProcessOptions};
use pheromone_world::scenario::{Overrides, Scenario};

fn metrics(robots: usize, seed: u64, merge: Option<bool>, duration_s: f64) -> serde_json::Value {
    let mut s = Scenario::load("ias-ss").unwrap();
    s.apply(&Overrides {
        robots: Some(robots),
        seed: Some(seed),
        duration_s: Some(duration_s),
        merge,
        ..Overrides::default()
    })
    .unwrap();
    let (summary, rec) = run_single_process(&s, SingleProcessOptions::default()).unwrap();
    assert_eq!(summary.field.nan_cells, 0);
    // As the user reads them: the JSON of `metrics`, mapping keys beside the others.
    serde_json::to_value(scenario_metrics(&s, &rec)).unwrap()
}

fn known_mean(m: &serde_json::Value) -> f64 {
    m["exploration_known"]["mean"]
        .as_f64()
        .unwrap_or_else(|| panic!("no exploration_known.mean: {m}"))
}

#[test]
fn integration_beats_no_integration_for_six_robots_over_several_seeds() {
    let (mut with, mut without) = (0.0, 0.0);
    for seed in 1..=3 {
        let on = metrics(6, seed, Some(true), 300.0);
        let off = metrics(6, seed, Some(false), 300.0);
        eprintln!(
            "seed {seed}: exploration_known {:.3} with integration ({} merges, alignment error {}), {:.3} without; visited {:.3}",
            known_mean(&on),
            on["merges"],
            on["merge_alignment_error_m"],
            known_mean(&off),
            on["exploration"]["mean"],
        );
        // The same robots drive the same paths either way: mapping draws its own noise.
        assert_eq!(on["exploration"], off["exploration"], "seed {seed}");
        assert!(on["merges"].as_u64().unwrap() > 0, "seed {seed}: {on}");
        assert_eq!(off["merges"], 0, "seed {seed}: {off}");
        assert!(known_mean(&on) >= known_mean(&off), "seed {seed}");
        // Where a merged map lands is off by little more than the localization's error.
        let err = &on["merge_alignment_error_m"];
        assert!(err["mean"].as_f64().unwrap() < 0.5, "seed {seed}: {err}");
        assert!(err["max"].as_f64().unwrap() < 2.0, "seed {seed}: {err}");
        with += known_mean(&on);
        without += known_mean(&off);
    }
    assert!(
        with > without + 0.3,
        "integration: {with:.3} / 3 vs {without:.3} / 3"
    );
}

#[test]
fn the_final_maps_are_pictured_in_their_own_frame_and_in_the_world() {
    let mut s = Scenario::load("ias-ss").unwrap();
    s.apply(&Overrides {
        robots: Some(2),
        duration_s: Some(20.0),
        merge: Some(true),
        ..Overrides::default()
    })
    .unwrap();
    let (_, rec) = run_single_process(&s, SingleProcessOptions::default()).unwrap();
    let dir = std::env::temp_dir().join(format!("pheromone-maps-{}", std::process::id()));
    let written = pheromone_report::write_plots(&dir, &s, &rec).unwrap();
    for id in [0, 1] {
        for name in [format!("map_r{id}.png"), format!("map_r{id}_world.png")] {
            let path = dir.join(&name);
            assert!(written.contains(&path), "{name} not written: {written:?}");
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(&bytes[1..4], b"PNG", "{name}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn mapping_reports_its_thresholds_and_leaves_the_run_without_it_unchanged() {
    let on = metrics(2, 4, Some(true), 60.0);
    assert_eq!(on["known_threshold"], 0.5);
    assert_eq!(on["merge"], true);
    assert_eq!(on["rc_m"], 8.0);
    let known = &on["exploration_known"];
    assert_eq!(known["sectors"], 24);
    assert_eq!(known["per_robot"].as_array().unwrap().len(), 2);
    // Each robot knows its own surroundings after a minute: some sectors, not all.
    for k in known["per_robot"].as_array().unwrap() {
        let k = k.as_f64().unwrap();
        assert!(k > 0.0 && k < 1.0, "{known}");
    }
    // No exchange before iteration 100.
    assert_eq!(on["merges"], 0);
    let plain = metrics(2, 4, None, 60.0);
    assert!(plain.get("exploration_known").is_none(), "{plain}");
    assert_eq!(plain["exploration"], on["exploration"]);
}
