use super::*;

fn header(width: u32, height: u32, channels: u32) -> FrameHeader {
    FrameHeader {
        channels,
        width,
        height,
        cell_size_m: 0.1,
        origin_x_m: -1.0,
        origin_y_m: 2.0,
        sequence: 7,
        ..Default::default()
    }
}

#[test]
fn a_small_plane_is_not_downsampled() {
    let plane: Vec<f32> = (0..12).map(|i| i as f32).collect();
    let d = downsample(&plane, 4, 3, 256);
    assert_eq!((d.width, d.height, d.factor), (4, 3, 1));
    assert_eq!(d.cells, plane);
}

#[test]
fn pooling_keeps_the_largest_magnitude_with_its_sign_and_partial_edge_blocks() {
    // 5 × 3, factor 2 → 3 × 2; blocks at the right and top edges are partial.
    #[rustfmt::skip]
    let plane = [
        1.0, 2.0,  0.0, -5.0, 7.0,
        0.5, 0.0,  4.0,  0.0, 0.0,
        0.0, -9.0, 3.0,  0.0, -1.0,
    ];
    let d = downsample(&plane, 5, 3, 3);
    assert_eq!((d.width, d.height, d.factor), (3, 2, 2));
    assert_eq!(d.cells, vec![2.0, -5.0, 7.0, -9.0, 3.0, -1.0]);
}

#[test]
fn shapes_never_exceed_max_side_and_cover_the_grid() {
    for (w, h) in [
        (1, 1),
        (1024, 1024),
        (1000, 3),
        (3, 1000),
        (257, 256),
        (4096, 17),
    ] {
        let plane = vec![1.0f32; w * h];
        for max_side in [1, 2, 3, 100, 255, 256, 1024, 4096] {
            let d = downsample(&plane, w, h, max_side);
            assert!(
                d.width <= max_side && d.height <= max_side,
                "{w}×{h} to {max_side}"
            );
            assert_eq!(d.width, w.div_ceil(d.factor));
            assert_eq!(d.height, h.div_ceil(d.factor));
            assert_eq!(d.cells.len(), d.width * d.height);
            // The smallest factor that fits: one less would not.
            if d.factor > 1 {
                assert!(w.max(h).div_ceil(d.factor - 1) > max_side);
            }
            assert!(d.cells.iter().all(|&v| v == 1.0));
        }
    }
}

#[test]
fn nan_and_infinity_never_reach_the_snapshot() {
    let mut plane = vec![f32::NAN; 64 * 64];
    plane[5] = f32::INFINITY;
    plane[6] = f32::NEG_INFINITY;
    plane[100] = 0.25;
    let d = downsample(&plane, 64, 64, 8);
    assert!(d.cells.iter().all(|v| v.is_finite()));
    assert_eq!(d.cells.iter().filter(|&&v| v == 0.25).count(), 1);
    let e = extremes(&plane);
    assert_eq!((e.min, e.max, e.argmax), (0.25, 0.25, 100));
    let all_nan = extremes(&[f32::NAN; 4]);
    assert_eq!((all_nan.min, all_nan.max), (0.0, 0.0));
    // The JSON has no NaN either (serde_json would write null).
    let h = header(64, 64, 1);
    let s = serde_json::to_string(&snapshot(&h, &plane, 0, 8)).unwrap();
    assert!(!s.contains("null") && !s.contains("NaN"), "{s}");
}

#[test]
fn the_snapshot_locates_the_hottest_cell_in_metres_and_scales_the_cell_size() {
    let h = header(100, 50, 2);
    let mut cells = vec![0.0f32; 2 * 100 * 50];
    // Channel 1, column 30, row 40: centre at (-1 + 3.05, 2 + 4.05).
    cells[100 * 50 + 40 * 100 + 30] = 3.5;
    cells[100 * 50 + 10] = -2.0;
    let s = snapshot(&h, &cells, 1, 25);
    assert_eq!((s.width, s.height, s.factor), (25, 13, 4));
    assert!((s.cell_size_m - 0.4).abs() < 1e-6);
    assert_eq!((s.min, s.max), (-2.0, 3.5));
    assert_eq!((s.hottest.col, s.hottest.row), (30, 40));
    assert!((s.hottest.x_m - 2.05).abs() < 1e-5, "{}", s.hottest.x_m);
    assert!((s.hottest.y_m - 6.05).abs() < 1e-5, "{}", s.hottest.y_m);
    // In the downsampled grid it is at (30 / 4, 40 / 4).
    assert_eq!(s.cells[10 * 25 + 7], 3.5);
    assert_eq!(s.cells[2], -2.0);
    // Channel 0 is all zeros.
    let s0 = snapshot(&h, &cells, 0, 25);
    assert_eq!((s0.min, s0.max), (0.0, 0.0));
}

#[test]
fn frame_queries_take_defaults_and_name_the_bad_parameter() {
    let q = |s: &str| parse_frame_query(Some(s), 256);
    assert_eq!(
        parse_frame_query(None, 256).unwrap(),
        FrameQuery {
            channel: 0,
            max_side: 256
        }
    );
    assert_eq!(
        q("channel=2&max_side=4096").unwrap(),
        FrameQuery {
            channel: 2,
            max_side: 4096
        }
    );
    assert_eq!(q("").unwrap().max_side, 256);
    let err = |s: &str| q(s).unwrap_err().to_string();
    assert_eq!(err("channel=x"), "channel=x: not a non-negative integer");
    assert_eq!(err("channel=-1"), "channel=-1: not a non-negative integer");
    assert_eq!(err("max_side=0"), "max_side=0: must be between 1 and 4096");
    assert_eq!(
        err("max_side=4097"),
        "max_side=4097: must be between 1 and 4096"
    );
    assert_eq!(err("max_side="), "max_side=: not a non-negative integer");
    assert_eq!(err("zoom=2"), "zoom=2: unknown parameter");
    assert_eq!(err("channel=1&channel=1"), "channel=1: given twice");
    assert_eq!(
        err("channel=4294967296"),
        "channel=4294967296: out of range"
    );
    let c = q("channel=3").unwrap();
    assert!(c.check_channel(4).is_ok());
    assert_eq!(
        c.check_channel(3).unwrap_err().to_string(),
        "channel=3: the field has 3 channel(s), 0..3"
    );
}

#[test]
fn the_tick_rate_comes_from_sequences_over_stamps() {
    let mut t = StatsTracker::default();
    assert_eq!(t.tick_hz(), 0.0);
    let mut h = header(4, 4, 1);
    // 100 Hz, every frame seen but one gap of 30 ms, then frames seen every third tick.
    for (seq, stamp_ms) in [(1u64, 0u64), (2, 10), (3, 40), (6, 70), (9, 100)] {
        h.sequence = seq;
        h.stamp_ns = stamp_ms * 1_000_000;
        t.record(&h);
        t.record(&h); // seen twice: counted once
    }
    assert!((t.tick_hz() - 80.0).abs() < 1e-9, "{}", t.tick_hz());
    let s = t.stats("f", Some(2));
    assert_eq!(s.frames_seen, 5);
    assert!((s.longest_tick_gap_ms - 30.0).abs() < 1e-9);
    assert_eq!(s.deposits_rejected.len(), RejectReason::ALL.len());
    assert!(s.attached);
    // Only the last 2 s count.
    for i in 1..=300u64 {
        h.sequence = 9 + i;
        h.stamp_ns = 100_000_000 + i * 10_000_000;
        t.record(&h);
    }
    assert!((t.tick_hz() - 100.0).abs() < 1e-6, "{}", t.tick_hz());
}

#[test]
fn robot_paths_keep_the_last_positions_and_skip_non_finite_poses() {
    let mut r = RobotPaths::default();
    let pose = |x: f64| pheromone_messages::PoseMsg {
        x_m: x,
        y_m: 1.0,
        ..Default::default()
    };
    for i in 0..(PATH_LENGTH + 50) {
        r.push(3, pose(i as f64));
    }
    r.push(3, pose(f64::NAN));
    r.push(1, pose(0.5));
    r.push(1, pose(0.5));
    let t = r.tracks();
    assert_eq!(t.iter().map(|t| t.id).collect::<Vec<_>>(), vec![1, 3]);
    assert_eq!(t[0].path.len(), 1, "a robot standing still adds one point");
    assert_eq!(t[1].path.len(), PATH_LENGTH);
    assert_eq!(t[1].path[0][0], 50.0);
    assert_eq!(t[1].x_m, (PATH_LENGTH + 49) as f64);
}
