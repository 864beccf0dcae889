//! The simulated world of a run, apart from the robot stack: what a real robot's sensors and
//! motors would be (`pheromone-roles` does not depend on this crate, `tests/crate_graph.rs`).
//!
//! - [`World`]: true poses of differential-drive robots among walls and landmarks, noisy odometry
//!   and noisy range/bearing observations, seed 000's laser, seed 004's scans and rendezvous.
//! - [`scenario`]: the scenario file (TOML, unknown keys are errors), built-ins, overrides, and
//!   the configuration of each robot's roles built from it (`Scenario::localizer_setup`, …).
//! - [`run_world`]: the world's process loop, which also conducts the lockstep.
//! - [`team`]: seed 004's `MappingTeam`, the mappers of a single-process run.
//!
//! The simulator:
//! - Kinematics: seed 000 eqs. 27–33 ([`diff_drive`]); a velocity command `(v, ω)` over `dt` is
//!   the wheel travel of [`wheel_travel`].
//! - Odometry: the executed `(v, ω)` plus Gaussian noise of the velocity motion model used by
//!   seed 001 Algorithm 1 line 5: σ_v² = α1·v² + α2·ω², σ_ω² = α3·v² + α4·ω².
//! - Observations: range and bearing (relative to the heading, wrapped to (−π, π]) with a
//!   signature, to landmarks within `sensor_range_m`, optionally within a field of view and in
//!   line of sight, nearest first, at most
//!   [`MAX_OBSERVATIONS`](pheromone_messages::MAX_OBSERVATIONS) — the measurement of seed 001
//!   Algorithm 1 line 9.
//! - Walls: axis-aligned rectangles and polylines; a ROS map_server PGM+YAML map becomes wall
//!   rectangles with [`OccupancyMap`].
//!
//! Everything is deterministic for a seed (`ChaCha8Rng`).

mod conductor;
pub mod scenario;
pub mod team;

pub use conductor::{
    lockstep_participants, mapper_robots, run_world, RobotSummary, WorldOptions, WorldSummary,
};
pub use scenario::WORLD_DEPOSITOR_ID;

mod laser;
mod map;
mod scan;
mod sensors;
mod slip;
#[cfg(test)]
mod test_support;
mod walls;

pub use laser::LaserConfig;
pub use map::{builtin_map_names, MapError, OccupancyMap, BUILTIN_MAPS};
pub use pheromone_messages::geometry::{
    sinc, sinc_derivative, Landmark, NoiseConfig, Segment, WorldPose,
};
pub use scan::ScanSensorConfig;
pub use slip::SlipZone;
pub use walls::{wall_segments, WallConfig};

use std::f64::consts::TAU;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use pheromone_messages::{SensorMsg, TruthMsg};
use walls::{inside_rect, SegmentIndex};

pub use pheromone_messages::wrap_angle;

/// Differential-drive motion by wheel travel (seed 000 eqs. 27–33).
///
/// `left_m` and `right_m` are the distances the left and right wheels rolled, `wheel_base_m`
/// (W, must be > 0) the distance between them. β = (r − l)/W (eq. 27), R = l/β (eq. 28),
/// θ' = (θ + β) mod 2π (eq. 30, so the returned heading is in [0, 2π)); straight motion when
/// r = l (eqs. 32–33).
///
/// Eqs. 29–31 are evaluated in the equivalent chord form
/// `p' = p + s·sinc(β/2)·(cos(θ + β/2), sin(θ + β/2))` with s = (l + r)/2 = (R + W/2)·β, which is
/// exact and stays accurate for tiny β. Eq. 31 as printed has the sign of its last term flipped
/// (it would not reduce to p' = p for β → 0); the chord form is the corrected eq. 31:
/// p' = C + (R + W/2)·(sin θ', −cos θ').
pub fn diff_drive(pose: WorldPose, left_m: f64, right_m: f64, wheel_base_m: f64) -> WorldPose {
    let theta = pose.theta_rad;
    if left_m == right_m {
        // seed 000 eqs. 32–33
        return WorldPose {
            x_m: pose.x_m + left_m * theta.cos(),
            y_m: pose.y_m + left_m * theta.sin(),
            theta_rad: heading_mod_tau(theta),
        };
    }
    let beta = (right_m - left_m) / wheel_base_m; // seed 000 eq. 27
    let arc_m = 0.5 * (left_m + right_m); // (R + W/2)·β with R = l/β, seed 000 eq. 28
    let half = 0.5 * beta;
    let chord_m = arc_m * sinc(half);
    WorldPose {
        x_m: pose.x_m + chord_m * (theta + half).cos(),
        y_m: pose.y_m + chord_m * (theta + half).sin(),
        theta_rad: heading_mod_tau(theta + beta), // seed 000 eq. 30
    }
}

fn heading_mod_tau(theta_rad: f64) -> f64 {
    let t = theta_rad.rem_euclid(TAU);
    if t >= TAU {
        0.0
    } else {
        t
    }
}

/// Wheel travel `(left_m, right_m)` of a velocity command held for `dt_s`:
/// l = (v − ω·W/2)·dt, r = (v + ω·W/2)·dt, so that β = ω·dt and (l + r)/2 = v·dt.
pub fn wheel_travel(
    v_m_per_s: f64,
    omega_rad_per_s: f64,
    dt_s: f64,
    wheel_base_m: f64,
) -> (f64, f64) {
    let half_w = 0.5 * wheel_base_m;
    (
        (v_m_per_s - omega_rad_per_s * half_w) * dt_s,
        (v_m_per_s + omega_rad_per_s * half_w) * dt_s,
    )
}

/// One robot of the world.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// Robot id carried in the messages (unique).
    pub id: u32,
    /// True start pose.
    #[serde(default)]
    pub start: WorldPose,
    /// Noise for this robot; the world's `noise` when absent.
    #[serde(default)]
    pub noise: Option<NoiseConfig>,
}

/// The simulated world.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorldConfig {
    /// Time advanced by one [`World::step`].
    #[serde(alias = "dt_secs")]
    pub dt_s: f64,
    /// Distance between the wheels (W of seed 000 eq. 27).
    pub wheel_base_m: f64,
    /// Robots are discs of this radius for wall collisions.
    pub robot_radius_m: f64,
    /// Landmarks farther than this are not observed.
    pub sensor_range_m: f64,
    /// Full opening angle of the sensor, centred on the heading; `None` = all around.
    pub field_of_view_rad: Option<f64>,
    /// Walls hide the landmarks behind them.
    pub line_of_sight: bool,
    /// Commands are clamped to |v| ≤ this.
    #[serde(alias = "max_speed_mps")]
    pub max_speed_m_per_s: f64,
    /// Commands are clamped to |ω| ≤ this.
    #[serde(alias = "max_turn_rate_radps")]
    pub max_turn_rate_rad_per_s: f64,
    /// Default noise for every robot.
    pub noise: NoiseConfig,
    pub robots: Vec<RobotConfig>,
    pub walls: Vec<WallConfig>,
    pub landmarks: Vec<Landmark>,
    /// A ROS map_server map (`map.yaml` + its PGM, or a built-in map's name, [`BUILTIN_MAPS`])
    /// whose occupied cells are walls too. A scenario loads it (`Scenario::load`, relative to
    /// the scenario file), adds its walls to `walls` and clears this key, so a [`World`] never
    /// sees it set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub map: Option<String>,
    /// Seed 000's laser range scanner on every robot (`laser.rs`); `None` = no laser. A
    /// particle-filter localizer needs it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub laser: Option<LaserConfig>,
    /// Odometry slip zones (`slip.rs`): floor where odometry errs beyond the usual noise.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub slip: Vec<SlipZone>,
}

impl Default for WorldConfig {
    fn default() -> Self {
        Self {
            dt_s: 0.1,
            wheel_base_m: 0.3,
            robot_radius_m: 0.2,
            sensor_range_m: 5.0,
            field_of_view_rad: None,
            line_of_sight: true,
            max_speed_m_per_s: 2.0,
            max_turn_rate_rad_per_s: 4.0,
            noise: NoiseConfig::default(),
            robots: Vec::new(),
            walls: Vec::new(),
            landmarks: Vec::new(),
            map: None,
            laser: None,
            slip: Vec::new(),
        }
    }
}

/// Why a world could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum WorldError {
    /// A scalar setting is out of range or not finite.
    #[error("world config: `{field}` = {value} is invalid ({expected})")]
    InvalidSetting {
        field: String,
        value: f64,
        expected: &'static str,
    },
    /// Two robots share an id.
    #[error("world config: robot id {id} appears more than once")]
    DuplicateRobotId { id: u32 },
    /// A robot's start pose overlaps a wall.
    #[error("world config: robot {id} starts at ({x_m}, {y_m}), inside or touching a wall")]
    StartInWall { id: u32, x_m: f64, y_m: f64 },
    /// A wall is degenerate or not finite.
    #[error("world config: wall {index} is invalid: {reason}")]
    InvalidWall { index: usize, reason: &'static str },
    /// `map` is still set: its walls were never loaded (a scenario loads them).
    #[error("world config: map {path} was not loaded (load the scenario with Scenario::load)")]
    UnloadedMap { path: String },
}

/// What one robot produced in one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutput {
    /// Odometry and observations (`stamp_ns` left 0 for the process loop).
    pub sensor: SensorMsg,
    /// The true pose after the step (`stamp_ns` left 0).
    pub truth: TruthMsg,
}

/// The simulator: true poses, walls, landmarks and a seeded RNG.
#[derive(Debug, Clone)]
pub struct World {
    config: WorldConfig,
    poses: Vec<WorldPose>,
    walls: SegmentIndex,
    rng: ChaCha8Rng,
    step: u64,
    rejected_commands: u64,
    /// Seed 004's range sensor and rendezvous measurement, when the scenario maps (`scan.rs`).
    mapping: Option<scan::MappingSensors>,
    /// Seed 000's laser, when `config.laser` is set (`laser.rs`).
    laser: Option<laser::Laser>,
}

impl World {
    /// Builds a world from a validated config; `seed` fixes every noise draw.
    pub fn new(config: WorldConfig, seed: u64) -> Result<Self, WorldError> {
        if let Some(path) = &config.map {
            return Err(WorldError::UnloadedMap { path: path.clone() });
        }
        validate_config(&config)?;
        if let Some(l) = &config.laser {
            l.validate()?;
        }
        let laser = config.laser.map(|l| laser::Laser::new(l, seed));
        let segments = wall_segments(&config.walls)?;
        let walls = SegmentIndex::new(segments, config.robot_radius_m.max(0.5));
        for robot in &config.robots {
            let p = [robot.start.x_m, robot.start.y_m];
            if walls.clearance_below(p, config.robot_radius_m) || inside_rect(&config.walls, p) {
                return Err(WorldError::StartInWall {
                    id: robot.id,
                    x_m: p[0],
                    y_m: p[1],
                });
            }
        }
        let poses = config
            .robots
            .iter()
            .map(|r| WorldPose {
                theta_rad: heading_mod_tau(r.start.theta_rad),
                ..r.start
            })
            .collect();
        Ok(Self {
            config,
            poses,
            walls,
            rng: ChaCha8Rng::seed_from_u64(seed),
            step: 0,
            rejected_commands: 0,
            mapping: None,
            laser,
        })
    }

    /// Advances every robot by `dt_s` under its command `(v_m_per_s, omega_rad_per_s)`, in the order
    /// of `config.robots`. A missing command (slice too short) means stop; a non-finite command
    /// is counted in [`World::rejected_commands`] and also means stop; commands are clamped to
    /// the speed limits. A move that would bring the robot's disc into a wall is not executed
    /// (the robot stays put but still turns, since turning in place cannot collide) and is
    /// reported as `collided`, with executed v = 0 in the odometry.
    pub fn step(&mut self, cmds: &[(f64, f64)]) -> Vec<StepOutput> {
        self.step += 1;
        let dt = self.config.dt_s;
        let sim_time_s = self.step as f64 * dt;
        let mut out = Vec::with_capacity(self.poses.len());
        for i in 0..self.poses.len() {
            let (mut v, mut w) = cmds.get(i).copied().unwrap_or((0.0, 0.0));
            if !(v.is_finite() && w.is_finite()) {
                self.rejected_commands += 1;
                v = 0.0;
                w = 0.0;
            }
            v = v.clamp(
                -self.config.max_speed_m_per_s,
                self.config.max_speed_m_per_s,
            );
            w = w.clamp(
                -self.config.max_turn_rate_rad_per_s,
                self.config.max_turn_rate_rad_per_s,
            );
            let pose = self.poses[i];
            let (l, r) = wheel_travel(v, w, dt, self.config.wheel_base_m);
            let next = diff_drive(pose, l, r, self.config.wheel_base_m);
            let collided = self.walls.blocks_move(
                [pose.x_m, pose.y_m],
                [next.x_m, next.y_m],
                self.config.robot_radius_m,
            );
            let (executed_v, new_pose) = if collided {
                (
                    0.0,
                    WorldPose {
                        theta_rad: next.theta_rad,
                        ..pose
                    },
                )
            } else {
                (v, next)
            };
            self.poses[i] = new_pose;

            let noise = self.config.robots[i].noise.unwrap_or(self.config.noise);
            let id = self.config.robots[i].id;
            let zone = self
                .config
                .slip
                .iter()
                .find(|z| z.applies(id, pose.x_m, pose.y_m));
            let (odo_noise, bias) = match zone {
                Some(z) if executed_v != 0.0 => (z.odometry_noise(&noise), z.turn_bias_rad_per_s),
                Some(z) => (z.odometry_noise(&noise), 0.0),
                None => (noise, 0.0),
            };
            // seed 001 Algorithm 1 line 5: the control noise the EKF models.
            let (var_v, var_w) = odo_noise.control_variances(executed_v, w);
            let odo_v = executed_v + var_v.sqrt() * self.normal();
            let odo_w = w + bias + var_w.sqrt() * self.normal();

            let mut sensor = SensorMsg {
                step: self.step,
                robot_id: self.config.robots[i].id,
                sim_time_s,
                dt_s: dt,
                v_m_per_s: odo_v,
                omega_rad_per_s: odo_w,
                ..SensorMsg::default()
            };
            sensor.count = self.observe(new_pose, &noise, &mut sensor.observations) as u32;
            let truth = TruthMsg {
                stamp_ns: 0,
                step: self.step,
                robot_id: self.config.robots[i].id,
                collided: u32::from(collided),
                sim_time_s,
                x_m: new_pose.x_m,
                y_m: new_pose.y_m,
                theta_rad: new_pose.theta_rad,
            };
            out.push(StepOutput { sensor, truth });
        }
        out
    }

    /// True poses, in the order of `config.robots`.
    pub fn poses(&self) -> &[WorldPose] {
        &self.poses
    }

    pub fn config(&self) -> &WorldConfig {
        &self.config
    }

    /// Steps taken so far.
    pub fn step_count(&self) -> u64 {
        self.step
    }

    /// Simulated time: steps × `dt_s`.
    pub fn sim_time_s(&self) -> f64 {
        self.step as f64 * self.config.dt_s
    }

    /// Non-finite commands seen (each treated as stop).
    pub fn rejected_commands(&self) -> u64 {
        self.rejected_commands
    }

    /// All walls as segments (rectangles as their four edges), for pictures.
    pub fn wall_segments(&self) -> &[Segment] {
        &self.walls.segments
    }

    /// Whether a disc of the robot radius centred at the point touches no wall.
    pub fn is_free(&self, x_m: f64, y_m: f64) -> bool {
        let p = [x_m, y_m];
        !self.walls.clearance_below(p, self.config.robot_radius_m)
            && !inside_rect(&self.config.walls, p)
    }
}

fn invalid(field: impl Into<String>, value: f64, expected: &'static str) -> WorldError {
    WorldError::InvalidSetting {
        field: field.into(),
        value,
        expected,
    }
}

fn validate_config(c: &WorldConfig) -> Result<(), WorldError> {
    let positive = [
        ("dt_s", c.dt_s),
        ("wheel_base_m", c.wheel_base_m),
        ("sensor_range_m", c.sensor_range_m),
    ];
    for (name, value) in positive {
        if !(value.is_finite() && value > 0.0) {
            return Err(invalid(name, value, "finite and > 0"));
        }
    }
    let non_negative = [
        ("robot_radius_m", c.robot_radius_m),
        ("max_speed_m_per_s", c.max_speed_m_per_s),
        ("max_turn_rate_rad_per_s", c.max_turn_rate_rad_per_s),
    ];
    for (name, value) in non_negative {
        if !(value.is_finite() && value >= 0.0) {
            return Err(invalid(name, value, "finite and >= 0"));
        }
    }
    if let Some(fov) = c.field_of_view_rad {
        if !(fov.is_finite() && fov > 0.0) {
            return Err(invalid("field_of_view_rad", fov, "finite and > 0"));
        }
    }
    c.noise
        .validate()
        .map_err(|(f, v)| invalid(format!("noise.{f}"), v, "finite and >= 0"))?;
    let mut ids = std::collections::HashSet::new();
    for (i, r) in c.robots.iter().enumerate() {
        if !ids.insert(r.id) {
            return Err(WorldError::DuplicateRobotId { id: r.id });
        }
        if !r.start.is_finite() {
            return Err(invalid(
                format!("robots[{i}].start"),
                f64::NAN,
                "finite coordinates",
            ));
        }
        if let Some(n) = &r.noise {
            n.validate().map_err(|(f, v)| {
                invalid(format!("robots[{i}].noise.{f}"), v, "finite and >= 0")
            })?;
        }
    }
    for (i, z) in c.slip.iter().enumerate() {
        z.validate(i)?;
    }
    for (i, lm) in c.landmarks.iter().enumerate() {
        if !(lm.x_m.is_finite() && lm.y_m.is_finite()) {
            return Err(invalid(
                format!("landmarks[{i}]"),
                f64::NAN,
                "finite coordinates",
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::one_robot;
    use approx::assert_relative_eq;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_6};

    #[test]
    fn straight_when_wheels_travel_equally() {
        // seed 000 eqs. 32–33
        let p = diff_drive(WorldPose::new(1.0, 2.0, FRAC_PI_6), 0.5, 0.5, 0.3);
        assert_relative_eq!(p.x_m, 1.0 + 0.5 * FRAC_PI_6.cos(), epsilon = 1e-12);
        assert_relative_eq!(p.y_m, 2.0 + 0.5 * FRAC_PI_6.sin(), epsilon = 1e-12);
        assert_relative_eq!(p.theta_rad, FRAC_PI_6, epsilon = 1e-12);
    }

    #[test]
    fn turning_in_place_keeps_position() {
        // r = −l: β = 2r/W, R = l/β = −W/2, the centre of rotation is the robot itself.
        let w = 0.4;
        let p = diff_drive(WorldPose::new(3.0, -1.0, 0.2), -0.1, 0.1, w);
        assert_relative_eq!(p.x_m, 3.0, epsilon = 1e-12);
        assert_relative_eq!(p.y_m, -1.0, epsilon = 1e-12);
        assert_relative_eq!(p.theta_rad, 0.2 + 0.2 / w, epsilon = 1e-12);
        // Negative turn wraps into [0, 2π) (eq. 30).
        let q = diff_drive(WorldPose::new(0.0, 0.0, 0.0), 0.1, -0.1, w);
        assert_relative_eq!(q.theta_rad, TAU - 0.5, epsilon = 1e-12);
    }

    #[test]
    fn arc_matches_centre_of_rotation_form() {
        // seed 000 eqs. 27–31 literally (eq. 31 with its sign corrected).
        let (x, y, th, l, r, w): (f64, f64, f64, f64, f64, f64) = (0.5, -0.2, 1.1, 0.3, 0.5, 0.35);
        let beta = (r - l) / w;
        let big_r = l / beta;
        let k = big_r + w / 2.0;
        let (cx, cy) = (x - k * th.sin(), y + k * th.cos());
        let th2 = th + beta;
        let (x2, y2) = (cx + k * th2.sin(), cy - k * th2.cos());
        let p = diff_drive(WorldPose::new(x, y, th), l, r, w);
        assert_relative_eq!(p.x_m, x2, epsilon = 1e-12);
        assert_relative_eq!(p.y_m, y2, epsilon = 1e-12);
        assert_relative_eq!(p.theta_rad, th2, epsilon = 1e-12);
        // A quarter circle of radius 1 m from the origin ends at (1, 1) facing +y.
        let (l, r) = wheel_travel(1.0, 1.0, FRAC_PI_2, 0.3);
        let q = diff_drive(WorldPose::default(), l, r, 0.3);
        assert_relative_eq!(q.x_m, 1.0, epsilon = 1e-12);
        assert_relative_eq!(q.y_m, 1.0, epsilon = 1e-12);
        assert_relative_eq!(q.theta_rad, FRAC_PI_2, epsilon = 1e-12);
    }

    #[test]
    fn world_step_moves_without_noise() {
        let mut world = World::new(one_robot(WorldPose::default()), 1).unwrap();
        for _ in 0..10 {
            let out = world.step(&[(1.0, 0.0)]);
            assert_eq!(out.len(), 1);
            assert_eq!(out[0].truth.collided, 0);
            assert_eq!(out[0].sensor.robot_id, 7);
            assert_eq!(out[0].sensor.v_m_per_s, 1.0);
            assert_eq!(out[0].sensor.stamp_ns, 0);
        }
        assert_relative_eq!(world.poses()[0].x_m, 1.0, epsilon = 1e-12);
        assert_eq!(world.step_count(), 10);
        assert_relative_eq!(world.sim_time_s(), 1.0, epsilon = 1e-12);
    }

    #[test]
    fn start_inside_wall_is_an_error() {
        let mut cfg = one_robot(WorldPose::new(1.1, 0.0, 0.0));
        cfg.walls = vec![WallConfig::Rect {
            min_x_m: 1.0,
            min_y_m: -1.0,
            max_x_m: 3.0,
            max_y_m: 1.0,
        }];
        assert!(matches!(
            World::new(cfg, 0),
            Err(WorldError::StartInWall { id: 7, .. })
        ));
    }

    fn noisy_config() -> WorldConfig {
        WorldConfig {
            robots: vec![
                RobotConfig {
                    id: 1,
                    start: WorldPose::default(),
                    noise: None,
                },
                RobotConfig {
                    id: 2,
                    start: WorldPose::new(2.0, 2.0, 1.0),
                    noise: Some(NoiseConfig {
                        alpha1: 0.1,
                        ..NoiseConfig::default()
                    }),
                },
            ],
            landmarks: vec![
                Landmark {
                    x_m: 1.0,
                    y_m: 1.0,
                    signature: 1,
                },
                Landmark {
                    x_m: 3.0,
                    y_m: -1.0,
                    signature: 2,
                },
            ],
            ..WorldConfig::default()
        }
    }

    #[test]
    fn deterministic_for_a_seed() {
        let run = |seed| {
            let mut world = World::new(noisy_config(), seed).unwrap();
            (0..30)
                .flat_map(|_| world.step(&[(0.5, 0.1), (0.3, -0.2)]))
                .collect::<Vec<_>>()
        };
        let a = run(42);
        assert_eq!(a, run(42));
        assert_ne!(a, run(43));
        // Noise is present: odometry differs from the command.
        assert!(a
            .iter()
            .any(|o| o.sensor.v_m_per_s != 0.5 && o.sensor.robot_id == 1));
    }

    #[test]
    fn bad_commands_and_config_are_handled() {
        let mut world = World::new(noisy_config(), 0).unwrap();
        let before = world.poses().to_vec();
        world.step(&[(f64::NAN, 0.0)]); // robot 2 has no command: stops
        assert_eq!(world.rejected_commands(), 1);
        assert_eq!(world.poses()[0].x_m, before[0].x_m);
        assert_eq!(world.poses()[1], before[1]);
        // Speed clamp.
        world.step(&[(100.0, 0.0)]);
        assert_relative_eq!(world.poses()[0].x_m, 0.2, epsilon = 1e-12);

        let mut cfg = noisy_config();
        cfg.dt_s = 0.0;
        assert!(matches!(
            World::new(cfg, 0),
            Err(WorldError::InvalidSetting { .. })
        ));
        let mut cfg = noisy_config();
        cfg.robots[1].id = 1;
        assert_eq!(
            World::new(cfg, 0).unwrap_err(),
            WorldError::DuplicateRobotId { id: 1 }
        );
    }
}
