//! A whole scenario in one process, in lockstep, bit-for-bit deterministic for a seed
//! (`pheromone sim --single-process`). It runs the same role types as the separate processes —
//! [`World`], the localizer [`Filter`], [`Depositor`], [`Follower`] and the field's
//! [`OwnedField`] — in the order the lockstep processes follow within one step:
//!
//! 1. the world applies the commands of step k−1 and produces sensors and truth of step k;
//! 2. scripted deposits due by then are offered to the field;
//! 3. each localizer turns its sensors into a pose, each depositor the pose into a deposit;
//! 4. the field ticks once (evaporation, then every deposit offered);
//! 5. each follower reads the new frame and decides its command (with own-map steering, its
//!    robot's map after the mapping team's step instead, at its estimate in the map's frame).
//!
//! The run also records what `pheromone_report` draws and what the metrics need, and with `--record`
//! hands each step's poses, applied deposits and recorded frames to a [`SimMcap`] (whose
//! thread writes the MCAP file).

use std::collections::{BTreeMap, VecDeque};

use pheromone_field::{DepositMsg, FieldConfig, FrameView, OwnedField, RejectReason};
use serde::Serialize;

use crate::recording::{deposit_peak, ProbeReading, Recording, RobotSample, Snapshot};
use crate::ros_record::{PoseRow, SimMcap};
use pheromone_messages::{FollowerState, LaserMsg, PoseMsg};
use pheromone_roles::depositor::Depositor;
use pheromone_roles::follower::{Follower, PoseSource};
use pheromone_roles::mapper::{pose_msg_in_frame, Pose2, MAP_CHANNELS};
use pheromone_roles::{Filter, ProcessError};
use pheromone_world::scenario::{ProbeSpec, Scenario};
use pheromone_world::team::MappingTeam;
use pheromone_world::{StepOutput, World};

/// What a run ends with, whichever way it ran.
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    pub steps: u64,
    pub sim_time_s: f64,
    pub ticks: u64,
    pub field: FieldSummary,
    pub robots: Vec<RobotResult>,
    /// Scripted deposits sent by the world.
    pub scripted_deposits: u64,
}

/// The field at the end of a run.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FieldSummary {
    pub width: u32,
    pub height: u32,
    pub cell_size_m: f32,
    pub channels: Vec<String>,
    /// Sum of the cells of each channel.
    pub total_mass: Vec<f64>,
    /// Largest cell of each channel.
    pub max: Vec<f32>,
    pub nan_cells: u64,
    pub deposits_applied: u64,
    /// Rejected deposits by reason.
    pub deposits_rejected: BTreeMap<String, u64>,
}

impl FieldSummary {
    /// Summarizes a frame and the field's counters.
    pub fn of(config: &FieldConfig, view: &FrameView<'_>, applied: u64, rejected: &[u64]) -> Self {
        let g = config.geometry();
        Self {
            width: g.width,
            height: g.height,
            cell_size_m: g.cell_size_m,
            channels: config.channels.iter().map(|c| c.name.clone()).collect(),
            total_mass: (0..view.channels).map(|c| view.total(c)).collect(),
            max: (0..view.channels).map(|c| view.max(c)).collect(),
            nan_cells: view.non_finite_cells() as u64,
            deposits_applied: applied,
            deposits_rejected: rejected_by_reason(rejected),
        }
    }
}

/// Named rejection counters (`FrameHeader::deposits_rejected` order).
pub fn rejected_by_reason(counts: &[u64]) -> BTreeMap<String, u64> {
    RejectReason::ALL
        .iter()
        .zip(counts)
        .map(|(r, n)| (r.name().to_string(), *n))
        .collect()
}

/// One robot at the end of a run.
#[derive(Debug, Clone, Serialize)]
pub struct RobotResult {
    pub id: u32,
    pub role: String,
    pub true_pose: [f64; 3],
    pub estimated_pose: Option<[f64; 3]>,
    pub distance_travelled_m: f64,
    pub trail_abandoned_at_s: Option<f64>,
    pub collisions: u64,
}

/// The role a robot plays, as reported: `leader`, `follower`, `depositor`, `explorer`…
pub fn role_name(scenario: &Scenario, id: u32) -> String {
    use pheromone_roles::follower::StrategyKind as K;
    let Some(r) = scenario.roles(id) else {
        return "idle".into();
    };
    let mut parts = Vec::new();
    match r.follower.as_ref().map(|f| f.strategy) {
        Some(K::Route) => parts.push("leader"),
        Some(K::Inverse | K::Uniform) => parts.push("explorer"),
        Some(K::Gradient | K::Antenna) => parts.push("follower"),
        None => {}
    }
    if r.depositor.is_some() {
        parts.push("depositor");
    }
    if parts.is_empty() {
        "localizer".into()
    } else {
        parts.join("+")
    }
}

/// Options of a single-process run.
#[derive(Default)]
pub struct SingleProcessOptions<'a> {
    /// EKF-SLAM localizers instead of the landmark EKF.
    pub slam: bool,
    /// Called after every step with (step, steps).
    pub progress: Option<&'a mut dyn FnMut(u64, u64)>,
    /// `--record`: the run's MCAP file (the caller finishes it).
    pub record: Option<&'a mut SimMcap>,
    /// Asked after every step: `true` ends the run there (SIGINT/SIGTERM); the summary and
    /// recording are then those of the steps run, and `RunSummary::steps` says how many.
    pub stop: Option<&'a dyn Fn() -> bool>,
}

struct Robot {
    id: u32,
    filter: Filter,
    depositor: Option<Depositor>,
    follower: Option<(Follower, PoseSource)>,
    pose: Option<PoseMsg>,
    /// The peak of this step's deposit, if the depositor sent one.
    deposit_peak: Option<f32>,
    collisions: u64,
}

impl Robot {
    /// Robot `id`'s roles as the scenario gives them: depositor, follower, localizer.
    fn new(scenario: &Scenario, id: u32, slam: bool) -> Result<Self, ProcessError> {
        let roles = scenario.roles(id);
        let depositor = match roles.and_then(|x| x.depositor.clone()) {
            Some(c) => Some(Depositor::new(c).map_err(|source| ProcessError::Depositor {
                robot: Some(id),
                source,
            })?),
            None => None,
        };
        let follower = match scenario.follower_config(id) {
            Some(c) => Some((
                Follower::from_config(id, &c)
                    .map_err(|source| ProcessError::Follower { robot: id, source })?,
                c.steer_by,
            )),
            None => None,
        };
        Ok(Self {
            id,
            filter: Filter::new(&scenario.localizer_setup(id, slam)?)?,
            depositor,
            follower,
            pose: None,
            deposit_peak: None,
            collisions: 0,
        })
    }

    /// Step `k` (at `t_s`) before the tick: the pose from the sensors, and the deposit offered.
    fn localize_and_deposit(
        &mut self,
        k: u64,
        t_s: f64,
        out: &StepOutput,
        laser: Option<&LaserMsg>,
        field: &mut OwnedField,
    ) {
        self.collisions += out.truth.collided as u64;
        // A rejected sensor message: the localizer keeps its previous estimate, as the
        // process does (which also logs it).
        let _ = self
            .filter
            .step(&out.sensor, laser.filter(|_| self.filter.needs_laser()));
        let mut p = self.filter.to_msg(self.id, k);
        // Simulated time as the stamp: deterministic, and what interval_s measures.
        p.stamp_ns = (t_s * 1e9).round() as u64;
        self.pose = Some(p);
        self.deposit_peak = None;
        if let Some(d) = self.depositor.as_mut() {
            if let Ok(Some(m)) = d.process(&p) {
                self.deposit_peak = Some(deposit_peak(&m));
                // A rejection is counted by the field.
                let _ = field.offer(&m);
            }
        }
    }

    /// After the tick: the follower's command into `cmd` (stop on error), its state and level.
    /// `own_map`: the robot steers on its own map (`view`), whose frame has this origin.
    fn follow(
        &mut self,
        pose: PoseMsg,
        out: &StepOutput,
        (view, own_map): (&FrameView<'_>, Option<Pose2>),
        dt: f64,
        cmd: &mut (f64, f64),
    ) -> (Option<FollowerState>, Option<f32>) {
        let mut state = None;
        let mut level = None;
        if let Some((f, source)) = self.follower.as_mut() {
            let steer = match source {
                PoseSource::Estimate => pose,
                PoseSource::Truth => pheromone_messages::truth_as_pose(&out.truth),
            };
            let steer = match own_map {
                Some(start) => pose_msg_in_frame(start, &steer),
                None => steer,
            };
            match f.step_pose(view, &steer, dt) {
                Ok(o) => {
                    *cmd = (o.cmd.v_m_per_s, o.cmd.omega_rad_per_s);
                    state = Some(o.decision.state);
                    level = Some(o.decision.sensed_level);
                }
                Err(_) => *cmd = (0.0, 0.0),
            }
        }
        (state, level)
    }
}

/// Runs the scenario in this process and returns its summary and recording.
pub fn run_single_process(
    scenario: &Scenario,
    mut options: SingleProcessOptions<'_>,
) -> Result<(RunSummary, Recording), ProcessError> {
    let mut run = SingleRun::new(scenario, options.slam)?;
    run.record = options.record.take();
    let steps = scenario.steps();
    for k in 0..steps {
        run.step(k);
        if let Some(p) = options.progress.as_mut() {
            p(k + 1, steps);
        }
        if options.stop.is_some_and(|stop| stop()) {
            break;
        }
    }
    Ok(run.finish())
}

/// A single-process run: the world, the field, the robots' roles and what is recorded.
struct SingleRun<'a> {
    scenario: &'a Scenario,
    world: World,
    mapping: Option<MappingTeam>,
    field: OwnedField,
    scripted: VecDeque<(f64, DepositMsg)>,
    scripted_total: u64,
    robots: Vec<Robot>,
    rec: Recording,
    frames: FrameSchedule,
    /// Each robot's command, applied by the next step.
    commands: Vec<(f64, f64)>,
    /// Own-map steering: each robot's map frame origin and its map as a frame (both planes,
    /// [`MAP_CHANNELS`]), refreshed after the mapping team's step; `None` on the shared field.
    own_maps: Vec<Option<(Pose2, Vec<f32>)>>,
    /// Seed 004's integration cost (`[mapping] merge_idle_iterations`): each robot stands still
    /// until this step (exclusive) after a merge.
    idle_until: Vec<u64>,
    record: Option<&'a mut SimMcap>,
}

impl<'a> SingleRun<'a> {
    /// Builds the world, the mapping team, the field, the scripted deposits and the robots.
    fn new(scenario: &'a Scenario, slam: bool) -> Result<Self, ProcessError> {
        let mut world =
            World::new(scenario.world.clone(), scenario.seed).map_err(ProcessError::from)?;
        if let Some(m) = scenario.mapping() {
            world.enable_mapping(m, scenario.seed);
        }
        let mapping = MappingTeam::new(scenario).map_err(ProcessError::Mapping)?;
        let field = OwnedField::new(scenario.field.clone()).map_err(ProcessError::Field)?;
        let scripted = VecDeque::from(scenario.scripted(world.wall_segments())?);
        let scripted_total = scripted.len() as u64;
        let mut robots = Vec::new();
        for r in &scenario.world.robots {
            robots.push(Robot::new(scenario, r.id, slam)?);
        }
        let rec = Recording {
            walls: world
                .wall_segments()
                .iter()
                .map(|s| (s.a_m, s.b_m))
                .collect(),
            wall_channel: scenario.mark_walls.as_ref().map(|m| m.channel as usize),
            ..Recording::default()
        };
        let commands = vec![(0.0, 0.0); robots.len()];
        let own_maps = scenario
            .world
            .robots
            .iter()
            .map(|r| {
                scenario.follower_config(r.id)?;
                let start = scenario.own_map_start(r.id)?;
                let team = mapping.as_ref()?;
                let map = &team.mapper(r.id)?.map;
                let cells = MAP_CHANNELS.len() * map.geometry().cells();
                Some((start, vec![0.0; cells]))
            })
            .collect();
        Ok(Self {
            scenario,
            world,
            mapping,
            field,
            scripted,
            scripted_total,
            robots,
            rec,
            frames: FrameSchedule::new(scenario),
            idle_until: vec![0; commands.len()],
            commands,
            own_maps,
            record: None,
        })
    }

    /// Step `k`, in the order of the lockstep processes (see the module's documentation).
    fn step(&mut self, k: u64) {
        let outputs = self.world.step(&self.commands);
        let sensed = self.world.mapping_outputs();
        let lasers = self.world.laser_outputs();
        let t = self.world.sim_time_s();
        while self.scripted.front().is_some_and(|(ts, _)| *ts <= t + 1e-9) {
            let (_, m) = self.scripted.pop_front().expect("checked");
            let _ = self.field.offer(&m); // a rejection is counted by the field
        }
        for (i, (r, out)) in self.robots.iter_mut().zip(&outputs).enumerate() {
            r.localize_and_deposit(k, t, out, lasers.get(i), &mut self.field);
        }
        if let Some(team) = self.mapping.as_mut() {
            let poses: Vec<PoseMsg> = self
                .robots
                .iter()
                .map(|r| r.pose.expect("set above"))
                .collect();
            team.step(self.world.step_count(), &poses, &sensed);
        }
        self.start_idling(k);
        self.refresh_own_maps();
        self.field.tick();
        let ft = self.field.stepper.sim_time_s;
        let view = self.field.view();
        self.frames.on_frame(&mut self.rec, ft, &view);
        let dt = self.scenario.world.dt_s;
        let robots = self.robots.iter_mut().zip(&outputs).zip(&self.own_maps);
        let mut rows = Vec::new();
        let idle = self.idle_until.iter();
        for ((((r, out), own), cmd), &idle_until) in robots.zip(self.commands.iter_mut()).zip(idle)
        {
            let pose = r.pose.expect("set above");
            if self.record.is_some() {
                rows.push(PoseRow {
                    robot: r.id,
                    t_s: t,
                    truth: [out.truth.x_m, out.truth.y_m, out.truth.theta_rad],
                    estimate: Some(pose),
                });
            }
            let (state, level) = match own {
                _ if k < idle_until => {
                    *cmd = (0.0, 0.0);
                    (None, None)
                }
                Some((start, cells)) => {
                    let g = *self
                        .mapping
                        .as_ref()
                        .and_then(|t| t.mapper(r.id))
                        .expect("own-map steering maps")
                        .map
                        .geometry();
                    let map = FrameView::new(g, MAP_CHANNELS.len(), cells);
                    r.follow(pose, out, (&map, Some(*start)), dt, cmd)
                }
                None => r.follow(pose, out, (&view, None), dt, cmd),
            };
            self.rec.robots.entry(r.id).or_default().push(RobotSample {
                t_s: t,
                true_pose: [out.truth.x_m, out.truth.y_m, out.truth.theta_rad],
                est_pose: Some([pose.x_m, pose.y_m, pose.theta_rad]),
                est_sigma_m: Some(sigma_max_m(&pose)),
                v_m_per_s: cmd.0,
                omega_rad_per_s: cmd.1,
                state,
                sensed_level: level,
                deposit_peak: r.deposit_peak,
            });
        }
        if let Some(out) = self.record.as_mut() {
            out.poses(rows);
            out.deposits(t, self.field.stepper.applied());
            out.frames(&self.rec);
        }
    }

    /// The integration cost: a robot that merged at step `k` stands still for
    /// `merge_idle_iterations` iterations from this step on.
    fn start_idling(&mut self, k: u64) {
        let (Some(team), Some(m)) = (self.mapping.as_ref(), self.scenario.mapping()) else {
            return;
        };
        let idle_steps = m.idle_steps_per_merge(self.scenario.world.dt_s);
        if idle_steps == 0 {
            return;
        }
        for id in team.merged_at(self.world.step_count()) {
            if let Some(i) = self.robots.iter().position(|r| r.id == id) {
                self.idle_until[i] = k + idle_steps;
            }
        }
    }

    /// Own-map steering: each robot's map of this step, as the frame its follower reads (the
    /// frame its mapper process publishes).
    fn refresh_own_maps(&mut self) {
        let Some(team) = self.mapping.as_ref() else {
            return;
        };
        for (r, own) in self.robots.iter().zip(self.own_maps.iter_mut()) {
            if let (Some((_, cells)), Some(m)) = (own.as_mut(), team.mapper(r.id)) {
                m.map.write_frame(cells);
            }
        }
    }

    /// Pictures the last frame and sums up the run.
    fn finish(mut self) -> (RunSummary, Recording) {
        let scenario = self.scenario;
        let field = &self.field;
        self.frames
            .finish(&mut self.rec, field.stepper.sim_time_s, field.cells());
        if let Some(out) = self.record.as_mut() {
            out.frames(&self.rec);
        }
        self.rec.mapping = self.mapping.map(MappingTeam::finish);
        let rec = self.rec;
        let counters = &field.stepper.counters;
        let summary = RunSummary {
            steps: self.world.step_count(),
            sim_time_s: self.world.sim_time_s(),
            ticks: field.stepper.sequence,
            field: FieldSummary::of(
                &scenario.field,
                &field.view(),
                counters.applied,
                &counters.rejected,
            ),
            robots: self
                .robots
                .iter()
                .zip(self.world.poses())
                .map(|(r, p)| RobotResult {
                    id: r.id,
                    role: role_name(scenario, r.id),
                    true_pose: [p.x_m, p.y_m, p.theta_rad],
                    estimated_pose: r.pose.map(|e| [e.x_m, e.y_m, e.theta_rad]),
                    distance_travelled_m: rec.distance_travelled_m(r.id),
                    trail_abandoned_at_s: rec.trail_abandoned_at_s(r.id),
                    collisions: r.collisions,
                })
                .collect(),
            scripted_deposits: self.scripted_total,
        };
        (summary, rec)
    }
}

/// What a run records of its frames, the same in both modes: the probes' readings and the
/// snapshots at the scenario's times, and the last frame.
pub struct FrameSchedule {
    field: FieldConfig,
    probes: std::collections::VecDeque<(f64, ProbeSpec)>,
    snapshot_times_s: std::collections::VecDeque<f64>,
    half_dt_s: f64,
}

impl FrameSchedule {
    pub fn new(scenario: &Scenario) -> Self {
        let mut times = scenario.snapshots_s.clone();
        times.sort_by(f64::total_cmp);
        Self {
            field: scenario.field.clone(),
            probes: scenario
                .probe_schedule()
                .into_iter()
                .map(|(t, i)| (t, scenario.probes[i].clone()))
                .collect(),
            snapshot_times_s: times.into(),
            half_dt_s: 0.5 * scenario.world.dt_s,
        }
    }

    /// Records what is due at the frame of field time `t_s`.
    pub fn on_frame(&mut self, rec: &mut Recording, t_s: f64, view: &FrameView<'_>) {
        while self.probes.front().is_some_and(|(pt, _)| *pt <= t_s + 1e-9) {
            let (_, p) = self.probes.pop_front().expect("checked");
            rec.probes.push(ProbeReading {
                t_s,
                x_m: p.x_m,
                y_m: p.y_m,
                channel: p.channel,
                value: view.value(p.channel as usize, p.x_m, p.y_m),
            });
        }
        while self
            .snapshot_times_s
            .front()
            .is_some_and(|s| *s <= t_s + self.half_dt_s)
        {
            self.snapshot_times_s.pop_front();
            rec.snapshots.push(snapshot(&self.field, t_s, view.cells));
        }
    }

    /// Pictures the last frame (field time `t_s`) unless it already was.
    pub fn finish(&self, rec: &mut Recording, t_s: f64, cells: &[f32]) {
        if rec.snapshots.last().is_none_or(|s| s.t_s < t_s) {
            rec.snapshots.push(snapshot(&self.field, t_s, cells));
        }
    }
}

/// A copy of the frame for the pictures.
pub fn snapshot(config: &FieldConfig, t_s: f64, cells: &[f32]) -> Snapshot {
    let g = config.geometry();
    Snapshot {
        t_s,
        width: g.width,
        height: g.height,
        cell_size_m: g.cell_size_m,
        channels: config.channels.iter().map(|c| c.name.clone()).collect(),
        planes: cells.to_vec(),
    }
}

/// √λmax of the position covariance (m): the long half-axis of the 1σ error ellipse.
pub fn sigma_max_m(p: &PoseMsg) -> f64 {
    let [a, b, c] = p.cov_xy();
    let half = 0.5 * (a + c);
    let d = (0.25 * (a - c).powi(2) + b * b).sqrt();
    (half + d).max(0.0).sqrt()
}
