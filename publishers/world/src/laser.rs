//! Seed 000's laser range scanner (Table 1, a simulated Hokuyo URG-04LX): 240° scan angle at
//! 1.875° (240°/128, so 129 beams with both edges), 60–4000 mm, Gaussian noise of σ = 25 mm up
//! to 1000 mm and σ = 2.5 % of the range beyond. Beams are cast against the walls
//! ([`SegmentIndex::raycast`]). Its draws come from an RNG of its own (seeded from the world's
//! seed), so turning the laser on changes no other draw of the world.
//!
//! Deviation: Table 1's distance resolution (3.84 mm) is not applied (the readings are not
//! quantized); the noise is.

use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::walls::SegmentIndex;
use super::{World, WorldError, WorldPose};
use pheromone_messages::{LaserMsg, MAX_LASER_BEAMS};

/// Mixed into the world's seed for the laser's RNG.
const LASER_SEED: u64 = 0x6c61_7365_7230_3030;

/// The laser of every robot of the world (`[world.laser]`); defaults are seed 000 Table 1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LaserConfig {
    /// Full scan angle, centred on the heading.
    pub fov_rad: f64,
    /// Beams from −fov/2 to +fov/2, both included (at most [`MAX_LASER_BEAMS`]).
    pub beams: u32,
    /// Nearest reading; a nearer wall reads this.
    pub range_min_m: f64,
    /// Farthest reading; a beam with no wall within it reads this and does not return.
    pub range_max_m: f64,
    /// σ of the range noise up to `near_limit_m`.
    pub near_sigma_m: f64,
    /// Beyond `near_limit_m`, σ = this × the true range.
    pub far_sigma_fraction: f64,
    pub near_limit_m: f64,
    /// A glass (or light-absorbing) stretch [min x, min y, max x, max y] (m): a beam whose
    /// first wall lies inside it does not return (issue 48: a sensor blackout). The robots
    /// still collide with those walls, and a particle filter's map leaves them out
    /// ([`LaserConfig::sees`]).
    pub glass_rect_m: Option<[f64; 4]>,
}

impl Default for LaserConfig {
    fn default() -> Self {
        Self {
            fov_rad: 240f64.to_radians(),
            beams: 129,
            range_min_m: 0.06,
            range_max_m: 4.0,
            near_sigma_m: 0.025,
            far_sigma_fraction: 0.025,
            near_limit_m: 1.0,
            glass_rect_m: None,
        }
    }
}

impl LaserConfig {
    /// Checks every setting; the error names the key (`laser.<key>`) and the value.
    pub fn validate(&self) -> Result<(), WorldError> {
        let bad = |key: &str, value: f64, expected| WorldError::InvalidSetting {
            field: format!("laser.{key}"),
            value,
            expected,
        };
        if !(self.fov_rad.is_finite()
            && self.fov_rad > 0.0
            && self.fov_rad <= std::f64::consts::TAU)
        {
            return Err(bad("fov_rad", self.fov_rad, "in (0, 2π]"));
        }
        if !(2..=MAX_LASER_BEAMS as u32).contains(&self.beams) {
            return Err(bad("beams", f64::from(self.beams), "in [2, 256]"));
        }
        let non_negative = [
            ("range_min_m", self.range_min_m),
            ("near_sigma_m", self.near_sigma_m),
            ("far_sigma_fraction", self.far_sigma_fraction),
            ("near_limit_m", self.near_limit_m),
        ];
        for (key, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(bad(key, value, "finite and >= 0"));
            }
        }
        let max = self.range_max_m;
        if !(max.is_finite() && max > self.range_min_m && max <= 1e3) {
            return Err(bad("range_max_m", max, "finite, > range_min_m and <= 1000"));
        }
        if let Some(g) = self.glass_rect_m {
            if !(g.iter().all(|v| v.is_finite()) && g[0] < g[2] && g[1] < g[3]) {
                return Err(bad(
                    "glass_rect_m",
                    g[2] - g[0],
                    "finite [min x, min y, max x, max y] with min < max",
                ));
            }
        }
        Ok(())
    }

    /// Whether the laser sees a wall at `p` (it is not behind glass).
    pub fn sees(&self, p: [f64; 2]) -> bool {
        self.glass_rect_m
            .is_none_or(|g| !(g[0] <= p[0] && p[0] <= g[2] && g[1] <= p[1] && p[1] <= g[3]))
    }

    /// Angle between neighbouring beams.
    pub fn step_rad(&self) -> f64 {
        self.fov_rad / f64::from(self.beams - 1)
    }

    /// σ of a reading at true range `range_m`.
    pub fn sigma_m(&self, range_m: f64) -> f64 {
        if range_m <= self.near_limit_m {
            self.near_sigma_m
        } else {
            self.far_sigma_fraction * range_m
        }
    }
}

/// The world's laser: its settings and its RNG.
#[derive(Debug, Clone)]
pub(super) struct Laser {
    config: LaserConfig,
    rng: ChaCha8Rng,
}

impl Laser {
    pub(super) fn new(config: LaserConfig, seed: u64) -> Self {
        Self {
            config,
            rng: ChaCha8Rng::seed_from_u64(seed ^ LASER_SEED),
        }
    }

    /// One scan from `pose` (stamps and step left 0). One draw per beam, returned or not.
    fn scan(&mut self, walls: &SegmentIndex, pose: WorldPose, robot_id: u32) -> LaserMsg {
        let c = self.config;
        let angle_min_rad = -0.5 * c.fov_rad;
        let mut msg = LaserMsg {
            robot_id,
            count: c.beams,
            angle_min_rad: angle_min_rad as f32,
            angle_step_rad: c.step_rad() as f32,
            range_min_m: c.range_min_m as f32,
            range_max_m: c.range_max_m as f32,
            ..LaserMsg::default()
        };
        for k in 0..c.beams as usize {
            let a = pose.theta_rad + angle_min_rad + k as f64 * c.step_rad();
            let n = self.rng.sample::<f64, _>(StandardNormal);
            let seen = |d: &f64| c.sees([pose.x_m + d * a.cos(), pose.y_m + d * a.sin()]);
            match walls
                .raycast([pose.x_m, pose.y_m], a, c.range_max_m)
                .filter(seen)
            {
                Some(d) => {
                    let r = (d + c.sigma_m(d) * n).clamp(c.range_min_m, c.range_max_m);
                    msg.ranges_m[k] = r as f32;
                    msg.set_returned(k);
                }
                None => msg.ranges_m[k] = c.range_max_m as f32,
            }
        }
        msg
    }
}

impl World {
    /// After a [`World::step`]: each robot's laser scan, in the order of `config.robots` (empty
    /// when the world has no laser). Stamps are left 0; `step` is the world's step count.
    pub fn laser_outputs(&mut self) -> Vec<LaserMsg> {
        let Some(laser) = self.laser.as_mut() else {
            return Vec::new();
        };
        let mut out = Vec::with_capacity(self.poses.len());
        for (pose, robot) in self.poses.iter().zip(&self.config.robots) {
            let mut m = laser.scan(&self.walls, *pose, robot.id);
            m.step = self.step;
            out.push(m);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::one_robot;
    use crate::{WallConfig, WorldConfig};

    /// A robot in a 6 m × 3 m box ([−1, 5] × [−1, 2]) with the laser `laser`.
    fn boxed(pose: WorldPose, laser: LaserConfig) -> World {
        let mut cfg: WorldConfig = one_robot(pose);
        cfg.walls = vec![WallConfig::Polyline {
            points_m: vec![[-1.0, -1.0], [5.0, -1.0], [5.0, 2.0], [-1.0, 2.0]],
            closed: true,
        }];
        cfg.laser = Some(laser);
        World::new(cfg, 3).unwrap()
    }

    /// Distance from `p` along angle `a` to the box's boundary, by the slab formula.
    fn box_distance(p: [f64; 2], a: f64) -> f64 {
        let (s, c) = a.sin_cos();
        let mut t = f64::INFINITY;
        for (o, d, lo, hi) in [(p[0], c, -1.0, 5.0), (p[1], s, -1.0, 2.0)] {
            if d > 1e-12 {
                t = t.min((hi - o) / d);
            } else if d < -1e-12 {
                t = t.min((lo - o) / d);
            }
        }
        t
    }

    fn noiseless() -> LaserConfig {
        LaserConfig {
            near_sigma_m: 0.0,
            far_sigma_fraction: 0.0,
            range_max_m: 20.0,
            ..LaserConfig::default()
        }
    }

    #[test]
    fn noiseless_ranges_are_the_exact_ray_wall_distances() {
        let pose = WorldPose::new(0.3, 0.4, 0.7);
        let mut w = boxed(pose, noiseless());
        w.step(&[]);
        let scans = w.laser_outputs();
        assert_eq!(scans.len(), 1);
        let m = &scans[0];
        assert_eq!(m.count, 129);
        assert_eq!(m.step, 1);
        assert!((f64::from(m.angle_step_rad) - 1.875f64.to_radians()).abs() < 1e-6);
        for (k, (bearing, range, returned)) in m.beams().enumerate() {
            let a = pose.theta_rad - 120f64.to_radians() + k as f64 * 1.875f64.to_radians();
            assert!((f64::from(bearing) + pose.theta_rad - a).abs() < 1e-5);
            let exact = box_distance([pose.x_m, pose.y_m], a);
            assert!(returned, "beam {k}");
            assert!(
                (f64::from(range) - exact).abs() < 1e-5,
                "beam {k}: {range} vs {exact}"
            );
        }
        // Beyond range_max_m: the beam does not return and reads range_max_m.
        let mut w = boxed(
            pose,
            LaserConfig {
                range_max_m: 1.0,
                ..noiseless()
            },
        );
        w.step(&[]);
        let m = w.laser_outputs()[0];
        for (k, (_, range, returned)) in m.beams().enumerate() {
            let a = pose.theta_rad - 120f64.to_radians() + k as f64 * 1.875f64.to_radians();
            let exact = box_distance([pose.x_m, pose.y_m], a);
            assert_eq!(returned, exact <= 1.0, "beam {k}: {exact}");
            if !returned {
                assert_eq!(range, 1.0);
            }
        }
    }

    /// Sample mean and variance of `errors`, checked against 0 and `var` within 5 standard
    /// errors of each (mean: √(var/n); variance: √(2/(n−1))·var for Gaussian samples).
    fn assert_moments(errors: &[f64], var: f64, what: &str) {
        let n = errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / n;
        let s2 = errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0);
        assert!(mean.abs() < 5.0 * (var / n).sqrt(), "{what}: mean {mean}");
        let se = (2.0 / (n - 1.0)).sqrt() * var;
        assert!(
            (s2 - var).abs() < 5.0 * se,
            "{what}: variance {s2} vs {var}"
        );
    }

    #[test]
    fn noise_has_the_configured_moments_and_is_seeded() {
        // Facing −y from y = −0.4: the beams within ±30° see the wall y = −1 at 0.6–0.7 m
        // (σ = 25 mm); facing +x from x = 1.0, those within ±15° see x = 5 at 4.0–4.15 m, which
        // a 6 m range keeps unclamped (σ = 2.5 % of the range).
        let laser = LaserConfig {
            range_max_m: 6.0,
            ..LaserConfig::default()
        };
        let cases: [(WorldPose, f64); 2] = [
            (
                WorldPose::new(0.3, -0.4, -std::f64::consts::FRAC_PI_2),
                30.0,
            ),
            (WorldPose::new(1.0, 0.5, 0.0), 15.0f64),
        ];
        for (pose, half_deg) in cases {
            let mut w = boxed(pose, laser);
            let mut normalized = Vec::new();
            for _ in 0..200 {
                w.step(&[]);
                let m = w.laser_outputs()[0];
                for (bearing, range, _) in m.beams() {
                    let b = f64::from(bearing);
                    if b.abs() > half_deg.to_radians() {
                        continue;
                    }
                    let a = pose.theta_rad + b;
                    let exact = box_distance([pose.x_m, pose.y_m], a);
                    normalized.push((f64::from(range) - exact) / laser.sigma_m(exact));
                }
            }
            assert!(normalized.len() > 2000, "{}", normalized.len());
            // f32 readings add at most ~1e-6 relative error: negligible against σ.
            assert_moments(&normalized, 1.0, &format!("{pose:?}"));
        }
        // The same seed gives the same scans; another seed other ones.
        let run = |seed| {
            let mut cfg = one_robot(WorldPose::new(0.0, 0.0, 0.0));
            cfg.walls = vec![WallConfig::Polyline {
                points_m: vec![[-1.0, -1.0], [5.0, -1.0], [5.0, 2.0], [-1.0, 2.0]],
                closed: true,
            }];
            cfg.laser = Some(LaserConfig::default());
            let mut w = World::new(cfg, seed).unwrap();
            w.step(&[]);
            w.laser_outputs()[0]
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
    }

    #[test]
    fn laser_draws_leave_the_worlds_other_draws_alone() {
        let mut cfg = one_robot(WorldPose::new(0.0, 0.0, 0.0));
        cfg.noise.alpha1 = 0.1;
        let mut b = World::new(cfg.clone(), 9).unwrap();
        cfg.laser = Some(LaserConfig::default());
        let mut a = World::new(cfg, 9).unwrap();
        for _ in 0..20 {
            let (oa, ob) = (a.step(&[(0.3, 0.2)]), b.step(&[(0.3, 0.2)]));
            assert_eq!(a.laser_outputs().len(), 1);
            assert!(b.laser_outputs().is_empty());
            assert_eq!(oa, ob);
        }
    }

    #[test]
    fn bad_settings_are_refused_naming_the_key() {
        let bad = [
            LaserConfig {
                fov_rad: f64::NAN,
                ..LaserConfig::default()
            },
            LaserConfig {
                beams: 1,
                ..LaserConfig::default()
            },
            LaserConfig {
                beams: 257,
                ..LaserConfig::default()
            },
            LaserConfig {
                range_max_m: 0.01,
                ..LaserConfig::default()
            },
            LaserConfig {
                near_sigma_m: -1.0,
                ..LaserConfig::default()
            },
        ];
        for (c, key) in bad.iter().zip([
            "laser.fov_rad",
            "laser.beams",
            "laser.beams",
            "laser.range_max_m",
            "laser.near_sigma_m",
        ]) {
            let mut cfg = one_robot(WorldPose::default());
            cfg.laser = Some(*c);
            let e = World::new(cfg, 0).unwrap_err().to_string();
            assert!(e.contains(key), "{e}");
        }
    }
}
