//! Seed 004's map merge (`pheromone_roles::mapper::merge_planes`) beside a same-size memcpy, in this
//! process: one merge of an n × n source map (occupancy and pheromone planes) into an n × n
//! destination, every cell known in both (so every covered cell is averaged), the source
//! rotated by 0.3 rad and moved 2 m, against a copy of both planes, by the `adopt-unknown` rule
//! (the pass with AVX2 runs). The reference merge (one cell at a time, what the mapper ran
//! before) is timed beside it, and so is seed 004's `average` rule (the default): its pass
//! (eight cells at a time with AVX2, two vector exponentials and a vector logarithm per eight
//! cells) and its reference (one cell at a time, a σ per side and a σ⁻¹ per cell by libm).

use std::hint::black_box;

use pheromone_field::{ChannelSpec, Evaporation};
use pheromone_roles::mapper::{LocalMap, MappingConfig, MergeRule, MergeTransform};
use serde::Serialize;

use crate::tick::{median_ns, median_ns_from};
use crate::BenchError;

/// Median times of one merge and one memcpy of both planes at one size, and their ratios.
#[derive(Debug, Clone, Serialize)]
pub struct MergeRow {
    pub side: u32,
    pub memcpy_us: f64,
    pub merge_us: f64,
    pub merge_ratio: f64,
    pub reference_us: f64,
    pub reference_ratio: f64,
    /// The `average` rule (seed 004's, the default).
    pub average_us: f64,
    pub average_ratio: f64,
    /// The `average` rule's reference pass (one cell at a time).
    pub average_reference_us: f64,
    pub average_reference_ratio: f64,
}

const CELL_M: f32 = 0.2;

pub(crate) fn map(side: u32, salt: u32) -> Result<LocalMap, BenchError> {
    let config = MappingConfig {
        enabled: true,
        cell_size_m: CELL_M,
        extent_m: side as f32 * CELL_M,
        merge_rule: MergeRule::AdoptUnknown,
        ..MappingConfig::default()
    };
    let channel = ChannelSpec::new("visited", Evaporation::None);
    let mut m = LocalMap::new(&config, &channel, 0.1)
        .map_err(|e| BenchError::Peer(format!("merge bench map: {e}")))?;
    for (i, (o, p)) in m.occupancy.iter_mut().zip(&mut m.pheromone).enumerate() {
        let h = (i as u32).wrapping_mul(2_654_435_761).wrapping_add(salt) >> 24;
        *o = (h as f32 - 127.5) / 32.0;
        *p = h as f32 / 255.0;
    }
    Ok(m)
}

/// The source's transform into the destination: rotated by 0.3 rad and moved 2 m.
pub(crate) fn transform() -> MergeTransform {
    MergeTransform {
        theta_ij_rad: 0.3,
        d_ij_m: 2.0,
        alpha_ji_rad: 0.7,
        ..MergeTransform::default()
    }
}

/// Measures one size, `reps` times each.
pub fn measure(side: u32, reps: usize) -> Result<MergeRow, BenchError> {
    let t = transform();
    let src = map(side, 1)?;
    let dst = map(side, 2)?;
    let cells = 2 * side as usize * side as usize;
    let from = vec![0.5f32; cells];
    let mut to = vec![0.0f32; cells];
    let memcpy = median_ns(reps, || {
        to.copy_from_slice(black_box(&from));
        black_box(&mut to);
    });
    let fail = |e| BenchError::Peer(format!("merge bench: {e}"));
    let mut result = Ok(());
    // Every merge starts from the same destination. Each merge pulls the destination towards
    // the source, and the reference's `a == b` shortcut skips the transcendental functions of
    // cells that reached it: merging into the last result would time ever cheaper merges.
    let pristine = (dst.occupancy.clone(), dst.pheromone.clone());
    let dst = std::cell::RefCell::new(dst);
    let restore = || {
        let mut d = dst.borrow_mut();
        d.occupancy.copy_from_slice(&pristine.0);
        d.pheromone.copy_from_slice(&pristine.1);
    };
    let merge = median_ns_from(reps, restore, || {
        if let Err(e) = dst.borrow_mut().merge(black_box(&src.view()), &t) {
            result = Err(fail(e));
        }
    });
    std::mem::replace(&mut result, Ok(()))?;
    let geometry = *dst.borrow().geometry();
    let timed = |rule: MergeRule, reference: bool| {
        let mut d = dst.borrow_mut();
        let d = &mut *d;
        let planes = (&mut d.occupancy[..], &mut d.pheromone[..]);
        let rule = (rule, MappingConfig::default().logodds_max);
        let view = src.view();
        let r = if reference {
            pheromone_roles::mapper::merge::merge_planes_reference(
                &geometry,
                planes,
                black_box(&view),
                &t,
                rule,
            )
        } else {
            pheromone_roles::mapper::merge_planes(&geometry, planes, black_box(&view), &t, rule)
        };
        r.map(|_| ()).map_err(fail)
    };
    let mut timed_ok = |rule: MergeRule, reference: bool| {
        if let Err(e) = timed(rule, reference) {
            result = Err(e);
        }
    };
    let reference = median_ns_from(reps, restore, || timed_ok(MergeRule::AdoptUnknown, true));
    let average_reference = median_ns_from(reps, restore, || timed_ok(MergeRule::Average, true));
    let average = median_ns_from(reps, restore, || timed_ok(MergeRule::Average, false));
    result?;
    let us = |ns: u64| (ns as f64 / 100.0).round() / 10.0;
    let ratio = |ns: u64| ((ns as f64 / memcpy as f64) * 100.0).round() / 100.0;
    Ok(MergeRow {
        side,
        memcpy_us: us(memcpy),
        merge_us: us(merge),
        merge_ratio: ratio(merge),
        reference_us: us(reference),
        reference_ratio: ratio(reference),
        average_us: us(average),
        average_ratio: ratio(average),
        average_reference_us: us(average_reference),
        average_reference_ratio: ratio(average_reference),
    })
}
