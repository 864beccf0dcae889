//! The merge pass (`merge_planes`: eight cells at a time with AVX2 where the CPU has it) gives
//! the reference pass's result (`merge_planes_reference`: one cell at a time) bit for bit by
//! the `adopt-unknown` rule, with the same counts, for any map sizes (1×1, 1×N, N×1, odd), cell
//! sizes, transforms and cells (unknown, free, occupied; pheromone). The `average` rule:
//! `merge_average.rs`.

mod merge_support;

use merge_support::{map, transform};
use pheromone_roles::mapper::merge::merge_planes_reference;
use pheromone_roles::mapper::{merge_planes, MapView, MergeRule};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn fast_merge_equals_the_reference_bit_for_bit(
        (sg, s) in map(),
        (dg, d) in map(),
        t in transform(),
    ) {
        let rule = MergeRule::AdoptUnknown;
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
