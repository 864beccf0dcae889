//! `pheromone sim --trials T` (seed 004's comparison): a scenario run `T` times with each of two
//! follower strategies on the same seeds, each run's `exploration.mean` kept, and Welch's t
//! between the two ([`Trials`], written as `trials.json`).

use pheromone_roles::follower::StrategyKind;
use pheromone_world::scenario::{Overrides, Scenario, ScenarioError};
use serde::Serialize;

use crate::metrics::{mean_sd, scenario_metrics, welch_t};
use crate::recording::Recording;

/// `--trials`: the exploration of each strategy over the same seeds, and Welch's t between them
/// (`trials.json`).
#[derive(Debug, Serialize)]
pub struct Trials {
    pub scenario: String,
    pub trials: usize,
    /// The first and last seed.
    pub seeds: [u64; 2],
    pub robots: usize,
    pub sim_time_s: f64,
    /// Ours first, then the other strategy.
    pub exploration: [StrategyTrials; 2],
    pub welch_t: f64,
    pub welch_df: f64,
}

/// One strategy's `exploration.mean` over the trials.
#[derive(Debug, Serialize)]
pub struct StrategyTrials {
    pub strategy: &'static str,
    pub mean: f64,
    pub sd: f64,
    pub per_trial: Vec<f64>,
}

/// Why the trials stopped: a run failed (or was stopped: the caller's error), or a seed's
/// scenario was refused.
#[derive(Debug, thiserror::Error)]
pub enum TrialsError<E> {
    #[error("{0}")]
    Run(E),
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
}

/// The strategy compared with `ours`: uniform, or inverse when ours is uniform.
pub fn other_strategy(ours: StrategyKind) -> StrategyKind {
    match ours {
        StrategyKind::Uniform => StrategyKind::Inverse,
        _ => StrategyKind::Uniform,
    }
}

/// Runs `scenario` (which has an exploration metric) `trials` times with `ours` and with
/// [`other_strategy`], seeds `scenario.seed ..`, each run by `run` (a single process or
/// processes: the caller's mode; its error ends the trials); `done` after each run.
pub fn run_trials<E>(
    scenario: &Scenario,
    trials: u32,
    ours: StrategyKind,
    mut run: impl FnMut(&Scenario) -> Result<Recording, E>,
    mut done: impl FnMut(),
) -> Result<Trials, TrialsError<E>> {
    let mut results = [(ours, Vec::new()), (other_strategy(ours), Vec::new())];
    for (kind, values) in &mut results {
        for t in 0..trials {
            let mut s = scenario.clone();
            s.apply(&Overrides {
                seed: Some(scenario.seed + t as u64),
                strategy: Some(*kind),
                ..Overrides::default()
            })?;
            let rec = run(&s).map_err(TrialsError::Run)?;
            let m = scenario_metrics(&s, &rec);
            values.push(m.exploration.map_or(f64::NAN, |e| e.mean));
            done();
        }
    }
    Ok(Trials::of(scenario, &results))
}

impl Trials {
    /// The trials' statistics from each strategy's values (ours first).
    pub fn of(scenario: &Scenario, results: &[(StrategyKind, Vec<f64>); 2]) -> Self {
        let stats = |(kind, values): &(StrategyKind, Vec<f64>)| {
            let (mean, sd) = mean_sd(values);
            StrategyTrials {
                strategy: kind.name(),
                mean,
                sd,
                per_trial: values.clone(),
            }
        };
        let exploration = [stats(&results[0]), stats(&results[1])];
        let n = results[0].1.len();
        let (x, y) = (&exploration[0], &exploration[1]);
        let (welch_t, welch_df) = welch_t(x.mean, x.sd, y.mean, y.sd, n as f64);
        Self {
            scenario: scenario.name.clone(),
            trials: n,
            seeds: [scenario.seed, scenario.seed + n as u64 - 1],
            robots: scenario.world.robots.len(),
            sim_time_s: scenario.duration_s,
            exploration,
            welch_t,
            welch_df,
        }
    }

    /// The line `pheromone sim --trials` writes on stderr.
    pub fn summary_line(&self) -> String {
        let (x, y) = (&self.exploration[0], &self.exploration[1]);
        format!(
            "{} trials of '{}' with {} robot(s), {:.0} s each: exploration {} {:.3} ± {:.3}, {} {:.3} ± {:.3}; Welch t = {:.2} (df {:.1})",
            self.trials,
            self.scenario,
            self.robots,
            self.sim_time_s,
            x.strategy,
            x.mean,
            x.sd,
            y.strategy,
            y.mean,
            y.sd,
            self.welch_t,
            self.welch_df,
        )
    }
}
