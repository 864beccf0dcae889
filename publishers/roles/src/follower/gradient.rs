//! The `gradient` strategy of seed 000: climbs ∇P (eqs. 15–16) with a ridge-aware look-ahead,
//! adapts its speed to the sensed level by the Table 2 speed table, and rejects a trail below an
//! absolute level or δ·P0 (MODELS.md M1).

use pheromone_field::{FrameView, SamplePose};
use serde::{Deserialize, Serialize};

use super::{
    check_nonneg, check_positive, invalid, wrap_angle, Decision, FollowerConfigError,
    FollowerStrategy, StrategyKind,
};
use pheromone_messages::FollowerState;

// ---------------------------------------------------------------------------------------------
// Speed adaptation (seed 000 Table 2)

/// One row of the speed table: from this sensed level up to the next row's, drive at `v_m_per_s`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedBand {
    pub from_level: f32,
    #[serde(alias = "v_mps")]
    pub v_m_per_s: f64,
}

/// Seed 000 Table 2: sensed 0–15 → 0.15 m/s, 15–30 → 0.45, 30–60 → 0.65, 60–100 → 1.0.
pub fn table2_speed_bands() -> Vec<SpeedBand> {
    [(0.0, 0.15), (15.0, 0.45), (30.0, 0.65), (60.0, 1.0)]
        .into_iter()
        .map(|(from_level, v_m_per_s)| SpeedBand {
            from_level,
            v_m_per_s,
        })
        .collect()
}

/// The speed of the highest band whose `from_level` ≤ `level` (the first band's below all of
/// them). Levels above the last band keep its speed.
pub fn speed_for_level(bands: &[SpeedBand], level: f32) -> f64 {
    let first = bands.first().map_or(0.0, |b| b.v_m_per_s);
    bands
        .iter()
        .take_while(|b| b.from_level <= level)
        .last()
        .map_or(first, |b| b.v_m_per_s)
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
        check_nonneg(&format!("{prefix}.speed_table[{i}].v_m_per_s"), b.v_m_per_s)?;
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
    /// far apart for their width) looks like its end. 1 = never turn back (on a channel of
    /// non-negative levels): at the end of a trail the follower drives on and gives it up.
    pub turn_back_margin: f32,
    /// Stop where the trail ends ahead (by the `turn_back_margin` test) instead of turning back:
    /// the end of a trail is where its leader is, as far as a follower can tell (seed 000: Alice
    /// waits at A). The follower stays `Following` there.
    pub stop_at_trail_end: bool,
    /// Issue 48 part 3: while following, never steer further than the fan's half angle from
    /// the direction it travels along the trail (its heading smoothed over about 20
    /// decisions), unless the trail ends outright ahead (the `turn_back_margin` test): a trail
    /// that fades gradually never turns it back along the way it came; it drives on and
    /// rejects the trail below the threshold. Off by default.
    pub keep_direction: bool,
    /// The look-ahead fan spans ± this angle around the heading (degrees, ≤ 180).
    pub fan_half_angle_deg: f64,
    /// Rays in the fan (≥ 1).
    pub fan_rays: usize,
    /// Proportional heading gain: ω = k·(heading error), clamped (1/s).
    pub heading_gain_per_s: f64,
    #[serde(alias = "omega_max_radps")]
    pub omega_max_rad_per_s: f64,
    /// Forward speed while no trail is acquired (m/s); 0 = wait in place.
    #[serde(alias = "explore_v_mps")]
    pub explore_v_m_per_s: f64,
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
            stop_at_trail_end: false,
            keep_direction: false,
            fan_half_angle_deg: 90.0,
            fan_rays: 17,
            heading_gain_per_s: 3.0,
            omega_max_rad_per_s: 1.5,
            explore_v_m_per_s: 0.15,
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
        if !(0.0..=1.0).contains(&self.turn_back_margin) {
            return Err(invalid(
                "gradient.turn_back_margin",
                self.turn_back_margin,
                "must be within [0, 1]",
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
        check_positive("gradient.omega_max_rad_per_s", self.omega_max_rad_per_s)?;
        check_nonneg("gradient.explore_v_m_per_s", self.explore_v_m_per_s)?;
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
/// States: `Exploring` until the level reaches `abandon_below` (moving at `explore_v_m_per_s` with
/// the same steering), then `Following`; `TrailAbandoned` (v = 0, ω = 0) when the level falls
/// below max(`abandon_below`, δ·P0), latched unless `latch_abandon` is false.
#[derive(Debug, Clone)]
pub struct GradientFollower {
    channel: usize,
    config: GradientConfig,
    state: FollowerState,
    /// P0: the highest level sensed since the trail was acquired.
    peak_level: f32,
    /// The direction it travels along the trail (rad; the heading, smoothed over about 20
    /// decisions), set while following.
    travel_rad: Option<f64>,
}

impl GradientFollower {
    pub fn new(channel: usize, config: GradientConfig) -> Result<Self, FollowerConfigError> {
        config.validate()?;
        Ok(Self {
            channel,
            config,
            state: FollowerState::Exploring,
            peak_level: 0.0,
            travel_rad: None,
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
            FollowerState::TrailAbandoned | FollowerState::LeaderLost => {
                if !self.config.latch_abandon && acquire {
                    self.state = FollowerState::Following;
                    self.peak_level = level;
                }
            }
        }
    }

    /// Score of the direction `phi`: the mean level at `lookahead_samples` points spread evenly
    /// along the ray up to `lookahead_m` (the mean smooths a dotted trail).
    fn ray_score(&self, frame: &FrameView<'_>, pose: SamplePose, phi: f64) -> f32 {
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

    /// The directions of the look-ahead fan around the heading `th` (rad).
    fn fan_angles(&self, th: f64) -> Vec<f64> {
        let n = self.config.fan_rays;
        let half = self.config.fan_half_angle_deg.to_radians();
        if n == 1 {
            return vec![th];
        }
        let step = 2.0 * half / (n - 1) as f64;
        (0..n).map(|k| th - half + k as f64 * step).collect()
    }

    /// Whether the trail ends ahead: every ray of the fan scores below the level here by more
    /// than `turn_back_margin` of it.
    pub fn trail_ends_ahead(&self, frame: &FrameView<'_>, pose: SamplePose) -> bool {
        let here = frame.value(self.channel, pose.x_m, pose.y_m);
        let best = self
            .fan_angles(pose.theta_rad as f64)
            .into_iter()
            .map(|a| self.ray_score(frame, pose, a))
            .fold(f32::NEG_INFINITY, f32::max);
        here > 0.0 && best < here - self.config.turn_back_margin * here
    }

    /// The desired heading (rad, world frame), or `None` where the field is flat.
    pub fn desired_heading(&self, frame: &FrameView<'_>, pose: SamplePose) -> Option<f64> {
        let th = pose.theta_rad as f64;
        let n = self.config.fan_rays;
        let half = self.config.fan_half_angle_deg.to_radians();
        let step = if n > 1 {
            2.0 * half / (n - 1) as f64
        } else {
            0.0
        };
        let angles = self.fan_angles(th);
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
            let in_fan = wrap_angle(phi_g - th).abs() <= half + 1e-9;
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

impl FollowerStrategy for GradientFollower {
    fn name(&self) -> &'static str {
        StrategyKind::Gradient.name()
    }

    fn channel(&self) -> usize {
        self.channel
    }

    fn decide(&mut self, frame: &FrameView<'_>, pose: SamplePose, _dt_s: f64) -> Decision {
        let level = frame.value(self.channel, pose.x_m, pose.y_m);
        self.update_state(level);
        if self.state == FollowerState::TrailAbandoned
            || (self.state == FollowerState::Following
                && self.config.stop_at_trail_end
                && self.trail_ends_ahead(frame, pose))
        {
            return Decision::stop(self.state, level);
        }
        let th = pose.theta_rad as f64;
        let desired = self.desired_heading(frame, pose);
        let keep = self.config.keep_direction;
        let desired = match (self.state, self.travel_rad) {
            (FollowerState::Following, Some(travel)) if keep => {
                let t = wrap_angle(travel + 0.05 * wrap_angle(th - travel));
                self.travel_rad = Some(t);
                // Issue 48 part 3: a trail that fades never turns the follower back along the
                // way it came; only where the trail ends outright (everything ahead below the
                // `turn_back_margin` test) may it turn further than the fan from its travel.
                let half = self.config.fan_half_angle_deg.to_radians();
                desired.map(|phi| {
                    let off = wrap_angle(phi - t);
                    if off.abs() <= half || self.trail_ends_ahead(frame, pose) {
                        phi
                    } else {
                        t + off.clamp(-half, half)
                    }
                })
            }
            (FollowerState::Following, None) if keep => {
                self.travel_rad = Some(th);
                desired
            }
            _ => {
                self.travel_rad = None;
                desired
            }
        };
        let c = &self.config;
        let err = desired.map_or(0.0, |phi| wrap_angle(phi - th));
        let omega =
            (c.heading_gain_per_s * err).clamp(-c.omega_max_rad_per_s, c.omega_max_rad_per_s);
        let v_base = match self.state {
            FollowerState::Following => {
                speed_for_level(&c.speed_table, level * c.speed_level_scale)
            }
            _ => c.explore_v_m_per_s,
        };
        Decision {
            v_m_per_s: v_base * err.cos().max(0.0),
            omega_rad_per_s: omega,
            state: self.state,
            sensed_level: level,
        }
    }

    fn reset(&mut self) {
        self.state = FollowerState::Exploring;
        self.peak_level = 0.0;
        self.travel_rad = None;
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::{FRAC_PI_2, PI};

    use pheromone_field::{ChannelSpec, Evaporation, FieldConfig, GridGeometry, OwnedField};

    use super::*;
    use crate::follower::test_support::{gaussian_ridge, mean, simulate, swept_rad, synth, Robot};

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
                    v_m_per_s: 0.1,
                },
                SpeedBand {
                    from_level: 0.0,
                    v_m_per_s: 0.2,
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
            (d.v_m_per_s - 1.0).abs() < 1e-6,
            "level 80 → Table 2 speed 1.0 m/s, got {}",
            d.v_m_per_s
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
    fn gradient_can_stop_at_a_trail_end_and_wait_there() {
        // A trail of σ = 0.1 m deposits along y = 5 that ends at x = 10 (a deposit's edge).
        let (g, cells) = synth(16.0, 10.0, 0.05, |x, y| {
            let end = (-(x - 10.0).max(0.0).powi(2) / (2.0 * 0.1 * 0.1)).exp();
            end * gaussian_ridge(y - 5.0, 80.0, 0.1)
        });
        let frame = FrameView::new(g, 1, &cells);
        let cfg = GradientConfig {
            abandon_below: 2.0,
            turn_back_margin: 0.9,
            stop_at_trail_end: true,
            fan_half_angle_deg: 60.0,
            ..GradientConfig::default()
        };
        let trace = ridge_run(cfg, &frame, Robot::new(6.0, 5.05, 0.0), 300);
        let (last, d) = trace.last().unwrap();
        let stop = (d.state, d.v_m_per_s, d.omega_rad_per_s);
        assert_eq!(stop, (FollowerState::Following, 0.0, 0.0));
        assert!((9.9..10.4).contains(&last.x), "stopped at x = {}", last.x);
        assert!(
            trace.iter().all(|(r, _)| r.x <= last.x + 1e-9),
            "it turned back"
        );
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
                    assert_eq!((d.v_m_per_s, d.omega_rad_per_s), (0.0, 0.0));
                    abandoned_at.get_or_insert(k);
                } else {
                    assert!(
                        abandoned_at.is_none(),
                        "left TrailAbandoned without a stronger trail"
                    );
                    assert!(d.sensed_level >= 10.0 && d.v_m_per_s >= 0.0);
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
                assert_eq!(d.v_m_per_s, 0.0);
                s.reset();
                assert_eq!(
                    s.decide(&frame, r.pose(), 0.05).state,
                    FollowerState::Following
                );
            } else {
                assert_eq!(d.state, FollowerState::Following);
                assert!(d.v_m_per_s > 0.0 || d.omega_rad_per_s != 0.0);
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
        let pose = SamplePose::new(2.0, 2.0, 0.0);
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
            SamplePose::new(1.0, 1.0, 0.3),
            0.1,
        );
        assert_eq!(d.state, FollowerState::Exploring);
        assert_eq!((d.v_m_per_s, d.omega_rad_per_s), (0.15, 0.0));
    }

    /// End to end with the depositor: a well-localized leader lays a dotted trail (a deposit
    /// every 0.3–0.4 m) into an evaporating field; the follower runs along it to its end, and
    /// abandons it once it has faded below the threshold.
    #[test]
    fn gradient_follows_a_deposited_trail_until_it_fades() {
        use crate::depositor::{AmountForm, Depositor, DepositorConfig};
        use pheromone_messages::PoseMsg;
        let mut f = OwnedField::new(FieldConfig {
            width: 200,
            height: 200,
            cell_size_m: 0.05,
            tick_hz: 10.0,
            channels: vec![ChannelSpec::new(
                "trail",
                Evaporation::Exponential { decay_per_s: 0.1 },
            )],
            ..FieldConfig::default()
        })
        .unwrap();
        let mut leader = Depositor::new(DepositorConfig {
            interval_m: 0.3,
            // γ as the peak (eqs. 12, 14 as printed): σ = 0.17 m is within the cap.
            amount: AmountForm::Literal,
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
                assert_eq!((d.v_m_per_s, d.omega_rad_per_s), (0.0, 0.0));
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

    /// Issue 48 part 3: a lost leader's trail brightens where its ellipse first widens (γ still
    /// capped), then fades and widens as its uncertainty grows. The follower keeps going along
    /// it, never back toward the brighter part behind, and rejects it where it falls below
    /// max(10, δ·P0) (seed 000 eqs. 24–26, T = δ·P0).
    #[test]
    fn gradient_never_turns_back_on_a_fading_trail_and_rejects_it_below_delta_p0() {
        let crest = |x: f32| {
            if x < 5.0 {
                100.0
            } else if x < 7.0 {
                100.0 + 80.0 * ((x - 5.0) / 2.0)
            } else {
                (180.0 * (1.0 - (x - 7.0) / 10.0)).max(0.0)
            }
        };
        let (g, cells) = synth(20.0, 10.0, 0.05, |x, y| {
            let sigma = 0.2 + 0.08 * (x - 7.0).max(0.0);
            gaussian_ridge(y - 5.0, crest(x), sigma)
        });
        let frame = FrameView::new(g, 1, &cells);
        for (margin, stop) in [(0.9, true), (0.9, false), (0.5, false)] {
            let cfg = GradientConfig {
                keep_direction: true,
                abandon_below: 10.0,
                abandon_delta: Some(0.25),
                speed_level_scale: 0.1,
                turn_back_margin: margin,
                stop_at_trail_end: stop,
                fan_half_angle_deg: 60.0,
                ..GradientConfig::default()
            };
            let trace = ridge_run(cfg, &frame, Robot::new(1.0, 5.0, 0.0), 2000);
            let mut max_x = f64::NEG_INFINITY;
            let mut abandoned = None;
            for (r, d) in &trace {
                max_x = max_x.max(r.x);
                assert!(
                    r.x > max_x - 0.2,
                    "turned back at x = {:.2} (margin {margin})",
                    r.x
                );
                if d.state == FollowerState::TrailAbandoned && abandoned.is_none() {
                    abandoned = Some((r.x, d.sensed_level));
                }
            }
            let (x, level) = abandoned.expect("never rejected the fading trail");
            // P0 = 180 (the bright part): rejected below 45, where the crest is at x = 14.5.
            assert!(
                level < 45.0 && (13.5..15.5).contains(&x),
                "rejected at x = {x:.2}, {level}"
            );
        }
    }
}
