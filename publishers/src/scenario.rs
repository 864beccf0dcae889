//! Scenarios: one TOML file describes the field, the world, each robot's roles and scripted
//! deposits. Every process of a run reads the same scenario and takes its own part. Built-in
//! scenarios are embedded in the binary and shipped under `examples/scenarios/`.

use std::path::Path;

use field::{DepositMsg, FieldConfig, KernelKind};
use serde::{Deserialize, Serialize};

use crate::depositor::DepositorConfig;
use crate::follower::FollowerConfig;
use crate::localizer::EkfConfig;
use crate::world::WorldConfig;

/// Built-in scenarios: (name, TOML text).
pub const BUILTIN: &[(&str, &str)] =
    &[("trail", include_str!("../../examples/scenarios/trail.toml"))];

/// Why a scenario could not be loaded. Names the file (or built-in) and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("{origin}: cannot read: {detail}")]
    Read { origin: String, detail: String },
    #[error("{origin}: {detail}")]
    Parse { origin: String, detail: String },
    #[error("{origin}: {detail}")]
    Invalid { origin: String, detail: String },
    #[error("unknown scenario '{0}': not a file, and not a built-in ({builtins})", builtins = builtin_names())]
    Unknown(String),
}

fn builtin_names() -> String {
    BUILTIN
        .iter()
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

/// A whole run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    #[serde(default)]
    pub seed: u64,
    /// Simulated time the run lasts (s).
    pub duration_s: f64,
    #[serde(default)]
    pub field: FieldConfig,
    #[serde(default)]
    pub world: WorldConfig,
    /// The roles of each robot (`[[robot]]`).
    #[serde(default, rename = "robot")]
    pub robots: Vec<RobotRoles>,
    /// Scripted deposits (`[[deposit]]`).
    #[serde(default, rename = "deposit")]
    pub deposits: Vec<ScriptedDeposit>,
}

/// What runs for one robot: a localizer always, a depositor and a follower if configured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotRoles {
    pub id: u32,
    #[serde(default)]
    pub localizer: EkfConfig,
    /// Standard deviation of the localizer's initial position estimate (m).
    #[serde(default = "default_initial_sigma_m")]
    pub initial_sigma_m: f64,
    #[serde(default)]
    pub depositor: Option<DepositorConfig>,
    #[serde(default)]
    pub follower: Option<FollowerConfig>,
}

fn default_initial_sigma_m() -> f64 {
    0.05
}

/// A deposit made by the world at time `t_s`; with `to_x_m`/`to_y_m`/`spacing_m` it is a line of
/// deposits every `spacing_m` from (x, y) to (to_x, to_y).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptedDeposit {
    #[serde(default)]
    pub t_s: f64,
    #[serde(default = "default_kernel")]
    pub kernel: String,
    #[serde(default)]
    pub channel: u32,
    pub x_m: f32,
    pub y_m: f32,
    #[serde(default)]
    pub to_x_m: Option<f32>,
    #[serde(default)]
    pub to_y_m: Option<f32>,
    #[serde(default)]
    pub spacing_m: Option<f32>,
    pub amount: f32,
    #[serde(default = "default_cov")]
    pub cov: [f32; 3],
    #[serde(default = "default_range_m")]
    pub range_m: f32,
    #[serde(default = "default_gamma_max")]
    pub gamma_max: f32,
    #[serde(default = "default_sigma_m")]
    pub sigma_m: f32,
    #[serde(default)]
    pub plateau_m: f32,
    #[serde(default)]
    pub slope_m: f32,
}

fn default_kernel() -> String {
    "ellipse".into()
}
fn default_cov() -> [f32; 3] {
    [0.01, 0.0, 0.01]
}
fn default_range_m() -> f32 {
    1.0
}
fn default_gamma_max() -> f32 {
    100.0
}
fn default_sigma_m() -> f32 {
    0.1
}

impl ScriptedDeposit {
    /// The deposit messages this entry stands for.
    pub fn messages(&self) -> Result<Vec<DepositMsg>, String> {
        let kernel: KernelKind = self.kernel.parse()?;
        let one = |x_m: f32, y_m: f32| DepositMsg {
            channel: self.channel,
            kernel: kernel as u32,
            x_m,
            y_m,
            amount: self.amount,
            cov_xx: self.cov[0],
            cov_xy: self.cov[1],
            cov_yy: self.cov[2],
            range_m: self.range_m,
            gamma_max: self.gamma_max,
            sigma_m: self.sigma_m,
            plateau_m: self.plateau_m,
            slope_m: self.slope_m,
            ..Default::default()
        };
        match (self.to_x_m, self.to_y_m, self.spacing_m) {
            (None, None, None) => Ok(vec![one(self.x_m, self.y_m)]),
            (Some(tx), Some(ty), Some(sp)) => {
                if !(sp.is_finite() && sp > 0.0) {
                    return Err(format!("spacing_m = {sp}: must be > 0"));
                }
                let len = ((tx - self.x_m).powi(2) + (ty - self.y_m).powi(2)).sqrt();
                let n = (len / sp).floor() as usize;
                if n > 1_000_000 {
                    return Err(format!(
                        "a line of {n} deposits is too long (spacing_m = {sp})"
                    ));
                }
                Ok((0..=n)
                    .map(|i| {
                        let f = if len > 0.0 { i as f32 * sp / len } else { 0.0 };
                        one(
                            self.x_m + f * (tx - self.x_m),
                            self.y_m + f * (ty - self.y_m),
                        )
                    })
                    .collect())
            }
            _ => Err("a line needs all of to_x_m, to_y_m and spacing_m".into()),
        }
    }
}

impl Scenario {
    /// Loads a built-in scenario by name, or a TOML file by path.
    pub fn load(name_or_path: &str) -> Result<Self, ScenarioError> {
        let path = Path::new(name_or_path);
        if path.is_file() {
            let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Read {
                origin: path.display().to_string(),
                detail: e.to_string(),
            })?;
            return Self::parse(&text, &path.display().to_string());
        }
        match BUILTIN.iter().find(|(n, _)| *n == name_or_path) {
            Some((n, text)) => Self::parse(text, &format!("built-in scenario '{n}'")),
            None => Err(ScenarioError::Unknown(name_or_path.to_string())),
        }
    }

    /// Parses and validates; `origin` names the source in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ScenarioError> {
        let s: Scenario = toml::from_str(text).map_err(|e| ScenarioError::Parse {
            origin: origin.to_string(),
            detail: e.to_string(),
        })?;
        s.validate().map_err(|detail| ScenarioError::Invalid {
            origin: origin.to_string(),
            detail,
        })?;
        Ok(s)
    }

    /// Cross-checks the parts: sizes, the field clock against the world step, robot ids.
    pub fn validate(&self) -> Result<(), String> {
        self.field.validate().map_err(|e| format!("field: {e}"))?;
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            return Err(format!("duration_s = {}: must be > 0", self.duration_s));
        }
        let field_dt = 1.0 / self.field.tick_hz as f64;
        if (field_dt - self.world.dt_secs).abs() > 1e-6 * self.world.dt_secs.max(1e-9) + 1e-9 {
            return Err(format!(
                "field.tick_hz = {} gives dt = {field_dt} s but world.dt_secs = {}: in lockstep the field ticks once per world step",
                self.field.tick_hz, self.world.dt_secs
            ));
        }
        for r in &self.robots {
            if !self.world.robots.iter().any(|w| w.id == r.id) {
                return Err(format!(
                    "robot id = {}: no [[world.robots]] entry with that id",
                    r.id
                ));
            }
            if let Some(d) = &r.depositor {
                d.validate()
                    .map_err(|e| format!("robot {} depositor: {e}", r.id))?;
            }
            if let Some(f) = &r.follower {
                f.validate()
                    .map_err(|e| format!("robot {} follower: {e}", r.id))?;
            }
        }
        for (i, d) in self.deposits.iter().enumerate() {
            d.messages()
                .map_err(|e| format!("deposit {}: {e}", i + 1))?;
        }
        crate::world::World::new(self.world.clone(), self.seed).map_err(|e| e.to_string())?;
        Ok(())
    }

    /// Number of world steps the run lasts.
    pub fn steps(&self) -> u64 {
        (self.duration_s / self.world.dt_secs).round() as u64
    }

    pub fn roles(&self, robot_id: u32) -> Option<&RobotRoles> {
        self.robots.iter().find(|r| r.id == robot_id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_scenario_loads() {
        for (name, _) in BUILTIN {
            let s = Scenario::load(name).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(&s.name, name);
        }
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused_with_the_origin() {
        let e = Scenario::parse("name = 'x'\nduration_s = 1\nspeed = 3\n", "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.toml") && e.contains("speed"), "{e}");
        let e = Scenario::parse("name = 'x'\nduration_s = -1\n", "y.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("y.toml") && e.contains("duration_s = -1"), "{e}");
        let e = Scenario::load("no-such-scenario").unwrap_err().to_string();
        assert!(e.contains("no-such-scenario") && e.contains("trail"), "{e}");
    }

    #[test]
    fn a_line_deposit_expands_every_spacing() {
        let s = Scenario::load("trail").unwrap();
        let msgs = s.deposits[0].messages().unwrap();
        assert_eq!(msgs.len(), 106);
        assert!((msgs[105].x_m - 11.0).abs() < 1e-3);
    }
}
