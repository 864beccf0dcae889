//! The lists of `pheromone sweep`'s dimensions (`--robots 1,2,4`, `--rc-m`, `--strategies`,
//! `--steer`, `--merge-rules`, `--merge-idle`): each parsed, checked and named in its error.

use pheromone_roles::follower::StrategyKind;
use pheromone_roles::mapper::{MergeRule, SteerOn};

use super::SweepError;

pub(super) fn list_error(
    option: &'static str,
    value: &str,
    reason: impl Into<String>,
) -> SweepError {
    SweepError::List {
        option,
        value: value.to_string(),
        reason: reason.into(),
    }
}

/// The comma-separated items of `text`, each trimmed; an empty item is an error naming it.
fn items<'a>(option: &'static str, text: &'a str) -> Result<Vec<&'a str>, SweepError> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(list_error(
            option,
            text,
            "expected a comma-separated list with no empty item",
        ));
    }
    Ok(parts)
}

/// The most robots a sweep's run may have (`pheromone sim --robots` takes as many).
pub const MAX_ROBOTS: usize = 512;
/// The largest communication radius R_C a sweep takes (m).
pub const MAX_RC_M: f64 = 1e6;

/// `--robots 1,2,4`: robot counts from 1 to `MAX_ROBOTS`, each at most once.
pub fn parse_robots(text: &str) -> Result<Vec<usize>, SweepError> {
    let mut out = Vec::new();
    for p in items("--robots", text)? {
        match p.parse::<usize>() {
            Ok(n) if (1..=MAX_ROBOTS).contains(&n) => {
                if out.contains(&n) {
                    return Err(list_error("--robots", p, "given twice"));
                }
                out.push(n)
            }
            _ => return Err(list_error("--robots", p, "not a robot count from 1 to 512")),
        }
    }
    Ok(out)
}

/// `--rc-m 4,8,16`: distances > 0, at most `MAX_RC_M` (m), each at most once.
pub fn parse_rc_m(text: &str) -> Result<Vec<f64>, SweepError> {
    let mut out = Vec::new();
    for p in items("--rc-m", text)? {
        match p.parse::<f64>() {
            Ok(r) if r.is_finite() && r > 0.0 && r <= MAX_RC_M => {
                if out.contains(&r) {
                    return Err(list_error("--rc-m", p, "given twice"));
                }
                out.push(r)
            }
            _ => {
                return Err(list_error(
                    "--rc-m",
                    p,
                    "not a communication radius > 0, at most 1e6 (m)",
                ))
            }
        }
    }
    Ok(out)
}

/// `--strategies inverse,uniform`: exploring strategies (inverse, uniform), each at most once.
pub fn parse_strategies(text: &str) -> Result<Vec<StrategyKind>, SweepError> {
    let mut out = Vec::new();
    for p in items("--strategies", text)? {
        match p.parse::<StrategyKind>() {
            Ok(k @ (StrategyKind::Inverse | StrategyKind::Uniform)) => {
                if out.contains(&k) {
                    return Err(list_error("--strategies", p, "given twice"));
                }
                out.push(k)
            }
            _ => {
                return Err(list_error(
                    "--strategies",
                    p,
                    "not an exploring strategy (inverse, uniform)",
                ))
            }
        }
    }
    Ok(out)
}

/// `--steer own-map,shared`: what the sector strategies steer on, each at most once.
pub fn parse_steer(text: &str) -> Result<Vec<SteerOn>, SweepError> {
    let mut out = Vec::new();
    for p in items("--steer", text)? {
        match p.parse::<SteerOn>() {
            Ok(k) => {
                if out.contains(&k) {
                    return Err(list_error("--steer", p, "given twice"));
                }
                out.push(k)
            }
            Err(_) => return Err(list_error("--steer", p, "expected own-map or shared")),
        }
    }
    Ok(out)
}

/// `--merge-rule average,max`: how merges combine two maps, each at most once.
pub fn parse_merge_rules(text: &str) -> Result<Vec<MergeRule>, SweepError> {
    let mut out = Vec::new();
    for p in items("--merge-rule", text)? {
        match p.parse::<MergeRule>() {
            Ok(k) if !out.contains(&k) => out.push(k),
            Ok(_) => return Err(list_error("--merge-rule", p, "given twice")),
            Err(_) => {
                return Err(list_error(
                    "--merge-rule",
                    p,
                    "expected average, adopt-unknown or max",
                ))
            }
        }
    }
    Ok(out)
}

/// The most idle iterations per merge a sweep takes (the paper runs 1000 iterations).
pub const MAX_IDLE_ITERATIONS: u32 = 100_000;

/// `--merge-idle 0,5,20`: iterations a robot stands still after a merge, each at most once.
pub fn parse_merge_idle(text: &str) -> Result<Vec<u32>, SweepError> {
    let mut out = Vec::new();
    for p in items("--merge-idle", text)? {
        match p.parse::<u32>() {
            Ok(k) if k <= MAX_IDLE_ITERATIONS && !out.contains(&k) => out.push(k),
            Ok(k) if k <= MAX_IDLE_ITERATIONS => {
                return Err(list_error("--merge-idle", p, "given twice"))
            }
            _ => {
                return Err(list_error(
                    "--merge-idle",
                    p,
                    "not a number of iterations from 0 to 100000",
                ))
            }
        }
    }
    Ok(out)
}
