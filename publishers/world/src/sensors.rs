//! What the robots sense: the [`NoiseConfig`] of odometry and observations (the control noise
//! of the velocity motion model, seed 001 Algorithm 1 line 5: σ_v² = α1·v² + α2·ω²,
//! σ_ω² = α3·v² + α4·ω²), the Gaussian draws of the world's seeded RNG, and the noisy
//! range/bearing/signature observations of landmarks within range, field of view and line of
//! sight, nearest first, at most [`MAX_OBSERVATIONS`] (the measurement of seed 001 Algorithm 1
//! line 9).

use rand::Rng;
use rand_distr::StandardNormal;

use super::{wrap_angle, NoiseConfig, World, WorldPose};
use pheromone_messages::{LandmarkObs, MAX_OBSERVATIONS};

impl World {
    pub(super) fn normal(&mut self) -> f64 {
        self.rng.sample::<f64, _>(StandardNormal)
    }

    /// Fills `out` with noisy observations, nearest landmark first; returns how many.
    pub(super) fn observe(
        &mut self,
        pose: WorldPose,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::one_robot;
    use crate::{Landmark, WallConfig};
    use approx::assert_relative_eq;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn observations_within_range_nearest_first() {
        let mut cfg = one_robot(WorldPose::new(0.0, 0.0, FRAC_PI_2));
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
        let mut cfg = one_robot(WorldPose::default());
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
        let mut cfg = one_robot(WorldPose::default());
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

    #[test]
    fn odometry_noise_matches_velocity_model() {
        // σ_v² = α1 v² + α2 ω² (seed 001 Algorithm 1 line 5), checked by sample variance.
        let mut cfg = one_robot(WorldPose::default());
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
            sv += o.v_m_per_s;
            sv2 += o.v_m_per_s * o.v_m_per_s;
            sw += o.omega_rad_per_s;
            sw2 += o.omega_rad_per_s * o.omega_rad_per_s;
        }
        let nf = n as f64;
        let var_v = sv2 / nf - (sv / nf).powi(2);
        let var_w = sw2 / nf - (sw / nf).powi(2);
        assert!((var_v / 0.04 - 1.0).abs() < 0.1, "var_v = {var_v}");
        assert!((var_w / (0.09 * 0.25) - 1.0).abs() < 0.1, "var_w = {var_w}");
        assert!((sv / nf - 1.0).abs() < 0.02);
    }

    #[test]
    fn config_rejects_unknown_fields() {
        use serde::de::value::{Error as DeError, MapDeserializer};
        use serde::Deserialize;
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
}
