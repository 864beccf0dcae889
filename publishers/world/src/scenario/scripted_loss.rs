//! `[scripted_loss]` and `pheromone sim --scripted-loss` (issue 48): a scenario whose leader
//! loses itself by its own filter (seed 000's particle filter in a featureless hall on a
//! slipping floor) can keep the old scripted loss as an explicit option. With the flag, the
//! named robot's localizer runs `filter` with the loss script `loss`, and the world's slip
//! zones are cleared (the script's heading drift stands in for them); without it the table is
//! not used.

use serde::{Deserialize, Serialize};

use super::{Scenario, ScenarioError};
use pheromone_roles::localizer::{FilterKind, LossConfig};

/// The scripted loss a scenario offers (`[scripted_loss]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptedLoss {
    /// The robot that gets lost.
    pub robot: u32,
    /// Its filter under the script (the loss script is EKF-only).
    #[serde(default)]
    pub filter: FilterKind,
    /// `localizer.loss` under the script.
    pub loss: LossConfig,
}

impl Scenario {
    /// `--scripted-loss`: applies `[scripted_loss]`; a scenario without one is refused,
    /// naming the flag.
    pub(super) fn apply_scripted_loss(&mut self) -> Result<(), ScenarioError> {
        let Some(s) = self.scripted_loss else {
            return Err(ScenarioError::Flag {
                flag: "--scripted-loss",
                value: self.name.clone(),
                reason: "the scenario has no [scripted_loss] table",
            });
        };
        let Some(r) = self.robots.iter_mut().find(|r| r.id == s.robot) else {
            return Err(ScenarioError::Value {
                key: "scripted_loss.robot".into(),
                value: s.robot.to_string(),
                reason: "no [[robot]] has this id",
            });
        };
        r.filter = s.filter;
        r.localizer.loss = s.loss;
        self.world.slip.clear();
        Ok(())
    }

    /// Whether any localizer runs a loss script (`metrics.json`'s `scripted_loss`).
    pub fn has_scripted_loss(&self) -> bool {
        self.robots
            .iter()
            .any(|r| r.localizer.loss.after_s.is_some())
    }
}
