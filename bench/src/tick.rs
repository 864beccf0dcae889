//! One tick of each evaporation model beside a same-size memcpy, in this process.

use std::hint::black_box;
use std::time::Instant;

use field::{ChannelSpec, Evaporation, FieldConfig, Stepper};
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
    pub ambient_ratio: f64,
}

fn median_ns(reps: usize, mut f: impl FnMut()) -> u64 {
    f();
    let mut t: Vec<u64> = (0..reps.max(1))
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_nanos() as u64
        })
        .collect();
    t.sort_unstable();
    t[t.len() / 2].max(1)
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
    let mut amb = stepper(
        width,
        Evaporation::Ambient {
            decay_per_s: 0.0057,
            alpha: 0.5,
            radius_m: 0.5,
        },
    )?;
    let ambient = median_ns(reps, || {
        amb.step(black_box(&prev), &mut next);
        black_box(&mut next);
    });
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
    })
}
