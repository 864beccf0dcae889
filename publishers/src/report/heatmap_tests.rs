use super::super::style::{lighter, Rgb, OUTLINE_RGB, ROBOT_RGB, VIRIDIS};
use super::super::tests::scene;
use super::*;

#[test]
fn trajectories_stop_at_the_snapshot_time() {
    let mut rec = scene();
    rec.snapshots[0].t_s = 4.0; // robot 0 is at x = 3 m then
    let pic = render_snapshot(&rec, &rec.snapshots[0], 0).unwrap();
    let layout = Layout::for_grid(100, 50, 0.1);
    let at = |x_m: f64, y_m: f64| {
        let (x, y) = layout.pixel_from_world(x_m, y_m);
        pic.get(x as usize, y as usize)
    };
    assert_eq!(at(2.0, 1.0), ROBOT_RGB[0]);
    assert_eq!(at(5.0, 1.0), VIRIDIS[0]);
    // The marker sits at the position at t = 4 s: the robot's colour inside an outline.
    assert_eq!(at(3.0, 1.0), ROBOT_RGB[0]);
    assert_eq!(at(3.0 + 6.0 / 80.0, 1.0), OUTLINE_RGB);
}

#[test]
fn a_gap_in_the_estimates_breaks_the_dashed_line() {
    let mut rec = scene();
    let rows = rec.robots.get_mut(&1).unwrap();
    for r in &mut rows[4..=6] {
        r.est_pose = None; // x = 3 … 4 m
    }
    let pic = render_snapshot(&rec, &rec.snapshots[0], 0).unwrap();
    let layout = Layout::for_grid(100, 50, 0.1);
    let row = |x0_m: f64, x1_m: f64| -> Vec<Rgb> {
        let (x0, y) = layout.pixel_from_world(x0_m, 2.5);
        let (x1, _) = layout.pixel_from_world(x1_m, 2.5);
        (x0 as usize..x1 as usize)
            .map(|x| pic.get(x, y as usize))
            .collect()
    };
    let shade = lighter(ROBOT_RGB[1]);
    assert!(row(1.0, 2.5).contains(&shade));
    assert!(row(4.5, 6.0).contains(&shade));
    assert!(row(2.6, 4.4).iter().all(|&c| c == VIRIDIS[0]));
}

#[test]
fn paths_are_anti_aliased() {
    // A diagonal true path: pixels beside it are blends of the path's colour and the cells'.
    let mut rec = scene();
    let rows = rec.robots.get_mut(&0).unwrap();
    for (i, r) in rows.iter_mut().enumerate() {
        r.true_pose = [1.0 + 0.3 * i as f64, 0.5 + 0.2 * i as f64, 0.0];
    }
    let pic = render_snapshot(&rec, &rec.snapshots[0], 0).unwrap();
    let layout = Layout::for_grid(100, 50, 0.1);
    let (a, b) = (ROBOT_RGB[0], VIRIDIS[0]);
    let mut full = 0;
    let mut blends = 0;
    for k in 0..40 {
        let t = 0.1 + 0.02 * k as f64;
        let (x, y) = layout.pixel_from_world(1.0 + 3.0 * t, 0.5 + 2.0 * t);
        for dy in -4i64..=4 {
            let c = pic.get(x as usize, (y as i64 + dy) as usize);
            if c == a {
                full += 1;
            } else if c != b {
                // Between the two colours, channel by channel.
                let between = (0..3).all(|i| c[i].min(a[i].max(b[i])) >= a[i].min(b[i]));
                assert!(between, "{c:?} is not a blend of {a:?} and {b:?}");
                blends += 1;
            }
        }
    }
    assert!(full >= 40, "{full} pixels of the path's own colour");
    assert!(
        blends >= 40,
        "{blends} blended pixels: the path is not anti-aliased"
    );
}

#[test]
fn picture_size_stays_between_800_and_2000_pixels() {
    for (w, h) in [
        (30, 20),
        (100, 50),
        (600, 400),
        (512, 512),
        (1500, 900),
        (10, 1000),
    ] {
        let l = Layout::for_grid(w, h, 0.05);
        assert_eq!(l.decimate, 1);
        assert!(
            l.field_w_px().max(l.field_h_px()) <= MAX_SIDE_PX,
            "{w}×{h}: {l:?}"
        );
        if (h as usize) * MIN_WIDTH_PX.div_ceil(w as usize) <= MAX_SIDE_PX {
            assert!(l.field_w_px() >= MIN_WIDTH_PX, "{w}×{h}: {l:?}");
        }
        let (pw, ph) = l.picture_px();
        assert_eq!(pw as usize, l.field_w_px() + (LEFT_PX + RIGHT_PX) as usize);
        assert_eq!(
            ph as usize,
            l.field_h_px() + (TOP_PX + AXIS_PX + STRIP_PX) as usize
        );
    }
    // A grid larger than the cap is reduced by whole blocks, keeping each block's max.
    let l = Layout::for_grid(5000, 7, 0.05);
    assert_eq!(
        (l.decimate, l.blocks_w, l.blocks_h, l.scale),
        (3, 1667, 3, 1)
    );
    let mut plane = vec![0.0f32; 5000 * 7];
    plane[6 * 5000 + 4999] = 2.0; // the last, partial block
    assert_eq!(l.block_value(&plane, 1666, 2), 2.0);
    assert_eq!(l.block_value(&plane, 0, 0), 0.0);
}

#[test]
fn colour_bar_ticks_are_round_include_the_ends_and_never_overlap() {
    for (lo, hi, width) in [
        (0.0, 7.0, 400),
        (0.0, 340.0, 436),
        (0.0, 0.0123, 300),
        (-2.5, 2.5, 380),
        (0.0, 1.0e6, 200),
        (0.0, 49.97, 120),
    ] {
        let ticks = bar_ticks(lo, hi, width);
        assert!(ticks.len() >= 2, "{lo}…{hi}: {ticks:?}");
        assert_eq!(ticks[0], lo);
        assert_eq!(*ticks.last().unwrap(), hi);
        let px = |v: f64| (v - lo) / (hi - lo) * width as f64;
        for p in ticks.windows(2) {
            assert!(p[1] > p[0], "{ticks:?}");
            if ticks.len() > 2 {
                let half = (text_width(&fmt_sig(p[0])) + text_width(&fmt_sig(p[1]))) as f64 / 2.0;
                assert!(
                    px(p[1]) - px(p[0]) > half,
                    "{lo}…{hi} in {width} px: {ticks:?}"
                );
            }
        }
    }
    // The bar sits right of the legend's half of the strip.
    let (x0, x1) = bar_span_px(800);
    assert!(x0 > 400 && x1 <= 800 - RIGHT_PX as i32);
}
