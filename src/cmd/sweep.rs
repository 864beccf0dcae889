//! `pheromone sweep`: paper 004's grid of experiments (`pheromone_sim::sweep`) on all cores,
//! with a progress bar, a summary on stderr and the files of `pheromone_report::write_sweep`.

use std::path::PathBuf;

use clap::Args;
use pheromone_roles::follower::StrategyKind;
use pheromone_roles::mapper::MergeRule;
use pheromone_sim::sweep::{
    integrations, parse_merge_idle, parse_merge_rules, parse_rc_m, parse_robots, parse_steer,
    parse_strategies, run_sweep_shard, Figure, Shard, SweepGrid, SweepResult,
};
use pheromone_sim::sweep_shard::{sweep_id, ShardRecord};
use pheromone_world::scenario::Scenario;

use super::out::Output;
use super::roles::load_scenario;
use super::sweep_trail::{is_trail, TrailArgs};
use super::{bad, bad_from};

/// Run paper 004's grid of experiments (exploration with and without map merging), or paper 002's
/// parameter study of trail following.
///
/// Paper 002 (`pheromone sweep trail-following`, a scenario with [[metrics.paths]] and antenna
/// robots): the robots' settings varied one at a time about the scenario's own, --omega-gain,
/// --wheel-base, --fov, --splay, --speed, --normalize (none given: the study of docs/gateway.md,
/// 23 settings); each value on seeds 1..=--trials, each run as separate processes (the default;
/// --single-process: in this one, the same figures). The scenario's own value of each setting is
/// always a point (run once). Writes sweep.csv (param, value, shipped, seed, path,
/// mean_path_error_m, turning_share: a row per run and path), sweep.json (the runs, the points
/// with mean ± sd, the scenario's values) and sweep_trail.png (a panel per setting: mean path
/// error ± sd against its value, a line per path, the scenario's value dotted). One run at a
/// time; the mapping flags (--rc-m, --merge, --steer, --duration, --shard, --jobs, …) are
/// refused. Time (debug build, 2 cores): a simulation takes ~0.7–1.2 s as processes, ~15 ms in
/// one process (the whole study at --trials 8: 220 s and 3 s). CI-sized: `pheromone sweep
/// trail-following --trials 2 --single-process`.
///
/// Paper 004 (`pheromone sweep ias-ss`):
///
/// Every combination of --robots × --rc-m × merge {on, off} × --strategies × --steer runs
/// --trials times (seeds 1..=T), each run the single-process simulation of the scenario
/// (deterministic for a seed) with mapping on. Runs go to --jobs worker threads from one queue,
/// the largest first (`--shard K/N`: only the K-th of N slices, see below). Per run it records `exploration_known` (sectors mapped by the robot's
/// sensor or merged into its map), `exploration_merged` (visited or received through a merge:
/// the paper's count) and `exploration` (visited), team and mean per robot; per point the mean
/// ± sd of each over the trials; at equal points it compares merge on vs off and inverse vs
/// uniform on --figure's mean per robot (Welch's t and its df; the paired t, the seeds match).
///
/// Steering (--steer) is a dimension like the others: `shared` steers every robot on the
/// shared field (every robot's deposits, at any range), `own-map` on its own merged map (paper
/// 004's Algorithm 2); each is its own point (CSV column steer_on, a chart line of its own).
///
/// Writes into --out: sweep.csv (one row per run: what it computed, the same bytes on any host
/// and at any --jobs), sweep_times.csv (each run's wall time), sweep.json (points and comparisons),
/// sweep_paper.md (each of the paper's values, docs/paper/seed004.csv, beside ours),
/// sweep_robots.png (exploration vs robots, with and without merging, the paper's values as
/// black crosses) and, when --rc-m lists two radii or more, sweep_rc.png (exploration vs R_C,
/// the paper's peak as a dotted line; one radius makes no line, so no chart), mean ± sd error
/// bars. A progress bar shows on a terminal only.
///
/// Paper 004's Table 9: `pheromone sweep ias-ss-open --robots 5 --rc-m 4,8,16,24,32,40 --merge
/// --steer own-map,shared --figure merged` (30 m × 20 m, no inner walls, random starts in the
/// top-left 5 m × 5 m, 1000 iterations, 10 seeds).
///
/// On a cluster: `--shard K/N` runs every N-th run of the plan from the K-th (K from 0 to N-1;
/// every run is in exactly one shard) and writes the shard's sweep.csv rows and shard.json
/// (which shard of which sweep: a hash of the scenario and every flag but --shard, --jobs and
/// --out) into --out [default: pheromone-out/sweep-<SCENARIO>-shard-K-of-N]; then `pheromone
/// sweep merge DIR… --out DIR` writes the files of the unsharded sweep from one directory per
/// shard. A Slurm array: `sbatch --array=0-3` with `--shard $SLURM_ARRAY_TASK_ID/4`; a Kubernetes
/// Indexed Job: `--shard $JOB_COMPLETION_INDEX/4` (examples/slurm/, docs/mapping.md).
///
/// Time (measured on a 2-core machine, release build): one 1000 s run takes 0.4 s (1 robot) to
/// 3.4 s (8 robots), so the default sweep (robots 1,2,4,6,8 × merge on/off × 10 trials = 100
/// runs of the paper's 1000 iterations) takes about a minute and a half on 2 cores; R_C and
/// strategy lists multiply it. Without merging R_C changes nothing: those points run once, at
/// the first R_C.
#[derive(Args, Debug)]
#[command(args_conflicts_with_subcommands = true)]
pub struct SweepArgs {
    #[command(subcommand)]
    pub command: Option<SweepCommand>,
    /// Scenario: a built-in name or a TOML file; it needs [metrics.exploration] (ias-ss), or
    /// [[metrics.paths]] and antenna robots for the trail study (trail-following).
    #[arg(default_value = "ias-ss")]
    pub scenario: String,
    /// Robot counts, comma-separated (each ≥ 1, at most the robots the scenario places).
    #[arg(
        long,
        value_name = "LIST",
        default_value = "1,2,4,6,8",
        allow_hyphen_values = true
    )]
    pub robots: String,
    /// Communication radii R_C (m), comma-separated, each > 0 [default: the scenario's
    /// [mapping] rc_m, 8 m in ias-ss].
    #[arg(long = "rc-m", value_name = "LIST", allow_hyphen_values = true)]
    pub rc_m: Option<String>,
    /// Only runs with map merging (exchanges at rendezvous).
    #[arg(long, conflicts_with = "no_merge")]
    pub merge: bool,
    /// Only runs without merging (each robot knows what it mapped itself).
    #[arg(long)]
    pub no_merge: bool,
    /// Exploring strategies, comma-separated: inverse (IAS-SS), uniform.
    #[arg(
        long,
        value_name = "LIST",
        default_value = "inverse",
        allow_hyphen_values = true
    )]
    pub strategies: String,
    /// Also the uniform strategy (the same as --strategies inverse,uniform).
    #[arg(long, conflicts_with = "strategies")]
    pub uniform: bool,
    /// What the robots steer on, comma-separated: own-map (each robot's own merged map, paper
    /// 004's Algorithm 2), shared (the shared field: every robot's deposits at any range)
    /// [default: the scenario's [mapping] steer_on: shared in ias-ss, own-map in ias-ss-open].
    #[arg(long, value_name = "LIST", allow_hyphen_values = true)]
    pub steer: Option<String>,
    /// Paper 004's ablation: how merges combine two maps, comma-separated: average (paper
    /// 004's mean), max (the larger occupancy and pheromone), adopt-unknown [default: the
    /// scenario's [mapping] merge_rule, average]. Each is a point (and chart line) of its own.
    #[arg(long = "merge-rule", value_name = "LIST", allow_hyphen_values = true)]
    pub merge_rule: Option<String>,
    /// Paper 004's ablation, the cost of an integration: iterations a robot stands still after
    /// each merge, comma-separated (e.g. 0,10,50) [default: the scenario's [mapping]
    /// merge_idle_iterations, 0]. Combined with every --merge-rule.
    #[arg(long = "merge-idle", value_name = "LIST", allow_hyphen_values = true)]
    pub merge_idle: Option<String>,
    /// The figure compared and charted: known (mapped or merged into the map), merged (visited
    /// or received through a merge: the paper's count) or visited. The CSV has all three.
    #[arg(long, value_name = "FIGURE", default_value = "known")]
    pub figure: Figure,
    /// Trials per point (seeds 1..=T).
    #[arg(long, value_parser = super::int::<u32>(1, 100_000), value_name = "T", default_value_t = 10)]
    pub trials: u32,
    /// Simulated seconds per run (one IAS-SS iteration a second: the paper's 1000 iterations).
    /// (`--duration-s`, its old name, is taken too.)
    /// [default: 1000; not for the trail study, which runs the scenario's duration]
    #[arg(long = "duration", alias = "duration-s", value_parser = super::secs(), value_name = "SECS")]
    pub duration_s: Option<f64>,
    /// Worker threads [default: the available parallelism].
    #[arg(long, value_parser = super::int::<usize>(1, 1024), value_name = "N")]
    pub jobs: Option<usize>,
    /// Directory for the files and run.json, which must be empty unless --force [default: a
    /// new pheromone-out/sweep-<SCENARIO>/<UTC time>-<tag>/ per sweep (with --shard:
    /// pheromone-out/sweep-<SCENARIO>-shard-K-of-N/<UTC time>-<tag>/); `latest` links to the
    /// newest].
    #[arg(long, value_name = "DIR", value_parser = super::check::out_dir())]
    pub out: Option<PathBuf>,
    /// Write into a non-empty --out DIR (a re-run shard replacing its directory's files).
    #[arg(long, requires = "out")]
    pub force: bool,
    /// Run only the K-th of N slices of the sweep's runs (every N-th run of the plan from the
    /// K-th; K from 0 to N-1, as $SLURM_ARRAY_TASK_ID with `sbatch --array=0-(N-1)` or
    /// $JOB_COMPLETION_INDEX in a Kubernetes Indexed Job) and write sweep.csv and shard.json
    /// for `pheromone sweep merge`.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    pub shard: Option<Shard>,
    /// Print sweep.json on stdout as well (with --shard: shard.json).
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub trail: TrailArgs,
}

fn parse_shard(s: &str) -> Result<Shard, String> {
    s.parse()
}

#[derive(clap::Subcommand, Debug)]
pub enum SweepCommand {
    Merge(MergeArgs),
}

/// Join the shards of one sweep (`pheromone sweep … --shard K/N`) into the files the unsharded
/// sweep writes: sweep.csv (the same rows in the same order, byte for byte), sweep_times.csv,
/// sweep.json, sweep_paper.md and the charts.
///
/// Give one directory per shard, every K from 0 to N-1 once. A missing shard, a shard given
/// twice (the same directory twice, or a re-run shard in a second directory beside the first:
/// re-run a shard into its own directory, which it replaces) or shards of different sweeps (another
/// scenario, another flag) exit with status 2 naming them. In sweep.json, `jobs` is the sum
/// of the shards' threads and `wall_s` the longest shard's; sweep_times.csv has each run's
/// wall time as its shard measured it.
#[derive(Args, Debug)]
pub struct MergeArgs {
    /// The shards' --out directories.
    #[arg(required = true, value_name = "DIR")]
    pub dirs: Vec<PathBuf>,
    /// Directory for the sweep's files and run.json, which must be empty unless --force.
    #[arg(long, value_name = "DIR", value_parser = super::check::out_dir())]
    pub out: PathBuf,
    /// Write into a non-empty --out DIR.
    #[arg(long)]
    pub force: bool,
    /// Print sweep.json on stdout as well.
    #[arg(long)]
    pub json: bool,
}

/// The grid of `a`, every list checked before the scenario is loaded; `--merge-rule` and
/// `--merge-idle` are combined with the scenario's settings by [`with_integration`].
fn grid(a: &SweepArgs) -> anyhow::Result<(SweepGrid, Vec<MergeRule>, Vec<u32>)> {
    let duration_s = a.duration_s.unwrap_or(1000.0);
    if !(duration_s.is_finite() && duration_s > 0.0) {
        return Err(bad(format!(
            "--duration {duration_s}: must be a number of seconds > 0"
        )));
    }
    if a.trials == 0 {
        return Err(bad("--trials 0: needs at least 1 trial"));
    }
    let strategies = if a.uniform {
        vec![StrategyKind::Inverse, StrategyKind::Uniform]
    } else {
        parse_strategies(&a.strategies).map_err(bad_from)?
    };
    let rules = match &a.merge_rule {
        Some(t) => parse_merge_rules(t).map_err(bad_from)?,
        None => Vec::new(),
    };
    let idle = match &a.merge_idle {
        Some(t) => parse_merge_idle(t).map_err(bad_from)?,
        None => Vec::new(),
    };
    let grid = SweepGrid {
        robots: parse_robots(&a.robots).map_err(bad_from)?,
        rc_m: match &a.rc_m {
            Some(t) => parse_rc_m(t).map_err(bad_from)?,
            None => Vec::new(),
        },
        merge: match (a.merge, a.no_merge) {
            (true, _) => vec![true],
            (_, true) => vec![false],
            _ => vec![true, false],
        },
        strategies,
        steer: match &a.steer {
            Some(t) => parse_steer(t).map_err(bad_from)?,
            None => Vec::new(),
        },
        integration: Vec::new(),
        trials: a.trials,
        duration_s,
        figure: a.figure,
    };
    Ok((grid, rules, idle))
}

/// `grid` with the merge variants of `rules` × `idle` (the scenario's where a list is empty).
fn with_integration(
    grid: SweepGrid,
    base: &Scenario,
    (rules, idle): (&[MergeRule], &[u32]),
) -> SweepGrid {
    SweepGrid {
        integration: integrations(base, rules, idle),
        ..grid
    }
}

pub fn run(a: SweepArgs) -> anyhow::Result<()> {
    if let Some(SweepCommand::Merge(m)) = &a.command {
        let out = Output::plan("sweep", Some(&m.out), false, m.force)?;
        let result = merge(m, &out);
        return out.finish(result);
    }
    let out = Output::plan("sweep", a.out.as_deref(), false, a.force)?;
    let result = sweep(&a, &out);
    out.finish(result)
}

/// The sweep (or its shard) run and written.
fn sweep(a: &SweepArgs, out: &Output) -> anyhow::Result<()> {
    // Every list checked before the scenario is loaded (an error names its flag).
    let (grid, rules, idle) = grid(a)?;
    a.trail.study()?;
    let base = load_scenario(&a.scenario)?;
    if is_trail(&base) {
        refuse_mapping_flags(a)?;
        return super::sweep_trail::sweep(&a.trail, a.trials, a.json, &base, out);
    }
    if a.trail.any() {
        return Err(bad(format!(
            "--omega-gain, --wheel-base, --fov, --splay, --speed, --normalize and \
             --single-process are for a trail study (a scenario with [[metrics.paths]], \
             trail-following), not '{}'",
            base.name
        )));
    }
    let grid = with_integration(grid, &base, (&rules, &idle));
    let jobs = match a.jobs {
        Some(0) => return Err(bad("--jobs 0: needs at least 1 worker")),
        Some(n) => n,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let total = pheromone_sim::sweep::plan(&base, &grid)
        .map_err(bad_from)?
        .len();
    let shard = a.shard.unwrap_or(Shard::WHOLE);
    let runs = shard.indices(total).len();
    let of = a
        .shard
        .map_or(String::new(), |k| format!(" (shard {k} of {total} runs)"));
    eprintln!(
        "sweep '{}': {runs} run(s){of} of {} s on {jobs} thread(s)",
        base.name, grid.duration_s
    );
    let result = with_bar(runs, &|progress| {
        run_sweep_shard(&base, &grid, shard, jobs, progress)
    })?;
    let seeds: Vec<u64> = (1..=u64::from(grid.trials)).collect();
    let Some(shard) = a.shard else {
        print_summary(&result);
        let dir = out.dir_in(&format!("sweep-{}", base.name), &base.name, &seeds)?;
        return write_outputs(&dir.unwrap_or_default(), &result, a.json);
    };
    let record = ShardRecord::new(sweep_id(&base, &grid), shard, total, &result);
    let name = format!(
        "sweep-{}-shard-{}-of-{}",
        base.name, shard.index, shard.count
    );
    let dir = out.dir_in(&name, &base.name, &seeds)?.unwrap_or_default();
    let files = pheromone_report::write_shard(&dir, &result, &record)?;
    eprintln!(
        "shard {shard} of sweep {} done: {} run(s) in {:.1} s; wrote {} file(s) to {}",
        record.sweep,
        result.runs.len(),
        result.wall_s,
        files.len(),
        dir.display()
    );
    if a.json {
        println!("{}", serde_json::to_string(&record)?);
    }
    Ok(())
}

/// What a sweep calls after each run: (runs done, runs in all).
type Progress<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// `run` with a progress bar of `runs` runs (drawn on a terminal only).
fn with_bar(
    runs: usize,
    run: &dyn Fn(Progress<'_>) -> Result<SweepResult, pheromone_sim::sweep::SweepError>,
) -> anyhow::Result<SweepResult> {
    let bar = super::sim::progress_bar_of(runs as u64, "runs");
    let result = run(&|done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    Ok(result)
}

/// The sweep's files (`pheromone_report::write_sweep`) and what they say on stderr.
fn write_outputs(dir: &std::path::Path, result: &SweepResult, json: bool) -> anyhow::Result<()> {
    let paper = pheromone_sim::paper::seed004()?;
    eprint!("{}", pheromone_report::paper_table(result, &paper));
    let files = pheromone_report::write_sweep(dir, result, &paper)?;
    eprintln!("wrote {} file(s) to {}", files.len(), dir.display());
    if let [rc_m] = pheromone_report::rc_values(result)[..] {
        eprintln!("no sweep_rc.png: the sweep has one R_C ({rc_m} m); give --rc-m two or more");
    }
    if json {
        println!("{}", serde_json::to_string(result)?);
    }
    Ok(())
}

/// `pheromone sweep merge`: the shards read back, checked and joined.
fn merge(m: &MergeArgs, out: &Output) -> anyhow::Result<()> {
    let shards = m
        .dirs
        .iter()
        .map(|d| pheromone_report::read_shard(d).map_err(bad_from))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let (sweep, count) = (shards[0].record.sweep.clone(), shards[0].record.shard.count);
    let result = pheromone_sim::sweep_shard::merge(shards).map_err(bad_from)?;
    eprintln!(
        "merged {count} shard(s) of sweep {sweep}: {} run(s) of '{}'",
        result.runs.len(),
        result.scenario
    );
    print_summary(&result);
    let seeds: Vec<u64> = (1..=u64::from(result.trials)).collect();
    let dir = out.dir(&result.scenario, &seeds)?.unwrap_or_default();
    write_outputs(&dir, &result, m.json)
}

fn print_summary(r: &SweepResult) {
    eprintln!(
        "sweep '{}' done: {} run(s) in {:.1} s wall time on {} thread(s)",
        r.scenario,
        r.runs.len(),
        r.wall_s,
        r.jobs
    );
    for p in &r.points {
        eprintln!(
            "  {}: known {:.3} ± {:.3} (team {:.3} ± {:.3}), merged {:.3} ± {:.3}, visited {:.3} ± {:.3}",
            p.key,
            p.known_mean.mean,
            p.known_mean.sd,
            p.known_team.mean,
            p.known_team.sd,
            p.merged_mean.mean,
            p.merged_mean.sd,
            p.visited_mean.mean,
            p.visited_mean.sd
        );
    }
    for c in &r.comparisons {
        let t = |x: Option<pheromone_sim::sweep_stats::TTest>| {
            x.map_or("undefined".to_string(), |x| {
                format!("{:.2} (df {:.1})", x.t, x.df)
            })
        };
        eprintln!(
            "  {} at {} ({}): {:.3} vs {:.3}, Welch t = {}, paired t = {}",
            c.kind,
            c.a,
            r.figure.name(),
            c.mean_a,
            c.mean_b,
            t(c.welch),
            t(c.paired)
        );
    }
}

/// The mapping sweep's flags a trail study refuses (named in the error).
fn refuse_mapping_flags(a: &SweepArgs) -> anyhow::Result<()> {
    let given = [
        ("--rc-m", a.rc_m.is_some()),
        ("--merge", a.merge),
        ("--no-merge", a.no_merge),
        ("--uniform", a.uniform),
        ("--steer", a.steer.is_some()),
        ("--merge-rule", a.merge_rule.is_some()),
        ("--merge-idle", a.merge_idle.is_some()),
        ("--duration", a.duration_s.is_some()),
        ("--shard", a.shard.is_some()),
        ("--jobs", a.jobs.is_some()),
    ];
    match given.iter().find(|(_, g)| *g) {
        Some((flag, _)) => Err(bad(format!(
            "{flag}: not for the trail study of '{}' (its flags: --omega-gain, --wheel-base, \
             --fov, --splay, --speed, --normalize, --trials, --single-process)",
            a.scenario
        ))),
        None => Ok(()),
    }
}
