//! The follower role: reads a field frame and the robot's pose and decides a motion command.
//! Pure library code (deterministic for a seed); the iceoryx2 loop lives elsewhere.
//!
//! One [`Strategy`] trait, four strategies:
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
//!
//! [`Follower`] wraps a strategy and produces the `CmdMsg` and `FollowerStatusMsg` a process
//! loop publishes.

pub mod run;

use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt;
use std::str::FromStr;

use field::{FrameView, Pose2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::messages::{CmdMsg, FollowerState, FollowerStatusMsg, PoseMsg};

/// What a strategy decided for one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// Forward speed (m/s).
    pub v_mps: f64,
    /// Turn rate (rad/s, counter-clockwise positive).
    pub omega_radps: f64,
    pub state: FollowerState,
    /// Pheromone level the strategy sensed (at the pose, or the antennas' mean).
    pub sensed_level: f32,
}

impl Decision {
    /// Standing still.
    pub fn stop(state: FollowerState, sensed_level: f32) -> Self {
        Self {
            v_mps: 0.0,
            omega_radps: 0.0,
            state,
            sensed_level,
        }
    }
}

/// A follower strategy: one decision per step from the current frame and pose.
pub trait Strategy: Send {
    /// The CLI name (`gradient`, `antenna`, `inverse`, `uniform`).
    fn name(&self) -> &'static str;
    /// The field channel this strategy reads.
    fn channel(&self) -> usize;
    /// Decides the command for the next `dt_secs`. The frame must have `channel()`.
    fn decide(&mut self, frame: &FrameView<'_>, pose: Pose2, dt_secs: f64) -> Decision;
    /// Back to the initial state (keeps the configuration; the RNG is not reseeded).
    fn reset(&mut self) {}
}

/// Angle wrapped into (−π, π].
pub fn wrap_pi(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(2.0 * PI) - PI;
    if w <= -PI {
        w + 2.0 * PI
    } else {
        w
    }
}

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
// Speed adaptation (seed 000 Table 2)

/// One row of the speed table: from this sensed level up to the next row's, drive at `v_mps`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedBand {
    pub from_level: f32,
    pub v_mps: f64,
}

/// Seed 000 Table 2: sensed 0–15 → 0.15 m/s, 15–30 → 0.45, 30–60 → 0.65, 60–100 → 1.0.
pub fn table2_speed_bands() -> Vec<SpeedBand> {
    [(0.0, 0.15), (15.0, 0.45), (30.0, 0.65), (60.0, 1.0)]
        .into_iter()
        .map(|(from_level, v_mps)| SpeedBand { from_level, v_mps })
        .collect()
}

/// The speed of the highest band whose `from_level` ≤ `level` (the first band's below all of
/// them). Levels above the last band keep its speed.
pub fn speed_for_level(bands: &[SpeedBand], level: f32) -> f64 {
    let first = bands.first().map_or(0.0, |b| b.v_mps);
    bands
        .iter()
        .take_while(|b| b.from_level <= level)
        .last()
        .map_or(first, |b| b.v_mps)
}

fn validate_bands(prefix: &str, bands: &[SpeedBand]) -> Result<(), FollowerConfigError> {
    if bands.is_empty() {
        return Err(invalid(
            &format!("{prefix}.speed_table"),
            "[]",
            "needs at least one band",
        ));
    }
    for (i, b) in bands.iter().enumerate() {
        if !b.from_level.is_finite() {
            return Err(invalid(
                &format!("{prefix}.speed_table[{i}].from_level"),
                b.from_level,
                "must be finite",
            ));
        }
        check_nonneg(&format!("{prefix}.speed_table[{i}].v_mps"), b.v_mps)?;
        if i > 0 && b.from_level <= bands[i - 1].from_level {
            return Err(invalid(
                &format!("{prefix}.speed_table[{i}].from_level"),
                b.from_level,
                "bands must be in increasing order of from_level",
            ));
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Gradient follower (seed 000)

/// Settings of the `gradient` strategy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GradientConfig {
    /// Speed adaptation table (seed 000 Table 2), in table levels.
    pub speed_table: Vec<SpeedBand>,
    /// Table level = sensed level × this (1 when the field uses the paper's 0–100 levels).
    pub speed_level_scale: f32,
    /// Absolute trail-rejection threshold (seed 000: 10 in the corridor experiment); also the
    /// level at which a trail is acquired.
    pub abandon_below: f32,
    /// Relative threshold δ ∈ (0, 1]: abandon below δ·P0, P0 = the highest level sensed since the
    /// trail was acquired (seed 000 eq. 26 uses T = δ·P0). The larger threshold applies.
    pub abandon_delta: Option<f32>,
    /// An abandoned trail stays abandoned (until `reset`); if false the follower re-acquires a
    /// trail whose level climbs back to `abandon_below`.
    pub latch_abandon: bool,
    /// Length of the look-ahead rays (m).
    pub lookahead_m: f64,
    /// Points averaged along each ray (≥ 1).
    pub lookahead_samples: usize,
    /// Turning back toward ∇P is allowed only when the best ray ahead scores below the level
    /// here by more than this fraction of it (default ½: the trail ends ahead). A small margin
    /// also climbs a gentle slope along the trail, but then a dip of a dotted trail (deposits
    /// far apart for their width) looks like its end.
    pub turn_back_margin: f32,
    /// The look-ahead fan spans ± this angle around the heading (degrees, ≤ 180).
    pub fan_half_angle_deg: f64,
    /// Rays in the fan (≥ 1).
    pub fan_rays: usize,
    /// Proportional heading gain: ω = k·(heading error), clamped (1/s).
    pub heading_gain_per_s: f64,
    pub omega_max_radps: f64,
    /// Forward speed while no trail is acquired (m/s); 0 = wait in place.
    pub explore_v_mps: f64,
}

impl Default for GradientConfig {
    fn default() -> Self {
        Self {
            speed_table: table2_speed_bands(),
            speed_level_scale: 1.0,
            abandon_below: 10.0,
            abandon_delta: None,
            latch_abandon: true,
            lookahead_m: 0.5,
            lookahead_samples: 3,
            turn_back_margin: 0.5,
            fan_half_angle_deg: 90.0,
            fan_rays: 17,
            heading_gain_per_s: 3.0,
            omega_max_radps: 1.5,
            explore_v_mps: 0.15,
        }
    }
}

impl GradientConfig {
    pub fn validate(&self) -> Result<(), FollowerConfigError> {
        validate_bands("gradient", &self.speed_table)?;
        check_positive("gradient.speed_level_scale", self.speed_level_scale as f64)?;
        check_nonneg("gradient.abandon_below", self.abandon_below as f64)?;
        if let Some(d) = self.abandon_delta {
            if !(d > 0.0 && d <= 1.0) {
                return Err(invalid(
                    "gradient.abandon_delta",
                    d,
                    "must be within (0, 1]",
                ));
            }
        }
        check_positive("gradient.lookahead_m", self.lookahead_m)?;
        if self.lookahead_samples == 0 || self.lookahead_samples > 64 {
            return Err(invalid(
                "gradient.lookahead_samples",
                self.lookahead_samples,
                "must be between 1 and 64",
            ));
        }
        if !(0.0..1.0).contains(&self.turn_back_margin) {
            return Err(invalid(
                "gradient.turn_back_margin",
                self.turn_back_margin,
                "must be within [0, 1)",
            ));
        }
        if !(self.fan_half_angle_deg.is_finite()
            && (0.0..=180.0).contains(&self.fan_half_angle_deg))
        {
            return Err(invalid(
                "gradient.fan_half_angle_deg",
                self.fan_half_angle_deg,
                "must be within [0, 180]",
            ));
        }
        if self.fan_rays == 0 || self.fan_rays > 1024 {
            return Err(invalid(
                "gradient.fan_rays",
                self.fan_rays,
                "must be between 1 and 1024",
            ));
        }
        check_positive("gradient.heading_gain_per_s", self.heading_gain_per_s)?;
        check_positive("gradient.omega_max_radps", self.omega_max_radps)?;
        check_nonneg("gradient.explore_v_mps", self.explore_v_mps)?;
        Ok(())
    }
}

/// Seed 000 follower: climbs the trail, adapts its speed to the level it senses (Table 2) and
/// rejects a trail that falls below the threshold (MODELS.md M1).
///
/// Steering. A trail is a ridge: on it ∇P (eqs. 15–16) is almost perpendicular to the trail and
/// vanishes on the crest, so steering along ∇P alone would make the robot zig-zag across the
/// trail instead of moving along it. The desired heading is therefore the steepest ascent
/// measured at the scale of a look-ahead distance L:
/// - a fan of rays over ±`fan_half_angle_deg` around the heading, each scored by the mean of P
///   at `lookahead_samples` points along it up to L (the best ray refined by a parabola through
///   its neighbours), and
/// - the local gradient direction ∇P/|∇P|, scored the same way, taken when it scores better and
///   lies in the fan — or, behind the robot, only when the best ray ahead is below the level
///   here by more than `turn_back_margin` of it (the trail ends ahead: turn back).
///
/// On a hill this is gradient ascent toward the summit (a summit behind is reached through the
/// ±90° rays). On a ridge the best point of the fan is where the look-ahead circle crosses the
/// crest ahead, so the robot pursues a point on the trail ahead of it (pure pursuit): it keeps
/// moving forward along the trail in the direction it travels and the lateral error decays
/// without oscillating; at the end of the trail it turns back. A flat neighbourhood keeps the
/// heading.
///
/// Control: ω = clamp(k·e, ±ω_max) for the heading error e; v = v_table(level)·max(0, cos e), so
/// the robot turns in place rather than driving away from the trail.
///
/// States: `Exploring` until the level reaches `abandon_below` (moving at `explore_v_mps` with
/// the same steering), then `Following`; `TrailAbandoned` (v = 0, ω = 0) when the level falls
/// below max(`abandon_below`, δ·P0), latched unless `latch_abandon` is false.
#[derive(Debug, Clone)]
pub struct GradientFollower {
    channel: usize,
    config: GradientConfig,
    state: FollowerState,
    /// P0: the highest level sensed since the trail was acquired.
    peak_level: f32,
}

impl GradientFollower {
    pub fn new(channel: usize, config: GradientConfig) -> Result<Self, FollowerConfigError> {
        config.validate()?;
        Ok(Self {
            channel,
            config,
            state: FollowerState::Exploring,
            peak_level: 0.0,
        })
    }

    pub fn config(&self) -> &GradientConfig {
        &self.config
    }

    pub fn state(&self) -> FollowerState {
        self.state
    }

    /// The current abandon threshold: max(abandon_below, δ·P0).
    pub fn threshold(&self) -> f32 {
        let rel = self
            .config
            .abandon_delta
            .map_or(0.0, |d| d * self.peak_level);
        self.config.abandon_below.max(rel)
    }

    fn update_state(&mut self, level: f32) {
        let acquire = level >= self.config.abandon_below && level > 0.0;
        match self.state {
            FollowerState::Exploring => {
                if acquire {
                    self.state = FollowerState::Following;
                    self.peak_level = level;
                }
            }
            FollowerState::Following => {
                self.peak_level = self.peak_level.max(level);
                if level < self.threshold() {
                    self.state = FollowerState::TrailAbandoned;
                }
            }
            FollowerState::TrailAbandoned => {
                if !self.config.latch_abandon && acquire {
                    self.state = FollowerState::Following;
                    self.peak_level = level;
                }
            }
        }
    }

    /// Score of the direction `phi`: the mean level at `lookahead_samples` points spread evenly
    /// along the ray up to `lookahead_m` (the mean smooths a dotted trail).
    fn ray_score(&self, frame: &FrameView<'_>, pose: Pose2, phi: f64) -> f32 {
        let (x, y) = (pose.x_m as f64, pose.y_m as f64);
        let m = self.config.lookahead_samples;
        let (s, c) = phi.sin_cos();
        let sum: f32 = (1..=m)
            .map(|i| {
                let r = self.config.lookahead_m * i as f64 / m as f64;
                frame.value(self.channel, (x + r * c) as f32, (y + r * s) as f32)
            })
            .sum();
        sum / m as f32
    }

    /// The desired heading (rad, world frame), or `None` where the field is flat.
    pub fn desired_heading(&self, frame: &FrameView<'_>, pose: Pose2) -> Option<f64> {
        let th = pose.theta_rad as f64;
        let n = self.config.fan_rays;
        let half = self.config.fan_half_angle_deg.to_radians();
        let step = if n > 1 {
            2.0 * half / (n - 1) as f64
        } else {
            0.0
        };
        let angles: Vec<f64> = (0..n)
            .map(|k| {
                if n > 1 {
                    th - half + k as f64 * step
                } else {
                    th
                }
            })
            .collect();
        let scores: Vec<f32> = angles
            .iter()
            .map(|&a| self.ray_score(frame, pose, a))
            .collect();
        let mut best = 0;
        for (k, s) in scores.iter().enumerate() {
            // Ties go to the ray closest to the heading.
            let closer = (angles[k] - th).abs() < (angles[best] - th).abs();
            if *s > scores[best] || (*s == scores[best] && closer) {
                best = k;
            }
        }
        let (mut lo, mut hi) = (scores[best], scores[best]);
        for &s in &scores {
            lo = lo.min(s);
            hi = hi.max(s);
        }
        let mut phi = angles[best];
        if best > 0 && best + 1 < n {
            let (sm, s0, sp) = (
                scores[best - 1] as f64,
                scores[best] as f64,
                scores[best + 1] as f64,
            );
            let denom = sm - 2.0 * s0 + sp;
            if denom < 0.0 {
                phi += (0.5 * (sm - sp) / denom * step).clamp(-0.5 * step, 0.5 * step);
            }
        }
        let best_score = scores[best];
        let (gx, gy) = frame.gradient(self.channel, pose.x_m, pose.y_m);
        if (gx != 0.0 || gy != 0.0) && gx.is_finite() && gy.is_finite() {
            // ∇P (seed 000 eqs. 15–16) as one more candidate. Outside the fan (behind the robot)
            // it is only considered when everything ahead is clearly lower than here (the end
            // of the trail), so that a dip of a dotted trail does not turn the robot around.
            let phi_g = (gy as f64).atan2(gx as f64);
            let sg = self.ray_score(frame, pose, phi_g);
            lo = lo.min(sg);
            hi = hi.max(sg);
            let in_fan = wrap_pi(phi_g - th).abs() <= half + 1e-9;
            let here = frame.value(self.channel, pose.x_m, pose.y_m);
            let ahead_is_lower = best_score < here - self.config.turn_back_margin * here.abs();
            if sg > best_score && (in_fan || ahead_is_lower) {
                phi = phi_g;
            }
        }
        let spread = hi - lo;
        let flat =
            spread.is_nan() || spread <= 1e-6 * hi.abs().max(lo.abs()).max(f32::MIN_POSITIVE);
        if flat {
            None
        } else {
            Some(phi)
        }
    }
}

impl Strategy for GradientFollower {
    fn name(&self) -> &'static str {
        StrategyKind::Gradient.name()
    }

    fn channel(&self) -> usize {
        self.channel
    }

    fn decide(&mut self, frame: &FrameView<'_>, pose: Pose2, _dt_secs: f64) -> Decision {
        let level = frame.value(self.channel, pose.x_m, pose.y_m);
        self.update_state(level);
        if self.state == FollowerState::TrailAbandoned {
            return Decision::stop(self.state, level);
        }
        let c = &self.config;
        let err = self
            .desired_heading(frame, pose)
            .map_or(0.0, |phi| wrap_pi(phi - pose.theta_rad as f64));
        let omega = (c.heading_gain_per_s * err).clamp(-c.omega_max_radps, c.omega_max_radps);
        let v_base = match self.state {
            FollowerState::Following => {
                speed_for_level(&c.speed_table, level * c.speed_level_scale)
            }
            _ => c.explore_v_mps,
        };
        Decision {
            v_mps: v_base * err.cos().max(0.0),
            omega_radps: omega,
            state: self.state,
            sensed_level: level,
        }
    }

    fn reset(&mut self) {
        self.state = FollowerState::Exploring;
        self.peak_level = 0.0;
    }
}

// ---------------------------------------------------------------------------------------------
// Antenna follower (seed 002)

/// Settings of the `antenna` strategy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AntennaConfig {
    /// b, the distance between the antennas (seed 002: the wheel base, "bias") (m).
    pub wheel_base_m: f32,
    /// The antennas sit this far ahead of the pose (m); 0 puts them on the wheel axis as in
    /// seed 002 eq. 5.
    pub antenna_ahead_m: f32,
    /// Readings are divided by this before clamping to [0, 1]; unset = by the larger reading.
    pub normalize_max: Option<f32>,
    /// K of seed 002 eq. 6: forward speed K·(1 − |P_L − P_R|) (m/s).
    pub k_v_mps: f64,
    /// Turn rate per unit normalized difference: ω = k·(P_L − P_R) (rad/s).
    pub omega_gain_radps: f64,
    pub omega_max_radps: f64,
    /// Both readings at or below this count as "no pheromone" (state `Exploring`).
    pub min_level: f32,
    /// Forward speed while exploring (m/s); 0 = stop.
    pub explore_v_mps: f64,
}

impl Default for AntennaConfig {
    fn default() -> Self {
        Self {
            wheel_base_m: 0.3,
            antenna_ahead_m: 0.15,
            normalize_max: None,
            k_v_mps: 0.5,
            omega_gain_radps: 3.0,
            omega_max_radps: 2.0,
            min_level: 1e-3,
            explore_v_mps: 0.1,
        }
    }
}

impl AntennaConfig {
    pub fn validate(&self) -> Result<(), FollowerConfigError> {
        check_positive("antenna.wheel_base_m", self.wheel_base_m as f64)?;
        if !self.antenna_ahead_m.is_finite() {
            return Err(invalid(
                "antenna.antenna_ahead_m",
                self.antenna_ahead_m,
                "must be finite",
            ));
        }
        if let Some(m) = self.normalize_max {
            check_positive("antenna.normalize_max", m as f64)?;
        }
        check_nonneg("antenna.k_v_mps", self.k_v_mps)?;
        check_nonneg("antenna.omega_gain_radps", self.omega_gain_radps)?;
        check_positive("antenna.omega_max_radps", self.omega_max_radps)?;
        check_nonneg("antenna.min_level", self.min_level as f64)?;
        check_nonneg("antenna.explore_v_mps", self.explore_v_mps)?;
        Ok(())
    }
}

/// Seed 002 two-antenna follower, as decided in MODELS.md M3: readings P_L, P_R at the antenna
/// points (`FrameView::antennas`), normalized to [0, 1] (by `normalize_max`, or by the larger
/// reading), then ω = k·(P_L − P_R) (turn toward the stronger antenna) and
/// v = K·(1 − |P_L − P_R|). Eq. 6 as printed turns away from the stronger side and stops when
/// P_L = P_R; this is its evident intent.
///
/// Deviation: the antennas may sit `antenna_ahead_m` ahead of the wheel axis (like an insect's
/// antennas on its head). On the axis (0, eq. 5) the difference measures only the lateral
/// offset, so the loop is an undamped oscillator about the trail; a forward offset also
/// measures the heading error and damps it (the "follow the carrot" remark of seed 002).
#[derive(Debug, Clone)]
pub struct AntennaFollower {
    channel: usize,
    config: AntennaConfig,
}

impl AntennaFollower {
    pub fn new(channel: usize, config: AntennaConfig) -> Result<Self, FollowerConfigError> {
        config.validate()?;
        Ok(Self { channel, config })
    }

    pub fn config(&self) -> &AntennaConfig {
        &self.config
    }

    /// Raw readings (P_L, P_R) at the antenna points.
    pub fn readings(&self, frame: &FrameView<'_>, pose: Pose2) -> (f32, f32) {
        let a = self.config.antenna_ahead_m;
        let (s, c) = pose.theta_rad.sin_cos();
        let head = Pose2::new(pose.x_m + a * c, pose.y_m + a * s, pose.theta_rad);
        frame.antennas(self.channel, head, self.config.wheel_base_m)
    }
}

impl Strategy for AntennaFollower {
    fn name(&self) -> &'static str {
        StrategyKind::Antenna.name()
    }

    fn channel(&self) -> usize {
        self.channel
    }

    fn decide(&mut self, frame: &FrameView<'_>, pose: Pose2, _dt_secs: f64) -> Decision {
        let c = &self.config;
        let (pl, pr) = self.readings(frame, pose);
        let level = 0.5 * (pl + pr);
        let strongest = pl.max(pr);
        if strongest.is_nan() || strongest <= c.min_level {
            return Decision {
                v_mps: c.explore_v_mps,
                omega_radps: 0.0,
                state: FollowerState::Exploring,
                sensed_level: level,
            };
        }
        let norm = c.normalize_max.unwrap_or(strongest);
        let (nl, nr) = (
            (pl / norm).clamp(0.0, 1.0) as f64,
            (pr / norm).clamp(0.0, 1.0) as f64,
        );
        let diff = nl - nr;
        Decision {
            v_mps: c.k_v_mps * (1.0 - diff.abs()),
            omega_radps: (c.omega_gain_radps * diff).clamp(-c.omega_max_radps, c.omega_max_radps),
            state: FollowerState::Following,
            sensed_level: level,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Route (a leader driven along waypoints)

/// Settings of the `route` strategy: a leader that drives through waypoints, as the
/// tele-operated or planned leader of seed 000 does. It ignores the field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RouteConfig {
    /// Waypoints [x, y] (m), driven in order.
    pub waypoints: Vec<[f64; 2]>,
    pub v_mps: f64,
    /// A waypoint counts as reached within this distance (m).
    pub reach_m: f64,
    /// Proportional heading gain (1/s).
    pub heading_gain_per_s: f64,
    pub omega_max_radps: f64,
    /// Start driving only after this much time (s).
    pub start_after_s: f64,
}

impl Default for RouteConfig {
    fn default() -> Self {
        Self {
            waypoints: Vec::new(),
            v_mps: 0.3,
            reach_m: 0.2,
            heading_gain_per_s: 2.0,
            omega_max_radps: 1.0,
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
        check_nonneg("route.v_mps", self.v_mps)?;
        check_positive("route.reach_m", self.reach_m)?;
        check_nonneg("route.heading_gain_per_s", self.heading_gain_per_s)?;
        check_positive("route.omega_max_radps", self.omega_max_radps)?;
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

impl Strategy for RouteFollower {
    fn name(&self) -> &'static str {
        StrategyKind::Route.name()
    }

    fn channel(&self) -> usize {
        self.channel
    }

    fn decide(&mut self, frame: &FrameView<'_>, pose: Pose2, dt_secs: f64) -> Decision {
        let level = frame.value(self.channel, pose.x_m, pose.y_m);
        self.elapsed_s += dt_secs;
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
        let err = wrap_pi((w[1] - y).atan2(w[0] - x) - pose.theta_rad as f64);
        let c = &self.config;
        Decision {
            v_mps: c.v_mps * err.cos().max(0.0),
            omega_radps: (c.heading_gain_per_s * err).clamp(-c.omega_max_radps, c.omega_max_radps),
            state: FollowerState::Following,
            sensed_level: level,
        }
    }

    fn reset(&mut self) {
        self.next = 0;
        self.elapsed_s = 0.0;
    }
}

// ---------------------------------------------------------------------------------------------
// Sector strategies (seed 004)

/// Settings of the `inverse` and `uniform` strategies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SectorConfig {
    /// R_D, the sensing distance (m): sectors are averaged over the half-disc of this radius.
    pub radius_m: f32,
    /// S: there are 2S + 1 sectors of π/(2S + 1) over [−90°, 90°].
    pub half_sectors: usize,
    /// |U|: the lowest-pheromone sectors always in the draw (inverse only, ≥ 1).
    pub u_count: usize,
    /// |V|: other sectors drawn uniformly at random into the draw (inverse only).
    pub v_count: usize,
    /// γ ∈ [0, 1] of eq. 2: θ(t) = θ(t−1) + γ·A_s*.
    pub gamma: f64,
    /// Constant forward speed (m/s).
    pub v_mps: f64,
    /// Turn-rate limit (rad/s).
    pub omega_max_radps: f64,
    /// A new sector is drawn every this many seconds (one seed 004 iteration); 0 = every step.
    /// In between the robot turns toward the heading of eq. 2 at up to `omega_max_radps`.
    pub decision_period_s: f64,
    /// τ_s = clamp(sector mean / this, 0, 1). 1 for a saturating channel; a negative value reads
    /// anti-pheromone (negative cells) as τ > 0.
    pub saturation_level: f32,
    /// A channel that marks obstacles (e.g. the scenario's `mark_walls`): a sector whose mean on
    /// it exceeds `obstacle_level` counts as saturated (τ_s = 1), so IAS-SS steers away from
    /// walls the way seed 004's robots do where pheromone builds up along them.
    pub obstacle_channel: Option<u32>,
    /// See `obstacle_channel`.
    pub obstacle_level: f32,
}

impl Default for SectorConfig {
    fn default() -> Self {
        Self {
            radius_m: 1.0,
            half_sectors: 4,
            u_count: 2,
            v_count: 2,
            gamma: 0.5,
            v_mps: 0.3,
            omega_max_radps: 1.5,
            decision_period_s: 0.0,
            saturation_level: 1.0,
            obstacle_channel: None,
            obstacle_level: 0.05,
        }
    }
}

impl SectorConfig {
    pub fn validate(&self) -> Result<(), FollowerConfigError> {
        check_positive("sectors.radius_m", self.radius_m as f64)?;
        if self.half_sectors > 90 {
            return Err(invalid(
                "sectors.half_sectors",
                self.half_sectors,
                "must be ≤ 90",
            ));
        }
        let n = 2 * self.half_sectors + 1;
        if self.u_count == 0 || self.u_count > n {
            return Err(invalid(
                "sectors.u_count",
                self.u_count,
                "must be between 1 and 2·half_sectors + 1",
            ));
        }
        if self.v_count > n {
            return Err(invalid(
                "sectors.v_count",
                self.v_count,
                "must be ≤ 2·half_sectors + 1",
            ));
        }
        if !(0.0..=1.0).contains(&self.gamma) {
            return Err(invalid(
                "sectors.gamma",
                self.gamma,
                "must be within [0, 1]",
            ));
        }
        check_nonneg("sectors.v_mps", self.v_mps)?;
        check_positive("sectors.omega_max_radps", self.omega_max_radps)?;
        check_nonneg("sectors.decision_period_s", self.decision_period_s)?;
        check_nonneg("sectors.obstacle_level", self.obstacle_level as f64)?;
        if !(self.saturation_level.is_finite() && self.saturation_level != 0.0) {
            return Err(invalid(
                "sectors.saturation_level",
                self.saturation_level,
                "must be finite and ≠ 0",
            ));
        }
        Ok(())
    }

    /// Number of sectors, 2S + 1.
    pub fn sectors(&self) -> usize {
        2 * self.half_sectors + 1
    }
}

/// A_s: the centre angle of sector `s` of `n` relative to the heading (rad); sector 0 is the
/// rightmost, as in `FrameView::sector_means`.
pub fn sector_angle(s: usize, n: usize) -> f64 {
    -FRAC_PI_2 + (s as f64 + 0.5) * PI / n as f64
}

/// Seed 004 eq. 1 over the drawn sectors `members` (U ∪ V): p(s) = (1 − τ_s)/Σ(1 − τ_i), τ
/// clamped to [0, 1]. If every member is saturated (Σ = 0) the draw is uniform over them.
pub fn inverse_probabilities(taus: &[f32], members: &[usize]) -> Vec<f64> {
    let w: Vec<f64> = members
        .iter()
        .map(|&s| 1.0 - (taus[s] as f64).clamp(0.0, 1.0))
        .collect();
    let total: f64 = w.iter().sum();
    if total > 0.0 {
        w.iter().map(|wi| wi / total).collect()
    } else {
        vec![1.0 / members.len() as f64; members.len()]
    }
}

/// The subsets of seed 004: U = the `u_count` lowest-pheromone sectors (ties broken at random,
/// so an empty field has no side bias), V = `v_count` of the others drawn uniformly. Returns
/// U ∪ V, U first.
pub fn draw_members(
    rng: &mut ChaCha8Rng,
    taus: &[f32],
    u_count: usize,
    v_count: usize,
) -> Vec<usize> {
    let n = taus.len();
    let mut order: Vec<usize> = (0..n).collect();
    // Fisher–Yates, then a stable sort: equal τ keep a random order.
    for i in (1..n).rev() {
        let j = rng.random_range(0..=i);
        order.swap(i, j);
    }
    order.sort_by(|&a, &b| taus[a].total_cmp(&taus[b]));
    let u = u_count.clamp(1, n);
    let rest = &order[u..];
    let picked = rand::seq::index::sample(rng, rest.len(), v_count.min(rest.len()));
    let mut members = order[..u].to_vec();
    members.extend(picked.iter().map(|i| rest[i]));
    members
}

/// Draws one sector by seed 004 eqs. 1 (U ∪ V, p ∝ 1 − τ).
pub fn choose_inverse(rng: &mut ChaCha8Rng, taus: &[f32], u_count: usize, v_count: usize) -> usize {
    let members = draw_members(rng, taus, u_count, v_count);
    let p = inverse_probabilities(taus, &members);
    let mut r = rng.random::<f64>();
    for (s, ps) in members.iter().zip(&p) {
        if r < *ps {
            return *s;
        }
        r -= ps;
    }
    *members.last().expect("at least one member")
}

/// What the sector strategies share: sensing, the RNG, and the eq. 2 steering.
#[derive(Debug, Clone)]
struct SectorSteer {
    channel: usize,
    config: SectorConfig,
    rng: ChaCha8Rng,
    goal_heading_rad: Option<f64>,
    since_decision_s: f64,
    last_sector: Option<usize>,
    decisions: u64,
}

#[derive(Debug, Clone, Copy)]
enum SectorRule {
    Inverse,
    Uniform,
}

impl SectorSteer {
    fn new(channel: usize, config: SectorConfig, seed: u64) -> Result<Self, FollowerConfigError> {
        config.validate()?;
        Ok(Self {
            channel,
            config,
            rng: ChaCha8Rng::seed_from_u64(seed),
            goal_heading_rad: None,
            since_decision_s: 0.0,
            last_sector: None,
            decisions: 0,
        })
    }

    /// τ_s of every sector, normalized and clamped to [0, 1]; sectors blocked on the obstacle
    /// channel (if any) count as saturated.
    fn taus(&self, frame: &FrameView<'_>, pose: Pose2) -> Vec<f32> {
        let c = &self.config;
        let mut taus: Vec<f32> = frame
            .sector_means(self.channel, pose, c.radius_m, c.half_sectors)
            .into_iter()
            .map(|m| {
                let t = m / c.saturation_level;
                if t.is_finite() {
                    t.clamp(0.0, 1.0)
                } else {
                    1.0
                }
            })
            .collect();
        if let Some(oc) = c.obstacle_channel.map(|o| o as usize) {
            if oc < frame.channels {
                let blocked = frame.sector_means(oc, pose, c.radius_m, c.half_sectors);
                for (t, b) in taus.iter_mut().zip(blocked) {
                    if b.is_nan() || b > c.obstacle_level {
                        *t = 1.0;
                    }
                }
            }
        }
        taus
    }

    /// 1 for the sectors blocked on the obstacle channel, 0 for the others.
    fn obstacle_taus(&self, frame: &FrameView<'_>, pose: Pose2) -> Vec<f32> {
        let c = &self.config;
        match c.obstacle_channel.map(|o| o as usize) {
            Some(oc) if oc < frame.channels => frame
                .sector_means(oc, pose, c.radius_m, c.half_sectors)
                .into_iter()
                .map(|b| if b <= c.obstacle_level { 0.0 } else { 1.0 })
                .collect(),
            _ => vec![0.0; c.sectors()],
        }
    }

    fn decide(
        &mut self,
        rule: SectorRule,
        frame: &FrameView<'_>,
        pose: Pose2,
        dt_secs: f64,
    ) -> Decision {
        let c = &self.config;
        let level = frame.value(self.channel, pose.x_m, pose.y_m);
        let theta = pose.theta_rad as f64;
        let due = self.goal_heading_rad.is_none()
            || c.decision_period_s == 0.0
            // (a small tolerance so that ten steps of 0.1 s make one period of 1 s)
            || self.since_decision_s >= c.decision_period_s - 1e-9;
        if due {
            let n = c.sectors();
            let s = match rule {
                SectorRule::Inverse => {
                    let taus = self.taus(frame, pose);
                    choose_inverse(&mut self.rng, &taus, c.u_count, c.v_count)
                }
                SectorRule::Uniform => {
                    // Uniform over the sectors not blocked by an obstacle (all if all are).
                    let open: Vec<usize> = match c.obstacle_channel {
                        Some(_) => {
                            let taus = self.obstacle_taus(frame, pose);
                            (0..n).filter(|&i| taus[i] < 1.0).collect()
                        }
                        None => Vec::new(),
                    };
                    if open.is_empty() {
                        self.rng.random_range(0..n)
                    } else {
                        open[self.rng.random_range(0..open.len())]
                    }
                }
            };
            // Seed 004 eq. 2: θ(t) = θ(t−1) + γ·A_s*.
            self.goal_heading_rad = Some(theta + self.config.gamma * sector_angle(s, n));
            self.since_decision_s = 0.0;
            self.last_sector = Some(s);
            self.decisions += 1;
        }
        let dt = if dt_secs.is_finite() && dt_secs > 0.0 {
            self.since_decision_s += dt_secs;
            dt_secs
        } else {
            f64::INFINITY
        };
        let c = &self.config;
        let err = wrap_pi(self.goal_heading_rad.unwrap_or(theta) - theta);
        Decision {
            v_mps: c.v_mps,
            omega_radps: (err / dt).clamp(-c.omega_max_radps, c.omega_max_radps),
            state: FollowerState::Exploring,
            sensed_level: level,
        }
    }

    fn reset(&mut self) {
        self.goal_heading_rad = None;
        self.since_decision_s = 0.0;
        self.last_sector = None;
    }
}

/// The two sector strategies of seed 004, sharing one steering core:
/// - `inverse` (IAS-SS): each decision senses τ_s in 2S + 1 sectors at R_D, draws a sector from
///   U ∪ V with p(s) ∝ 1 − τ_s (eq. 1) and sets the heading goal θ(t−1) + γ·A_s* (eq. 2);
/// - `uniform` (the paper's baseline): the sector is drawn uniformly from all 2S + 1.
///
/// The command is ω = wrap(goal − θ)/dt clamped to ±`omega_max_radps` (= γ·A_s*/dt when a sector
/// is drawn every step and the clamp is not reached), at the constant speed `v_mps`. State is
/// always `Exploring`.
#[derive(Debug, Clone)]
pub struct SectorStrategy {
    core: SectorSteer,
    rule: SectorRule,
}

impl SectorStrategy {
    /// The IAS-SS strategy (`inverse`).
    pub fn inverse(
        channel: usize,
        config: SectorConfig,
        seed: u64,
    ) -> Result<Self, FollowerConfigError> {
        Ok(Self {
            core: SectorSteer::new(channel, config, seed)?,
            rule: SectorRule::Inverse,
        })
    }

    /// The uniform baseline (`uniform`).
    pub fn uniform(
        channel: usize,
        config: SectorConfig,
        seed: u64,
    ) -> Result<Self, FollowerConfigError> {
        Ok(Self {
            core: SectorSteer::new(channel, config, seed)?,
            rule: SectorRule::Uniform,
        })
    }

    /// The sector drawn at the last decision (0 = rightmost).
    pub fn last_sector(&self) -> Option<usize> {
        self.core.last_sector
    }

    /// Decisions taken so far.
    pub fn decisions(&self) -> u64 {
        self.core.decisions
    }

    pub fn config(&self) -> &SectorConfig {
        &self.core.config
    }
}

impl Strategy for SectorStrategy {
    fn name(&self) -> &'static str {
        match self.rule {
            SectorRule::Inverse => StrategyKind::Inverse.name(),
            SectorRule::Uniform => StrategyKind::Uniform.name(),
        }
    }

    fn channel(&self) -> usize {
        self.core.channel
    }

    fn decide(&mut self, frame: &FrameView<'_>, pose: Pose2, dt_secs: f64) -> Decision {
        self.core.decide(self.rule, frame, pose, dt_secs)
    }

    fn reset(&mut self) {
        self.core.reset();
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

/// A strategy name that is not one of the four.
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
        self.route.validate()
    }

    /// The selected strategy.
    pub fn build(&self) -> Result<Box<dyn Strategy>, FollowerConfigError> {
        self.validate()?;
        let ch = self.channel as usize;
        Ok(match self.strategy {
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
    #[error("dt_secs = {0} must be finite and > 0")]
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
    strategy: Box<dyn Strategy>,
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
    pub fn new(robot_id: u32, strategy: Box<dyn Strategy>) -> Self {
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

    pub fn strategy(&self) -> &dyn Strategy {
        self.strategy.as_ref()
    }

    pub fn strategy_mut(&mut self) -> &mut dyn Strategy {
        self.strategy.as_mut()
    }

    /// One step for world step `step`. Non-finite strategy outputs are replaced by 0 (stop).
    pub fn step(
        &mut self,
        frame: &FrameView<'_>,
        pose: Pose2,
        dt_secs: f64,
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
        if !(dt_secs.is_finite() && dt_secs > 0.0) {
            return Err(FollowError::BadDt(dt_secs));
        }
        let mut d = self.strategy.decide(frame, pose, dt_secs);
        let finite_or_zero = |v: f64| if v.is_finite() { v } else { 0.0 };
        d.v_mps = finite_or_zero(d.v_mps);
        d.omega_radps = finite_or_zero(d.omega_radps);
        if !d.sensed_level.is_finite() {
            d.sensed_level = 0.0;
        }
        let cmd = CmdMsg {
            stamp_ns: 0,
            step,
            robot_id: self.robot_id,
            _pad: 0,
            v_mps: d.v_mps,
            omega_radps: d.omega_radps,
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
        dt_secs: f64,
    ) -> Result<FollowOutput, FollowError> {
        let mut p = Pose2::default();
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
        self.step(frame, p, dt_secs, pose.step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use field::{ChannelSpec, Evaporation, FieldConfig, GridGeometry, OwnedField};

    /// A one-channel synthetic field sampled at cell centres.
    fn synth(
        width_m: f32,
        height_m: f32,
        cell_m: f32,
        f: impl Fn(f32, f32) -> f32,
    ) -> (GridGeometry, Vec<f32>) {
        let g = GridGeometry::new(
            (width_m / cell_m).round() as u32,
            (height_m / cell_m).round() as u32,
            cell_m,
        )
        .unwrap();
        let mut cells = vec![0.0; g.cells()];
        for y in 0..g.height {
            for x in 0..g.width {
                let (wx, wy) = g.world_from_grid(x, y);
                cells[g.index(x, y)] = f(wx, wy);
            }
        }
        (g, cells)
    }

    /// Unicycle kinematics over one step (midpoint heading), in f64.
    #[derive(Debug, Clone, Copy)]
    struct Robot {
        x: f64,
        y: f64,
        th: f64,
    }

    impl Robot {
        fn new(x: f64, y: f64, th: f64) -> Self {
            Self { x, y, th }
        }
        fn pose(&self) -> Pose2 {
            Pose2::new(self.x as f32, self.y as f32, self.th as f32)
        }
        fn advance(&mut self, d: &Decision, dt: f64) {
            let mid = self.th + 0.5 * d.omega_radps * dt;
            self.x += d.v_mps * mid.cos() * dt;
            self.y += d.v_mps * mid.sin() * dt;
            self.th = wrap_pi(self.th + d.omega_radps * dt);
        }
    }

    fn simulate(
        s: &mut dyn Strategy,
        frame: &FrameView<'_>,
        mut r: Robot,
        dt: f64,
        steps: usize,
    ) -> Vec<(Robot, Decision)> {
        (0..steps)
            .map(|_| {
                let d = s.decide(frame, r.pose(), dt);
                r.advance(&d, dt);
                (r, d)
            })
            .collect()
    }

    fn gaussian_ridge(d: f32, amp: f32, sigma: f32) -> f32 {
        amp * (-d * d / (2.0 * sigma * sigma)).exp()
    }

    /// Signed angle (rad, counter-clockwise positive) a trace sweeps around `centre`.
    fn swept_rad(trace: &[(Robot, Decision)], centre: (f64, f64)) -> f64 {
        let polar = |r: &Robot| (r.y - centre.1).atan2(r.x - centre.0);
        trace
            .windows(2)
            .map(|w| wrap_pi(polar(&w[1].0) - polar(&w[0].0)))
            .sum()
    }

    fn mean(v: impl Iterator<Item = f64>) -> f64 {
        let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
        s / n as f64
    }

    // ---- speed table ----

    #[test]
    fn speed_table_matches_seed_000_table_2() {
        let t = table2_speed_bands();
        for (level, v) in [
            (-5.0, 0.15),
            (0.0, 0.15),
            (14.9, 0.15),
            (15.0, 0.45),
            (29.0, 0.45),
            (45.0, 0.65),
            (60.0, 1.0),
            (100.0, 1.0),
            (250.0, 1.0),
        ] {
            assert_eq!(speed_for_level(&t, level), v, "level {level}");
        }
        let cfg = GradientConfig {
            speed_table: vec![
                SpeedBand {
                    from_level: 0.0,
                    v_mps: 0.1,
                },
                SpeedBand {
                    from_level: 0.0,
                    v_mps: 0.2,
                },
            ],
            ..GradientConfig::default()
        };
        let e = cfg.validate().unwrap_err();
        assert!(e.name.contains("speed_table[1]"), "{e}");
    }

    // ---- gradient ----

    #[test]
    fn gradient_climbs_a_gaussian_hill() {
        let (g, cells) = synth(10.0, 10.0, 0.05, |x, y| {
            let r2 = (x - 5.0).powi(2) + (y - 5.0).powi(2);
            100.0 * (-r2 / (2.0 * 1.5 * 1.5)).exp()
        });
        let frame = FrameView::new(g, 1, &cells);
        for (start, th) in [
            ((2.5, 5.5), FRAC_PI_2),
            ((7.5, 2.5), 0.0),
            ((5.0, 8.0), 0.0),
        ] {
            let mut s = GradientFollower::new(0, GradientConfig::default()).unwrap();
            let trace = simulate(&mut s, &frame, Robot::new(start.0, start.1, th), 0.05, 400);
            let dist = |r: &Robot| (r.x - 5.0).hypot(r.y - 5.0);
            let (last, d) = trace.last().unwrap();
            assert!(
                dist(last) < 0.15,
                "from {start:?}: ended {:.3} m from the peak",
                dist(last)
            );
            assert!(
                trace[300..].iter().all(|(r, _)| dist(r) < 0.25),
                "from {start:?}: left the peak"
            );
            assert_eq!(d.state, FollowerState::Following);
            assert!(d.sensed_level > 99.0);
        }
    }

    fn ridge_run(
        cfg: GradientConfig,
        frame: &FrameView<'_>,
        r: Robot,
        steps: usize,
    ) -> Vec<(Robot, Decision)> {
        let mut s = GradientFollower::new(0, cfg).unwrap();
        simulate(&mut s, frame, r, 0.05, steps)
    }

    #[test]
    fn gradient_moves_along_a_straight_ridge() {
        // Trail along y = 5, σ = 0.2 m (about 0.5 m wide), level 80 on the crest.
        let (g, cells) = synth(16.0, 10.0, 0.05, |_, y| gaussian_ridge(y - 5.0, 80.0, 0.2));
        let frame = FrameView::new(g, 1, &cells);
        let trace = ridge_run(
            GradientConfig::default(),
            &frame,
            Robot::new(1.0, 5.3, 0.5),
            300,
        );
        let (last, d) = trace.last().unwrap();
        assert!(last.x > 1.0 + 5.0, "only reached x = {:.2}", last.x);
        assert!(trace
            .iter()
            .all(|(_, d)| d.state != FollowerState::TrailAbandoned));
        let off = mean(trace[100..].iter().map(|(r, _)| (r.y - 5.0).abs()));
        assert!(off < 0.05, "mean offset {off:.3} m");
        assert_eq!(d.state, FollowerState::Following);
        assert!(
            (d.v_mps - 1.0).abs() < 1e-6,
            "level 80 → Table 2 speed 1.0 m/s, got {}",
            d.v_mps
        );
    }

    #[test]
    fn gradient_follows_a_curved_ridge_and_turns_back_at_a_trail_end() {
        // Ring trail of radius 3 m around (6, 6).
        let (g, cells) = synth(12.0, 12.0, 0.05, |x, y| {
            let r = (x - 6.0).hypot(y - 6.0);
            gaussian_ridge(r - 3.0, 80.0, 0.2)
        });
        let frame = FrameView::new(g, 1, &cells);
        let trace = ridge_run(
            GradientConfig::default(),
            &frame,
            Robot::new(6.1, 3.15, 0.0),
            400,
        );
        let off = mean(
            trace
                .iter()
                .map(|(r, _)| ((r.x - 6.0).hypot(r.y - 6.0) - 3.0).abs()),
        );
        assert!(off < 0.1, "mean distance to the arc {off:.3} m");
        // 400 steps at about 1 m/s: more than a full turn of the 18.8 m ring.
        let swept = swept_rad(&trace, (6.0, 6.0));
        assert!(swept > 2.0 * PI, "swept only {swept:.2} rad of the ring");

        // A finite trail from x = 2 to x = 10 m: the follower runs to its end, turns back and
        // follows it the other way.
        let (g, cells) = synth(16.0, 10.0, 0.05, |x, y| {
            let along = if (2.0..=10.0).contains(&x) { 1.0 } else { 0.0 };
            along * gaussian_ridge(y - 5.0, 80.0, 0.2)
        });
        let frame = FrameView::new(g, 1, &cells);
        let trace = ridge_run(
            GradientConfig::default(),
            &frame,
            Robot::new(6.0, 5.0, 0.0),
            300,
        );
        let (turn, max_x) =
            trace.iter().enumerate().fold(
                (0, f64::MIN),
                |b, (i, (r, _))| if r.x > b.1 { (i, r.x) } else { b },
            );
        assert!(
            (9.5..10.5).contains(&max_x),
            "turned back at x = {max_x:.2}"
        );
        let back = trace[turn..]
            .iter()
            .map(|(r, _)| r.x)
            .fold(f64::MAX, f64::min);
        assert!(back < 3.0, "went back only to x = {back:.2}");
        assert!(trace
            .iter()
            .all(|(r, d)| (r.y - 5.0).abs() < 0.3 && d.state == FollowerState::Following));
    }

    #[test]
    fn gradient_abandons_a_fading_trail_and_latches() {
        let (g, base) = synth(10.0, 10.0, 0.05, |x, y| {
            let r2 = (x - 5.0).powi(2) + (y - 5.0).powi(2);
            100.0 * (-r2 / (2.0 * 1.5 * 1.5)).exp()
        });
        for latch in [true, false] {
            let cfg = GradientConfig {
                latch_abandon: latch,
                ..GradientConfig::default()
            };
            let mut s = GradientFollower::new(0, cfg).unwrap();
            let mut r = Robot::new(4.0, 5.0, 0.0);
            let mut amp = 1.0f32;
            let mut abandoned_at = None;
            for k in 0..200 {
                let cells: Vec<f32> = base.iter().map(|v| v * amp).collect();
                let frame = FrameView::new(g, 1, &cells);
                let d = s.decide(&frame, r.pose(), 0.05);
                if d.state == FollowerState::TrailAbandoned {
                    assert!(d.sensed_level < 10.0);
                    assert_eq!((d.v_mps, d.omega_radps), (0.0, 0.0));
                    abandoned_at.get_or_insert(k);
                } else {
                    assert!(
                        abandoned_at.is_none(),
                        "left TrailAbandoned without a stronger trail"
                    );
                    assert!(d.sensed_level >= 10.0 && d.v_mps >= 0.0);
                }
                r.advance(&d, 0.05);
                amp *= 0.97;
            }
            assert!(abandoned_at.is_some(), "never abandoned");
            // The trail comes back (e.g. a new leader deposits).
            let frame = FrameView::new(g, 1, &base);
            let d = s.decide(&frame, r.pose(), 0.05);
            if latch {
                assert_eq!(d.state, FollowerState::TrailAbandoned);
                assert_eq!(d.v_mps, 0.0);
                s.reset();
                assert_eq!(
                    s.decide(&frame, r.pose(), 0.05).state,
                    FollowerState::Following
                );
            } else {
                assert_eq!(d.state, FollowerState::Following);
                assert!(d.v_mps > 0.0 || d.omega_radps != 0.0);
            }
        }
    }

    #[test]
    fn gradient_relative_threshold_uses_the_peak_level() {
        let mut s = GradientFollower::new(
            0,
            GradientConfig {
                abandon_below: 5.0,
                abandon_delta: Some(0.5),
                ..GradientConfig::default()
            },
        )
        .unwrap();
        let g = GridGeometry::new(4, 4, 1.0).unwrap();
        let pose = Pose2::new(2.0, 2.0, 0.0);
        let mut at = |level: f32| {
            let cells = vec![level; g.cells()];
            s.decide(&FrameView::new(g, 1, &cells), pose, 0.1).state
        };
        assert_eq!(at(3.0), FollowerState::Exploring);
        assert_eq!(at(20.0), FollowerState::Following);
        assert_eq!(at(80.0), FollowerState::Following); // P0 = 80
        assert_eq!(at(41.0), FollowerState::Following);
        assert_eq!(at(39.0), FollowerState::TrailAbandoned); // < δ·P0 = 40
        assert_eq!(at(80.0), FollowerState::TrailAbandoned);
    }

    #[test]
    fn gradient_explores_slowly_on_an_empty_field() {
        let g = GridGeometry::new(20, 20, 0.1).unwrap();
        let cells = vec![0.0; g.cells()];
        let mut s = GradientFollower::new(0, GradientConfig::default()).unwrap();
        let d = s.decide(
            &FrameView::new(g, 1, &cells),
            Pose2::new(1.0, 1.0, 0.3),
            0.1,
        );
        assert_eq!(d.state, FollowerState::Exploring);
        assert_eq!((d.v_mps, d.omega_radps), (0.15, 0.0));
    }

    /// End to end with the depositor: a well-localized leader lays a dotted trail (a deposit
    /// every 0.3–0.4 m) into an evaporating field; the follower runs along it to its end, and
    /// abandons it once it has faded below the threshold.
    #[test]
    fn gradient_follows_a_deposited_trail_until_it_fades() {
        use crate::messages::PoseMsg;
        use crate::roles::depositor::{Depositor, DepositorConfig};
        let mut f = OwnedField::new(FieldConfig {
            width: 200,
            height: 200,
            cell_size_m: 0.05,
            tick_hz: 10.0,
            channels: vec![ChannelSpec::new(
                "trail",
                Evaporation::Exponential { decay_per_sec: 0.1 },
            )],
            ..FieldConfig::default()
        })
        .unwrap();
        let mut leader = Depositor::new(DepositorConfig {
            interval_m: 0.3,
            ..DepositorConfig::default()
        })
        .unwrap();
        let mut end_x = 0.0f64;
        for k in 0..=80 {
            let pose = PoseMsg {
                stamp_ns: k * 100_000_000,
                x_m: 1.0 + 0.1 * k as f64,
                y_m: 5.0,
                cov: [0.03, 0.0, 0.0, 0.0, 0.03, 0.0, 0.0, 0.0, 0.01],
                ..PoseMsg::default()
            };
            if let Some(m) = leader.process(&pose).unwrap() {
                f.offer(&m).unwrap();
                end_x = m.x_m as f64;
            }
            f.tick();
        }
        // Every 0.3 m (give or take the rounding of 0.1 m steps) along 8 m.
        assert!(
            (20..=27).contains(&leader.counters().deposits),
            "{:?}",
            leader.counters()
        );
        let mut s = GradientFollower::new(0, GradientConfig::default()).unwrap();
        let mut r = Robot::new(1.3, 5.15, 0.3);
        let (mut max_x, mut abandoned_at, mut offsets) = (0.0f64, None, Vec::new());
        for k in 0..500 {
            let d = s.decide(&f.view(), r.pose(), 0.1);
            if d.state == FollowerState::TrailAbandoned {
                abandoned_at.get_or_insert((k, d.sensed_level));
                assert_eq!((d.v_mps, d.omega_radps), (0.0, 0.0));
            } else {
                assert!(abandoned_at.is_none());
                assert_eq!(d.state, FollowerState::Following);
                offsets.push((r.y - 5.0).abs());
            }
            r.advance(&d, 0.1);
            max_x = max_x.max(r.x);
            f.tick();
        }
        // It ran to the end of the trail (the last deposit) before turning back.
        assert!(
            end_x > 8.5 && max_x > end_x - 0.3,
            "reached only x = {max_x:.2} (trail end {end_x:.2})"
        );
        let (k, level) = abandoned_at.expect("the faded trail was never abandoned");
        assert!(
            k > 100 && level < 10.0,
            "abandoned at step {k}, level {level}"
        );
        let off = mean(offsets.iter().copied());
        assert!(off < 0.1, "mean offset {off:.3} m");
    }

    // ---- antenna ----

    fn antenna() -> AntennaFollower {
        AntennaFollower::new(0, AntennaConfig::default()).unwrap()
    }

    #[test]
    fn antenna_follows_a_straight_trail() {
        let (g, cells) = synth(14.0, 10.0, 0.05, |_, y| gaussian_ridge(y - 5.0, 1.0, 0.2));
        let frame = FrameView::new(g, 1, &cells);
        let trace = simulate(
            &mut antenna(),
            &frame,
            Robot::new(1.0, 5.25, -0.35),
            0.05,
            300,
        );
        // Seed 002's criterion: mean distance to the path, sampled every 0.2 s.
        let err = mean(trace.iter().step_by(4).map(|(r, _)| (r.y - 5.0).abs()));
        assert!(err < 0.2, "mean distance {err:.3} m");
        let settled = mean(trace[100..].iter().map(|(r, _)| (r.y - 5.0).abs()));
        assert!(settled < 0.03, "settled mean distance {settled:.3} m");
        assert!(
            trace.last().unwrap().0.x > 1.0 + 5.0,
            "too slow: x = {:.2}",
            trace.last().unwrap().0.x
        );
        assert!(trace
            .iter()
            .all(|(_, d)| d.state == FollowerState::Following));
    }

    #[test]
    fn antenna_follows_a_circular_arc() {
        let (g, cells) = synth(12.0, 12.0, 0.05, |x, y| {
            let r = (x - 6.0).hypot(y - 6.0);
            gaussian_ridge(r - 3.0, 1.0, 0.2)
        });
        let frame = FrameView::new(g, 1, &cells);
        let trace = simulate(
            &mut antenna(),
            &frame,
            Robot::new(6.0, 2.85, 0.2),
            0.05,
            400,
        );
        let dist = |r: &Robot| ((r.x - 6.0).hypot(r.y - 6.0) - 3.0).abs();
        let err = mean(trace.iter().step_by(4).map(|(r, _)| dist(r)));
        assert!(err < 0.2, "mean distance {err:.3} m");
        // 400 steps at up to 0.5 m/s: at least a quarter of the ring, counter-clockwise.
        let swept = swept_rad(&trace, (6.0, 6.0));
        assert!(swept > FRAC_PI_2, "swept only {swept:.2} rad of the arc");
    }

    #[test]
    fn antenna_turns_toward_the_stronger_side_and_explores_on_nothing() {
        // Pheromone only at y > 5 (left of a robot heading +x at y = 5).
        let (g, cells) = synth(10.0, 10.0, 0.05, |_, y| if y > 5.0 { 1.0 } else { 0.0 });
        let frame = FrameView::new(g, 1, &cells);
        let d = antenna().decide(&frame, Pose2::new(5.0, 5.0, 0.0), 0.05);
        assert!(
            d.omega_radps > 0.0,
            "should turn left (toward the stronger antenna): {d:?}"
        );
        assert!(d.v_mps < 0.5 && d.state == FollowerState::Following);
        // Symmetric readings: straight on at full speed K.
        let (g2, even) = synth(10.0, 10.0, 0.05, |_, _| 0.7);
        let d = antenna().decide(
            &FrameView::new(g2, 1, &even),
            Pose2::new(5.0, 5.0, 1.0),
            0.05,
        );
        assert_eq!(
            (d.v_mps, d.omega_radps, d.state),
            (0.5, 0.0, FollowerState::Following)
        );
        // Nothing at all: exploring.
        let zero = vec![0.0; g.cells()];
        let d = antenna().decide(
            &FrameView::new(g, 1, &zero),
            Pose2::new(5.0, 5.0, 0.0),
            0.05,
        );
        assert_eq!(
            (d.state, d.v_mps, d.omega_radps),
            (FollowerState::Exploring, 0.1, 0.0)
        );
    }

    // ---- sector strategies ----

    #[test]
    fn eq1_probabilities_are_inverse_to_pheromone() {
        let taus = [0.0f32, 0.5, 0.75, 1.0, 2.0, -1.0];
        let p = inverse_probabilities(&taus, &[0, 1, 2, 3]);
        let expect = [1.0 / 1.75, 0.5 / 1.75, 0.25 / 1.75, 0.0];
        for (a, b) in p.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{p:?}");
        }
        // Clamped to [0, 1]; all saturated → uniform over the members.
        assert_eq!(inverse_probabilities(&taus, &[3, 4]), vec![0.5, 0.5]);
        assert_eq!(inverse_probabilities(&taus, &[5, 0]), vec![0.5, 0.5]);
    }

    #[test]
    fn u_holds_the_lowest_sectors_and_v_the_others() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let taus = [0.9f32, 0.1, 0.8, 0.05, 0.7, 0.6, 0.95];
        for _ in 0..50 {
            let m = draw_members(&mut rng, &taus, 2, 3);
            assert_eq!(&m[..2], &[3, 1]);
            assert_eq!(m.len(), 5);
            let mut v = m[2..].to_vec();
            v.sort_unstable();
            v.dedup();
            assert_eq!(v.len(), 3);
            assert!(v.iter().all(|s| ![1, 3].contains(s)));
        }
        // Ties are broken at random: on an empty field U is not always the rightmost sectors.
        let flat = [0.0f32; 9];
        let firsts: std::collections::HashSet<usize> = (0..100)
            .map(|_| draw_members(&mut rng, &flat, 1, 0)[0])
            .collect();
        assert!(firsts.len() >= 7, "{firsts:?}");
    }

    /// Half the field (left of the robot) is saturated with pheromone.
    fn half_field() -> (GridGeometry, Vec<f32>) {
        synth(10.0, 10.0, 0.1, |_, y| if y > 5.0 { 0.9 } else { 0.1 })
    }

    #[test]
    fn inverse_prefers_low_pheromone_sectors_over_uniform() {
        let (g, cells) = half_field();
        let frame = FrameView::new(g, 1, &cells);
        let pose = Pose2::new(5.0, 5.0, 0.0);
        let cfg = SectorConfig::default();
        let taus = frame.sector_means(0, pose, cfg.radius_m, cfg.half_sectors);
        let low: Vec<bool> = taus.iter().map(|&t| t < 0.5).collect();
        assert_eq!(low.iter().filter(|&&l| l).count(), 4, "{taus:?}");
        assert!(
            taus.iter()
                .all(|&t| !(0.2..0.8).contains(&t) || t == taus[4]),
            "{taus:?}"
        );

        let n = 2000;
        let mut inverse = SectorStrategy::inverse(0, cfg.clone(), 42).unwrap();
        let mut uniform = SectorStrategy::uniform(0, cfg, 42).unwrap();
        let (mut k_inv, mut k_uni) = (0usize, 0usize);
        for _ in 0..n {
            inverse.decide(&frame, pose, 0.1);
            uniform.decide(&frame, pose, 0.1);
            k_inv += low[inverse.last_sector().unwrap()] as usize;
            k_uni += low[uniform.last_sector().unwrap()] as usize;
        }
        assert_eq!(
            (inverse.decisions(), uniform.decisions()),
            (n as u64, n as u64)
        );
        let (p1, p2) = (k_inv as f64 / n as f64, k_uni as f64 / n as f64);
        let pooled = (k_inv + k_uni) as f64 / (2 * n) as f64;
        let z = (p1 - p2) / (pooled * (1.0 - pooled) * 2.0 / n as f64).sqrt();
        assert!(z > 3.0, "inverse {p1:.3} vs uniform {p2:.3}: z = {z:.2}");
        // Uniform picks a low sector about 4/9 of the time.
        assert!((p2 - 4.0 / 9.0).abs() < 0.05, "uniform share {p2:.3}");
    }

    #[test]
    fn sector_steering_follows_eq2_and_is_deterministic() {
        let (g, cells) = half_field();
        let frame = FrameView::new(g, 1, &cells);
        let pose = Pose2::new(5.0, 5.0, 0.4);
        let cfg = SectorConfig {
            omega_max_radps: 100.0,
            ..SectorConfig::default()
        };
        let n = cfg.sectors();
        let mut s = SectorStrategy::inverse(0, cfg.clone(), 1).unwrap();
        for _ in 0..20 {
            let d = s.decide(&frame, pose, 0.1);
            let a = sector_angle(s.last_sector().unwrap(), n);
            // ω = γ·A_s*/dt (eq. 2 over one step).
            assert!((d.omega_radps - 0.5 * a / 0.1).abs() < 1e-5, "{d:?}");
            assert_eq!((d.v_mps, d.state), (0.3, FollowerState::Exploring));
        }
        // Clamped turn rate.
        let mut c = SectorStrategy::inverse(0, SectorConfig::default(), 1).unwrap();
        assert!(c.decide(&frame, pose, 0.01).omega_radps.abs() <= 1.5);
        // Same seed, same choices; another seed, other choices.
        let run = |seed| {
            let mut s = SectorStrategy::inverse(0, cfg.clone(), seed).unwrap();
            (0..50)
                .map(|_| {
                    s.decide(&frame, pose, 0.1);
                    s.last_sector().unwrap()
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
    }

    #[test]
    fn decision_period_holds_the_heading_goal() {
        let (g, cells) = half_field();
        let frame = FrameView::new(g, 1, &cells);
        let cfg = SectorConfig {
            decision_period_s: 1.0,
            ..SectorConfig::default()
        };
        let mut s = SectorStrategy::uniform(0, cfg, 9).unwrap();
        let mut r = Robot::new(5.0, 5.0, 0.0);
        let mut goal = None;
        for k in 0..40 {
            let d = s.decide(&frame, r.pose(), 0.1);
            if k % 10 == 0 {
                let a = sector_angle(s.last_sector().unwrap(), 9);
                goal = Some(r.th + 0.5 * a);
            }
            assert!(d.omega_radps.abs() <= 1.5 + 1e-12);
            r.advance(&d, 0.1);
            if k % 10 == 9 {
                assert!(
                    wrap_pi(goal.unwrap() - r.th).abs() < 1e-5,
                    "goal not reached by step {k}"
                );
            }
        }
        assert_eq!(s.decisions(), 4);
    }

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
            assert_eq!(out.cmd.v_mps, out.decision.v_mps);
            assert_eq!(out.cmd.omega_radps, out.decision.omega_radps);
            assert_eq!(
                FollowerState::from_code(out.status.state),
                Some(out.decision.state)
            );
            assert_eq!(out.status.sensed_level, out.decision.sensed_level);
            assert!(out.cmd.v_mps.is_finite() && out.cmd.omega_radps.is_finite());
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
            .step(&frame, Pose2::new(1.0, 1.0, 0.0), 0.1, 0)
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
            .step(&frame, Pose2::new(f32::NAN, 1.0, 0.0), 0.1, 0)
            .unwrap_err();
        assert!(matches!(e, FollowError::BadPose { name: "x_m", .. }), "{e}");
        assert!(matches!(
            f.step(&frame, Pose2::new(1.0, 1.0, 0.0), 0.0, 0),
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
            let w = wrap_pi(a);
            assert!(w > -PI - 1e-12 && w <= PI + 1e-12, "{a} → {w}");
            assert!(
                ((a - w) / (2.0 * PI)).fract().abs() < 1e-9
                    || ((a - w) / (2.0 * PI)).fract().abs() > 1.0 - 1e-9
            );
        }
    }
}
