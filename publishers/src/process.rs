//! The process loops: each role is a library type driven by a short loop that waits on iceoryx2
//! events (never sleeps). In lockstep (the default) the world conducts every step as
//! `field::lockstep` describes: each role joins the run after creating its ports, a depositor
//! acknowledges each step once its deposit is sent, and a follower steers on the frame the field
//! computed for the step, so a run as processes gives the single-process answer.

use std::time::{Duration, Instant};

use field::link::{LinkOptions, Receiver, Sender};
use field::lockstep::{self, Conductor, LockstepError, Participant};
use field::shm::{now_ns, DepositPublisher, FieldReader, ShmError, Svc};
use iceoryx2::node::Node;
use nalgebra::Matrix3;

use crate::depositor::Depositor;
use crate::follower::{Follower, PoseSource};
use crate::localizer::{Ekf, EkfSlam, EkfSlamConfig, LocalizerError};
use crate::messages::{CmdMsg, FollowerStatusMsg, PoseMsg, SensorMsg, TruthMsg};
use crate::scenario::Scenario;
use crate::world::World;

/// Steps without a new frame after which a follower checks whether its field is still alive.
const STALE_STEPS: u32 = 10;

/// Why a role's loop stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Shm(#[from] ShmError),
    #[error("scenario: {0}")]
    Setup(String),
    #[error(transparent)]
    Lockstep(#[from] LockstepError),
    #[error("robot {robot} sent no command for step {step} within {timeout_s} s (is its follower running?)")]
    Stalled {
        robot: u32,
        step: u64,
        timeout_s: f64,
    },
}

/// Service names of one robot.
#[derive(Debug, Clone)]
pub struct RobotServices {
    pub sensors: String,
    pub truth: String,
    pub pose: String,
    pub cmd: String,
    pub status: String,
}

impl RobotServices {
    /// Robots are named `r<ID>` within their world, so several simulations (or test runs) on one
    /// host never share a service.
    pub fn new(world: &str, robot: u32) -> Self {
        Self {
            sensors: format!("sim/{world}/r{robot}/sensors"),
            truth: format!("sim/{world}/r{robot}/truth"),
            pose: format!("pheromone/{world}/r{robot}/pose"),
            cmd: format!("pheromone/{world}/r{robot}/cmd"),
            status: format!("pheromone/{world}/r{robot}/status"),
        }
    }
}

fn wake(service: &str) -> String {
    format!("{service}-ready")
}

fn sender<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    service: &str,
) -> Result<Sender<T>, ShmError> {
    Sender::create(node, service, &wake(service), LinkOptions::default())
}

fn receiver<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    service: &str,
) -> Result<Receiver<T>, ShmError> {
    Receiver::create(node, service, &wake(service), LinkOptions::default())
}

/// Options of the world process.
#[derive(Debug, Clone)]
pub struct WorldOptions {
    pub world: String,
    pub field: String,
    /// Step on wall time (dt per step) instead of lockstep.
    pub realtime: bool,
    /// Lockstep: give up when a step has made no progress for this long.
    pub stall_timeout: Duration,
    /// Lockstep: how long every process of the run may take to join (None: 10 s + 0.5 s per
    /// process).
    pub attach_timeout: Option<Duration>,
    /// An observer (`pheromone sim`) takes part in the lockstep: the world waits for it to
    /// record each frame.
    pub observed: bool,
}

impl WorldOptions {
    /// The default attach timeout for `processes` processes: it grows with the run.
    pub fn default_attach_timeout(processes: usize) -> Duration {
        Duration::from_secs_f64(10.0 + 0.5 * processes as f64)
    }
}

/// What the world reports at the end.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSummary {
    pub steps: u64,
    pub sim_time_s: f64,
    pub robots: Vec<RobotSummary>,
    pub deposits_sent: u64,
    /// Stopped early by SIGINT/SIGTERM.
    pub interrupted: bool,
    /// Lockstep: seconds from the world's start until every process of the run had joined.
    pub startup_s: f64,
    /// Processes the world waited for (lockstep).
    pub participants: usize,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSummary {
    pub id: u32,
    pub true_pose: [f64; 3],
    pub distance_travelled_m: f64,
    pub collisions: u64,
}

/// The processes a lockstep run of `scenario` has besides the world: the field, and each
/// robot's localizer, depositor and follower where the scenario gives them (plus an observer
/// when `observed`).
pub fn lockstep_participants(scenario: &Scenario, observed: bool) -> usize {
    1 + observed as usize
        + scenario
            .robots
            .iter()
            .map(|r| 1 + r.depositor.is_some() as usize + r.follower.is_some() as usize)
            .sum::<usize>()
}

/// The world process: simulates, publishes sensors and truth, applies commands, makes the
/// scenario's scripted deposits and conducts the lockstep (`field::lockstep`).
pub fn run_world(
    node: &Node<Svc>,
    scenario: &Scenario,
    o: &WorldOptions,
) -> Result<WorldSummary, ProcessError> {
    let started = Instant::now();
    let mut world = World::new(scenario.world.clone(), scenario.seed)
        .map_err(|e| ProcessError::Setup(e.to_string()))?;
    let ids: Vec<u32> = scenario.world.robots.iter().map(|r| r.id).collect();
    let mut conductor = Conductor::create(node, &o.world, !o.realtime)?;
    let mut sensors = Vec::new();
    let mut truths = Vec::new();
    let mut cmds = Vec::new();
    for &id in &ids {
        let s = RobotServices::new(&o.world, id);
        sensors.push(sender::<SensorMsg>(node, &s.sensors)?);
        truths.push(sender::<TruthMsg>(node, &s.truth)?);
        // Only a robot with a follower sends commands; the others stand still.
        let driven = scenario.roles(id).is_some_and(|r| r.follower.is_some());
        cmds.push(if driven {
            Some(receiver::<CmdMsg>(node, &s.cmd)?)
        } else {
            None
        });
    }
    // Who acknowledges a step before the field ticks (depositors), and after (the field, the
    // observer); followers answer with their command.
    let depositors: Vec<(u32, u32)> = scenario
        .robots
        .iter()
        .filter(|r| r.depositor.is_some())
        .map(|r| (lockstep::role::DEPOSITOR, r.id))
        .collect();
    let mut after_tick = vec![(lockstep::role::FIELD, 0)];
    if o.observed {
        after_tick.push((lockstep::role::OBSERVER, 0));
    }
    let participants = lockstep_participants(scenario, o.observed);
    let mut startup = Duration::ZERO;
    if !o.realtime {
        let timeout = o
            .attach_timeout
            .unwrap_or_else(|| WorldOptions::default_attach_timeout(participants));
        startup = match conductor.wait_for_participants(
            node,
            participants,
            "field, localizers, depositors, followers, observer",
            timeout,
        ) {
            Ok(_) => started.elapsed(),
            Err(LockstepError::Interrupted { .. }) => {
                return Err(ProcessError::Setup(
                    "interrupted while waiting for the robot processes".into(),
                ))
            }
            Err(e) => return Err(e.into()),
        };
    }
    let mut scripted = std::collections::VecDeque::from(
        scenario
            .scripted(world.wall_segments())
            .map_err(ProcessError::Setup)?,
    );
    let mut depositor = if scripted.is_empty() {
        None
    } else {
        let mut d = DepositPublisher::attach_within(
            node,
            &o.field,
            WORLD_DEPOSITOR_ID,
            o.attach_timeout
                .unwrap_or_else(|| WorldOptions::default_attach_timeout(participants)),
        )?;
        // In lockstep the field acknowledges every tick: nothing is left to flush at the end.
        if !o.realtime {
            d.flush_timeout = Duration::ZERO;
        }
        Some(d)
    };
    let mut deposits_sent = 0u64;
    let mut distance = vec![0.0f64; ids.len()];
    let mut collisions = vec![0u64; ids.len()];
    let mut last_pose: Vec<_> = world.poses().to_vec();
    let mut commands = vec![(0.0, 0.0); ids.len()];
    let steps = scenario.steps();
    let dt = scenario.world.dt_secs;
    let mut next_wall = Instant::now();
    let mut stopped = false;
    let mut run = || -> Result<(), ProcessError> {
        for k in 0..steps {
            let outputs = world.step(&commands);
            for (i, p) in world.poses().iter().enumerate() {
                distance[i] += ((p.x_m - last_pose[i].x_m).powi(2)
                    + (p.y_m - last_pose[i].y_m).powi(2))
                .sqrt();
            }
            last_pose = world.poses().to_vec();
            // Scripted deposits due by now: in the field's queue before its tick for step k.
            while let Some((t, _)) = scripted.front() {
                if *t > world.sim_time_s() + 1e-9 {
                    break;
                }
                let (_, m) = scripted.pop_front().expect("checked above");
                if let Some(d) = depositor.as_mut() {
                    d.send(m)?;
                    deposits_sent += 1;
                }
            }
            let stamp = now_ns();
            for (i, out) in outputs.iter().enumerate() {
                collisions[i] += out.truth.collided as u64;
                let mut s = out.sensor;
                s.stamp_ns = stamp;
                s.step = k;
                sensors[i].send(s)?;
                let mut t = out.truth;
                t.stamp_ns = stamp;
                t.step = k;
                truths[i].send(t)?;
            }
            if o.realtime {
                conductor.tick(k, world.sim_time_s(), dt)?;
                next_wall += Duration::from_secs_f64(dt);
                if node
                    .wait(next_wall.saturating_duration_since(Instant::now()))
                    .is_err()
                {
                    stopped = true;
                    break;
                }
                for (i, rx) in cmds.iter().enumerate() {
                    let Some(rx) = rx else { continue };
                    if let Some(c) = rx.latest()? {
                        commands[i] = (c.v_mps, c.omega_radps);
                    }
                }
                continue;
            }
            let collected = conductor
                .collect(node, k, &depositors, o.stall_timeout)
                .and_then(|()| Ok(conductor.tick(k, world.sim_time_s(), dt)?))
                .and_then(|()| conductor.collect(node, k, &after_tick, o.stall_timeout));
            match collected {
                Ok(()) => {}
                Err(LockstepError::Interrupted { .. }) => {
                    stopped = true;
                    break;
                }
                Err(e) => return Err(e.into()),
            }
            for (i, rx) in cmds.iter().enumerate() {
                let Some(rx) = rx else { continue };
                let mut deadline = Instant::now() + o.stall_timeout;
                loop {
                    match rx.recv_timeout(Duration::from_millis(100))? {
                        Some(c) if c.step == k => {
                            commands[i] = (c.v_mps, c.omega_radps);
                            break;
                        }
                        Some(_) => deadline = Instant::now() + o.stall_timeout,
                        None => {}
                    }
                    if node.wait(Duration::ZERO).is_err() {
                        stopped = true;
                        break;
                    }
                    if Instant::now() > deadline {
                        return Err(ProcessError::Stalled {
                            robot: ids[i],
                            step: k,
                            timeout_s: o.stall_timeout.as_secs_f64(),
                        });
                    }
                }
                if stopped {
                    break;
                }
            }
            if stopped {
                break;
            }
        }
        Ok(())
    };
    let result = run();
    // Announce the end also after a failure, so every role stops.
    if let Err(e) = conductor.finish(world.step_count(), world.sim_time_s(), dt) {
        eprintln!("world '{}': could not announce the end: {e}", o.world);
    }
    result?;
    Ok(WorldSummary {
        steps: world.step_count(),
        sim_time_s: world.sim_time_s(),
        deposits_sent,
        interrupted: stopped,
        startup_s: startup.as_secs_f64(),
        participants: if o.realtime { 0 } else { participants },
        robots: ids
            .iter()
            .enumerate()
            .map(|(i, &id)| {
                let p = world.poses()[i];
                RobotSummary {
                    id,
                    true_pose: [p.x_m, p.y_m, p.theta_rad],
                    distance_travelled_m: distance[i],
                    collisions: collisions[i],
                }
            })
            .collect(),
    })
}

/// The robot id the world's scripted deposits carry: after every robot's in a tick's
/// canonical order (`field::shm::FieldServer::tick`).
pub const WORLD_DEPOSITOR_ID: u32 = u32::MAX;

/// Counters a robot role reports at the end.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoleSummary {
    pub robot: u32,
    pub role: String,
    pub steps: u64,
    pub rejected: u64,
    pub repeats: u64,
    pub last_step: Option<u64>,
}

/// How a robot role takes part in a run.
#[derive(Debug, Clone)]
pub struct RoleOptions {
    pub robot: u32,
    pub world: String,
    pub field: String,
    /// Lockstep (the default): a depositor acknowledges each step, a follower waits for the
    /// frame of its step. `false`: the world steps on wall time and nobody waits.
    pub lockstep: bool,
}

/// Runs `on_step` for every new message on `rx` until the world ends or a termination request.
/// A message with a step already handled calls `on_repeat` instead.
fn role_loop<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    end: &Participant,
    rx: &Receiver<T>,
    step_of: impl Fn(&T) -> u64,
    summary: &mut RoleSummary,
    mut on_step: impl FnMut(&T) -> Result<(), ProcessError>,
    mut on_repeat: impl FnMut() -> Result<(), ProcessError>,
) -> Result<(), ProcessError> {
    let mut handle = |m: &T, summary: &mut RoleSummary| -> Result<(), ProcessError> {
        let step = step_of(m);
        if summary.last_step.is_some_and(|l| step <= l) {
            summary.repeats += 1;
            on_repeat()
        } else {
            on_step(m)?;
            summary.steps += 1;
            summary.last_step = Some(step);
            Ok(())
        }
    };
    loop {
        if let Some(m) = rx.recv_timeout(Duration::from_millis(100))? {
            handle(&m, summary)?;
        }
        // Read the clock every round, not only when idle: a subscriber connects to the world's
        // publisher when it receives, and a world that ends before that connection exists
        // takes its last message with it.
        if end.finished()? {
            break;
        }
        if node.wait(Duration::ZERO).is_err() {
            return Ok(());
        }
    }
    // The world has ended, but a role that nobody waits on in lockstep (a localizer behind a
    // truth-steered follower) may still have the last steps queued or on their way from its
    // upstream role: handle them before leaving. Stop when the last step is in, when the
    // upstream is gone and its queue is empty, or after a bounded wait.
    let want_last = end.final_steps().and_then(|n| n.checked_sub(1));
    let deadline = Instant::now() + END_DRAIN;
    loop {
        // Read the upstream's presence before draining: what it sent before leaving stays
        // receivable (iceoryx2 keeps a connection that still holds samples).
        let upstream_gone = rx.senders() == 0;
        while let Some(m) = rx.try_recv()? {
            handle(&m, summary)?;
        }
        let complete = match (want_last, summary.last_step) {
            (Some(want), Some(last)) => last >= want,
            (None, _) => true,
            (Some(_), None) => false,
        };
        if complete || upstream_gone || Instant::now() >= deadline {
            return Ok(());
        }
        // Woken by the upstream's next message (or the bound).
        rx.wait(Duration::from_millis(50))?;
        if node.wait(Duration::ZERO).is_err() {
            return Ok(());
        }
    }
}

/// How long a role keeps handling its queue after the world announced the end.
const END_DRAIN: Duration = Duration::from_secs(3);

/// A role's summary before its first step.
fn summary_of(robot: u32, role: &str) -> RoleSummary {
    RoleSummary {
        robot,
        role: role.to_string(),
        ..Default::default()
    }
}

/// The localizer process: sensors → EKF → pose with covariance. The pose is stamped with the
/// step's simulated time: the robot's clock, which the depositor's interval rule reads.
pub fn run_localizer(
    node: &Node<Svc>,
    scenario: &Scenario,
    o: &RoleOptions,
    slam: bool,
) -> Result<RoleSummary, ProcessError> {
    let robot = o.robot;
    let mut filter = Filter::for_robot(scenario, robot, slam)?;
    let s = RobotServices::new(&o.world, robot);
    let sensors = receiver::<SensorMsg>(node, &s.sensors)?;
    let poses = sender::<PoseMsg>(node, &s.pose)?;
    let end = Participant::join(node, &o.world)?;
    let mut summary = summary_of(robot, "localizer");
    let last = std::cell::Cell::new(None::<PoseMsg>);
    let mut rejected = 0u64;
    role_loop(
        node,
        &end,
        &sensors,
        |m: &SensorMsg| m.step,
        &mut summary,
        |m| {
            if let Err(e) = filter.step(m) {
                rejected += 1;
                eprintln!("localizer r{robot}: step {} rejected: {e}", m.step);
            }
            let mut p = filter.to_msg(robot, m.step);
            p.stamp_ns = sim_stamp_ns(m.sim_time_s);
            poses.send(p)?;
            last.set(Some(p));
            Ok(())
        },
        || {
            if let Some(p) = last.get() {
                poses.send(p)?;
            }
            Ok(())
        },
    )?;
    summary.rejected = rejected;
    Ok(summary)
}

/// A simulated time as a message stamp (ns), the same in every mode.
pub fn sim_stamp_ns(sim_time_s: f64) -> u64 {
    (sim_time_s * 1e9).round() as u64
}

/// The depositor process: pose → deposits into the field. In lockstep it acknowledges each
/// step once its deposit is in the field's queue; a deposit the field did not take ends the run
/// (the field's answer would differ from a single-process run's).
pub fn run_depositor(
    node: &Node<Svc>,
    o: &RoleOptions,
    config: crate::depositor::DepositorConfig,
) -> Result<RoleSummary, ProcessError> {
    let robot = o.robot;
    let mut depositor = Depositor::new(config).map_err(|e| ProcessError::Setup(e.to_string()))?;
    let s = RobotServices::new(&o.world, robot);
    let poses = receiver::<PoseMsg>(node, &s.pose)?;
    let mut publisher =
        DepositPublisher::attach_within(node, &o.field, robot, Duration::from_secs(30))?;
    if o.lockstep {
        // The field acknowledges every tick: nothing is left to flush at the end.
        publisher.flush_timeout = Duration::ZERO;
    }
    let end = Participant::join(node, &o.world)?;
    let mut summary = summary_of(robot, "depositor");
    let mut rejected = 0u64;
    let lockstep = o.lockstep;
    role_loop(
        node,
        &end,
        &poses,
        |m: &PoseMsg| m.step,
        &mut summary,
        |p| {
            match depositor.process(p) {
                Ok(Some(d)) => match publisher.send(d) {
                    Ok(()) => {}
                    Err(e) if lockstep => return Err(e.into()),
                    Err(e) => eprintln!("depositor r{robot}: {e}"),
                },
                Ok(None) => {}
                Err(e) => {
                    rejected += 1;
                    eprintln!("depositor r{robot}: pose of step {} rejected: {e}", p.step);
                }
            }
            if lockstep {
                end.ack(p.step, lockstep::role::DEPOSITOR, robot)?;
            }
            Ok(())
        },
        || Ok(()),
    )?;
    summary.rejected = rejected;
    Ok(summary)
}

/// The follower process: pose + the frame of its step → command and status. The pose is the
/// localizer's estimate, or the world's truth for a follower configured to steer by it.
pub fn run_follower(
    node: &Node<Svc>,
    o: &RoleOptions,
    follower: Follower,
    source: PoseSource,
    dt_s: f64,
) -> Result<RoleSummary, ProcessError> {
    let s = RobotServices::new(&o.world, o.robot);
    match source {
        PoseSource::Estimate => follow(
            node,
            o,
            follower,
            dt_s,
            receiver::<PoseMsg>(node, &s.pose)?,
            |p: &PoseMsg| *p,
        ),
        PoseSource::Truth => follow(
            node,
            o,
            follower,
            dt_s,
            receiver::<TruthMsg>(node, &s.truth)?,
            crate::simulation::truth_as_pose,
        ),
    }
}

fn follow<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    o: &RoleOptions,
    mut follower: Follower,
    dt_s: f64,
    poses: Receiver<T>,
    to_pose: impl Fn(&T) -> PoseMsg,
) -> Result<RoleSummary, ProcessError> {
    let (robot, field_name) = (o.robot, o.field.as_str());
    let s = RobotServices::new(&o.world, robot);
    let cmds = sender::<CmdMsg>(node, &s.cmd)?;
    let statuses = sender::<FollowerStatusMsg>(node, &s.status)?;
    let mut reader = FieldReader::attach_within(node, field_name, Duration::from_secs(30))?;
    let end = Participant::join(node, &o.world)?;
    let mut summary = summary_of(robot, "follower");
    let last = std::cell::Cell::new(None::<CmdMsg>);
    let mut rejected = 0u64;
    let (mut stale_steps, mut field_gone) = (0u32, false);
    role_loop(
        node,
        &end,
        &poses,
        |m: &T| to_pose(m).step,
        &mut summary,
        |m| {
            let p = to_pose(m);
            if o.lockstep {
                // The frame the field computed for this step (sequence step + 1), and no other.
                let want = p.step + 1;
                loop {
                    reader.update()?;
                    if reader.frame().is_some_and(|f| f.header.sequence >= want) {
                        break;
                    }
                    if end.conductor_gone() || node.wait(Duration::ZERO).is_err() {
                        return Ok(());
                    }
                    reader.wait_frame(Duration::from_millis(100))?;
                }
            } else if reader.update()? {
                // A field that died leaves its last frame with the reader: steer on it, say
                // so once, and say when a field of that name publishes again.
                stale_steps = 0;
                if field_gone {
                    field_gone = false;
                    eprintln!("follower r{robot}: field '{field_name}' is publishing again");
                }
            } else {
                stale_steps += 1;
                if stale_steps >= STALE_STEPS && !field_gone && !reader.field_alive() {
                    field_gone = true;
                    eprintln!(
                        "follower r{robot}: field '{field_name}' is gone; steering on its last frame until it returns"
                    );
                }
            }
            if reader.frame().is_none() {
                reader.wait_frame(Duration::from_secs(5))?;
            }
            let Some(frame) = reader.frame() else {
                return Err(ProcessError::Shm(ShmError::NoField {
                    field: field_name.to_string(),
                    service: format!("pheromone/{field_name}/frame"),
                }));
            };
            let (mut cmd, status) = match follower.step_pose(&frame.view, &p, dt_s) {
                Ok(out) => (out.cmd, Some(out.status)),
                Err(e) => {
                    rejected += 1;
                    eprintln!(
                        "follower r{robot}: step {}: {e}; stopping the robot",
                        p.step
                    );
                    (
                        CmdMsg {
                            robot_id: robot,
                            ..Default::default()
                        },
                        None,
                    )
                }
            };
            cmd.step = p.step;
            cmd.stamp_ns = now_ns();
            cmds.send(cmd)?;
            if let Some(mut st) = status {
                st.step = p.step;
                st.stamp_ns = cmd.stamp_ns;
                statuses.send(st)?;
            }
            last.set(Some(cmd));
            Ok(())
        },
        || {
            if let Some(c) = last.get() {
                cmds.send(c)?;
            }
            Ok(())
        },
    )?;
    summary.rejected = rejected;
    Ok(summary)
}

/// The localizer's filter: landmark-based EKF, or EKF-SLAM (faer) when the map is unknown.
pub enum Filter {
    Ekf(Box<Ekf>),
    Slam(Box<EkfSlam>),
}

impl Filter {
    /// The filter of robot `robot` as the scenario configures it (start pose, initial σ,
    /// noise, loss); EKF-SLAM if `slam`.
    pub fn for_robot(scenario: &Scenario, robot: u32, slam: bool) -> Result<Self, ProcessError> {
        let roles = scenario
            .roles(robot)
            .ok_or_else(|| ProcessError::Setup(format!("robot {robot} has no [[robot]] entry")))?;
        let start = scenario
            .world
            .robots
            .iter()
            .find(|r| r.id == robot)
            .ok_or_else(|| ProcessError::Setup(format!("robot {robot} is not in the world")))?
            .start;
        let var = roles.initial_sigma_m.powi(2);
        let cov0 = Matrix3::from_diagonal(&nalgebra::Vector3::new(var, var, (0.05f64).powi(2)));
        Ok(if slam {
            // EKF-SLAM: landmarks are not given, they join the state as they are seen.
            if let Some(region) = roles.localizer.landmark_region_m {
                return Err(ProcessError::Setup(format!(
                    "robot {robot}: `{}` = {region:?} restricts the known map of the EKF; EKF-SLAM (--slam) has no map to restrict",
                    crate::localizer::LANDMARK_REGION_KEY
                )));
            }
            let config = EkfSlamConfig {
                noise: roles.localizer.noise,
                limits: roles.localizer.limits,
                ..EkfSlamConfig::default()
            };
            Filter::Slam(Box::new(
                EkfSlam::new(config, start, cov0)
                    .map_err(|e| ProcessError::Setup(e.to_string()))?,
            ))
        } else {
            Filter::Ekf(Box::new(
                Ekf::new(
                    roles.localizer,
                    scenario.world.landmarks.clone(),
                    start,
                    cov0,
                )
                .map_err(|e| ProcessError::Setup(e.to_string()))?,
            ))
        })
    }

    pub fn step(&mut self, m: &SensorMsg) -> Result<(), LocalizerError> {
        match self {
            Filter::Ekf(f) => f.step(m).map(|_| ()),
            Filter::Slam(f) => f.step(m).map(|_| ()),
        }
    }

    pub fn to_msg(&self, robot: u32, step: u64) -> PoseMsg {
        match self {
            Filter::Ekf(f) => f.to_msg(robot, step),
            Filter::Slam(f) => f.to_msg(robot, step),
        }
    }
}
