//! The simulator's library type: true poses of differential-drive robots among walls and
//! landmarks, noisy odometry and noisy range/bearing observations.
//!
//! - Kinematics: seed 000 eqs. 27–33 ([`diff_drive`]); a velocity command `(v, ω)` over `dt` is
//!   the wheel travel of [`wheel_travel`].
//! - Odometry: the executed `(v, ω)` plus Gaussian noise of the velocity motion model used by
//!   seed 001 Algorithm 1 line 5: σ_v² = α1·v² + α2·ω², σ_ω² = α3·v² + α4·ω².
//! - Observations: range and bearing (relative to the heading, wrapped to (−π, π]) with a
//!   signature, to landmarks within `sensor_range_m`, optionally within a field of view and in
//!   line of sight, nearest first, at most [`MAX_OBSERVATIONS`] — the measurement of seed 001
//!   Algorithm 1 line 9.
//! - Walls: axis-aligned rectangles and polylines; a ROS map_server PGM+YAML map becomes wall
//!   rectangles with [`OccupancyMap`].
//!
//! Everything is deterministic for a seed (`ChaCha8Rng`).

pub mod run;

use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::messages::{LandmarkObs, SensorMsg, TruthMsg, MAX_OBSERVATIONS};

/// A planar pose: metres and radians, θ counter-clockwise from +x.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pose2 {
    pub x_m: f64,
    pub y_m: f64,
    pub theta_rad: f64,
}

impl Pose2 {
    pub fn new(x_m: f64, y_m: f64, theta_rad: f64) -> Self {
        Self {
            x_m,
            y_m,
            theta_rad,
        }
    }

    fn is_finite(&self) -> bool {
        self.x_m.is_finite() && self.y_m.is_finite() && self.theta_rad.is_finite()
    }
}

/// Wraps an angle to (−π, π].
pub fn wrap_angle(angle_rad: f64) -> f64 {
    let a = (angle_rad + PI).rem_euclid(TAU) - PI;
    if a <= -PI {
        a + TAU
    } else {
        a
    }
}

/// sin(x)/x, exact near 0.
pub(crate) fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        1.0 - x * x / 6.0
    } else {
        x.sin() / x
    }
}

/// d/dx of sin(x)/x, exact near 0.
pub(crate) fn sinc_derivative(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        -x / 3.0 + x * x * x / 30.0
    } else {
        (x * x.cos() - x.sin()) / (x * x)
    }
}

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
pub fn diff_drive(pose: Pose2, left_m: f64, right_m: f64, wheel_base_m: f64) -> Pose2 {
    let theta = pose.theta_rad;
    if left_m == right_m {
        // seed 000 eqs. 32–33
        return Pose2 {
            x_m: pose.x_m + left_m * theta.cos(),
            y_m: pose.y_m + left_m * theta.sin(),
            theta_rad: heading_mod_tau(theta),
        };
    }
    let beta = (right_m - left_m) / wheel_base_m; // seed 000 eq. 27
    let arc_m = 0.5 * (left_m + right_m); // (R + W/2)·β with R = l/β, seed 000 eq. 28
    let half = 0.5 * beta;
    let chord_m = arc_m * sinc(half);
    Pose2 {
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

/// Wheel travel `(left_m, right_m)` of a velocity command held for `dt_secs`:
/// l = (v − ω·W/2)·dt, r = (v + ω·W/2)·dt, so that β = ω·dt and (l + r)/2 = v·dt.
pub fn wheel_travel(v_mps: f64, omega_radps: f64, dt_secs: f64, wheel_base_m: f64) -> (f64, f64) {
    let half_w = 0.5 * wheel_base_m;
    (
        (v_mps - omega_radps * half_w) * dt_secs,
        (v_mps + omega_radps * half_w) * dt_secs,
    )
}

/// Sensor and odometry noise. The α's are those of the velocity motion model (seed 001
/// Algorithm 1 line 5): σ_v² = α1·v² + α2·ω², σ_ω² = α3·v² + α4·ω².
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NoiseConfig {
    /// Standard deviation of the measured range.
    pub range_sigma_m: f64,
    /// Standard deviation of the measured bearing.
    pub bearing_sigma_rad: f64,
    /// (m/s)² of v-noise per (m/s)² of v.
    pub alpha1: f64,
    /// (m/s)² of v-noise per (rad/s)² of ω.
    pub alpha2: f64,
    /// (rad/s)² of ω-noise per (m/s)² of v.
    pub alpha3: f64,
    /// (rad/s)² of ω-noise per (rad/s)² of ω.
    pub alpha4: f64,
}

impl Default for NoiseConfig {
    fn default() -> Self {
        Self {
            range_sigma_m: 0.05,
            bearing_sigma_rad: 0.02,
            alpha1: 0.01,
            alpha2: 0.001,
            alpha3: 0.001,
            alpha4: 0.01,
        }
    }
}

impl NoiseConfig {
    /// No noise at all (for tests and ground-truth runs).
    pub fn zero() -> Self {
        Self {
            range_sigma_m: 0.0,
            bearing_sigma_rad: 0.0,
            alpha1: 0.0,
            alpha2: 0.0,
            alpha3: 0.0,
            alpha4: 0.0,
        }
    }

    /// Variances (σ_v², σ_ω²) of the control noise for a command (seed 001 Algorithm 1 line 5).
    pub fn control_variances(&self, v_mps: f64, omega_radps: f64) -> (f64, f64) {
        let (v2, w2) = (v_mps * v_mps, omega_radps * omega_radps);
        (
            self.alpha1 * v2 + self.alpha2 * w2,
            self.alpha3 * v2 + self.alpha4 * w2,
        )
    }

    /// The first field that is negative or not finite.
    pub(crate) fn validate(&self) -> Result<(), (&'static str, f64)> {
        let fields = [
            ("range_sigma_m", self.range_sigma_m),
            ("bearing_sigma_rad", self.bearing_sigma_rad),
            ("alpha1", self.alpha1),
            ("alpha2", self.alpha2),
            ("alpha3", self.alpha3),
            ("alpha4", self.alpha4),
        ];
        for (name, value) in fields {
            if !(value.is_finite() && value >= 0.0) {
                return Err((name, value));
            }
        }
        Ok(())
    }
}

/// One robot of the world.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// Robot id carried in the messages (unique).
    pub id: u32,
    /// True start pose.
    #[serde(default)]
    pub start: Pose2,
    /// Noise for this robot; the world's `noise` when absent.
    #[serde(default)]
    pub noise: Option<NoiseConfig>,
}

/// A wall: an axis-aligned rectangle or a polyline of segments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum WallConfig {
    /// Solid axis-aligned rectangle.
    Rect {
        min_x_m: f64,
        min_y_m: f64,
        max_x_m: f64,
        max_y_m: f64,
    },
    /// Thin wall along consecutive points; `closed` joins the last point to the first.
    Polyline {
        points_m: Vec<[f64; 2]>,
        #[serde(default)]
        closed: bool,
    },
}

/// A point landmark with a signature (0 = no signature / ambiguous).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Landmark {
    pub x_m: f64,
    pub y_m: f64,
    #[serde(default)]
    pub signature: u32,
}

/// The simulated world.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorldConfig {
    /// Time advanced by one [`World::step`].
    pub dt_secs: f64,
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
    pub max_speed_mps: f64,
    /// Commands are clamped to |ω| ≤ this.
    pub max_turn_rate_radps: f64,
    /// Default noise for every robot.
    pub noise: NoiseConfig,
    pub robots: Vec<RobotConfig>,
    pub walls: Vec<WallConfig>,
    pub landmarks: Vec<Landmark>,
}

impl Default for WorldConfig {
    fn default() -> Self {
        Self {
            dt_secs: 0.1,
            wheel_base_m: 0.3,
            robot_radius_m: 0.2,
            sensor_range_m: 5.0,
            field_of_view_rad: None,
            line_of_sight: true,
            max_speed_mps: 2.0,
            max_turn_rate_radps: 4.0,
            noise: NoiseConfig::default(),
            robots: Vec::new(),
            walls: Vec::new(),
            landmarks: Vec::new(),
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
}

/// A wall segment from `a_m` to `b_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub a_m: [f64; 2],
    pub b_m: [f64; 2],
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
    poses: Vec<Pose2>,
    walls: SegmentIndex,
    rng: ChaCha8Rng,
    step: u64,
    rejected_commands: u64,
}

impl World {
    /// Builds a world from a validated config; `seed` fixes every noise draw.
    pub fn new(config: WorldConfig, seed: u64) -> Result<Self, WorldError> {
        validate_config(&config)?;
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
            .map(|r| Pose2 {
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
        })
    }

    /// Advances every robot by `dt_secs` under its command `(v_mps, omega_radps)`, in the order
    /// of `config.robots`. A missing command (slice too short) means stop; a non-finite command
    /// is counted in [`World::rejected_commands`] and also means stop; commands are clamped to
    /// the speed limits. A move that would bring the robot's disc into a wall is not executed
    /// (the robot stays put but still turns, since turning in place cannot collide) and is
    /// reported as `collided`, with executed v = 0 in the odometry.
    pub fn step(&mut self, cmds: &[(f64, f64)]) -> Vec<StepOutput> {
        self.step += 1;
        let dt = self.config.dt_secs;
        let sim_time_s = self.step as f64 * dt;
        let mut out = Vec::with_capacity(self.poses.len());
        for i in 0..self.poses.len() {
            let (mut v, mut w) = cmds.get(i).copied().unwrap_or((0.0, 0.0));
            if !(v.is_finite() && w.is_finite()) {
                self.rejected_commands += 1;
                v = 0.0;
                w = 0.0;
            }
            v = v.clamp(-self.config.max_speed_mps, self.config.max_speed_mps);
            w = w.clamp(
                -self.config.max_turn_rate_radps,
                self.config.max_turn_rate_radps,
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
                    Pose2 {
                        theta_rad: next.theta_rad,
                        ..pose
                    },
                )
            } else {
                (v, next)
            };
            self.poses[i] = new_pose;

            let noise = self.config.robots[i].noise.unwrap_or(self.config.noise);
            // seed 001 Algorithm 1 line 5: the control noise the EKF models.
            let (var_v, var_w) = noise.control_variances(executed_v, w);
            let odo_v = executed_v + var_v.sqrt() * self.normal();
            let odo_w = w + var_w.sqrt() * self.normal();

            let mut sensor = SensorMsg {
                step: self.step,
                robot_id: self.config.robots[i].id,
                sim_time_s,
                dt_secs: dt,
                v_mps: odo_v,
                omega_radps: odo_w,
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
    pub fn poses(&self) -> &[Pose2] {
        &self.poses
    }

    pub fn config(&self) -> &WorldConfig {
        &self.config
    }

    /// Steps taken so far.
    pub fn step_count(&self) -> u64 {
        self.step
    }

    /// Simulated time: steps × `dt_secs`.
    pub fn sim_time_s(&self) -> f64 {
        self.step as f64 * self.config.dt_secs
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

    fn normal(&mut self) -> f64 {
        self.rng.sample::<f64, _>(StandardNormal)
    }

    /// Fills `out` with noisy observations, nearest landmark first; returns how many.
    fn observe(
        &mut self,
        pose: Pose2,
        noise: &NoiseConfig,
        out: &mut [LandmarkObs; MAX_OBSERVATIONS],
    ) -> usize {
        let range_max = self.config.sensor_range_m;
        let half_fov = self.config.field_of_view_rad.map(|f| 0.5 * f);
        let mut seen: Vec<(f64, f64, u32)> = Vec::new();
        for lm in &self.config.landmarks {
            let dx = lm.x_m - pose.x_m;
            let dy = lm.y_m - pose.y_m;
            let range = dx.hypot(dy);
            if range > range_max || range < 1e-9 {
                continue;
            }
            let bearing = wrap_angle(dy.atan2(dx) - pose.theta_rad);
            if half_fov.is_some_and(|h| bearing.abs() > h) {
                continue;
            }
            if self.config.line_of_sight
                && self.walls.occludes([pose.x_m, pose.y_m], [lm.x_m, lm.y_m])
            {
                continue;
            }
            seen.push((range, bearing, lm.signature));
        }
        seen.sort_by(|a, b| a.0.total_cmp(&b.0));
        seen.truncate(MAX_OBSERVATIONS);
        for (slot, &(range, bearing, signature)) in out.iter_mut().zip(&seen) {
            let noisy_range = range + noise.range_sigma_m * self.normal();
            let noisy_bearing = wrap_angle(bearing + noise.bearing_sigma_rad * self.normal());
            *slot = LandmarkObs {
                range_m: noisy_range.max(0.0) as f32,
                bearing_rad: noisy_bearing as f32,
                signature,
                _pad: 0,
            };
        }
        seen.len()
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
        ("dt_secs", c.dt_secs),
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
        ("max_speed_mps", c.max_speed_mps),
        ("max_turn_rate_radps", c.max_turn_rate_radps),
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

fn wall_segments(walls: &[WallConfig]) -> Result<Vec<Segment>, WorldError> {
    let mut segs = Vec::new();
    for (index, wall) in walls.iter().enumerate() {
        match wall {
            WallConfig::Rect {
                min_x_m,
                min_y_m,
                max_x_m,
                max_y_m,
            } => {
                let (x0, y0, x1, y1) = (*min_x_m, *min_y_m, *max_x_m, *max_y_m);
                if ![x0, y0, x1, y1].iter().all(|v| v.is_finite()) {
                    return Err(WorldError::InvalidWall {
                        index,
                        reason: "non-finite corner",
                    });
                }
                if x1 < x0 || y1 < y0 {
                    return Err(WorldError::InvalidWall {
                        index,
                        reason: "max below min",
                    });
                }
                let c = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
                for k in 0..4 {
                    segs.push(Segment {
                        a_m: c[k],
                        b_m: c[(k + 1) % 4],
                    });
                }
            }
            WallConfig::Polyline { points_m, closed } => {
                if points_m.len() < 2 {
                    return Err(WorldError::InvalidWall {
                        index,
                        reason: "a polyline needs at least two points",
                    });
                }
                if !points_m.iter().flatten().all(|v| v.is_finite()) {
                    return Err(WorldError::InvalidWall {
                        index,
                        reason: "non-finite point",
                    });
                }
                for w in points_m.windows(2) {
                    segs.push(Segment {
                        a_m: w[0],
                        b_m: w[1],
                    });
                }
                if *closed && points_m.len() > 2 {
                    segs.push(Segment {
                        a_m: points_m[points_m.len() - 1],
                        b_m: points_m[0],
                    });
                }
            }
        }
    }
    Ok(segs)
}

fn inside_rect(walls: &[WallConfig], p: [f64; 2]) -> bool {
    walls.iter().any(|w| match w {
        WallConfig::Rect {
            min_x_m,
            min_y_m,
            max_x_m,
            max_y_m,
        } => p[0] >= *min_x_m && p[0] <= *max_x_m && p[1] >= *min_y_m && p[1] <= *max_y_m,
        WallConfig::Polyline { .. } => false,
    })
}

// ---------------------------------------------------------------------------------------------
// Geometry

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = sub(b, a);
    let len2 = dot(ab, ab);
    let t = if len2 > 0.0 {
        (dot(sub(p, a), ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let q = [a[0] + t * ab[0], a[1] + t * ab[1]];
    let d = sub(p, q);
    d[0].hypot(d[1])
}

/// Parameter t ∈ [0, 1] along p→p2 where it meets q→q2, if the segments properly cross or touch.
fn segment_intersection(p: [f64; 2], p2: [f64; 2], q: [f64; 2], q2: [f64; 2]) -> Option<f64> {
    let d = sub(p2, p);
    let e = sub(q2, q);
    let denom = cross(d, e);
    if denom.abs() < 1e-15 {
        return None;
    }
    let qp = sub(q, p);
    let t = cross(qp, e) / denom;
    let u = cross(qp, d) / denom;
    ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then_some(t)
}

fn segment_segment_distance(p: [f64; 2], p2: [f64; 2], q: [f64; 2], q2: [f64; 2]) -> f64 {
    if segment_intersection(p, p2, q, q2).is_some() {
        return 0.0;
    }
    point_segment_distance(p, q, q2)
        .min(point_segment_distance(p2, q, q2))
        .min(point_segment_distance(q, p, p2))
        .min(point_segment_distance(q2, p, p2))
}

/// Wall segments bucketed in a uniform grid so queries cost O(nearby walls).
#[derive(Debug, Clone)]
struct SegmentIndex {
    segments: Vec<Segment>,
    origin_m: [f64; 2],
    cell_m: f64,
    nx: usize,
    ny: usize,
    cells: Vec<Vec<u32>>,
}

impl SegmentIndex {
    const MAX_CELLS: usize = 1 << 20;

    fn new(segments: Vec<Segment>, cell_hint_m: f64) -> Self {
        if segments.is_empty() {
            return Self {
                segments,
                origin_m: [0.0; 2],
                cell_m: 1.0,
                nx: 0,
                ny: 0,
                cells: Vec::new(),
            };
        }
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for s in &segments {
            for p in [s.a_m, s.b_m] {
                for k in 0..2 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        let extent = [(hi[0] - lo[0]).max(1e-9), (hi[1] - lo[1]).max(1e-9)];
        let mut cell_m = cell_hint_m.max(1e-3);
        while (extent[0] / cell_m).ceil() * (extent[1] / cell_m).ceil() > Self::MAX_CELLS as f64 {
            cell_m *= 2.0;
        }
        let nx = ((extent[0] / cell_m).ceil() as usize).max(1);
        let ny = ((extent[1] / cell_m).ceil() as usize).max(1);
        let mut index = Self {
            segments,
            origin_m: lo,
            cell_m,
            nx,
            ny,
            cells: vec![Vec::new(); nx * ny],
        };
        for (k, s) in index.segments.iter().enumerate() {
            let (x0, x1, y0, y1) = index.cell_range(
                [s.a_m[0].min(s.b_m[0]), s.a_m[1].min(s.b_m[1])],
                [s.a_m[0].max(s.b_m[0]), s.a_m[1].max(s.b_m[1])],
            );
            for cy in y0..=y1 {
                for cx in x0..=x1 {
                    index.cells[cy * nx + cx].push(k as u32);
                }
            }
        }
        index
    }

    /// Inclusive cell ranges covering a box (clamped to the grid).
    fn cell_range(&self, lo: [f64; 2], hi: [f64; 2]) -> (usize, usize, usize, usize) {
        let to_cell = |v: f64, o: f64, n: usize| -> usize {
            let c = ((v - o) / self.cell_m).floor();
            if c <= 0.0 {
                0
            } else {
                (c as usize).min(n - 1)
            }
        };
        (
            to_cell(lo[0], self.origin_m[0], self.nx),
            to_cell(hi[0], self.origin_m[0], self.nx),
            to_cell(lo[1], self.origin_m[1], self.ny),
            to_cell(hi[1], self.origin_m[1], self.ny),
        )
    }

    /// Calls `f` on every segment whose cell overlaps the box (a segment may repeat); stops
    /// and returns true as soon as `f` does.
    fn any_near(&self, lo: [f64; 2], hi: [f64; 2], mut f: impl FnMut(&Segment) -> bool) -> bool {
        if self.cells.is_empty() {
            return false;
        }
        let grid_hi = [
            self.origin_m[0] + self.nx as f64 * self.cell_m,
            self.origin_m[1] + self.ny as f64 * self.cell_m,
        ];
        if hi[0] < self.origin_m[0]
            || hi[1] < self.origin_m[1]
            || lo[0] > grid_hi[0]
            || lo[1] > grid_hi[1]
        {
            return false;
        }
        let (x0, x1, y0, y1) = self.cell_range(lo, hi);
        for cy in y0..=y1 {
            for cx in x0..=x1 {
                for &k in &self.cells[cy * self.nx + cx] {
                    if f(&self.segments[k as usize]) {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Whether a disc of `radius_m` at `p` overlaps a wall segment.
    fn clearance_below(&self, p: [f64; 2], radius_m: f64) -> bool {
        let lo = [p[0] - radius_m, p[1] - radius_m];
        let hi = [p[0] + radius_m, p[1] + radius_m];
        self.any_near(lo, hi, |s| {
            point_segment_distance(p, s.a_m, s.b_m) < radius_m - 1e-9
        })
    }

    /// Whether sweeping a disc of `radius_m` from `p0` to `p1` (the chord of the step's arc)
    /// brings it closer than its radius to a wall it was not already that close to. A robot
    /// touching a wall may still move along it or away from it.
    fn blocks_move(&self, p0: [f64; 2], p1: [f64; 2], radius_m: f64) -> bool {
        let lo = [p0[0].min(p1[0]) - radius_m, p0[1].min(p1[1]) - radius_m];
        let hi = [p0[0].max(p1[0]) + radius_m, p0[1].max(p1[1]) + radius_m];
        self.any_near(lo, hi, |s| {
            let d_path = segment_segment_distance(p0, p1, s.a_m, s.b_m);
            d_path < radius_m && d_path < point_segment_distance(p0, s.a_m, s.b_m) - 1e-12
        })
    }

    /// Whether a wall crosses the sight line from `from` to `to` before reaching `to`
    /// (a landmark on a wall's surface stays visible).
    fn occludes(&self, from: [f64; 2], to: [f64; 2]) -> bool {
        let len = sub(to, from);
        let len_m = len[0].hypot(len[1]);
        let t_max = 1.0 - 1e-6 / len_m.max(1e-9);
        let lo = [from[0].min(to[0]), from[1].min(to[1])];
        let hi = [from[0].max(to[0]), from[1].max(to[1])];
        self.any_near(lo, hi, |s| {
            segment_intersection(from, to, s.a_m, s.b_m).is_some_and(|t| t < t_max)
        })
    }
}

// ---------------------------------------------------------------------------------------------
// ROS map_server occupancy maps

/// Why a ROS map could not be loaded.
#[derive(Debug, Error)]
pub enum MapError {
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("map yaml line {line}: {reason}")]
    Yaml { line: usize, reason: String },
    #[error("map yaml: missing key `{0}`")]
    MissingKey(&'static str),
    #[error("map yaml: `{key}` = {value} is invalid ({expected})")]
    InvalidValue {
        key: &'static str,
        value: f64,
        expected: &'static str,
    },
    #[error("pgm image: {0}")]
    Pgm(String),
}

/// An occupancy grid read from a ROS map_server map (YAML + PGM image).
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyMap {
    pub width: usize,
    pub height: usize,
    pub resolution_m: f64,
    /// World position of the lower-left corner of cell (0, 0).
    pub origin_m: [f64; 2],
    /// Row-major from the bottom row (y up), `true` = occupied.
    pub occupied: Vec<bool>,
}

/// The keys of a map_server YAML file.
#[derive(Debug, Clone, PartialEq)]
struct MapYaml {
    image: String,
    resolution_m: f64,
    origin: [f64; 3],
    negate: bool,
    occupied_thresh: f64,
}

impl OccupancyMap {
    /// Loads `map.yaml` and the image it names (relative to the YAML's directory).
    pub fn load(yaml_path: &Path) -> Result<Self, MapError> {
        let text = std::fs::read_to_string(yaml_path).map_err(|source| MapError::Io {
            path: yaml_path.to_path_buf(),
            source,
        })?;
        let yaml = parse_map_yaml(&text)?;
        let image_path = yaml_path
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .join(&yaml.image);
        let bytes = std::fs::read(&image_path).map_err(|source| MapError::Io {
            path: image_path.clone(),
            source,
        })?;
        Self::from_parts(&text, &bytes)
    }

    /// Builds a map from the YAML text and the PGM bytes (P5 binary or P2 ASCII). A cell is
    /// occupied when its occupancy probability exceeds `occupied_thresh` (map_server "trinary"
    /// reading: p = (max − value)/max, or value/max with `negate: 1`).
    pub fn from_parts(yaml_text: &str, pgm_bytes: &[u8]) -> Result<Self, MapError> {
        let yaml = parse_map_yaml(yaml_text)?;
        let (width, height, maxval, pixels) = parse_pgm(pgm_bytes)?;
        let mut occupied = vec![false; width * height];
        for row in 0..height {
            // The image's first row is the top of the map.
            let y = height - 1 - row;
            for x in 0..width {
                let v = f64::from(pixels[row * width + x]) / f64::from(maxval);
                let p = if yaml.negate { v } else { 1.0 - v };
                occupied[y * width + x] = p > yaml.occupied_thresh;
            }
        }
        Ok(Self {
            width,
            height,
            resolution_m: yaml.resolution_m,
            origin_m: [yaml.origin[0], yaml.origin[1]],
            occupied,
        })
    }

    /// Occupied cells merged into rectangles: runs along each row, then identical runs of
    /// consecutive rows joined, so a wall of many cells becomes a few rectangles.
    pub fn to_walls(&self) -> Vec<WallConfig> {
        let res = self.resolution_m;
        let mut open: std::collections::HashMap<(usize, usize), usize> = Default::default();
        let mut rects: Vec<(usize, usize, usize, usize)> = Vec::new(); // x0, x1 (excl), y0, y1 (excl)
        for y in 0..self.height {
            let mut next_open = std::collections::HashMap::new();
            let row = &self.occupied[y * self.width..(y + 1) * self.width];
            let mut x = 0;
            while x < self.width {
                if !row[x] {
                    x += 1;
                    continue;
                }
                let start = x;
                while x < self.width && row[x] {
                    x += 1;
                }
                let key = (start, x);
                let idx = match open.get(&key) {
                    Some(&idx) => {
                        rects[idx].3 = y + 1;
                        idx
                    }
                    None => {
                        rects.push((start, x, y, y + 1));
                        rects.len() - 1
                    }
                };
                next_open.insert(key, idx);
            }
            open = next_open;
        }
        rects
            .into_iter()
            .map(|(x0, x1, y0, y1)| WallConfig::Rect {
                min_x_m: self.origin_m[0] + x0 as f64 * res,
                max_x_m: self.origin_m[0] + x1 as f64 * res,
                min_y_m: self.origin_m[1] + y0 as f64 * res,
                max_y_m: self.origin_m[1] + y1 as f64 * res,
            })
            .collect()
    }
}

fn parse_map_yaml(text: &str) -> Result<MapYaml, MapError> {
    let mut image = None;
    let mut resolution = None;
    let mut origin = None;
    let mut negate = false;
    let mut occupied_thresh = 0.65;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let yaml_err = |reason: String| MapError::Yaml {
            line: line_no,
            reason,
        };
        let (key, value) = line
            .split_once(':')
            .ok_or_else(|| yaml_err(format!("expected `key: value`, got `{line}`")))?;
        let value = value.trim();
        let number = |v: &str| -> Result<f64, MapError> {
            v.trim()
                .parse::<f64>()
                .map_err(|_| yaml_err(format!("`{}` is not a number", v.trim())))
        };
        match key.trim() {
            "image" => image = Some(value.trim_matches(['"', '\'']).to_string()),
            "resolution" => resolution = Some(number(value)?),
            "origin" => {
                let inner = value
                    .strip_prefix('[')
                    .and_then(|v| v.strip_suffix(']'))
                    .ok_or_else(|| yaml_err("origin must be `[x, y, yaw]`".into()))?;
                let parts: Vec<&str> = inner.split(',').collect();
                if parts.len() != 3 {
                    return Err(yaml_err("origin must be `[x, y, yaw]`".into()));
                }
                origin = Some([number(parts[0])?, number(parts[1])?, number(parts[2])?]);
            }
            "negate" => negate = number(value)? != 0.0,
            "occupied_thresh" => occupied_thresh = number(value)?,
            "free_thresh" => {
                number(value)?;
            }
            "mode" => {
                if value.trim_matches(['"', '\'']) != "trinary" {
                    return Err(yaml_err(format!(
                        "mode `{value}` unsupported (trinary only)"
                    )));
                }
            }
            other => return Err(yaml_err(format!("unknown key `{other}`"))),
        }
    }
    let resolution_m = resolution.ok_or(MapError::MissingKey("resolution"))?;
    if !(resolution_m.is_finite() && resolution_m > 0.0) {
        return Err(MapError::InvalidValue {
            key: "resolution",
            value: resolution_m,
            expected: "finite and > 0",
        });
    }
    let origin = origin.ok_or(MapError::MissingKey("origin"))?;
    if !origin.iter().all(|v| v.is_finite()) {
        return Err(MapError::InvalidValue {
            key: "origin",
            value: f64::NAN,
            expected: "finite",
        });
    }
    if origin[2].abs() > 1e-9 {
        return Err(MapError::InvalidValue {
            key: "origin",
            value: origin[2],
            expected: "yaw 0: walls are axis-aligned",
        });
    }
    if !(0.0..=1.0).contains(&occupied_thresh) {
        return Err(MapError::InvalidValue {
            key: "occupied_thresh",
            value: occupied_thresh,
            expected: "in [0, 1]",
        });
    }
    Ok(MapYaml {
        image: image.ok_or(MapError::MissingKey("image"))?,
        resolution_m,
        origin,
        negate,
        occupied_thresh,
    })
}

/// Parses a PGM image (P5 binary with maxval < 256 or ≥ 256, or P2 ASCII) into
/// `(width, height, maxval, pixels)`, pixels row-major from the top row.
fn parse_pgm(bytes: &[u8]) -> Result<(usize, usize, u16, Vec<u16>), MapError> {
    let err = |m: &str| MapError::Pgm(m.to_string());
    let mut pos = 0;
    // Header tokens, skipping whitespace and `#` comments.
    let next_token = |pos: &mut usize| -> Option<String> {
        loop {
            while *pos < bytes.len() && bytes[*pos].is_ascii_whitespace() {
                *pos += 1;
            }
            if *pos < bytes.len() && bytes[*pos] == b'#' {
                while *pos < bytes.len() && bytes[*pos] != b'\n' {
                    *pos += 1;
                }
                continue;
            }
            break;
        }
        let start = *pos;
        while *pos < bytes.len() && !bytes[*pos].is_ascii_whitespace() {
            *pos += 1;
        }
        (start < *pos).then(|| String::from_utf8_lossy(&bytes[start..*pos]).into_owned())
    };
    let magic = next_token(&mut pos).ok_or_else(|| err("empty file"))?;
    let mut header_num = |name: &str| -> Result<usize, MapError> {
        next_token(&mut pos)
            .and_then(|t| t.parse::<usize>().ok())
            .ok_or_else(|| MapError::Pgm(format!("bad or missing {name}")))
    };
    let width = header_num("width")?;
    let height = header_num("height")?;
    let maxval = header_num("maxval")?;
    if width == 0 || height == 0 || !(1..=65535).contains(&maxval) {
        return Err(err("width, height must be > 0 and maxval in 1..=65535"));
    }
    let n = width
        .checked_mul(height)
        .ok_or_else(|| err("image too large"))?;
    // Never reserve more than the file can hold: a header may claim any size.
    let mut pixels = Vec::with_capacity(n.min(bytes.len()));
    match magic.as_str() {
        "P5" => {
            pos += 1; // single whitespace after maxval
            let bpp = if maxval < 256 { 1 } else { 2 };
            let data = n
                .checked_mul(bpp)
                .and_then(|len| pos.checked_add(len))
                .and_then(|end| bytes.get(pos..end))
                .ok_or_else(|| err("truncated pixel data"))?;
            if bpp == 1 {
                pixels.extend(data.iter().map(|&b| u16::from(b)));
            } else {
                pixels.extend(
                    data.chunks_exact(2)
                        .map(|c| u16::from_be_bytes([c[0], c[1]])),
                );
            }
        }
        "P2" => {
            for _ in 0..n {
                let v = next_token(&mut pos)
                    .and_then(|t| t.parse::<u16>().ok())
                    .ok_or_else(|| err("truncated or bad ASCII pixel data"))?;
                pixels.push(v);
            }
        }
        other => {
            return Err(MapError::Pgm(format!(
                "unsupported magic `{other}` (P5 or P2)"
            )))
        }
    }
    if pixels.iter().any(|&v| usize::from(v) > maxval) {
        return Err(err("pixel above maxval"));
    }
    Ok((width, height, maxval as u16, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_6};

    fn one_robot(start: Pose2) -> WorldConfig {
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

    #[test]
    fn straight_when_wheels_travel_equally() {
        // seed 000 eqs. 32–33
        let p = diff_drive(Pose2::new(1.0, 2.0, FRAC_PI_6), 0.5, 0.5, 0.3);
        assert_relative_eq!(p.x_m, 1.0 + 0.5 * FRAC_PI_6.cos(), epsilon = 1e-12);
        assert_relative_eq!(p.y_m, 2.0 + 0.5 * FRAC_PI_6.sin(), epsilon = 1e-12);
        assert_relative_eq!(p.theta_rad, FRAC_PI_6, epsilon = 1e-12);
    }

    #[test]
    fn turning_in_place_keeps_position() {
        // r = −l: β = 2r/W, R = l/β = −W/2, the centre of rotation is the robot itself.
        let w = 0.4;
        let p = diff_drive(Pose2::new(3.0, -1.0, 0.2), -0.1, 0.1, w);
        assert_relative_eq!(p.x_m, 3.0, epsilon = 1e-12);
        assert_relative_eq!(p.y_m, -1.0, epsilon = 1e-12);
        assert_relative_eq!(p.theta_rad, 0.2 + 0.2 / w, epsilon = 1e-12);
        // Negative turn wraps into [0, 2π) (eq. 30).
        let q = diff_drive(Pose2::new(0.0, 0.0, 0.0), 0.1, -0.1, w);
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
        let p = diff_drive(Pose2::new(x, y, th), l, r, w);
        assert_relative_eq!(p.x_m, x2, epsilon = 1e-12);
        assert_relative_eq!(p.y_m, y2, epsilon = 1e-12);
        assert_relative_eq!(p.theta_rad, th2, epsilon = 1e-12);
        // A quarter circle of radius 1 m from the origin ends at (1, 1) facing +y.
        let (l, r) = wheel_travel(1.0, 1.0, FRAC_PI_2, 0.3);
        let q = diff_drive(Pose2::default(), l, r, 0.3);
        assert_relative_eq!(q.x_m, 1.0, epsilon = 1e-12);
        assert_relative_eq!(q.y_m, 1.0, epsilon = 1e-12);
        assert_relative_eq!(q.theta_rad, FRAC_PI_2, epsilon = 1e-12);
    }

    #[test]
    fn wrap_angle_range() {
        assert_relative_eq!(wrap_angle(PI), PI);
        assert_relative_eq!(wrap_angle(-PI), PI);
        assert_relative_eq!(wrap_angle(3.0 * PI / 2.0), -FRAC_PI_2, epsilon = 1e-12);
        assert_relative_eq!(wrap_angle(-7.0), -7.0 + TAU, epsilon = 1e-12);
    }

    #[test]
    fn world_step_moves_without_noise() {
        let mut world = World::new(one_robot(Pose2::default()), 1).unwrap();
        for _ in 0..10 {
            let out = world.step(&[(1.0, 0.0)]);
            assert_eq!(out.len(), 1);
            assert_eq!(out[0].truth.collided, 0);
            assert_eq!(out[0].sensor.robot_id, 7);
            assert_eq!(out[0].sensor.v_mps, 1.0);
            assert_eq!(out[0].sensor.stamp_ns, 0);
        }
        assert_relative_eq!(world.poses()[0].x_m, 1.0, epsilon = 1e-12);
        assert_eq!(world.step_count(), 10);
        assert_relative_eq!(world.sim_time_s(), 1.0, epsilon = 1e-12);
    }

    #[test]
    fn wall_blocks_robot() {
        let mut cfg = one_robot(Pose2::default());
        cfg.walls = vec![
            WallConfig::Rect {
                min_x_m: 1.0,
                min_y_m: -1.0,
                max_x_m: 1.2,
                max_y_m: 1.0,
            },
            WallConfig::Polyline {
                points_m: vec![[-1.0, -1.0], [-1.0, 1.0]],
                closed: false,
            },
        ];
        let mut world = World::new(cfg, 3).unwrap();
        let mut collided = false;
        for _ in 0..50 {
            let out = world.step(&[(1.0, 0.0)]);
            collided |= out[0].truth.collided == 1;
            if out[0].truth.collided == 1 {
                assert_eq!(out[0].sensor.v_mps, 0.0);
            }
        }
        assert!(collided);
        let x = world.poses()[0].x_m;
        assert!(x <= 1.0 - 0.2 + 1e-9, "robot passed the wall: x = {x}");
        assert!(x > 0.6, "robot stopped far from the wall: x = {x}");
        // It can still turn in place (8 × π/8) and drive away, until the thin polyline stops it.
        for _ in 0..8 {
            world.step(&[(0.0, PI / 8.0 / world.config().dt_secs)]);
        }
        assert_relative_eq!(world.poses()[0].theta_rad, PI, epsilon = 1e-9);
        for _ in 0..60 {
            world.step(&[(1.0, 0.0)]);
        }
        let x = world.poses()[0].x_m;
        assert!(x >= -1.0 + 0.2 - 1e-9, "robot passed the polyline: x = {x}");
        assert!(x < -0.6, "robot stopped far from the polyline: x = {x}");
        assert!(world.is_free(world.poses()[0].x_m, world.poses()[0].y_m));
    }

    #[test]
    fn fast_robot_does_not_tunnel_through_thin_wall() {
        let mut cfg = one_robot(Pose2::default());
        cfg.robot_radius_m = 0.05;
        cfg.dt_secs = 1.0;
        cfg.walls = vec![WallConfig::Polyline {
            points_m: vec![[0.5, -1.0], [0.5, 1.0]],
            closed: false,
        }];
        let mut world = World::new(cfg, 3).unwrap();
        let out = world.step(&[(2.0, 0.0)]); // would jump to x = 2
        assert_eq!(out[0].truth.collided, 1);
        assert_eq!(world.poses()[0].x_m, 0.0);
    }

    #[test]
    fn start_inside_wall_is_an_error() {
        let mut cfg = one_robot(Pose2::new(1.1, 0.0, 0.0));
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

    #[test]
    fn observations_within_range_nearest_first() {
        let mut cfg = one_robot(Pose2::new(0.0, 0.0, FRAC_PI_2));
        cfg.sensor_range_m = 3.0;
        cfg.landmarks = vec![
            Landmark {
                x_m: 2.5,
                y_m: 0.0,
                signature: 1,
            },
            Landmark {
                x_m: 0.0,
                y_m: 1.0,
                signature: 2,
            },
            Landmark {
                x_m: 3.5,
                y_m: 0.0,
                signature: 3,
            },
            Landmark {
                x_m: -2.0,
                y_m: -2.0,
                signature: 4,
            },
        ];
        let mut world = World::new(cfg, 0).unwrap();
        let out = world.step(&[(0.0, 0.0)]);
        let obs = out[0].sensor.observations();
        assert_eq!(obs.len(), 3);
        assert_eq!(
            obs.iter().map(|o| o.signature).collect::<Vec<_>>(),
            vec![2, 1, 4]
        );
        assert_relative_eq!(obs[0].range_m, 1.0, epsilon = 1e-6);
        assert_relative_eq!(obs[0].bearing_rad, 0.0, epsilon = 1e-6);
        assert_relative_eq!(obs[1].bearing_rad, -FRAC_PI_2 as f32, epsilon = 1e-6);
        assert_relative_eq!(obs[2].bearing_rad, (PI * 0.75) as f32, epsilon = 1e-6);
        assert!(obs.iter().all(|o| o.range_m <= 3.0));
    }

    #[test]
    fn field_of_view_and_line_of_sight_hide_landmarks() {
        let mut cfg = one_robot(Pose2::default());
        cfg.field_of_view_rad = Some(PI); // front half only
        cfg.landmarks = vec![
            Landmark {
                x_m: 2.0,
                y_m: 0.0,
                signature: 1,
            },
            Landmark {
                x_m: -2.0,
                y_m: 0.0,
                signature: 2,
            },
            Landmark {
                x_m: 0.0,
                y_m: 3.0,
                signature: 3,
            },
        ];
        cfg.walls = vec![WallConfig::Polyline {
            points_m: vec![[-1.0, 1.5], [1.0, 1.5]],
            closed: false,
        }];
        let mut world = World::new(cfg.clone(), 0).unwrap();
        let out = world.step(&[]);
        let sigs: Vec<u32> = out[0]
            .sensor
            .observations()
            .iter()
            .map(|o| o.signature)
            .collect();
        assert_eq!(sigs, vec![1]);
        cfg.line_of_sight = false;
        let mut world = World::new(cfg, 0).unwrap();
        let out = world.step(&[]);
        let sigs: Vec<u32> = out[0]
            .sensor
            .observations()
            .iter()
            .map(|o| o.signature)
            .collect();
        assert_eq!(sigs, vec![1, 3]);
    }

    #[test]
    fn at_most_max_observations() {
        let mut cfg = one_robot(Pose2::default());
        cfg.landmarks = (0..50)
            .map(|i| Landmark {
                x_m: 0.05 * (i + 1) as f64,
                y_m: 0.5,
                signature: i,
            })
            .collect();
        let mut world = World::new(cfg, 0).unwrap();
        let out = world.step(&[]);
        assert_eq!(out[0].sensor.count as usize, MAX_OBSERVATIONS);
        let r: Vec<f32> = out[0]
            .sensor
            .observations()
            .iter()
            .map(|o| o.range_m)
            .collect();
        assert!(r.windows(2).all(|w| w[0] <= w[1]));
    }

    fn noisy_config() -> WorldConfig {
        WorldConfig {
            robots: vec![
                RobotConfig {
                    id: 1,
                    start: Pose2::default(),
                    noise: None,
                },
                RobotConfig {
                    id: 2,
                    start: Pose2::new(2.0, 2.0, 1.0),
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
            .any(|o| o.sensor.v_mps != 0.5 && o.sensor.robot_id == 1));
    }

    #[test]
    fn odometry_noise_matches_velocity_model() {
        // σ_v² = α1 v² + α2 ω² (seed 001 Algorithm 1 line 5), checked by sample variance.
        let mut cfg = one_robot(Pose2::default());
        cfg.noise = NoiseConfig {
            alpha1: 0.04,
            alpha2: 0.0,
            alpha3: 0.0,
            alpha4: 0.09,
            ..NoiseConfig::default()
        };
        let mut world = World::new(cfg, 9).unwrap();
        let n = 4000;
        let (mut sv, mut sv2, mut sw, mut sw2) = (0.0, 0.0, 0.0, 0.0);
        for _ in 0..n {
            let o = world.step(&[(1.0, 0.5)])[0].sensor;
            sv += o.v_mps;
            sv2 += o.v_mps * o.v_mps;
            sw += o.omega_radps;
            sw2 += o.omega_radps * o.omega_radps;
        }
        let nf = n as f64;
        let var_v = sv2 / nf - (sv / nf).powi(2);
        let var_w = sw2 / nf - (sw / nf).powi(2);
        assert!((var_v / 0.04 - 1.0).abs() < 0.1, "var_v = {var_v}");
        assert!((var_w / (0.09 * 0.25) - 1.0).abs() < 0.1, "var_w = {var_w}");
        assert!((sv / nf - 1.0).abs() < 0.02);
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
        cfg.dt_secs = 0.0;
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

    #[test]
    fn config_rejects_unknown_fields() {
        use serde::de::value::{Error as DeError, MapDeserializer};
        let ok: Result<NoiseConfig, DeError> = NoiseConfig::deserialize(MapDeserializer::new(
            vec![("range_sigma_m", 0.1)].into_iter(),
        ));
        let ok = ok.unwrap();
        assert_eq!(ok.range_sigma_m, 0.1);
        assert_eq!(ok.alpha1, NoiseConfig::default().alpha1);
        let bad: Result<NoiseConfig, DeError> =
            NoiseConfig::deserialize(MapDeserializer::new(vec![("range_sigma", 0.1)].into_iter()));
        assert!(bad.unwrap_err().to_string().contains("range_sigma"));
    }

    const MAP_YAML: &str = "image: map.pgm\nresolution: 0.5\norigin: [-1.0, -2.0, 0.0]\n\
                            negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196 # comment\n";

    #[test]
    fn ros_map_p2_becomes_merged_rectangles() {
        // 4×3 image, top row first; 0 = black = occupied.
        let pgm = b"P2\n# made by hand\n4 3\n255\n0 0 255 255\n0 0 255 254\n255 255 255 0\n";
        let map = OccupancyMap::from_parts(MAP_YAML, pgm).unwrap();
        assert_eq!((map.width, map.height), (4, 3));
        // Bottom row (image row 2): only x = 3 occupied.
        assert_eq!(&map.occupied[0..4], &[false, false, false, true]);
        let walls = map.to_walls();
        assert_eq!(walls.len(), 2);
        assert!(walls.contains(&WallConfig::Rect {
            min_x_m: -1.0,
            max_x_m: 0.0,
            min_y_m: -1.5,
            max_y_m: -0.5,
        }));
        assert!(walls.contains(&WallConfig::Rect {
            min_x_m: 0.5,
            max_x_m: 1.0,
            min_y_m: -2.0,
            max_y_m: -1.5,
        }));
        // A world built from them blocks a robot.
        let mut cfg = one_robot(Pose2::new(-0.5, -3.0, FRAC_PI_2));
        cfg.robot_radius_m = 0.1;
        cfg.walls = walls;
        let mut world = World::new(cfg, 0).unwrap();
        for _ in 0..40 {
            world.step(&[(1.0, 0.0)]);
        }
        assert!(world.poses()[0].y_m <= -1.5 - 0.1 + 1e-9);
    }

    #[test]
    fn ros_map_p5_and_errors() {
        let mut pgm = b"P5 2 2 255\n".to_vec();
        pgm.extend([0u8, 255, 255, 10]);
        let map = OccupancyMap::from_parts(MAP_YAML, &pgm).unwrap();
        assert_eq!(map.occupied, vec![false, true, true, false]);
        let negated = MAP_YAML.replace("negate: 0", "negate: 1");
        let map = OccupancyMap::from_parts(&negated, &pgm).unwrap();
        assert_eq!(map.occupied, vec![true, false, false, true]);
        assert!(matches!(
            OccupancyMap::from_parts(MAP_YAML, b"P5 2 2 255\n\x00"),
            Err(MapError::Pgm(_))
        ));
        assert!(matches!(
            OccupancyMap::from_parts("image: a.pgm\nresolution: 0.1\n", &pgm),
            Err(MapError::MissingKey("origin"))
        ));
        assert!(matches!(
            OccupancyMap::from_parts(&format!("{MAP_YAML}bogus: 1\n"), &pgm),
            Err(MapError::Yaml { line: 7, .. })
        ));
    }
}
