//! Messages between the robot roles: fixed-size `#[repr(C)]`, `ZeroCopySend`, each with a robot id
//! and a monotonic stamp (ns, CLOCK_MONOTONIC). Type names carry the layout version.
//!
//! Services (robot `r<ID>` of world `W`, named by `pheromone_roles::RobotServices`):
//! `pheromone/W/r<ID>/pose` ([`PoseMsg`]), `pheromone/W/r<ID>/cmd` ([`CmdMsg`]),
//! `pheromone/W/r<ID>/status` ([`FollowerStatusMsg`]), `sim/W/r<ID>/sensors` ([`SensorMsg`]),
//! `sim/W/r<ID>/truth` ([`TruthMsg`]), `sim/W/r<ID>/laser` ([`LaserMsg`]); each has a `…-ready` event that wakes its receivers.

#![warn(missing_docs)]

pub mod geometry;

pub use geometry::{sinc, sinc_derivative, Landmark, NoiseConfig, Segment, WorldPose};

/// Most landmark observations one sensor message carries; the world reports the nearest ones.
pub const MAX_OBSERVATIONS: usize = 32;

/// Pose estimate with its 3×3 covariance (row-major over x, y, θ).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct PoseMsg {
    /// Monotonic time (ns, CLOCK_MONOTONIC) at which the estimate was published.
    pub stamp_ns: u64,
    /// World step this estimate belongs to.
    pub step: u64,
    /// Robot whose pose this is.
    pub robot_id: u32,
    /// Landmarks associated in this update.
    pub landmarks_used: u32,
    /// Estimated x position in the world frame (m).
    pub x_m: f64,
    /// Estimated y position in the world frame (m).
    pub y_m: f64,
    /// Estimated heading (rad, counter-clockwise from +x).
    pub theta_rad: f64,
    /// Covariance of (x, y, θ), row-major 3×3 (m², m·rad, rad²); symmetric.
    pub cov: [f64; 9],
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(PoseMsg, "PoseMsg", size = 120, align = 8);

impl PoseMsg {
    /// The estimate (mean and covariance) without robot, step and stamp: what the one
    /// pose → deposit rule of `pheromone_field::kernel::pose` reads.
    pub fn estimate(&self) -> pheromone_field::PoseEstimate {
        pheromone_field::PoseEstimate {
            x_m: self.x_m,
            y_m: self.y_m,
            theta_rad: self.theta_rad,
            cov: self.cov,
        }
    }

    /// The position block Σxy as `[xx, xy, yy]`.
    pub fn cov_xy(&self) -> [f64; 3] {
        [self.cov[0], self.cov[1], self.cov[4]]
    }
}

/// One landmark seen by a robot: range (m), bearing (rad, relative to the heading), signature.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct LandmarkObs {
    /// Measured (noisy) distance to the landmark (m, ≥ 0).
    pub range_m: f32,
    /// Measured (noisy) bearing of the landmark relative to the heading (rad, in (−π, π]).
    pub bearing_rad: f32,
    /// The landmark's signature (0 = no signature / ambiguous).
    pub signature: u32,
    /// Padding for the `#[repr(C)]` layout; always 0.
    pub _pad: u32,
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(LandmarkObs, "LandmarkObs", size = 16, align = 4);

/// What the world tells one robot after a step: the (noisy) velocity it executed — the control
/// input of the velocity motion model — and the landmarks in sensor range.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct SensorMsg {
    /// Monotonic time (ns, CLOCK_MONOTONIC) at which the world published the step.
    pub stamp_ns: u64,
    /// World step these readings belong to.
    pub step: u64,
    /// Robot the readings are for.
    pub robot_id: u32,
    /// Valid entries of `observations`.
    pub count: u32,
    /// Simulated time at the end of the step (s).
    pub sim_time_s: f64,
    /// Length of the step (s).
    pub dt_s: f64,
    /// Odometry: linear velocity measured over the last step (m/s, with control noise).
    pub v_m_per_s: f64,
    /// Odometry: angular velocity measured over the last step (rad/s, with control noise).
    pub omega_rad_per_s: f64,
    /// Landmarks in sensor range, nearest first; only the first `count` are valid (see
    /// [`SensorMsg::observations`]).
    pub observations: [LandmarkObs; MAX_OBSERVATIONS],
}

// repr(C): numbers and an array of `LandmarkObs` only.
pheromone_field::wire_type!(
    SensorMsg,
    "SensorMsg",
    size = 56 + 16 * MAX_OBSERVATIONS,
    align = 8
);

impl Default for SensorMsg {
    fn default() -> Self {
        Self {
            stamp_ns: 0,
            step: 0,
            robot_id: 0,
            count: 0,
            sim_time_s: 0.0,
            dt_s: 0.0,
            v_m_per_s: 0.0,
            omega_rad_per_s: 0.0,
            observations: [LandmarkObs::default(); MAX_OBSERVATIONS],
        }
    }
}

impl SensorMsg {
    /// The valid observations: the first `count` entries (at most [`MAX_OBSERVATIONS`]).
    pub fn observations(&self) -> &[LandmarkObs] {
        &self.observations[..(self.count as usize).min(MAX_OBSERVATIONS)]
    }
}

/// The true pose of a robot (for metrics and pictures; robots' own roles never read it).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct TruthMsg {
    /// Monotonic time (ns, CLOCK_MONOTONIC) at which the world published the step.
    pub stamp_ns: u64,
    /// World step this pose is the outcome of.
    pub step: u64,
    /// Robot whose true pose this is.
    pub robot_id: u32,
    /// 1 if the last command was blocked by a wall.
    pub collided: u32,
    /// Simulated time at the end of the step (s).
    pub sim_time_s: f64,
    /// True x position in the world frame (m).
    pub x_m: f64,
    /// True y position in the world frame (m).
    pub y_m: f64,
    /// True heading (rad, counter-clockwise from +x).
    pub theta_rad: f64,
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(TruthMsg, "TruthMsg", size = 56, align = 8);

/// Motion command for one robot: linear and angular velocity.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct CmdMsg {
    /// Monotonic time (ns, CLOCK_MONOTONIC) at which the command was sent.
    pub stamp_ns: u64,
    /// The world step this command answers (lockstep clock).
    pub step: u64,
    /// Robot the command is for.
    pub robot_id: u32,
    /// Padding for the `#[repr(C)]` layout; always 0.
    pub _pad: u32,
    /// Commanded linear velocity (m/s, positive forwards); the world clamps it to the robot's
    /// top speed.
    pub v_m_per_s: f64,
    /// Commanded angular velocity (rad/s, positive counter-clockwise); the world clamps it to
    /// the robot's top turn rate.
    pub omega_rad_per_s: f64,
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(CmdMsg, "CmdMsg", size = 40, align = 8);

/// What a follower is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u32)]
pub enum FollowerState {
    /// Climbing a trail.
    Following = 0,
    /// The sensed level fell below the threshold: the trail was abandoned.
    TrailAbandoned = 1,
    /// Looking for pheromone / exploring.
    Exploring = 2,
    /// Gave a trail up ("leader lost", seed 000 L12) and explores on its own.
    LeaderLost = 3,
}

impl FollowerState {
    /// The state whose `#[repr(u32)]` code is `code` (as carried in
    /// [`FollowerStatusMsg::state`]); `None` for an unknown code.
    pub fn from_code(code: u32) -> Option<Self> {
        Some(match code {
            0 => FollowerState::Following,
            1 => FollowerState::TrailAbandoned,
            2 => FollowerState::Exploring,
            3 => FollowerState::LeaderLost,
            _ => return None,
        })
    }

    /// The snake_case name used in logs and reports (the same as its serde name).
    pub fn name(self) -> &'static str {
        match self {
            FollowerState::Following => "following",
            FollowerState::TrailAbandoned => "trail_abandoned",
            FollowerState::Exploring => "exploring",
            FollowerState::LeaderLost => "leader_lost",
        }
    }
}

/// A follower's status, published with every command.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct FollowerStatusMsg {
    /// Monotonic time (ns, CLOCK_MONOTONIC) at which the status was sent.
    pub stamp_ns: u64,
    /// The world step the accompanying command answers.
    pub step: u64,
    /// The follower reporting.
    pub robot_id: u32,
    /// [`FollowerState`] code; decode with [`FollowerState::from_code`].
    pub state: u32,
    /// Pheromone level the follower senses at its pose.
    pub sensed_level: f32,
    /// Padding for the `#[repr(C)]` layout; always 0.
    pub _pad: u32,
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(FollowerStatusMsg, "FollowerStatusMsg", size = 32, align = 8);

/// Most rays one [`ScanMsg`] carries (seed 004's range sensor).
pub const MAX_RAYS: usize = 64;

/// One range scan of a robot (seed 004, `[mapping]`): `count` rays from `angle_min_rad` (relative
/// to the heading) every `angle_step_rad`; ray `i` measured `ranges_m[i]` and hit a wall when bit
/// `i` of `hits` is set (otherwise the ray saw nothing within `range_max_m` and
/// `ranges_m[i] = range_max_m`). Published by the world on `sim/W/r<ID>/scan` when the scenario
/// maps.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct ScanMsg {
    /// Monotonic time (ns, CLOCK_MONOTONIC) at which the world published the step.
    pub stamp_ns: u64,
    /// World step the scan was taken at.
    pub step: u64,
    /// Robot that took the scan.
    pub robot_id: u32,
    /// Valid entries of `ranges_m`.
    pub count: u32,
    /// Bearing of ray 0 relative to the heading (rad).
    pub angle_min_rad: f32,
    /// Angle between consecutive rays (rad).
    pub angle_step_rad: f32,
    /// Longest range the sensor measures (m); rays that hit nothing report it.
    pub range_max_m: f32,
    /// Padding for the `#[repr(C)]` layout; always 0.
    pub _pad: u32,
    /// Bit i: ray i hit a wall.
    pub hits: u64,
    /// Measured range of each ray (m); only the first `count` are valid.
    pub ranges_m: [f32; MAX_RAYS],
}

// repr(C): numbers and an array of numbers only.
pheromone_field::wire_type!(ScanMsg, "ScanMsg", size = 48 + 4 * MAX_RAYS, align = 8);

impl Default for ScanMsg {
    fn default() -> Self {
        Self {
            stamp_ns: 0,
            step: 0,
            robot_id: 0,
            count: 0,
            angle_min_rad: 0.0,
            angle_step_rad: 0.0,
            range_max_m: 0.0,
            _pad: 0,
            hits: 0,
            ranges_m: [0.0; MAX_RAYS],
        }
    }
}

impl ScanMsg {
    /// The valid rays as (bearing relative to the heading, range, hit).
    pub fn rays(&self) -> impl Iterator<Item = (f32, f32, bool)> + '_ {
        let n = (self.count as usize).min(MAX_RAYS);
        (0..n).map(move |i| {
            (
                self.angle_min_rad + i as f32 * self.angle_step_rad,
                self.ranges_m[i],
                self.hits >> i & 1 == 1,
            )
        })
    }
}

/// Most beams one [`LaserMsg`] carries (seed 000 Table 1's scanner has 129: 240° every 1.875°).
pub const MAX_LASER_BEAMS: usize = 256;

/// One scan of a robot's laser range scanner (seed 000 Table 1, a simulated URG-04LX): `count`
/// beams from `angle_min_rad` (relative to the heading) every `angle_step_rad`. Beam `i`
/// measured `ranges_m[i]` when bit `i % 64` of `returns[i / 64]` is set; otherwise it saw no
/// wall within `range_max_m` and `ranges_m[i] = range_max_m`. Published by the world on
/// `sim/W/r<ID>/laser` (before the step's [`SensorMsg`]) when the world has a laser.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct LaserMsg {
    /// Monotonic time (ns, CLOCK_MONOTONIC) at which the world published the step.
    pub stamp_ns: u64,
    /// World step the scan was taken at.
    pub step: u64,
    /// Robot that took the scan.
    pub robot_id: u32,
    /// Valid entries of `ranges_m`.
    pub count: u32,
    /// Bearing of beam 0 relative to the heading (rad).
    pub angle_min_rad: f32,
    /// Angle between consecutive beams (rad).
    pub angle_step_rad: f32,
    /// Shortest range the scanner measures (m).
    pub range_min_m: f32,
    /// Longest range the scanner measures (m); beams without a return report it.
    pub range_max_m: f32,
    /// Bit i % 64 of word i / 64: beam i returned from a wall.
    pub returns: [u64; MAX_LASER_BEAMS / 64],
    /// Measured range of each beam (m); only the first `count` are valid.
    pub ranges_m: [f32; MAX_LASER_BEAMS],
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(
    LaserMsg,
    "LaserMsg",
    size = 40 + 8 * (MAX_LASER_BEAMS / 64) + 4 * MAX_LASER_BEAMS,
    align = 8
);

impl Default for LaserMsg {
    fn default() -> Self {
        Self {
            stamp_ns: 0,
            step: 0,
            robot_id: 0,
            count: 0,
            angle_min_rad: 0.0,
            angle_step_rad: 0.0,
            range_min_m: 0.0,
            range_max_m: 0.0,
            returns: [0; MAX_LASER_BEAMS / 64],
            ranges_m: [0.0; MAX_LASER_BEAMS],
        }
    }
}

impl LaserMsg {
    /// Whether beam `i` returned from a wall.
    pub fn returned(&self, i: usize) -> bool {
        i < MAX_LASER_BEAMS && self.returns[i / 64] >> (i % 64) & 1 == 1
    }

    /// Marks beam `i` (< [`MAX_LASER_BEAMS`]) as returned from a wall.
    pub fn set_returned(&mut self, i: usize) {
        self.returns[i / 64] |= 1 << (i % 64);
    }

    /// The valid beams as (bearing relative to the heading, range, returned).
    pub fn beams(&self) -> impl Iterator<Item = (f32, f32, bool)> + '_ {
        let n = (self.count as usize).min(MAX_LASER_BEAMS);
        (0..n).map(move |i| {
            (
                self.angle_min_rad + i as f32 * self.angle_step_rad,
                self.ranges_m[i],
                self.returned(i),
            )
        })
    }
}

/// Most robots one [`RendezvousMsg`] lists.
pub const MAX_PEERS: usize = 16;

/// A robot within R_C as the observer measures it (noisy): distance d_ij, the bearing of the
/// peer relative to the observer's heading, and the peer's heading relative to the observer's.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct PeerObs {
    /// The observed peer.
    pub robot_id: u32,
    /// Padding for the `#[repr(C)]` layout; always 0.
    pub _pad: u32,
    /// Measured distance d_ij to the peer (m).
    pub range_m: f64,
    /// Measured bearing of the peer relative to the observer's heading (rad, in (−π, π]).
    pub bearing_rad: f64,
    /// Measured heading of the peer relative to the observer's heading (rad, in (−π, π]).
    pub heading_rad: f64,
}

// repr(C): numbers only.
pheromone_field::wire_type!(PeerObs, "PeerObs", size = 32, align = 8);

/// The robots within R_C of one robot after a step (seed 004's rendezvous measurement),
/// published by the world on `sim/W/r<ID>/rendezvous` when the scenario maps.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct RendezvousMsg {
    /// Monotonic time (ns, CLOCK_MONOTONIC) at which the world published the step.
    pub stamp_ns: u64,
    /// World step the measurement was taken at.
    pub step: u64,
    /// The observing robot.
    pub robot_id: u32,
    /// Valid entries of `peers`, by robot id.
    pub count: u32,
    /// The peers within R_C; only the first `count` are valid (see [`RendezvousMsg::peers`]).
    pub peers: [PeerObs; MAX_PEERS],
}

// repr(C): numbers and an array of `PeerObs` only.
pheromone_field::wire_type!(
    RendezvousMsg,
    "RendezvousMsg",
    size = 24 + 32 * MAX_PEERS,
    align = 8
);

impl Default for RendezvousMsg {
    fn default() -> Self {
        Self {
            stamp_ns: 0,
            step: 0,
            robot_id: 0,
            count: 0,
            peers: [PeerObs::default(); MAX_PEERS],
        }
    }
}

impl RendezvousMsg {
    /// The valid peer observations: the first `count` entries (at most [`MAX_PEERS`]).
    pub fn peers(&self) -> &[PeerObs] {
        &self.peers[..(self.count as usize).min(MAX_PEERS)]
    }
}

// ---- Planar geometry shared by the roles ----

/// Wraps an angle to (−π, π].
pub fn wrap_angle(angle_rad: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let a = (angle_rad + PI).rem_euclid(TAU) - PI;
    if a <= -PI {
        a + TAU
    } else {
        a
    }
}

/// A true pose as a pose message with zero covariance (a leader steered by its operator).
pub fn truth_as_pose(t: &TruthMsg) -> PoseMsg {
    PoseMsg {
        step: t.step,
        robot_id: t.robot_id,
        x_m: t.x_m,
        y_m: t.y_m,
        theta_rad: t.theta_rad,
        ..PoseMsg::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI, TAU};

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12
    }

    #[test]
    fn wrap_angle_range() {
        assert_eq!(wrap_angle(PI), PI);
        assert_eq!(wrap_angle(-PI), PI);
        assert!(close(wrap_angle(3.0 * PI / 2.0), -FRAC_PI_2));
        assert!(close(wrap_angle(-7.0), -7.0 + TAU));
    }
}
