//! Paper 004's grid of experiments (`pheromone sweep`): robots × R_C × merge {on, off} ×
//! strategy × steering (shared field, own map) × trials, each run the single-process runner ([`run_single_process`]) on the
//! scenario with its overrides and the seeds 1..=T, in parallel on a work queue
//! (`std::thread::scope`, one worker per job). Per run: `exploration_known` (team, mean per
//! robot), `exploration_merged` (the paper's count) and `exploration` (visited); per point
//! (every value but the seed): mean ± sd of each ([`sweep_stats`](super::sweep_stats));
//! comparisons at equal points on the sweep's [`Figure`]: merge on vs off and inverse vs
//! uniform, Welch's t and the paired t (the seeds match).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use serde::Serialize;

use super::exploration::{exploration_known, exploration_merged};
use super::metrics::exploration;
use super::single::{run_single_process, SingleProcessOptions};
use super::sweep_stats::{paired, welch, MeanSd, TTest};
use pheromone_roles::follower::StrategyKind;
use pheromone_roles::mapper::{MergeRule, SteerOn};
use pheromone_roles::process::role_loop::ProcessError;
use pheromone_world::scenario::{Overrides, Scenario, ScenarioError};

mod parse;
use parse::list_error;
pub use parse::{
    parse_merge_idle, parse_merge_rules, parse_rc_m, parse_robots, parse_steer, parse_strategies,
};

/// A sweep cannot be planned or one of its runs failed.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// A list option is malformed or holds a value out of range.
    #[error("{option} {value:?}: {reason}")]
    List {
        option: &'static str,
        value: String,
        reason: String,
    },
    /// The scenario has no exploration sectors to count.
    #[error("scenario '{0}' has no [metrics.exploration] (try ias-ss)")]
    NoExploration(String),
    /// The overrides of a point are refused by the scenario.
    #[error("{point}: {source}")]
    Scenario {
        point: String,
        #[source]
        source: Box<ScenarioError>,
    },
    /// A run failed.
    #[error("{point}, seed {seed}: {source}")]
    Run {
        point: String,
        seed: u64,
        #[source]
        source: Box<ProcessError>,
    },
}

/// Every combination of the merge rules and idle iterations given (an empty list: the
/// scenario's); empty when neither is given.
pub fn integrations(base: &Scenario, rules: &[MergeRule], idle: &[u32]) -> Vec<Integration> {
    if rules.is_empty() && idle.is_empty() {
        return Vec::new();
    }
    let rules = if rules.is_empty() {
        vec![base.mapping.merge_rule]
    } else {
        rules.to_vec()
    };
    let idle = if idle.is_empty() {
        vec![base.mapping.merge_idle_iterations]
    } else {
        idle.to_vec()
    };
    rules
        .iter()
        .flat_map(|&merge_rule| {
            idle.iter().map(move |&merge_idle_iterations| Integration {
                merge_rule,
                merge_idle_iterations,
            })
        })
        .collect()
}

/// The exploration figure a sweep compares and charts (every run records all three).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Figure {
    /// `exploration_known`: sectors mapped by the robot's sensor or merged into its final map.
    #[default]
    Known,
    /// `exploration_merged`: sectors visited or received through a merge (the paper's count).
    Merged,
    /// `exploration`: sectors the robot visited.
    Visited,
}

impl Figure {
    pub fn name(self) -> &'static str {
        match self {
            Figure::Known => "known",
            Figure::Merged => "merged",
            Figure::Visited => "visited",
        }
    }
}

impl std::str::FromStr for Figure {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "known" => Ok(Figure::Known),
            "merged" => Ok(Figure::Merged),
            "visited" => Ok(Figure::Visited),
            _ => Err(format!("'{s}': expected known, merged or visited")),
        }
    }
}

/// What a sweep runs: every combination of the lists, `trials` seeds each (1..=trials).
#[derive(Debug, Clone, PartialEq)]
pub struct SweepGrid {
    pub robots: Vec<usize>,
    /// Empty: the scenario's R_C only.
    pub rc_m: Vec<f64>,
    pub merge: Vec<bool>,
    pub strategies: Vec<StrategyKind>,
    /// Empty: the scenario's `[mapping] steer_on` only.
    pub steer: Vec<SteerOn>,
    /// How merges combine and what they cost (paper 004's ablations); empty: the scenario's
    /// `[mapping] merge_rule` and `merge_idle_iterations` only.
    pub integration: Vec<Integration>,
    pub trials: u32,
    pub duration_s: f64,
    /// The figure the comparisons test and the charts draw.
    pub figure: Figure,
}

/// How a point's merges combine two maps and what one costs: `[mapping] merge_rule` and
/// `merge_idle_iterations` (paper 004's ablations: merge by max; k idle iterations per merge).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct Integration {
    #[serde(serialize_with = "rule_name")]
    pub merge_rule: MergeRule,
    pub merge_idle_iterations: u32,
}

fn rule_name<S: serde::Serializer>(k: &MergeRule, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(k.name())
}

impl Integration {
    /// `max, 10 idle`; empty for paper 004's own (average, free).
    pub fn words(self) -> String {
        let mut w = Vec::new();
        if self.merge_rule != MergeRule::Average {
            w.push(format!("by {}", self.merge_rule.name()));
        }
        if self.merge_idle_iterations > 0 {
            w.push(format!("{} idle", self.merge_idle_iterations));
        }
        w.join(", ")
    }
}

/// One point of the grid: every setting but the seed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PointKey {
    pub robots: usize,
    pub rc_m: f64,
    pub merge: bool,
    #[serde(serialize_with = "strategy_name")]
    pub strategy: StrategyKind,
    #[serde(serialize_with = "steer_name")]
    pub steer_on: SteerOn,
    /// Without merging, the scenario's (it changes nothing).
    #[serde(flatten)]
    pub integration: Integration,
}

fn strategy_name<S: serde::Serializer>(k: &StrategyKind, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(k.name())
}

fn steer_name<S: serde::Serializer>(k: &SteerOn, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(k.name())
}

impl std::fmt::Display for PointKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} robot(s), R_C = {} m, {}, {}, steering on {}",
            self.robots,
            self.rc_m,
            if self.merge { "merge" } else { "no merge" },
            self.strategy.name(),
            self.steer_on.name()
        )?;
        match self.integration.words() {
            w if w.is_empty() => Ok(()),
            w => write!(f, ", merge {w}"),
        }
    }
}

/// One run's figures.
#[derive(Debug, Clone, Serialize)]
pub struct RunResult {
    #[serde(flatten)]
    pub point: PointKey,
    pub seed: u64,
    /// `exploration_known`: mean over the robots, and known by at least one.
    pub known_mean: f64,
    pub known_team: f64,
    /// `exploration_merged` (visited or received through a merge, the paper's count): mean
    /// over the robots, and counted by at least one.
    pub merged_mean: f64,
    pub merged_team: f64,
    /// `exploration` (visited): mean over the robots, and visited by at least one.
    pub visited_mean: f64,
    pub visited_team: f64,
    pub merges: usize,
    /// Mean merge alignment error (m), `None` without merges.
    pub alignment_error_m: Option<f64>,
    pub wall_s: f64,
}

/// A point's trials summarised.
#[derive(Debug, Clone, Serialize)]
pub struct Point {
    #[serde(flatten)]
    pub key: PointKey,
    pub seeds: Vec<u64>,
    pub known_mean: MeanSd,
    pub known_team: MeanSd,
    pub merged_mean: MeanSd,
    pub merged_team: MeanSd,
    pub visited_mean: MeanSd,
    pub visited_team: MeanSd,
    pub merges: MeanSd,
}

impl Point {
    /// The mean per robot of `figure`, mean ± sd over the trials.
    pub fn figure(&self, figure: Figure) -> MeanSd {
        match figure {
            Figure::Known => self.known_mean,
            Figure::Merged => self.merged_mean,
            Figure::Visited => self.visited_mean,
        }
    }
}

impl RunResult {
    /// The mean per robot of `figure`.
    pub fn figure(&self, figure: Figure) -> f64 {
        match figure {
            Figure::Known => self.known_mean,
            Figure::Merged => self.merged_mean,
            Figure::Visited => self.visited_mean,
        }
    }
}

/// Two points that differ in one setting, on the sweep's figure, mean per robot.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// `merge` (a: on, b: off) or `strategy` (a: inverse, b: uniform).
    pub kind: &'static str,
    pub a: PointKey,
    pub b: PointKey,
    pub mean_a: f64,
    pub mean_b: f64,
    /// Welch's t of a against b (unequal variances), `None` where undefined.
    pub welch: Option<TTest>,
    /// Paired t over the seeds (both points ran the same seeds), `None` where undefined.
    pub paired: Option<TTest>,
}

/// Everything a sweep measured.
#[derive(Debug, Clone, Serialize)]
pub struct SweepResult {
    pub scenario: String,
    pub duration_s: f64,
    pub trials: u32,
    pub sectors: u32,
    pub jobs: usize,
    /// The figure the comparisons and charts use.
    pub figure: Figure,
    pub wall_s: f64,
    pub points: Vec<Point>,
    pub comparisons: Vec<Comparison>,
    /// One per run, in grid order (robots, R_C, merge, strategy, steering, seed).
    #[serde(skip)]
    pub runs: Vec<RunResult>,
}

/// The most shards a sweep is split into.
pub const MAX_SHARDS: usize = 100_000;

/// The `K`-th of `N` slices of a sweep's runs (`K` from 0; `pheromone sweep --shard K/N`,
/// [`sweep_shard`](super::sweep_shard)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// The whole sweep: shard 0 of 1.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Whether the run at plan index `i` is in this shard.
    pub fn holds(self, i: usize) -> bool {
        i % self.count == self.index
    }

    /// The plan indices of this shard's runs, of a sweep of `total` runs, ascending.
    pub fn indices(self, total: usize) -> Vec<usize> {
        (self.index..total).step_by(self.count).collect()
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl std::str::FromStr for Shard {
    type Err = String;
    /// `K/N`: `N` from 1 to [`MAX_SHARDS`], `K` from 0 to `N − 1`.
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = |why: &str| format!("{s:?}: {why}");
        let (k, n) = s
            .split_once('/')
            .ok_or_else(|| bad("expected K/N, e.g. 0/4 (K from 0 to N-1)"))?;
        let n: usize = match n.trim().parse() {
            Ok(n) if (1..=MAX_SHARDS).contains(&n) => n,
            _ => return Err(bad("N is not a number of shards from 1 to 100000")),
        };
        match k.trim().parse::<usize>() {
            Ok(k) if k < n => Ok(Shard { index: k, count: n }),
            _ => Err(bad(&format!(
                "K is not a shard index from 0 to {} (shards count from 0, as $SLURM_ARRAY_TASK_ID with --array=0-{})",
                n - 1,
                n - 1
            ))),
        }
    }
}

/// The runs of a sweep: each point's scenario with its overrides, `trials` seeds each, in grid
/// order. Without merging, R_C only decides which rendezvous the world measures, and nobody
/// uses them: those points run once, at the first R_C of the list. Every point is checked
/// against the scenario before anything runs.
pub fn plan(
    base: &Scenario,
    grid: &SweepGrid,
) -> Result<Vec<(PointKey, u64, Scenario)>, SweepError> {
    if base.metrics.exploration.is_none() {
        return Err(SweepError::NoExploration(base.name.clone()));
    }
    if grid.trials == 0 {
        return Err(list_error("--trials", "0", "needs at least 1 trial"));
    }
    let max = base.world.robots.len();
    if let Some(&n) = grid.robots.iter().find(|&&n| n > max) {
        return Err(list_error(
            "--robots",
            &n.to_string(),
            format!("scenario '{}' places at most {max} robots", base.name),
        ));
    }
    let rc_m = if grid.rc_m.is_empty() {
        vec![base.mapping.rc_m]
    } else {
        grid.rc_m.clone()
    };
    let steer = if grid.steer.is_empty() {
        vec![base.mapping.steer_on]
    } else {
        grid.steer.clone()
    };
    let integration = if grid.integration.is_empty() {
        vec![Integration {
            merge_rule: base.mapping.merge_rule,
            merge_idle_iterations: base.mapping.merge_idle_iterations,
        }]
    } else {
        grid.integration.clone()
    };
    let mut out = Vec::new();
    for &robots in &grid.robots {
        for (ir, &rc) in rc_m.iter().enumerate() {
            for &merge in &grid.merge {
                // Without merging R_C and the merge settings change nothing a robot knows:
                // once, at the first of each.
                if !merge && ir > 0 {
                    continue;
                }
                let variants = if merge {
                    &integration[..]
                } else {
                    &integration[..1]
                };
                for &strategy in &grid.strategies {
                    for (&steer_on, &integration) in steer
                        .iter()
                        .flat_map(|s| variants.iter().map(move |v| (s, v)))
                    {
                        let key = PointKey {
                            robots,
                            rc_m: rc,
                            merge,
                            strategy,
                            steer_on,
                            integration,
                        };
                        for seed in 1..=grid.trials as u64 {
                            out.push((key, seed, point_scenario(base, grid, key, seed)?));
                        }
                    }
                }
            }
        }
    }
    Ok(out)
}

/// The scenario of one run: `base` with the point's settings and the seed.
fn point_scenario(
    base: &Scenario,
    grid: &SweepGrid,
    key: PointKey,
    seed: u64,
) -> Result<Scenario, SweepError> {
    let mut s = base.clone();
    s.apply(&Overrides {
        seed: Some(seed),
        robots: Some(key.robots),
        duration_s: Some(grid.duration_s),
        strategy: Some(key.strategy),
        merge: Some(key.merge),
        rc_m: Some(key.rc_m),
        steer_on: Some(key.steer_on),
        ..Overrides::default()
    })
    .map_err(|source| SweepError::Scenario {
        point: key.to_string(),
        source: Box::new(source),
    })?;
    s.mapping.merge_rule = key.integration.merge_rule;
    s.mapping.merge_idle_iterations = key.integration.merge_idle_iterations;
    Ok(s)
}

/// One run and its figures.
fn run_one(key: PointKey, seed: u64, s: &Scenario) -> Result<RunResult, SweepError> {
    let started = Instant::now();
    let (_, rec) = run_single_process(s, SingleProcessOptions::default()).map_err(|source| {
        SweepError::Run {
            point: key.to_string(),
            seed,
            source: Box::new(source),
        }
    })?;
    let m = s
        .metrics
        .exploration
        .as_ref()
        .ok_or_else(|| SweepError::NoExploration(s.name.clone()))?;
    let visited = exploration(m, &rec);
    let mapping = rec.mapping.as_ref();
    let known = mapping.and_then(|r| exploration_known(s, m, r));
    // Without a mapping record nobody merged: the paper's count is what each robot visited.
    let merged = mapping.map(|r| exploration_merged(m, &rec, &r.merges, s.world.dt_s));
    let errors: Vec<f64> = mapping
        .map(|r| r.merges.iter().map(|e| e.alignment_error_m).collect())
        .unwrap_or_default();
    Ok(RunResult {
        point: key,
        seed,
        known_mean: known.as_ref().map_or(visited.mean, |k| k.mean),
        known_team: known.as_ref().map_or(visited.team, |k| k.team),
        merged_mean: merged.as_ref().map_or(visited.mean, |k| k.mean),
        merged_team: merged.as_ref().map_or(visited.team, |k| k.team),
        visited_mean: visited.mean,
        visited_team: visited.team,
        merges: errors.len(),
        alignment_error_m: (!errors.is_empty())
            .then(|| errors.iter().sum::<f64>() / errors.len() as f64),
        wall_s: started.elapsed().as_secs_f64(),
    })
}

/// Runs the sweep on `jobs` threads (at least 1). `progress(done, total)` is called after every
/// run, from the worker that finished it. The first failure stops the sweep (runs under way
/// finish) and is returned.
pub fn run_sweep(
    base: &Scenario,
    grid: &SweepGrid,
    jobs: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SweepResult, SweepError> {
    run_sweep_shard(base, grid, Shard::WHOLE, jobs, progress)
}

/// [`run_sweep`] of `shard`'s runs only (plan indices `i % N == K`, [`Shard::holds`]): the
/// result's runs are the shard's, in plan order, and its points and comparisons theirs.
pub fn run_sweep_shard(
    base: &Scenario,
    grid: &SweepGrid,
    shard: Shard,
    jobs: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SweepResult, SweepError> {
    let started = Instant::now();
    let runs: Vec<_> = plan(base, grid)?
        .into_iter()
        .enumerate()
        .filter(|(i, _)| shard.holds(*i))
        .map(|(_, run)| run)
        .collect();
    let total = runs.len();
    // The largest runs first, so that the last ones to finish are short.
    let mut order: Vec<usize> = (0..total).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(runs[i].0.robots));
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let results: Mutex<Vec<Option<RunResult>>> = Mutex::new(vec![None; total]);
    let first_error: Mutex<Option<SweepError>> = Mutex::new(None);
    let jobs = jobs.clamp(1, total.max(1));
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| loop {
                if failed.load(Ordering::Relaxed) {
                    return;
                }
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(&i) = order.get(k) else {
                    return;
                };
                let (key, seed, s) = &runs[i];
                match run_one(*key, *seed, s) {
                    Ok(r) => {
                        results.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(r);
                        progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
                    }
                    Err(e) => {
                        failed.store(true, Ordering::Relaxed);
                        first_error
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .get_or_insert(e);
                        return;
                    }
                }
            });
        }
    });
    if let Some(e) = first_error.into_inner().unwrap_or_else(|e| e.into_inner()) {
        return Err(e);
    }
    let runs: Vec<RunResult> = results
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .flatten()
        .collect();
    let sectors = base
        .metrics
        .exploration
        .as_ref()
        .map_or(0, |m| m.cols * m.rows);
    let points = points(&runs);
    Ok(SweepResult {
        scenario: base.name.clone(),
        duration_s: grid.duration_s,
        trials: grid.trials,
        sectors,
        jobs,
        figure: grid.figure,
        wall_s: started.elapsed().as_secs_f64(),
        comparisons: comparisons(&runs, &points, grid.figure),
        points,
        runs,
    })
}

/// The runs of each point, in grid order.
fn by_point(runs: &[RunResult]) -> Vec<(PointKey, Vec<&RunResult>)> {
    let mut out: Vec<(PointKey, Vec<&RunResult>)> = Vec::new();
    for r in runs {
        match out.iter_mut().find(|(k, _)| *k == r.point) {
            Some((_, v)) => v.push(r),
            None => out.push((r.point, vec![r])),
        }
    }
    out
}

/// Each point's mean ± sd, in grid order.
pub fn points(runs: &[RunResult]) -> Vec<Point> {
    by_point(runs)
        .into_iter()
        .filter_map(|(key, rs)| {
            let of = |f: &dyn Fn(&RunResult) -> f64| {
                MeanSd::of(&rs.iter().map(|r| f(r)).collect::<Vec<_>>())
            };
            Some(Point {
                key,
                seeds: rs.iter().map(|r| r.seed).collect(),
                known_mean: of(&|r| r.known_mean)?,
                known_team: of(&|r| r.known_team)?,
                merged_mean: of(&|r| r.merged_mean)?,
                merged_team: of(&|r| r.merged_team)?,
                visited_mean: of(&|r| r.visited_mean)?,
                visited_team: of(&|r| r.visited_team)?,
                merges: of(&|r| r.merges as f64)?,
            })
        })
        .collect()
}

/// Merge on against off (at every R_C, against the one no-merge point of the same robots,
/// strategy and steering), and inverse against uniform, wherever both points ran; on
/// `figure`'s mean per robot.
pub fn comparisons(runs: &[RunResult], points: &[Point], figure: Figure) -> Vec<Comparison> {
    let values: BTreeMap<usize, Vec<(u64, f64)>> = by_point(runs)
        .into_iter()
        .enumerate()
        .map(|(i, (_, rs))| (i, rs.iter().map(|r| (r.seed, r.figure(figure))).collect()))
        .collect();
    let keys: Vec<PointKey> = by_point(runs).into_iter().map(|(k, _)| k).collect();
    let find = |k: &PointKey| keys.iter().position(|x| x == k);
    let mut out = Vec::new();
    for (ia, a) in keys.iter().enumerate() {
        // The no-merge point of the same robots and strategy (it ran at one R_C only).
        let partner = a
            .merge
            .then(|| {
                keys.iter().find(|k| {
                    !k.merge
                        && k.robots == a.robots
                        && k.strategy == a.strategy
                        && k.steer_on == a.steer_on
                })
            })
            .flatten()
            .map(|k| ("merge", *k));
        let rival = (a.strategy == StrategyKind::Inverse).then_some((
            "strategy",
            PointKey {
                strategy: StrategyKind::Uniform,
                ..*a
            },
        ));
        for (kind, b) in partner.into_iter().chain(rival) {
            let Some(ib) = find(&b) else { continue };
            let (va, vb) = (&values[&ia], &values[&ib]);
            let xa: Vec<f64> = va.iter().map(|v| v.1).collect();
            let xb: Vec<f64> = vb.iter().map(|v| v.1).collect();
            let same_seeds = va.iter().map(|v| v.0).eq(vb.iter().map(|v| v.0));
            let mean = |k: &PointKey| {
                points
                    .iter()
                    .find(|p| p.key == *k)
                    .map_or(f64::NAN, |p| p.figure(figure).mean)
            };
            out.push(Comparison {
                kind,
                a: *a,
                b,
                mean_a: mean(a),
                mean_b: mean(&b),
                welch: welch(&xa, &xb),
                paired: if same_seeds { paired(&xa, &xb) } else { None },
            });
        }
    }
    out
}

#[cfg(test)]
mod tests;
