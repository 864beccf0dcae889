//! The process loops: each role is a library type driven by a short loop that waits on iceoryx2
//! events (never sleeps). Lockstep: the world publishes step k (sensors, truth, clock), waits
//! for every robot's command for step k, then advances. While it waits it re-sends step k every
//! `RESEND` so a role that attached late still gets it; the roles answer a repeated step by
//! repeating their last output instead of computing it twice.

use std::time::{Duration, Instant};

use field::link::{LinkOptions, Receiver, Sender};
use field::messages::{clock_services, ClockMsg};
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

/// How often the world re-sends a step nobody has answered yet.
const RESEND: Duration = Duration::from_millis(200);

/// Why a role's loop stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Shm(#[from] ShmError),
    #[error("scenario: {0}")]
    Setup(String),
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

/// Watches the world's clock for the end of the run: its `finished` message, or the world's
/// clock publisher disappearing after it was seen (a world that ended, or died, before this
/// subscriber connected to it).
struct EndWatch {
    clock: Receiver<ClockMsg>,
    /// The world has been seen attached (so its absence later means it is gone).
    seen: std::cell::Cell<bool>,
    /// The world's step count when it announced the end.
    final_steps: std::cell::Cell<Option<u64>>,
}

impl EndWatch {
    fn new(node: &Node<Svc>, world: &str) -> Result<Self, ShmError> {
        let (service, wake) = clock_services(world);
        Ok(Self {
            clock: Receiver::create(
                node,
                &service,
                &wake,
                LinkOptions {
                    keep_latest: false,
                    buffer: 1024,
                    ..LinkOptions::default()
                },
            )?,
            seen: std::cell::Cell::new(false),
            final_steps: std::cell::Cell::new(None),
        })
    }

    /// True once the world has announced the end (drains the clock queue).
    fn finished(&self) -> Result<bool, ShmError> {
        let mut done = false;
        while let Some(m) = self.clock.try_recv()? {
            if m.finished != 0 {
                done = true;
                self.final_steps.set(Some(m.step));
            }
        }
        let world_attached = self.clock.senders() > 0;
        let world_gone = self.seen.get() && !world_attached;
        self.seen.set(self.seen.get() | world_attached);
        Ok(done || world_gone)
    }

    /// The world's step count at its announced end (None when it vanished without one).
    fn final_steps(&self) -> Option<u64> {
        self.final_steps.get()
    }
}

/// Options of the world process.
#[derive(Debug, Clone)]
pub struct WorldOptions {
    pub world: String,
    pub field: String,
    /// Step on wall time (dt per step) instead of lockstep.
    pub realtime: bool,
    /// Lockstep: give up when a robot has not answered a step for this long.
    pub stall_timeout: Duration,
}

/// What the world reports at the end.
#[derive(Debug, Clone, serde::Serialize)]
pub struct WorldSummary {
    pub steps: u64,
    pub sim_time_s: f64,
    pub robots: Vec<RobotSummary>,
    pub deposits_sent: u64,
    /// Stopped early by SIGINT/SIGTERM.
    pub interrupted: bool,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct RobotSummary {
    pub id: u32,
    pub true_pose: [f64; 3],
    pub distance_travelled_m: f64,
    pub collisions: u64,
}

/// The world process: simulates, publishes sensors/truth/clock, applies commands, and makes the
/// scenario's scripted deposits.
pub fn run_world(
    node: &Node<Svc>,
    scenario: &Scenario,
    o: &WorldOptions,
) -> Result<WorldSummary, ProcessError> {
    let mut world = World::new(scenario.world.clone(), scenario.seed)
        .map_err(|e| ProcessError::Setup(e.to_string()))?;
    let ids: Vec<u32> = scenario.world.robots.iter().map(|r| r.id).collect();
    let (clock_service, clock_wake) = clock_services(&o.world);
    let clock = Sender::<ClockMsg>::create(
        node,
        &clock_service,
        &clock_wake,
        LinkOptions {
            keep_latest: false,
            buffer: 1024,
            ..LinkOptions::default()
        },
    )?;
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
    let mut scripted = std::collections::VecDeque::from(
        scenario
            .scripted(world.wall_segments())
            .map_err(ProcessError::Setup)?,
    );
    let mut depositor = if scripted.is_empty() {
        None
    } else {
        Some(DepositPublisher::attach_within(
            node,
            &o.field,
            u32::MAX,
            Duration::from_secs(30),
        )?)
    };
    let mut deposits_sent = 0u64;
    let mut distance = vec![0.0f64; ids.len()];
    let mut collisions = vec![0u64; ids.len()];
    let mut last_pose: Vec<_> = world.poses().to_vec();
    let mut commands = vec![(0.0, 0.0); ids.len()];
    let steps = scenario.steps();
    let dt = scenario.world.dt_secs;
    // Lockstep: wait until the field and every robot role of the scenario watch the clock, so
    // none misses the start (or the end) of the run.
    if !o.realtime {
        let expected = 1 + scenario
            .robots
            .iter()
            .map(|r| 1 + r.depositor.is_some() as usize + r.follower.is_some() as usize)
            .sum::<usize>();
        let since = Instant::now();
        while clock.receivers() < expected {
            if since.elapsed() > o.stall_timeout {
                return Err(ProcessError::Setup(format!(
                    "only {} of the {expected} processes of the scenario (field, localizers, depositors, followers) attached within {} s",
                    clock.receivers(),
                    o.stall_timeout.as_secs_f64()
                )));
            }
            if node.wait(Duration::from_millis(5)).is_err() {
                return Err(ProcessError::Setup(
                    "interrupted while waiting for the robot processes".into(),
                ));
            }
        }
    }
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
            // Scripted deposits due by now.
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
            let publish = |outputs: &[crate::world::StepOutput]| -> Result<(), ShmError> {
                let stamp = now_ns();
                clock.send(ClockMsg {
                    stamp_ns: stamp,
                    step: k,
                    sim_time_s: world.sim_time_s(),
                    dt_secs: dt,
                    finished: 0,
                    _pad: 0,
                })?;
                for (i, out) in outputs.iter().enumerate() {
                    let mut s = out.sensor;
                    s.stamp_ns = stamp;
                    s.step = k;
                    sensors[i].send(s)?;
                    let mut t = out.truth;
                    t.stamp_ns = stamp;
                    t.step = k;
                    truths[i].send(t)?;
                }
                Ok(())
            };
            for (i, out) in outputs.iter().enumerate() {
                collisions[i] += out.truth.collided as u64;
            }
            publish(&outputs)?;
            if o.realtime {
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
            } else {
                for (i, rx) in cmds.iter().enumerate() {
                    let Some(rx) = rx else { continue };
                    let since = Instant::now();
                    let mut last_send = Instant::now();
                    loop {
                        match rx.recv_timeout(RESEND)? {
                            Some(c) if c.step == k => {
                                commands[i] = (c.v_mps, c.omega_radps);
                                break;
                            }
                            Some(_) => continue, // an answer to an older step
                            None => {}
                        }
                        if node.wait(Duration::ZERO).is_err() {
                            stopped = true;
                            break;
                        }
                        if since.elapsed() > o.stall_timeout {
                            return Err(ProcessError::Stalled {
                                robot: ids[i],
                                step: k,
                                timeout_s: o.stall_timeout.as_secs_f64(),
                            });
                        }
                        if last_send.elapsed() >= RESEND {
                            publish(&outputs)?;
                            last_send = Instant::now();
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
        }
        Ok(())
    };
    let result = run();
    // Announce the end also after a failure, so every role stops.
    let _ = clock.send(ClockMsg {
        stamp_ns: now_ns(),
        step: world.step_count(),
        sim_time_s: world.sim_time_s(),
        dt_secs: dt,
        finished: 1,
        _pad: 0,
    });
    result?;
    Ok(WorldSummary {
        steps: world.step_count(),
        sim_time_s: world.sim_time_s(),
        deposits_sent,
        interrupted: stopped,
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

/// Counters a robot role reports at the end.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct RoleSummary {
    pub robot: u32,
    pub role: &'static str,
    pub steps: u64,
    pub rejected: u64,
    pub repeats: u64,
    pub last_step: Option<u64>,
}

/// Runs `on_step` for every new message on `rx` until the world ends or a termination request.
/// A message with a step already handled calls `on_repeat` instead.
fn role_loop<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    end: &EndWatch,
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
    // The world has ended, but a role that nobody waits on in lockstep (a depositor, a localizer
    // behind a truth-steered follower) may still have the last steps queued or on their way
    // from its upstream role: handle them before leaving. Stop when the last step is in, when
    // the upstream is gone and its queue is empty, or after a bounded wait.
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
        if node.wait(Duration::from_millis(2)).is_err() {
            return Ok(());
        }
    }
}

/// How long a role keeps handling its queue after the world announced the end.
const END_DRAIN: Duration = Duration::from_secs(3);

/// The localizer process: sensors → EKF → pose with covariance.
pub fn run_localizer(
    node: &Node<Svc>,
    scenario: &Scenario,
    robot: u32,
    world: &str,
    slam: bool,
) -> Result<RoleSummary, ProcessError> {
    let mut filter = Filter::for_robot(scenario, robot, slam)?;
    let s = RobotServices::new(world, robot);
    let sensors = receiver::<SensorMsg>(node, &s.sensors)?;
    let poses = sender::<PoseMsg>(node, &s.pose)?;
    let end = EndWatch::new(node, world)?;
    let mut summary = RoleSummary {
        robot,
        role: "localizer",
        ..Default::default()
    };
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
            p.stamp_ns = now_ns();
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

/// The depositor process: pose → deposits into the field.
pub fn run_depositor(
    node: &Node<Svc>,
    robot: u32,
    world: &str,
    field_name: &str,
    config: crate::depositor::DepositorConfig,
) -> Result<RoleSummary, ProcessError> {
    let mut depositor = Depositor::new(config).map_err(|e| ProcessError::Setup(e.to_string()))?;
    let s = RobotServices::new(world, robot);
    let poses = receiver::<PoseMsg>(node, &s.pose)?;
    let mut publisher =
        DepositPublisher::attach_within(node, field_name, robot, Duration::from_secs(30))?;
    let end = EndWatch::new(node, world)?;
    let mut summary = RoleSummary {
        robot,
        role: "depositor",
        ..Default::default()
    };
    let mut rejected = 0u64;
    role_loop(
        node,
        &end,
        &poses,
        |m: &PoseMsg| m.step,
        &mut summary,
        |p| {
            match depositor.process(p) {
                Ok(Some(d)) => {
                    if let Err(e) = publisher.send(d) {
                        eprintln!("depositor r{robot}: {e}");
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    rejected += 1;
                    eprintln!("depositor r{robot}: pose of step {} rejected: {e}", p.step);
                }
            }
            Ok(())
        },
        || Ok(()),
    )?;
    summary.rejected = rejected;
    Ok(summary)
}

/// The follower process: pose + newest frame → command and status. The pose is the
/// localizer's estimate, or the world's truth for a follower configured to steer by it.
pub fn run_follower(
    node: &Node<Svc>,
    robot: u32,
    world: &str,
    field_name: &str,
    follower: Follower,
    source: PoseSource,
    dt_secs: f64,
) -> Result<RoleSummary, ProcessError> {
    let s = RobotServices::new(world, robot);
    match source {
        PoseSource::Estimate => follow(
            node,
            robot,
            world,
            field_name,
            follower,
            dt_secs,
            receiver::<PoseMsg>(node, &s.pose)?,
            |p: &PoseMsg| *p,
        ),
        PoseSource::Truth => follow(
            node,
            robot,
            world,
            field_name,
            follower,
            dt_secs,
            receiver::<TruthMsg>(node, &s.truth)?,
            |t: &TruthMsg| PoseMsg {
                step: t.step,
                robot_id: t.robot_id,
                x_m: t.x_m,
                y_m: t.y_m,
                theta_rad: t.theta_rad,
                ..PoseMsg::default()
            },
        ),
    }
}

#[allow(clippy::too_many_arguments)]
fn follow<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    robot: u32,
    world: &str,
    field_name: &str,
    mut follower: Follower,
    dt_secs: f64,
    poses: Receiver<T>,
    to_pose: impl Fn(&T) -> PoseMsg,
) -> Result<RoleSummary, ProcessError> {
    let s = RobotServices::new(world, robot);
    let cmds = sender::<CmdMsg>(node, &s.cmd)?;
    let statuses = sender::<FollowerStatusMsg>(node, &s.status)?;
    let mut reader = FieldReader::attach_within(node, field_name, Duration::from_secs(30))?;
    let end = EndWatch::new(node, world)?;
    let mut summary = RoleSummary {
        robot,
        role: "follower",
        ..Default::default()
    };
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
            // A field that died leaves its last frame with the reader: steer on it, say so
            // once, and say when a field of that name publishes again.
            if reader.update()? {
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
            let (mut cmd, status) = match follower.step_pose(&frame.view, &p, dt_secs) {
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
