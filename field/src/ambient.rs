//! The tick's plane pass over bands of rows: separable running-sum box mean for the ambient
//! model, fused with the decay, and the split of a plane's rows across threads.
//!
//! # The ambient mean
//! `Pa` of a cell is the mean of `prev` over the `(2r+1)²` window around it, clipped to the grid.
//! It is computed separably, per *band* of consecutive rows:
//! - vertically, `col_sum[x]` (f64) holds the sum of column `x` over the rows of the current
//!   row's window; the next row adds the row entering and drops the row leaving (one f64 add of
//!   an exact f32 difference per column, wide over x);
//! - horizontally, a prefix sum of `col_sum` along the row, whose differences are the window
//!   sums. The fast pass (`band_grouped`) takes the column sums of four consecutive rows and
//!   sums their prefixes at once, one row per SIMD lane (`Dispatch::prefix_rows4`: 4 × 4
//!   transposes, one add of loop-carried chain per four columns), where the reference pass
//!   (`band_reference`, `Dispatch::reference`) sums one row at a time in eight interleaved
//!   blocks (`kernels::prefix_sum`), a chain of dependent scalar adds;
//! - the output is fused: `P' = P − (1 − e)·(P − min(P, α·Pa))`, written once per cell, so each
//!   cell of `prev` is read once for the output (plus the running sums' reads of the rows entering
//!   and leaving the window, which are cache-hot for small radii) and each cell of `next` is
//!   written once.
//!
//! Small radii (`r ≤ DIRECT_RADIUS_MAX`, windows up to 5 × 5) take the *direct* pass instead
//! (`band_direct`): no running sums and no prefix sums, but each row's column sums added afresh
//! in f32 from its `2r + 1` window rows (`kernels::column_sums`, all rows in one pass over the
//! row) and each cell's window sum from its `2r + 1` column sums (`kernels::decay_direct`, fused
//! with the decay as above), eight cells per AVX2 instruction. For a 3 × 3 window that is four
//! f32 adds per cell where the running sums cost an f64 swap, a prefix pass and a difference per
//! cell, and nothing carries from one row to the next.
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
//! sum; the bound holds for any order of the additions, so for both passes, which differ only
//! in that order and so by at most twice it: `field/tests/ambient_fast.rs` checks the fast pass
//! against the reference within it). Dividing by the cell count and rounding to f32 adds
//! ½ ulp(f32). For the grids of the
//! property tests (values ≤ 1e6, W ≤ 32) that is far below 1e-6 relative; for a 4096² field it is
//! below 2⁻³⁹·S_row / count — negligible against the f32 output unless one window holds values
//! 1e10 times larger than its neighbours' (then the small means are absolutely, not relatively,
//! accurate). A window sum that round-off pushes below 0 is clamped to 0.
//!
//! The direct pass adds the `n ≤ (2r + 1)²` cells of a clipped window in f32 (u₃₂ = 2⁻²⁴) in a
//! fixed tree, vertical then horizontal, in which every cell passes through at most
//! `d = 2·⌈log₂(2r + 1)⌉` additions (0, 4, 6 for r = 0, 1, 2), so its window sum is within
//! `γ_d·S_w` of the exact one (γ_d = d·u₃₂ / (1 − d·u₃₂), `S_w` the sum of |cells| of that
//! window alone: Higham, *Accuracy and Stability of Numerical Algorithms*, §4.2, for any
//! summation tree). 1 / n is computed in f64 and rounded once to f32, and the product rounded
//! once more, so the mean is within `(d + 3)·u₃₂·S_w / n` of the exact window mean (the third
//! u₃₂ covers the second-order terms), plus 2⁻¹⁴⁹ where the product underflows — for
//! non-negative cells at most 4.2·10⁻⁷ (r = 1) and 5.4·10⁻⁷ (r = 2) of the mean itself, inside
//! the peers' and the property tests' tolerances; beside the reference pass's bound it is the
//! larger term. `field/tests/ambient_fast.rs` checks it against a compensated sum of each
//! window and against the reference pass (within the sum of both bounds).
//!
//! # SIMD
//! The row kernels (`crate::simd::kernels`) are plain Rust written so that they vectorize;
//! `crate::simd` runs them compiled for AVX2 when the CPU has it (detected once at run time) and for the baseline
//! otherwise. Both compile the same operations in the same order without FMA contraction, so the
//! two paths give bit-identical results (`field/tests/properties.rs` checks it).
//!
//! On planes of at least `STREAM_CELLS_MIN` cells (16 MiB) the fast passes make each output row
//! in a row buffer and copy it to the plane with non-temporal stores (`simd::stream_copy`, then
//! one `sfence` per band): the next frame is not read into the caches before it is written, and
//! does not evict the rows still to be read. The bits are the same.

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

/// The largest radius the direct pass serves (`band_direct`: a window of at most 5 × 5 cells,
/// each cell's sum added from its own cells); larger radii take the running sums.
pub const DIRECT_RADIUS_MAX: usize = 2;

/// Rows the fast pass sums horizontally at once (one per SIMD lane, `Dispatch::prefix_rows4`).
const GROUP_ROWS: usize = 4;

/// Per-thread scratch of the band pass (O(width), never O(grid)).
#[derive(Debug, Default, Clone)]
pub struct BandScratch {
    col_sum: Vec<f64>,
    inv_count_x: Vec<f64>,
    diffused: Vec<f32>,
    /// Per row of a group (the reference pass uses the first only): the column sums, the
    /// padded prefix sums, 1 / (cells of each window) and the window rows that one was made for.
    cols: [Vec<f64>; GROUP_ROWS],
    prefix: [Vec<f64>; GROUP_ROWS],
    inv_count: [Vec<f64>; GROUP_ROWS],
    inv_count_rows: [usize; GROUP_ROWS],
    /// The direct pass's column sums (padded by the radius) and 1 / (cells of each window).
    direct_cols: Vec<f32>,
    direct_inv: Vec<f32>,
    /// A fast pass's output row before it is streamed to the plane (`Rows::write_out`).
    direct_out: Vec<f32>,
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
    let rows = Rows {
        output,
        kappa,
        width,
        prev,
        y0,
        stream: prev.len() >= STREAM_CELLS_MIN,
    };
    match radius {
        None if kappa == 0.0 => no_window(output, &prev[y0 * width..y1 * width], out),
        None => {
            for y in y0..y1 {
                rows.write(
                    y,
                    Window::None,
                    &mut out[(y - y0) * width..(y - y0 + 1) * width],
                    s,
                    0,
                    dispatch,
                );
            }
        }
        Some(r) if dispatch.is_reference() => band_reference(&rows, r, y1, out, s, dispatch),
        Some(r) if r <= DIRECT_RADIUS_MAX => band_direct(&rows, r, y1, out, s, dispatch),
        Some(r) => band_grouped(&rows, r, y1, out, s, dispatch),
    }
    if rows.stream {
        crate::simd::store_fence();
    }
}

/// The plans without a window mean or diffusion: each cell from its own previous value.
fn no_window(output: Output, src: &[f32], out: &mut [f32]) {
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
}

/// The reference pass: one row at a time, the row's prefix sums by `kernels::prefix_sum`.
fn band_reference(
    rows: &Rows<'_>,
    radius: usize,
    y1: usize,
    out: &mut [f32],
    s: &mut BandScratch,
    d: Dispatch,
) {
    let (w, y0) = (rows.width, rows.y0);
    let mut sums = ColumnSums::start(w, rows.prev, radius, y0, s, d);
    let rx = sums.radius_x;
    for y in y0..y1 {
        let rows_in = sums.advance(y, y0, rows.prev, s, d);
        set_inv_count(s, 0, rows_in);
        let prefix = &mut s.prefix[0];
        d.prefix_sum(&s.col_sum, &mut prefix[rx..=rx + w]);
        pad(prefix, rx, w);
        let o = &mut out[(y - y0) * w..(y - y0 + 1) * w];
        rows.write(y, Window::Prefix(rx), o, s, 0, d);
    }
}

/// The fast pass: the column sums of `GROUP_ROWS` consecutive rows, then their prefix sums at
/// once (`Dispatch::prefix_rows4`, one row per lane), then the rows' outputs. Groups start at
/// the band's first row, so they too are independent of the thread count.
fn band_grouped(
    rows: &Rows<'_>,
    radius: usize,
    y1: usize,
    out: &mut [f32],
    s: &mut BandScratch,
    d: Dispatch,
) {
    let (w, y0) = (rows.width, rows.y0);
    let sums = ColumnSums::start(w, rows.prev, radius, y0, s, d);
    let rx = sums.radius_x;
    for c in &mut s.cols {
        c.clear();
        c.resize(w, 0.0);
    }
    // Each group row's sums are the previous row's moved by one row, out of place (the group's
    // first row continues from the last row of the group before, or from the start-up sums).
    s.cols[GROUP_ROWS - 1].copy_from_slice(&s.col_sum);
    let mut y = y0;
    while y < y1 {
        let g = (y1 - y).min(GROUP_ROWS);
        for k in 0..g {
            let (before, from_k) = s.cols.split_at_mut(k);
            let (dst, after) = from_k.split_first_mut().expect("k < GROUP_ROWS");
            let src = match k {
                0 => &after[GROUP_ROWS - 2],
                _ => &before[k - 1],
            };
            let rows_in = sums.advance_into(y + k, y0, rows.prev, src, dst, d);
            set_inv_count(s, k, rows_in);
        }
        // A short last group repeats its last row in the unused lanes (results unused).
        let [c0, c1, c2, c3] = &s.cols;
        let cols = [c0, c1, c2, c3].map(|c| c.as_slice());
        let cols = std::array::from_fn(|k| cols[k.min(g - 1)]);
        let [p0, p1, p2, p3] = &mut s.prefix;
        d.prefix_rows4(cols, [p0, p1, p2, p3].map(|p| &mut p[rx..=rx + w]));
        for k in 0..g {
            pad(&mut s.prefix[k], rx, w);
            let o = &mut out[(y + k - y0) * w..(y + k - y0 + 1) * w];
            rows.write_out(y + k, Window::Prefix(rx), o, s, k, d);
        }
        y += g;
    }
}

/// The direct pass of small radii (`r ≤ DIRECT_RADIUS_MAX`): each row's column sums over its
/// window rows added afresh in f32 (`Dispatch::column_sums`, into `direct_cols` between `r`
/// zeros on each side), then each cell's window sum from its `2r + 1` column sums
/// (`Dispatch::decay_direct`).
/// No state carries from one row to the next, so bands and threads change nothing.
fn band_direct(
    rows: &Rows<'_>,
    r: usize,
    y1: usize,
    out: &mut [f32],
    s: &mut BandScratch,
    d: Dispatch,
) {
    let (w, y0, prev) = (rows.width, rows.y0, rows.prev);
    let h = prev.len() / w;
    s.direct_cols.clear();
    s.direct_cols.resize(w + 2 * r, 0.0);
    set_inv_count_x(s, w, r.min(w));
    for y in y0..y1 {
        let (top, bottom) = (y.saturating_sub(r), (y + r).min(h - 1));
        // The row that enters the next row's window is fetched from memory while this row is
        // computed (a hint: no result changes; `kernels::swap_row` says why it pays).
        if y + r + 1 < h {
            for v in prev[(y + r + 1) * w..(y + r + 2) * w].iter().step_by(16) {
                crate::simd::prefetch(v);
            }
        }
        d.column_sums(
            &mut s.direct_cols[r..r + w],
            &prev[top * w..(bottom + 1) * w],
        );
        let rows_in = bottom + 1 - top;
        if s.inv_count_rows[0] != rows_in {
            set_inv_count(s, 0, rows_in);
            s.direct_inv.clear();
            s.direct_inv
                .extend(s.inv_count[0].iter().map(|&c| c as f32));
        }
        let o = &mut out[(y - y0) * w..(y - y0 + 1) * w];
        rows.write_out(y, Window::Direct(r), o, s, 0, d);
    }
}

/// Planes of at least this many cells are written by the fast passes with non-temporal stores
/// (`simd::stream_copy`): 4 Mi cells, 16 MiB, beyond what the caches keep of a frame beside the
/// one it is read from.
const STREAM_CELLS_MIN: usize = 1 << 22;

/// Fills the right pad of a prefix row with the row's total (the left pad stays 0).
fn pad(prefix: &mut [f64], rx: usize, w: usize) {
    let total = prefix[rx + w];
    prefix[rx + w + 1..].fill(total);
}

/// Where a row's window sums come from.
#[derive(Debug, Clone, Copy)]
enum Window {
    /// No window (diffusion or a plan without a mean).
    None,
    /// Prefix sums of group row `k` padded by this many columns (`s.prefix[k]`).
    Prefix(usize),
    /// The direct pass's column sums padded by this radius (`s.direct_cols`).
    Direct(usize),
}

/// What every row of a band shares.
struct Rows<'a> {
    output: Output,
    kappa: f32,
    width: usize,
    prev: &'a [f32],
    y0: usize,
    /// The fast passes write through `write_out` with non-temporal stores (large planes).
    stream: bool,
}

impl Rows<'_> {
    /// As `write`; on a large plane (`stream`) the row is made in `s.direct_out` and streamed
    /// to `o` (`simd::stream_copy`, the same bits; `band` fences after the last row).
    fn write_out(
        &self,
        y: usize,
        window: Window,
        o: &mut [f32],
        s: &mut BandScratch,
        k: usize,
        d: Dispatch,
    ) {
        if !self.stream {
            return self.write(y, window, o, s, k, d);
        }
        let mut row = std::mem::take(&mut s.direct_out);
        row.resize(o.len(), 0.0);
        self.write(y, window, &mut row, s, k, d);
        crate::simd::stream_copy(o, &row);
        s.direct_out = row;
    }

    /// Writes output row `y` into `o`, from the window sums `window` of group row `k` of `s`.
    fn write(
        &self,
        y: usize,
        window: Window,
        o: &mut [f32],
        s: &mut BandScratch,
        k: usize,
        d: Dispatch,
    ) {
        let (width, prev) = (self.width, self.prev);
        let height = prev.len() / width;
        let row = &prev[y * width..(y + 1) * width];
        let src: &[f32] = if self.kappa > 0.0 {
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
            s.diffused.resize(width, 0.0);
            diffuse_row(row, up, down, self.kappa, &mut s.diffused);
            &s.diffused
        } else {
            row
        };
        let (prefix, inv) = (&s.prefix[k], &s.inv_count[k]);
        match (self.output, window) {
            (Output::Mean { .. }, Window::Prefix(rx)) => d.mean_row(prefix, inv, 2 * rx + 1, o),
            (Output::Mean { .. }, Window::Direct(r)) => {
                d.mean_direct(&s.direct_cols, &s.direct_inv, 2 * r + 1, o)
            }
            (Output::Mean { .. }, Window::None) => unreachable!("the mean always has a window"),
            (Output::Step { plan, .. }, _) => match plan {
                PlanePlan::Scale { factor } => scale(src, o, factor),
                PlanePlan::Subtract { loss } => {
                    for (c, &p) in o.iter_mut().zip(src) {
                        *c = subtract_toward_zero(p, loss);
                    }
                }
                PlanePlan::Ambient { factor, alpha, .. } => match window {
                    Window::Prefix(rx) => {
                        d.decay_row(prefix, inv, 2 * rx + 1, src, o, factor, alpha)
                    }
                    Window::Direct(r) => {
                        let (cols, inv) = (&s.direct_cols, &s.direct_inv);
                        d.decay_direct(cols, inv, 2 * r + 1, src, o, factor, alpha)
                    }
                    Window::None => ambient_no_mean(src, o, factor),
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

/// The vertical running sums of one band (`BandScratch::col_sum`).
struct ColumnSums {
    radius_y: usize,
    radius_x: usize,
    width: usize,
    height: usize,
}

impl ColumnSums {
    fn start(
        width: usize,
        prev: &[f32],
        radius: usize,
        y0: usize,
        s: &mut BandScratch,
        dispatch: Dispatch,
    ) -> Self {
        let height = prev.len() / width;
        let (radius_x, radius_y) = (radius.min(width), radius.min(height));
        s.col_sum.clear();
        s.col_sum.resize(width, 0.0);
        // The left pads stay 0 (= Σ of nothing); the rest is rewritten every row.
        for p in &mut s.prefix {
            p.clear();
            p.resize(width + 2 * radius_x + 1, 0.0);
        }
        set_inv_count_x(s, width, radius_x);
        // The window of row y0 without its last row (row y0 + r enters in `advance`).
        for y in y0.saturating_sub(radius_y)..(y0 + radius_y).min(height) {
            dispatch.add_row(&mut s.col_sum, &prev[y * width..(y + 1) * width]);
        }
        Self {
            radius_y,
            radius_x,
            width,
            height,
        }
    }

    /// Moves the sums to row `y` (rows in order from the band's first row `y0`); returns the
    /// number of rows in row `y`'s window.
    fn advance(
        &mut self,
        y: usize,
        y0: usize,
        prev: &[f32],
        s: &mut BandScratch,
        d: Dispatch,
    ) -> usize {
        let (w, r) = (self.width, self.radius_y);
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
        (y + r).min(self.height - 1) - y.saturating_sub(r) + 1
    }

    /// As `advance`, out of place: `dst` = the sums of row `y` from `src`, those of row
    /// `y − 1` (the same operations, so the same bits).
    fn advance_into(
        &self,
        y: usize,
        y0: usize,
        prev: &[f32],
        src: &[f64],
        dst: &mut [f64],
        d: Dispatch,
    ) -> usize {
        let (w, r) = (self.width, self.radius_y);
        let row = |i: usize| &prev[i * w..(i + 1) * w];
        let enters = y + r < self.height;
        let leaves = y > y0 && y > r;
        match (enters, leaves) {
            (true, true) => {
                let ahead = if y + r + 1 < self.height {
                    row(y + r + 1)
                } else {
                    &[]
                };
                d.swap_row_into(dst, src, row(y + r), row(y - r - 1), ahead)
            }
            (true, false) => d.add_row_into(dst, src, row(y + r)),
            (false, true) => d.sub_row_into(dst, src, row(y - r - 1)),
            (false, false) => dst.copy_from_slice(src),
        }
        (y + r).min(self.height - 1) - y.saturating_sub(r) + 1
    }
}

/// Makes `s.inv_count_x[x]` 1 / (columns of the window of column `x`, half-width `radius_x`
/// clipped to the row) and resets every `s.inv_count[k]` (`set_inv_count` fills them).
fn set_inv_count_x(s: &mut BandScratch, width: usize, radius_x: usize) {
    s.inv_count_x.clear();
    s.inv_count_x.extend(
        (0..width)
            .map(|x| 1.0 / ((x + radius_x + 1).min(width) - x.saturating_sub(radius_x)) as f64),
    );
    for (c, rows) in s.inv_count.iter_mut().zip(&mut s.inv_count_rows) {
        c.clear();
        c.resize(width, 0.0);
        *rows = 0;
    }
}

/// Makes `s.inv_count[k]` 1 / (cells of each window of a row whose window has `rows_in`
/// rows).
fn set_inv_count(s: &mut BandScratch, k: usize, rows_in: usize) {
    if s.inv_count_rows[k] == rows_in {
        return;
    }
    let inv_rows = 1.0 / rows_in as f64;
    for (c, &cx) in s.inv_count[k].iter_mut().zip(&s.inv_count_x) {
        *c = cx * inv_rows;
    }
    s.inv_count_rows[k] = rows_in;
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
