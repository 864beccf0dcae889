//! `pheromone sweep --shard K/N` and `pheromone sweep merge`: a sweep split over the tasks of a
//! scheduler (a Slurm array, a Kubernetes Indexed Job) and joined again.
//!
//! Shard `K/N` (`K` from 0 to N − 1, as `$SLURM_ARRAY_TASK_ID` with `--array=0-(N-1)` and
//! `$JOB_COMPLETION_INDEX` count) runs the runs of the sweep's plan ([`plan`](super::sweep::plan))
//! whose index `i` has `i % N == K`: round-robin, so every run is in exactly one shard and each
//! shard gets about the same mix of small and large points. A shard records which sweep it
//! belongs to ([`sweep_id`]: a hash of the scenario and every setting of the grid) in its
//! [`ShardRecord`]; [`merge`] takes one shard of each index, refuses a missing or duplicated
//! index and shards of different sweeps (naming them), and puts the runs back in plan order,
//! so the points and comparisons are those of the unsharded sweep.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::sweep::{comparisons, points, Figure, RunResult, Shard, SweepGrid, SweepResult};
use pheromone_world::scenario::Scenario;

/// The version of [`ShardRecord`]'s layout (`shard.json`'s `format`).
pub const SHARD_FORMAT: u32 = 1;

/// The identity of a sweep: FNV-1a (64 bits, hex) of the scenario (every value, as JSON) and
/// the grid (every list, the trials, the duration and the figure). Two shards with the same id
/// ran the same plan; `--jobs` and `--out` are not part of it.
pub fn sweep_id(base: &Scenario, grid: &SweepGrid) -> String {
    let scenario = serde_json::to_string(base).unwrap_or_else(|e| format!("{base:?} ({e})"));
    let text = format!("pheromone sweep\n{scenario}\n{grid:?}\n");
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// `shard.json`: which shard of which sweep a directory holds, and what the merge needs to
/// write the sweep's files (the rows themselves are the directory's `sweep.csv`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardRecord {
    /// [`SHARD_FORMAT`].
    pub format: u32,
    /// [`sweep_id`].
    pub sweep: String,
    pub shard: Shard,
    /// The runs of the whole sweep.
    pub total_runs: usize,
    /// The plan index of each row of `sweep.csv`, in order.
    pub runs: Vec<usize>,
    /// Each row's wall time (s), in order (`sweep.csv` holds only what the runs computed).
    pub run_wall_s: Vec<f64>,
    pub scenario: String,
    pub duration_s: f64,
    pub trials: u32,
    pub sectors: u32,
    pub figure: Figure,
    /// This shard's worker threads and wall time (s).
    pub jobs: usize,
    pub wall_s: f64,
}

impl ShardRecord {
    /// The record of `result`, shard `shard` of the sweep `id` of `total_runs` runs.
    pub fn new(id: String, shard: Shard, total_runs: usize, result: &SweepResult) -> ShardRecord {
        ShardRecord {
            format: SHARD_FORMAT,
            sweep: id,
            shard,
            total_runs,
            runs: shard.indices(total_runs),
            run_wall_s: result.runs.iter().map(|r| r.wall_s).collect(),
            scenario: result.scenario.clone(),
            duration_s: result.duration_s,
            trials: result.trials,
            sectors: result.sectors,
            figure: result.figure,
            jobs: result.jobs,
            wall_s: result.wall_s,
        }
    }
}

/// Shards that do not make one sweep; each names the directories concerned.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    #[error("no shard directory given")]
    Empty,
    #[error("{}: shard.json format {found}, this build reads format {SHARD_FORMAT}", dir.display())]
    Format { dir: PathBuf, found: u32 },
    #[error(
        "{} and {} are shards of different sweeps ({detail}; every shard needs the same scenario and flags but --shard, --jobs and --out)",
        a.display(), b.display()
    )]
    DifferentSweeps {
        a: PathBuf,
        b: PathBuf,
        detail: String,
    },
    #[error("shard {shard} given twice: {} and {} (give each shard's directory once)", first.display(), second.display())]
    Duplicate {
        shard: Shard,
        first: PathBuf,
        second: PathBuf,
    },
    #[error(
        "sweep {sweep}: missing shard(s) {} of {count} (given: {})",
        list(missing),
        list(given)
    )]
    Missing {
        sweep: String,
        count: usize,
        missing: Vec<usize>,
        given: Vec<usize>,
    },
    #[error("{}: {detail}", dir.display())]
    Inconsistent { dir: PathBuf, detail: String },
}

fn list(v: &[usize]) -> String {
    v.iter()
        .map(|k| k.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// One shard as read back: its directory, its record and its rows.
#[derive(Debug, Clone)]
pub struct ShardRuns {
    pub dir: PathBuf,
    pub record: ShardRecord,
    pub runs: Vec<RunResult>,
}

/// `a` and `b` belong to the same sweep, split the same way.
fn same_sweep(a: &ShardRuns, b: &ShardRuns) -> Result<(), MergeError> {
    let what = |s: &ShardRuns| format!("'{}' shard {}", s.record.scenario, s.record.shard);
    if a.record.sweep != b.record.sweep || a.record.shard.count != b.record.shard.count {
        return Err(MergeError::DifferentSweeps {
            a: a.dir.clone(),
            b: b.dir.clone(),
            detail: format!(
                "{} of sweep {}, {} of sweep {}",
                what(a),
                a.record.sweep,
                what(b),
                b.record.sweep
            ),
        });
    }
    Ok(())
}

/// A shard's rows are the runs its index holds.
fn check_rows(s: &ShardRuns) -> Result<(), MergeError> {
    let r = &s.record;
    let bad = |detail: String| MergeError::Inconsistent {
        dir: s.dir.clone(),
        detail,
    };
    if r.format != SHARD_FORMAT {
        return Err(MergeError::Format {
            dir: s.dir.clone(),
            found: r.format,
        });
    }
    if r.runs != r.shard.indices(r.total_runs) {
        return Err(bad(format!(
            "shard.json: the runs of shard {} of a {}-run sweep are not its plan indices",
            r.shard, r.total_runs
        )));
    }
    if r.run_wall_s.len() != r.runs.len() {
        return Err(bad(format!(
            "shard.json lists {} run(s) and {} wall time(s)",
            r.runs.len(),
            r.run_wall_s.len()
        )));
    }
    if r.runs.len() != s.runs.len() {
        return Err(bad(format!(
            "sweep.csv has {} row(s), shard.json lists {} run(s) (a shard that did not finish?)",
            s.runs.len(),
            r.runs.len()
        )));
    }
    Ok(())
}

/// The shards in index order, after checking that they are every shard of one sweep, once.
fn complete(mut shards: Vec<ShardRuns>) -> Result<Vec<ShardRuns>, MergeError> {
    let first = shards.first().ok_or(MergeError::Empty)?.clone();
    for s in &shards {
        same_sweep(&first, s)?;
        check_rows(s)?;
    }
    shards.sort_by_key(|s| s.record.shard.index);
    for w in shards.windows(2) {
        if w[0].record.shard == w[1].record.shard {
            return Err(MergeError::Duplicate {
                shard: w[0].record.shard,
                first: w[0].dir.clone(),
                second: w[1].dir.clone(),
            });
        }
    }
    let given: Vec<usize> = shards.iter().map(|s| s.record.shard.index).collect();
    let count = first.record.shard.count;
    let missing: Vec<usize> = (0..count).filter(|k| !given.contains(k)).collect();
    if !missing.is_empty() {
        return Err(MergeError::Missing {
            sweep: first.record.sweep,
            count,
            missing,
            given,
        });
    }
    Ok(shards)
}

/// The sweep the shards make: every run in plan order, the points and comparisons computed
/// from them as the unsharded sweep computes them. `jobs` is the sum of the shards' threads,
/// `wall_s` the longest shard's (what the sweep took with every shard running at once).
pub fn merge(shards: Vec<ShardRuns>) -> Result<SweepResult, MergeError> {
    let shards = complete(shards)?;
    let r = shards[0].record.clone();
    let mut slots: Vec<Option<RunResult>> = vec![None; r.total_runs];
    for s in &shards {
        for (&i, run) in s.record.runs.iter().zip(&s.runs) {
            slots[i] = Some(run.clone());
        }
    }
    // Every index is held by exactly one complete shard (checked above).
    let runs: Vec<RunResult> = slots.into_iter().flatten().collect();
    let points = points(&runs);
    Ok(SweepResult {
        scenario: r.scenario,
        duration_s: r.duration_s,
        trials: r.trials,
        sectors: r.sectors,
        jobs: shards.iter().map(|s| s.record.jobs).sum(),
        figure: r.figure,
        wall_s: shards.iter().map(|s| s.record.wall_s).fold(0.0, f64::max),
        comparisons: comparisons(&runs, &points, r.figure),
        points,
        runs,
    })
}

#[cfg(test)]
mod tests;
