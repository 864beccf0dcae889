use super::*;

#[test]
fn lists_parse_and_bad_items_are_refused_naming_the_option_and_value() {
    assert_eq!(parse_robots("1, 2,4").unwrap(), vec![1, 2, 4]);
    assert_eq!(parse_rc_m("4,8.5,40").unwrap(), vec![4.0, 8.5, 40.0]);
    assert_eq!(
        parse_strategies("inverse,uniform").unwrap(),
        vec![StrategyKind::Inverse, StrategyKind::Uniform]
    );
    for (e, option, value) in [
        (parse_robots("0").unwrap_err(), "--robots", "\"0\""),
        (parse_robots("1,x").unwrap_err(), "--robots", "\"x\""),
        (parse_robots("2,2").unwrap_err(), "--robots", "\"2\""),
        (parse_robots("1,,2").unwrap_err(), "--robots", "\"1,,2\""),
        (parse_rc_m("-1").unwrap_err(), "--rc-m", "\"-1\""),
        (parse_rc_m("abc").unwrap_err(), "--rc-m", "\"abc\""),
        (parse_rc_m("8,NaN").unwrap_err(), "--rc-m", "\"NaN\""),
        (parse_rc_m("inf").unwrap_err(), "--rc-m", "\"inf\""),
        (
            parse_strategies("route").unwrap_err(),
            "--strategies",
            "\"route\"",
        ),
    ] {
        let text = e.to_string();
        assert!(text.contains(option) && text.contains(value), "{text}");
    }
}

fn grid() -> SweepGrid {
    SweepGrid {
        robots: vec![1, 2],
        rc_m: vec![],
        merge: vec![true, false],
        strategies: vec![StrategyKind::Inverse],
        steer: vec![],
        integration: vec![],
        trials: 2,
        duration_s: 15.0,
        figure: Figure::Known,
    }
}

#[test]
fn steering_is_a_dimension_of_the_plan_and_a_bad_item_is_refused() {
    assert_eq!(
        parse_steer("own-map, shared").unwrap(),
        vec![SteerOn::OwnMap, SteerOn::Shared]
    );
    for bad in ["own", "shared,shared", "own-map,,shared"] {
        let e = parse_steer(bad).unwrap_err().to_string();
        assert!(e.contains("--steer"), "{e}");
    }
    assert_eq!("merged".parse::<Figure>(), Ok(Figure::Merged));
    assert!("max".parse::<Figure>().is_err());
    let base = Scenario::load("ias-ss").unwrap();
    let g = SweepGrid {
        robots: vec![2],
        steer: vec![SteerOn::OwnMap, SteerOn::Shared],
        trials: 1,
        ..grid()
    };
    let runs = plan(&base, &g).unwrap();
    let keys: Vec<(bool, SteerOn)> = runs.iter().map(|r| (r.0.merge, r.0.steer_on)).collect();
    assert_eq!(
        keys,
        [
            (true, SteerOn::OwnMap),
            (true, SteerOn::Shared),
            (false, SteerOn::OwnMap),
            (false, SteerOn::Shared)
        ]
    );
    for (key, _, s) in &runs {
        assert_eq!(s.mapping.steer_on, key.steer_on);
        // Own-map steering reads the map's pheromone plane (channel 1), shared the field's.
        let channel = s.follower_config(0).unwrap().channel;
        assert_eq!(channel, u32::from(key.steer_on == SteerOn::OwnMap));
    }
    // Without --steer: the scenario's setting.
    let runs = plan(
        &base,
        &SweepGrid {
            trials: 1,
            ..grid()
        },
    )
    .unwrap();
    assert!(runs.iter().all(|r| r.0.steer_on == SteerOn::Shared));
    let open = Scenario::load("ias-ss-open").unwrap();
    let runs = plan(
        &open,
        &SweepGrid {
            trials: 1,
            ..grid()
        },
    )
    .unwrap();
    assert!(runs.iter().all(|r| r.0.steer_on == SteerOn::OwnMap));
}

#[test]
fn a_sweep_over_both_steerings_records_both_and_compares_like_with_like() {
    let base = Scenario::load("ias-ss").unwrap();
    let g = SweepGrid {
        robots: vec![3],
        steer: vec![SteerOn::OwnMap, SteerOn::Shared],
        duration_s: 150.0,
        figure: Figure::Merged,
        ..grid()
    };
    let r = run_sweep(&base, &g, 2, &|_, _| {}).unwrap();
    assert_eq!(r.figure, Figure::Merged);
    assert_eq!(r.points.len(), 4, "merge on/off × own-map/shared");
    for steer in [SteerOn::OwnMap, SteerOn::Shared] {
        assert_eq!(
            r.points.iter().filter(|p| p.key.steer_on == steer).count(),
            2
        );
    }
    // Merge on vs off within each steering, never across.
    let merge: Vec<&Comparison> = r.comparisons.iter().filter(|c| c.kind == "merge").collect();
    assert_eq!(merge.len(), 2);
    assert!(merge.iter().all(|c| c.a.steer_on == c.b.steer_on));
    for c in &merge {
        let p = r.points.iter().find(|p| p.key == c.a).unwrap();
        assert_eq!(c.mean_a, p.merged_mean.mean, "the comparison's figure");
    }
    for x in &r.runs {
        // The paper's count holds every visited sector.
        assert!(x.merged_mean + 1e-12 >= x.visited_mean, "{x:?}");
        if !x.point.merge {
            assert_eq!(x.merged_mean, x.visited_mean, "{x:?}");
        }
    }
}

#[test]
fn the_plan_is_the_cross_product_and_refuses_too_many_robots() {
    let base = Scenario::load("ias-ss").unwrap();
    let runs = plan(&base, &grid()).unwrap();
    assert_eq!(runs.len(), 2 * 2 * 2);
    let (key, seed, s) = &runs[1];
    assert_eq!((key.robots, key.merge, *seed), (1, true, 2));
    assert_eq!((s.world.robots.len(), s.seed, s.duration_s), (1, 2, 15.0));
    assert_eq!(key.rc_m, base.mapping.rc_m, "the scenario's R_C by default");
    let e = plan(
        &base,
        &SweepGrid {
            robots: vec![99],
            ..grid()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("--robots") && e.contains("99"), "{e}");
    // Two radii: merge on at both, merge off once (at the first).
    let runs = plan(
        &base,
        &SweepGrid {
            robots: vec![2],
            rc_m: vec![4.0, 24.0],
            ..grid()
        },
    )
    .unwrap();
    let keys: Vec<(f64, bool)> = runs.iter().map(|r| (r.0.rc_m, r.0.merge)).collect();
    assert_eq!(
        keys,
        [
            (4.0, true),
            (4.0, true),
            (4.0, false),
            (4.0, false),
            (24.0, true),
            (24.0, true)
        ]
    );
}

#[test]
fn a_sweep_on_two_threads_gives_every_run_once_and_its_comparisons() {
    let base = Scenario::load("ias-ss").unwrap();
    let calls = AtomicUsize::new(0);
    let r = run_sweep(&base, &grid(), 2, &|_, total| {
        assert_eq!(total, 8);
        calls.fetch_add(1, Ordering::Relaxed);
    })
    .unwrap();
    assert_eq!(calls.into_inner(), 8);
    assert_eq!(r.runs.len(), 8);
    assert_eq!(r.points.len(), 4);
    // Grid order, whatever order the threads ran them in.
    let order: Vec<(usize, bool, u64)> = r
        .runs
        .iter()
        .map(|x| (x.point.robots, x.point.merge, x.seed))
        .collect();
    assert_eq!(order[..3], [(1, true, 1), (1, true, 2), (1, false, 1)]);
    assert!(r.runs.iter().all(|x| x.point.steer_on == SteerOn::Shared));
    // One run equals the same run alone (the threads share nothing).
    let (key, seed, s) = &plan(&base, &grid()).unwrap()[5];
    let alone = run_one(*key, *seed, s).unwrap();
    assert_eq!(r.runs[5].known_mean, alone.known_mean);
    assert_eq!(r.runs[5].visited_mean, alone.visited_mean);
    // Merge on vs off for each robot count; no uniform point, so no strategy comparison.
    assert_eq!(r.comparisons.len(), 2);
    assert!(r
        .comparisons
        .iter()
        .all(|c| c.kind == "merge" && c.a.merge && !c.b.merge));
    for x in &r.runs {
        assert!((0.0..=1.0).contains(&x.known_mean) && x.known_mean.is_finite());
        assert!(x.known_mean + 1e-12 >= 0.0);
    }
}

#[test]
fn the_ablations_parse_and_are_points_of_their_own_without_merging_once() {
    assert_eq!(
        parse_merge_rules("average, max").unwrap(),
        vec![MergeRule::Average, MergeRule::Max]
    );
    assert_eq!(parse_merge_idle("0,5,20").unwrap(), vec![0, 5, 20]);
    for e in [
        parse_merge_rules("mean").unwrap_err(),
        parse_merge_rules("max,max").unwrap_err(),
    ] {
        assert!(e.to_string().contains("--merge-rule"), "{e}");
    }
    for (text, value) in [("-1", "\"-1\""), ("5,5", "\"5\""), ("100001", "\"100001\"")] {
        let e = parse_merge_idle(text).unwrap_err().to_string();
        assert!(e.contains("--merge-idle") && e.contains(value), "{e}");
    }
    let base = Scenario::load("ias-ss-open").unwrap();
    assert!(integrations(&base, &[], &[]).is_empty());
    let only_idle = integrations(&base, &[], &[0, 20]);
    assert_eq!(only_idle.len(), 2);
    assert!(only_idle.iter().all(|v| v.merge_rule == MergeRule::Average));
    let variants = integrations(&base, &[MergeRule::Average, MergeRule::Max], &[0, 20]);
    assert_eq!(variants.len(), 4);
    let g = SweepGrid {
        robots: vec![2],
        trials: 1,
        integration: vec![variants[0], variants[3]],
        ..grid()
    };
    let runs = plan(&base, &g).unwrap();
    let keys: Vec<(bool, MergeRule, u32)> = runs
        .iter()
        .map(|r| {
            let v = r.0.integration;
            (r.0.merge, v.merge_rule, v.merge_idle_iterations)
        })
        .collect();
    assert_eq!(
        keys,
        [
            (true, MergeRule::Average, 0),
            (true, MergeRule::Max, 20),
            (false, MergeRule::Average, 0)
        ]
    );
    for (key, _, s) in &runs {
        assert_eq!(s.mapping.merge_rule, key.integration.merge_rule);
        assert_eq!(
            s.mapping.merge_idle_iterations,
            key.integration.merge_idle_iterations
        );
    }
    assert!(runs[1].0.to_string().ends_with("merge by max, 20 idle"));
}

/// Samples of robot `id` with no command (standing still).
fn still(rec: &crate::recording::Recording, id: u32) -> usize {
    rec.robots[&id]
        .iter()
        .filter(|s| s.v_m_per_s == 0.0 && s.omega_rad_per_s == 0.0)
        .count()
}

#[test]
fn a_robot_stands_still_for_the_idle_iterations_after_each_merge() {
    let mut s = Scenario::load("ias-ss-open").unwrap();
    s.apply(&Overrides {
        robots: Some(3),
        duration_s: Some(170.0),
        ..Overrides::default()
    })
    .unwrap();
    let run = |idle: u32| {
        let mut s = s.clone();
        s.mapping.merge_idle_iterations = idle;
        run_single_process(&s, SingleProcessOptions::default())
            .unwrap()
            .1
    };
    let (free, costly) = (run(0), run(20));
    let merges = &costly.mapping.as_ref().unwrap().merges;
    assert!(!merges.is_empty(), "the robots start together: they merge");
    let first = merges[0];
    let dt = s.world.dt_s;
    // From the merge's step on, 20 iterations (200 steps) without a command.
    let samples = &costly.robots[&first.dst];
    let from = samples
        .iter()
        .position(|x| x.t_s + 1e-9 >= first.step as f64 * dt)
        .unwrap();
    let idle = &samples[from..from + 200];
    assert!(
        idle.iter()
            .all(|x| x.v_m_per_s == 0.0 && x.omega_rad_per_s == 0.0),
        "robot {} after its merge at step {}",
        first.dst,
        first.step
    );
    // Before it, the same as the run where merging is free; overall, more standing still.
    let before = |rec: &crate::recording::Recording| rec.robots[&first.dst][..from].to_vec();
    assert_eq!(
        before(&free)
            .iter()
            .map(|x| x.true_pose)
            .collect::<Vec<_>>(),
        before(&costly)
            .iter()
            .map(|x| x.true_pose)
            .collect::<Vec<_>>()
    );
    assert!(still(&costly, first.dst) >= still(&free, first.dst) + 200);
}
