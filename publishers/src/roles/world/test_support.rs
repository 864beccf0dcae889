//! Test fixtures shared by the world's unit tests.

use crate::roles::world::{NoiseConfig, Pose2, RobotConfig, WorldConfig};

pub(super) fn one_robot(start: Pose2) -> WorldConfig {
    WorldConfig {
        robots: vec![RobotConfig {
            id: 7,
            start,
            noise: None,
        }],
        noise: NoiseConfig::zero(),
        ..WorldConfig::default()
    }
}
