//! Fuzzing what the robot roles accept (issue 7, part 5): every message a role reads from shared
//! memory — `SensorMsg` into the EKF and EKF-SLAM localizers, `PoseMsg` into the depositor and
//! the followers (with wild frames), `CmdMsg` velocities into the world — with arbitrary bit
//! patterns (NaN, ±inf, subnormals, 1e308, absurd counts): never a panic, never a non-finite
//! output, every rejection counted. Also the loaders: scenario TOML, and ROS map_server PGM +
//! YAML maps, random and truncated: never a panic, and every error names what is wrong.
//!
//! `PHEROMONE_FUZZ_CASES` (default 256) scales the number of cases.

use nalgebra::Matrix3;
use pheromone_field::{
    ChannelSpec, DepositMsg, Evaporation, FieldConfig, FrameView, GridGeometry, OwnedField,
};
use pheromone_messages::{LandmarkObs, PoseMsg, SensorMsg, MAX_OBSERVATIONS};
use pheromone_roles::depositor::{msg_is_finite, DepositMode, Depositor, DepositorConfig};
use pheromone_roles::follower::{Follower, FollowerConfig, StrategyKind};
use pheromone_roles::localizer::{CheckedFilter, Ekf, EkfConfig, EkfSlam, EkfSlamConfig};
use pheromone_testkit::toml_fuzz;
use pheromone_world::scenario::Scenario;
use pheromone_world::{Landmark, OccupancyMap, RobotConfig, World, WorldConfig, WorldPose};
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{Config, TestRunner};

fn cases(default: u32) -> u32 {
    match std::env::var("PHEROMONE_FUZZ_CASES") {
        Ok(v) => v
            .parse()
            .unwrap_or_else(|_| panic!("PHEROMONE_FUZZ_CASES = '{v}': expected a whole number")),
        Err(_) => default,
    }
}

fn run<S: Strategy>(cases: u32, strategy: &S, test: impl Fn(S::Value) -> Result<(), TestCaseError>)
where
    S::Value: std::fmt::Debug,
{
    let mut runner = TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    });
    if let Err(e) = runner.run(strategy, test) {
        panic!("{e}");
    }
}

const SPECIALS_F64: [f64; 16] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::MAX,
    f64::MIN,
    1.0e308,
    1.0e39, // finite in f64, ∞ in f32
    -1.0e39,
    f64::MIN_POSITIVE,
    5.0e-324, // subnormal
    1.0e-300,
    -0.0,
    0.0,
    1.0,
    -1.0,
    1.0e6,
];

/// An f64: raw bits, a special value, or plausible in units of `scale`.
fn wild_f64(scale: f64) -> impl Strategy<Value = f64> + Clone {
    prop_oneof![
        1 => any::<u64>().prop_map(f64::from_bits),
        2 => prop::sample::select(&SPECIALS_F64[..]),
        6 => (-1.0f64..1.0).prop_map(move |v| v * scale),
    ]
}

fn wild_f32(scale: f32) -> impl Strategy<Value = f32> + Clone {
    prop_oneof![
        1 => any::<u32>().prop_map(f32::from_bits),
        2 => prop::sample::select(vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, 1.0e-45, -0.0, 0.0]),
        6 => (-1.0f32..1.0).prop_map(move |v| v * scale),
    ]
}

fn wild_obs() -> impl Strategy<Value = LandmarkObs> {
    (
        prop_oneof![1 => wild_f32(8.0), 8 => 0.0f32..8.0],
        prop_oneof![1 => wild_f32(4.0), 8 => -3.2f32..3.2],
        prop_oneof![4 => 0u32..10, 1 => any::<u32>()],
    )
        .prop_map(|(range_m, bearing_rad, signature)| LandmarkObs {
            range_m,
            bearing_rad,
            signature,
            _pad: 0,
        })
}

fn wild_sensor() -> impl Strategy<Value = SensorMsg> {
    (
        any::<u64>(),
        prop_oneof![12 => 0u32..4, 2 => 0u32..(MAX_OBSERVATIONS as u32 + 1), 1 => any::<u32>()],
        (wild_f64(1.0), wild_f64(2.0), wild_f64(1.0)),
        prop_oneof![3 => Just(0.1f64), 1 => wild_f64(1.0)],
        prop::collection::vec(wild_obs(), MAX_OBSERVATIONS),
    )
        .prop_map(
            |(step, count, (v_m_per_s, omega_rad_per_s, sim_time_s), dt_s, obs)| {
                let mut observations = [LandmarkObs::default(); MAX_OBSERVATIONS];
                observations.copy_from_slice(&obs);
                SensorMsg {
                    stamp_ns: 1,
                    step,
                    robot_id: 0,
                    count,
                    sim_time_s,
                    dt_s,
                    v_m_per_s,
                    omega_rad_per_s,
                    observations,
                }
            },
        )
}

fn landmarks() -> Vec<Landmark> {
    (0..8)
        .map(|i| Landmark {
            x_m: (i % 4) as f64 * 3.0,
            y_m: if i < 4 { 0.5 } else { 4.5 },
            signature: i + 1,
        })
        .collect()
}

/// Sensor messages of any content into the EKF and EKF-SLAM: the state stays finite, the
/// covariance symmetric with a non-negative diagonal, and every message is either used or
/// rejected (counted).
#[test]
fn localizers_survive_any_sensor_message() {
    let mut totals = std::cell::RefCell::new((0u64, 0u64));
    run(
        cases(256),
        &prop::collection::vec(wild_sensor(), 1..24),
        |msgs| {
            let start = WorldPose::new(1.0, 2.5, 0.3);
            let cov0 = Matrix3::from_diagonal(&nalgebra::Vector3::new(0.01, 0.01, 0.001));
            let mut ekf = Ekf::new(EkfConfig::default(), landmarks(), start, cov0).unwrap();
            let mut slam = EkfSlam::new(EkfSlamConfig::default(), start, cov0).unwrap();
            let mut rejected = 0u64;
            for m in &msgs {
                let a = ekf.step(m);
                let b = slam.step(m);
                prop_assert_eq!(a.is_ok(), b.is_ok(), "the two filters disagree on {:?}", m);
                if let Err(e) = a {
                    rejected += 1;
                    prop_assert!(!e.to_string().is_empty());
                }
                for p in [ekf.to_msg(0, m.step), slam.to_msg(0, m.step)] {
                    prop_assert!(
                        [p.x_m, p.y_m, p.theta_rad].iter().all(|v| v.is_finite())
                            && p.cov.iter().all(|v| v.is_finite()),
                        "non-finite estimate {:?} after {:?}",
                        p,
                        m
                    );
                    prop_assert!(
                        p.cov[0] >= 0.0 && p.cov[4] >= 0.0 && p.cov[8] >= 0.0,
                        "{:?}",
                        p
                    );
                }
            }
            prop_assert_eq!(ekf.counters().rejected_total(), rejected);
            prop_assert_eq!(slam.counters().rejected_total(), rejected);
            prop_assert_eq!(ekf.counters().predictions, msgs.len() as u64 - rejected);
            let mut t = totals.borrow_mut();
            t.0 += msgs.len() as u64;
            t.1 += rejected;
            Ok(())
        },
    );
    let (n, rejected) = *totals.get_mut();
    eprintln!("localizer fuzz: {n} sensor messages, {rejected} rejected");
    assert!(rejected > 0 && rejected < n, "{rejected} of {n} rejected");
}

fn wild_pose() -> impl Strategy<Value = PoseMsg> {
    (
        any::<u64>(),
        (wild_f64(6.0), wild_f64(3.0), wild_f64(4.0)),
        prop::array::uniform9(wild_f64(0.05)),
        0u8..4,
    )
        .prop_map(|(step, (x_m, y_m, theta_rad), mut cov, shape)| {
            match shape {
                // Mirror the upper triangle: symmetric, PSD or not.
                0 => {
                    cov[3] = cov[1];
                    cov[6] = cov[2];
                    cov[7] = cov[5];
                }
                // L·Lᵀ of the lower triangle: positive semi-definite whenever finite.
                1 | 2 => {
                    let l = Matrix3::new(
                        cov[0], 0.0, 0.0, cov[3], cov[4], 0.0, cov[6], cov[7], cov[8],
                    );
                    let c = l * l.transpose();
                    cov.copy_from_slice(c.as_slice());
                }
                // As drawn: anything.
                _ => {}
            }
            PoseMsg {
                stamp_ns: step.wrapping_mul(100_000_000),
                step,
                robot_id: 0,
                landmarks_used: 0,
                x_m: x_m + 6.0,
                y_m: y_m + 2.5,
                theta_rad,
                cov,
            }
        })
}

/// Pose messages of any content into the depositor (every mode): a deposit is produced only from
/// a valid pose, every field of it is finite, and the field accepts or rejects it — never a NaN
/// cell. Every rejected pose is counted under its reason.
#[test]
fn the_depositor_never_turns_a_bad_pose_into_a_bad_deposit() {
    let field_config = FieldConfig {
        width: 240,
        height: 100,
        cell_size_m: 0.05,
        tick_hz: 10.0,
        channels: vec![{
            let mut c = ChannelSpec::new("trail", Evaporation::Exponential { decay_per_s: 0.1 });
            c.signed = true;
            c
        }],
        ..FieldConfig::default()
    };
    let totals = std::cell::RefCell::new([0u64; 3]);
    run(
        cases(256),
        &(
            prop::sample::select(vec![
                DepositMode::UncertaintyAware,
                DepositMode::Saturating,
                DepositMode::Constant,
            ]),
            any::<bool>(),
            prop::collection::vec(wild_pose(), 1..32),
        ),
        |(mode, anti_pheromone, poses)| {
            let mut d = Depositor::new(DepositorConfig {
                mode,
                anti_pheromone,
                interval_m: 0.0,
                ..DepositorConfig::default()
            })
            .unwrap();
            let mut field = OwnedField::new(field_config.clone()).unwrap();
            let mut deposits = 0u64;
            for p in &poses {
                match d.process(p) {
                    Ok(Some(msg)) => {
                        deposits += 1;
                        prop_assert!(msg_is_finite(&msg), "{:?} from {:?}", msg, p);
                        let _ = field.offer(&msg);
                    }
                    Ok(None) => {}
                    Err(e) => prop_assert!(!e.to_string().is_empty()),
                }
            }
            field.tick();
            prop_assert_eq!(field.view().non_finite_cells(), 0);
            let c = d.counters();
            prop_assert_eq!(c.poses, poses.len() as u64);
            prop_assert_eq!(c.deposits, deposits);
            prop_assert_eq!(
                c.deposits + c.skipped_interval + c.rejected_total(),
                c.poses
            );
            let mut t = totals.borrow_mut();
            t[0] += c.poses;
            t[1] += c.deposits;
            t[2] += c.rejected_total();
            Ok(())
        },
    );
    let [poses, deposits, rejected] = totals.into_inner();
    eprintln!("depositor fuzz: {poses} poses, {deposits} deposits, {rejected} rejected");
    assert!(deposits > 0 && rejected > 0);
}

/// A frame with arbitrary cells (a reader must not trust them either) and any pose: every
/// strategy's command is finite or the step is refused with a reason.
#[test]
fn followers_never_command_a_non_finite_velocity() {
    let geometry = GridGeometry::new(24, 12, 0.4).unwrap();
    let n = geometry.cells();
    let totals = std::cell::RefCell::new([0u64; 2]);
    run(
        cases(256),
        &(
            prop::sample::select(StrategyKind::ALL.to_vec()),
            any::<u64>(),
            prop::collection::vec((wild_pose(), wild_f64(0.2)), 1..12),
        ),
        |(strategy, seed, steps)| {
            // Cells from the seed (SplitMix64): plausible levels, and for odd seeds some
            // poison (NaN, ±inf, f32::MAX) — a reader must not trust a frame blindly either.
            let mut state = seed;
            let cells: Vec<f32> = (0..n * 2)
                .map(|_| {
                    state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
                    let mut z = state;
                    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                    z ^= z >> 31;
                    match (seed % 2, z % 16) {
                        (1, 0) => [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX]
                            [(z >> 8) as usize % 4],
                        _ => (z >> 40) as f32 / (1u64 << 24) as f32 * 50.0,
                    }
                })
                .collect();
            let frame = FrameView::new(geometry, 2, &cells);
            let config = FollowerConfig {
                strategy,
                seed,
                channel: (seed % 3) as u32, // channel 2 does not exist
                ..FollowerConfig::default()
            };
            let mut follower = Follower::from_config(4, &config).unwrap();
            let mut t = totals.borrow_mut();
            for (pose, dt) in &steps {
                let dt = if seed % 3 == 1 { 0.1 } else { *dt };
                t[0] += 1;
                match follower.step_pose(&frame, pose, dt) {
                    Ok(out) => {
                        prop_assert!(
                            out.cmd.v_m_per_s.is_finite()
                                && out.cmd.omega_rad_per_s.is_finite()
                                && out.status.sensed_level.is_finite(),
                            "{:?} from {:?}",
                            out,
                            pose
                        );
                        prop_assert_eq!(out.cmd.step, pose.step);
                    }
                    Err(e) => {
                        t[1] += 1;
                        prop_assert!(!e.to_string().is_empty());
                    }
                }
            }
            Ok(())
        },
    );
    let [steps, refused] = totals.into_inner();
    eprintln!("follower fuzz: {steps} steps, {refused} refused");
    assert!(refused > 0 && refused < steps);
}

/// Any velocity command into the world: poses stay finite, non-finite commands are counted.
#[test]
fn the_world_survives_any_command() {
    let config = WorldConfig {
        robots: (0..3)
            .map(|id| RobotConfig {
                id,
                start: WorldPose::new(1.0 + id as f64, 2.5, 0.0),
                noise: None,
            })
            .collect(),
        landmarks: landmarks(),
        walls: vec![pheromone_world::WallConfig::Rect {
            min_x_m: 0.0,
            min_y_m: 4.9,
            max_x_m: 12.0,
            max_y_m: 5.0,
        }],
        ..WorldConfig::default()
    };
    run(
        cases(256),
        &prop::collection::vec(
            prop::collection::vec((wild_f64(3.0), wild_f64(5.0)), 0..4),
            1..40,
        ),
        |steps| {
            let mut world = World::new(config.clone(), 3).unwrap();
            let mut non_finite = 0u64;
            for cmds in &steps {
                non_finite += cmds
                    .iter()
                    .take(3)
                    .filter(|(v, w)| !(v.is_finite() && w.is_finite()))
                    .count() as u64;
                for out in world.step(cmds) {
                    let s = &out.sensor;
                    prop_assert!(s.v_m_per_s.is_finite() && s.omega_rad_per_s.is_finite());
                    prop_assert!(s
                        .observations()
                        .iter()
                        .all(|o| o.range_m.is_finite() && o.bearing_rad.is_finite()));
                }
                for p in world.poses() {
                    prop_assert!(
                        p.x_m.is_finite() && p.y_m.is_finite() && p.theta_rad.is_finite(),
                        "{:?}",
                        p
                    );
                }
            }
            prop_assert_eq!(world.rejected_commands(), non_finite);
            Ok(())
        },
    );
}

/// Mutated and truncated scenario files: either a valid scenario or an error that names the
/// origin (file) and, for syntax errors, the line.
#[test]
fn mutated_scenarios_are_refused_with_file_and_reason() {
    let text = pheromone_world::scenario::BUILTIN[0].1;
    let lines: Vec<String> = text.lines().map(str::to_string).collect();
    let stats = std::cell::RefCell::new([0u64; 2]);
    run(cases(256), &toml_fuzz::mutations(lines.len()), |muts| {
        let text = toml_fuzz::apply(&lines, &muts);
        let mut s = stats.borrow_mut();
        match Scenario::parse(&text, "fuzzed.toml") {
            Ok(_) => s[0] += 1,
            Err(e) => {
                s[1] += 1;
                let e = e.to_string();
                prop_assert!(
                    e.starts_with("fuzzed.toml: "),
                    "error does not name the file: {}",
                    e
                );
                prop_assert!(
                    e.len() > "fuzzed.toml: ".len() + 5,
                    "error without a reason: {}",
                    e
                );
            }
        }
        Ok(())
    });
    let [ok, refused] = stats.into_inner();
    eprintln!("scenario fuzz: {ok} accepted, {refused} refused");
    assert!(ok > 0 && refused > 0);
}

fn pgm_header(magic: &str, w: u64, h: u64, max: u64) -> Vec<u8> {
    format!("{magic}\n# fuzz\n{w} {h}\n{max}\n").into_bytes()
}

/// Map files: random bytes, truncated images, headers that claim huge sizes, wild YAML values.
#[test]
fn broken_maps_are_refused_never_a_panic() {
    let yaml = "image: map.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n";
    // A valid 4×3 map first: the loader works at all.
    let mut good = pgm_header("P5", 4, 3, 255);
    good.extend([0u8, 255, 255, 0, 255, 0, 0, 255, 255, 255, 255, 0]);
    let map = OccupancyMap::from_parts(yaml, &good).unwrap();
    assert_eq!((map.width, map.height), (4, 3));
    // Headers that claim enormous images with only a few bytes behind them: refused, without
    // trying to allocate what the header claims.
    for (magic, w, h) in [
        ("P5", 1u64 << 40, 1u64),
        ("P2", 1u64 << 40, 1),
        ("P5", 1 << 31, 1 << 31),
        ("P5", u64::MAX, 1),
        ("P5", 1, u64::MAX),
        ("P5", 1 << 63, 1),
    ] {
        let mut img = pgm_header(magic, w, h, if w == 1 << 63 { 65535 } else { 255 });
        img.extend([0u8; 16]);
        let e = OccupancyMap::from_parts(yaml, &img)
            .unwrap_err()
            .to_string();
        assert!(e.contains("pgm image"), "{magic} {w}×{h}: {e}");
    }
    let stats = std::cell::RefCell::new([0u64; 2]);
    let image = prop_oneof![
        // Pure noise.
        prop::collection::vec(any::<u8>(), 0..64),
        // A header claiming any size (up to absurd), then some pixels.
        (
            prop::sample::select(vec!["P5", "P2", "P6", "P5P5", ""]),
            prop_oneof![
                1u64..40,
                Just(0u64),
                Just(u32::MAX as u64),
                Just(1u64 << 40),
                Just(u64::MAX)
            ],
            prop_oneof![1u64..40, Just(0u64), Just(1u64 << 31), Just(u64::MAX)],
            prop_oneof![
                Just(255u64),
                Just(65535u64),
                Just(0u64),
                Just(65536u64),
                1u64..300
            ],
            prop::collection::vec(any::<u8>(), 0..200),
        )
            .prop_map(|(magic, w, h, max, tail)| {
                let mut v = pgm_header(magic, w, h, max);
                v.extend(tail);
                v
            }),
        // The good image truncated, or whole.
        (0..good.len() + 4).prop_map(move |n| good[..n.min(good.len())].to_vec()),
    ];
    let yaml_text = prop_oneof![
        3 => Just(yaml.to_string()),
        2 => (0..yaml.len()).prop_map(move |n| yaml[..n].to_string()),
        2 => (
            prop::sample::select(vec!["resolution", "origin", "negate", "occupied_thresh", "mode", "image", "free_thresh", "bogus"]),
            prop::sample::select(vec!["nan", "inf", "-1", "0", "1e400", "[1, 2]", "[nan, 0, 0]", "[0, 0, 1]", "x", "", "trinary", "raw"]),
        )
            .prop_map(move |(k, v)| format!("{yaml}{k}: {v}\n")),
        1 => "[ -~\n]{0,80}",
    ];
    run(cases(256) * 2, &(yaml_text, image), |(yaml_text, image)| {
        let mut s = stats.borrow_mut();
        match OccupancyMap::from_parts(&yaml_text, &image) {
            Ok(m) => {
                s[0] += 1;
                prop_assert_eq!(m.occupied.len(), m.width * m.height);
                prop_assert!(m.resolution_m.is_finite() && m.resolution_m > 0.0);
            }
            Err(e) => {
                s[1] += 1;
                let e = e.to_string();
                prop_assert!(e.contains("map yaml") || e.contains("pgm image"), "{}", e);
            }
        }
        Ok(())
    });
    let [ok, refused] = stats.into_inner();
    eprintln!("map fuzz: {ok} accepted, {refused} refused");
    assert!(ok > 0 && refused > 0);
}

/// The end-to-end chain of bad input: a depositor fed garbage poses never gets a deposit with a
/// non-finite value past the field's checks (the field is the last line of defence).
#[test]
fn deposits_from_any_pose_keep_the_field_finite_over_many_ticks() {
    let mut field = OwnedField::new(FieldConfig {
        width: 64,
        height: 64,
        cell_size_m: 0.2,
        ..FieldConfig::default()
    })
    .unwrap();
    let mut d = Depositor::new(DepositorConfig {
        interval_m: 0.0,
        ..DepositorConfig::default()
    })
    .unwrap();
    let mut runner = TestRunner::new(Config {
        failure_persistence: None,
        ..Config::default()
    });
    let poses = prop::collection::vec(wild_pose(), 2000)
        .new_tree(&mut runner)
        .unwrap()
        .current();
    let mut offered = 0u64;
    for chunk in poses.chunks(50) {
        for p in chunk {
            if let Ok(Some(msg)) = d.process(p) {
                let m: DepositMsg = msg;
                offered += 1;
                let _ = field.offer(&m);
            }
        }
        field.tick();
        assert_eq!(field.view().non_finite_cells(), 0);
    }
    let c = field.stepper.counters;
    assert_eq!(c.applied + c.rejected_total(), offered);
    assert!(c.applied > 0);
}
