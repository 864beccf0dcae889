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

// ---------------------------------------------------------------------------------------------
// The direct pass of small radii (`crate::ambient`'s `band_direct`): each window sum added up
// from its own cells in f32, in a fixed tree (every cell passes through at most
// `2·⌈log₂(2r + 1)⌉` additions: the bound of `crate::ambient`), no running sums and no prefix
// sums.

/// `col[x] = Σ_k rows[k][x]` over the `n = rows.len() / col.len()` consecutive rows (1 ≤ n ≤ 5),
/// in f32 in a tree: `(r0 + r1) + r2` for three rows, `((r0 + r1) + (r2 + r3)) + r4` for five
/// (each cell through at most ⌈log₂ n⌉ additions).
#[inline(always)]
pub(crate) fn column_sums(col: &mut [f32], rows: &[f32]) {
    let w = col.len();
    let n = rows.len() / w;
    let row = |k: usize| &rows[k * w..(k + 1) * w];
    match n {
        1 => col.copy_from_slice(row(0)),
        2 => {
            for ((c, &a), &b) in col.iter_mut().zip(row(0)).zip(row(1)) {
                *c = a + b;
            }
        }
        3 => {
            for (((c, &a), &b), &e) in col.iter_mut().zip(row(0)).zip(row(1)).zip(row(2)) {
                *c = (a + b) + e;
            }
        }
        4 => {
            let rows4 = row(0).iter().zip(row(1)).zip(row(2)).zip(row(3));
            for (c, (((&a, &b), &e), &f)) in col.iter_mut().zip(rows4) {
                *c = (a + b) + (e + f);
            }
        }
        5 => {
            let rows4 = row(0).iter().zip(row(1)).zip(row(2)).zip(row(3));
            for ((c, (((&a, &b), &e), &f)), &g) in col.iter_mut().zip(rows4).zip(row(4)) {
                *c = ((a + b) + (e + f)) + g;
            }
        }
        _ => unreachable!("the direct pass sums 1 to 5 rows"),
    }
}

/// The window sum of `S` (1, 3 or 5) consecutive column sums from `col[x]`, in the tree of
/// `column_sums`, clamped at 0 as `window_mean` clamps.
#[inline(always)]
fn direct_sum<const S: usize>(col: &[f32], x: usize) -> f32 {
    let sum = match S {
        1 => col[x],
        3 => (col[x] + col[x + 1]) + col[x + 2],
        _ => ((col[x] + col[x + 1]) + (col[x + 2] + col[x + 3])) + col[x + 4],
    };
    if sum > 0.0 {
        sum
    } else {
        0.0
    }
}

#[inline(always)]
fn mean_direct_span<const S: usize>(col: &[f32], inv_count: &[f32], out: &mut [f32]) {
    let w = out.len();
    let (col, inv_count) = (&col[..w + S - 1], &inv_count[..w]);
    for (x, (o, &inv)) in out.iter_mut().zip(inv_count).enumerate() {
        *o = direct_sum::<S>(col, x) * inv;
    }
}

#[inline(always)]
fn decay_direct_span<const S: usize>(
    col: &[f32],
    inv_count: &[f32],
    src: &[f32],
    out: &mut [f32],
    factor: f32,
    alpha: f32,
) {
    let w = out.len();
    let (col, inv_count, src) = (&col[..w + S - 1], &inv_count[..w], &src[..w]);
    let one_minus = 1.0 - factor;
    for (x, ((o, &p), &inv)) in out.iter_mut().zip(src).zip(inv_count).enumerate() {
        // The same expression as `decay_row`, from the window's own mean.
        let m = alpha * (direct_sum::<S>(col, x) * inv);
        let m = if m < p { m } else { p };
        *o = p - one_minus * (p - m);
    }
}

/// The window mean of each cell of a row: `out[x] = (Σ col[x..x + span]) · inv_count[x]`, `col`
/// the column sums with `(span − 1) / 2` zeros on each side; span 1, 3 or 5.
#[inline(always)]
pub(crate) fn mean_direct(col: &[f32], inv_count: &[f32], span: usize, out: &mut [f32]) {
    match span {
        1 => mean_direct_span::<1>(col, inv_count, out),
        3 => mean_direct_span::<3>(col, inv_count, out),
        5 => mean_direct_span::<5>(col, inv_count, out),
        _ => unreachable!("the direct pass serves spans 1, 3 and 5"),
    }
}

/// As `decay_row` from the direct window sums (`mean_direct`'s `col` and `inv_count`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn decay_direct(
    col: &[f32],
    inv_count: &[f32],
    span: usize,
    src: &[f32],
    out: &mut [f32],
    factor: f32,
    alpha: f32,
) {
    match span {
        1 => decay_direct_span::<1>(col, inv_count, src, out, factor, alpha),
        3 => decay_direct_span::<3>(col, inv_count, src, out, factor, alpha),
        5 => decay_direct_span::<5>(col, inv_count, src, out, factor, alpha),
        _ => unreachable!("the direct pass serves spans 1, 3 and 5"),
    }
}
