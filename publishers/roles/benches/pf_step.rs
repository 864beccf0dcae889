//! Criterion benchmark of one particle-filter step (seed 000's leader with the laser of
//! Table 1): prediction, likelihood-field weights of every beam (`beam_stride = 1`, 129 beams)
//! for 500 particles, resampling and the weighted covariance, against the 10 Hz budget of
//! 100 ms a step.
//!
//! The world is a 20 m × 4 m corridor with an alcove every 4 m; the robot drives along it at
//! 0.6 m/s. Each sample starts from the same filter and the same sensor message and scan
//! (cloned outside the timing).
//!
//! `cargo bench -p pheromone-roles --bench pf_step`.

use std::hint::black_box;

use criterion::{BatchSize, Criterion};
use nalgebra::{Matrix3, Vector3};
use pheromone_roles::localizer::{EkfConfig, ParticleFilter, PfConfig};
use pheromone_world::{
    wall_segments, LaserConfig, RobotConfig, WallConfig, World, WorldConfig, WorldPose,
};

const PARTICLES: usize = 500;

fn world() -> WorldConfig {
    let mut walls = vec![WallConfig::Polyline {
        points_m: vec![[0.0, 0.0], [0.0, 4.0], [20.0, 4.0], [20.0, 0.0]],
        closed: false,
    }];
    for i in 0..5 {
        let x = 4.0 * f64::from(i);
        walls.push(WallConfig::Polyline {
            points_m: vec![
                [x, 0.0],
                [x + 3.0, 0.0],
                [x + 3.0, -1.0],
                [x + 4.0, -1.0],
                [x + 4.0, 0.0],
            ],
            closed: false,
        });
    }
    WorldConfig {
        robots: vec![RobotConfig {
            id: 1,
            start: WorldPose::new(6.0, 2.0, 0.0),
            noise: None,
        }],
        walls,
        laser: Some(LaserConfig::default()),
        ..WorldConfig::default()
    }
}

fn bench(c: &mut Criterion) {
    let cfg = world();
    let walls = wall_segments(&cfg.walls).unwrap();
    let start = cfg.robots[0].start;
    let mut w = World::new(cfg, 1).unwrap();
    let out = w.step(&[(0.6, 0.0)]);
    let laser = w.laser_outputs()[0];
    assert_eq!(laser.count, 129);
    let pf = PfConfig {
        particles: PARTICLES,
        beam_stride: 1,
        ..PfConfig::default()
    };
    let cov0 = Matrix3::from_diagonal(&Vector3::new(0.01, 0.01, 0.001));
    let filter =
        ParticleFilter::new(EkfConfig::default(), pf, Vec::new(), &walls, start, cov0, 7).unwrap();
    c.bench_function("pf_step_500_particles_129_beams", |b| {
        b.iter_batched(
            || filter.clone(),
            |mut f| {
                f.step_with_laser(black_box(&out[0].sensor), Some(black_box(&laser)))
                    .unwrap();
                f
            },
            BatchSize::SmallInput,
        )
    });
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    bench(&mut c);
    c.final_summary();
}
