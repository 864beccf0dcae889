//! The localizer's process loop, and the filter it runs (EKF, UKF, particle filter or
//! EKF-SLAM).

use field::lockstep::Participant;
use field::shm::Svc;
use iceoryx2::node::Node;
use nalgebra::Matrix3;

use crate::localizer::{
    CheckedFilter, Ekf, EkfSlam, EkfSlamConfig, FilterKind, LocalizerError, ParticleFilter, Ukf,
};
use crate::scenario::Scenario;
use crate::{
    receiver, role_loop, sender, sim_stamp_ns, summary_of, ProcessError, RobotServices,
    RoleOptions, RoleSummary,
};
use messages::{LaserMsg, PoseMsg, SensorMsg};

/// Mixed into a particle filter's seed.
const PF_SEED: u64 = 0x7061_7274_6963_6c65;

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
    let lasers = match filter.needs_laser() {
        true => Some(receiver::<LaserMsg>(node, &s.laser)?),
        false => None,
    };
    let mut laser_backlog = None;
    let wait = if o.lockstep {
        super::mapper::STEP_WAIT
    } else {
        super::mapper::REALTIME_WAIT
    };
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
            // The world sends a step's scan before its sensors: it is there already.
            let laser = match &lasers {
                Some(rx) => {
                    let l = super::mapper::recv_step(node, rx, &mut laser_backlog, m.step, wait)?;
                    if l.is_none() {
                        eprintln!("localizer r{robot}: step {}: no laser scan", m.step);
                    }
                    l
                }
                None => None,
            };
            if let Err(e) = filter.step(m, laser.as_ref()) {
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

/// The localizer's filter: landmark-based EKF or UKF, a particle filter with the laser, or
/// EKF-SLAM (faer) when the map is unknown.
pub enum Filter {
    Ekf(Box<Ekf>),
    Ukf(Box<Ukf>),
    Pf(Box<ParticleFilter>),
    Slam(Box<EkfSlam>),
}

impl Filter {
    /// The filter of robot `robot` as the scenario configures it (its `filter`, start pose,
    /// initial σ, noise, loss); EKF-SLAM if `slam`. A particle filter's RNG is seeded from the
    /// scenario's seed and the robot id.
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
            let landmarks = scenario.world.landmarks.clone();
            let cfg = roles.localizer;
            let e = ProcessError::Localizer;
            match roles.filter {
                FilterKind::Ekf => {
                    Filter::Ekf(Box::new(Ekf::new(cfg, landmarks, start, cov0).map_err(e)?))
                }
                FilterKind::Ukf => Filter::Ukf(Box::new(
                    Ukf::new(cfg, roles.ukf, landmarks, start, cov0).map_err(e)?,
                )),
                FilterKind::Pf => {
                    let walls = crate::world::wall_segments(&scenario.world.walls)
                        .map_err(ProcessError::World)?;
                    let seed = scenario.seed ^ (u64::from(robot) << 32) ^ PF_SEED;
                    Filter::Pf(Box::new(
                        ParticleFilter::new(cfg, roles.pf, landmarks, &walls, start, cov0, seed)
                            .map_err(e)?,
                    ))
                }
            }
        })
    }

    /// Whether the filter reads the world's laser.
    pub fn needs_laser(&self) -> bool {
        matches!(self, Filter::Pf(_))
    }

    /// One step on the sensors of `m` (and the step's laser scan, which only the particle
    /// filter reads).
    pub fn step(&mut self, m: &SensorMsg, laser: Option<&LaserMsg>) -> Result<(), LocalizerError> {
        match self {
            Filter::Ekf(f) => f.step(m).map(|_| ()),
            Filter::Ukf(f) => f.step(m).map(|_| ()),
            Filter::Pf(f) => f.step_with_laser(m, laser).map(|_| ()),
            Filter::Slam(f) => f.step(m).map(|_| ()),
        }
    }

    pub fn to_msg(&self, robot: u32, step: u64) -> PoseMsg {
        match self {
            Filter::Ekf(f) => f.to_msg(robot, step),
            Filter::Ukf(f) => f.to_msg(robot, step),
            Filter::Pf(f) => f.to_msg(robot, step),
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
