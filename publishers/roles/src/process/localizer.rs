//! The localizer's process loop, and the filter it runs (EKF or EKF-SLAM).

use field::lockstep::Participant;
use field::shm::Svc;
use iceoryx2::node::Node;
use nalgebra::Matrix3;

use crate::localizer::{CheckedFilter, Ekf, EkfSlam, EkfSlamConfig, LocalizerError};
use crate::scenario::Scenario;
use crate::{
    receiver, role_loop, sender, sim_stamp_ns, summary_of, ProcessError, RobotServices,
    RoleOptions, RoleSummary,
};
use messages::{PoseMsg, SensorMsg};

/// The localizer process: sensors → EKF → pose with covariance. The pose is stamped with the
/// step's simulated time: the robot's clock, which the depositor's interval rule reads.
pub fn run_localizer(
    node: &Node<Svc>,
    scenario: &Scenario,
    o: &RoleOptions,
    slam: bool,
) -> Result<RoleSummary, ProcessError> {
    let robot = o.robot;
    let mut filter = Filter::for_robot(scenario, robot, slam)?;
    let s = RobotServices::new(&o.world, robot);
    let sensors = receiver::<SensorMsg>(node, &s.sensors)?;
    let poses = sender::<PoseMsg>(node, &s.pose)?;
    let end = Participant::join(node, &o.world)?;
    let mut summary = summary_of(robot, "localizer");
    let last = std::cell::Cell::new(None::<PoseMsg>);
    let mut rejected = 0u64;
    role_loop(
        node,
        &end,
        &sensors,
        |m: &SensorMsg| m.step,
        &mut summary,
        |m| {
            if let Err(e) = filter.step(m) {
                rejected += 1;
                eprintln!("localizer r{robot}: step {} rejected: {e}", m.step);
            }
            let mut p = filter.to_msg(robot, m.step);
            p.stamp_ns = sim_stamp_ns(m.sim_time_s);
            poses.send(p)?;
            last.set(Some(p));
            Ok(())
        },
        || {
            if let Some(p) = last.get() {
                poses.send(p)?;
            }
            Ok(())
        },
    )?;
    summary.rejected = rejected;
    Ok(summary)
}

/// The localizer's filter: landmark-based EKF, or EKF-SLAM (faer) when the map is unknown.
pub enum Filter {
    Ekf(Box<Ekf>),
    Slam(Box<EkfSlam>),
}

impl Filter {
    /// The filter of robot `robot` as the scenario configures it (start pose, initial σ,
    /// noise, loss); EKF-SLAM if `slam`.
    pub fn for_robot(scenario: &Scenario, robot: u32, slam: bool) -> Result<Self, ProcessError> {
        let roles = scenario
            .roles(robot)
            .ok_or(ProcessError::NoRoles { robot })?;
        let start = scenario
            .world
            .robots
            .iter()
            .find(|r| r.id == robot)
            .ok_or(ProcessError::NotInWorld { robot })?
            .start;
        let var = roles.initial_sigma_m.powi(2);
        let cov0 = Matrix3::from_diagonal(&nalgebra::Vector3::new(var, var, (0.05f64).powi(2)));
        Ok(if slam {
            // EKF-SLAM: landmarks are not given, they join the state as they are seen.
            if let Some(region) = roles.localizer.landmark_region_m {
                return Err(ProcessError::SlamRegion {
                    robot,
                    key: crate::localizer::LANDMARK_REGION_KEY,
                    region,
                });
            }
            let config = EkfSlamConfig {
                noise: roles.localizer.noise,
                limits: roles.localizer.limits,
                ..EkfSlamConfig::default()
            };
            Filter::Slam(Box::new(
                EkfSlam::new(config, start, cov0).map_err(ProcessError::Localizer)?,
            ))
        } else {
            Filter::Ekf(Box::new(
                Ekf::new(
                    roles.localizer,
                    scenario.world.landmarks.clone(),
                    start,
                    cov0,
                )
                .map_err(ProcessError::Localizer)?,
            ))
        })
    }

    pub fn step(&mut self, m: &SensorMsg) -> Result<(), LocalizerError> {
        match self {
            Filter::Ekf(f) => f.step(m).map(|_| ()),
            Filter::Slam(f) => f.step(m).map(|_| ()),
        }
    }

    pub fn to_msg(&self, robot: u32, step: u64) -> PoseMsg {
        match self {
            Filter::Ekf(f) => f.to_msg(robot, step),
            Filter::Slam(f) => f.to_msg(robot, step),
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::localizer::test_support::CAPTURED;

    #[test]
    fn ekf_slam_refuses_landmark_region_m() {
        let mut scenario = crate::scenario::Scenario::load("trail").unwrap();
        let id = scenario.robots[0].id;
        scenario.robots[0].localizer.landmark_region_m = Some(CAPTURED);
        assert!(crate::Filter::for_robot(&scenario, id, false).is_ok());
        let e = crate::Filter::for_robot(&scenario, id, true)
            .err()
            .expect("EKF-SLAM accepted a landmark region");
        assert!(e.to_string().contains("landmark_region_m"), "{e}");
    }
}
