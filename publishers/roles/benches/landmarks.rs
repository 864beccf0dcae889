//! Criterion benchmark of seed 001's "localization restricted to the captured area" (Algorithm 1
//! lines 10–14, eq. 13, Fig. 6): one [`Ekf::update`] with `OBSERVATIONS` observations when
//! maximum-likelihood association runs over the whole map vs over the 40 % of the landmarks
//! inside the robot's captured area (`EkfConfig::landmark_region_m`), for maps of 50, 200 and
//! 1000 landmarks.
//!
//! The map is a corridor with two rows of landmarks 1 m apart; the captured area is the middle
//! 40 % of its length and the robot stands in its centre. Observations are exact range/bearing
//! readings of the `OBSERVATIONS` nearest landmarks with signature 0, so every map landmark is a
//! candidate (predicted measurement, S_t, likelihood — the paper's per-landmark "match") and the
//! cost is the association, not the signature test. Each sample starts from the same filter
//! (cloned outside the timing). Throughput is landmark comparisons (observations × candidates).
//!
//! `cargo bench -p pheromone-roles --bench landmarks`; after the run a table of the
//! captured/whole time ratios is printed from criterion's estimates.

use std::collections::HashSet;
use std::hint::black_box;
use std::path::PathBuf;

use criterion::{BatchSize, BenchmarkId, Criterion, Throughput};
use nalgebra::Matrix3;
use pheromone_messages::LandmarkObs;
use pheromone_roles::localizer::{CheckedFilter, Ekf, EkfConfig};
use pheromone_world::{Landmark, WorldPose};

const MAP_SIZES: &[usize] = &[50, 200, 1000];
/// Observations per update (what a 5 m sensor sees in the corridor).
const OBSERVATIONS: usize = 10;
/// Share of the landmarks inside the captured area (seed 001 Fig. 6).
const CAPTURED_SHARE: f64 = 0.4;
const SPACING_M: f64 = 1.0;
const GROUP: &str = "ekf_update_10_obs";

/// `n` landmarks (n even) in two rows along x, signature 0; the captured area
/// `[min_x, min_y, max_x, max_y]` holding the middle `CAPTURED_SHARE` of them; the robot pose
/// in its centre.
fn corridor(n: usize) -> (Vec<Landmark>, [f64; 4], WorldPose) {
    let columns = n / 2;
    let map = (0..n)
        .map(|k| Landmark {
            x_m: SPACING_M * (k / 2) as f64,
            y_m: if k % 2 == 0 { 0.0 } else { 2.0 },
            signature: 0,
        })
        .collect();
    let captured_columns = (CAPTURED_SHARE * columns as f64).round() as usize;
    let first = (columns - captured_columns) / 2;
    let min_x_m = SPACING_M * (first as f64 - 0.5);
    let max_x_m = SPACING_M * ((first + captured_columns) as f64 - 0.5);
    let robot = WorldPose::new(0.5 * (min_x_m + max_x_m), 1.0, 0.0);
    (map, [min_x_m, -1.0, max_x_m, 3.0], robot)
}

/// Exact observations of the `OBSERVATIONS` landmarks nearest to `robot`.
fn observations(map: &[Landmark], robot: WorldPose) -> Vec<LandmarkObs> {
    let mut near: Vec<&Landmark> = map.iter().collect();
    near.sort_by(|a, b| {
        let d = |l: &Landmark| (l.x_m - robot.x_m).hypot(l.y_m - robot.y_m);
        d(a).total_cmp(&d(b))
    });
    near.iter()
        .take(OBSERVATIONS)
        .map(|l| {
            let (dx, dy) = (l.x_m - robot.x_m, l.y_m - robot.y_m);
            LandmarkObs {
                range_m: dx.hypot(dy) as f32,
                bearing_rad: (dy.atan2(dx) - robot.theta_rad) as f32,
                signature: 0,
                _pad: 0,
            }
        })
        .collect()
}

fn bench_update(c: &mut Criterion) -> HashSet<(usize, &'static str)> {
    let mut ran = HashSet::new();
    let mut group = c.benchmark_group(GROUP);
    for &n in MAP_SIZES {
        let (map, region, robot) = corridor(n);
        let obs = observations(&map, robot);
        let cov0 = Matrix3::from_diagonal_element(1e-4);
        let whole = Ekf::new(EkfConfig::default(), map.clone(), robot, cov0).unwrap();
        let captured = Ekf::new(
            EkfConfig {
                landmark_region_m: Some(region),
                ..EkfConfig::default()
            },
            map,
            robot,
            cov0,
        )
        .unwrap();
        let inside = captured.landmark_filter().map_or(n, <[usize]>::len);
        assert_eq!(inside as f64, CAPTURED_SHARE * n as f64, "map of {n}");
        // The captured filter must still use every observation (all lie inside the area).
        let stats = captured.clone().update(&obs).unwrap();
        assert_eq!(stats.used as usize, OBSERVATIONS, "map of {n}: {stats:?}");
        for (name, ekf, candidates) in [("whole", &whole, n), ("captured_40pct", &captured, inside)]
        {
            group.throughput(Throughput::Elements((OBSERVATIONS * candidates) as u64));
            group.bench_with_input(BenchmarkId::new(name, n), &obs, |b, obs| {
                ran.insert((n, name));
                b.iter_batched_ref(
                    || ekf.clone(),
                    |e| black_box(e.update(black_box(obs)).unwrap()),
                    BatchSize::SmallInput,
                )
            });
        }
    }
    group.finish();
    ran
}

/// Where criterion writes its estimates (same rules as criterion: $CRITERION_HOME,
/// $CARGO_TARGET_DIR/criterion, else the workspace's target/criterion).
fn criterion_dir() -> PathBuf {
    if let Some(home) = std::env::var_os("CRITERION_HOME") {
        return PathBuf::from(home);
    }
    if let Some(target) = std::env::var_os("CARGO_TARGET_DIR") {
        return PathBuf::from(target).join("criterion");
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join("target")
        .join("criterion")
}

/// Criterion's typical time (slope, else mean) of one bench in ns, if it ran.
fn estimate_ns(id: &str, n: usize) -> Option<f64> {
    let path = criterion_dir()
        .join(GROUP)
        .join(id)
        .join(n.to_string())
        .join("new")
        .join("estimates.json");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    ["slope", "mean"]
        .iter()
        .find_map(|k| v.get(k)?.get("point_estimate")?.as_f64())
}

fn print_ratio_table(ran: &HashSet<(usize, &'static str)>) {
    let mut rows = Vec::new();
    for &n in MAP_SIZES {
        let get = |id| estimate_ns(id, n).filter(|_| ran.contains(&(n, id)));
        if let (Some(whole), Some(captured)) = (get("whole"), get("captured_40pct")) {
            let per_match_ns = |t: f64, candidates: f64| t / (OBSERVATIONS as f64 * candidates);
            rows.push(format!(
                "{n:>6}  {:>10.2} µs  {:>10.2} µs  {:>6.3}  {:>8.1} ns  {:>8.1} ns",
                whole / 1e3,
                captured / 1e3,
                captured / whole,
                per_match_ns(whole, n as f64),
                per_match_ns(captured, CAPTURED_SHARE * n as f64),
            ));
        }
    }
    if !rows.is_empty() {
        eprintln!(
            "\none Ekf::update with {OBSERVATIONS} observations, whole map vs captured 40 %:"
        );
        eprintln!(
            "{:>6}  {:>13}  {:>13}  {:>6}  {:>11}  {:>11}",
            "map", "whole", "captured", "ratio", "match whole", "match capt."
        );
        for r in rows {
            eprintln!("{r}");
        }
    }
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    let ran = bench_update(&mut c);
    c.final_summary();
    print_ratio_table(&ran);
}
