//! The `antenna` strategy of seed 002: two virtual antennas half a wheel base to each side
//! (eq. 5 with the MODELS.md M3 convention), turn toward the stronger one, forward speed
//! K·(1 − |P_L − P_R|) (the evident intent of eq. 6).

use pheromone_field::sources::SourceSensing;
use pheromone_field::{FrameView, SamplePose};
use serde::{Deserialize, Serialize};

use super::{
    check_nonneg, check_positive, invalid, Decision, FollowerConfigError, FollowerStrategy,
    StrategyKind,
};
use pheromone_messages::FollowerState;

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
    #[serde(alias = "k_v_mps")]
    pub k_v_m_per_s: f64,
    /// Turn rate per unit normalized difference: ω = k·(P_L − P_R) (rad/s).
    #[serde(alias = "omega_gain_radps")]
    pub omega_gain_rad_per_s: f64,
    #[serde(alias = "omega_max_radps")]
    pub omega_max_rad_per_s: f64,
    /// Both readings at or below this count as "no pheromone" (state `Exploring`).
    pub min_level: f32,
    /// Forward speed while exploring (m/s); 0 = stop.
    #[serde(alias = "explore_v_mps")]
    pub explore_v_m_per_s: f64,
    /// The channel's sources (MODELS.md M3) when it has them: the readings are then eq. 4 seen
    /// by directional antennas (`pheromone_field::sources::antennas`). Not a key of the
    /// scenario's follower: the scenario copies its channel's `sources` here.
    #[serde(skip)]
    pub sources: Option<SourceSensing>,
}

impl Default for AntennaConfig {
    fn default() -> Self {
        Self {
            wheel_base_m: 0.3,
            antenna_ahead_m: 0.15,
            normalize_max: None,
            k_v_m_per_s: 0.5,
            omega_gain_rad_per_s: 3.0,
            omega_max_rad_per_s: 2.0,
            min_level: 1e-3,
            explore_v_m_per_s: 0.1,
            sources: None,
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
        check_nonneg("antenna.k_v_m_per_s", self.k_v_m_per_s)?;
        check_nonneg("antenna.omega_gain_rad_per_s", self.omega_gain_rad_per_s)?;
        check_positive("antenna.omega_max_rad_per_s", self.omega_max_rad_per_s)?;
        check_nonneg("antenna.min_level", self.min_level as f64)?;
        check_nonneg("antenna.explore_v_m_per_s", self.explore_v_m_per_s)?;
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
/// On a source channel (`sources`, M3) the antennas are directional: on the axis they see only
/// the sources ahead, which measures the heading error as well, so `trail-following` keeps
/// them on the axis (`antenna_ahead_m = 0`, eq. 5).
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

    /// The point the two antennas sit either side of: the pose moved `antenna_ahead_m` along
    /// its heading. A thin client sends this pose in its PIR (with half the wheel base), so
    /// the gateway reads exactly the points [`Self::readings`] reads.
    pub fn head(&self, pose: SamplePose) -> SamplePose {
        let a = self.config.antenna_ahead_m;
        let (s, c) = pose.theta_rad.sin_cos();
        SamplePose::new(pose.x_m + a * c, pose.y_m + a * s, pose.theta_rad)
    }

    /// Raw readings (P_L, P_R) at the antenna points.
    /// On a source channel, each antenna sees only its field of view (M3).
    pub fn readings(&self, frame: &FrameView<'_>, pose: SamplePose) -> (f32, f32) {
        let (head, b) = (self.head(pose), self.config.wheel_base_m);
        match &self.config.sources {
            Some(s) => pheromone_field::sources::antennas(frame, self.channel, head, b, s),
            None => frame.antennas(self.channel, head, b),
        }
    }

    /// The decision from the two readings, wherever they were read (a frame in shared memory or
    /// a gateway's PIR reply).
    pub fn decide_readings(&self, pl: f32, pr: f32) -> Decision {
        let c = &self.config;
        let level = 0.5 * (pl + pr);
        let strongest = pl.max(pr);
        if strongest.is_nan() || strongest <= c.min_level {
            return Decision {
                v_m_per_s: c.explore_v_m_per_s,
                omega_rad_per_s: 0.0,
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
            v_m_per_s: c.k_v_m_per_s * (1.0 - diff.abs()),
            omega_rad_per_s: (c.omega_gain_rad_per_s * diff)
                .clamp(-c.omega_max_rad_per_s, c.omega_max_rad_per_s),
            state: FollowerState::Following,
            sensed_level: level,
        }
    }
}

impl FollowerStrategy for AntennaFollower {
    fn name(&self) -> &'static str {
        StrategyKind::Antenna.name()
    }

    fn channel(&self) -> usize {
        self.channel
    }

    fn decide(&mut self, frame: &FrameView<'_>, pose: SamplePose, _dt_s: f64) -> Decision {
        let (pl, pr) = self.readings(frame, pose);
        self.decide_readings(pl, pr)
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::FRAC_PI_2;

    use super::*;
    use crate::follower::test_support::{gaussian_ridge, mean, simulate, swept_rad, synth, Robot};

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
        let d = antenna().decide(&frame, SamplePose::new(5.0, 5.0, 0.0), 0.05);
        assert!(
            d.omega_rad_per_s > 0.0,
            "should turn left (toward the stronger antenna): {d:?}"
        );
        assert!(d.v_m_per_s < 0.5 && d.state == FollowerState::Following);
        // Symmetric readings: straight on at full speed K.
        let (g2, even) = synth(10.0, 10.0, 0.05, |_, _| 0.7);
        let d = antenna().decide(
            &FrameView::new(g2, 1, &even),
            SamplePose::new(5.0, 5.0, 1.0),
            0.05,
        );
        assert_eq!(
            (d.v_m_per_s, d.omega_rad_per_s, d.state),
            (0.5, 0.0, FollowerState::Following)
        );
        // Nothing at all: exploring.
        let zero = vec![0.0; g.cells()];
        let d = antenna().decide(
            &FrameView::new(g, 1, &zero),
            SamplePose::new(5.0, 5.0, 0.0),
            0.05,
        );
        assert_eq!(
            (d.state, d.v_m_per_s, d.omega_rad_per_s),
            (FollowerState::Exploring, 0.1, 0.0)
        );
    }
}
