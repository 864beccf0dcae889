use super::super::marks::{marks, AREA_A_RGB, AREA_B_RGB};
use super::super::style::{lighter, Rgb, OUTLINE_RGB, ROBOT_RGB, VIRIDIS};
use super::super::tests::scene;
use super::*;
use pheromone_messages::FollowerState;
use pheromone_world::scenario::Scenario;

/// The first snapshot's channel 0, in its own colour scale.
fn draw_first(rec: &Recording, marks: &[Mark]) -> Result<Picture, String> {
    let snap = &rec.snapshots[0];
    render_snapshot(rec, snap, 0, marks, &ColourMap::for_plane(snap.plane(0)))
}

#[test]
fn trajectories_stop_at_the_snapshot_time() {
    let mut rec = scene();
    rec.snapshots[0].t_s = 4.0; // robot 0 is at x = 3 m then
    let pic = draw_first(&rec, &[]).unwrap();
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
    let pic = draw_first(&rec, &[]).unwrap();
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
    let pic = draw_first(&rec, &[]).unwrap();
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

/// A recording of `scenario`'s grid (zero everywhere) at `t_s`, with robot 1 in the corridor,
/// "leader lost" from t = 30 s at x = 15 m, at x = 16 m by t = 31 s.
fn blank_run(scenario: &Scenario, t_s: f64) -> Recording {
    let f = &scenario.field;
    let mut rec = Recording::default();
    rec.snapshots.push(Snapshot {
        t_s,
        width: f.width,
        height: f.height,
        cell_size_m: f.cell_size_m,
        channels: vec!["leader".into()],
        planes: vec![0.0; (f.width * f.height) as usize],
    });
    let mut lost = super::super::tests::sample(30.0, 15.0, 1.5);
    lost.state = Some(FollowerState::LeaderLost);
    let mut before = super::super::tests::sample(29.9, 14.95, 1.5);
    before.state = Some(FollowerState::Following);
    let mut after = super::super::tests::sample(31.0, 16.0, 1.5);
    after.state = Some(FollowerState::LeaderLost);
    rec.robots.insert(1, vec![before, lost, after]);
    rec
}

#[test]
fn wrong_area_marks_a_b_and_where_a_follower_explored() {
    let s = Scenario::load("wrong-area").unwrap();
    let w = s.metrics.wrong_area.clone().unwrap();
    let layout = Layout::for_grid(s.field.width, s.field.height, s.field.cell_size_m);
    let draw = |t_s: f64| {
        let rec = blank_run(&s, t_s);
        draw_first(&rec, &marks(&s, &rec)).unwrap()
    };
    let pic = draw(80.0);
    let at = |x_m: f64, y_m: f64| {
        let (x, y) = layout.pixel_from_world(x_m, y_m);
        pic.get(x.round() as usize, y.round() as usize)
    };
    // A's outline, at 39 points along each of its four sides.
    let ([x0, y0], [x1, y1]) = (w.a_min_m, w.a_max_m);
    for k in 1..40 {
        let f = k as f64 / 40.0;
        let (x, y) = (x0 + f * (x1 - x0), y0 + f * (y1 - y0));
        for (px, py) in [(x, y0), (x, y1), (x0, y), (x1, y)] {
            assert_eq!(
                at(px, py),
                AREA_A_RGB,
                "A's outline at ({px:.2}, {py:.2}) m"
            );
        }
    }
    // Inside A, off its outline and label: the cells.
    assert_eq!(at(20.5, 5.0), VIRIDIS[0]);
    // B: a circle of b_radius_m around b_m, its centre left as it is.
    let (bx, by, r) = (w.b_m[0], w.b_m[1], w.b_radius_m);
    for deg in [0.0f64, 30.0, 60.0, 120.0, 150.0, 180.0, 210.0, 330.0] {
        let (x, y) = (
            bx + r * deg.to_radians().cos(),
            by + r * deg.to_radians().sin(),
        );
        assert_eq!(at(x, y), AREA_B_RGB, "B's circle at {deg}°");
    }
    assert_eq!(at(bx, by), VIRIDIS[0]);
    // Robot 1's colour on the cross where it started exploring, from then on only.
    assert_eq!(at(15.0 + 0.1, 1.5 + 0.1), ROBOT_RGB[1]);
    let early = draw(20.0);
    let (x, y) = layout.pixel_from_world(15.1, 1.6);
    assert_eq!(
        early.get(x.round() as usize, y.round() as usize),
        VIRIDIS[0]
    );

    // A scenario without `wrong_area` marks neither A nor B: neither colour anywhere.
    let plain = Scenario::load("blind-leader").unwrap();
    assert!(plain.metrics.wrong_area.is_none());
    let rec = blank_run(&plain, 80.0);
    assert!(marks(&plain, &rec)
        .iter()
        .all(|m| matches!(m.shape, Shape::Point { .. })));
    let pic = draw_first(&rec, &marks(&plain, &rec)).unwrap();
    let (pw, ph) = (pic.width as usize, pic.height as usize);
    for y in 0..ph {
        for x in 0..pw {
            let c = pic.get(x, y);
            assert!(
                c != AREA_A_RGB && c != AREA_B_RGB,
                "a mark's colour at ({x}, {y})"
            );
        }
    }
}

/// Issue 48 part 5 (seed 000 Fig. 22): wrong-area's pictures draw the leader's σ as a circle
/// of that radius at its estimate at each of L1–L15, each from its checkpoint's time on, in its
/// colour; only the last is labelled.
#[test]
fn wrong_area_draws_the_leaders_sigma_circles_along_its_path() {
    let s = Scenario::load("wrong-area").unwrap();
    let layout = Layout::for_grid(s.field.width, s.field.height, s.field.cell_size_m);
    // The leader drives along y = 1.5 m from x = 3.5 to 25.5 m, its estimate on its true path,
    // its σ growing from 0.1 to 2 m.
    let n = 221;
    let rows: Vec<RobotSample> = (0..n)
        .map(|k| {
            let f = k as f64 / (n - 1) as f64;
            let mut r = super::super::tests::sample(0.2 * k as f64, 3.5 + 0.1 * k as f64, 1.5);
            r.est_pose = Some(r.true_pose);
            r.est_sigma_m = Some(0.1 + 1.9 * f * f);
            r
        })
        .collect();
    let mut rec = blank_run(&s, 80.0);
    rec.robots.insert(0, rows);
    let all = marks(&s, &rec);
    let circles: Vec<&Mark> = all
        .iter()
        .filter(|m| m.rgb == ROBOT_RGB[0] && matches!(m.shape, Shape::Circle { .. }))
        .collect();
    assert_eq!(circles.len(), 15, "{all:?}");
    let labelled: Vec<&str> = circles.iter().map(|m| m.label.as_str()).collect();
    assert_eq!(labelled[14], "R0 σ at L1–L15 (estimate)");
    assert!(labelled[..14].iter().all(|l| l.is_empty()), "{labelled:?}");
    // A point of each ring: σ above L8's estimate, and L15's at 150° (B's label, above B,
    // hides its top).
    let on_circle = |m: &Mark, deg: f64| match m.shape {
        Shape::Circle { centre_m, radius_m } => (
            centre_m[0] + radius_m * deg.to_radians().cos(),
            centre_m[1] + radius_m * deg.to_radians().sin(),
            radius_m,
        ),
        _ => unreachable!(),
    };
    let (x8, y8, r8) = on_circle(circles[7], 90.0);
    let (x15, y15, r15) = on_circle(circles[14], 150.0);
    assert!((r8 - (0.1 + 1.9 * 0.25)).abs() < 0.05 && (r15 - 2.0).abs() < 1e-9);
    // The ring (3 px in the leader's colour over a 5 px dark edge) passes within 2 px.
    let on_ring = |pic: &Picture, x_m: f64, y_m: f64| {
        let (x, y) = layout.pixel_from_world(x_m, y_m);
        let (x, y) = (x.round() as usize, y.round() as usize);
        (y - 2..=y + 2).any(|y| (x - 2..=x + 2).any(|x| pic.get(x, y) == ROBOT_RGB[0]))
    };
    let pic = draw_first(&rec, &all).unwrap();
    assert!(on_ring(&pic, x8, y8) && on_ring(&pic, x15, y15));
    // At L7's time (the robot, its "R0" label with it, 1.6 m short of L8) neither is drawn.
    rec.snapshots[0].t_s = circles[6].from_s;
    let early = draw_first(&rec, &all).unwrap();
    assert!(!on_ring(&early, x8, y8) && !on_ring(&early, x15, y15));
}

/// Issue 51: blind-leader's pictures mark where the leader (R0) got lost, at its true position
/// at the scripted loss (25 s), labelled with its world x and the time, and where the follower
/// (R1) gave the trail up; each from its time on, the two labels apart.
#[test]
fn blind_leader_marks_where_the_leader_got_lost_and_where_the_follower_gave_up() {
    let s = Scenario::load("blind-leader").unwrap();
    let layout = Layout::for_grid(s.field.width, s.field.height, s.field.cell_size_m);
    let run = |t_s: f64| {
        let mut rec = blank_run(&s, t_s);
        let leader = (0..=60)
            .map(|k| super::super::tests::sample(k as f64, 3.0 + 0.5 * k as f64, 1.5))
            .collect();
        rec.robots.insert(0, leader);
        rec
    };
    let rec = run(80.0);
    let m = marks(&s, &rec);
    let labels: Vec<&str> = m.iter().map(|m| m.label.as_str()).collect();
    assert_eq!(
        labels,
        [
            "R0 lost at x = 15.5 m (t = 25.0 s)",
            "R1 gave up at x = 15.0 m (t = 30.0 s)"
        ]
    );
    assert_eq!(m[0].shape, Shape::Point { at_m: [15.5, 1.5] });
    assert_eq!((m[0].rgb, m[1].rgb), (ROBOT_RGB[0], ROBOT_RGB[1]));
    let pic = draw_first(&rec, &m).unwrap();
    let at = |pic: &Picture, x_m: f64, y_m: f64| {
        let (x, y) = layout.pixel_from_world(x_m, y_m);
        pic.get(x.round() as usize, y.round() as usize)
    };
    // The leader's cross: its colour on the cross's arm, 3 px from its centre.
    let (cx, cy) = layout.pixel_from_world(15.5, 1.5);
    assert_eq!(
        pic.get(cx.round() as usize + 3, cy.round() as usize + 3),
        ROBOT_RGB[0]
    );
    // Before the loss neither cross is drawn.
    let early = run(20.0);
    let pic = draw_first(&early, &marks(&s, &early)).unwrap();
    assert_ne!(
        pic.get(cx.round() as usize + 3, cy.round() as usize + 3),
        ROBOT_RGB[0]
    );
    assert_eq!(at(&pic, 15.0 + 0.03, 1.5 + 0.03), VIRIDIS[0]);
}

/// Two crosses at one place: their labels do not overlap (the second moves).
#[test]
fn labels_of_crosses_at_one_place_do_not_overlap() {
    let s = Scenario::load("blind-leader").unwrap();
    let rec = blank_run(&s, 80.0);
    let layout = Layout::for_grid(s.field.width, s.field.height, s.field.cell_size_m);
    let cross = |label: &str, rgb: Rgb| Mark {
        shape: Shape::Point { at_m: [10.0, 1.5] },
        label: label.into(),
        rgb,
        from_s: 0.0,
    };
    let m = [
        cross("first label here", ROBOT_RGB[2]),
        cross("second label here", ROBOT_RGB[3]),
    ];
    let pic = draw_first(&rec, &m).unwrap();
    // The rows that hold each label's text colour, within the field.
    let rows_of = |rgb: Rgb| -> Vec<usize> {
        let (x0, _) = layout.pixel_from_world(0.0, 0.0);
        let x1 = x0 as usize + layout.field_w_px();
        (0..pic.height as usize)
            .filter(|&y| (x0 as usize..x1).any(|x| pic.get(x, y) == rgb))
            .collect()
    };
    let (a, b) = (rows_of(ROBOT_RGB[2]), rows_of(ROBOT_RGB[3]));
    assert!(!a.is_empty() && !b.is_empty());
    let text_a: Vec<usize> = a.iter().copied().filter(|y| !b.contains(y)).collect();
    let text_b: Vec<usize> = b.iter().copied().filter(|y| !a.contains(y)).collect();
    assert!(
        !text_a.is_empty() && !text_b.is_empty(),
        "each label has rows of its own: {a:?} {b:?}"
    );
}
