//! Odometry slip zones (`[[world.slip]]`, issue 48): a stretch of floor where a robot's wheels
//! slip, so its odometry errs beyond what its localizer's motion model assumes. Inside a zone
//! the listed robots' odometry has the zone's control noise (α1..α4 of the velocity motion
//! model, in place of the robot's) and reports a turn rate off by `turn_bias_rad_per_s` (a
//! wheel that slips on one side: the robot truly drives as commanded, its odometry says it
//! turned). Nothing else changes: the true motion, the observations and the laser.

use serde::{Deserialize, Serialize};

use crate::{invalid, NoiseConfig, WorldError};

/// One zone: an axis-aligned rectangle of floor, its odometry noise and turn-rate bias.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlipZone {
    /// Lower-left corner [x, y] (m).
    pub min_m: [f64; 2],
    /// Upper-right corner [x, y] (m).
    pub max_m: [f64; 2],
    /// (m/s)² of v-noise per (m/s)² of v, inside the zone.
    pub alpha1: f64,
    /// (m/s)² of v-noise per (rad/s)² of ω.
    pub alpha2: f64,
    /// (rad/s)² of ω-noise per (m/s)² of v.
    pub alpha3: f64,
    /// (rad/s)² of ω-noise per (rad/s)² of ω.
    pub alpha4: f64,
    /// Added to the odometry's turn rate while the robot moves (rad/s, counter-clockwise).
    #[serde(default)]
    pub turn_bias_rad_per_s: f64,
    /// The robots whose wheels slip here (by id); empty = every robot.
    #[serde(default)]
    pub robots: Vec<u32>,
}

impl SlipZone {
    /// Whether the zone applies to robot `id` at (`x_m`, `y_m`).
    pub fn applies(&self, id: u32, x_m: f64, y_m: f64) -> bool {
        (self.robots.is_empty() || self.robots.contains(&id))
            && (self.min_m[0]..=self.max_m[0]).contains(&x_m)
            && (self.min_m[1]..=self.max_m[1]).contains(&y_m)
    }

    /// `noise` with the zone's α1..α4.
    pub fn odometry_noise(&self, noise: &NoiseConfig) -> NoiseConfig {
        NoiseConfig {
            alpha1: self.alpha1,
            alpha2: self.alpha2,
            alpha3: self.alpha3,
            alpha4: self.alpha4,
            ..*noise
        }
    }

    /// Checks zone `i`: finite corners with min < max, α ≥ 0 and finite, a finite bias.
    pub fn validate(&self, i: usize) -> Result<(), WorldError> {
        for k in 0..2 {
            let (lo, hi) = (self.min_m[k], self.max_m[k]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(invalid(
                    format!("slip[{i}].max_m[{k}]"),
                    hi,
                    "finite and above min_m",
                ));
            }
        }
        for (name, v) in [
            ("alpha1", self.alpha1),
            ("alpha2", self.alpha2),
            ("alpha3", self.alpha3),
            ("alpha4", self.alpha4),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(format!("slip[{i}].{name}"), v, "finite and >= 0"));
            }
        }
        let b = self.turn_bias_rad_per_s;
        if !(b.is_finite() && b.abs() <= 10.0) {
            return Err(invalid(
                format!("slip[{i}].turn_bias_rad_per_s"),
                b,
                "finite, |bias| <= 10",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::one_robot;
    use crate::{World, WorldPose};

    fn zone(robots: Vec<u32>) -> SlipZone {
        SlipZone {
            min_m: [5.0, -5.0],
            max_m: [50.0, 5.0],
            alpha1: 0.0,
            alpha2: 0.0,
            alpha3: 0.0,
            alpha4: 0.0,
            turn_bias_rad_per_s: 0.1,
            robots,
        }
    }

    /// Inside the zone the odometry reports the bias as a turn; the true path stays straight.
    #[test]
    fn a_slip_zone_biases_the_odometry_not_the_motion() {
        for (robots, slips) in [(vec![], true), (vec![99], false)] {
            let mut cfg = one_robot(WorldPose::new(0.0, 0.0, 0.0));
            cfg.noise = NoiseConfig {
                alpha1: 0.0,
                alpha2: 0.0,
                alpha3: 0.0,
                alpha4: 0.0,
                ..NoiseConfig::default()
            };
            cfg.slip = vec![zone(robots)];
            let id = cfg.robots[0].id;
            let mut world = World::new(cfg, 1).unwrap();
            for k in 0..100 {
                let before = world.poses()[0];
                let out = world.step(&[(1.0, 0.0)]);
                let inside = before.x_m >= 5.0 && slips;
                let want = if inside { 0.1 } else { 0.0 };
                assert_eq!(out[0].sensor.omega_rad_per_s, want, "step {k} (robot {id})");
                assert_eq!(world.poses()[0].y_m, 0.0);
            }
        }
        let mut cfg = one_robot(WorldPose::new(0.0, 0.0, 0.0));
        cfg.slip = vec![SlipZone {
            alpha3: f64::NAN,
            ..zone(vec![])
        }];
        let e = World::new(cfg, 1).unwrap_err().to_string();
        assert!(e.contains("slip[0].alpha3"), "{e}");
    }
}
