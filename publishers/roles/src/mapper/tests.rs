use pheromone_field::{ChannelSpec, Evaporation, FrameHeader};

use super::*;
use pheromone_messages::{PeerObs, PoseMsg, ScanMsg};

/// The rule most tests here check geometry with: a cell unknown in the destination takes the
/// source's values, so a merge into an empty map reproduces the source.
fn config(extent_m: f32) -> MappingConfig {
    MappingConfig {
        enabled: true,
        cell_size_m: 0.2,
        extent_m,
        merge_rule: MergeRule::AdoptUnknown,
        ..MappingConfig::default()
    }
}

/// A map that merges by seed 004's rule (`average`).
fn averaging(extent_m: f32) -> LocalMap {
    let c = MappingConfig {
        merge_rule: MergeRule::Average,
        ..config(extent_m)
    };
    LocalMap::new(&c, &channel(), 0.1).unwrap()
}

fn channel() -> ChannelSpec {
    ChannelSpec::new("visited", Evaporation::Saturating { rho_per_tick: 0.01 })
}

fn empty(extent_m: f32) -> LocalMap {
    LocalMap::new(&config(extent_m), &channel(), 0.1).unwrap()
}

/// A map with a pattern of known cells (free, occupied, pheromone) and unknown ones.
fn patterned(extent_m: f32, salt: u32) -> LocalMap {
    let mut m = empty(extent_m);
    for (i, (o, p)) in m.occupancy.iter_mut().zip(&mut m.pheromone).enumerate() {
        let h = (i as u32).wrapping_mul(2_654_435_761).wrapping_add(salt) >> 24;
        if !h.is_multiple_of(3) {
            *o = (h as f32 - 128.0) / 40.0 + 0.01;
            *p = (h % 7) as f32 / 7.0;
        }
    }
    m
}

#[test]
fn merging_into_an_empty_map_reproduces_it_for_an_exact_transform() {
    let src = patterned(8.0, 1);
    let mut dst = empty(8.0);
    let s = dst.merge(&src.view(), &MergeTransform::default()).unwrap();
    assert_eq!(dst.occupancy, src.occupancy);
    assert_eq!(dst.pheromone, src.pheromone);
    assert_eq!(s.averaged, 0);
    assert_eq!(s.adopted, src.mapped_cells(f32::MIN_POSITIVE));

    // A quarter turn and a translation of whole cells: every cell lands on a cell centre.
    let t = MergeTransform {
        theta_ij_rad: std::f64::consts::FRAC_PI_2,
        d_ij_m: 0.6,
        alpha_ji_rad: 0.0,
        ..MergeTransform::default()
    };
    let mut dst = empty(8.0);
    dst.merge(&src.view(), &t).unwrap();
    let g = *src.geometry();
    let mut checked = 0;
    for y in 0..g.height {
        for x in 0..g.width {
            let (px, py) = g.world_from_grid(x, y);
            let q = t.apply([px as f64, py as f64]);
            if let Some(j) = dst.cell_index(q[0], q[1]) {
                let i = g.index(x, y);
                assert_eq!(dst.occupancy[j], src.occupancy[i], "cell ({x}, {y})");
                assert_eq!(dst.pheromone[j], src.pheromone[i], "cell ({x}, {y})");
                checked += 1;
            }
        }
    }
    assert!(checked > (g.cells() * 8) / 10, "{checked}");
}

#[test]
fn merging_is_symmetric_in_the_averaging_sense() {
    let (a, b) = (patterned(6.0, 1), patterned(6.0, 77));
    let (mut ab, mut ba) = (a.clone(), b.clone());
    let sa = ab.merge(&b.view(), &MergeTransform::default()).unwrap();
    let sb = ba.merge(&a.view(), &MergeTransform::default()).unwrap();
    assert_eq!(ab.occupancy, ba.occupancy);
    assert_eq!(ab.pheromone, ba.pheromone);
    assert!(sa.averaged > 0 && sa.averaged == sb.averaged);
    // Where both knew the cell, the merge is the mean of both.
    let i = (0..a.occupancy.len())
        .find(|&i| a.occupancy[i] != 0.0 && b.occupancy[i] != 0.0)
        .unwrap();
    assert_eq!(ab.occupancy[i], 0.5 * (a.occupancy[i] + b.occupancy[i]));
}

/// Occupied cells of a map whose frame has origin `origin` in the world, for the walls of an
/// L-shaped room (segments within half a cell of a cell centre).
fn walls_map(origin: Pose2) -> LocalMap {
    let walls = [
        ([-1.0, -1.0], [4.0, -1.0]),
        ([4.0, -1.0], [4.0, 0.5]),
        ([-1.0, -1.0], [-1.0, 3.0]),
        ([-1.0, 3.0], [1.5, 3.0]),
    ];
    let mut m = empty(16.0);
    let g = *m.geometry();
    for y in 0..g.height {
        for x in 0..g.width {
            let (px, py) = g.world_from_grid(x, y);
            let w = map::point_from_frame(origin, [px as f64, py as f64]);
            let near = walls.iter().any(|(a, b): &([f64; 2], [f64; 2])| {
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let t = (((w[0] - a[0]) * dx + (w[1] - a[1]) * dy) / (dx * dx + dy * dy))
                    .clamp(0.0, 1.0);
                (w[0] - a[0] - t * dx).hypot(w[1] - a[1] - t * dy) <= 0.1
            });
            m.occupancy[g.index(x, y)] = if near { 2.0 } else { -1.0 };
        }
    }
    m
}

#[test]
fn a_known_rotation_and_translation_is_recovered_within_one_cell() {
    let sa = [0.5, 0.2, 0.3];
    let sb = [2.7, 1.1, 2.1];
    let (a, b) = (walls_map(sa), walls_map(sb));
    let mut merged = empty(16.0);
    merged
        .merge(&b.view(), &MergeTransform::between_frames(sb, sa))
        .unwrap();
    let g = *a.geometry();
    let occupied = |m: &LocalMap, x: i64, y: i64| {
        (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                let (u, v) = (x + dx, y + dy);
                u >= 0
                    && v >= 0
                    && (u as u32) < g.width
                    && (v as u32) < g.height
                    && m.occupancy[g.index(u as u32, v as u32)] > 0.0
            })
        })
    };
    let mut walls = 0;
    for y in 0..g.height {
        for x in 0..g.width {
            let i = g.index(x, y);
            if merged.occupancy[i] > 0.0 {
                walls += 1;
                assert!(
                    occupied(&a, x as i64, y as i64),
                    "merged wall at ({x}, {y})"
                );
            }
            if a.occupancy[i] > 0.0 && merged.occupancy[i] != 0.0 {
                assert!(
                    occupied(&merged, x as i64, y as i64),
                    "lost wall at ({x}, {y})"
                );
            }
        }
    }
    assert!(walls > 50, "{walls}");
    // The same transform from a rendezvous measured exactly, with the robots anywhere.
    let (ri, rj) = ([1.0, 2.0, 0.7], [3.0, 1.5, -0.4]);
    let (ei, ej) = (pose_in_frame(sb, ri), pose_in_frame(sa, rj));
    let obs = PeerObs {
        robot_id: 1,
        range_m: (ri[0] - rj[0]).hypot(ri[1] - rj[1]),
        bearing_rad: (ri[1] - rj[1]).atan2(ri[0] - rj[0]) - rj[2],
        heading_rad: ri[2] - rj[2],
        ..PeerObs::default()
    };
    let measured = MergeTransform::from_measurement(ej, ei, &obs);
    for p in [[0.0, 0.0], [5.0, -3.0], [-7.0, 6.0]] {
        let d = measured.displacement_m(&MergeTransform::between_frames(sb, sa), p);
        assert!(d < 1e-9, "{p:?}: {d}");
    }
}

/// `true` when a cell within one cell (3 × 3) of (x, y) is occupied in `m`.
fn wall_near(m: &LocalMap, x: i64, y: i64) -> bool {
    let g = *m.geometry();
    (-1..=1).any(|dy| {
        (-1..=1).any(|dx| {
            let (u, v) = (x + dx, y + dy);
            u >= 0
                && v >= 0
                && (u as u32) < g.width
                && (v as u32) < g.height
                && m.occupancy[g.index(u as u32, v as u32)] > 0.0
        })
    })
}

// A test reads as one scenario, top to bottom (the line limit is for non-test code).
#[allow(clippy::too_many_lines)]
#[test]
fn a_known_rotation_and_translation_is_recovered_within_one_cell_under_the_worlds_noise() {
    use pheromone_world::{NoiseConfig, RobotConfig, World, WorldConfig, WorldPose};
    // Robot j (id 0, the destination) and robot i (id 1) stand still at their start poses, the
    // origins of their frames, so their estimates are exact ([0, 0, 0]): only the rendezvous
    // measurement is noisy, drawn by the world at the mapping's configured noise.
    let (sa, sb) = ([0.5, 0.2, 0.3], [2.7, 1.1, 2.1]);
    let mapping = MappingConfig {
        enabled: true,
        ..MappingConfig::default()
    };
    let (sd_range, sd_bearing, sd_heading) = (
        mapping.relpose_range_sigma_m,
        mapping.relpose_bearing_sigma_rad,
        mapping.relpose_heading_sigma_rad,
    );
    assert!(sd_range > 0.0 && sd_bearing > 0.0 && sd_heading > 0.0);
    let robot = |id, s: Pose2| RobotConfig {
        id,
        start: WorldPose::new(s[0], s[1], s[2]),
        noise: None,
    };
    let mut world = World::new(
        WorldConfig {
            robots: vec![robot(0, sa), robot(1, sb)],
            noise: NoiseConfig::zero(),
            ..WorldConfig::default()
        },
        7,
    )
    .unwrap();
    world.enable_mapping(
        pheromone_world::ScanSensorConfig {
            rays: mapping.rays,
            range_max_m: mapping.range_max_m,
            range_sigma_m: mapping.range_sigma_m,
            rc_m: mapping.rc_m,
            relpose_range_sigma_m: mapping.relpose_range_sigma_m,
            relpose_bearing_sigma_rad: mapping.relpose_bearing_sigma_rad,
            relpose_heading_sigma_rad: mapping.relpose_heading_sigma_rad,
        },
        7,
    );
    let truth = MergeTransform::between_frames(sb, sa);
    let d = (sb[0] - sa[0]).hypot(sb[1] - sa[1]);
    let (b, a) = (walls_map(sb), walls_map(sa));
    let g = *b.geometry();
    // Robot i's walls, as points of its frame, with their distance from robot i.
    let walls: Vec<[f64; 2]> = (0..g.height)
        .flat_map(|y| (0..g.width).map(move |x| (x, y)))
        .filter(|&(x, y)| b.occupancy[g.index(x, y)] > 0.0)
        .map(|(x, y)| {
            let (px, py) = g.world_from_grid(x, y);
            [px as f64, py as f64]
        })
        .collect();
    let reach_m = walls.iter().map(|p| p[0].hypot(p[1])).fold(0.0, f64::max);
    let draws = 300;
    let (mut sq_origin, mut sq_walls, mut clean_draws) = (0.0, vec![0.0; walls.len()], 0);
    let (mut merged_walls, mut placed) = (0usize, 0usize);
    for _ in 0..draws {
        world.step(&[]);
        let out = world.mapping_outputs();
        let obs = out[0].1.peers()[0];
        assert_eq!(obs.robot_id, 1);
        let measured = MergeTransform::from_measurement([0.0; 3], [0.0; 3], &obs);
        // The noise of this draw, and how far it can move a point at distance r from robot i:
        // |δd| + d·|δα| + r·|δθ| (eqs. 7–10 are a rotation about robot i and a translation).
        let (dd, da, dt) = (
            (measured.d_ij_m - truth.d_ij_m).abs(),
            pheromone_world::wrap_angle(measured.alpha_ji_rad - truth.alpha_ji_rad).abs(),
            pheromone_world::wrap_angle(measured.theta_ij_rad - truth.theta_ij_rad).abs(),
        );
        assert!(dd + da + dt > 0.0, "the measurement is noisy");
        let e0 = measured.displacement_m(&truth, [0.0, 0.0]);
        assert!(e0 <= dd + d * da + 1e-9, "{e0} {dd} {da}");
        sq_origin += e0 * e0;
        for (p, sq) in walls.iter().zip(&mut sq_walls) {
            let e = measured.displacement_m(&truth, *p);
            assert!(
                e <= dd + d * da + p[0].hypot(p[1]) * dt + 1e-9,
                "{p:?}: {e}"
            );
            *sq += e * e;
        }
        // The merged map: every wall it places lies within one cell of robot j's own walls.
        let mut merged = empty(16.0);
        merged.merge(&b.view(), &measured).unwrap();
        let (mut here, mut off) = (0usize, 0usize);
        for y in 0..g.height {
            for x in 0..g.width {
                if merged.occupancy[g.index(x, y)] > 0.0 {
                    here += 1;
                    off += usize::from(!wall_near(&a, x as i64, y as i64));
                }
            }
        }
        assert!(here > 50, "{here}");
        merged_walls += here;
        placed += here - off;
        clean_draws += usize::from(off == 0);
    }
    let n = draws as f64;
    // The root mean square error the noise predicts at distance r from robot i:
    // √(σ_d² + (d·σ_α)² + (r·σ_θ)²) (σ_α: the bearing's, and robot j's estimate is exact).
    let predicted =
        |r: f64| (sd_range.powi(2) + (d * sd_bearing).powi(2) + (r * sd_heading).powi(2)).sqrt();
    let cell = g.cell_size_m as f64;
    let rms_origin = (sq_origin / n).sqrt();
    let rms_walls = sq_walls.iter().map(|s| (s / n).sqrt()).fold(0.0, f64::max);
    eprintln!(
        "d = {d:.2} m, walls within {reach_m:.2} m of robot i; rms error at robot i {rms_origin:.3} m \
         (predicted {:.3}), worst wall point {rms_walls:.3} m (predicted {:.3}); \
         {placed} / {merged_walls} merged wall cells within one cell, {clean_draws} / {draws} draws all",
        predicted(0.0),
        predicted(reach_m)
    );
    assert!(
        (rms_origin / predicted(0.0) - 1.0).abs() < 0.2,
        "{rms_origin}"
    );
    assert!(rms_walls < 1.2 * predicted(reach_m), "{rms_walls}");
    // Within one cell: the alignment error (robot i's position, the metric runs report) is
    // under half a cell, every wall point's under one cell, in root mean square.
    assert!(
        rms_origin < 0.5 * cell && rms_walls < cell,
        "{rms_origin} {rms_walls}"
    );
    assert!(
        placed as f64 >= 0.99 * merged_walls as f64,
        "{placed} / {merged_walls}"
    );
    assert!(clean_draws as f64 >= 0.9 * n, "{clean_draws} / {draws}");
}

#[test]
fn bad_maps_and_transforms_are_rejected_counted_and_never_merged() {
    let src = patterned(6.0, 3);
    let mut cells = vec![0.0; 2 * src.geometry().cells()];
    src.write_frame(&mut cells);
    let g = src.geometry();
    let header = FrameHeader {
        channels: 2,
        width: g.width,
        height: g.height,
        cell_size_m: g.cell_size_m,
        origin_x_m: g.origin_x_m,
        origin_y_m: g.origin_y_m,
        ..FrameHeader::default()
    };
    assert!(MapView::from_frame(&header, &cells).is_ok());

    // A mapper with a map of its own: a merge would average into it.
    let mut m = Mapper::new(0, &config(6.0), [0.0; 3], &channel(), 0.1, None).unwrap();
    m.on_step(1, &PoseMsg::default(), &ScanMsg::default());
    m.map = patterned(6.0, 9);
    let before = m.map.clone();
    let obs = PeerObs {
        robot_id: 1,
        range_m: 1.0,
        ..PeerObs::default()
    };
    // A frame whose header disagrees with its length, through the mapper process's path.
    let e = m
        .accept_frame(1, &header, &cells[1..], [0.0; 3], &obs)
        .unwrap_err();
    assert!(matches!(e, MapError::Length { .. }), "{e}");
    assert!(
        e.to_string().contains(&(cells.len() - 1).to_string()),
        "{e}"
    );
    let three = FrameHeader {
        channels: 3,
        ..header
    };
    let e = m
        .accept_frame(1, &three, &cells, [0.0; 3], &obs)
        .unwrap_err();
    assert!(e.to_string().contains("3 channels"), "{e}");
    // A view whose planes disagree with its geometry, through `accept`.
    let short = MapView {
        occupancy: &cells[..g.cells() - 1],
        ..MapView::from_frame(&header, &cells).unwrap()
    };
    let e = m.accept(1, &short, [0.0; 3], &obs).unwrap_err();
    assert!(matches!(e, MapError::Length { .. }), "{e}");
    assert_eq!(m.counters.merges_rejected["length"], 3);
    assert_eq!(m.counters.merges, 0);
    assert_eq!(m.map.occupancy, before.occupancy);
    assert_eq!(m.map.pheromone, before.pheromone);

    cells[17] = f32::NAN;
    let e = m
        .accept_frame(1, &header, &cells, [0.0; 3], &obs)
        .unwrap_err();
    assert!(e.to_string().contains("cell 17 is NaN"), "{e}");
    cells[17] = 0.5;
    let view = MapView::from_frame(&header, &cells).unwrap();
    for (bad, name) in [(f64::NAN, "d_ij_m = NaN"), (1e6, "d_ij_m = 1000000")] {
        let obs = PeerObs {
            range_m: bad,
            ..obs
        };
        let e = m.accept(1, &view, [0.0; 3], &obs).unwrap_err();
        assert!(e.to_string().contains(name), "{e}");
    }
    assert_eq!(m.map.occupancy, before.occupancy);
    assert_eq!(m.map.pheromone, before.pheromone);
    assert_eq!(m.counters.merges, 0);
    assert_eq!(m.counters.merges_rejected["non_finite_cell"], 1);
    assert_eq!(m.counters.merges_rejected["transform"], 2);
    assert_eq!(m.counters.merges_rejected["length"], 3);
    m.accept_frame(1, &header, &cells, [0.0; 3], &obs).unwrap();
    assert_eq!(m.counters.merges, 1);
    assert_ne!(m.map.occupancy, before.occupancy, "a valid frame is merged");
}

#[test]
fn a_scan_frees_the_cells_along_each_ray_and_marks_the_hit() {
    let mut m = empty(8.0);
    let mut scan = ScanMsg {
        count: 2,
        angle_min_rad: 0.0,
        angle_step_rad: std::f32::consts::FRAC_PI_2,
        range_max_m: 3.0,
        hits: 0b01,
        ..ScanMsg::default()
    };
    scan.ranges_m[0] = 2.0; // a wall 2 m ahead
    scan.ranges_m[1] = 3.0; // nothing within 3 m to the left
                            // The robot at (1, 0) of its frame, heading +y: ray 0 goes +y, ray 1 goes −x.
    let pose = [1.0, 0.0, std::f64::consts::FRAC_PI_2];
    m.integrate_scan(pose, &scan).unwrap();
    let at = |x: f64, y: f64| m.occupancy[m.cell_index(x, y).unwrap()];
    assert!(at(1.0, 2.05) > 0.0, "hit");
    assert!(
        at(1.0, 1.0) < 0.0 && at(1.0, 0.3) < 0.0,
        "free before the hit"
    );
    assert_eq!(at(1.0, 2.5), 0.0, "unknown beyond the hit");
    assert!(at(-1.5, 0.05) < 0.0, "free along the ray that hit nothing");
    assert_eq!(at(-2.5, 0.05), 0.0, "unknown beyond the range");
    let mut bad = scan;
    bad.ranges_m[1] = f32::NAN;
    let before = m.occupancy.clone();
    assert!(matches!(
        m.integrate_scan(pose, &bad),
        Err(MapError::BadRay { ray: 1, .. })
    ));
    assert!(m.integrate_scan([f64::NAN, 0.0, 0.0], &scan).is_err());
    assert_eq!(m.occupancy, before);
    assert_eq!(m.scans_rejected, 2);
}

#[test]
fn a_robot_whose_localization_is_lost_is_known_as_lost() {
    let mut m = Mapper::new(0, &config(6.0), [0.0; 3], &channel(), 0.1, None).unwrap();
    assert!(m.lost(), "no estimate yet");
    let mut p = PoseMsg::default();
    p.cov[0] = 0.01;
    p.cov[4] = 0.01;
    m.on_step(1, &p, &ScanMsg::default());
    assert!(!m.lost(), "det = 1e-4 m⁴");
    p.cov[0] = 1.0;
    p.cov[4] = 1.0;
    m.on_step(2, &p, &ScanMsg::default());
    assert!(m.lost(), "det = 1 m⁴");
}

#[test]
fn exchanges_start_after_the_start_iteration_and_repeat_every_interval() {
    let c = config(6.0);
    let mut m = Mapper::new(0, &c, [0.0; 3], &channel(), 0.1, None).unwrap();
    assert!(!m.due(1, 1000), "iteration 100 is not after 100");
    assert!(!m.due(1, 1015), "not an iteration boundary");
    assert!(m.due(1, 1010));
    m.last_exchange.insert(1, 101);
    assert!(!m.due(1, 1500) && m.due(1, 1510) && m.due(2, 1010));
}

#[test]
fn seed_004_averaging_is_symmetric_in_the_averaged_cells_and_never_makes_nan() {
    // Two maps with known, unknown and marked cells, extreme log-odds (±1e30, clamped) included.
    let fill = |salt: u32| {
        let mut m = averaging(6.0);
        let p = patterned(6.0, salt);
        m.occupancy.copy_from_slice(&p.occupancy);
        m.pheromone.copy_from_slice(&p.pheromone);
        m.occupancy[5] = 1e30;
        m.occupancy[6] = -1e30;
        m
    };
    // (A salt in the high bits: another pattern of unknown cells.)
    let (a, b) = (fill(1), fill(0x5000_0000));
    let (mut ab, mut ba) = (a.clone(), b.clone());
    let sa = ab.merge(&b.view(), &MergeTransform::default()).unwrap();
    let sb = ba.merge(&a.view(), &MergeTransform::default()).unwrap();
    assert_eq!((sa.adopted, sb.adopted), (0, 0), "average adopts nothing");
    assert!(
        sa.averaged > 0 && sa.averaged == sb.averaged,
        "{sa:?} {sb:?}"
    );
    // Symmetric: A merging B and B merging A leave the same cells, bit for bit.
    assert_eq!(ab.occupancy, ba.occupancy);
    assert_eq!(ab.pheromone, ba.pheromone);
    assert!(ab
        .occupancy
        .iter()
        .chain(&ab.pheromone)
        .all(|v| v.is_finite()));
    assert!(ab.occupancy.iter().all(|v| v.abs() <= 4.0));
    let sigma = |l: f32| 1.0 / (1.0 + (-l.clamp(-4.0, 4.0)).exp());
    let mut unknown_in_one = 0;
    for i in 0..a.occupancy.len() {
        let (x, y) = (a.occupancy[i], b.occupancy[i]);
        // Probabilities averaged (an unknown cell counts as p = 0.5), pheromone averaged.
        let want = 0.5 * (sigma(x) + sigma(y));
        assert!(
            (sigma(ab.occupancy[i]) - want).abs() < 1e-5,
            "cell {i}: {x} {y}"
        );
        assert_eq!(ab.pheromone[i], 0.5 * (a.pheromone[i] + b.pheromone[i]));
        if (x == 0.0) != (y == 0.0) {
            unknown_in_one += 1;
            // Unlike `adopt-unknown`, a cell one map does not know moves halfway to p = 0.5.
            let known = if x == 0.0 { y } else { x };
            assert!(ab.occupancy[i].abs() < known.abs().min(4.0), "cell {i}");
            assert_eq!(ab.occupancy[i].signum(), known.signum(), "cell {i}");
        }
    }
    assert!(unknown_in_one > 100, "{unknown_in_one}");
    // Two unknown cells stay exactly unknown.
    let (mut e, f) = (averaging(6.0), averaging(6.0));
    e.merge(&f.view(), &MergeTransform::default()).unwrap();
    assert!(e.occupancy.iter().all(|v| *v == 0.0));
}

#[test]
fn an_averaging_merge_with_a_bad_transform_is_refused_counted_and_changes_nothing() {
    let c = MappingConfig {
        merge_rule: MergeRule::Average,
        ..config(6.0)
    };
    let mut m = Mapper::new(0, &c, [0.0; 3], &channel(), 0.1, None).unwrap();
    m.on_step(1, &PoseMsg::default(), &ScanMsg::default());
    let src = patterned(6.0, 5);
    let before = m.map.clone();
    for (range_m, bearing_rad) in [(f64::INFINITY, 0.0), (1.0, f64::NAN), (1e9, 0.0)] {
        let obs = PeerObs {
            robot_id: 1,
            range_m,
            bearing_rad,
            ..PeerObs::default()
        };
        let e = m.accept(1, &src.view(), [0.0; 3], &obs).unwrap_err();
        assert!(matches!(e, MapError::Transform { .. }), "{e}");
    }
    assert_eq!(m.counters.merges_rejected["transform"], 3);
    assert_eq!(m.counters.merges, 0);
    assert_eq!(m.map.occupancy, before.occupancy);
    assert_eq!(m.map.pheromone, before.pheromone);
}

#[test]
fn merging_by_max_is_symmetric_keeps_what_either_knows_and_lets_obstacles_win() {
    let by_max = |salt: u32| {
        let c = MappingConfig {
            merge_rule: MergeRule::Max,
            ..config(6.0)
        };
        let mut m = LocalMap::new(&c, &channel(), 0.1).unwrap();
        let p = patterned(6.0, salt);
        m.occupancy.copy_from_slice(&p.occupancy);
        m.pheromone.copy_from_slice(&p.pheromone);
        m
    };
    let (a, b) = (by_max(1), by_max(0x5000_0000));
    let (mut ab, mut ba) = (a.clone(), b.clone());
    let sa = ab.merge(&b.view(), &MergeTransform::default()).unwrap();
    ba.merge(&a.view(), &MergeTransform::default()).unwrap();
    assert!(sa.adopted > 100 && sa.averaged > 100, "{sa:?}");
    assert_eq!(ab.occupancy, ba.occupancy);
    assert_eq!(ab.pheromone, ba.pheromone);
    for i in 0..a.occupancy.len() {
        let (x, y) = (a.occupancy[i], b.occupancy[i]);
        let want = match (x == 0.0, y == 0.0) {
            (true, _) => y,
            (_, true) => x,
            _ => x.max(y),
        };
        assert_eq!(ab.occupancy[i], want, "cell {i}: {x} {y}");
        assert_eq!(ab.pheromone[i], a.pheromone[i].max(b.pheromone[i]));
        assert!(ab.occupancy[i].is_finite());
    }
    assert_eq!("max".parse::<MergeRule>(), Ok(MergeRule::Max));
    assert!("mean".parse::<MergeRule>().is_err());
}
