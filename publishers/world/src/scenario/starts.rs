//! `[start_area]`: robots started at random poses in a rectangle, drawn from the scenario's
//! seed (seed 004's Table 9 setup: "robots started at random poses in the top-left 5 × 5 m").
//! The draw replaces every `[[world.robots]]` start: robot i (in file order) gets the i-th pose
//! of a `ChaCha8Rng` seeded by the scenario's seed, x and y uniform in the rectangle, heading
//! uniform in [−π, π). Robot i's pose depends on the seed only, not on how many robots run.
//! It is drawn when the scenario is parsed and again when `--seed` changes the seed, so a run
//! as processes (whose sub-processes re-read the scenario) places the same robots.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{Scenario, ScenarioError};
use crate::WorldPose;

/// Mixed into the seed so the starts' draws differ from every other stream of the run.
const START_SEED: u64 = 0x5354_4152_5441_5245;

/// `[start_area]`: the rectangle the robots start in (m, world frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartArea {
    pub min_x_m: f64,
    pub min_y_m: f64,
    pub max_x_m: f64,
    pub max_y_m: f64,
}

impl StartArea {
    /// Whether (x, y) lies in the rectangle (edges included).
    pub fn contains(&self, x_m: f64, y_m: f64) -> bool {
        (self.min_x_m..=self.max_x_m).contains(&x_m) && (self.min_y_m..=self.max_y_m).contains(&y_m)
    }

    /// The rectangle's corners are finite and min < max on both axes.
    fn validate(&self) -> Result<(), ScenarioError> {
        for (key, v) in [
            ("start_area.min_x_m", self.min_x_m),
            ("start_area.min_y_m", self.min_y_m),
            ("start_area.max_x_m", self.max_x_m),
            ("start_area.max_y_m", self.max_y_m),
        ] {
            if !v.is_finite() {
                return Err(ScenarioError::value(key, v, "must be finite (m)"));
            }
        }
        if self.min_x_m >= self.max_x_m {
            return Err(ScenarioError::value(
                "start_area.max_x_m",
                self.max_x_m,
                "must be greater than start_area.min_x_m",
            ));
        }
        if self.min_y_m >= self.max_y_m {
            return Err(ScenarioError::value(
                "start_area.max_y_m",
                self.max_y_m,
                "must be greater than start_area.min_y_m",
            ));
        }
        Ok(())
    }

    /// `n` poses drawn from `seed`.
    pub fn draw(&self, seed: u64, n: usize) -> Vec<WorldPose> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ START_SEED);
        (0..n)
            .map(|_| {
                let x = rng.random_range(self.min_x_m..self.max_x_m);
                let y = rng.random_range(self.min_y_m..self.max_y_m);
                let theta = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
                WorldPose::new(x, y, theta)
            })
            .collect()
    }
}

impl Scenario {
    /// With a `[start_area]`, every world robot's start drawn from the seed (see the module);
    /// without one, nothing changes. A bad rectangle is an error naming the key and value.
    pub(super) fn place_random_starts(&mut self) -> Result<(), ScenarioError> {
        let Some(area) = self.start_area else {
            return Ok(());
        };
        area.validate()?;
        let poses = area.draw(self.seed, self.world.robots.len());
        for (r, p) in self.world.robots.iter_mut().zip(poses) {
            r.start = p;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Overrides;

    #[test]
    fn the_open_world_starts_every_robot_inside_the_top_left_5_by_5_m_and_the_seed_moves_them() {
        let s = Scenario::load("ias-ss-open").unwrap();
        let area = s.start_area.expect("ias-ss-open has a [start_area]");
        // Inside the world's top-left 5 m × 5 m (y up: x 0–5, y 15–20).
        assert!(area.min_x_m >= 0.0 && area.max_x_m <= 5.0, "{area:?}");
        assert!(area.min_y_m >= 15.0 && area.max_y_m <= 20.0, "{area:?}");
        let starts = |seed: u64, robots: usize| {
            let mut s = Scenario::load("ias-ss-open").unwrap();
            s.apply(&Overrides {
                seed: Some(seed),
                robots: Some(robots),
                ..Overrides::default()
            })
            .unwrap();
            s.world
                .robots
                .iter()
                .map(|r| r.start)
                .collect::<Vec<WorldPose>>()
        };
        let mut all = Vec::new();
        for seed in 1..=10 {
            let p = starts(seed, 5);
            assert_eq!(p.len(), 5);
            for q in &p {
                assert!(area.contains(q.x_m, q.y_m), "seed {seed}: {q:?}");
                assert!((-std::f64::consts::PI..std::f64::consts::PI).contains(&q.theta_rad));
            }
            // Robot i's start does not depend on how many robots run.
            assert_eq!(starts(seed, 3)[..], p[..3]);
            all.push(p);
        }
        assert_ne!(all[0], all[1], "seeds 1 and 2 start the robots elsewhere");
        // Two robots of a run never share a start.
        assert_ne!(all[0][0], all[0][1]);
        // The same seed gives the same starts, and re-reading the applied scenario (what a
        // sub-process does) keeps them.
        assert_eq!(starts(3, 5), all[2]);
        let mut s3 = Scenario::load("ias-ss-open").unwrap();
        s3.apply(&Overrides {
            seed: Some(3),
            robots: Some(5),
            ..Overrides::default()
        })
        .unwrap();
        let again = Scenario::parse(&s3.to_toml().unwrap(), "dump").unwrap();
        assert_eq!(again.world.robots, s3.world.robots);
    }

    #[test]
    fn a_bad_start_area_is_refused_naming_the_key_and_value() {
        let base = crate::scenario::BUILTIN
            .iter()
            .find(|(n, _)| *n == "ias-ss-open")
            .unwrap()
            .1;
        let text = base.replace("max_x_m = 5.0,", "max_x_m = -1.0,");
        assert_ne!(text, base, "the test edits the start area");
        let e = Scenario::parse(&text, "open.toml").unwrap_err().to_string();
        assert!(
            e.contains("open.toml") && e.contains("start_area.max_x_m = -1"),
            "{e}"
        );
    }
}
