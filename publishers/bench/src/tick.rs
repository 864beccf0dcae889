//! One tick of each evaporation model beside a same-size memcpy, in this process.

use std::hint::black_box;
use std::time::Instant;

use pheromone_field::models::{step_plane_with, Dispatch, PlanePlan, Scratch};
use pheromone_field::{ChannelSpec, Evaporation, FieldConfig, Stepper};
use serde::Serialize;

use crate::BenchError;

/// Median times of one frame's worth of work at one size, and the ratios to memcpy.
#[derive(Debug, Clone, Serialize)]
pub struct TickRow {
    pub width: u32,
    pub frame_bytes: u64,
    pub memcpy_us: f64,
    pub exponential_us: f64,
    pub ambient_us: f64,
    pub exponential_ratio: f64,
    /// The ambient model at radius 0.5 m (10 cells of 5 cm).
    pub ambient_ratio: f64,
    /// The ambient model at several radii (`AMBIENT_RADII_M`), one thread.
    pub ambient_by_radius: Vec<RadiusRow>,
    /// The ambient tick (radius 0.5 m) on 2 threads, and 1-thread time / 2-thread time.
    pub ambient_2_threads_us: f64,
    pub ambient_thread_speedup: f64,
    /// The reference ambient pass (one row's prefix sums at a time, what the tick ran before the
    /// four-row pass) at radius 0.5 m, one thread, and its ratio to memcpy.
    pub ambient_reference_us: f64,
    pub ambient_reference_ratio: f64,
    /// The kernel instantiation the tick ran (`"avx2"` or `"portable"`).
    pub kernels: &'static str,
}

/// One radius of the ambient model.
#[derive(Debug, Clone, Serialize)]
pub struct RadiusRow {
    pub radius_cells: u32,
    pub ambient_us: f64,
    pub ambient_ratio: f64,
    /// The reference pass at this radius (`TickRow::ambient_reference_us`).
    pub reference_us: f64,
    pub reference_ratio: f64,
}

/// The radii of the by-radius ambient measurement (m, on 5 cm cells: 1, 10 and 40 cells).
pub const AMBIENT_RADII_M: [f32; 3] = [0.05, 0.5, 2.0];

/// The median time of `reps` runs of `f` (ns, at least 1), after one warm-up run, with `setup`
/// run before each call and not timed (to start every call from the same state).
pub(crate) fn median_ns_from(reps: usize, mut setup: impl FnMut(), mut f: impl FnMut()) -> u64 {
    setup();
    f();
    let mut t: Vec<u64> = (0..reps.max(1))
        .map(|_| {
            setup();
            let start = Instant::now();
            f();
            start.elapsed().as_nanos() as u64
        })
        .collect();
    t.sort_unstable();
    t[t.len() / 2].max(1)
}

/// As `median_ns_from`, with nothing to set up.
pub(crate) fn median_ns(reps: usize, f: impl FnMut()) -> u64 {
    median_ns_from(reps, || {}, f)
}

fn stepper(width: u32, evaporation: Evaporation) -> Result<Stepper, BenchError> {
    Stepper::new(FieldConfig {
        width,
        height: width,
        channels: vec![ChannelSpec::new("trail", evaporation)],
        ..FieldConfig::default()
    })
    .map_err(|e| BenchError::Peer(format!("tick bench configuration: {e}")))
}

/// Measures one size (`width`² single-channel f32 cells), `reps` times each.
pub fn measure(width: u32, reps: usize) -> Result<TickRow, BenchError> {
    let n = width as usize * width as usize;
    let prev: Vec<f32> = (0..n).map(|i| (i % 977) as f32 * 0.01).collect();
    let mut next = vec![0.0f32; n];
    let memcpy = median_ns(reps, || {
        next.copy_from_slice(black_box(&prev));
        black_box(&mut next);
    });
    let mut exp = stepper(
        width,
        Evaporation::Exponential {
            decay_per_s: 0.0057,
        },
    )?;
    let exponential = median_ns(reps, || {
        exp.step(black_box(&prev), &mut next);
        black_box(&mut next);
    });
    let ambient_at = |radius_m: f32, threads: usize, next: &mut Vec<f32>| {
        let mut amb = stepper(
            width,
            Evaporation::Ambient {
                decay_per_s: 0.0057,
                alpha: 0.5,
                radius_m,
            },
        )?;
        amb.set_threads(threads)
            .map_err(|e| BenchError::Peer(format!("tick bench threads: {e}")))?;
        Ok::<u64, BenchError>(median_ns(reps, || {
            amb.step(black_box(&prev), next);
            black_box(&mut *next);
        }))
    };
    let (w, cell_m) = (width as usize, FieldConfig::default().cell_size_m);
    let mut scratch = Scratch::default();
    let mut reference_at = |radius_m: f32, next: &mut Vec<f32>| {
        // The plan a Stepper computes for this channel (any factor: the work is the same).
        let plan = PlanePlan::Ambient {
            factor: 0.9994,
            alpha: 0.5,
            radius_cells: (radius_m / cell_m).round() as u32,
        };
        let reference = Dispatch::detect().reference();
        median_ns(reps, || {
            step_plane_with(plan, 0.0, w, &prev, next, &mut scratch, 1, reference);
            black_box(&mut *next);
        })
    };
    let ambient = ambient_at(0.5, 1, &mut next)?;
    let ambient_reference = reference_at(0.5, &mut next);
    let ambient_2 = ambient_at(0.5, 2, &mut next)?;
    let mut by_radius = Vec::new();
    for radius_m in AMBIENT_RADII_M {
        let ns = ambient_at(radius_m, 1, &mut next)?;
        let reference = reference_at(radius_m, &mut next);
        by_radius.push((radius_m, ns, reference));
    }
    let us = |ns: u64| (ns as f64 / 100.0).round() / 10.0;
    let ratio = |ns: u64| ((ns as f64 / memcpy as f64) * 100.0).round() / 100.0;
    Ok(TickRow {
        width,
        frame_bytes: n as u64 * 4,
        memcpy_us: us(memcpy),
        exponential_us: us(exponential),
        ambient_us: us(ambient),
        exponential_ratio: ratio(exponential),
        ambient_ratio: ratio(ambient),
        ambient_by_radius: by_radius
            .into_iter()
            .map(|(radius_m, ns, reference)| RadiusRow {
                radius_cells: (radius_m / cell_m).round() as u32,
                ambient_us: us(ns),
                ambient_ratio: ratio(ns),
                reference_us: us(reference),
                reference_ratio: ratio(reference),
            })
            .collect(),
        ambient_2_threads_us: us(ambient_2),
        ambient_thread_speedup: ((ambient as f64 / ambient_2 as f64) * 100.0).round() / 100.0,
        ambient_reference_us: us(ambient_reference),
        ambient_reference_ratio: ratio(ambient_reference),
        kernels: pheromone_field::models::Dispatch::detect().name(),
    })
}
