//! `pheromone sweep trail-following`: paper 002's parameter study
//! (`pheromone_sim::trail_sweep`), each run as processes by default (`--single-process`: in
//! this one), and the files of `pheromone_report::write_trail_sweep`.

use std::time::Duration;

use clap::Args;
use pheromone_sim::processes::{run_as_processes, ProcessRunError, ProcessRunOptions};
use pheromone_sim::recording::Recording;
use pheromone_sim::single::{run_single_process, SingleProcessOptions};
use pheromone_sim::trail_sweep::{
    default_study, plan, run_trail_sweep, TrailParam, TrailSweep, TrailSweepError,
};
use pheromone_world::scenario::Scenario;

use super::out::Output;
use super::stop::{self, Stopped};
use super::{bad, bad_from};

/// The flags of paper 002's study (a scenario with `[[metrics.paths]]` and antenna robots).
#[derive(Args, Debug, Default)]
pub struct TrailArgs {
    /// Trail study (paper 002): turn gains k of ω = k·(P_L − P_R) (rad/s), comma-separated,
    /// each in (0, 100].
    #[arg(long = "omega-gain", value_name = "LIST", allow_hyphen_values = true)]
    pub omega_gain: Option<String>,
    /// Trail study: antenna spacings b (m), comma-separated, each in (0, 2].
    #[arg(long = "wheel-base", value_name = "LIST", allow_hyphen_values = true)]
    pub wheel_base: Option<String>,
    /// Trail study: each antenna's field of view on a source channel (degrees), each in
    /// (0, 360].
    #[arg(long, value_name = "LIST", allow_hyphen_values = true)]
    pub fov: Option<String>,
    /// Trail study: each antenna turned outward from the heading (degrees), each in [0, 90].
    #[arg(long, value_name = "LIST", allow_hyphen_values = true)]
    pub splay: Option<String>,
    /// Trail study: forward speeds K of eq. 6 (m/s), each in (0, 5].
    #[arg(long, value_name = "LIST", allow_hyphen_values = true)]
    pub speed: Option<String>,
    /// Trail study: the antennas' reading scales (normalize_max), each > 0, or `max` (by the
    /// larger of the two readings, the scenario's).
    #[arg(long, value_name = "LIST", allow_hyphen_values = true)]
    pub normalize: Option<String>,
    /// Trail study: run each simulation in this process, not as separate processes (the same
    /// figures, faster).
    #[arg(long = "single-process")]
    pub single_process: bool,
}

impl TrailArgs {
    /// The lists given, each parsed ([`default_study`] when none is).
    pub fn study(&self) -> anyhow::Result<Vec<(TrailParam, Vec<f64>)>> {
        let given = [
            (TrailParam::OmegaGain, &self.omega_gain),
            (TrailParam::WheelBase, &self.wheel_base),
            (TrailParam::Fov, &self.fov),
            (TrailParam::Splay, &self.splay),
            (TrailParam::Speed, &self.speed),
            (TrailParam::Normalize, &self.normalize),
        ];
        let mut out = Vec::new();
        for (p, text) in given {
            if let Some(t) = text {
                out.push((p, p.parse(t).map_err(bad_from)?));
            }
        }
        Ok(if out.is_empty() { default_study() } else { out })
    }

    /// Whether a flag of the trail study was given.
    pub fn any(&self) -> bool {
        self.single_process
            || [
                &self.omega_gain,
                &self.wheel_base,
                &self.fov,
                &self.splay,
                &self.speed,
                &self.normalize,
            ]
            .iter()
            .any(|x| x.is_some())
    }
}

/// Whether `s` is a scenario for the trail study: paths to measure and no exploration.
pub fn is_trail(s: &Scenario) -> bool {
    !s.metrics.paths.is_empty() && s.metrics.exploration.is_none()
}

/// The study of `base` run and written.
pub fn sweep(
    trail: &TrailArgs,
    trials: u32,
    json: bool,
    base: &Scenario,
    out: &Output,
) -> anyhow::Result<()> {
    stop::install()?;
    let study = trail.study()?;
    let planned = plan(base, &study).map_err(bad_from)?;
    let sims = (planned.iter().map(|(_, _, v)| v.len()).sum::<usize>() + 1 - planned.len())
        * trials as usize;
    let mode = if trail.single_process {
        "in one process"
    } else {
        "as processes"
    };
    eprintln!(
        "sweep '{}': paper 002's study, {sims} simulation(s) {mode}",
        base.name
    );
    let bar = super::sim::progress_bar_of(sims as u64, "runs");
    let run = |s: &Scenario| one_run(s, trail.single_process);
    let result = match run_trail_sweep(base, &planned, trials, run, || bar.inc(1)) {
        Ok(r) => r,
        Err(TrailSweepError::Run { source, .. }) => return Err(source),
        Err(e) => return Err(bad(e.to_string())),
    };
    bar.finish_and_clear();
    write(json, &result, out)
}

/// One simulation of the study (processes or this one); a stop request ends the study.
fn one_run(s: &Scenario, single: bool) -> anyhow::Result<Recording> {
    let stopped = || stop::requested().is_some();
    let rec = if single {
        let options = SingleProcessOptions {
            slam: false,
            progress: None,
            record: None,
            stop: Some(&stopped),
        };
        run_single_process(s, options)?.1
    } else {
        let options = ProcessRunOptions {
            exe: std::env::current_exe()?,
            slam: false,
            realtime: false,
            timeout: Duration::from_secs(900),
            attach_timeout: None,
            stall_timeout: Duration::from_secs(30),
            progress: None,
            view: None,
            ros2: None,
            ros2_args: Vec::new(),
            rt_args: Vec::new(),
            remote: false,
            follower_wait: None,
            record: None,
        };
        match run_as_processes(s, options) {
            Ok(r) => r.1,
            Err(ProcessRunError::Interrupted) => {
                eprintln!("sweep: stopped: nothing written");
                return Err(Stopped::by_requested().into());
            }
            Err(e) => return Err(e.into()),
        }
    };
    if stopped() {
        eprintln!("sweep: stopped: nothing written");
        return Err(Stopped::by_requested().into());
    }
    Ok(rec)
}

/// The study's lines on stderr and its files.
fn write(json: bool, r: &TrailSweep, out: &Output) -> anyhow::Result<()> {
    eprintln!(
        "sweep '{}' done: {} simulation(s), seeds 1–{}",
        r.scenario, r.simulations, r.trials
    );
    eprint!("{}", pheromone_report::trail_table(r));
    let seeds: Vec<u64> = (1..=u64::from(r.trials)).collect();
    let name = format!("sweep-{}", r.scenario);
    if let Some(dir) = out.dir_in(&name, &r.scenario, &seeds)? {
        let files = pheromone_report::write_trail_sweep(&dir, r)?;
        eprintln!("wrote {} file(s) to {}", files.len(), dir.display());
    }
    if json {
        println!("{}", serde_json::to_string(r)?);
    }
    Ok(())
}
