//! Seed 004's sensing for mapping (`[mapping]`): a range sensor (rays against the walls, max
//! range R_D, field of view [−90°, 90°], Gaussian range noise) and the rendezvous measurement
//! (the robots within R_C, with a noisy distance, bearing and relative heading). Its draws come
//! from an RNG of their own (seeded from the world's seed), so turning mapping on changes no other
//! draw of the world: the robots move as they do without it.

use std::f64::consts::FRAC_PI_2;

use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::walls::SegmentIndex;
use super::{wrap_angle, World};
use pheromone_messages::{PeerObs, RendezvousMsg, ScanMsg, MAX_PEERS};
use pheromone_roles::mapper::MappingConfig;

/// Mixed into the world's seed for the mapping RNG.
const MAPPING_SEED: u64 = 0x6d61_7070_696e_6721;

/// The range scanner and the rendezvous measurement the world simulates for seed 004 (from a
/// scenario's `[mapping]`, `From<&MappingConfig>`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanSensorConfig {
    /// Rays of one scan, spread evenly over [−90°, 90°].
    pub rays: u32,
    /// R_D: the range sensor's maximum range.
    pub range_max_m: f64,
    /// Standard deviation of the Gaussian range noise.
    pub range_sigma_m: f64,
    /// R_C: robots this close (true distance) measure each other.
    pub rc_m: f64,
    /// Noise of the relative-pose measurement at a rendezvous.
    pub relpose_range_sigma_m: f64,
    pub relpose_bearing_sigma_rad: f64,
    pub relpose_heading_sigma_rad: f64,
}

impl From<&MappingConfig> for ScanSensorConfig {
    fn from(c: &MappingConfig) -> Self {
        Self {
            rays: c.rays,
            range_max_m: c.range_max_m,
            range_sigma_m: c.range_sigma_m,
            rc_m: c.rc_m,
            relpose_range_sigma_m: c.relpose_range_sigma_m,
            relpose_bearing_sigma_rad: c.relpose_bearing_sigma_rad,
            relpose_heading_sigma_rad: c.relpose_heading_sigma_rad,
        }
    }
}

/// The world's mapping sensors.
#[derive(Debug, Clone)]
pub(super) struct MappingSensors {
    config: ScanSensorConfig,
    rng: ChaCha8Rng,
}

impl MappingSensors {
    pub(super) fn new(config: ScanSensorConfig, seed: u64) -> Self {
        Self {
            config,
            rng: ChaCha8Rng::seed_from_u64(seed ^ MAPPING_SEED),
        }
    }

    fn normal(&mut self) -> f64 {
        self.rng.sample::<f64, _>(StandardNormal)
    }
}

impl SegmentIndex {
    /// Distance along the ray from `from` in direction `angle_rad` to the first wall within
    /// `max_m`, if any.
    pub(super) fn raycast(&self, from: [f64; 2], angle_rad: f64, max_m: f64) -> Option<f64> {
        let (s, c) = angle_rad.sin_cos();
        let to = [from[0] + c * max_m, from[1] + s * max_m];
        let lo = [from[0].min(to[0]), from[1].min(to[1])];
        let hi = [from[0].max(to[0]), from[1].max(to[1])];
        let mut best: Option<f64> = None;
        self.any_near(lo, hi, |seg| {
            if let Some(t) = super::walls::segment_intersection(from, to, seg.a_m, seg.b_m) {
                let d = t * max_m;
                if best.is_none_or(|b| d < b) {
                    best = Some(d);
                }
            }
            false
        });
        best
    }
}

impl World {
    /// Turns the mapping sensors on ([`World::mapping_outputs`]).
    pub fn enable_mapping(&mut self, config: impl Into<ScanSensorConfig>, seed: u64) {
        self.mapping = Some(MappingSensors::new(config.into(), seed));
    }

    /// After a [`World::step`]: each robot's range scan and rendezvous measurement, in the order
    /// of `config.robots` (empty when mapping is off). Stamps are left 0.
    pub fn mapping_outputs(&mut self) -> Vec<(ScanMsg, RendezvousMsg)> {
        let Some(mut m) = self.mapping.take() else {
            return Vec::new();
        };
        let c = m.config;
        let n = self.poses.len();
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let p = self.poses[i];
            let id = self.config.robots[i].id;
            let mut scan = ScanMsg {
                step: self.step,
                robot_id: id,
                count: c.rays,
                angle_min_rad: -FRAC_PI_2 as f32,
                angle_step_rad: (std::f64::consts::PI / (c.rays - 1) as f64) as f32,
                range_max_m: c.range_max_m as f32,
                ..ScanMsg::default()
            };
            for k in 0..c.rays as usize {
                let a =
                    p.theta_rad - FRAC_PI_2 + k as f64 * std::f64::consts::PI / (c.rays - 1) as f64;
                let noise = m.normal() * c.range_sigma_m;
                match self.walls.raycast([p.x_m, p.y_m], a, c.range_max_m) {
                    Some(d) => {
                        scan.ranges_m[k] = (d + noise).clamp(0.0, c.range_max_m) as f32;
                        scan.hits |= 1 << k;
                    }
                    None => scan.ranges_m[k] = c.range_max_m as f32,
                }
            }
            let mut rv = RendezvousMsg {
                step: self.step,
                robot_id: id,
                ..RendezvousMsg::default()
            };
            for j in 0..n {
                let q = self.poses[j];
                let d = (q.x_m - p.x_m).hypot(q.y_m - p.y_m);
                if j == i || d > c.rc_m || rv.count as usize >= MAX_PEERS {
                    continue;
                }
                let bearing = (q.y_m - p.y_m).atan2(q.x_m - p.x_m) - p.theta_rad;
                rv.peers[rv.count as usize] = PeerObs {
                    robot_id: self.config.robots[j].id,
                    _pad: 0,
                    range_m: (d + m.normal() * c.relpose_range_sigma_m).max(0.0),
                    bearing_rad: wrap_angle(bearing + m.normal() * c.relpose_bearing_sigma_rad),
                    heading_rad: wrap_angle(
                        q.theta_rad - p.theta_rad + m.normal() * c.relpose_heading_sigma_rad,
                    ),
                };
                rv.count += 1;
            }
            out.push((scan, rv));
        }
        self.mapping = Some(m);
        out
    }

    /// Whether a point lies in a wall or within `margin_m` of one (the true map, for metrics).
    pub fn in_wall(&self, x_m: f64, y_m: f64, margin_m: f64) -> bool {
        let p = [x_m, y_m];
        self.walls.clearance_below(p, margin_m) || super::walls::inside_rect(&self.config.walls, p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::one_robot;
    use crate::{WallConfig, WorldPose};

    fn boxed(sigma_m: f64) -> (World, MappingConfig) {
        let mut cfg = one_robot(WorldPose::new(0.0, 0.0, 0.0));
        cfg.walls = vec![WallConfig::Polyline {
            points_m: vec![[-3.0, -2.0], [3.0, -2.0], [3.0, 2.0], [-3.0, 2.0]],
            closed: true,
        }];
        cfg.robots.push(crate::RobotConfig {
            id: 9,
            start: WorldPose::new(1.0, 1.0, 1.0),
            noise: None,
        });
        let mapping = MappingConfig {
            enabled: true,
            range_max_m: 2.5,
            rays: 5,
            range_sigma_m: sigma_m,
            rc_m: 1.5,
            relpose_range_sigma_m: 0.0,
            relpose_bearing_sigma_rad: 0.0,
            relpose_heading_sigma_rad: 0.0,
            ..MappingConfig::default()
        };
        let mut w = World::new(cfg, 1).unwrap();
        w.enable_mapping(&mapping, 1);
        (w, mapping)
    }

    #[test]
    fn rays_hit_the_walls_at_their_distance_and_miss_beyond_the_range() {
        let (mut w, _) = boxed(0.0);
        w.step(&[]);
        let out = w.mapping_outputs();
        let (scan, _) = &out[0];
        let rays: Vec<_> = scan.rays().collect();
        assert_eq!(rays.len(), 5);
        // −90°: the wall at y = −2; −45°: 2√2 beyond R_D = 2.5; 0°: x = 3 → beyond; +90°: y = 2.
        assert!((rays[0].0 + std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert!(rays[0].2 && (rays[0].1 - 2.0).abs() < 1e-5, "{rays:?}");
        assert!(!rays[1].2 && rays[1].1 == 2.5, "{rays:?}");
        assert!(!rays[2].2 && rays[2].1 == 2.5, "{rays:?}");
        assert!(rays[4].2 && (rays[4].1 - 2.0).abs() < 1e-5, "{rays:?}");
    }

    #[test]
    fn noise_moves_the_ranges_and_the_rendezvous_lists_the_robots_within_rc() {
        let (mut w, _) = boxed(0.05);
        w.step(&[]);
        let out = w.mapping_outputs();
        let r = out[0].0.ranges_m[0];
        assert!(r != 2.0 && (r - 2.0).abs() < 0.3, "{r}");
        // Robot 9 at (1, 1) is √2 < 1.5 from robot 0, at bearing 45°; its heading is 1 rad.
        let peers = out[0].1.peers();
        assert_eq!(peers.len(), 1);
        assert_eq!(peers[0].robot_id, 9);
        assert!((peers[0].range_m - 2f64.sqrt()).abs() < 1e-9);
        assert!((peers[0].bearing_rad - std::f64::consts::FRAC_PI_4).abs() < 1e-9);
        assert!((peers[0].heading_rad - 1.0).abs() < 1e-9);
        assert_eq!(out[1].1.peers()[0].robot_id, w.config().robots[0].id);
    }

    #[test]
    fn mapping_draws_leave_the_worlds_other_draws_alone() {
        let (mut a, _) = boxed(0.05);
        let mut b = a.clone();
        b.mapping = None;
        for _ in 0..20 {
            let (oa, ob) = (a.step(&[(0.3, 0.2)]), b.step(&[(0.3, 0.2)]));
            a.mapping_outputs();
            assert_eq!(oa, ob);
        }
    }
}
