//! Seed 004's mapping in scenarios: `[mapping]` ([`MappingConfig`]) and the flags that change it.
//! `--merge` turns mapping on with exchanges at rendezvous, `--no-merge` turns it on without
//! (each robot knows what it mapped itself: the paper's "integration inactive"); neither flag
//! leaves the scenario's `[mapping]` as it is (off in every built-in scenario, so their runs are
//! unchanged). `--rc-m R` sets R_C whether mapping is on or not.

use super::{Overrides, Scenario, ScenarioError};
use crate::mapper::MappingConfig;
use messages::MAX_PEERS;

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
        Ok(())
    }

    /// `[mapping]`, when enabled: its values, and a world small enough for one rendezvous
    /// message per robot.
    pub(super) fn validate_mapping(&self) -> Result<(), ScenarioError> {
        if !self.mapping.enabled {
            return Ok(());
        }
        self.mapping.validate().map_err(ScenarioError::Mapping)?;
        let robots = self.world.robots.len();
        if robots > MAX_PEERS + 1 {
            return Err(ScenarioError::Mapping(crate::mapper::MappingConfigError {
                key: "enabled",
                value: robots as f64,
                expected: "at most MAX_PEERS + 1 = 17 robots in a mapping world",
            }));
        }
        Ok(())
    }

    /// The mapping settings of a run, if it maps.
    pub fn mapping(&self) -> Option<&MappingConfig> {
        self.mapping.enabled.then_some(&self.mapping)
    }

    /// The field channel robot `id`'s pheromone map follows: its depositor's (channel 0 without
    /// one).
    pub fn mapping_channel(&self, id: u32) -> field::ChannelSpec {
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
