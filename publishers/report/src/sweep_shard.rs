//! What `pheromone sweep --shard K/N` writes and `pheromone sweep merge` reads back: the shard's
//! `sweep.csv` (its rows, in the format of [`sweep_csv`]) and `shard.json`
//! ([`ShardRecord`]: which shard of which sweep, and each row's wall time). The CSV is read back exactly: each number is
//! written as Rust prints an `f64` (the shortest text that parses back to the same value), so
//! the merged sweep's rows are the shards' rows byte for byte.

use std::fs;
use std::path::{Path, PathBuf};

use super::files::{write_file, write_json};
use super::sweep::{sweep_csv, SWEEP_CSV_HEADER};
use super::ReportError;
use pheromone_sim::sweep::{Integration, PointKey, RunResult, SweepResult};
use pheromone_sim::sweep_shard::{ShardRecord, ShardRuns};

/// A shard directory that cannot be read back.
#[derive(Debug, thiserror::Error)]
pub enum ShardFileError {
    #[error("{}: {source} (is it the --out of `pheromone sweep --shard K/N`?)", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: not a shard record: {source}", path.display())]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{}:{line}: {detail}", path.display())]
    Csv {
        path: PathBuf,
        line: usize,
        detail: String,
    },
}

/// Writes `sweep.csv` (the shard's rows) and `shard.json` into `dir` (created if needed).
pub fn write_shard(
    dir: &Path,
    r: &SweepResult,
    record: &ShardRecord,
) -> Result<Vec<PathBuf>, ReportError> {
    fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let csv = dir.join("sweep.csv");
    write_file(&csv, sweep_csv(r).as_bytes())?;
    let json = dir.join("shard.json");
    write_json(&json, record)?;
    Ok(vec![csv, json])
}

/// The shard in `dir`: its `shard.json` and the rows of its `sweep.csv`.
pub fn read_shard(dir: &Path) -> Result<ShardRuns, ShardFileError> {
    let read = |name: &str| {
        let path = dir.join(name);
        fs::read_to_string(&path).map_err(|source| ShardFileError::Read { path, source })
    };
    let json = read("shard.json")?;
    let record: ShardRecord =
        serde_json::from_str(&json).map_err(|source| ShardFileError::Json {
            path: dir.join("shard.json"),
            source,
        })?;
    let mut runs =
        parse_sweep_csv(&read("sweep.csv")?).map_err(|(line, detail)| ShardFileError::Csv {
            path: dir.join("sweep.csv"),
            line,
            detail,
        })?;
    if record.run_wall_s.len() == runs.len() {
        for (run, &t) in runs.iter_mut().zip(&record.run_wall_s) {
            run.wall_s = t;
        }
    }
    Ok(ShardRuns {
        dir: dir.to_path_buf(),
        record,
        runs,
    })
}

/// The runs of a `sweep.csv` (their `wall_s`: NaN, it is not in the file); an error is the line
/// (from 1) and what is wrong with it.
pub fn parse_sweep_csv(text: &str) -> Result<Vec<RunResult>, (usize, String)> {
    let mut lines = text.lines();
    match lines.next() {
        Some(SWEEP_CSV_HEADER) => {}
        other => {
            return Err((
                1,
                format!("header {other:?}, expected {SWEEP_CSV_HEADER:?}"),
            ))
        }
    }
    lines
        .enumerate()
        .map(|(i, line)| parse_row(line).map_err(|detail| (i + 2, detail)))
        .collect()
}

/// One row of `sweep.csv`, every column parsed as [`sweep_csv`] wrote it.
fn parse_row(line: &str) -> Result<RunResult, String> {
    let c: Vec<&str> = line.split(',').collect();
    if c.len() != 16 {
        return Err(format!("{} column(s), expected 16", c.len()));
    }
    fn p<T: std::str::FromStr>(c: &[&str], i: usize) -> Result<T, String> {
        let name = SWEEP_CSV_HEADER.split(',').nth(i).unwrap_or("?");
        c[i].parse()
            .map_err(|_| format!("column {name}: {:?} is not a valid value", c[i]))
    }
    Ok(RunResult {
        point: PointKey {
            robots: p(&c, 0)?,
            rc_m: p(&c, 1)?,
            merge: p(&c, 2)?,
            strategy: p(&c, 3)?,
            steer_on: p(&c, 4)?,
            integration: Integration {
                merge_rule: p(&c, 5)?,
                merge_idle_iterations: p(&c, 6)?,
            },
        },
        seed: p(&c, 7)?,
        known_mean: p(&c, 8)?,
        known_team: p(&c, 9)?,
        merged_mean: p(&c, 10)?,
        merged_team: p(&c, 11)?,
        visited_mean: p(&c, 12)?,
        visited_team: p(&c, 13)?,
        merges: p(&c, 14)?,
        alignment_error_m: match c[15] {
            "" => None,
            _ => Some(p(&c, 15)?),
        },
        // Not in sweep.csv: `read_shard` takes it from `shard.json`.
        wall_s: f64::NAN,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pheromone_roles::follower::StrategyKind;
    use pheromone_roles::mapper::{MergeRule, SteerOn};
    use pheromone_sim::sweep::{Figure, Shard};

    fn run(seed: u64, x: f64, merge: bool) -> RunResult {
        RunResult {
            point: PointKey {
                robots: 3,
                rc_m: 8.25,
                merge,
                strategy: StrategyKind::Uniform,
                steer_on: SteerOn::OwnMap,
                integration: Integration {
                    merge_rule: MergeRule::Max,
                    merge_idle_iterations: 7,
                },
            },
            seed,
            known_mean: x,
            known_team: 1.0 / 3.0,
            merged_mean: 0.1 + 0.2,
            merged_team: 1e-300,
            visited_mean: 2.0f64.sqrt(),
            visited_team: 0.0,
            merges: 12,
            alignment_error_m: merge.then_some(0.123_456_789_012_345_67),
            wall_s: 0.017,
        }
    }

    #[test]
    fn a_shard_reads_back_row_for_row_and_byte_for_byte() {
        let r = SweepResult {
            scenario: "ias-ss".into(),
            duration_s: 15.0,
            trials: 2,
            sectors: 24,
            jobs: 1,
            figure: Figure::Merged,
            wall_s: 0.5,
            points: Vec::new(),
            comparisons: Vec::new(),
            runs: vec![run(1, 0.7, true), run(2, f64::EPSILON, false)],
        };
        let shard = Shard { index: 1, count: 2 };
        let record = ShardRecord::new("00000000deadbeef".into(), shard, 4, &r);
        let dir = std::env::temp_dir().join(format!("sweep-shard-{}", std::process::id()));
        write_shard(&dir, &r, &record).unwrap();
        let back = read_shard(&dir).unwrap();
        assert_eq!(back.record, record);
        assert_eq!(back.record.runs, [1, 3]);
        let again = SweepResult {
            runs: back.runs,
            ..r.clone()
        };
        assert_eq!(sweep_csv(&again), sweep_csv(&r));
        assert_eq!(again.runs[1].wall_s, 0.017);
        // A damaged row is named by file, line and column.
        let text = sweep_csv(&r).replace("uniform", "sideways");
        let (line, detail) = parse_sweep_csv(&text).unwrap_err();
        assert_eq!(line, 2);
        assert!(
            detail.contains("strategy") && detail.contains("sideways"),
            "{detail}"
        );
        fs::write(dir.join("sweep.csv"), "robots\n").unwrap();
        let e = read_shard(&dir).unwrap_err().to_string();
        assert!(e.contains("sweep.csv:1: header"), "{e}");
        fs::remove_dir_all(&dir).unwrap();
        let e = read_shard(&dir).unwrap_err().to_string();
        assert!(e.contains("shard.json"), "{e}");
    }
}
