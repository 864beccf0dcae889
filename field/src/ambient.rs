//! The tick's plane pass over bands of rows: separable running-sum box mean for the ambient
//! model, fused with the decay, and the split of a plane's rows across threads.
//!
//! # The ambient mean
//! `Pa` of a cell is the mean of `prev` over the `(2r+1)²` window around it, clipped to the grid.
//! It is computed separably, per *band* of consecutive rows:
//! - vertically, `col_sum[x]` (f64) holds the sum of column `x` over the rows of the current
//!   row's window; the next row adds the row entering and drops the row leaving (one f64 add of
//!   an exact f32 difference per column, wide over x);
//! - horizontally, a blocked prefix sum of `col_sum` along the row, whose differences are the
//!   window sums;
//! - the output is fused: `P' = P − (1 − e)·(P − min(P, α·Pa))`, written once per cell, so each
//!   cell of `prev` is read once for the output (plus the running sums' reads of the rows entering
//!   and leaving the window, which are cache-hot for small radii) and each cell of `next` is
//!   written once.
//!
//! Every band restarts its column sums from the rows of its first window. The band height
//! (`band_rows`) depends only on the grid height and the radius, never on the thread count, so
//! any number of threads computes exactly the same bits as one thread.
//!
//! # Error bound
//! With u = 2⁻⁵³ and `B` the band height, a column sum is the result of at most
//! `n_v = 2r + 1 + 2B` f64 additions of f32 values (exact in f64), so it is within
//! `n_v·u·S_v` of the exact column sum, `S_v` the largest sum of |cells| of that column over
//! any window of the band. The prefix sum along a row adds at most `W` (the width) such values;
//! a window sum is a difference of two prefixes, so it is within `(2·W + n_v)·u·S_row` of the
//! exact window sum, `S_row` the sum over the row's window rows of the whole row (≥ every partial
//! sum). Dividing by the cell count and rounding to f32 adds ½ ulp(f32). For the grids of the
//! property tests (values ≤ 1e6, W ≤ 32) that is far below 1e-6 relative; for a 4096² field it is
//! below 2⁻³⁹·S_row / count — negligible against the f32 output unless one window holds values
//! 1e10 times larger than its neighbours' (then the small means are absolutely, not relatively,
//! accurate). A window sum that round-off pushes below 0 is clamped to 0.
//!
//! # SIMD
//! The row kernels (`crate::simd::kernels`) are plain Rust written so that they vectorize;
//! `crate::simd` runs them compiled for AVX2 when the CPU has it (detected once at run time) and for the baseline
//! otherwise. Both compile the same operations in the same order without FMA contraction, so the
//! two paths give bit-identical results (`field/tests/properties.rs` checks it).

use crate::plan::PlanePlan;
use crate::simd::kernels::{diffuse_row, scale, subtract_toward_zero};
use crate::simd::Dispatch;

/// Smallest band height of the ambient pass (rows).
pub const BAND_ROWS_MIN: usize = 256;

/// The band height for a `height`-row plane and window half-height `r`: at least
/// `BAND_ROWS_MIN` and at least `4r` (so a band's start-up sums, `2r` rows, cost at most half a
/// band's reads), at most the plane. Independent of the thread count.
pub fn band_rows(height: usize, r: usize) -> usize {
    BAND_ROWS_MIN.max(4 * r).min(height).max(1)
}

/// Per-thread scratch of the band pass (O(width), never O(grid)).
#[derive(Debug, Default, Clone)]
pub struct BandScratch {
    col_sum: Vec<f64>,
    prefix: Vec<f64>,
    inv_count_x: Vec<f64>,
    inv_count: Vec<f64>,
    diffused: Vec<f32>,
}

/// What a band pass writes for each cell.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Output {
    /// The plane plan's update (with diffusion if `kappa > 0`).
    Step { plan: PlanePlan, kappa: f32 },
    /// The ambient mean itself (tests and tools).
    Mean { radius_cells: usize },
}

/// Computes rows `y0..y1` of the output from the whole previous plane `prev` (`width` wide) into
/// `out` (exactly those rows).
pub(crate) fn band(
    output: Output,
    width: usize,
    prev: &[f32],
    (y0, y1): (usize, usize),
    out: &mut [f32],
    s: &mut BandScratch,
    dispatch: Dispatch,
) {
    let height = prev.len() / width;
    debug_assert_eq!(out.len(), (y1 - y0) * width);
    let (kappa, radius) = match output {
        Output::Step {
            plan:
                PlanePlan::Ambient {
                    alpha,
                    radius_cells,
                    ..
                },
            kappa,
        } if alpha > 0.0 => (kappa, Some(radius_cells as usize)),
        Output::Step { kappa, .. } => (kappa, None),
        Output::Mean { radius_cells } => (0.0, Some(radius_cells)),
    };
    if kappa == 0.0 && radius.is_none() {
        let src = &prev[y0 * width..y1 * width];
        match output {
            Output::Step {
                plan: PlanePlan::Subtract { loss },
                ..
            } => {
                for (o, &p) in out.iter_mut().zip(src) {
                    *o = subtract_toward_zero(p, loss);
                }
            }
            Output::Step {
                plan: PlanePlan::Scale { factor },
                ..
            } => scale(src, out, factor),
            // Ambient with α = 0: min(P, 0) = 0 for P ≥ 0, so P' = P·e.
            Output::Step {
                plan: PlanePlan::Ambient { factor, .. },
                ..
            } => ambient_no_mean(src, out, factor),
            Output::Mean { .. } => unreachable!("the mean always has a radius"),
        }
        return;
    }
    let mut sums = radius.map(|r| ColumnSums::start(width, height, r, prev, y0, s, dispatch));
    s.diffused.resize(width, 0.0);
    for y in y0..y1 {
        let row = &prev[y * width..(y + 1) * width];
        let o = &mut out[(y - y0) * width..(y - y0 + 1) * width];
        if let Some(sums) = sums.as_mut() {
            sums.advance(y, y0, prev, s, dispatch);
        }
        let src: &[f32] = if kappa > 0.0 {
            let up = if y > 0 {
                &prev[(y - 1) * width..y * width]
            } else {
                row
            };
            let down = if y + 1 < height {
                &prev[(y + 1) * width..(y + 2) * width]
            } else {
                row
            };
            diffuse_row(row, up, down, kappa, &mut s.diffused);
            &s.diffused
        } else {
            row
        };
        match output {
            Output::Mean { .. } => {
                let rx = sums.as_ref().map_or(0, |c| c.radius_x);
                dispatch.mean_row(&s.prefix, &s.inv_count, 2 * rx + 1, o);
            }
            Output::Step { plan, .. } => match plan {
                PlanePlan::Scale { factor } => scale(src, o, factor),
                PlanePlan::Subtract { loss } => {
                    for (c, &p) in o.iter_mut().zip(src) {
                        *c = subtract_toward_zero(p, loss);
                    }
                }
                PlanePlan::Ambient { factor, alpha, .. } => match sums.as_ref() {
                    Some(c) => dispatch.decay_row(
                        &s.prefix,
                        &s.inv_count,
                        2 * c.radius_x + 1,
                        src,
                        o,
                        factor,
                        alpha,
                    ),
                    None => ambient_no_mean(src, o, factor),
                },
            },
        }
    }
}

fn ambient_no_mean(src: &[f32], out: &mut [f32], factor: f32) {
    // P − (1 − e)·(P − 0), the same expression as the general case with m = 0.
    let one_minus = 1.0 - factor;
    for (o, &p) in out.iter_mut().zip(src) {
        let m = if 0.0 < p { 0.0 } else { p };
        *o = p - one_minus * (p - m);
    }
}

/// The vertical running sums of one band and the per-row prefix sums derived from them.
struct ColumnSums {
    radius_y: usize,
    radius_x: usize,
    width: usize,
    height: usize,
    inv_count_rows: usize,
}

impl ColumnSums {
    fn start(
        width: usize,
        height: usize,
        radius: usize,
        prev: &[f32],
        y0: usize,
        s: &mut BandScratch,
        dispatch: Dispatch,
    ) -> Self {
        let (radius_x, radius_y) = (radius.min(width), radius.min(height));
        s.col_sum.clear();
        s.col_sum.resize(width, 0.0);
        // The left pad stays 0 (= Σ of nothing); the rest is rewritten every row.
        s.prefix.clear();
        s.prefix.resize(width + 2 * radius_x + 1, 0.0);
        s.inv_count_x.clear();
        s.inv_count_x
            .extend((0..width).map(|x| {
                1.0 / ((x + radius_x + 1).min(width) - x.saturating_sub(radius_x)) as f64
            }));
        s.inv_count.clear();
        s.inv_count.resize(width, 0.0);
        // The window of row y0 without its last row (row y0 + r enters in `advance`).
        for y in y0.saturating_sub(radius_y)..(y0 + radius_y).min(height) {
            dispatch.add_row(&mut s.col_sum, &prev[y * width..(y + 1) * width]);
        }
        Self {
            radius_y,
            radius_x,
            width,
            height,
            inv_count_rows: 0,
        }
    }

    /// Moves the sums to row `y` (rows in order from the band's first row `y0`) and computes the
    /// row's prefix sums into `s.prefix`.
    fn advance(&mut self, y: usize, y0: usize, prev: &[f32], s: &mut BandScratch, d: Dispatch) {
        let (w, r, rx) = (self.width, self.radius_y, self.radius_x);
        let row = |i: usize| &prev[i * w..(i + 1) * w];
        let enters = y + r < self.height;
        // Row y − r − 1 was summed only if it is a row of the band's start-up window or later.
        let leaves = y > y0 && y > r;
        match (enters, leaves) {
            (true, true) => {
                // The row after this one enters next: fetched from memory while this one is
                // summed, so the next row's sums do not wait on it (`swap_row`).
                let ahead = if y + r + 1 < self.height {
                    row(y + r + 1)
                } else {
                    &[]
                };
                d.swap_row(&mut s.col_sum, row(y + r), row(y - r - 1), ahead)
            }
            (true, false) => d.add_row(&mut s.col_sum, row(y + r)),
            (false, true) => d.sub_row(&mut s.col_sum, row(y - r - 1)),
            (false, false) => {}
        }
        let rows_in = (y + r).min(self.height - 1) - y.saturating_sub(r) + 1;
        if rows_in != self.inv_count_rows {
            let inv_rows = 1.0 / rows_in as f64;
            for (c, &cx) in s.inv_count.iter_mut().zip(&s.inv_count_x) {
                *c = cx * inv_rows;
            }
            self.inv_count_rows = rows_in;
        }
        d.prefix_sum(&s.col_sum, &mut s.prefix[rx..=rx + w]);
        let total = s.prefix[rx + w];
        s.prefix[rx + w + 1..].fill(total);
    }
}

// ---------------------------------------------------------------------------------------------
// Rows across threads.

/// Splits a plane's rows into bands and the bands into `threads` contiguous groups, computes
/// each group on its own thread (the calling thread takes the first), and returns when all are
/// done. Bands are fixed by `band_rows` for the ambient plan, so the result does not depend on
/// `threads`; the other plans compute each row from `prev` alone.
pub(crate) fn plane(
    output: Output,
    width: usize,
    prev: &[f32],
    next: &mut [f32],
    workers: &mut Vec<BandScratch>,
    threads: usize,
    dispatch: Dispatch,
) {
    let height = prev.len() / width;
    let band_h = match output {
        Output::Step {
            plan:
                PlanePlan::Ambient {
                    radius_cells,
                    alpha,
                    ..
                },
            ..
        } if alpha > 0.0 => band_rows(height, radius_cells as usize),
        Output::Mean { radius_cells } => band_rows(height, radius_cells),
        _ => height.div_ceil(threads.max(1)).max(1),
    };
    let bands = height.div_ceil(band_h);
    let threads = threads.clamp(1, bands);
    if workers.len() < threads {
        workers.resize_with(threads, BandScratch::default);
    }
    // Thread t computes bands [t·bands/threads, (t+1)·bands/threads).
    let rows_of = |t: usize| ((t * bands / threads) * band_h).min(height);
    let run = |y0: usize, y1: usize, out: &mut [f32], s: &mut BandScratch| {
        let mut y = y0;
        while y < y1 {
            let end = (y + band_h).min(y1);
            let o = &mut out[(y - y0) * width..(end - y0) * width];
            band(output, width, prev, (y, end), o, s, dispatch);
            y = end;
        }
    };
    if threads == 1 {
        run(0, height, next, &mut workers[0]);
        return;
    }
    std::thread::scope(|scope| {
        let mut rest = next;
        let mut first = None;
        for (t, s) in workers.iter_mut().take(threads).enumerate() {
            let (y0, y1) = (rows_of(t), rows_of(t + 1));
            let (mine, tail) = std::mem::take(&mut rest).split_at_mut((y1 - y0) * width);
            rest = tail;
            if t == 0 {
                first = Some((mine, s));
            } else {
                let run = &run;
                scope.spawn(move || run(y0, y1, mine, s));
            }
        }
        if let Some((mine, s)) = first {
            run(0, rows_of(1), mine, s);
        }
    });
}
