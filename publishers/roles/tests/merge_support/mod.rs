//! The random maps and transforms both merge property tests draw (`merge_fast.rs`,
//! `merge_average.rs`): any map size from 1×1 to 140² (1×N, N×1, odd), cell sizes 0.05–0.5 m,
//! any rotation, unknown / free / occupied cells (log-odds beyond any clamp included) and
//! pheromone levels.

use pheromone_field::GridGeometry;
use pheromone_roles::mapper::MergeTransform;
use proptest::collection::vec;
use proptest::prelude::*;

fn cell() -> impl Strategy<Value = (f32, f32)> {
    prop_oneof![
        2 => Just((0.0f32, 0.0f32)),
        1 => (Just(0.0f32), 0.0f32..1.0),
        3 => (-5.0f32..5.0, 0.0f32..1.0),
        1 => (-30.0f32..30.0, 0.0f32..1.0),
        1 => (Just(-0.0f32), Just(0.5f32)),
    ]
}

fn side() -> impl Strategy<Value = u32> {
    prop_oneof![1u32..=3, 1u32..=40, 60u32..=140]
}

/// A map: geometry (centred on its origin, as `LocalMap`'s) and both planes' cells.
pub fn map() -> impl Strategy<Value = (GridGeometry, Vec<(f32, f32)>)> {
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

pub fn transform() -> impl Strategy<Value = MergeTransform> {
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
