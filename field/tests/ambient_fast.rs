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

use pheromone_field::models::band_rows;
use pheromone_field::models::{
    ambient_mean_plane_with, step_plane_with, Dispatch, PlanePlan, Scratch,
};
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
                    let bound = mean_bound(w, h, r, x, y, abs_sum) + ulp(f.max(g));
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
                let mean = mean_bound(w, h, r as usize, x, y, abs_sum) + ulp(p);
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
