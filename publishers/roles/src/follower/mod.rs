//! The follower role: reads a field frame and the robot's pose and decides a motion command.
//! Pure library code (deterministic for a seed); the iceoryx2 loop lives elsewhere.
//!
//! One [`FollowerStrategy`] trait, five strategies:
//! - [`GradientFollower`] (`gradient`) — seed 000: climb ∇P (eqs. 15–16) with a ridge-aware
//!   look-ahead, speed adaptation from the Table 2 speed table, and trail rejection below an
//!   absolute level or δ·P0 (MODELS.md M1).
//! - [`AntennaFollower`] (`antenna`) — seed 002: two virtual antennas half a wheel base to each
//!   side (eq. 5 with the MODELS.md M3 convention), turn toward the stronger one, forward speed
//!   K·(1 − |P_L − P_R|) (the evident intent of eq. 6).
//! - [`SectorStrategy::inverse`] (`inverse`) — seed 004 IAS-SS: sector means at distance R_D, the subsets U
//!   and V, p(s) ∝ 1 − τ_s (eq. 1), steering θ(t) = θ(t−1) + γ·A_s* (eq. 2).
//! - [`SectorStrategy::uniform`] (`uniform`) — seed 004's baseline: a sector drawn uniformly, same
//!   steering.
//! - [`RouteFollower`] (`route`) — a leader driven through waypoints (the tele-operated or
//!   planned leader of seed 000); it ignores the field.
//!
//! [`Follower`] wraps a strategy and produces the `CmdMsg` and `FollowerStatusMsg` a process
//! loop publishes. With `after_loss` set, [`ExploreAfterLoss`] (`after_loss.rs`) makes a
//! follower that gives its trail up ("leader lost", seed 000) explore with `inverse` or
//! `uniform` instead of stopping.
//!
//! Each strategy lives in its own file (`gradient.rs`, `antenna.rs`, `route.rs`, `sector.rs`,
//! all re-exported here); this module holds the shared types, the configuration and the wrapper.

mod after_loss;
mod antenna;
pub mod antenna_source;
mod gradient;
mod route;
mod sector;
#[cfg(test)]
mod test_support;

use std::fmt;
use std::str::FromStr;

use pheromone_field::{FrameView, SamplePose};
use serde::{Deserialize, Serialize};

use pheromone_messages::{CmdMsg, FollowerState, FollowerStatusMsg, PoseMsg};

pub use after_loss::{AfterLossConfig, ExploreAfterLoss};
pub use antenna::{AntennaConfig, AntennaFollower};
pub use gradient::{
    speed_for_level, table2_speed_bands, GradientConfig, GradientFollower, SpeedBand,
};
pub use route::{RouteConfig, RouteFollower};
pub use sector::{
    choose_inverse, draw_members, inverse_probabilities, sector_angle, SectorConfig, SectorStrategy,
};

/// What a strategy decided for one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// Forward speed (m/s).
    pub v_m_per_s: f64,
    /// Turn rate (rad/s, counter-clockwise positive).
    pub omega_rad_per_s: f64,
    pub state: FollowerState,
    /// Pheromone level the strategy sensed (at the pose, or the antennas' mean).
    pub sensed_level: f32,
}

impl Decision {
    /// Standing still.
    pub fn stop(state: FollowerState, sensed_level: f32) -> Self {
        Self {
            v_m_per_s: 0.0,
            omega_rad_per_s: 0.0,
            state,
            sensed_level,
        }
    }
}

/// A follower strategy: one decision per step from the current frame and pose.
pub trait FollowerStrategy: Send {
    /// The CLI name (`gradient`, `antenna`, `inverse`, `uniform`, `route`).
    fn name(&self) -> &'static str;
    /// The field channel this strategy reads.
    fn channel(&self) -> usize;
    /// Decides the command for the next `dt_s`. The frame must have `channel()`.
    fn decide(&mut self, frame: &FrameView<'_>, pose: SamplePose, dt_s: f64) -> Decision;
    /// Back to the initial state (keeps the configuration; the RNG is not reseeded).
    fn reset(&mut self) {}
}

/// Angle wrapped into (−π, π]: the world's, one function for the whole crate.
pub use pheromone_messages::wrap_angle;

/// A follower setting that is out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("follower setting {name} = {value}: {reason}")]
pub struct FollowerConfigError {
    pub name: String,
    pub value: String,
    pub reason: &'static str,
}

fn invalid(name: &str, value: impl fmt::Display, reason: &'static str) -> FollowerConfigError {
    FollowerConfigError {
        name: name.to_string(),
        value: value.to_string(),
        reason,
    }
}

fn check_nonneg(name: &str, v: f64) -> Result<(), FollowerConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(name, v, "must be finite and ≥ 0"))
    }
}

fn check_positive(name: &str, v: f64) -> Result<(), FollowerConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(name, v, "must be finite and > 0"))
    }
}

// ---------------------------------------------------------------------------------------------
// Strategy selection and the follower wrapper

/// The strategies by CLI name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StrategyKind {
    #[default]
    Gradient,
    Antenna,
    Inverse,
    Uniform,
    Route,
}

impl StrategyKind {
    pub const ALL: [StrategyKind; 5] = [
        StrategyKind::Gradient,
        StrategyKind::Antenna,
        StrategyKind::Inverse,
        StrategyKind::Uniform,
        StrategyKind::Route,
    ];

    pub fn name(self) -> &'static str {
        match self {
            StrategyKind::Gradient => "gradient",
            StrategyKind::Antenna => "antenna",
            StrategyKind::Inverse => "inverse",
            StrategyKind::Uniform => "uniform",
            StrategyKind::Route => "route",
        }
    }
}

impl fmt::Display for StrategyKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A strategy name that is not one of the five.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown follower strategy '{0}' (expected one of: gradient, antenna, inverse, uniform, route)"
)]
pub struct UnknownStrategy(pub String);

impl FromStr for StrategyKind {
    type Err = UnknownStrategy;
    fn from_str(s: &str) -> Result<Self, UnknownStrategy> {
        StrategyKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| UnknownStrategy(s.to_string()))
    }
}

/// Everything a follower needs. Unknown keys are errors; every key has a default.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FollowerConfig {
    pub strategy: StrategyKind,
    /// Field channel the strategy reads.
    pub channel: u32,
    /// Seed of the sector strategies' RNG (ChaCha8).
    pub seed: u64,
    pub gradient: GradientConfig,
    pub antenna: AntennaConfig,
    /// Settings of `inverse` and `uniform`.
    pub sectors: SectorConfig,
    pub route: RouteConfig,
    /// Which pose the strategy steers by: the localizer's estimate (default) or, for a leader
    /// driven by an operator who sees the robot, the world's true pose.
    pub steer_by: PoseSource,
    /// What the follower does once it gives its trail up: explore with this strategy
    /// ("leader lost", seed 000) instead of stopping. Unset = stop.
    pub after_loss: Option<AfterLossConfig>,
}

/// Where a follower takes its pose from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PoseSource {
    #[default]
    Estimate,
    Truth,
}

impl FollowerConfig {
    /// Checks every section (also those of the strategies not selected).
    pub fn validate(&self) -> Result<(), FollowerConfigError> {
        self.gradient.validate()?;
        self.antenna.validate()?;
        self.sectors.validate()?;
        if let Some(a) = &self.after_loss {
            a.validate()?;
        }
        self.route.validate()
    }

    /// The selected strategy.
    pub fn build(&self) -> Result<Box<dyn FollowerStrategy>, FollowerConfigError> {
        let primary = self.build_strategy(self.strategy, self.channel)?;
        Ok(match &self.after_loss {
            Some(a) => {
                let explorer =
                    self.build_strategy(a.strategy, a.channel.unwrap_or(self.channel))?;
                Box::new(ExploreAfterLoss::new(primary, explorer))
            }
            None => primary,
        })
    }

    /// Strategy `kind` on `channel`, with this configuration's settings.
    fn build_strategy(
        &self,
        kind: StrategyKind,
        channel: u32,
    ) -> Result<Box<dyn FollowerStrategy>, FollowerConfigError> {
        self.validate()?;
        let ch = channel as usize;
        Ok(match kind {
            StrategyKind::Gradient => Box::new(GradientFollower::new(ch, self.gradient.clone())?),
            StrategyKind::Antenna => Box::new(AntennaFollower::new(ch, self.antenna.clone())?),
            StrategyKind::Inverse => Box::new(SectorStrategy::inverse(
                ch,
                self.sectors.clone(),
                self.seed,
            )?),
            StrategyKind::Uniform => Box::new(SectorStrategy::uniform(
                ch,
                self.sectors.clone(),
                self.seed,
            )?),
            StrategyKind::Route => Box::new(RouteFollower::new(ch, self.route.clone())?),
        })
    }
}

/// Why a follower step produced no command.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FollowError {
    #[error("the frame has {channels} channel(s); the follower reads channel {channel}")]
    ChannelMissing { channel: usize, channels: usize },
    #[error("pose {name} = {value} is not a finite f32")]
    BadPose { name: &'static str, value: f64 },
    #[error("dt_s = {0} must be finite and > 0")]
    BadDt(f64),
}

/// A command, its status message and the decision behind them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowOutput {
    pub cmd: CmdMsg,
    pub status: FollowerStatusMsg,
    pub decision: Decision,
}

/// A strategy bound to a robot: pose + frame in, `CmdMsg` + `FollowerStatusMsg` out. Stamps are
/// left 0 for the process loop to fill.
pub struct Follower {
    robot_id: u32,
    strategy: Box<dyn FollowerStrategy>,
}

impl fmt::Debug for Follower {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Follower")
            .field("robot_id", &self.robot_id)
            .field("strategy", &self.strategy.name())
            .finish()
    }
}

impl Follower {
    pub fn new(robot_id: u32, strategy: Box<dyn FollowerStrategy>) -> Self {
        Self { robot_id, strategy }
    }

    pub fn from_config(
        robot_id: u32,
        config: &FollowerConfig,
    ) -> Result<Self, FollowerConfigError> {
        Ok(Self::new(robot_id, config.build()?))
    }

    pub fn robot_id(&self) -> u32 {
        self.robot_id
    }

    pub fn strategy(&self) -> &dyn FollowerStrategy {
        self.strategy.as_ref()
    }

    pub fn strategy_mut(&mut self) -> &mut dyn FollowerStrategy {
        self.strategy.as_mut()
    }

    /// One step for world step `step`. Non-finite strategy outputs are replaced by 0 (stop).
    pub fn step(
        &mut self,
        frame: &FrameView<'_>,
        pose: SamplePose,
        dt_s: f64,
        step: u64,
    ) -> Result<FollowOutput, FollowError> {
        let channel = self.strategy.channel();
        if channel >= frame.channels {
            return Err(FollowError::ChannelMissing {
                channel,
                channels: frame.channels,
            });
        }
        for (name, v) in [
            ("x_m", pose.x_m),
            ("y_m", pose.y_m),
            ("theta_rad", pose.theta_rad),
        ] {
            if !v.is_finite() {
                return Err(FollowError::BadPose {
                    name,
                    value: v as f64,
                });
            }
        }
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(FollowError::BadDt(dt_s));
        }
        let mut d = self.strategy.decide(frame, pose, dt_s);
        let finite_or_zero = |v: f64| if v.is_finite() { v } else { 0.0 };
        d.v_m_per_s = finite_or_zero(d.v_m_per_s);
        d.omega_rad_per_s = finite_or_zero(d.omega_rad_per_s);
        if !d.sensed_level.is_finite() {
            d.sensed_level = 0.0;
        }
        let cmd = CmdMsg {
            stamp_ns: 0,
            step,
            robot_id: self.robot_id,
            _pad: 0,
            v_m_per_s: d.v_m_per_s,
            omega_rad_per_s: d.omega_rad_per_s,
        };
        let status = FollowerStatusMsg {
            stamp_ns: 0,
            step,
            robot_id: self.robot_id,
            state: d.state as u32,
            sensed_level: d.sensed_level,
            _pad: 0,
        };
        Ok(FollowOutput {
            cmd,
            status,
            decision: d,
        })
    }

    /// One step from a localizer's pose message (its `step` is echoed in the command).
    pub fn step_pose(
        &mut self,
        frame: &FrameView<'_>,
        pose: &PoseMsg,
        dt_s: f64,
    ) -> Result<FollowOutput, FollowError> {
        let mut p = SamplePose::default();
        for (name, v, out) in [
            ("x_m", pose.x_m, &mut p.x_m),
            ("y_m", pose.y_m, &mut p.y_m),
            ("theta_rad", pose.theta_rad, &mut p.theta_rad),
        ] {
            let f = v as f32;
            if !f.is_finite() {
                return Err(FollowError::BadPose { name, value: v });
            }
            *out = f;
        }
        self.step(frame, p, dt_s, pose.step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::follower::test_support::half_field;
    use std::f64::consts::PI;

    // ---- wrapper ----

    #[test]
    fn strategy_kind_parses_cli_names() {
        for k in StrategyKind::ALL {
            assert_eq!(k.name().parse::<StrategyKind>().unwrap(), k);
            assert_eq!(k.to_string(), k.name());
        }
        let e = "gradiant".parse::<StrategyKind>().unwrap_err().to_string();
        assert!(
            e.contains("'gradiant'") && e.contains("gradient, antenna, inverse, uniform"),
            "{e}"
        );
    }

    #[test]
    fn follower_builds_every_strategy_and_fills_messages() {
        let (g, cells) = half_field();
        let frame = FrameView::new(g, 1, &cells);
        for k in StrategyKind::ALL {
            let cfg = FollowerConfig {
                strategy: k,
                ..FollowerConfig::default()
            };
            let mut f = Follower::from_config(7, &cfg).unwrap();
            assert_eq!(f.strategy().name(), k.name());
            let pose = PoseMsg {
                step: 12,
                x_m: 5.0,
                y_m: 4.0,
                theta_rad: 0.3,
                ..PoseMsg::default()
            };
            let out = f.step_pose(&frame, &pose, 0.1).unwrap();
            assert_eq!(
                (out.cmd.robot_id, out.cmd.step, out.cmd.stamp_ns),
                (7, 12, 0)
            );
            assert_eq!(
                (out.status.robot_id, out.status.step, out.status.stamp_ns),
                (7, 12, 0)
            );
            assert_eq!(out.cmd.v_m_per_s, out.decision.v_m_per_s);
            assert_eq!(out.cmd.omega_rad_per_s, out.decision.omega_rad_per_s);
            assert_eq!(
                FollowerState::from_code(out.status.state),
                Some(out.decision.state)
            );
            assert_eq!(out.status.sensed_level, out.decision.sensed_level);
            assert!(out.cmd.v_m_per_s.is_finite() && out.cmd.omega_rad_per_s.is_finite());
        }
    }

    #[test]
    fn follower_refuses_bad_input() {
        let (g, cells) = half_field();
        let frame = FrameView::new(g, 1, &cells);
        let mut f = Follower::from_config(
            1,
            &FollowerConfig {
                channel: 2,
                ..FollowerConfig::default()
            },
        )
        .unwrap();
        let e = f
            .step(&frame, SamplePose::new(1.0, 1.0, 0.0), 0.1, 0)
            .unwrap_err();
        assert_eq!(
            e,
            FollowError::ChannelMissing {
                channel: 2,
                channels: 1
            }
        );
        let mut f = Follower::from_config(1, &FollowerConfig::default()).unwrap();
        let e = f
            .step(&frame, SamplePose::new(f32::NAN, 1.0, 0.0), 0.1, 0)
            .unwrap_err();
        assert!(matches!(e, FollowError::BadPose { name: "x_m", .. }), "{e}");
        assert!(matches!(
            f.step(&frame, SamplePose::new(1.0, 1.0, 0.0), 0.0, 0),
            Err(FollowError::BadDt(_))
        ));
        let huge = PoseMsg {
            y_m: 1e300,
            ..PoseMsg::default()
        };
        assert!(matches!(
            f.step_pose(&frame, &huge, 0.1),
            Err(FollowError::BadPose { name: "y_m", .. })
        ));
    }

    #[test]
    fn follower_config_validates_and_denies_unknown_keys() {
        use serde::de::value::{Error as DeError, MapDeserializer};
        let bad = FollowerConfig {
            sectors: SectorConfig {
                gamma: 1.5,
                ..SectorConfig::default()
            },
            ..FollowerConfig::default()
        };
        let e = Follower::from_config(0, &bad).unwrap_err();
        assert_eq!(e.name, "sectors.gamma");
        let cfg: Result<FollowerConfig, DeError> = FollowerConfig::deserialize(
            MapDeserializer::new([("strategy", "inverse")].into_iter()),
        );
        assert_eq!(cfg.unwrap().strategy, StrategyKind::Inverse);
        let cfg: Result<FollowerConfig, DeError> = FollowerConfig::deserialize(
            MapDeserializer::new([("strategy", "sideways")].into_iter()),
        );
        assert!(cfg.is_err());
        let cfg: Result<FollowerConfig, DeError> = FollowerConfig::deserialize(
            MapDeserializer::new([("strategie", "inverse")].into_iter()),
        );
        assert!(cfg.unwrap_err().to_string().contains("strategie"));
        let g: Result<GradientConfig, DeError> = GradientConfig::deserialize(MapDeserializer::new(
            [("lookahead_m", 0.7f64), ("abandon_below", 5.0)].into_iter(),
        ));
        let g = g.unwrap();
        assert_eq!((g.lookahead_m, g.abandon_below, g.fan_rays), (0.7, 5.0, 17));
    }

    #[test]
    fn wrap_pi_stays_in_range() {
        for a in [-10.0, -PI, -3.0, 0.0, 3.0, PI, 7.0, 100.0] {
            let w = wrap_angle(a);
            assert!(w > -PI - 1e-12 && w <= PI + 1e-12, "{a} → {w}");
            assert!(
                ((a - w) / (2.0 * PI)).fract().abs() < 1e-9
                    || ((a - w) / (2.0 * PI)).fract().abs() > 1.0 - 1e-9
            );
        }
    }
}
