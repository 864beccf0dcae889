//! The `route` strategy: a leader driven through waypoints, as the tele-operated or planned
//! leader of seed 000. It ignores the field.

use pheromone_field::{FrameView, SamplePose};
use serde::{Deserialize, Serialize};

use super::{
    check_nonneg, check_positive, invalid, wrap_angle, Decision, FollowerConfigError,
    FollowerStrategy, StrategyKind,
};
use pheromone_messages::FollowerState;

/// Settings of the `route` strategy: a leader that drives through waypoints, as the
/// tele-operated or planned leader of seed 000 does. It ignores the field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RouteConfig {
    /// Waypoints [x, y] (m), driven in order.
    pub waypoints: Vec<[f64; 2]>,
    #[serde(alias = "v_mps")]
    pub v_m_per_s: f64,
    /// A waypoint counts as reached within this distance (m).
    pub reach_m: f64,
    /// Proportional heading gain (1/s).
    pub heading_gain_per_s: f64,
    #[serde(alias = "omega_max_radps")]
    pub omega_max_rad_per_s: f64,
    /// Start driving only after this much time (s).
    pub start_after_s: f64,
}

impl Default for RouteConfig {
    fn default() -> Self {
        Self {
            waypoints: Vec::new(),
            v_m_per_s: 0.3,
            reach_m: 0.2,
            heading_gain_per_s: 2.0,
            omega_max_rad_per_s: 1.0,
            start_after_s: 0.0,
        }
    }
}

impl RouteConfig {
    pub fn validate(&self) -> Result<(), FollowerConfigError> {
        for (i, w) in self.waypoints.iter().enumerate() {
            if !(w[0].is_finite() && w[1].is_finite()) {
                return Err(invalid(
                    &format!("route.waypoints[{i}]"),
                    format!("{w:?}"),
                    "must be finite",
                ));
            }
        }
        check_nonneg("route.v_m_per_s", self.v_m_per_s)?;
        check_positive("route.reach_m", self.reach_m)?;
        check_nonneg("route.heading_gain_per_s", self.heading_gain_per_s)?;
        check_positive("route.omega_max_rad_per_s", self.omega_max_rad_per_s)?;
        check_nonneg("route.start_after_s", self.start_after_s)?;
        Ok(())
    }
}

/// Drives through the waypoints; stops at the last one. Turns on the spot when the next
/// waypoint is more than 90° off.
#[derive(Debug, Clone)]
pub struct RouteFollower {
    channel: usize,
    config: RouteConfig,
    next: usize,
    elapsed_s: f64,
}

impl RouteFollower {
    pub fn new(channel: usize, config: RouteConfig) -> Result<Self, FollowerConfigError> {
        config.validate()?;
        Ok(Self {
            channel,
            config,
            next: 0,
            elapsed_s: 0.0,
        })
    }

    /// Index of the waypoint driven to (= the number of waypoints once the route is done).
    pub fn next_waypoint(&self) -> usize {
        self.next
    }
}

impl FollowerStrategy for RouteFollower {
    fn name(&self) -> &'static str {
        StrategyKind::Route.name()
    }

    fn channel(&self) -> usize {
        self.channel
    }

    fn decide(&mut self, frame: &FrameView<'_>, pose: SamplePose, dt_s: f64) -> Decision {
        let level = frame.value(self.channel, pose.x_m, pose.y_m);
        self.elapsed_s += dt_s;
        if self.elapsed_s < self.config.start_after_s - 1e-9 {
            return Decision::stop(FollowerState::Following, level);
        }
        let (x, y) = (pose.x_m as f64, pose.y_m as f64);
        while let Some(w) = self.config.waypoints.get(self.next) {
            if (w[0] - x).hypot(w[1] - y) > self.config.reach_m {
                break;
            }
            self.next += 1;
        }
        let Some(w) = self.config.waypoints.get(self.next) else {
            return Decision::stop(FollowerState::Following, level);
        };
        let err = wrap_angle((w[1] - y).atan2(w[0] - x) - pose.theta_rad as f64);
        let c = &self.config;
        Decision {
            v_m_per_s: c.v_m_per_s * err.cos().max(0.0),
            omega_rad_per_s: (c.heading_gain_per_s * err)
                .clamp(-c.omega_max_rad_per_s, c.omega_max_rad_per_s),
            state: FollowerState::Following,
            sensed_level: level,
        }
    }

    fn reset(&mut self) {
        self.next = 0;
        self.elapsed_s = 0.0;
    }
}
