//! `pheromone graph | graph-robot`, and `pheromone sim regions | regions-skeleton | …`: paper
//! 001's node-graph signalling with area capture and conflict resolution, as processes (or in
//! one process with `--single-process`); `--trials T` pairs `--localize constant` and `rho` over
//! T seeds.

use std::path::Path;
use std::time::{Duration, Instant};

use clap::Args;
use pheromone_field::shm::create_node;
use pheromone_graph::agent::{GraphStrategy, RegionsScenario, Until, BUILTIN_REGIONS};
use pheromone_graph::compare::{compare, comparison_text, Comparison};
use pheromone_graph::localize::{DepositWeight, Localization, LocalizeConfig};
use pheromone_graph::processes::{run_graph_robot, run_graph_writer, RobotOptions, WriterOptions};
use pheromone_graph::run::{simulate_with, RunReport};
use pheromone_graph::tables::tables_text;
use pheromone_sim::metrics::RunMode;
use serde::Serialize;

use super::sim_args::SimArgs;
use super::{bad, bad_from, bad_in};

/// Whether `name` is a `regions` scenario: a built-in one, or a TOML file with a `dock`.
pub fn is_regions(name: &str) -> bool {
    if BUILTIN_REGIONS.iter().any(|(n, _)| *n == name) {
        return true;
    }
    let p = Path::new(name);
    p.is_file() && std::fs::read_to_string(p).is_ok_and(|text| RegionsScenario::looks_like(&text))
}

/// A built-in `regions` scenario or a TOML file; every problem is bad input (exit status 2).
pub fn load_regions(name: &str) -> anyhow::Result<RegionsScenario> {
    let sc = match RegionsScenario::builtin(name) {
        Some(sc) => sc,
        None => {
            let text = std::fs::read_to_string(name).map_err(|e| {
                let names: Vec<&str> = BUILTIN_REGIONS.iter().map(|(n, _)| *n).collect();
                bad_in(
                    format!(
                        "regions scenario '{name}': not a built-in one ({}) and cannot read it as a file",
                        names.join(", ")
                    ),
                    e,
                )
            })?;
            toml::from_str(&text).map_err(|e| bad_in(name, e))?
        }
    };
    sc.validate().map_err(|e| bad_in(name, e))?;
    Ok(sc)
}

/// The localization of a run's robots (`--localize`): the scenario's `[localize]` table with
/// `deposit`, and the landmark EKF of `roles` (the graph crate does not depend on it). The
/// same in one process, in every `graph-robot` process and for the run's report.
fn localization(scenario: &RegionsScenario, deposit: DepositWeight) -> Localization<'static> {
    Localization {
        config: scenario.localize_config(deposit),
        make_filter: &pheromone_roles::localizer::graph_filter::make_graph_ekf,
    }
}

fn parse_strategy(s: &str) -> anyhow::Result<GraphStrategy> {
    s.parse::<GraphStrategy>().map_err(bad_from)
}

/// Run the graph writer of a `regions` run: owns the node graph and its regions in shared
/// memory, runs the lockstep clock, applies the robots' updates (link deposits, dead ends,
/// captures, releases) in robot order and publishes an immutable snapshot per step.
///
/// Start it with N `pheromone graph-robot` processes of the same --name; it waits for all of
/// them, runs until the scenario's goal (every region served, or captured) or its max_time_s,
/// and prints the run's tables (captures, final link values, area capture matrix).
#[derive(Args, Debug)]
pub struct GraphArgs {
    /// Scenario: regions, regions-skeleton, or a TOML file (examples/scenarios/regions*.toml).
    #[arg(long, default_value = "regions")]
    pub scenario: String,
    /// Name of the graph (its services are pheromone/<NAME>/graph, …/graph-update, …/contend).
    #[arg(long, default_value = "graph")]
    pub name: String,
    /// Number of robot processes that take part (ids 1..=N).
    #[arg(long, value_parser = super::int::<usize>(1, 512), value_name = "N")]
    pub robots: usize,
    /// Strategy the robots use (recorded in the report): pheromone or shortest-path.
    #[arg(long, default_value = "pheromone")]
    pub strategy: String,
    /// Seed of the run (recorded in the report).
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// Seconds to wait for every robot to attach.
    #[arg(long, value_parser = super::secs(), default_value_t = 30.0, value_name = "SECS")]
    pub attach_timeout: f64,
    /// Seconds one step may wait for the robots before the run fails.
    #[arg(long, value_parser = super::secs(), default_value_t = 30.0, value_name = "SECS")]
    pub stall_timeout: f64,
    /// Print the report as one JSON object on stdout (the tables go to stderr either way).
    #[arg(long)]
    pub json: bool,
}

fn secs(what: &str, v: f64) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(v)
        .ok()
        .filter(|d| !d.is_zero())
        .ok_or_else(|| bad(format!("{what} {v}: must be a positive number of seconds")))
}

pub fn run_writer(a: GraphArgs) -> anyhow::Result<()> {
    pheromone_field::shm::check_name(&a.name).map_err(bad_from)?;
    let scenario = load_regions(&a.scenario)?;
    let o = WriterOptions {
        name: a.name.clone(),
        robots: a.robots,
        strategy: parse_strategy(&a.strategy)?,
        seed: a.seed.unwrap_or(scenario.seed),
        attach_timeout: secs("--attach-timeout", a.attach_timeout)?,
        stall_timeout: secs("--stall-timeout", a.stall_timeout)?,
    };
    if a.robots == 0 {
        return Err(bad("--robots 0: a run needs at least one robot"));
    }
    let node = create_node(&format!("graph-{}", a.name))?;
    let report = run_graph_writer(&node, &scenario, &o)?;
    eprint!("{}", tables_text(&report));
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    }
    Ok(())
}

/// Run one robot of a `regions` run: reads each step's graph snapshot without a copy, moves
/// along the links (eq. 8: the largest value, ties broken by a seeded draw; −1 on a link it
/// takes, −∞ on a dead end), claims the nearest region with room (eq. 9), resolves contention
/// with the other claimants by exchanging the paper's JSON message (Listing 1) over iceoryx2,
/// serves the region it won and releases it.
#[derive(Args, Debug)]
pub struct GraphRobotArgs {
    /// Scenario: regions, regions-skeleton, or a TOML file.
    #[arg(long, default_value = "regions")]
    pub scenario: String,
    /// Name of the graph to attach to.
    #[arg(long, default_value = "graph")]
    pub name: String,
    /// This robot's id (1..=N); robot k leaves the dock after (k − 1) × start_interval_s.
    #[arg(long, value_parser = super::int::<u32>(1, 512), value_name = "ID")]
    pub robot: u32,
    /// Number of robots of the run.
    #[arg(long, value_parser = super::int::<usize>(1, 512), value_name = "N")]
    pub robots: usize,
    /// pheromone (paper 001: anti-pheromone on links and region capture) or shortest-path
    /// (A* to the nearest region, conflicts resolved on arrival).
    #[arg(long, default_value = "pheromone")]
    pub strategy: String,
    /// Seed of the tie-breaking draws.
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// Seconds to wait for the other robots and for each step.
    #[arg(long, value_parser = super::secs(), default_value_t = 30.0, value_name = "SECS")]
    pub timeout: f64,
    /// Localize on landmarks with the EKF (paper 001 Algorithm 1, the scenario's `[localize]`
    /// table): this robot owns its filter and its simulated sensors, seeded per robot as in
    /// `sim --single-process`; as a region holder it matches only its region's landmarks, else
    /// only the free areas'. Its link deposits are its constant −1 (`constant`) or −1 × ρ_t of
    /// its covariance (`rho`); its summary reports the landmark comparisons and step times.
    #[arg(long, value_name = "constant|rho")]
    pub localize: Option<pheromone_graph::localize::DepositWeight>,
    /// Print this robot's summary as one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run_robot(a: GraphRobotArgs) -> anyhow::Result<()> {
    pheromone_field::shm::check_name(&a.name).map_err(bad_from)?;
    if a.robot == 0 || a.robot as usize > a.robots {
        return Err(bad(format!(
            "--robot {}: ids run from 1 to --robots ({})",
            a.robot, a.robots
        )));
    }
    let scenario = load_regions(&a.scenario)?;
    let strategy = parse_strategy(&a.strategy)?;
    let node = create_node(&format!("graph-{}-r{}", a.name, a.robot))?;
    let o = RobotOptions {
        name: a.name.clone(),
        index: a.robot as usize - 1,
        robots: a.robots,
        strategy,
        seed: a.seed.unwrap_or(scenario.seed),
        timeout: secs("--timeout", a.timeout)?,
        localization: a.localize.map(|deposit| localization(&scenario, deposit)),
    };
    let report = run_graph_robot(&node, &scenario, &o)?;
    eprintln!(
        "graph-robot R{}: {:.1} m driven, {} capture(s), {} conflict(s)",
        report.robot, report.distance_m, report.capture_count, report.conflicts
    );
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    }
    Ok(())
}

/// `pheromone sim` on a `regions` scenario: every robot count of the scenario (or --robots)
/// with both strategies (or --strategy), then the comparison of the time to the goal.
pub fn run_sim(a: &SimArgs, out: &super::out::Output) -> anyhow::Result<()> {
    refuse_grid_flags(a)?;
    let scenario = load_regions(&a.scenario)?;
    let seed = a.seed.unwrap_or(scenario.seed);
    let counts = robot_counts(a, &scenario)?;
    let strategies = match &a.strategy {
        Some(s) => vec![parse_strategy(s)?],
        None => scenario.strategies.clone(),
    };
    super::stop::install()?;
    if let Some(trials) = a.trials {
        return run_trials(a, out, &scenario, (&counts, &strategies), seed, trials);
    }
    let started = Instant::now();
    let (runs, mut text, interrupted) = run_each(a, &scenario, &counts, &strategies, seed)?;
    let comparison = compare(&runs);
    // A run for a fixed time (Sec. 6.2) has no goal to reach: nothing to compare.
    let cmp_text = if scenario.regions_sim.until == Until::Time {
        String::new()
    } else {
        comparison_text(&comparison)
    };
    eprint!("{cmp_text}");
    text += &cmp_text;
    let metrics = RegionsMetrics {
        scenario: scenario.name.clone(),
        seed,
        mode: if a.single_process {
            RunMode::SingleProcess
        } else {
            RunMode::Processes
        },
        // Stopped by Ctrl-C or SIGTERM: the runs that finished before it.
        interrupted,
        wall_time_s: started.elapsed().as_secs_f64(),
        comparison,
        runs,
    };
    if let Some(dir) = out.dir(&scenario.name, &[seed])? {
        write_sim_out(&dir, &scenario, &metrics, &text)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&metrics)?);
    }
    if interrupted {
        return Err(super::stop::Stopped::by_requested().into());
    }
    Ok(())
}

/// Refuses the `sim` flags that only grid scenarios take.
fn refuse_grid_flags(a: &SimArgs) -> anyhow::Result<()> {
    for (set, flag) in [
        (a.duration.is_some(), "--duration"),
        (a.realtime, "--realtime"),
        (a.constant, "--constant"),
        (a.slam, "--slam"),
        (a.map.is_some(), "--map"),
        (a.filter.is_some(), "--filter"),
        (a.particles.is_some(), "--particles"),
        (a.no_scripted_loss, "--no-scripted-loss"),
    ] {
        if set {
            return Err(bad(format!(
                "{flag} does not apply to the regions scenario '{}' (it has no grid robots)",
                a.scenario
            )));
        }
    }
    Ok(())
}

/// `--trials T`: every run of the scenario on seeds S … S + T − 1, each with `--localize
/// constant` and with `rho`, paired by seed (`trials` in `metrics.json`, the text in
/// `tables.txt`): the paired t of rho − constant of the time to the goal and of the mean capture
/// time.
fn run_trials(
    a: &SimArgs,
    out: &super::out::Output,
    scenario: &RegionsScenario,
    (counts, strategies): (&[usize], &[GraphStrategy]),
    seed: u64,
    trials: u32,
) -> anyhow::Result<()> {
    if a.localize.is_some() {
        return Err(bad(
            "--trials on a regions scenario runs each seed with --localize constant and with rho: leave --localize out",
        ));
    }
    let points: Vec<(usize, GraphStrategy)> = counts
        .iter()
        .flat_map(|&n| strategies.iter().map(move |&s| (n, s)))
        .collect();
    let started = Instant::now();
    let run = |n, strategy, seed, weight| -> anyhow::Result<RunReport> {
        let loc = localization(scenario, weight);
        let r = if a.single_process {
            simulate_with(scenario, strategy, n, seed, Some(&loc))?
        } else {
            run_as_processes(a, strategy, n, seed, Some(loc.config))?
        };
        match super::stop::requested() {
            Some(_) => Err(super::stop::Stopped::by_requested().into()),
            None => Ok(r),
        }
    };
    let done = |r: &RunReport| {
        let weight = r
            .localization
            .as_ref()
            .map_or("", |l| l.config.deposit.name());
        let finish = r
            .finish_s
            .map_or("not reached".into(), |t| format!("{t:.2} s"));
        eprintln!(
            "  seed {} {} robot(s) --localize {weight}: {finish}",
            r.seed, r.robots
        );
    };
    let trials = pheromone_sim::localize_trials::run_localize_trials(
        &scenario.name,
        &points,
        seed,
        trials,
        run,
        done,
    )?;
    let metrics = TrialsMetrics {
        scenario: scenario.name.clone(),
        mode: if a.single_process {
            RunMode::SingleProcess
        } else {
            RunMode::Processes
        },
        wall_time_s: started.elapsed().as_secs_f64(),
        trials,
    };
    write_trials(a, out, &metrics)
}

/// Prints the trials and writes them (`metrics.json`, `tables.txt`).
fn write_trials(
    a: &SimArgs,
    out: &super::out::Output,
    metrics: &TrialsMetrics,
) -> anyhow::Result<()> {
    let t = &metrics.trials;
    let text = t.text();
    eprint!("{text}");
    let seeds: Vec<u64> = (t.seeds[0]..=t.seeds[1]).collect();
    if let Some(dir) = out.dir(&t.scenario, &seeds)? {
        let json = serde_json::to_string_pretty(metrics)?;
        pheromone_field::outfile::write_file(&dir.join("metrics.json"), json.as_bytes())?;
        pheromone_field::outfile::write_file(&dir.join("tables.txt"), text.as_bytes())?;
        eprintln!("wrote metrics.json and tables.txt to {}", dir.display());
    }
    if a.json {
        println!("{}", serde_json::to_string(metrics)?);
    }
    Ok(())
}

/// The metrics of `sim <regions scenario> --trials` (`--json`, `metrics.json`).
#[derive(Debug, Serialize)]
struct TrialsMetrics {
    scenario: String,
    mode: RunMode,
    wall_time_s: f64,
    trials: pheromone_sim::localize_trials::LocalizeTrials,
}

/// The robot counts to run (--robots, else the scenario's), each checked.
fn robot_counts(a: &SimArgs, scenario: &RegionsScenario) -> anyhow::Result<Vec<usize>> {
    let counts = match a.robots {
        Some(n) => vec![n],
        None => scenario.robots.clone(),
    };
    if let Some(&n) = counts
        .iter()
        .find(|&&n| n == 0 || n > pheromone_graph::shm::MAX_GRAPH_ROBOTS)
    {
        return Err(bad(format!(
            "robots {n}: a regions run takes 1 to {}",
            pheromone_graph::shm::MAX_GRAPH_ROBOTS
        )));
    }
    Ok(counts)
}

/// Every run, by robot count then strategy, and their tables as text; stopped early (`true`)
/// by SIGINT or SIGTERM, with the runs that finished before it (a run in progress as processes
/// ends with its children; one in this process ends first).
fn run_each(
    a: &SimArgs,
    scenario: &RegionsScenario,
    counts: &[usize],
    strategies: &[GraphStrategy],
    seed: u64,
) -> anyhow::Result<(Vec<RunReport>, String, bool)> {
    let mut runs: Vec<RunReport> = Vec::new();
    let mut text = String::new();
    let stopped = || super::stop::requested().is_some();
    let localization = a.localize.map(|deposit| localization(scenario, deposit));
    for &n in counts {
        for &strategy in strategies {
            if stopped() {
                return Ok((runs, text, true));
            }
            let run_started = Instant::now();
            let report = if a.single_process {
                simulate_with(scenario, strategy, n, seed, localization.as_ref())?
            } else {
                let config = localization.map(|l| l.config);
                match run_as_processes(a, strategy, n, seed, config) {
                    Ok(r) => r,
                    // The children got the terminal's Ctrl-C too: whatever ended the run first.
                    Err(_) if stopped() => return Ok((runs, text, true)),
                    Err(e) => return Err(e),
                }
            };
            let t = tables_text(&report);
            eprintln!(
                "{t}  ({:.2} s wall time)\n",
                run_started.elapsed().as_secs_f64()
            );
            text += &t;
            text += "\n";
            runs.push(report);
        }
    }
    Ok((runs, text, stopped()))
}

/// The metrics of a regions run (`--json`, `metrics.json`).
#[derive(Debug, Serialize)]
struct RegionsMetrics {
    scenario: String,
    seed: u64,
    mode: RunMode,
    interrupted: bool,
    wall_time_s: f64,
    /// Per robot count, the strategies against each other (Fig. 4c).
    comparison: Vec<Comparison>,
    /// Every run, by robot count then strategy.
    runs: Vec<RunReport>,
}

/// Writes `metrics.json`, `tables.txt` and a picture of the graph per run into the out dir.
fn write_sim_out(
    dir: &Path,
    scenario: &RegionsScenario,
    metrics: &RegionsMetrics,
    text: &str,
) -> anyhow::Result<()> {
    let runs = &metrics.runs;
    let json = serde_json::to_string_pretty(metrics)?;
    pheromone_field::outfile::write_file(&dir.join("metrics.json"), json.as_bytes())?;
    pheromone_field::outfile::write_file(&dir.join("tables.txt"), text.as_bytes())?;
    let state = scenario.validate()?;
    let dock = scenario.dock_node(&state.graph)?;
    for r in runs {
        let png = dir.join(format!(
            "graph_{}_{}robots.png",
            r.strategy.name(),
            r.robots
        ));
        pheromone_report::write_graph_png(&png, &state, r, dock)?;
    }
    let summary = pheromone_report::write_graph_summary(dir, &state, runs, dock)?;
    eprintln!(
        "wrote metrics.json, tables.txt, {} picture(s) of the graph and {} to {}",
        runs.len(),
        if summary.is_some() {
            "summary.png"
        } else {
            "no summary (no run)"
        },
        dir.display()
    );
    Ok(())
}

/// One run as processes: the graph writer and one `graph-robot` per robot.
fn run_as_processes(
    a: &SimArgs,
    strategy: GraphStrategy,
    robots: usize,
    seed: u64,
    localize: Option<LocalizeConfig>,
) -> anyhow::Result<RunReport> {
    Ok(pheromone_sim::processes::run_graph_as_processes(
        &std::env::current_exe()?,
        &a.scenario,
        strategy,
        robots,
        seed,
        super::seconds("timeout", a.timeout)?,
        localize,
    )?)
}
