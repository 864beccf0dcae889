//! `pheromone sim`: runs a whole scenario — by default as separate processes (field, world, and
//! each robot's localizer, depositor and follower), or in one process (`--single-process`) —
//! and reports what happened: a summary on stderr, `--json` metrics on stdout, and with
//! `--out DIR` pictures of the field, the scenario's charts, a CSV per robot and
//! `metrics.json`.

use std::time::Instant;

use pheromone_roles::follower::StrategyKind;
use pheromone_ros2::record::{ChunkCompression, McapRecorder, RecordError};
use pheromone_sim::metrics::{RunMetrics, RunMode};
use pheromone_sim::processes::ProcessRunInfo;
use pheromone_sim::recording::Recording;
use pheromone_sim::ros_record::{McapTotals, SimMcap};
use pheromone_sim::single::{run_single_process, RunSummary, SingleProcessOptions};
use pheromone_sim::trials::TrialsError;
use pheromone_world::scenario::{Overrides, Scenario};

use super::out::Output;
use super::roles::load_scenario;
pub use super::sim_args::SimArgs;
use super::sim_run::run_processes;
use super::stop::{self, Stopped};
use super::{bad, bad_from, bad_in};

/// The follower strategy of --strategy (grid scenarios).
fn follower_strategy(a: &SimArgs) -> anyhow::Result<Option<StrategyKind>> {
    a.strategy
        .as_deref()
        .map(|s| s.parse::<StrategyKind>().map_err(bad_from))
        .transpose()
}

pub fn run(a: SimArgs) -> anyhow::Result<()> {
    if let Some(name) = &a.print_scenario {
        return print_scenario(name);
    }
    let out = Output::plan("sim", a.out.as_deref(), a.no_out, a.force)?;
    out.make_named()?;
    let result = dispatch(&a, &out);
    out.finish(result)
}

/// `--print-scenario NAME`: the built-in scenario's TOML on stdout.
fn print_scenario(name: &str) -> anyhow::Result<()> {
    let grid = pheromone_world::scenario::BUILTIN.iter();
    let regions = pheromone_graph::agent::BUILTIN_REGIONS.iter();
    match grid.chain(regions).find(|(n, _)| *n == name) {
        Some((_, text)) => {
            print!("{text}");
            Ok(())
        }
        None => {
            let names: Vec<&str> = pheromone_world::scenario::BUILTIN
                .iter()
                .chain(pheromone_graph::agent::BUILTIN_REGIONS.iter())
                .map(|(n, _)| *n)
                .collect();
            Err(bad(format!(
                "--print-scenario {name}: not a built-in scenario (built-in: {})",
                names.join(", ")
            )))
        }
    }
}

/// The run `a` asks for: a node-graph scenario, trials, filters compared, or one run.
fn dispatch(a: &SimArgs, out: &Output) -> anyhow::Result<()> {
    if super::graph::is_regions(&a.scenario) {
        if a.record.is_some() {
            return Err(bad(format!(
                "--record: '{}' is a node-graph scenario: it has no field to record",
                a.scenario
            )));
        }
        return super::graph::run_sim(a, out);
    }
    // A name that is neither kind fails here, naming the built-in scenarios.
    let scenario = scenario_of(a)?;
    if a.localize.is_some() {
        return Err(bad(format!(
            "--localize applies to node-graph scenarios only; '{}' is a grid scenario (its robots localize already)",
            a.scenario
        )));
    }
    // From here SIGINT/SIGTERM end the run with what it has (exit status 130/143).
    super::stop::install()?;
    // `sim --merge` on one robot merges nothing (a sweep's one-robot point keeps it: its row is
    // the baseline).
    let robots = scenario.world.robots.len();
    if a.merge && robots < 2 {
        return Err(bad(format!(
            "--merge with {robots} robot(s): maps merge between robots that meet: needs at least 2 robots"
        )));
    }
    if let Some(t) = a.trials {
        return run_trials(a, &scenario, t, out);
    }
    if a.compare_filters {
        return super::sim_filters::run(a, &scenario, out);
    }
    run_scenario(a, &scenario, out)
}

/// The scenario of `a` with its flags' overrides.
fn scenario_of(a: &SimArgs) -> anyhow::Result<Scenario> {
    let mut scenario = load_scenario(&a.scenario)?;
    scenario
        .apply(&Overrides {
            seed: a.seed,
            robots: a.robots,
            duration_s: a.duration,
            strategy: follower_strategy(a)?,
            constant: a.constant,
            map: a.map.clone(),
            merge: a.merge_flag(),
            rc_m: a.rc_m,
            filter: a.filter,
            particles: a.particles,
            no_scripted_loss: a.no_scripted_loss,
            scripted_loss: a.scripted_loss,
            steer_on: a.steer,
            clients: a.clients,
        })
        .map_err(|e| bad_in(a.scenario.as_str(), e))?;
    Ok(scenario)
}

/// One run of the scenario, its summary, metrics and files.
fn run_scenario(a: &SimArgs, scenario: &Scenario, out: &Output) -> anyhow::Result<()> {
    if a.remote && scenario.antenna_robots().is_empty() {
        return Err(bad(format!(
            "--remote: scenario '{}' has no robot with an antenna follower (try trail-following)",
            scenario.name
        )));
    }
    if scenario.radio.is_some() && !a.remote {
        return Err(bad(format!(
            "scenario '{}' has [radio]: the shared air is the gateway's thin clients', run it with --remote",
            scenario.name
        )));
    }
    eprintln!(
        "sim '{}' (seed {}): {} robot(s), {:.1} s simulated, field {}×{} cells, {}",
        scenario.name,
        scenario.seed,
        scenario.world.robots.len(),
        scenario.duration_s,
        scenario.field.width,
        scenario.field.height,
        if a.single_process {
            "one process"
        } else {
            "separate processes"
        }
    );
    let record = start_record(a, scenario)?;
    let started = Instant::now();
    let (summary, rec, processes, record) = run_once(a, scenario, record)?;
    let interrupted = match &processes {
        Some(info) => info.interrupted,
        None => stop::requested().is_some(),
    };
    let wall_s = started.elapsed().as_secs_f64();
    let mut metrics = RunMetrics::new(scenario, &summary, &rec, run_mode(a), wall_s);
    metrics.interrupted = interrupted;
    if let Some(info) = processes {
        metrics.startup_s = Some(info.startup_s);
        metrics.processes = Some(info.reports);
    }
    // A file that could not be written fails the run, after its other outputs.
    let record = record.map(|totals| add_record(&mut metrics, totals));
    print_summary(&metrics);
    write_outputs(a, (scenario, out), &rec, &metrics)?;
    record?;
    if interrupted {
        return Err(Stopped::by_requested().into());
    }
    Ok(())
}

/// `--out DIR`'s files and the `--json` metrics.
fn write_outputs(
    a: &SimArgs,
    (scenario, out): (&Scenario, &Output),
    rec: &Recording,
    metrics: &RunMetrics,
) -> anyhow::Result<()> {
    if let Some(dir) = out.dir(&scenario.name, &[scenario.seed])? {
        let marks = pheromone_report::marks(scenario, rec);
        let mut files = pheromone_report::write_outputs(&dir, rec, metrics, &marks)?;
        files.extend(pheromone_report::write_plots(&dir, scenario, rec)?);
        let summary = pheromone_report::write_summary(&dir, scenario, rec, metrics, &marks)?;
        eprintln!(
            "wrote {} file(s) to {} (the result at a glance: {})",
            files.len() + 1,
            dir.display(),
            summary.display()
        );
    }
    if a.json {
        println!("{}", serde_json::to_string(metrics)?);
    }
    Ok(())
}

fn run_mode(a: &SimArgs) -> RunMode {
    if a.single_process {
        RunMode::SingleProcess
    } else if a.remote {
        RunMode::ProcessesRemote
    } else {
        RunMode::Processes
    }
}

/// `--record`: what the file holds, printed and in the metrics.
fn add_record(metrics: &mut RunMetrics, totals: Option<McapTotals>) {
    if let Some(t) = totals {
        eprintln!(
            "sim: recorded {} messages ({} frames, {} poses, {} deposits) in {}",
            t.messages,
            t.frames,
            t.poses,
            t.deposits,
            t.file.display()
        );
        metrics.record = Some(t);
    }
}

/// What one run gives: its summary, recording, processes and, with `--record`, what the file
/// holds (or why it could not be written).
type RunOutcome = (
    RunSummary,
    Recording,
    Option<ProcessRunInfo>,
    Result<Option<McapTotals>, RecordError>,
);

/// The scenario run once, in the mode of `a`, with a progress bar; SIGINT/SIGTERM end it early.
fn run_once(
    a: &SimArgs,
    scenario: &Scenario,
    mut record: Option<SimMcap>,
) -> anyhow::Result<RunOutcome> {
    let bar = progress_bar(scenario.steps());
    let stop = || stop::requested().is_some();
    let out = if a.single_process {
        let mut tick = |k: u64, _n: u64| bar.set_position(k);
        let out = run_single_process(
            scenario,
            SingleProcessOptions {
                slam: a.slam,
                progress: Some(&mut tick),
                record: record.as_mut(),
                stop: Some(&stop),
            },
        )?;
        let totals = record.map(SimMcap::finish).transpose();
        (out.0, out.1, None, totals)
    } else {
        let dt = scenario.world.dt_s;
        let mut tick = |t: f64| bar.set_position((t / dt).round() as u64);
        let (summary, rec, info) = run_processes(a, scenario, Some(&mut tick), record)?;
        let totals = Ok(info.record.clone());
        (summary, rec, Some(info), totals)
    };
    bar.finish_and_clear();
    Ok(out)
}

/// `--record FILE`: the file created (refused with exit 2 if it cannot be) and its writer
/// started.
fn start_record(a: &SimArgs, scenario: &Scenario) -> anyhow::Result<Option<SimMcap>> {
    let Some(path) = &a.record else {
        return Ok(None);
    };
    let compression = ChunkCompression::from_name(&a.record_compression)
        .ok_or_else(|| bad(format!("--record-compression {}", a.record_compression)))?;
    let file = McapRecorder::create_with(path, compression)
        .map_err(|e| bad(format!("--record {}: {}", path.display(), e)))?;
    Ok(Some(SimMcap::start(file, scenario)?))
}

fn print_summary(m: &RunMetrics) {
    let how = if m.interrupted {
        "stopped by a signal, written as far as it ran"
    } else {
        "done"
    };
    eprintln!(
        "sim '{}' {how}: {} s simulated ({} ticks) in {:.2} s wall time ({:.1}× real time); {} deposits applied, {} NaN cells",
        m.scenario,
        m.sim_time_s,
        m.ticks,
        m.wall_time_s,
        m.sim_time_per_wall_time,
        m.field.deposits_applied,
        m.field.nan_cells,
    );
    for r in &m.robots {
        let abandoned = match r.trail_abandoned_at_s {
            Some(t) => format!(", gave the trail up at {t:.1} s"),
            None => String::new(),
        };
        eprintln!(
            "  robot {} ({}): travelled {:.2} m, ends at ({:.2}, {:.2}){abandoned}",
            r.id, r.role, r.distance_travelled_m, r.true_pose[0], r.true_pose[1],
        );
    }
    if let Ok(serde_json::Value::Object(o)) = serde_json::to_value(&m.metrics) {
        for (k, v) in o {
            eprintln!("  {k}: {v}");
        }
    }
}

fn progress_bar(steps: u64) -> indicatif::ProgressBar {
    progress_bar_of(steps, "steps")
}

/// A progress bar of `len` `unit`s whose ETA counts from the first progress, not from the
/// start (a run as processes spends its first seconds starting them: indicatif's own estimate
/// then said 40 min for a 4 s run), shown once 1 % is done.
pub(super) fn progress_bar_of(len: u64, unit: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    let template = format!("{{spinner}} [{{bar:40}}] {{pos}}/{{len}} {unit} ({{eta}})");
    if let Ok(style) = indicatif::ProgressStyle::with_template(&template) {
        bar.set_style(style.with_key("eta", Eta::default()).progress_chars("=> "));
    }
    bar
}

/// The ETA of [`progress_bar_of`]: the rate since the first position above 0.
#[derive(Clone, Default)]
struct Eta {
    first: Option<(u64, Instant)>,
}

impl indicatif::style::ProgressTracker for Eta {
    fn clone_box(&self) -> Box<dyn indicatif::style::ProgressTracker> {
        Box::new(self.clone())
    }

    fn tick(&mut self, state: &indicatif::ProgressState, now: Instant) {
        if self.first.is_none() && state.pos() > 0 {
            self.first = Some((state.pos(), now));
        }
    }

    fn reset(&mut self, _: &indicatif::ProgressState, _: Instant) {
        self.first = None;
    }

    fn write(&self, state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write) {
        let len = state.len().unwrap_or(0);
        let eta = self.first.and_then(|(p0, t0)| {
            let (done, secs) = (state.pos().saturating_sub(p0), t0.elapsed().as_secs_f64());
            (done * 100 >= len && done > 0 && secs >= 0.5)
                .then(|| secs / done as f64 * len.saturating_sub(state.pos()) as f64)
        });
        let _ = match eta {
            Some(s) => write!(
                w,
                "{:#}",
                indicatif::HumanDuration(std::time::Duration::from_secs_f64(s))
            ),
            None => write!(w, "ETA …"),
        };
    }
}

// ---------------------------------------------------------------------------------------------
// Trials (paper 004's comparison)

fn run_trials(a: &SimArgs, scenario: &Scenario, trials: u32, out: &Output) -> anyhow::Result<()> {
    if trials < 2 {
        return Err(bad(format!("--trials {trials}: needs at least 2")));
    }
    if scenario.metrics.exploration.is_none() {
        return Err(bad(format!(
            "--trials: scenario '{}' has no exploration metric (try ias-ss)",
            scenario.name
        )));
    }
    let ours = follower_strategy(a)?.unwrap_or(StrategyKind::Inverse);
    let bar = progress_bar(2 * trials as u64);
    let stopped = || stop::requested().is_some();
    let run = |s: &Scenario| -> anyhow::Result<Recording> {
        let rec = if a.single_process {
            let options = SingleProcessOptions {
                slam: a.slam,
                progress: None,
                record: None,
                stop: Some(&stopped),
            };
            run_single_process(s, options)?.1
        } else {
            run_processes(a, s, None, None)?.1
        };
        if stop::requested().is_some() {
            eprintln!("sim: trials stopped: nothing written");
            return Err(Stopped::by_requested().into());
        }
        Ok(rec)
    };
    let result = match pheromone_sim::trials::run_trials(scenario, trials, ours, run, || bar.inc(1))
    {
        Ok(r) => r,
        Err(TrialsError::Run(e)) => return Err(e),
        Err(TrialsError::Scenario(e)) => return Err(bad_from(e)),
    };
    bar.finish_and_clear();
    eprintln!("{}", result.summary_line());
    let seeds: Vec<u64> = (0..u64::from(trials)).map(|i| scenario.seed + i).collect();
    if let Some(dir) = out.dir(&scenario.name, &seeds)? {
        let path = dir.join("trials.json");
        pheromone_field::outfile::write_file(
            &path,
            serde_json::to_string_pretty(&result)?.as_bytes(),
        )?;
        eprintln!("wrote {}", path.display());
    }
    if a.json {
        println!("{}", serde_json::to_string(&result)?);
    }
    Ok(())
}
