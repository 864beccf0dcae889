//! Criterion benchmark of seed 004's map merge (eqs. 7–10, `LocalMap::merge`): one merge of a
//! source map into a destination map of the same size (n × n cells, occupancy and pheromone
//! planes, every cell known in both so every cell is averaged; the source rotated by 0.3 rad
//! and moved 2 m) against a same-size memcpy (both planes copied), for n = 256, 512, 1024. The
//! merge includes its validation pass over the source (no non-finite cell).
//!
//! `cargo bench -p pheromone-roles --bench map_merge`; after the run a table of the
//! merge/memcpy time ratios is printed from criterion's estimates.

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{BenchmarkId, Criterion, Throughput};
use pheromone_field::{ChannelSpec, Evaporation};
use pheromone_roles::mapper::{LocalMap, MappingConfig, MergeTransform};

const SIDES: &[u32] = &[256, 512, 1024];
const GROUP: &str = "map_merge";
const CELL_M: f32 = 0.2;

fn map(side: u32, salt: u32) -> LocalMap {
    let config = MappingConfig {
        enabled: true,
        cell_size_m: CELL_M,
        extent_m: side as f32 * CELL_M,
        ..MappingConfig::default()
    };
    let channel = ChannelSpec::new("visited", Evaporation::None);
    let mut m = LocalMap::new(&config, &channel, 0.1).expect("valid map");
    for (i, (o, p)) in m.occupancy.iter_mut().zip(&mut m.pheromone).enumerate() {
        let h = (i as u32).wrapping_mul(2_654_435_761).wrapping_add(salt) >> 24;
        *o = (h as f32 - 127.5) / 32.0;
        *p = h as f32 / 255.0;
    }
    m
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group(GROUP);
    let t = MergeTransform {
        theta_ij_rad: 0.3,
        d_ij_m: 2.0,
        alpha_ji_rad: 0.7,
        ..MergeTransform::default()
    };
    for &side in SIDES {
        let src = map(side, 1);
        let mut dst = map(side, 2);
        let cells = 2 * side as usize * side as usize;
        group.throughput(Throughput::Bytes(cells as u64 * 4));
        group.bench_function(BenchmarkId::new("merge", side), |b| {
            b.iter(|| black_box(dst.merge(black_box(&src.view()), &t).expect("valid")))
        });
        let from = vec![0.5f32; cells];
        let mut to = vec![0.0f32; cells];
        group.bench_function(BenchmarkId::new("memcpy", side), |b| {
            b.iter(|| to.copy_from_slice(black_box(&from)))
        });
        black_box(&to);
    }
    group.finish();
}

/// Where criterion writes its estimates (same rules as criterion).
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

fn estimate_ns(id: &str, side: u32) -> Option<f64> {
    let path = criterion_dir()
        .join(GROUP)
        .join(id)
        .join(side.to_string())
        .join("new")
        .join("estimates.json");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    ["slope", "mean"]
        .iter()
        .find_map(|k| v.get(k)?.get("point_estimate")?.as_f64())
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    bench(&mut c);
    c.final_summary();
    println!(
        "\n{:>6}  {:>12}  {:>12}  {:>8}",
        "side", "merge", "memcpy", "ratio"
    );
    for &side in SIDES {
        if let (Some(m), Some(c)) = (estimate_ns("merge", side), estimate_ns("memcpy", side)) {
            println!(
                "{side:>6}  {:>9.1} µs  {:>9.1} µs  {:>8.2}",
                m / 1e3,
                c / 1e3,
                m / c
            );
        }
    }
}
