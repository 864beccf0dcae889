//! Test fixtures shared by the localizer's unit tests: the arena and corridor worlds of
//! seed 001's experiments, the start covariance and a pair of observations.

use nalgebra::{Matrix3, Vector3};

use pheromone_messages::LandmarkObs;
use pheromone_world::{Landmark, RobotConfig, WallConfig, WorldConfig, WorldPose};

pub(super) const V_MPS: f64 = 0.6;
pub(super) const OMEGA_RADPS: f64 = 0.2;

/// A 20 m × 20 m walled arena with a 4 × 4 grid of landmarks (signatures 1..=16); the robot
/// starts at (10, 7) facing +x, so (0.6 m/s, 0.2 rad/s) drives a circle of radius 3 m.
pub(super) fn arena() -> WorldConfig {
    let landmarks = (0..16)
        .map(|k| Landmark {
            x_m: 2.5 + 5.0 * (k % 4) as f64,
            y_m: 2.5 + 5.0 * (k / 4) as f64,
            signature: k as u32 + 1,
        })
        .collect();
    WorldConfig {
        robots: vec![RobotConfig {
            id: 1,
            start: WorldPose::new(10.0, 7.0, 0.0),
            noise: None,
        }],
        walls: vec![WallConfig::Polyline {
            points_m: vec![[0.0, 0.0], [20.0, 0.0], [20.0, 20.0], [0.0, 20.0]],
            closed: true,
        }],
        landmarks,
        ..WorldConfig::default()
    }
}

pub(super) fn initial_cov() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(
        0.05f64.powi(2),
        0.05f64.powi(2),
        0.02f64.powi(2),
    ))
}

pub(super) fn some_obs() -> Vec<LandmarkObs> {
    vec![
        LandmarkObs {
            range_m: 2.0,
            bearing_rad: 0.3,
            signature: 6,
            _pad: 0,
        },
        LandmarkObs {
            range_m: 3.0,
            bearing_rad: -1.0,
            signature: 7,
            _pad: 0,
        },
    ]
}

/// A 40 m × 4 m walled corridor with two rows of landmarks every 2 m (signatures 1..=40);
/// the robot starts at (10, 2) facing +x.
pub(super) fn corridor() -> WorldConfig {
    let landmarks = (0..40)
        .map(|k| Landmark {
            x_m: 1.0 + 2.0 * (k / 2) as f64,
            y_m: if k % 2 == 0 { 0.5 } else { 3.5 },
            signature: k as u32 + 1,
        })
        .collect();
    WorldConfig {
        robots: vec![RobotConfig {
            id: 1,
            start: WorldPose::new(10.0, 2.0, 0.0),
            noise: None,
        }],
        walls: vec![WallConfig::Polyline {
            points_m: vec![[0.0, 0.0], [40.0, 0.0], [40.0, 4.0], [0.0, 4.0]],
            closed: true,
        }],
        landmarks,
        ..WorldConfig::default()
    }
}

/// The captured area of the corridor: x in [8, 24] m, 16 of the 40 landmarks (40 %, as in
/// seed 001 Fig. 6).
pub(crate) const CAPTURED: [f64; 4] = [8.0, 0.0, 24.0, 4.0];
