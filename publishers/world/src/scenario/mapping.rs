//! Seed 004's mapping in scenarios: `[mapping]` ([`MappingConfig`]) and the flags that change it.
//! `--merge` turns mapping on with exchanges at rendezvous, `--no-merge` turns it on without
//! (each robot knows what it mapped itself: the paper's "integration inactive"); neither flag
//! leaves the scenario's `[mapping]` as it is (off in every built-in scenario, so their runs are
//! unchanged). `--rc-m R` sets R_C whether mapping is on or not. `--steer own-map` (`steer_on`)
//! makes every sector follower steer on its robot's own map instead of the shared field: it
//! reads τ_s from the map's pheromone plane and walls from its occupancy grid, at its estimate
//! in its own frame ([`Scenario::own_map_start`]).

use super::{Overrides, Scenario, ScenarioError};
use pheromone_messages::MAX_PEERS;
use pheromone_roles::follower::{FollowerConfig, StrategyKind};
use pheromone_roles::mapper::{MappingConfig, Pose2, SteerOn, MAP_CHANNELS};

impl Scenario {
    /// `--merge` / `--no-merge` and `--rc-m`.
    pub(super) fn apply_mapping(&mut self, o: &Overrides) -> Result<(), ScenarioError> {
        if let Some(r) = o.rc_m {
            if !(r.is_finite() && r > 0.0) {
                return Err(ScenarioError::Flag {
                    flag: "--rc-m",
                    value: r.to_string(),
                    reason: "must be a finite distance > 0 (m)",
                });
            }
            self.mapping.rc_m = r;
        }
        if let Some(merge) = o.merge {
            self.mapping.enabled = true;
            self.mapping.merge = merge;
        }
        if let Some(steer) = o.steer_on {
            self.mapping.steer_on = steer;
        }
        Ok(())
    }

    /// `[mapping]`, when enabled: its values, and a world small enough for one rendezvous
    /// message per robot.
    pub(super) fn validate_mapping(&self) -> Result<(), ScenarioError> {
        self.validate_steer_on()?;
        if !self.mapping.enabled {
            return Ok(());
        }
        self.mapping.validate().map_err(ScenarioError::Mapping)?;
        let robots = self.world.robots.len();
        if robots > MAX_PEERS + 1 {
            return Err(ScenarioError::Mapping(
                pheromone_roles::mapper::MappingConfigError {
                    key: "enabled",
                    value: robots as f64,
                    expected: "at most MAX_PEERS + 1 = 17 robots in a mapping world",
                },
            ));
        }
        Ok(())
    }

    /// `steer_on = "own-map"`: the robots map (a map to steer on), and every follower is a
    /// sector strategy (the only ones that read a map).
    fn validate_steer_on(&self) -> Result<(), ScenarioError> {
        if self.mapping.steer_on != SteerOn::OwnMap {
            return Ok(());
        }
        let bad = |reason| ScenarioError::Value {
            key: "mapping.steer_on".into(),
            value: SteerOn::OwnMap.name().into(),
            reason,
        };
        if !self.mapping.enabled {
            return Err(bad(
                "needs the robots' local maps: [mapping] enabled = true, or --merge / --no-merge",
            ));
        }
        let sectors = [StrategyKind::Inverse, StrategyKind::Uniform];
        if self
            .robots
            .iter()
            .filter_map(|r| r.follower.as_ref())
            .any(|f| !sectors.contains(&f.strategy) || f.after_loss.is_some())
        {
            return Err(bad(
                "only the sector strategies (inverse, uniform) steer on a map; a follower here has another strategy or after_loss",
            ));
        }
        Ok(())
    }

    /// With own-map steering, robot `id`'s map frame origin (its start pose in the world): its
    /// follower steers on its map there. `None` when it steers on the shared field.
    pub fn own_map_start(&self, id: u32) -> Option<Pose2> {
        if self.mapping().is_none_or(|m| m.steer_on != SteerOn::OwnMap) {
            return None;
        }
        let r = self.world.robots.iter().find(|r| r.id == id)?;
        Some([r.start.x_m, r.start.y_m, r.start.theta_rad])
    }

    /// A sector follower's settings for own-map steering: τ_s from the map's pheromone plane,
    /// walls from its occupancy plane (a sector is blocked above `obstacle_level` of its points
    /// seen occupied, |log-odds| ≥ `known_logodds`).
    pub(super) fn steer_on_own_map(&self, f: &mut FollowerConfig) {
        if self.mapping().is_none_or(|m| m.steer_on != SteerOn::OwnMap) {
            return;
        }
        f.channel = 1;
        debug_assert_eq!(MAP_CHANNELS[1], "pheromone");
        f.sectors.obstacle_channel = Some(0);
        f.sectors.obstacle_logodds = Some(self.mapping.known_logodds);
    }

    /// The mapping settings of a run, if it maps.
    pub fn mapping(&self) -> Option<&MappingConfig> {
        self.mapping.enabled.then_some(&self.mapping)
    }

    /// The field channel robot `id`'s pheromone map follows: its depositor's (channel 0 without
    /// one).
    pub fn mapping_channel(&self, id: u32) -> pheromone_field::ChannelSpec {
        let c = self
            .roles(id)
            .and_then(|r| r.depositor.as_ref())
            .map_or(0, |d| d.channel as usize);
        self.field.channels[c.min(self.field.channels.len() - 1)].clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merge_flags_turn_mapping_on_and_a_bad_radius_is_refused_naming_the_flag() {
        let mut s = Scenario::load("ias-ss").unwrap();
        assert!(s.mapping().is_none(), "mapping is off by default");
        let mut off = s.clone();
        off.apply(&Overrides {
            merge: Some(false),
            rc_m: Some(16.0),
            ..Overrides::default()
        })
        .unwrap();
        let m = off.mapping().expect("--no-merge maps");
        assert!(!m.merge);
        assert_eq!(m.rc_m, 16.0);
        s.apply(&Overrides {
            merge: Some(true),
            ..Overrides::default()
        })
        .unwrap();
        assert!(s.mapping().unwrap().merge);
        for bad in [f64::NAN, 0.0, -3.0, f64::INFINITY] {
            let e = Scenario::load("ias-ss")
                .unwrap()
                .apply(&Overrides {
                    rc_m: Some(bad),
                    ..Overrides::default()
                })
                .unwrap_err()
                .to_string();
            assert!(e.contains("--rc-m") && e.contains(&bad.to_string()), "{e}");
        }
    }

    #[test]
    fn own_map_steering_reads_the_map_planes_and_needs_mapping_on() {
        let steer = |merge| {
            let mut s = Scenario::load("ias-ss").unwrap();
            s.apply(&Overrides {
                merge,
                steer_on: Some(SteerOn::OwnMap),
                ..Overrides::default()
            })
            .map(|_| s)
        };
        let e = steer(None).unwrap_err().to_string();
        assert!(
            e.contains("mapping.steer_on = own-map") && e.contains("--merge"),
            "{e}"
        );
        let s = steer(Some(false)).unwrap();
        let f = s.follower_config(0).unwrap();
        assert_eq!(f.channel, 1, "the map's pheromone plane");
        assert_eq!(f.sectors.obstacle_channel, Some(0), "the occupancy plane");
        assert_eq!(f.sectors.obstacle_logodds, Some(s.mapping.known_logodds));
        let start = s.world.robots[1].start;
        assert_eq!(
            s.own_map_start(1),
            Some([start.x_m, start.y_m, start.theta_rad])
        );
        // Shared steering: the scenario's channels, no map.
        let shared = Scenario::load("ias-ss").unwrap();
        assert_eq!(shared.follower_config(0).unwrap().channel, 0);
        assert_eq!(shared.own_map_start(0), None);
        // In a file: the key, and a bad value named.
        let text = |v: &str| {
            format!(
                "{}\n[mapping]\nenabled = true\nsteer_on = \"{v}\"\n",
                crate::scenario::BUILTIN
                    .iter()
                    .find(|(n, _)| *n == "ias-ss")
                    .unwrap()
                    .1
            )
        };
        let s = Scenario::parse(&text("own-map"), "m.toml").unwrap();
        assert_eq!(s.mapping.steer_on, SteerOn::OwnMap);
        let e = Scenario::parse(&text("theirs"), "m.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("m.toml") && e.contains("theirs"), "{e}");
    }

    #[test]
    fn a_bad_mapping_value_is_refused_naming_the_key_and_value() {
        let text = format!(
            "{}\n[mapping]\nenabled = true\nknown_share = 1.5\n",
            crate::scenario::BUILTIN
                .iter()
                .find(|(n, _)| *n == "ias-ss")
                .unwrap()
                .1
        );
        let e = Scenario::parse(&text, "m.toml").unwrap_err().to_string();
        assert!(
            e.contains("m.toml") && e.contains("mapping.known_share = 1.5"),
            "{e}"
        );
    }
}
