//! The localizer's process loop, and the filter it runs (EKF, UKF, particle filter or
//! EKF-SLAM).

use iceoryx2::node::Node;
use nalgebra::Matrix3;
use pheromone_field::process::lockstep::Participant;
use pheromone_field::shm::Svc;

use crate::localizer::{
    CheckedFilter, Ekf, EkfConfig, EkfSlam, EkfSlamConfig, FilterKind, LocalizerError,
    ParticleFilter, PfConfig, Ukf, UkfConfig,
};
use crate::{
    receiver, role_loop, sender, sim_stamp_ns, summary_of, ProcessError, RobotServices,
    RoleOptions, RoleSummary,
};
use pheromone_messages::{Landmark, LaserMsg, PoseMsg, Segment, SensorMsg, WorldPose};

/// Mixed into a particle filter's seed.
const PF_SEED: u64 = 0x7061_7274_6963_6c65;

/// Everything a robot's localizer needs, and nothing of the simulator: which filter, its
/// settings, the robot's start pose and σ, the known map (landmarks, and walls for the particle
/// filter's laser model) and a seed. A scenario builds it (`pheromone_world`'s
/// `Scenario::localizer_setup`); a real robot fills it from its own configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalizerSetup {
    pub robot: u32,
    pub filter: FilterKind,
    /// EKF-SLAM: the landmarks are not given, they join the state as they are seen.
    pub slam: bool,
    pub ekf: EkfConfig,
    pub ukf: UkfConfig,
    pub pf: PfConfig,
    pub start: WorldPose,
    /// σ of the start position (m), in x and in y.
    pub initial_sigma_m: f64,
    pub landmarks: Vec<Landmark>,
    /// The walls as segments (the particle filter's likelihood field).
    pub walls: Vec<Segment>,
    /// The run's seed (a particle filter's RNG mixes in the robot id).
    pub seed: u64,
}

/// The localizer process: sensors → EKF → pose with covariance. The pose is stamped with the
/// step's simulated time: the robot's clock, which the depositor's interval rule reads.
pub fn run_localizer(
    node: &Node<Svc>,
    setup: &LocalizerSetup,
    o: &RoleOptions,
) -> Result<RoleSummary, ProcessError> {
    let robot = o.robot;
    let mut filter = Filter::new(setup)?;
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
/// EKF-SLAM when the map is unknown.
pub enum Filter {
    Ekf(Box<Ekf>),
    Ukf(Box<Ukf>),
    Pf(Box<ParticleFilter>),
    Slam(Box<EkfSlam>),
}

impl Filter {
    /// The filter of `s`: its `filter` kind (EKF-SLAM if `s.slam`), start pose, initial σ, noise,
    /// loss. A particle filter's RNG is seeded from the run's seed and the robot id.
    pub fn new(s: &LocalizerSetup) -> Result<Self, ProcessError> {
        let var = s.initial_sigma_m.powi(2);
        let cov0 = Matrix3::from_diagonal(&nalgebra::Vector3::new(var, var, (0.05f64).powi(2)));
        let (start, cfg, e) = (s.start, s.ekf, ProcessError::Localizer);
        Ok(if s.slam {
            // EKF-SLAM: landmarks are not given, they join the state as they are seen.
            if let Some(region) = cfg.landmark_region_m {
                return Err(ProcessError::SlamRegion {
                    robot: s.robot,
                    key: crate::localizer::LANDMARK_REGION_KEY,
                    region,
                });
            }
            let config = EkfSlamConfig {
                noise: cfg.noise,
                limits: cfg.limits,
                ..EkfSlamConfig::default()
            };
            Filter::Slam(Box::new(EkfSlam::new(config, start, cov0).map_err(e)?))
        } else {
            let landmarks = s.landmarks.clone();
            match s.filter {
                FilterKind::Ekf => {
                    Filter::Ekf(Box::new(Ekf::new(cfg, landmarks, start, cov0).map_err(e)?))
                }
                FilterKind::Ukf => Filter::Ukf(Box::new(
                    Ukf::new(cfg, s.ukf, landmarks, start, cov0).map_err(e)?,
                )),
                FilterKind::Pf => {
                    let seed = s.seed ^ (u64::from(s.robot) << 32) ^ PF_SEED;
                    Filter::Pf(Box::new(
                        ParticleFilter::new(cfg, s.pf, landmarks, &s.walls, start, cov0, seed)
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
