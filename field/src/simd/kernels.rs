//! The row kernels of the plane pass (`crate::ambient`): plain Rust, written so that they
//! vectorize. The ones `Dispatch` runs are marked `#[inline(always)]` and instantiated by the
//! parent module twice, for the baseline and for AVX2.

#[inline]
pub(crate) fn scale(src: &[f32], out: &mut [f32], factor: f32) {
    for (o, &p) in out.iter_mut().zip(src) {
        *o = p * factor;
    }
}

#[inline]
pub(crate) fn subtract_toward_zero(p: f32, loss: f32) -> f32 {
    let m = (p.abs() - loss).max(0.0);
    m.copysign(p)
}

pub(crate) fn diffuse_row(row: &[f32], up: &[f32], down: &[f32], kappa: f32, out: &mut [f32]) {
    let w = row.len();
    if w == 1 {
        out[0] = row[0] + kappa * (up[0] + down[0] - 2.0 * row[0]);
        return;
    }
    out[0] = row[0] + kappa * (row[1] + up[0] + down[0] - 3.0 * row[0]);
    for x in 1..w - 1 {
        out[x] = row[x] + kappa * (row[x - 1] + row[x + 1] + up[x] + down[x] - 4.0 * row[x]);
    }
    out[w - 1] = row[w - 1] + kappa * (row[w - 2] + up[w - 1] + down[w - 1] - 3.0 * row[w - 1]);
}

#[inline(always)]
pub(crate) fn add_row(col_sum: &mut [f64], row: &[f32]) {
    for (c, &v) in col_sum.iter_mut().zip(row) {
        *c += v as f64;
    }
}

#[inline(always)]
pub(crate) fn sub_row(col_sum: &mut [f64], row: &[f32]) {
    for (c, &v) in col_sum.iter_mut().zip(row) {
        *c -= v as f64;
    }
}

/// One row enters the window and one leaves. The difference of two f32 is exact in f64, so this
/// is one rounding per column instead of two.
///
/// `ahead` (the row that enters next, or empty) is prefetched a cache line per line of this
/// row: the entering row is the pass's one read from memory, and without the hint every row
/// starts with a stall on it (`perf annotate`: 72 % of this kernel's samples on that load at
/// 2048²), as the hardware prefetcher does not run ahead across the rows' other work. A hint
/// changes no result.
#[inline(always)]
pub(crate) fn swap_row(col_sum: &mut [f64], row_in: &[f32], row_out: &[f32], ahead: &[f32]) {
    const LINE: usize = 16; // f32 per 64-byte cache line
    let n = col_sum.len().min(row_in.len()).min(row_out.len());
    let full = n - n % LINE;
    let chunks = col_sum[..full]
        .chunks_exact_mut(LINE)
        .zip(row_in[..full].chunks_exact(LINE))
        .zip(row_out[..full].chunks_exact(LINE));
    for (k, ((c, ri), ro)) in chunks.enumerate() {
        if let Some(a) = ahead.get(k * LINE) {
            super::prefetch(a);
        }
        for ((c, &i), &o) in c.iter_mut().zip(ri).zip(ro) {
            *c += i as f64 - o as f64;
        }
    }
    for ((c, &i), &o) in col_sum[full..n]
        .iter_mut()
        .zip(&row_in[full..n])
        .zip(&row_out[full..n])
    {
        *c += i as f64 - o as f64;
    }
}

/// As `add_row`, out of place: `dst = src + row` (the fast pass keeps each group row's sums).
#[inline(always)]
pub(crate) fn add_row_into(dst: &mut [f64], src: &[f64], row: &[f32]) {
    for ((d, &c), &v) in dst.iter_mut().zip(src).zip(row) {
        *d = c + v as f64;
    }
}

/// As `sub_row`, out of place.
#[inline(always)]
pub(crate) fn sub_row_into(dst: &mut [f64], src: &[f64], row: &[f32]) {
    for ((d, &c), &v) in dst.iter_mut().zip(src).zip(row) {
        *d = c - v as f64;
    }
}

/// As `swap_row`, out of place (the same operations, so the same bits): `dst = src + (in −
/// out)`, prefetching `ahead`.
#[inline(always)]
pub(crate) fn swap_row_into(
    dst: &mut [f64],
    src: &[f64],
    row_in: &[f32],
    row_out: &[f32],
    ahead: &[f32],
) {
    const LINE: usize = 16; // f32 per 64-byte cache line
    let n = dst
        .len()
        .min(src.len())
        .min(row_in.len())
        .min(row_out.len());
    let full = n - n % LINE;
    let chunks = dst[..full]
        .chunks_exact_mut(LINE)
        .zip(src[..full].chunks_exact(LINE))
        .zip(row_in[..full].chunks_exact(LINE))
        .zip(row_out[..full].chunks_exact(LINE));
    for (k, (((d, c), ri), ro)) in chunks.enumerate() {
        if let Some(a) = ahead.get(k * LINE) {
            super::prefetch(a);
        }
        for (((d, &c), &i), &o) in d.iter_mut().zip(c).zip(ri).zip(ro) {
            *d = c + (i as f64 - o as f64);
        }
    }
    for (((d, &c), &i), &o) in dst[full..n]
        .iter_mut()
        .zip(&src[full..n])
        .zip(&row_in[full..n])
        .zip(&row_out[full..n])
    {
        *d = c + (i as f64 - o as f64);
    }
}

/// `prefix[i] = Σ col[..i]` (`prefix` is one longer than `col`). The row is cut into eight
/// blocks whose local sums run interleaved, so the adds overlap instead of waiting on each other;
/// a second, vectorized pass adds to each block the total of the blocks before it.
#[inline(always)]
pub(crate) fn prefix_sum(col: &[f64], prefix: &mut [f64]) {
    const K: usize = 8;
    let n = col.len();
    assert_eq!(prefix.len(), n + 1);
    prefix[0] = 0.0;
    let out = &mut prefix[1..];
    let q = n / K;
    if q < 4 {
        let mut acc = 0.0;
        for (p, &c) in out.iter_mut().zip(col) {
            acc += c;
            *p = acc;
        }
        return;
    }
    let mut acc = [0.0f64; K];
    for i in 0..q {
        for k in 0..K {
            acc[k] += col[k * q + i];
            out[k * q + i] = acc[k];
        }
    }
    // The remainder joins the last block.
    for i in K * q..n {
        acc[K - 1] += col[i];
        out[i] = acc[K - 1];
    }
    let mut offset = 0.0;
    for k in 1..K {
        offset += acc[k - 1];
        let end = if k == K - 1 { n } else { (k + 1) * q };
        for p in &mut out[k * q..end] {
            *p += offset;
        }
    }
}

/// The window mean of each cell of a row from its prefix sums.
#[inline(always)]
fn window_mean(hi: f64, lo: f64, inv: f64) -> f32 {
    // Clamped at 0: the cells are non-negative (the ambient model is unsigned-only), but running
    // sums that add and later drop a large value can end a hair below 0.
    let sum = hi - lo;
    let sum = if sum > 0.0 { sum } else { 0.0 };
    (sum * inv) as f32
}

#[inline(always)]
pub(crate) fn mean_row(prefix: &[f64], inv_count: &[f64], span: usize, out: &mut [f32]) {
    let w = out.len();
    for (((a, &hi), &lo), &inv) in out
        .iter_mut()
        .zip(&prefix[span..span + w])
        .zip(&prefix[..w])
        .zip(&inv_count[..w])
    {
        *a = window_mean(hi, lo, inv);
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn decay_row(
    prefix: &[f64],
    inv_count: &[f64],
    span: usize,
    src: &[f32],
    out: &mut [f32],
    factor: f32,
    alpha: f32,
) {
    let w = out.len();
    let one_minus = 1.0 - factor;
    for ((((o, &p), &hi), &lo), &inv) in out
        .iter_mut()
        .zip(&src[..w])
        .zip(&prefix[span..span + w])
        .zip(&prefix[..w])
        .zip(&inv_count[..w])
    {
        // = P·e + (1 − e)·min(P, α·Pa), written so that rounding can never raise the cell:
        // P − (1 − e)·(P − m) with 0 ≤ m ≤ P gives 0 ≤ P' ≤ P in floating point too. (A plain
        // compare-select, not f32::min: cells are finite, and it vectorizes to one minps.)
        let m = alpha * window_mean(hi, lo, inv);
        let m = if m < p { m } else { p };
        *o = p - one_minus * (p - m);
    }
}
