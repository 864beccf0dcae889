//! The configuration of each robot role built from a scenario: what `pheromone-roles` takes in
//! place of the scenario (which it does not know), so that the robot stack runs the same on a
//! real robot, fed its own configuration.

use pheromone_roles::depositor::Depositor;
use pheromone_roles::localizer::FilterKind;
use pheromone_roles::mapper::{MapError, Mapper, Pose2};
use pheromone_roles::{LocalizerSetup, MapperSetup, ProcessError};

use super::{Scenario, ScenarioError};
use crate::{wall_segments, WorldError};

impl Scenario {
    /// Robot `robot`'s localizer as the scenario configures it (its `filter`, start pose, initial
    /// σ, noise, loss, the world's landmarks; the walls for a particle filter); EKF-SLAM if `slam`.
    pub fn localizer_setup(&self, robot: u32, slam: bool) -> Result<LocalizerSetup, ProcessError> {
        let roles = self.roles(robot).ok_or(ProcessError::NoRoles { robot })?;
        let start = self
            .world
            .robots
            .iter()
            .find(|r| r.id == robot)
            .ok_or(ProcessError::NotInWorld { robot })?
            .start;
        // Only the particle filter's laser model reads the walls: those its laser sees (a
        // wall behind glass, both ends inside `laser.glass_rect_m`, is not on its map).
        let walls = match (slam, roles.filter) {
            (false, FilterKind::Pf) => {
                let mut w = wall_segments(&self.world.walls)?;
                if let Some(l) = &self.world.laser {
                    w.retain(|s| l.sees(s.a_m) || l.sees(s.b_m));
                }
                w
            }
            _ => Vec::new(),
        };
        Ok(LocalizerSetup {
            robot,
            filter: roles.filter,
            slam,
            ekf: roles.localizer,
            ukf: roles.ukf,
            pf: roles.pf,
            start,
            initial_sigma_m: roles.initial_sigma_m,
            landmarks: self.world.landmarks.clone(),
            walls,
            seed: self.seed,
        })
    }

    /// Robot `id`'s mapper as the scenario sets it up (`None` when the scenario does not map or
    /// the robot is not in the world): its start pose is the world's, its depositor copy the
    /// scenario's.
    pub fn mapper(&self, id: u32) -> Result<Option<Mapper>, MapError> {
        let Some(config) = self.mapping() else {
            return Ok(None);
        };
        let Some(r) = self.world.robots.iter().find(|r| r.id == id) else {
            return Ok(None);
        };
        let depositor = self
            .roles(id)
            .and_then(|x| x.depositor.clone())
            .and_then(|c| Depositor::new(c).ok());
        Mapper::new(
            id,
            config,
            [r.start.x_m, r.start.y_m, r.start.theta_rad],
            &self.mapping_channel(id),
            self.world.dt_s,
            depositor,
        )
        .map(Some)
    }

    /// Robot `robot`'s mapper process: its mapper ([`Scenario::mapper`]), the world's step and
    /// every other robot's start pose (the frames of their maps).
    pub fn mapper_setup(&self, robot: u32) -> Result<MapperSetup, ProcessError> {
        let mapper = self
            .mapper(robot)
            .map_err(ProcessError::Mapping)?
            .ok_or(ProcessError::NotMapping { robot })?;
        let peers = self
            .world
            .robots
            .iter()
            .filter(|r| r.id != robot)
            .map(|r| (r.id, [r.start.x_m, r.start.y_m, r.start.theta_rad] as Pose2))
            .collect();
        Ok(MapperSetup {
            mapper,
            dt_s: self.world.dt_s,
            peers,
        })
    }
}

impl From<ScenarioError> for ProcessError {
    fn from(e: ScenarioError) -> Self {
        ProcessError::Setup(Box::new(e))
    }
}

impl From<WorldError> for ProcessError {
    fn from(e: WorldError) -> Self {
        ProcessError::Setup(Box::new(e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ekf_slam_refuses_landmark_region_m() {
        let mut scenario = Scenario::load("trail").unwrap();
        let id = scenario.robots[0].id;
        scenario.robots[0].localizer.landmark_region_m = Some([8.0, 0.0, 24.0, 4.0]);
        let setup = scenario.localizer_setup(id, false).unwrap();
        assert!(pheromone_roles::Filter::new(&setup).is_ok());
        let slam = scenario.localizer_setup(id, true).unwrap();
        let e = pheromone_roles::Filter::new(&slam)
            .err()
            .expect("EKF-SLAM accepted a landmark region");
        assert!(e.to_string().contains("landmark_region_m"), "{e}");
    }

    #[test]
    fn a_robot_without_roles_or_not_in_the_world_is_named() {
        let scenario = Scenario::load("trail").unwrap();
        let e = scenario.localizer_setup(9999, false).unwrap_err();
        assert!(e.to_string().contains("robot 9999"), "{e}");
    }
}
