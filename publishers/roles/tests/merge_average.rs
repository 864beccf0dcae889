//! Seed 004's `average` rule: the merge pass (`merge_planes`, eight cells at a time with AVX2
//! where the CPU has it) against the reference pass (`merge_planes_reference`, one cell at a
//! time, libm's σ and σ⁻¹): the same counts and pheromone bits, and every occupancy cell equal
//! or within the proven bound `average_logodds_bound(logodds_max)`; both against the exact
//! average over a dense grid of log-odds pairs; no NaN in or out.

mod merge_support;

use merge_support::{map, transform};
use pheromone_field::GridGeometry;
use pheromone_roles::mapper::merge::{average_logodds_bound, merge_planes_reference};
use pheromone_roles::mapper::{
    merge_planes, MapError, MapView, MergeRule, MergeStats, MergeTransform,
};
use proptest::prelude::*;

type Planes = (Vec<f32>, Vec<f32>);

/// Both passes over copies of `dst`: (fast, its planes), (reference, its planes).
#[allow(clippy::type_complexity)]
fn both(
    dg: &GridGeometry,
    dst: &Planes,
    view: &MapView<'_>,
    t: &MergeTransform,
    max: f32,
) -> (
    (Result<MergeStats, MapError>, Planes),
    (Result<MergeStats, MapError>, Planes),
) {
    let rule = (MergeRule::Average, max);
    let (mut fo, mut fp) = dst.clone();
    let fast = merge_planes(dg, (&mut fo, &mut fp), view, t, rule);
    let (mut ro, mut rp) = dst.clone();
    let reference = merge_planes_reference(dg, (&mut ro, &mut rp), view, t, rule);
    ((fast, (fo, fp)), (reference, (ro, rp)))
}

/// The largest |fast − reference| over the cells (0 where the bits are equal); fails on a
/// non-finite cell.
fn max_difference(fast: &[f32], reference: &[f32]) -> f64 {
    fast.iter().zip(reference).fold(0.0f64, |m, (f, r)| {
        assert!(f.is_finite() && r.is_finite(), "{f} vs {r}");
        if f.to_bits() == r.to_bits() {
            m
        } else {
            m.max((*f as f64 - *r as f64).abs())
        }
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn fast_average_equals_the_reference_within_the_bound(
        (sg, s) in map(),
        (dg, d) in map(),
        t in transform(),
        max in prop_oneof![3 => Just(4.0f32), 2 => 0.25f32..8.0, 1 => Just(8.0f32), 1 => 8.0f32..20.0],
    ) {
        let (so, sp): Planes = s.into_iter().unzip();
        let view = MapView { geometry: sg, occupancy: &so, pheromone: &sp };
        let dst: Planes = d.into_iter().unzip();
        let ((fast, (fo, fp)), (reference, (ro, rp))) = both(&dg, &dst, &view, &t, max);
        prop_assert_eq!(fast.is_ok(), reference.is_ok());
        if let (Ok(f), Ok(r)) = (fast, reference) {
            prop_assert_eq!(f, r);
        }
        let same = fp.iter().zip(&rp).all(|(x, y)| x.to_bits() == y.to_bits());
        prop_assert!(same, "pheromone differs");
        let diff = max_difference(&fo, &ro);
        prop_assert!(diff <= average_logodds_bound(max), "occupancy off by {diff} at max {max}");
        // Beyond the eight-lane pass's range the one-cell pass runs: equal bits.
        if max > 8.0 {
            prop_assert_eq!(diff, 0.0);
        }
    }
}

/// σ⁻¹((σ(a) + σ(b))/2) in f64, in the form without cancellation.
fn exact(a: f32, b: f32, max: f32) -> f64 {
    let m = max as f64;
    let (a, b) = ((a as f64).clamp(-m, m), (b as f64).clamp(-m, m));
    let (ea, eb) = ((-a).exp(), (-b).exp());
    ((2.0 + ea + eb) / (ea + eb + 2.0 * ea * eb))
        .ln()
        .clamp(-m, m)
}

/// One merge of a grid of log-odds pairs (the destination's cell holds a, the source's the same
/// cell's b, identity transform): every pair of a grid of `steps` values across
/// [−max − 1, max + 1] (so the clamps are crossed), plus the equal pairs. Returns the largest
/// |fast − reference|, |fast − exact| and |reference − exact|.
fn grid(max: f32, steps: usize) -> [f64; 3] {
    let values: Vec<f32> = (0..steps)
        .map(|k| (max + 1.0) * (2.0 * k as f32 / (steps - 1) as f32 - 1.0))
        .collect();
    // An odd width: every row ends in a tail the eight-lane loop leaves to the one-cell loop.
    let width = 131u32;
    let height = (steps * steps).div_ceil(width as usize) as u32;
    let g = GridGeometry {
        width,
        height,
        cell_size_m: 0.1,
        origin_x_m: 0.0,
        origin_y_m: 0.0,
    };
    let cells = g.cells();
    let pair = |i: usize| (values[(i / steps) % steps], values[i % steps]);
    let a: Vec<f32> = (0..cells).map(|i| pair(i).0).collect();
    let b: Vec<f32> = (0..cells).map(|i| pair(i).1).collect();
    let pheromone = vec![0.25f32; cells];
    let view = MapView {
        geometry: g,
        occupancy: &b,
        pheromone: &pheromone,
    };
    let dst = (a.clone(), pheromone.clone());
    let t = MergeTransform::default();
    let ((fast, (fo, _)), (reference, (ro, _))) = both(&g, &dst, &view, &t, max);
    assert_eq!(fast.unwrap(), reference.unwrap());
    let off = |x: &[f32]| {
        (0..cells).fold(0.0f64, |m, i| {
            m.max((x[i] as f64 - exact(a[i], b[i], max)).abs())
        })
    };
    [max_difference(&fo, &ro), off(&fo), off(&ro)]
}

#[test]
fn average_over_a_dense_grid_is_within_the_bound_and_closer_to_exact_than_the_reference() {
    let u = 1.0 / 16_777_216.0;
    for max in [0.5f32, 1.0, 4.0, 8.0] {
        let [fast_ref, fast_exact, ref_exact] = grid(max, 601);
        println!(
            "max {max}: |fast − ref| ≤ {fast_ref:.3e} (bound {:.3e}), |fast − exact| ≤ \
             {fast_exact:.3e}, |ref − exact| ≤ {ref_exact:.3e}",
            average_logodds_bound(max)
        );
        assert!(fast_ref <= average_logodds_bound(max));
        // The eight-lane form's own bound (module doc of `merge_logodds`): 3ε_e + 5u + ε_l
        // with ε_e = 2u, ε_l = 2u(1 + M), doubled.
        let m = max as f64;
        assert!(fast_exact <= 2.0 * u * (13.0 + 2.0 * m), "{fast_exact}");
        // The reference's own bound: u(7 + 5e^M + 2M), doubled.
        assert!(
            ref_exact <= 2.0 * u * (7.0 + 5.0 * m.exp() + 2.0 * m),
            "{ref_exact}"
        );
    }
}

#[test]
fn extreme_finite_cells_give_finite_averages_and_a_nan_source_is_refused() {
    let extremes = [
        0.0f32,
        -0.0,
        f32::MAX,
        -f32::MAX,
        f32::MIN_POSITIVE,
        -f32::MIN_POSITIVE,
        1e-45,
        4.0,
        -4.0,
        3.999_999_8,
        100.0,
    ];
    let n = extremes.len();
    let g = GridGeometry {
        width: (n * n) as u32,
        height: 1,
        cell_size_m: 0.1,
        origin_x_m: 0.0,
        origin_y_m: 0.0,
    };
    let a: Vec<f32> = (0..n * n).map(|i| extremes[i / n]).collect();
    let mut b: Vec<f32> = (0..n * n).map(|i| extremes[i % n]).collect();
    let pheromone = vec![0.0f32; n * n];
    let dst = (a.clone(), pheromone.clone());
    let t = MergeTransform::default();
    let view = MapView {
        geometry: g,
        occupancy: &b,
        pheromone: &pheromone,
    };
    let ((fast, (fo, _)), (reference, (ro, _))) = both(&g, &dst, &view, &t, 4.0);
    assert_eq!(fast.unwrap(), reference.unwrap());
    assert!(fo.iter().all(|v| v.is_finite() && v.abs() <= 4.0), "{fo:?}");
    assert!(max_difference(&fo, &ro) <= average_logodds_bound(4.0));
    // A NaN or ±∞ in the source: refused before any cell changes, by both passes.
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        b[n + 3] = bad;
        let view = MapView {
            geometry: g,
            occupancy: &b,
            pheromone: &pheromone,
        };
        let ((fast, (fo, _)), (reference, (ro, _))) = both(&g, &dst, &view, &t, 4.0);
        assert!(matches!(fast, Err(MapError::NonFiniteCell { index, .. }) if index == n + 3));
        assert!(reference.is_err());
        assert_eq!((fo, ro), (a.clone(), a.clone()));
    }
}
