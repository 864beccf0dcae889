//! The merge pass (`merge_planes`: eight cells at a time with AVX2 where the CPU has it) gives
//! the reference pass's result (`merge_planes_reference`: one cell at a time) bit for bit, with
//! the same counts, for any map sizes (1×1, 1×N, N×1, odd), cell sizes, transforms and cells
//! (unknown, free, occupied; pheromone).

use field::GridGeometry;
use proptest::collection::vec;
use proptest::prelude::*;
use roles::mapper::merge::merge_planes_reference;
use roles::mapper::{merge_planes, MapView, MergeRule, MergeTransform};

fn cell() -> impl Strategy<Value = (f32, f32)> {
    prop_oneof![
        2 => Just((0.0f32, 0.0f32)),
        1 => (Just(0.0f32), 0.0f32..1.0),
        3 => (-5.0f32..5.0, 0.0f32..1.0),
        1 => (Just(-0.0f32), Just(0.5f32)),
    ]
}

fn side() -> impl Strategy<Value = u32> {
    prop_oneof![1u32..=3, 1u32..=40, 60u32..=140]
}

/// A map: geometry (centred on its origin, as `LocalMap`'s) and both planes.
fn map() -> impl Strategy<Value = (GridGeometry, Vec<(f32, f32)>)> {
    (side(), side(), prop_oneof![Just(0.2f32), 0.05f32..0.5]).prop_flat_map(|(w, h, c)| {
        let g = GridGeometry {
            width: w,
            height: h,
            cell_size_m: c,
            origin_x_m: -0.5 * w as f32 * c,
            origin_y_m: -0.5 * h as f32 * c,
        };
        (Just(g), vec(cell(), (w * h) as usize))
    })
}

fn transform() -> impl Strategy<Value = MergeTransform> {
    (
        prop_oneof![Just(0.0f64), Just(0.3), -3.2f64..3.2],
        prop_oneof![Just(0.0f64), 0.0f64..3.0],
        -3.2f64..3.2,
        (-1.0f64..1.0, -1.0f64..1.0),
    )
        .prop_map(|(theta, d, alpha, (px, py))| MergeTransform {
            theta_ij_rad: theta,
            d_ij_m: d,
            alpha_ji_rad: alpha,
            src_robot_m: [px, py],
            dst_robot_m: [py, px],
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn fast_merge_equals_the_reference_bit_for_bit(
        (sg, s) in map(),
        (dg, d) in map(),
        t in transform(),
        rule in prop_oneof![Just(MergeRule::AdoptUnknown), Just(MergeRule::Average)],
    ) {
        let (so, sp): (Vec<f32>, Vec<f32>) = s.into_iter().unzip();
        let (d_occ, d_ph): (Vec<f32>, Vec<f32>) = d.into_iter().unzip();
        let view = MapView { geometry: sg, occupancy: &so, pheromone: &sp };
        let (mut fo, mut fp) = (d_occ.clone(), d_ph.clone());
        let (mut ro, mut rp) = (d_occ, d_ph);
        let fast = merge_planes(&dg, (&mut fo, &mut fp), &view, &t, (rule, 4.0));
        let reference = merge_planes_reference(&dg, (&mut ro, &mut rp), &view, &t, (rule, 4.0));
        prop_assert_eq!(fast.is_ok(), reference.is_ok());
        if let (Ok(f), Ok(r)) = (fast, reference) {
            prop_assert_eq!(f, r);
        }
        let same = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        prop_assert!(same(&fo, &ro), "occupancy differs");
        prop_assert!(same(&fp, &rp), "pheromone differs");
    }
}
