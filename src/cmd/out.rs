//! Where `sim` and `sweep` write (`pheromone_report::rundir`): `--out DIR` (refused when not
//! empty, unless `--force`), by default a new `pheromone-out/<scenario>/<run-id>/`; `--no-out`
//! nothing. The directory is made when the run has something to write; `run.json` and the
//! `latest` links when the command ends.

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use pheromone_report::rundir::{self, RunDir, RunDirError, RunInfo};

use super::stop::Stopped;

/// One invocation's output: where it goes, and what `run.json` will say.
pub struct Output {
    /// `None`: `--no-out`; `Some(None)`: the default directory; `Some(Some(dir))`: `--out`.
    plan: Option<Option<PathBuf>>,
    /// The subcommand (`sim`, `sweep`): run.json's flags are what follows it.
    command: &'static str,
    started: SystemTime,
    made: RefCell<Option<(RunDir, String, Vec<u64>)>>,
}

impl Output {
    /// `--out`, `--no-out` and `--force` checked now: a non-empty `--out` without `--force`
    /// is bad input (exit 2) before anything runs (nothing is created: [`make_named`]).
    ///
    /// [`make_named`]: Self::make_named
    pub fn plan(
        command: &'static str,
        out: Option<&Path>,
        no_out: bool,
        force: bool,
    ) -> anyhow::Result<Self> {
        if let Some(dir) = out {
            RunDir::check_named(dir, force).map_err(bad_out)?;
        }
        Ok(Self {
            plan: (!no_out).then(|| out.map(Path::to_path_buf)),
            command,
            started: SystemTime::now(),
            made: RefCell::new(None),
        })
    }

    /// `--out DIR` made now, so a directory that cannot be made (`/proc/x`, a file on the
    /// way) is bad input before the run rather than an error after it.
    pub fn make_named(&self) -> anyhow::Result<()> {
        if let Some(Some(dir)) = &self.plan {
            RunDir::named(dir, true).map_err(bad_out)?;
        }
        Ok(())
    }

    /// The directory of the run of `scenario` with `seeds` (made on the first call; `None`
    /// with `--no-out`).
    pub fn dir(&self, scenario: &str, seeds: &[u64]) -> anyhow::Result<Option<PathBuf>> {
        self.dir_in(scenario, scenario, seeds)
    }

    /// [`dir`](Self::dir), the default directory under `pheromone-out/<name>/` (a sweep's).
    pub fn dir_in(
        &self,
        name: &str,
        scenario: &str,
        seeds: &[u64],
    ) -> anyhow::Result<Option<PathBuf>> {
        let Some(plan) = &self.plan else {
            return Ok(None);
        };
        let mut made = self.made.borrow_mut();
        if made.is_none() {
            let dir = match plan {
                // Checked by `plan`: what the run wrote there since (--record) is its own.
                Some(d) => RunDir::named(d, true)?,
                None => RunDir::unique(Path::new(rundir::ROOT), name, self.started)?,
            };
            *made = Some((dir, scenario.to_string(), seeds.to_vec()));
        }
        Ok(made.as_ref().map(|(d, ..)| d.path().to_path_buf()))
    }

    /// `run.json` and the `latest` links, if the run made its directory; then `result`.
    pub fn finish(self, result: anyhow::Result<()>) -> anyhow::Result<()> {
        let Some((dir, scenario, seeds)) = self.made.into_inner() else {
            return result;
        };
        let status = match &result {
            Ok(()) => "done",
            Err(e) if e.downcast_ref::<Stopped>().is_some() => "interrupted",
            Err(_) => "failed",
        };
        let command: Vec<String> = std::env::args().collect();
        let after = command
            .iter()
            .position(|a| a == self.command)
            .map_or(1, |i| i + 1);
        let info = RunInfo {
            flags: command.iter().skip(after).cloned().collect(),
            command,
            version: env!("CARGO_PKG_VERSION").to_string(),
            scenario,
            seeds,
            started_utc: rundir::utc(self.started),
            ended_utc: rundir::utc(SystemTime::now()),
            status: status.to_string(),
            files: Vec::new(),
        };
        let written = dir.finish(info);
        result?;
        written?;
        Ok(())
    }
}

/// A refused `--out` as bad input (exit status 2).
fn bad_out(e: RunDirError) -> anyhow::Error {
    super::bad(format!("--out {e}"))
}
