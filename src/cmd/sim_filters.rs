//! `pheromone sim --compare-filters`: paper 000's comparison of localization filters (Figs.
//! 13–18). The scenario runs once per filter (EKF, UKF, PF), on the same seed and without its
//! scripted loss, in the mode `sim` would use; one robot's estimation errors, deposits and σ
//! from each run become `filters.csv`, six charts and `filters.json`.

use pheromone_report::filters::{truth_spread_m, Comparison};
use pheromone_report::{FilterRun, FilterSummary};
use pheromone_roles::localizer::FilterKind;
use pheromone_sim::single::{run_single_process, SingleProcessOptions};
use pheromone_world::scenario::{Overrides, Scenario};

use super::bad;
use super::out::Output;
use super::sim_args::SimArgs;
use super::sim_run::run_processes;
use super::stop::{self, Stopped};

/// The robot compared: `--compare-robot`, or the lowest id with a depositor.
fn robot_of(a: &SimArgs, scenario: &Scenario) -> anyhow::Result<u32> {
    let ids: Vec<u32> = scenario.world.robots.iter().map(|r| r.id).collect();
    if let Some(id) = a.compare_robot {
        if !ids.contains(&id) {
            return Err(bad(format!(
                "--compare-robot {id}: scenario '{}' has robots {ids:?}",
                scenario.name
            )));
        }
        return Ok(id);
    }
    scenario
        .robots
        .iter()
        .filter(|r| r.depositor.is_some() && ids.contains(&r.id))
        .map(|r| r.id)
        .min()
        .or(ids.first().copied())
        .ok_or_else(|| {
            bad(format!(
                "--compare-filters: scenario '{}' has no robot",
                scenario.name
            ))
        })
}

/// Runs `scenario` once with `filter` and returns the robot's time series.
fn run_with(
    a: &SimArgs,
    scenario: &Scenario,
    filter: FilterKind,
    robot: u32,
) -> anyhow::Result<Vec<pheromone_sim::recording::RobotSample>> {
    let mut s = scenario.clone();
    s.apply(&Overrides {
        filter: Some(filter),
        particles: a.particles,
        no_scripted_loss: true,
        ..Overrides::default()
    })
    .map_err(|e| super::bad_in(a.scenario.as_str(), e))?;
    let stop = || stop::requested().is_some();
    let mut rec = if a.single_process {
        let options = SingleProcessOptions {
            slam: false,
            progress: None,
            record: None,
            stop: Some(&stop),
        };
        run_single_process(&s, options)?.1
    } else {
        run_processes(a, &s, None, None)?.1
    };
    if stop() {
        eprintln!("sim: --compare-filters stopped: nothing written");
        return Err(Stopped::by_requested().into());
    }
    Ok(rec.robots.remove(&robot).unwrap_or_default())
}

pub fn run(a: &SimArgs, scenario: &Scenario, output: &Output) -> anyhow::Result<()> {
    let robot = robot_of(a, scenario)?;
    eprintln!(
        "sim '{}' (seed {}) --compare-filters: robot {robot}, once with each of ekf, ukf and pf, \
         scripted loss off, {}",
        scenario.name,
        scenario.seed,
        if a.single_process {
            "one process"
        } else {
            "separate processes"
        }
    );
    let kinds = [FilterKind::Ekf, FilterKind::Ukf, FilterKind::Pf];
    let mut series = Vec::new();
    for k in kinds {
        series.push(run_with(a, scenario, k, robot)?);
    }
    let runs: Vec<FilterRun> = kinds
        .iter()
        .zip(&series)
        .map(|(k, rows)| FilterRun::of(k.name(), rows))
        .collect();
    if runs.iter().any(|r| r.steps.is_empty()) {
        return Err(bad(format!(
            "--compare-filters: robot {robot} of '{}' has no localizer estimate to compare",
            scenario.name
        )));
    }
    let out = Comparison {
        scenario: scenario.name.clone(),
        seed: scenario.seed,
        robot,
        particles: a.particles,
        truth_spread_m: truth_spread_m(&series),
        filters: runs.iter().map(FilterSummary::of).collect(),
    };
    for f in &out.filters {
        eprintln!("{}", f.line());
    }
    if let Some(dir) = output.dir(&scenario.name, &[scenario.seed])? {
        let mut files = pheromone_report::write_filter_comparison(&dir, robot, &runs)?;
        let path = dir.join("filters.json");
        let json = serde_json::to_string_pretty(&out)? + "\n";
        pheromone_field::outfile::write_file(&path, json.as_bytes())?;
        files.push(path);
        eprintln!("wrote {} file(s) to {}", files.len(), dir.display());
    }
    if a.json {
        println!("{}", serde_json::to_string(&out)?);
    }
    Ok(())
}
