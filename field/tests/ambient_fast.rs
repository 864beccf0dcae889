//! The fast ambient pass (four rows' prefix sums at once, `pheromone_field::ambient`) against the
//! reference pass (one row at a time), within the bound `pheromone_field::ambient` proves.
//!
//! Both passes sum the same terms in different orders. Each window sum is within
//! `E = (2·W + n_v)·u·S` of the exact one (u = 2⁻⁵³, W the width, `n_v = 2r + 1 + 2B` with B
//! the band height, S here the sum of |cells| of the whole plane, which bounds every partial
//! sum), so the two differ by at most `2E`; dividing by the window's cell count `c` (the same
//! factor in both, one rounding each) and rounding to f32 (½ ulp each) gives
//! `|fast − reference| ≤ 2E/c·(1 + 2u) + ulp(max(|fast|, |reference|))`. The fused step
//! `P' = P − (1 − e)·(P − min(P, α·Pa))` moves by at most `(1 − e)·α` times that plus a few
//! ulps of `P` for its own roundings.
//!
//! Radii up to `DIRECT_RADIUS_MAX` take the direct pass (each window added from its own cells in
//! f32, `pheromone_field::ambient`): within `(d + 3)·u₃₂·S_w / n` of the exact window mean
//! (`direct_bound`), checked against each window's compensated sum, and against the reference
//! within the sum of both passes' bounds.

use pheromone_field::models::{
    ambient_mean_plane_with, step_plane_with, Dispatch, PlanePlan, Scratch,
};
use pheromone_field::models::{band_rows, DIRECT_RADIUS_MAX};
use proptest::collection::vec;
use proptest::prelude::*;

fn cell_value() -> impl Strategy<Value = f32> + Clone {
    prop_oneof![
        3 => Just(0.0f32),
        3 => 0.0f32..1.0,
        2 => 0.0f32..1.0e3,
        1 => 1.0e3f32..1.0e7,
        1 => 1.0e-30f32..1.0e-6,
    ]
}

/// Any shape: 1×1, 1×N, N×1, odd, widths with and without a four-column tail, and planes
/// taller than a band (band restarts, short last groups).
fn plane() -> impl Strategy<Value = (usize, usize, Vec<f32>)> {
    prop_oneof![
        (1usize..=9, 1usize..=9),
        (1usize..=1, 1usize..=40),
        (1usize..=40, 1usize..=1),
        (1usize..=37, 1usize..=37),
        (1usize..=13, 250usize..=600),
    ]
    .prop_flat_map(|(w, h)| (Just(w), Just(h), vec(cell_value(), w * h)))
}

fn dispatches() -> Vec<Dispatch> {
    let mut d = vec![Dispatch::portable()];
    d.extend(Dispatch::avx2());
    d
}

/// The bound on |fast − reference| of the mean at (x, y), before the f32 rounding.
fn mean_bound(w: usize, h: usize, r: usize, x: usize, y: usize, abs_sum: f64) -> f64 {
    let u = f64::EPSILON / 2.0;
    let n_v = 2 * r + 1 + 2 * band_rows(h, r);
    let e = (2 * w + n_v) as f64 * u * abs_sum;
    let cols = (x + r).min(w - 1) - x.saturating_sub(r) + 1;
    let rows = (y + r).min(h - 1) - y.saturating_sub(r) + 1;
    2.0 * e / (cols * rows) as f64 * (1.0 + 4.0 * u)
}

/// The direct pass's bound on |mean − exact mean| for a window of `n` cells whose |cells| sum
/// to `abs` (`pheromone_field::ambient`): (d + 3)·u₃₂·abs / n, d = 2·⌈log₂(2r + 1)⌉, plus the
/// smallest subnormal for an underflowing product.
fn direct_bound(r: usize, abs: f64, n: usize) -> f64 {
    let d = [0.0, 4.0, 6.0][r];
    (d + 3.0) * (f32::EPSILON as f64 / 2.0) * abs / n as f64 + f32::from_bits(1) as f64
}

/// The window of (x, y) clipped to the plane: its Σ|cells| and its cell count.
fn window_abs(cells: &[f32], w: usize, r: usize, x: usize, y: usize) -> (f64, usize) {
    let h = cells.len() / w;
    let (mut abs, mut n) = (0.0f64, 0usize);
    for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
        for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
            abs += cells[yy * w + xx].abs() as f64;
            n += 1;
        }
    }
    (abs, n)
}

/// The direct pass's bound at (x, y) if radius `r` takes it, else 0.
fn direct_extra(cells: &[f32], w: usize, r: usize, x: usize, y: usize) -> f64 {
    if r > DIRECT_RADIUS_MAX {
        return 0.0;
    }
    let (abs, n) = window_abs(cells, w, r, x, y);
    direct_bound(r, abs, n)
}

fn ulp(v: f32) -> f64 {
    (f32::EPSILON as f64 * v.abs() as f64).max(f32::from_bits(1) as f64)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The fast mean equals the reference within the proven bound, never NaN nor negative, on
    /// both kernel instantiations and on several threads.
    #[test]
    fn fast_ambient_mean_is_within_the_bound_of_the_reference(
        (w, h, cells) in plane(),
        r in prop_oneof![0usize..=3, 0usize..=45],
        threads in 1usize..=3,
    ) {
        let abs_sum: f64 = cells.iter().map(|&c| c.abs() as f64).sum();
        for d in dispatches() {
            let reference = ambient_mean_plane_with(&cells, w, r, d.reference(), 1);
            let fast = ambient_mean_plane_with(&cells, w, r, d, threads);
            for y in 0..h {
                for x in 0..w {
                    let (f, g) = (fast[y * w + x], reference[y * w + x]);
                    prop_assert!(f.is_finite() && f >= 0.0, "({x}, {y}): {f}");
                    let bound = mean_bound(w, h, r, x, y, abs_sum)
                        + ulp(f.max(g))
                        + direct_extra(&cells, w, r, x, y);
                    prop_assert!(
                        (f as f64 - g as f64).abs() <= bound,
                        "({x}, {y}) of {w}×{h}, r = {r}, {}: fast {f} vs reference {g} \
                         (bound {bound:e})", d.name()
                    );
                }
            }
        }
    }

    /// The fused step of the fast pass equals the reference's within the bound carried through
    /// the decay, and never raises a cell.
    #[test]
    fn fast_ambient_step_is_within_the_bound_of_the_reference(
        (w, h, cells) in plane(),
        r in prop_oneof![0u32..=3, 0u32..=45],
        factor in 0.0f32..=1.0,
        alpha in prop_oneof![Just(1.0f32), 0.0f32..=1.0],
    ) {
        let abs_sum: f64 = cells.iter().map(|&c| c.abs() as f64).sum();
        let plan = PlanePlan::Ambient { factor, alpha, radius_cells: r };
        for d in dispatches() {
            let step = |d: Dispatch| {
                let mut next = vec![f32::NAN; cells.len()];
                step_plane_with(plan, 0.0, w, &cells, &mut next, &mut Scratch::default(), 1, d);
                next
            };
            let (fast, reference) = (step(d), step(d.reference()));
            for (i, ((&f, &g), &p)) in fast.iter().zip(&reference).zip(&cells).enumerate() {
                let (x, y) = (i % w, i / w);
                prop_assert!(f.is_finite() && (0.0..=p).contains(&f), "cell {i}: {p} -> {f}");
                let mean = mean_bound(w, h, r as usize, x, y, abs_sum)
                    + ulp(p)
                    + direct_extra(&cells, w, r as usize, x, y);
                let bound = (1.0 - factor as f64) * alpha as f64 * mean + 4.0 * ulp(p);
                prop_assert!(
                    (f as f64 - g as f64).abs() <= bound,
                    "({x}, {y}) of {w}×{h}, r = {r}, {}: fast {f} vs reference {g} \
                     (bound {bound:e})", d.name()
                );
            }
        }
    }
}

/// The window mean of (x, y) summed with Neumaier's compensated sum (error O(n·u²)·Σ|cells|,
/// far below the direct pass's bound), the window's Σ|cells| and its cell count.
fn compensated_mean(cells: &[f32], w: usize, r: usize, x: usize, y: usize) -> (f64, f64, usize) {
    let h = cells.len() / w;
    let (mut sum, mut comp, mut abs, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
        for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
            let v = cells[yy * w + xx] as f64;
            let t = sum + v;
            comp += if sum.abs() >= v.abs() {
                (sum - t) + v
            } else {
                (v - t) + sum
            };
            sum = t;
            abs += v.abs();
            n += 1;
        }
    }
    ((sum + comp) / n as f64, abs, n)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The direct pass of small radii (`r ≤ DIRECT_RADIUS_MAX`) is within its own bound of
    /// each window's exact mean (`direct_bound`), and gives the same bits on both kernel
    /// instantiations and on any number of threads.
    #[test]
    fn direct_ambient_mean_is_within_its_window_bound(
        (w, h, cells) in plane(),
        r in 0usize..=DIRECT_RADIUS_MAX,
        threads in 1usize..=3,
    ) {
        let u = f64::EPSILON / 2.0;
        let base = ambient_mean_plane_with(&cells, w, r, Dispatch::portable(), 1);
        for y in 0..h {
            for x in 0..w {
                let (exact, abs, n) = compensated_mean(&cells, w, r, x, y);
                let got = base[y * w + x];
                // The compensated mean's own error (a few u₆₄ of abs / n) is far below it.
                let bound = direct_bound(r, abs, n) + 4.0 * u * abs / n as f64;
                prop_assert!(
                    (got as f64 - exact).abs() <= bound,
                    "({x}, {y}) of {w}×{h}, r = {r}: direct {got} vs exact {exact} (bound {bound:e})"
                );
            }
        }
        for d in dispatches() {
            let other = ambient_mean_plane_with(&cells, w, r, d, threads);
            prop_assert!(
                other.iter().zip(&base).all(|(a, b)| a.to_bits() == b.to_bits()),
                "{} on {threads} threads differs from portable on 1", d.name()
            );
        }
    }
}

/// A plane large enough for the fast passes' non-temporal stores (≥ 4 Mi cells; an odd width,
/// so that rows start at every alignment): the mean by the direct pass (r = 1) and by the
/// running sums (r = 3) equals the reference pass within the bounds above at the first and
/// last columns of every row and at every 61st, on one thread and on two, and the fused step
/// likewise.
#[test]
fn streamed_large_plane_equals_the_reference() {
    let (w, h) = (4099usize, 1024usize);
    let cells: Vec<f32> = (0..w * h)
        .map(|i| ((i as u32).wrapping_mul(2_654_435_761) >> 8) as f32 / 65_536.0)
        .collect();
    let abs_sum: f64 = cells.iter().map(|&c| c as f64).sum();
    let columns: Vec<usize> = (0..5)
        .chain(w - 5..w)
        .chain((5..w - 5).step_by(61))
        .collect();
    let d = Dispatch::detect();
    for r in [1usize, 3] {
        let reference = ambient_mean_plane_with(&cells, w, r, d.reference(), 1);
        for threads in [1, 2] {
            let fast = ambient_mean_plane_with(&cells, w, r, d, threads);
            for y in 0..h {
                for &x in &columns {
                    let (f, g) = (fast[y * w + x], reference[y * w + x]);
                    let bound = mean_bound(w, h, r, x, y, abs_sum)
                        + ulp(f.max(g))
                        + direct_extra(&cells, w, r, x, y);
                    assert!(
                        (f as f64 - g as f64).abs() <= bound,
                        "({x}, {y}), r = {r}, {threads} threads: fast {f} vs reference {g}"
                    );
                }
            }
        }
        let plan = PlanePlan::Ambient {
            factor: 0.9,
            alpha: 1.0,
            radius_cells: r as u32,
        };
        let step = |d: Dispatch| {
            let mut next = vec![f32::NAN; cells.len()];
            step_plane_with(
                plan,
                0.0,
                w,
                &cells,
                &mut next,
                &mut Scratch::default(),
                2,
                d,
            );
            next
        };
        let (fast, reference) = (step(d), step(d.reference()));
        for y in 0..h {
            for &x in &columns {
                let (f, g, p) = (fast[y * w + x], reference[y * w + x], cells[y * w + x]);
                let mean =
                    mean_bound(w, h, r, x, y, abs_sum) + ulp(p) + direct_extra(&cells, w, r, x, y);
                assert!(
                    (f as f64 - g as f64).abs() <= 0.1 * mean + 4.0 * ulp(p),
                    "step ({x}, {y}), r = {r}: fast {f} vs reference {g}"
                );
            }
        }
    }
}
