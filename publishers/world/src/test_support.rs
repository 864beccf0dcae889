//! Test fixtures shared by the world's unit tests.

use crate::{NoiseConfig, RobotConfig, WorldConfig, WorldPose};

pub(super) fn one_robot(start: WorldPose) -> WorldConfig {
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
