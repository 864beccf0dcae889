//! A scenario as separate processes (`pheromone sim`, the default mode): the field, the world,
//! and each robot's localizer, depositor and follower, each a child of the `pheromone` binary
//! under one [`Supervisor`], in lockstep (`pheromone_field::process::lockstep`) with an [`Observer`] in this
//! process that records what a single-process run records. The result is the single-process
//! run's for the same seed, key by key.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use pheromone_field::process::run::FieldRunSummary;
use pheromone_field::shm::{cleanup_dead_nodes, create_node, ShmError};
use serde::Serialize;

use crate::observer::Observer;
use crate::recording::Recording;
use crate::ros_feed::McapFeed;
use crate::ros_record::{McapTotals, SimMcap};
use crate::single::{role_name, FieldSummary, RobotResult, RunSummary};
use pheromone_roles::process::follower_antenna::AntennaRobotSummary;
use pheromone_roles::{MapperSummary, RoleSummary};
use pheromone_supervisor::{ChildId, ChildSpec, Supervisor, SupervisorError};
use pheromone_world::scenario::{Scenario, ScenarioError};
use pheromone_world::World;
use pheromone_world::{lockstep_participants, mapper_robots, WorldOptions, WorldSummary};

mod children;
mod interrupt;
pub mod limits;

use children::*;
use interrupt::*;

/// How to run the processes.
pub struct ProcessRunOptions<'a> {
    /// The `pheromone` binary the roles are started from.
    pub exe: PathBuf,
    /// EKF-SLAM localizers.
    pub slam: bool,
    /// The world steps on wall time; nobody waits (the result is not the single-process one).
    pub realtime: bool,
    /// The whole run's limit.
    pub timeout: Duration,
    /// How long every process may take to join (None: grows with the number of processes).
    pub attach_timeout: Option<Duration>,
    /// Lockstep: a step that makes no progress for this long fails the run.
    pub stall_timeout: Duration,
    /// Called with the field time of each new frame.
    pub progress: Option<&'a mut dyn FnMut(f64)>,
    /// Serve `pheromone view` of the run's field and robots on this HTTP address.
    pub view: Option<String>,
    /// Start `pheromone ros2 --field F --world W --robots IDS --connect ENDPOINT` (the field and
    /// the robots on ROS 2 over Zenoh), connecting to this Zenoh endpoint.
    pub ros2: Option<String>,
    /// More arguments of that `pheromone ros2` child (its TLS, credentials and Zenoh
    /// configuration flags).
    pub ros2_args: Vec<String>,
    /// More arguments of every control-loop child (the field, the world, the roles, the
    /// mappers, the gateway): `--rt-priority N`, `--rt-best-effort`.
    pub rt_args: Vec<String>,
    /// The antenna robots read the field only through a `pheromone gateway` child (seed 002's
    /// thin clients, PIR over UDP loopback) instead of shared memory.
    pub remote: bool,
    /// Passed to every follower that reads the field in shared memory as `--wait`.
    pub follower_wait: Option<pheromone_field::shm::WaitPolicy>,
    /// `--record`: the observer writes the run to this MCAP file (finished also when the run
    /// fails).
    pub record: Option<SimMcap>,
}

/// Why a run as processes failed. Every process of the run has been stopped by then.
#[derive(Debug, thiserror::Error)]
pub enum ProcessRunError {
    #[error(transparent)]
    Child(#[from] SupervisorError),
    #[error("observer: {0}")]
    Observer(#[from] ShmError),
    #[error("scenario: {0}")]
    Scenario(#[from] ScenarioError),
    #[error("cannot write the scenario file {path}: {source}")]
    ScenarioFile {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("the field of the run did not come up within {timeout_s:.1} s")]
    NoField { timeout_s: f64 },
    #[error("the gateway of the run did not serve within {timeout_s:.1} s; its last output:\n{stderr_tail}")]
    NoGateway { timeout_s: f64, stderr_tail: String },
    #[error("the gateway of the run announced '{line}', not udp://HOST:PORT")]
    GatewayAddress { line: String },
    #[error("--remote: scenario '{scenario}' has no robot with an antenna follower")]
    NoRemoteRobot { scenario: String },
    #[error("--record: {0}")]
    Record(#[from] pheromone_ros2::record::RecordError),
    #[error("interrupted: stopped every process of the run")]
    Interrupted,
    /// The run needs more than the host gives (`limits`): nothing was started.
    #[error("the run needs {needed} but {limit} is {value}: nothing was started")]
    HostLimit {
        limit: String,
        value: u64,
        needed: u64,
    },
    #[error("the run took longer than {timeout_s} s: stopped every process")]
    Timeout { timeout_s: f64 },
    #[error(
        "{who} did not stop within {timeout_s:.0} s of the end of the run: stopped every process"
    )]
    NotStopped { who: String, timeout_s: f64 },
}

pheromone_field::from_shm_errors!(ProcessRunError);

/// One child's summary, as `metrics.json` lists them.
#[derive(Debug, Clone, Serialize)]
pub struct ProcessReport {
    pub role: String,
    pub summary: serde_json::Value,
}

/// What a run as processes gives besides the summary and recording shared with the
/// single-process mode.
#[derive(Debug, Clone, Serialize)]
pub struct ProcessRunInfo {
    /// From the first process started until the field's first lockstep frame (s).
    pub startup_s: f64,
    /// Processes of the run (the observer not counted).
    pub processes: usize,
    pub reports: Vec<ProcessReport>,
    /// `--record`: what the MCAP file holds.
    pub record: Option<McapTotals>,
    /// Stopped early by SIGINT/SIGTERM: the run's world was stopped as Ctrl-C stops it, every
    /// process has stopped, and the summary and recording are those up to the stop.
    pub interrupted: bool,
}

/// The effective scenario (after the flags) as a file the field, the world, the mappers and the
/// view read, and each robot's part of it ([`Scenario::robot_part`]) as a file its localizer,
/// depositor and follower read (one robot to parse and validate, not N: issue 52), in a private
/// temporary directory: a random name, mode 0700, each file created exclusively (`tempfile`,
/// `create_new`), so nobody can plant a symlink where they go or read them. Removed with its
/// directory on drop.
struct ScenarioFile {
    path: PathBuf,
    /// Robot id → the file of its part.
    parts: BTreeMap<u32, PathBuf>,
    dir: Option<tempfile::TempDir>,
}

impl ScenarioFile {
    fn write(scenario: &Scenario, tag: &str) -> Result<Self, ProcessRunError> {
        let io = |path: &std::path::Path| {
            let path = path.display().to_string();
            move |source| ProcessRunError::ScenarioFile { path, source }
        };
        let tmp = std::env::temp_dir();
        remove_stale_scenario_dirs(&tmp);
        let private = std::os::unix::fs::PermissionsExt::from_mode(0o700);
        let dir = tempfile::Builder::new()
            .prefix(&format!("pheromone-{tag}-"))
            .permissions(private)
            .tempdir_in(&tmp)
            .map_err(io(&tmp))?;
        let path = dir.path().join("scenario.toml");
        write_new(&path, &scenario.to_toml()?).map_err(io(&path))?;
        let mut parts = BTreeMap::new();
        for r in &scenario.robots {
            if let Some(part) = scenario.robot_part(r.id) {
                let file = dir.path().join(format!("robot-{}.toml", r.id));
                write_new(&file, &part.to_toml()?).map_err(io(&file))?;
                parts.insert(r.id, file);
            }
        }
        Ok(Self {
            path,
            parts,
            dir: Some(dir),
        })
    }
}

/// Writes `text` to the new file `path`: `create_new` (O_EXCL), so not even a file that
/// appeared in the fresh directory is followed.
fn write_new(path: &Path, text: &str) -> std::io::Result<()> {
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)?;
    std::io::Write::write_all(&mut file, text.as_bytes())
}

/// Removes the scenario directories that sims killed with SIGKILL could not remove: entries
/// `pheromone-sim<PID>x<N>-…` of `tmp` that are real directories of this user's and whose sim
/// (PID) no longer runs. A PID reused by another process keeps its directory until a later run.
fn remove_stale_scenario_dirs(tmp: &std::path::Path) {
    use std::os::unix::fs::MetadataExt;
    let uid = nix::unistd::geteuid().as_raw();
    let Ok(entries) = std::fs::read_dir(tmp) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(scenario_dir_pid) else {
            continue;
        };
        let Ok(meta) = std::fs::symlink_metadata(entry.path()) else {
            continue;
        };
        let alive = !matches!(
            nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), None),
            Err(nix::errno::Errno::ESRCH)
        );
        if meta.is_dir() && meta.uid() == uid && !alive {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// The sim's PID in a scenario directory's name (`pheromone-sim<PID>x<N>-<random>`).
fn scenario_dir_pid(name: &str) -> Option<i32> {
    let rest = name.strip_prefix("pheromone-sim")?;
    let (pid, rest) = rest.split_once('x')?;
    let (run, random) = rest.split_once('-')?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    (digits(pid) && digits(run) && !random.is_empty())
        .then(|| pid.parse().ok())
        .flatten()
        .filter(|&p: &i32| p > 0)
}

impl Drop for ScenarioFile {
    fn drop(&mut self) {
        // A directory that another cleanup already removed is not an error; anything else
        // leaves it behind, and says so.
        if let Some(dir) = self.dir.take() {
            let shown = dir.path().display().to_string();
            match dir.close() {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    eprintln!("sim: cannot remove {shown}: {e}")
                }
                _ => {}
            }
        }
    }
}

/// Removes what killed (or crashed) children of run `tag` left in shared memory: their nodes
/// and the memory behind them. A cleanup that cannot run says so: the leftovers stay until the
/// next run's cleanup.
fn cleanup_after(tag: &str) {
    match create_node(&format!("{tag}-cleanup")) {
        Ok(node) => {
            cleanup_dead_nodes(&node);
        }
        Err(e) => eprintln!("sim: cannot clean up the shared memory of run {tag}: {e}"),
    }
}

/// A run tag no other run on this host uses: names the field, the world and the temp dir.
fn run_tag() -> String {
    use std::sync::atomic::{AtomicU32, Ordering};
    static RUN: AtomicU32 = AtomicU32::new(0);
    format!(
        "sim{}x{}",
        std::process::id(),
        RUN.fetch_add(1, Ordering::Relaxed)
    )
}

/// Runs `scenario` as separate processes and returns what the single-process mode returns,
/// plus the processes' reports. On any failure every process is stopped, what killed ones left
/// in shared memory is cleaned up, and the error names the process that failed.
pub fn run_as_processes(
    scenario: &Scenario,
    o: ProcessRunOptions<'_>,
) -> Result<(RunSummary, Recording, ProcessRunInfo), ProcessRunError> {
    limits::check(
        lockstep_participants(scenario, true, true),
        limits::nofile_soft(),
        pheromone_field::shm::shm_available_bytes(),
        pheromone_field::shm::frame_pool(&scenario.field).1,
    )?;
    let tag = run_tag();
    let file = ScenarioFile::write(scenario, &tag)?;
    let mut sup = Supervisor::new(&o.exe);
    // This process cleans up after dead nodes (its node's creation, `cleanup_after`), and a child
    // that dies ends the run: the children skip the walk of every node (N² over a start-up).
    sup.env.push((
        pheromone_field::shm::CLEANED_BY_SUPERVISOR_ENV.to_string(),
        "1".to_string(),
    ));
    // The children are `pheromone`: started without a fork of this process (issue 52).
    sup.death_signal_by_child = true;
    let result = supervise(scenario, o, &tag, &file, &mut sup);
    if result.is_err() {
        sup.stop_all(Duration::from_secs(5));
    }
    // Children killed (or crashed) leave their nodes behind: remove them, and their memory.
    cleanup_after(&tag);
    drop(file);
    result
}

/// The run under `sup`: starts every child, records until the world ends, collects the reports.
fn supervise(
    scenario: &Scenario,
    mut o: ProcessRunOptions<'_>,
    tag: &str,
    file: &ScenarioFile,
    sup: &mut Supervisor,
) -> Result<(RunSummary, Recording, ProcessRunInfo), ProcessRunError> {
    let args = ChildArgs {
        field: tag.to_string(),
        world: tag.to_string(),
        scenario: file.path.display().to_string(),
        parts: file
            .parts
            .iter()
            .map(|(id, p)| (*id, p.display().to_string()))
            .collect(),
        realtime: o.realtime,
        rt: o.rt_args.clone(),
    };
    let participants = lockstep_participants(scenario, true, true);
    let attach_timeout = o
        .attach_timeout
        .unwrap_or_else(|| WorldOptions::default_attach_timeout(participants));
    // The node first: from here on Ctrl-C is iceoryx2's, whatever thread it reaches.
    let node = create_node(&format!("{tag}-observer"))?;
    let started = Instant::now();
    let start = RunStart {
        node: &node,
        started,
        attach_timeout,
    };
    let children = Children::spawn(scenario, &o, &args, &start, sup)?;
    let mut observer = join_observer(scenario, &args, &start, sup)?;
    let world = World::new(scenario.world.clone(), scenario.seed).ok();
    let segments = world.as_ref().map_or(&[][..], |w| w.wall_segments());
    observer.set_walls(
        segments.iter().map(|s| (s.a_m, s.b_m)).collect(),
        scenario.mark_walls.as_ref().map(|m| m.channel as usize),
    );
    if let Some(out) = o.record.take() {
        let scripted = scenario.scripted(segments)?;
        observer.record_to(McapFeed::new(out, scenario, scripted));
    }
    let recorded = record_until_the_world_ends(&mut observer, children.world, &start, &mut o, sup)?;
    if recorded.interrupted {
        let startup_s = recorded.startup.unwrap_or_else(|| started.elapsed());
        let out = finish_interrupted(scenario, observer, &children, sup, participants);
        return Ok((
            out.0,
            out.1,
            ProcessRunInfo {
                startup_s: startup_s.as_secs_f64(),
                ..out.2
            },
        ));
    }
    let startup = recorded.startup;
    let world_summary: WorldSummary = sup.summary(children.world)?;
    // The other roles stop by themselves when the world announces the end.
    let end_timeout = Duration::from_secs(15);
    children.wait_roles_stopped(sup, end_timeout)?;
    let (field_summary, mut reports) = children.reports(sup)?;
    if let Some((id, _)) = children.gateway {
        reports.push(stop_gateway(sup, id, end_timeout)?);
    }
    reports.push(report("world", &world_summary));
    let (rec, mcap) = observer.finish_with_mcap();
    let record = mcap.transpose()?;
    let counters = FieldCounters::of(&field_summary);
    let summary = run_summary(scenario, &world_summary, &counters, &rec);
    Ok((
        summary,
        rec,
        ProcessRunInfo {
            startup_s: startup.unwrap_or_else(|| started.elapsed()).as_secs_f64(),
            processes: participants, // the observer counted in, the world not: as many
            reports,
            record,
            interrupted: false,
        },
    ))
}

/// How the recording ended: the startup time, and whether SIGINT/SIGTERM stopped it.
struct Recorded {
    startup: Option<Duration>,
    interrupted: bool,
}

/// After SIGINT/SIGTERM, how long the world may take to stop and announce the end while the
/// observer records its last frames.
const WIND_DOWN: Duration = Duration::from_secs(5);

/// Records until the world ends (watching children, Ctrl-C, the time limit). On SIGINT or
/// SIGTERM the world is stopped as Ctrl-C stops it (it announces the end, the roles stop on
/// it) and the frames until then are recorded, `WIND_DOWN` at most; no child's failure ends
/// the recording then.
fn record_until_the_world_ends(
    observer: &mut Observer,
    world: ChildId,
    start: &RunStart<'_>,
    o: &mut ProcessRunOptions<'_>,
    sup: &mut Supervisor,
) -> Result<Recorded, ProcessRunError> {
    let deadline = start.started + o.timeout;
    let mut startup = None;
    let mut wind_down: Option<Instant> = None;
    while sup.exit_status(world).is_none() {
        if wind_down.is_none() && !pheromone_field::shm::wait_or_stop(start.node, Duration::ZERO) {
            sup.signal(world, nix::sys::signal::Signal::SIGTERM);
            wind_down = Some(Instant::now() + WIND_DOWN);
        }
        match wind_down {
            Some(end) if Instant::now() > end => break,
            Some(_) => sup.poll(Duration::ZERO),
            None => {
                sup.check()?;
                if Instant::now() > deadline {
                    return Err(ProcessRunError::Timeout {
                        timeout_s: o.timeout.as_secs_f64(),
                    });
                }
            }
        }
        // Woken by the next frame; a child's exit is seen at most one round later.
        match observer.poll(Duration::from_millis(20)) {
            Ok(()) => {}
            Err(_) if wind_down.is_some() => break,
            Err(e) => return Err(e.into()),
        }
        if let Some(t) = observer.sim_time_s() {
            if startup.is_none() && t > 0.0 {
                startup = Some(start.started.elapsed());
            }
            if let Some(p) = o.progress.as_mut() {
                p(t);
            }
        }
    }
    Ok(Recorded {
        startup,
        interrupted: wind_down.is_some(),
    })
}

fn report(role: &str, s: &impl Serialize) -> ProcessReport {
    ProcessReport {
        role: role.to_string(),
        summary: serde_json::to_value(s).unwrap_or(serde_json::Value::Null),
    }
}

/// The run's summary from the children's typed summaries and the observer's recording, built
/// the way the single-process runner builds it.
fn run_summary(
    scenario: &Scenario,
    world: &WorldSummary,
    field: &FieldCounters,
    rec: &Recording,
) -> RunSummary {
    let mut fs = match rec.snapshots.last() {
        Some(snap) => {
            let view = pheromone_field::FrameView::new(
                scenario.field.geometry(),
                scenario.field.channels.len(),
                &snap.planes,
            );
            FieldSummary::of(&scenario.field, &view, field.deposits_applied, &[])
        }
        None => FieldSummary::default(),
    };
    // The field's own counters are authoritative.
    fs.deposits_applied = field.deposits_applied;
    fs.deposits_rejected = field.deposits_rejected.clone();
    let robots = world
        .robots
        .iter()
        .map(|r| RobotResult {
            id: r.id,
            role: role_name(scenario, r.id),
            true_pose: r.true_pose,
            estimated_pose: rec
                .robots
                .get(&r.id)
                .and_then(|rows| rows.iter().rev().find_map(|row| row.est_pose)),
            distance_travelled_m: rec.distance_travelled_m(r.id),
            trail_abandoned_at_s: rec.trail_abandoned_at_s(r.id),
            collisions: r.collisions,
        })
        .collect();
    RunSummary {
        steps: world.steps,
        sim_time_s: world.sim_time_s,
        ticks: field.ticks,
        field: fs,
        robots,
        scripted_deposits: world.deposits_sent,
    }
}

/// A node-graph run (seed 001) as processes: the graph writer and one `graph-robot` per robot,
/// under one supervisor. `scenario` is what `pheromone graph --scenario` takes. With
/// `localize` (the run's settings, built from that scenario's `[localize]` table), every robot
/// process localizes (`graph-robot --localize`) and the run's η1, η2 come from the robots'
/// reports, as in one process.
pub fn run_graph_as_processes(
    exe: &Path,
    scenario: &str,
    strategy: pheromone_graph::agent::GraphStrategy,
    robots: usize,
    seed: u64,
    timeout: Duration,
    localize: Option<pheromone_graph::localize::LocalizeConfig>,
) -> Result<pheromone_graph::run::RunReport, ProcessRunError> {
    use std::sync::atomic::{AtomicU32, Ordering};
    static RUN: AtomicU32 = AtomicU32::new(0);
    let tag = format!(
        "sim{}g{}",
        std::process::id(),
        RUN.fetch_add(1, Ordering::Relaxed)
    );
    let mut sup = Supervisor::new(exe);
    // As in `run_as_processes`: this process cleans (its node's creation, `cleanup_after`) and a
    // child that dies ends the run, so the robots skip the walks of every node.
    sup.env.push((
        pheromone_field::shm::CLEANED_BY_SUPERVISOR_ENV.to_string(),
        "1".to_string(),
    ));
    // The children are `pheromone`: started without a fork of this process (issue 52).
    sup.death_signal_by_child = true;
    let result = (|| {
        let node = create_node(&format!("{tag}-sim"))?;
        let common = |role: &str| -> Vec<String> {
            [
                role,
                "--scenario",
                scenario,
                "--name",
                &tag,
                "--robots",
                &robots.to_string(),
                "--strategy",
                strategy.name(),
                "--seed",
                &seed.to_string(),
                "--json",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect()
        };
        let writer = sup.spawn(ChildSpec::new("graph", None, common("graph")))?;
        let mut ids = Vec::new();
        for id in 1..=robots {
            let mut args = common("graph-robot");
            args.extend(["--robot".to_string(), id.to_string()]);
            if let Some(l) = &localize {
                args.extend(["--localize".to_string(), l.deposit.name().to_string()]);
            }
            ids.push(sup.spawn(ChildSpec::new("graph-robot", Some(id as u32), args))?);
        }
        let deadline = Instant::now() + timeout;
        while sup.exit_status(writer).is_none() {
            sup.check()?;
            if Instant::now() > deadline {
                return Err(ProcessRunError::Timeout {
                    timeout_s: timeout.as_secs_f64(),
                });
            }
            if pheromone_field::shm::should_stop(&node) {
                return Err(ProcessRunError::Interrupted);
            }
            // Woken by the first child that exits; the bound lets Ctrl-C through.
            sup.poll(Duration::from_millis(100));
        }
        let mut report: pheromone_graph::run::RunReport = sup.summary(writer)?;
        let end_timeout = Duration::from_secs(15);
        let end = Instant::now() + end_timeout;
        for &id in &ids {
            if !sup.wait_exit(id, end.saturating_duration_since(Instant::now())) {
                return Err(ProcessRunError::NotStopped {
                    who: sup.spec(id).who(),
                    timeout_s: end_timeout.as_secs_f64(),
                });
            }
            report.robot_reports.push(sup.summary(id)?);
        }
        if let Some(config) = localize {
            report.add_localization(config);
        }
        Ok(report)
    })();
    if result.is_err() {
        sup.stop_all(Duration::from_secs(5));
    }
    cleanup_after(&tag);
    result
}
