//! The cost of a bigger swarm (issue 52 part 3, `pheromone bench --only scale`): one scenario,
//! `ias-ss` (seed 004's six rooms) with N robots, run by `pheromone sim` as separate processes
//! and with `--single-process` at each N of a list (8 … 256), each run a child of this process
//! watched from `/proc` ([`crate::scale_probe`]). Per run: start-up (the sim's `startup_s`:
//! first process started → first lockstep frame; for `--single-process` the child's whole wall
//! time less its run), wall time per simulated second after start-up (the stepping and the
//! shutdown), peak resident memory of all its processes (RSS summed, and PSS, which counts a
//! page shared by k processes as 1/k in each), the `/dev/shm` bytes they map, the processes and
//! the run's iceoryx2 services; and for each figure the growth exponent b of `figure ∝ robots^b`
//! (least squares on the logarithms). A run that fails or is refused is a row with its error,
//! never a hang: each run has a deadline, after which it is killed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use pheromone_world::scenario::Scenario;
use serde::Serialize;

use crate::scale_probe::Sampler;
use crate::BenchError;
use pheromone_supervisor::{ChildSpec, Supervisor};

/// The robot counts of a full run.
pub const ROBOTS: [usize; 6] = [8, 16, 32, 64, 128, 256];

/// What to run (`pheromone bench --only scale --scale-robots … --scale-chart …`).
#[derive(Debug, Clone, Default)]
pub struct ScaleOptions {
    /// The robot counts, ascending; empty: the mode's ([`ScaleOptions::sizes`]).
    pub robots: Vec<usize>,
    /// Simulated seconds of each run; `None`: the mode's.
    pub duration_s: Option<f64>,
    /// Where the scale chart goes (`None`: none is drawn).
    pub chart: Option<PathBuf>,
}

impl ScaleOptions {
    /// The robot counts and simulated seconds of a run in `mode`: all of [`ROBOTS`] for 10 s
    /// (full), 8 and 16 for 5 s (quick), 2 and 4 for 1 s (smoke); the options' own first.
    pub fn sizes(&self, mode: crate::Mode) -> (Vec<usize>, f64) {
        let (robots, duration_s): (&[usize], f64) = match mode {
            crate::Mode::Full => (&ROBOTS, 10.0),
            crate::Mode::Quick => (&ROBOTS[..2], 5.0),
            crate::Mode::Smoke => (&[2, 4], 1.0),
        };
        let robots = match self.robots.is_empty() {
            true => robots.to_vec(),
            false => self.robots.clone(),
        };
        (robots, self.duration_s.unwrap_or(duration_s))
    }
}

/// How a run was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RunMode {
    Processes,
    SingleProcess,
}

/// One run at one size.
#[derive(Debug, Clone, Serialize)]
pub struct ScaleRow {
    pub robots: usize,
    pub mode: RunMode,
    /// First process started → first lockstep frame (processes); the child's wall time less
    /// its run (one process: start, scenario, field).
    pub startup_s: f64,
    /// The child's whole wall time (spawned → exited).
    pub total_s: f64,
    /// (wall time − start-up) / simulated time: the stepping and the shutdown.
    pub wall_per_sim_s: f64,
    pub sim_time_s: f64,
    /// Peak of the summed resident memory of the run's processes.
    pub peak_rss_bytes: u64,
    /// Peak of their summed proportional set sizes (shared pages divided).
    pub peak_pss_bytes: u64,
    /// Peak of the `/dev/shm` bytes they map (allocated, each file once).
    pub shm_bytes: u64,
    /// Peak number of processes (the `sim` itself counted).
    pub processes: usize,
    /// Peak number of the run's iceoryx2 services.
    pub services: usize,
    /// Samples taken from `/proc`.
    pub samples: u64,
    /// Why the run failed or was refused (exit status and the end of its stderr).
    pub error: Option<String>,
}

/// A figure's growth: `figure ∝ robots^exponent` fitted over the sizes that gave a value.
#[derive(Debug, Clone, Serialize)]
pub struct Growth {
    pub exponent: f64,
    /// The sizes fitted.
    pub points: usize,
}

/// The `scale` section.
#[derive(Debug, Clone, Serialize)]
pub struct ScaleReport {
    pub scenario: &'static str,
    pub duration_s: f64,
    /// `debug` or `release`: the build the runs were made with (this binary's).
    pub build: &'static str,
    pub rows: Vec<ScaleRow>,
    /// Keyed `"<mode>/<figure>"`, e.g. `"processes/startup_s"`.
    pub growth: BTreeMap<String, Growth>,
    /// The chart written, if any.
    pub chart: Option<PathBuf>,
}

/// The figures fitted and charted, with their keys.
pub const FIGURES: [&str; 7] = [
    "startup_s",
    "wall_per_sim_s",
    "peak_rss_bytes",
    "peak_pss_bytes",
    "shm_bytes",
    "processes",
    "services",
];

impl ScaleRow {
    /// The figure `key` of [`FIGURES`].
    pub fn figure(&self, key: &str) -> f64 {
        match key {
            "startup_s" => self.startup_s,
            "wall_per_sim_s" => self.wall_per_sim_s,
            "peak_rss_bytes" => self.peak_rss_bytes as f64,
            "peak_pss_bytes" => self.peak_pss_bytes as f64,
            "shm_bytes" => self.shm_bytes as f64,
            "processes" => self.processes as f64,
            "services" => self.services as f64,
            _ => f64::NAN,
        }
    }
}

/// `ias-ss` with `n` robots: robot 0's roles for every robot (each follower its own seed, the
/// robot's id), started on a grid of 384 places 1 m apart inside the six rooms, spread.
pub fn swarm(n: usize, duration_s: f64) -> Result<Scenario, BenchError> {
    let scenario_err = |e: pheromone_world::scenario::ScenarioError| {
        BenchError::Peer(format!("scale: scenario ias-ss with {n} robots: {e}"))
    };
    let mut s = Scenario::load("ias-ss").map_err(scenario_err)?;
    let template_world = s.world.robots[0].clone();
    let template_roles = s.robots[0].clone();
    let room_x = |i: usize| 1.5 + (i % 8) as f64 + 10.0 * (i / 8) as f64;
    let room_y = |j: usize| 1.5 + (j % 8) as f64 + 10.0 * (j / 8) as f64;
    let places: Vec<(f64, f64)> = (0..16)
        .flat_map(|j| (0..24).map(move |i| (room_x(i), room_y(j))))
        .collect();
    s.world.robots = (0..n)
        .map(|i| {
            let (x_m, y_m) = places[(i * 97) % places.len()];
            let mut r = template_world.clone();
            r.id = i as u32;
            r.start.x_m = x_m;
            r.start.y_m = y_m;
            r.start.theta_rad = (i as f64 * 0.7) % std::f64::consts::TAU;
            r
        })
        .collect();
    s.robots = (0..n)
        .map(|i| {
            let mut r = template_roles.clone();
            r.id = i as u32;
            if let Some(f) = r.follower.as_mut() {
                f.seed = i as u64;
            }
            r
        })
        .collect();
    s.active_robots = None;
    s.snapshots_s.clear();
    s.duration_s = duration_s;
    s.validate().map_err(scenario_err)?;
    Ok(s)
}

/// The `scale` section of a bench run: `None` unless `--only` names it. Runs after the bench
/// has unpinned itself: the sims' children run on every core.
pub(crate) fn section(
    opts: &crate::Options,
    say: &mut dyn FnMut(&str),
) -> Result<Option<ScaleReport>, BenchError> {
    match opts.only.contains(&crate::Section::Scale) {
        true => measure(&opts.scale, opts.mode, &opts.launcher.program, say).map(Some),
        false => Ok(None),
    }
}

/// Runs every size of `o` in `mode` with `program` (`pheromone`), as processes and in one
/// process, and draws the chart (progress through `say`).
pub fn measure(
    o: &ScaleOptions,
    mode: crate::Mode,
    program: &Path,
    say: &mut dyn FnMut(&str),
) -> Result<ScaleReport, BenchError> {
    let (robots, duration_s) = o.sizes(mode);
    let dir = tempfile::Builder::new()
        .prefix("pheromone-bench-scale-")
        .tempdir()
        .map_err(|source| BenchError::Io {
            what: "a temporary directory for the scale scenarios".into(),
            source,
        })?;
    let mut rows = Vec::new();
    for &n in &robots {
        let path = dir.path().join(format!("swarm{n}.toml"));
        let text = swarm(n, duration_s)?
            .to_toml()
            .map_err(|e| BenchError::Peer(format!("scale: {e}")))?;
        std::fs::write(&path, text).map_err(|source| BenchError::Io {
            what: path.display().to_string(),
            source,
        })?;
        for how in [RunMode::Processes, RunMode::SingleProcess] {
            say(&format!("scale: {n} robots, {how:?}, {duration_s} s"));
            let row = run_one(program, &path, n, how, duration_s)?;
            match &row.error {
                Some(e) => say(&format!("scale: {n} robots, {how:?} failed: {e}")),
                None => say(&format!(
                    "scale: {n} robots, {how:?}: start-up {:.2} s, {:.3} s per simulated s, \
                     {} processes, {} services, RSS {:.0} MiB, PSS {:.0} MiB, /dev/shm {:.0} MiB",
                    row.startup_s,
                    row.wall_per_sim_s,
                    row.processes,
                    row.services,
                    row.peak_rss_bytes as f64 / 1048576.0,
                    row.peak_pss_bytes as f64 / 1048576.0,
                    row.shm_bytes as f64 / 1048576.0
                )),
            }
            rows.push(row);
        }
    }
    let growth = growth(&rows);
    let mut report = ScaleReport {
        scenario: "ias-ss",
        duration_s,
        build: if cfg!(debug_assertions) {
            "debug"
        } else {
            "release"
        },
        rows,
        growth,
        chart: None,
    };
    if let Some(path) = &o.chart {
        chart(path, &report)?;
        report.chart = Some(path.clone());
    }
    Ok(report)
}

/// The chart: a log-log panel per figure, processes beside one process, each line labelled
/// with its growth exponent.
fn chart(path: &Path, r: &ScaleReport) -> Result<(), BenchError> {
    let titles = [
        ("startup_s", "start-up (s)", 1.0),
        ("wall_per_sim_s", "wall time per simulated second (s)", 1.0),
        ("peak_pss_bytes", "memory, PSS summed (MiB)", 1048576.0),
        ("peak_rss_bytes", "memory, RSS summed (MiB)", 1048576.0),
        ("shm_bytes", "/dev/shm mapped (MiB)", 1048576.0),
        ("services", "iceoryx2 services", 1.0),
    ];
    let panels: Vec<pheromone_report::LogLogPanel> = titles
        .iter()
        .map(|&(key, title, unit)| pheromone_report::LogLogPanel {
            title: title.to_string(),
            series: [RunMode::Processes, RunMode::SingleProcess]
                .into_iter()
                .map(|how| {
                    let name = mode_name(how);
                    let b = r
                        .growth
                        .get(&format!("{name}/{key}"))
                        .map_or("-".to_string(), |g| format!("{:.2}", g.exponent));
                    pheromone_report::LogLogSeries {
                        label: format!("{name} (b = {b})"),
                        points: r
                            .rows
                            .iter()
                            .filter(|x| x.mode == how && x.error.is_none())
                            .map(|x| (x.robots as f64, x.figure(key) / unit))
                            .collect(),
                    }
                })
                .collect(),
        })
        .collect();
    let subtitle = format!(
        "'{}' with N robots, {} simulated s per run, {} build, {} cores; figure ∝ N^b",
        r.scenario,
        r.duration_s,
        r.build,
        crate::machine::cores()
    );
    pheromone_report::write_log_log_panels(
        path,
        "The cost of a bigger swarm: pheromone sim as processes and in one process",
        &subtitle,
        "robots",
        &panels,
        3,
    )
    .map_err(|e| BenchError::Peer(format!("scale chart: {e}")))
}

fn mode_name(how: RunMode) -> &'static str {
    match how {
        RunMode::Processes => "processes",
        RunMode::SingleProcess => "single-process",
    }
}

/// How long a run of `n` robots may take before it is killed: the sim's own limits (10 s +
/// 0.5 s per process to join, 30 s for a step) and a generous stepping allowance.
fn deadline(n: usize, duration_s: f64) -> Duration {
    Duration::from_secs_f64(120.0 + 3.0 * n as f64 + 20.0 * duration_s)
}

/// One `pheromone sim` child under a [`Supervisor`], sampled every 100 ms (memory and services
/// every 500 ms after the first second; a run in one process every 2 ms): between samples this waits for the child's
/// exit, so a run is over when it ends, not at the next sample.
fn run_one(
    program: &Path,
    scenario: &Path,
    n: usize,
    mode: RunMode,
    duration_s: f64,
) -> Result<ScaleRow, BenchError> {
    let mut args: Vec<String> = vec!["sim".into(), scenario.display().to_string()];
    args.extend(["--no-out", "--json", "--duration"].map(String::from));
    args.push(duration_s.to_string());
    if mode == RunMode::SingleProcess {
        args.push("--single-process".into());
    }
    let mut sup = Supervisor::new(program);
    let started = Instant::now();
    let id = sup.spawn(ChildSpec::new("sim", None, args))?;
    let pid = sup.pid(id) as i32;
    let tag = (mode == RunMode::Processes).then(|| format!("sim{pid}x0"));
    let mut sampler = Sampler::new(pid, tag);
    // One process runs for milliseconds: its own memory, every 2 ms.
    sampler.root_only = mode == RunMode::SingleProcess;
    let (every, full_every) = match sampler.root_only {
        true => (Duration::from_millis(2), 1),
        false => (Duration::from_millis(100), 5),
    };
    let limit = deadline(n, duration_s);
    let status = loop {
        // Services and /dev/shm every sample over the first second (a small run is over in
        // less than a second: its few full samples could all fall before or after it).
        let full = sampler.samples() < 10 || sampler.samples().is_multiple_of(full_every);
        sampler.sample(full);
        if sup.wait_exit(id, every) {
            break sup.exit_status(id);
        }
        if started.elapsed() > limit {
            // SIGTERM (the sim stops its children as on Ctrl-C), SIGKILL 10 s later (its
            // children then get SIGTERM from the kernel: `PR_SET_PDEATHSIG`).
            sup.stop_all(Duration::from_secs(10));
            break None;
        }
    };
    let total_s = started.elapsed().as_secs_f64();
    let (stdout, stderr) = sup.output(id);
    let mut row = ScaleRow {
        robots: n,
        mode,
        startup_s: f64::NAN,
        total_s,
        wall_per_sim_s: f64::NAN,
        sim_time_s: 0.0,
        peak_rss_bytes: sampler.peaks.rss_bytes,
        peak_pss_bytes: sampler.peaks.pss_bytes,
        shm_bytes: sampler.peaks.shm_bytes,
        processes: sampler.peaks.processes,
        services: sampler.peaks.services,
        samples: sampler.samples(),
        error: None,
    };
    let tail = || stderr.lines().rev().take(4).collect::<Vec<_>>().join(" | ");
    match status {
        None => {
            row.error = Some(format!(
                "killed after {:.0} s: {}",
                limit.as_secs_f64(),
                tail()
            ))
        }
        Some(s) if !s.success() => row.error = Some(format!("{s}: {}", tail())),
        Some(_) => fill_from_json(&mut row, &stdout)?,
    }
    Ok(row)
}

/// The sim's `--json` figures into `row`.
fn fill_from_json(row: &mut ScaleRow, stdout: &str) -> Result<(), BenchError> {
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).map_err(|e| {
        BenchError::Peer(format!(
            "scale: the sim's --json is not JSON ({e}): {stdout:.200}"
        ))
    })?;
    let num = |k: &str| v.get(k).and_then(serde_json::Value::as_f64);
    let (wall, sim) = (num("wall_time_s"), num("sim_time_s"));
    let (Some(wall), Some(sim)) = (wall, sim.filter(|s| *s > 0.0)) else {
        return Err(BenchError::Peer(format!(
            "scale: the sim's --json has no wall_time_s / sim_time_s: {stdout:.200}"
        )));
    };
    let startup = num("startup_s").unwrap_or(row.total_s - wall);
    row.sim_time_s = sim;
    row.startup_s = startup.max(0.0);
    row.wall_per_sim_s = (wall - num("startup_s").unwrap_or(0.0)).max(0.0) / sim;
    Ok(())
}

/// The growth exponent of every figure in each mode (sizes with a positive, finite value; at
/// least two sizes).
pub fn growth(rows: &[ScaleRow]) -> BTreeMap<String, Growth> {
    let mut out = BTreeMap::new();
    for mode in [RunMode::Processes, RunMode::SingleProcess] {
        let name = mode_name(mode);
        for key in FIGURES {
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.mode == mode && r.error.is_none())
                .map(|r| (r.robots as f64, r.figure(key)))
                .filter(|(_, y)| y.is_finite() && *y > 0.0)
                .collect();
            if let Some(exponent) = log_log_slope(&pts) {
                out.insert(
                    format!("{name}/{key}"),
                    Growth {
                        exponent: (exponent * 1000.0).round() / 1000.0,
                        points: pts.len(),
                    },
                );
            }
        }
    }
    out
}

/// The least-squares slope of ln y against ln x; `None` below two distinct x.
pub fn log_log_slope(pts: &[(f64, f64)]) -> Option<f64> {
    let logs: Vec<(f64, f64)> = pts.iter().map(|(x, y)| (x.ln(), y.ln())).collect();
    let n = logs.len() as f64;
    let mx = logs.iter().map(|p| p.0).sum::<f64>() / n;
    let my = logs.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = logs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = logs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (logs.len() >= 2 && sxx > 1e-12).then(|| sxy / sxx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slope_of_a_power_law_is_its_exponent() {
        let pts: Vec<(f64, f64)> = ROBOTS
            .iter()
            .map(|&n| (n as f64, 3.0 * (n as f64).powf(1.5)))
            .collect();
        assert!((log_log_slope(&pts).unwrap() - 1.5).abs() < 1e-9);
        assert_eq!(log_log_slope(&pts[..1]), None);
        assert_eq!(log_log_slope(&[(8.0, 1.0), (8.0, 2.0)]), None);
    }

    #[test]
    fn a_swarm_has_every_robot_with_its_own_seed_inside_the_walls() {
        let s = swarm(256, 2.0).unwrap();
        assert_eq!(s.world.robots.len(), 256);
        assert_eq!(s.robots.len(), 256);
        assert_eq!(s.robots[200].follower.as_ref().unwrap().seed, 200);
        let mut places: Vec<(i64, i64)> = s
            .world
            .robots
            .iter()
            .map(|r| ((r.start.x_m * 10.0) as i64, (r.start.y_m * 10.0) as i64))
            .collect();
        for (x, y) in &places {
            assert!((10..290).contains(x) && (10..190).contains(y), "{x} {y}");
            assert!(x % 100 != 0 && y % 100 != 0, "{x} {y} on an inner wall");
        }
        places.sort();
        places.dedup();
        assert_eq!(places.len(), 256, "two robots start at one place");
        // What the sim reads back is the same scenario.
        let back = Scenario::parse(&s.to_toml().unwrap(), "swarm").unwrap();
        assert_eq!(back, s);
    }

    #[test]
    fn growth_skips_failed_runs_and_keys_each_mode_and_figure() {
        let row = |n: usize, mode, err: Option<&str>| ScaleRow {
            robots: n,
            mode,
            startup_s: n as f64 * 0.1,
            total_s: 1.0,
            wall_per_sim_s: (n * n) as f64,
            sim_time_s: 1.0,
            peak_rss_bytes: 1000 * n as u64,
            peak_pss_bytes: 500 * n as u64,
            shm_bytes: 7,
            processes: 3 * n + 2,
            services: 0,
            samples: 3,
            error: err.map(str::to_string),
        };
        let rows = vec![
            row(8, RunMode::Processes, None),
            row(16, RunMode::Processes, None),
            row(32, RunMode::Processes, Some("refused")),
            row(8, RunMode::SingleProcess, None),
        ];
        let g = growth(&rows);
        assert!((g["processes/startup_s"].exponent - 1.0).abs() < 1e-9);
        assert_eq!(g["processes/startup_s"].points, 2);
        assert!((g["processes/wall_per_sim_s"].exponent - 2.0).abs() < 1e-9);
        assert_eq!(g["processes/shm_bytes"].exponent, 0.0);
        assert!(!g.contains_key("processes/services"), "no positive value");
        assert!(!g.contains_key("single-process/startup_s"), "one size only");
    }
}
