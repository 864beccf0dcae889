//! "Leader lost" (seed 000 Sec. 5, location L12 and Fig. 24): a follower whose trail falls below
//! its rejection threshold does not stop; it leaves the trail and explores on its own with one
//! of seed 004's sector strategies (`inverse` or `uniform`), the way the paper's Turtlebot gives
//! the lost leader's trail up and goes to B instead of A.
//!
//! [`ExploreAfterLoss`] wraps the follower's own strategy (normally `gradient`): while that one
//! follows, it decides; on the first step it reports `TrailAbandoned`, the explorer takes over
//! for good (until `reset`) and every decision is reported as `LeaderLost`.

use pheromone_field::{FrameView, SamplePose};
use serde::{Deserialize, Serialize};

use super::{invalid, Decision, FollowerConfigError, FollowerStrategy, StrategyKind};
use pheromone_messages::FollowerState;

/// `[robot.follower.after_loss]`: what a follower does once it has given a trail up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AfterLossConfig {
    /// `inverse` (IAS-SS: away from pheromone, so away from the trail it gave up) or `uniform`,
    /// with the follower's `sectors` settings.
    pub strategy: StrategyKind,
    /// Channel the explorer reads; the follower's own `channel` when unset.
    #[serde(default)]
    pub channel: Option<u32>,
}

impl AfterLossConfig {
    pub fn validate(&self) -> Result<(), FollowerConfigError> {
        match self.strategy {
            StrategyKind::Inverse | StrategyKind::Uniform => Ok(()),
            other => Err(invalid(
                "after_loss.strategy",
                other,
                "must be inverse or uniform (an exploring strategy of seed 004)",
            )),
        }
    }
}

/// A follower's strategy with the switch to exploring after "leader lost".
pub struct ExploreAfterLoss {
    primary: Box<dyn FollowerStrategy>,
    explorer: Box<dyn FollowerStrategy>,
    lost: bool,
}

impl ExploreAfterLoss {
    pub fn new(primary: Box<dyn FollowerStrategy>, explorer: Box<dyn FollowerStrategy>) -> Self {
        Self {
            primary,
            explorer,
            lost: false,
        }
    }

    /// Whether the follower has given its trail up and explores.
    pub fn is_exploring(&self) -> bool {
        self.lost
    }
}

impl FollowerStrategy for ExploreAfterLoss {
    fn name(&self) -> &'static str {
        self.primary.name()
    }

    fn channel(&self) -> usize {
        self.primary.channel()
    }

    fn decide(&mut self, frame: &FrameView<'_>, pose: SamplePose, dt_s: f64) -> Decision {
        if !self.lost {
            let d = self.primary.decide(frame, pose, dt_s);
            if d.state != FollowerState::TrailAbandoned {
                return d;
            }
            self.lost = true;
        }
        if self.explorer.channel() >= frame.channels {
            // A frame without the explorer's channel (the scenario checks this up front).
            return Decision::stop(FollowerState::LeaderLost, 0.0);
        }
        Decision {
            state: FollowerState::LeaderLost,
            ..self.explorer.decide(frame, pose, dt_s)
        }
    }

    fn reset(&mut self) {
        self.primary.reset();
        self.explorer.reset();
        self.lost = false;
    }
}

#[cfg(test)]
mod tests {
    use pheromone_field::{FrameView, GridGeometry};

    use super::*;
    use crate::follower::{FollowerConfig, GradientConfig};

    #[test]
    fn a_follower_that_gives_its_trail_up_explores_instead_of_stopping() {
        let cfg = FollowerConfig {
            gradient: GradientConfig {
                abandon_below: 5.0,
                ..GradientConfig::default()
            },
            after_loss: Some(AfterLossConfig {
                strategy: StrategyKind::Inverse,
                channel: None,
            }),
            ..FollowerConfig::default()
        };
        let mut s = cfg.build().unwrap();
        assert_eq!((s.name(), s.channel()), ("gradient", 0));
        let g = GridGeometry::new(40, 40, 0.1).unwrap();
        let pose = SamplePose::new(2.0, 2.0, 0.0);
        let at = |s: &mut Box<dyn FollowerStrategy>, level: f32| {
            let cells = vec![level; g.cells()];
            s.decide(&FrameView::new(g, 1, &cells), pose, 0.1)
        };
        assert_eq!(at(&mut s, 1.0).state, FollowerState::Exploring);
        assert_eq!(at(&mut s, 20.0).state, FollowerState::Following);
        // The trail fades below 5: the gradient strategy alone would stop (v = 0); here the
        // sector strategy drives on at its speed, and it stays so when the trail comes back.
        for level in [2.0, 0.0, 20.0] {
            let d = at(&mut s, level);
            assert_eq!(d.state, FollowerState::LeaderLost, "level {level}");
            assert_eq!(d.v_m_per_s, cfg.sectors.v_m_per_s);
        }
        s.reset();
        assert_eq!(at(&mut s, 20.0).state, FollowerState::Following);
    }

    #[test]
    fn only_an_exploring_strategy_can_take_over() {
        for (k, ok) in [
            (StrategyKind::Inverse, true),
            (StrategyKind::Uniform, true),
            (StrategyKind::Gradient, false),
            (StrategyKind::Route, false),
        ] {
            let cfg = FollowerConfig {
                after_loss: Some(AfterLossConfig {
                    strategy: k,
                    channel: Some(1),
                }),
                ..FollowerConfig::default()
            };
            match cfg.build() {
                Ok(_) => assert!(ok, "{k} accepted"),
                Err(e) => {
                    assert!(!ok, "{k}: {e}");
                    assert_eq!(e.name, "after_loss.strategy");
                    assert!(e.to_string().contains(k.name()), "{e}");
                }
            }
        }
    }
}
