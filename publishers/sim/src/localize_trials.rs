//! `pheromone sim <regions scenario> --trials T` (seed 001, issue 49): each run of a node-graph
//! scenario (robot counts × strategies) on seeds S … S + T − 1, once with `--localize constant`
//! and once with `--localize rho`, paired by seed. Per seed: the time to the goal, the mean
//! capture time and whether the captures (region, robot, time) differ; over the seeds: mean ±
//! sd of each weight and the paired t of rho − constant ([`LocalizeTrials`], written into the
//! run's `metrics.json`).

use pheromone_graph::agent::GraphStrategy;
use pheromone_graph::localize::DepositWeight;
use pheromone_graph::run::RunReport;
use serde::Serialize;

use crate::sweep_stats::{paired, MeanSd, TTest};

/// `--trials` on a node-graph scenario: every (robots, strategy) with both deposit weights.
#[derive(Debug, Clone, Serialize)]
pub struct LocalizeTrials {
    pub scenario: String,
    pub trials: usize,
    /// The first and last seed.
    pub seeds: [u64; 2],
    pub points: Vec<PairedPoint>,
}

/// One robot count and strategy over the seeds.
#[derive(Debug, Clone, Serialize)]
pub struct PairedPoint {
    pub robots: usize,
    pub strategy: GraphStrategy,
    pub per_seed: Vec<SeedPair>,
    /// Seeds whose captures (region, robot, time) differ between the two weights.
    pub captures_differ: usize,
    /// Time to the goal (runs that reached it).
    pub finish_s: PairedStat,
    /// Mean time of a run's captures.
    pub mean_capture_s: PairedStat,
}

/// One figure of both weights over the seeds where both have it.
#[derive(Debug, Clone, Serialize)]
pub struct PairedStat {
    /// Seeds where both runs have the figure.
    pub pairs: usize,
    pub constant: Option<MeanSd>,
    pub rho: Option<MeanSd>,
    /// Mean of rho − constant.
    pub mean_difference: Option<f64>,
    /// Paired t of rho − constant (df = pairs − 1); `None` when every difference is the same
    /// (no difference at all, most often) or with fewer than two pairs.
    pub paired_t: Option<TTest>,
}

/// One seed: the run with each weight.
#[derive(Debug, Clone, Serialize)]
pub struct SeedPair {
    pub seed: u64,
    pub constant: Outcome,
    pub rho: Outcome,
    pub captures_differ: bool,
}

/// What one run did, in short.
#[derive(Debug, Clone, Serialize)]
pub struct Outcome {
    pub finish_s: Option<f32>,
    pub mean_capture_s: Option<f64>,
    pub conflicts: u32,
    /// `region:R<robot>@<time>` in time order.
    pub captures: Vec<String>,
    /// The smallest ρ_t of a link deposit (1 when every deposit was made well localized).
    pub rho_min: Option<f64>,
}

impl Outcome {
    pub fn of(r: &RunReport) -> Self {
        let n = r.captures.len();
        let mean_capture_s = (n > 0).then(|| {
            r.captures
                .iter()
                .map(|c| f64::from(c.captured_s))
                .sum::<f64>()
                / n as f64
        });
        Self {
            finish_s: r.finish_s,
            mean_capture_s,
            conflicts: r.conflicts,
            captures: r
                .captures
                .iter()
                .map(|c| format!("{}:R{}@{:.2}", c.region, c.robot, c.captured_s))
                .collect(),
            rho_min: r
                .localization
                .as_ref()
                .filter(|l| l.all.deposits > 0)
                .map(|l| l.all.rho_min),
        }
    }
}

impl PairedStat {
    fn of(pairs: &[(Option<f64>, Option<f64>)]) -> Self {
        let (c, r): (Vec<f64>, Vec<f64>) =
            pairs.iter().filter_map(|&(c, r)| Some((c?, r?))).unzip();
        let d: Vec<f64> = r.iter().zip(&c).map(|(r, c)| r - c).collect();
        Self {
            pairs: c.len(),
            constant: MeanSd::of(&c),
            rho: MeanSd::of(&r),
            mean_difference: MeanSd::of(&d).map(|m| m.mean),
            paired_t: paired(&r, &c),
        }
    }

    fn line(&self, what: &str) -> String {
        let ms = |m: Option<MeanSd>| {
            m.map_or("—".into(), |m| format!("{:.2} ± {:.2} s", m.mean, m.sd))
        };
        let t = match (self.paired_t, self.mean_difference) {
            (Some(t), _) => format!("paired t = {:.2} (df {:.0})", t.t, t.df),
            (None, Some(0.0)) => "no difference on any seed".into(),
            _ => "paired t undefined".into(),
        };
        format!(
            "  {what}: constant {}, rho {}; rho − constant {} over {} seed(s), {t}",
            ms(self.constant),
            ms(self.rho),
            self.mean_difference
                .map_or("—".into(), |d| format!("{d:+.2} s")),
            self.pairs
        )
    }
}

impl PairedPoint {
    fn of(robots: usize, strategy: GraphStrategy, per_seed: Vec<SeedPair>) -> Self {
        let finish: Vec<_> = per_seed
            .iter()
            .map(|p| {
                (
                    p.constant.finish_s.map(f64::from),
                    p.rho.finish_s.map(f64::from),
                )
            })
            .collect();
        let capture: Vec<_> = per_seed
            .iter()
            .map(|p| (p.constant.mean_capture_s, p.rho.mean_capture_s))
            .collect();
        Self {
            robots,
            strategy,
            captures_differ: per_seed.iter().filter(|p| p.captures_differ).count(),
            finish_s: PairedStat::of(&finish),
            mean_capture_s: PairedStat::of(&capture),
            per_seed,
        }
    }
}

/// Runs every `(robots, strategy)` of `points` on `trials` seeds from `first_seed`, each with
/// both deposit weights (constant first), by `run` (one process or processes: the caller's
/// mode; its error ends the trials); `done` gets each run's report.
pub fn run_localize_trials<E>(
    scenario: &str,
    points: &[(usize, GraphStrategy)],
    first_seed: u64,
    trials: u32,
    mut run: impl FnMut(usize, GraphStrategy, u64, DepositWeight) -> Result<RunReport, E>,
    mut done: impl FnMut(&RunReport),
) -> Result<LocalizeTrials, E> {
    let mut out = Vec::with_capacity(points.len());
    for &(robots, strategy) in points {
        let mut per_seed = Vec::with_capacity(trials as usize);
        for seed in (0..u64::from(trials)).map(|t| first_seed + t) {
            let c = run(robots, strategy, seed, DepositWeight::Constant)?;
            done(&c);
            let r = run(robots, strategy, seed, DepositWeight::Rho)?;
            done(&r);
            let (constant, rho) = (Outcome::of(&c), Outcome::of(&r));
            per_seed.push(SeedPair {
                seed,
                captures_differ: constant.captures != rho.captures,
                constant,
                rho,
            });
        }
        out.push(PairedPoint::of(robots, strategy, per_seed));
    }
    Ok(LocalizeTrials {
        scenario: scenario.to_string(),
        trials: trials as usize,
        seeds: [first_seed, first_seed + u64::from(trials).saturating_sub(1)],
        points: out,
    })
}

impl LocalizeTrials {
    /// The trials as text: per seed, then the statistics of each point.
    pub fn text(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let f = |v: Option<f32>| v.map_or("not reached".into(), |v| format!("{v:.2}"));
        let g = |v: Option<f64>| v.map_or("—".into(), |v| format!("{v:.2}"));
        for p in &self.points {
            let _ = writeln!(
                s,
                "{}: {} robot(s), {}, seeds {}–{}: --localize constant against rho",
                self.scenario,
                p.robots,
                p.strategy.name(),
                self.seeds[0],
                self.seeds[1]
            );
            let _ = writeln!(
                s,
                "  seed  finish s (constant / rho)  mean capture s (constant / rho)  ρ_t min  captures"
            );
            for q in &p.per_seed {
                let _ = writeln!(
                    s,
                    "  {:>4}  {:>10} / {:<12}  {:>8} / {:<8}  {:>7}  {}",
                    q.seed,
                    f(q.constant.finish_s),
                    f(q.rho.finish_s),
                    g(q.constant.mean_capture_s),
                    g(q.rho.mean_capture_s),
                    q.rho.rho_min.map_or("—".into(), |v| format!("{v:.4}")),
                    if q.captures_differ { "differ" } else { "same" }
                );
            }
            s += &p.finish_s.line("time to the goal");
            s.push('\n');
            s += &p.mean_capture_s.line("mean capture time");
            s.push('\n');
            let _ = writeln!(
                s,
                "  captures differ on {} of {} seed(s)",
                p.captures_differ,
                p.per_seed.len()
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paired_stat_takes_rho_minus_constant_over_the_seeds_both_have() {
        let s = PairedStat::of(&[
            (Some(10.0), Some(12.0)),
            (Some(10.0), Some(11.0)),
            (Some(10.0), None),
            (Some(20.0), Some(23.0)),
        ]);
        assert_eq!(s.pairs, 3);
        // d = 2, 1, 3: mean 2, sd 1, t = 2 / (1 / √3) = 3.464.
        assert_eq!(s.mean_difference, Some(2.0));
        let t = s.paired_t.unwrap();
        assert!((t.t - 3.464_101_6).abs() < 1e-6, "{t:?}");
        assert_eq!(t.df, 2.0);
        let same = PairedStat::of(&[(Some(5.0), Some(5.0)), (Some(6.0), Some(6.0))]);
        assert_eq!(same.paired_t, None);
        assert!(
            same.line("x").contains("no difference on any seed"),
            "{}",
            same.line("x")
        );
    }
}
