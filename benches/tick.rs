//! Criterion benchmarks of the field's hot paths, each beside the machine's own limit.
//!
//! - `tick_<N>`: one tick (`Stepper::step(prev, next)`) of an N×N single-channel field for each
//!   evaporation model, next to a same-size `memcpy` (`dst.copy_from_slice(&src)`) in the same
//!   group, and a `store_loop` baseline (the same copy as a loop of ordinary stores: large memcpys
//!   use non-temporal stores that safe Rust cannot emit). Throughput is the bytes a tick must move
//!   at least (read one frame, write one frame), so memcpy's GB/s is the memory bandwidth the tick
//!   competes with.
//! - `deposit`: stamping one ellipse deposit vs its kernel size (σ = 1…64 cells, z_rng = 3σ), plus
//!   the saturating and Z-shape kernels; throughput in kernel-box cells.
//! - `sample`: value, gradient, antennas and IAS-SS sector means on a 1024² field.
//!
//! Sizes: `PHEROMONE_BENCH_SIZES=1024,4096 cargo bench --bench tick` (default 512,1024,2048,4096).
//! Only some groups: `cargo bench --bench tick -- tick_1024`. After the run a table of tick/memcpy
//! time ratios and cells/s is printed from criterion's estimates.

use std::cell::RefCell;
use std::collections::HashSet;
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, Throughput};
use pheromone_field::deposit::{prepare, DepositLimits};
use pheromone_field::{
    ChannelSpec, DepositMsg, Evaporation, FieldConfig, FrameView, GridGeometry, SamplePose, Stepper,
};
use pheromone_field::{Deposit, Kernel};

const CELL_SIZE_M: f32 = 0.05;
const TICK_HZ: f32 = 50.0;
const DEFAULT_SIZES: &[usize] = &[512, 1024, 2048, 4096];

/// The evaporation models benchmarked, by bench id.
fn models() -> Vec<(&'static str, ChannelSpec)> {
    let ambient = |radius_m: f32| Evaporation::Ambient {
        decay_per_s: 0.0057,
        alpha: 0.5,
        radius_m,
    };
    let mut diffusing = ChannelSpec::new(
        "trail",
        Evaporation::Exponential {
            decay_per_s: 0.0057,
        },
    );
    // κ = D·dt/h² = 0.1.
    diffusing.diffusion_m2_per_s = 0.1 * CELL_SIZE_M * CELL_SIZE_M * TICK_HZ;
    let mut saturating = ChannelSpec::new("anti", Evaporation::Saturating { rho_per_tick: 0.01 });
    saturating.signed = true;
    let mut quantum = ChannelSpec::new(
        "counter",
        Evaporation::Quantum {
            quantum: 1.0,
            tau_s: 1.0,
        },
    );
    quantum.signed = true;
    vec![
        (
            "exponential",
            ChannelSpec::new(
                "trail",
                Evaporation::Exponential {
                    decay_per_s: 0.0057,
                },
            ),
        ),
        ("ambient_0.25m", ChannelSpec::new("trail", ambient(0.25))),
        ("ambient_1m", ChannelSpec::new("trail", ambient(1.0))),
        ("ambient_4m", ChannelSpec::new("trail", ambient(4.0))),
        ("saturating", saturating),
        ("quantum", quantum),
        ("exponential+diffusion", diffusing),
    ]
}

fn bench_sizes() -> Vec<usize> {
    match std::env::var("PHEROMONE_BENCH_SIZES") {
        Ok(s) if !s.trim().is_empty() => s
            .split(',')
            .map(|v| {
                v.trim()
                    .parse::<usize>()
                    .ok()
                    .filter(|&n| (1..=16_384).contains(&n))
                    .unwrap_or_else(|| {
                        panic!(
                            "PHEROMONE_BENCH_SIZES: '{v}' is not a side length in 1..=16384 cells"
                        )
                    })
            })
            .collect(),
        _ => DEFAULT_SIZES.to_vec(),
    }
}

fn config(side: usize, spec: ChannelSpec) -> FieldConfig {
    FieldConfig {
        width: side as u32,
        height: side as u32,
        cell_size_m: CELL_SIZE_M,
        tick_hz: TICK_HZ,
        channels: vec![spec],
        ..FieldConfig::default()
    }
}

/// A deterministic, non-uniform field in [0, 100]: smooth hills plus per-cell noise, so the
/// ambient `min` takes both branches and nothing decays into denormals.
fn test_pattern(side: usize) -> Vec<f32> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    (0..side * side)
        .map(|i| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let noise = (state >> 40) as f32 / (1u64 << 24) as f32;
            let (x, y) = ((i % side) as f32, (i / side) as f32);
            50.0 * (1.0 + (x * 0.05).sin() * (y * 0.03).cos()) * (0.5 + 0.5 * noise)
        })
        .collect()
}

fn group_settings(side: usize) -> (usize, Duration) {
    if side >= 2048 {
        (10, Duration::from_secs(2))
    } else {
        (20, Duration::from_secs(2))
    }
}

/// Runs the tick groups; returns the `(side, id)` of the benches that ran (not filtered out).
fn bench_ticks(c: &mut Criterion, sizes: &[usize]) -> HashSet<(usize, String)> {
    let ran = RefCell::new(HashSet::new());
    for &side in sizes {
        let cells = side * side;
        let prev = test_pattern(side);
        let mut next = vec![0.0f32; cells];
        let mut group = c.benchmark_group(format!("tick_{side}"));
        let (samples, time) = group_settings(side);
        group
            .sample_size(samples)
            .warm_up_time(Duration::from_millis(500))
            .measurement_time(time)
            // Read one frame and write one frame.
            .throughput(Throughput::Bytes(2 * 4 * cells as u64));
        group.bench_function("memcpy", |b| {
            ran.borrow_mut().insert((side, "memcpy".to_string()));
            b.iter(|| {
                next.copy_from_slice(black_box(&prev));
                black_box(&mut next);
            })
        });
        // A second baseline: the same copy as a plain loop of ordinary stores. Large memcpys use
        // non-temporal stores (no read-for-ownership of the destination), which safe Rust
        // cannot emit; this shows what a store loop costs at the same size.
        group.bench_function("store_loop", |b| {
            ran.borrow_mut().insert((side, "store_loop".to_string()));
            let one = black_box(1.0f32);
            b.iter(|| {
                for (o, &p) in next.iter_mut().zip(black_box(&prev)) {
                    *o = p * one;
                }
                black_box(&mut next);
            })
        });
        for (name, spec) in models() {
            let mut stepper = Stepper::new(config(side, spec)).expect("valid bench config");
            group.bench_function(name, |b| {
                ran.borrow_mut().insert((side, name.to_string()));
                b.iter(|| {
                    stepper.step(black_box(&prev), black_box(&mut next));
                })
            });
        }
        group.finish();
    }
    ran.into_inner()
}

fn bench_deposits(c: &mut Criterion) {
    let side = 1024usize;
    let g = GridGeometry::new(side as u32, side as u32, CELL_SIZE_M).unwrap();
    let trail = ChannelSpec::new(
        "trail",
        Evaporation::Exponential {
            decay_per_s: 0.0057,
        },
    );
    let mut anti = ChannelSpec::new("anti", Evaporation::Saturating { rho_per_tick: 0.01 });
    anti.signed = true;
    let channels = [trail, anti];
    let limits = DepositLimits::default();
    let prev = vec![0.0f32; g.cells()];
    let mut plane = vec![0.0f32; g.cells()];
    let centre = 0.5 * g.width_m() + 0.013;
    let mut group = c.benchmark_group("deposit");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    let mut run = |group: &mut criterion::BenchmarkGroup<'_, _>,
                   name: &str,
                   sigma_cells: u32,
                   msg: DepositMsg| {
        let d = prepare(&msg, &g, &channels, &limits).expect("valid bench deposit");
        let (lo, hi) = channels[d.channel].value_range();
        group.throughput(Throughput::Elements(d.cells.cells() as u64));
        group.bench_with_input(BenchmarkId::new(name, sigma_cells), &d, |b, d| {
            b.iter(|| {
                plane.fill(0.0);
                black_box(d.apply(&g, &prev, &mut plane, lo, hi))
            })
        });
    };
    for sigma_cells in [1u32, 2, 4, 8, 16, 32, 64] {
        let sigma_m = sigma_cells as f32 * CELL_SIZE_M;
        let var = sigma_m * sigma_m;
        let msg = DepositMsg::from(Deposit {
            channel: 0,
            x_m: centre,
            y_m: centre,
            kernel: Kernel::Ellipse {
                tau: 0.2,
                cov_m2: [var, 0.0, var],
                range_m: 3.0 * sigma_m,
                gamma_max: 100.0,
            },
        });
        run(&mut group, "ellipse_sigma_cells", sigma_cells, msg);
    }
    let sigma_cells = 8;
    let sigma_m = sigma_cells as f32 * CELL_SIZE_M;
    run(
        &mut group,
        "saturating_sigma_cells",
        sigma_cells,
        DepositMsg::from(Deposit {
            channel: 1,
            x_m: centre,
            y_m: centre,
            kernel: Kernel::Saturating {
                rho: 0.5,
                sigma_m,
                range_m: 3.0 * sigma_m,
            },
        }),
    );
    run(
        &mut group,
        "z_shape_sigma_cells",
        sigma_cells,
        DepositMsg::from(Deposit {
            channel: 0,
            x_m: centre,
            y_m: centre,
            kernel: Kernel::ZShape {
                amount: 1.0,
                plateau_m: sigma_m,
                slope_m: 2.0 * sigma_m,
            },
        }),
    );
    group.finish();
}

fn bench_sampling(c: &mut Criterion) {
    let side = 1024usize;
    let g = GridGeometry::new(side as u32, side as u32, CELL_SIZE_M).unwrap();
    let cells = test_pattern(side);
    let view = FrameView::new(g, 1, &cells);
    let pose = SamplePose::new(25.3, 24.7, 0.6);
    let mut group = c.benchmark_group("sample");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    group.bench_function("value", |b| {
        b.iter(|| black_box(view.value(0, black_box(pose.x_m), black_box(pose.y_m))))
    });
    group.bench_function("gradient", |b| {
        b.iter(|| black_box(view.gradient(0, black_box(pose.x_m), black_box(pose.y_m))))
    });
    group.bench_function("antennas", |b| {
        b.iter(|| black_box(view.antennas(0, black_box(pose), 0.3)))
    });
    for radius_m in [0.5f32, 2.0] {
        group.bench_function(format!("sector_means_5x{radius_m}m"), |b| {
            b.iter(|| black_box(view.sector_means(0, black_box(pose), radius_m, 2)))
        });
    }
    group.finish();
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
        .join("target")
        .join("criterion")
}

/// Criterion's typical time (slope, else mean) of one bench in ns, if it ran.
fn estimate_ns(group: &str, id: &str) -> Option<f64> {
    let path = criterion_dir()
        .join(group)
        .join(id)
        .join("new")
        .join("estimates.json");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    ["slope", "mean"]
        .iter()
        .find_map(|k| v.get(k)?.get("point_estimate")?.as_f64())
}

fn print_ratio_table(sizes: &[usize], ran: &HashSet<(usize, String)>) {
    let mut rows = Vec::new();
    for &side in sizes {
        let group = format!("tick_{side}");
        let ran = |id: &str| ran.contains(&(side, id.to_string()));
        let Some(memcpy) = estimate_ns(&group, "memcpy").filter(|_| ran("memcpy")) else {
            continue;
        };
        let bytes = 2.0 * 4.0 * (side * side) as f64;
        rows.push(format!(
            "{side:>5}²  {:<22} {:>10.3} ms  {:>6.2}×  {:>7.2} GB/s  {:>8.1} Mcells/s",
            "memcpy",
            memcpy / 1e6,
            1.0,
            bytes / memcpy,
            (side * side) as f64 / memcpy * 1e3
        ));
        for name in std::iter::once("store_loop").chain(models().into_iter().map(|(n, _)| n)) {
            if let Some(t) = estimate_ns(&group, &report_safe(name)).filter(|_| ran(name)) {
                rows.push(format!(
                    "{side:>5}²  {name:<22} {:>10.3} ms  {:>6.2}×  {:>7.2} GB/s  {:>8.1} Mcells/s",
                    t / 1e6,
                    t / memcpy,
                    bytes / t,
                    (side * side) as f64 / t * 1e3
                ));
            }
        }
    }
    if !rows.is_empty() {
        eprintln!(
            "\none tick vs a same-size memcpy (GB/s = one frame read + one written per tick):"
        );
        eprintln!(
            "{:>6}  {:<22} {:>13}  {:>7}  {:>12}  {:>17}",
            "size", "model", "time", "ratio", "throughput", "cells"
        );
        for r in rows {
            eprintln!("{r}");
        }
    }
}

/// Criterion's directory name for a bench id.
fn report_safe(id: &str) -> String {
    id.replace(['?', '"', '/', '\\', '*', '<', '>', ':', '|', '^'], "_")
}

fn main() {
    let sizes = bench_sizes();
    let mut c = Criterion::default().configure_from_args();
    let ran = bench_ticks(&mut c, &sizes);
    bench_deposits(&mut c);
    bench_sampling(&mut c);
    c.final_summary();
    print_ratio_table(&sizes, &ran);
}
