//! The world's process loop: it simulates, and conducts the lockstep of the run.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::process::link::{Receiver, Sender};
use pheromone_field::process::lockstep::{self, Conductor, LockstepError};
use pheromone_field::shm::{now_ns, DepositPublisher, Svc};
use pheromone_field::DepositMsg;

use crate::scenario::{Scenario, WORLD_DEPOSITOR_ID};
use crate::{StepOutput, World, WorldPose};
use pheromone_messages::{CmdMsg, LaserMsg, RendezvousMsg, ScanMsg, SensorMsg, TruthMsg};
use pheromone_roles::{receiver, sender, ProcessError, RobotServices};

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
    /// One mapper per robot (`pheromone mapper`) takes part when the scenario maps: the world
    /// waits for each one's map frame of every step.
    pub mapped: bool,
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
/// when `observed`, and one mapper per robot of the world when `mapped` and the scenario maps).
pub fn lockstep_participants(scenario: &Scenario, observed: bool, mapped: bool) -> usize {
    1 + observed as usize
        + mapper_robots(scenario, mapped).len()
        + scenario
            .robots
            .iter()
            .map(|r| 1 + r.depositor.is_some() as usize + r.follower.is_some() as usize)
            .sum::<usize>()
}

/// The robots whose mapper takes part in a run (every robot of the world when `mapped` and the
/// scenario maps; none otherwise).
pub fn mapper_robots(scenario: &Scenario, mapped: bool) -> Vec<u32> {
    if mapped && scenario.mapping().is_some() {
        scenario.world.robots.iter().map(|r| r.id).collect()
    } else {
        Vec::new()
    }
}

/// The world process: simulates, publishes sensors and truth, applies commands, makes the
/// scenario's scripted deposits and conducts the lockstep (`pheromone_field::process::lockstep`).
pub fn run_world(
    node: &Node<Svc>,
    scenario: &Scenario,
    o: &WorldOptions,
) -> Result<WorldSummary, ProcessError> {
    let mut run = WorldRun::start(node, scenario, o)?;
    let result = run.steps(scenario.steps());
    run.finish(result)
}

/// The world's ports to each robot, in the order of the world's robots.
struct RobotPorts {
    /// Seed 004's scan and rendezvous of each robot, when the scenario maps.
    mapping: Vec<(Sender<ScanMsg>, Sender<RendezvousMsg>)>,
    /// The commands of each robot with a follower (None: it stands still).
    cmds: Vec<Option<Receiver<CmdMsg>>>,
    truths: Vec<Sender<TruthMsg>>,
    sensors: Vec<Sender<SensorMsg>>,
    /// Seed 000's laser scan of each robot, when the world has a laser.
    lasers: Vec<Sender<LaserMsg>>,
}

impl RobotPorts {
    /// Opens the ports of robots `ids` of world `world`.
    fn open(
        node: &Node<Svc>,
        scenario: &Scenario,
        world: &str,
        ids: &[u32],
    ) -> Result<Self, ProcessError> {
        let mut sensors = Vec::new();
        let mut truths = Vec::new();
        let mut cmds = Vec::new();
        let mut mapping = Vec::new();
        let mut lasers = Vec::new();
        for &id in ids {
            let s = RobotServices::new(world, id);
            if scenario.world.laser.is_some() {
                lasers.push(sender::<LaserMsg>(node, &s.laser)?);
            }
            sensors.push(sender::<SensorMsg>(node, &s.sensors)?);
            truths.push(sender::<TruthMsg>(node, &s.truth)?);
            if scenario.mapping().is_some() {
                mapping.push((
                    sender::<ScanMsg>(node, &s.scan)?,
                    sender::<RendezvousMsg>(node, &s.rendezvous)?,
                ));
            }
            // Only a robot with a follower sends commands; the others stand still.
            let driven = scenario.roles(id).is_some_and(|r| r.follower.is_some());
            cmds.push(if driven {
                Some(receiver::<CmdMsg>(node, &s.cmd)?)
            } else {
                None
            });
        }
        Ok(Self {
            mapping,
            cmds,
            truths,
            sensors,
            lasers,
        })
    }

    /// Publishes step `k`'s laser scans, sensors, truth, scans and rendezvous, stamped
    /// `stamp`. A laser scan goes first: the localizer has it when the step's sensors wake it.
    fn publish(
        &self,
        k: u64,
        stamp: u64,
        outputs: &[StepOutput],
        sensed: &[(ScanMsg, RendezvousMsg)],
        lasers: &[LaserMsg],
    ) -> Result<(), ProcessError> {
        for (tx, laser) in self.lasers.iter().zip(lasers) {
            tx.send(LaserMsg {
                stamp_ns: stamp,
                step: k,
                ..*laser
            })?;
        }
        for (i, out) in outputs.iter().enumerate() {
            let mut s = out.sensor;
            s.stamp_ns = stamp;
            s.step = k;
            self.sensors[i].send(s)?;
            let mut t = out.truth;
            t.stamp_ns = stamp;
            t.step = k;
            self.truths[i].send(t)?;
        }
        for ((scan_tx, rv_tx), (scan, rv)) in self.mapping.iter().zip(sensed) {
            scan_tx.send(ScanMsg {
                stamp_ns: stamp,
                step: k,
                ..*scan
            })?;
            rv_tx.send(RendezvousMsg {
                stamp_ns: stamp,
                step: k,
                ..*rv
            })?;
        }
        Ok(())
    }
}

/// Who acknowledges a lockstep step before the field ticks: the depositors.
fn acks_before_tick(scenario: &Scenario) -> Vec<(u32, u32)> {
    scenario
        .robots
        .iter()
        .filter(|r| r.depositor.is_some())
        .map(|r| (lockstep::role::DEPOSITOR, r.id))
        .collect()
}

/// Who acknowledges a lockstep step after the field ticks: the field, the observer, mappers.
fn acks_after_tick(scenario: &Scenario, o: &WorldOptions) -> Vec<(u32, u32)> {
    let mut after_tick = vec![(lockstep::role::FIELD, 0)];
    if o.observed {
        after_tick.push((lockstep::role::OBSERVER, 0));
    }
    for id in mapper_robots(scenario, o.mapped) {
        after_tick.push((lockstep::role::MAPPER, id));
    }
    after_tick
}

/// Lockstep: waits until the run's `participants` have joined; the time since `started`.
fn await_participants(
    conductor: &Conductor,
    node: &Node<Svc>,
    o: &WorldOptions,
    participants: usize,
    started: Instant,
) -> Result<Duration, ProcessError> {
    let timeout = o
        .attach_timeout
        .unwrap_or_else(|| WorldOptions::default_attach_timeout(participants));
    match conductor.wait_for_participants(
        node,
        participants,
        "field, localizers, depositors, followers, observer",
        timeout,
    ) {
        Ok(_) => Ok(started.elapsed()),
        Err(e @ LockstepError::Interrupted { .. }) => Err(ProcessError::Interrupted(e)),
        Err(e) => Err(e.into()),
    }
}

/// The publisher of the scenario's scripted deposits, when it has any.
fn scripted_depositor(
    node: &Node<Svc>,
    o: &WorldOptions,
    participants: usize,
    any: bool,
) -> Result<Option<DepositPublisher>, ProcessError> {
    if !any {
        return Ok(None);
    }
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
    Ok(Some(d))
}

/// The world process's state from its start to its summary.
struct WorldRun<'a> {
    /// First, so dropped (and flushed) before the other ports.
    depositor: Option<DepositPublisher>,
    node: &'a Node<Svc>,
    o: &'a WorldOptions,
    world: World,
    ids: Vec<u32>,
    ports: RobotPorts,
    conductor: Conductor,
    before_tick: Vec<(u32, u32)>,
    after_tick: Vec<(u32, u32)>,
    participants: usize,
    startup: Duration,
    scripted: VecDeque<(f64, DepositMsg)>,
    deposits_sent: u64,
    distance: Vec<f64>,
    collisions: Vec<u64>,
    last_pose: Vec<WorldPose>,
    commands: Vec<(f64, f64)>,
    dt: f64,
    next_wall: Instant,
    /// Stopped early by SIGINT/SIGTERM.
    stopped: bool,
}

impl<'a> WorldRun<'a> {
    /// Builds the world, opens its ports, awaits the run (lockstep), attaches the depositor.
    fn start(
        node: &'a Node<Svc>,
        scenario: &Scenario,
        o: &'a WorldOptions,
    ) -> Result<Self, ProcessError> {
        let started = Instant::now();
        let mut world =
            World::new(scenario.world.clone(), scenario.seed).map_err(ProcessError::from)?;
        if let Some(m) = scenario.mapping() {
            world.enable_mapping(m, scenario.seed);
        }
        let ids: Vec<u32> = scenario.world.robots.iter().map(|r| r.id).collect();
        let conductor = Conductor::create(node, &o.world, !o.realtime)?;
        let ports = RobotPorts::open(node, scenario, &o.world, &ids)?;
        let participants = lockstep_participants(scenario, o.observed, o.mapped);
        let startup = if o.realtime {
            Duration::ZERO
        } else {
            await_participants(&conductor, node, o, participants, started)?
        };
        let scripted = VecDeque::from(scenario.scripted(world.wall_segments())?);
        let depositor = scripted_depositor(node, o, participants, !scripted.is_empty())?;
        let n = ids.len();
        Ok(Self {
            depositor,
            node,
            o,
            last_pose: world.poses().to_vec(),
            world,
            ids,
            ports,
            conductor,
            before_tick: acks_before_tick(scenario),
            after_tick: acks_after_tick(scenario, o),
            participants,
            startup,
            scripted,
            deposits_sent: 0,
            distance: vec![0.0; n],
            collisions: vec![0; n],
            commands: vec![(0.0, 0.0); n],
            dt: scenario.world.dt_s,
            next_wall: Instant::now(),
            stopped: false,
        })
    }

    /// Runs steps 0..`steps`, or until stopped by SIGINT/SIGTERM.
    fn steps(&mut self, steps: u64) -> Result<(), ProcessError> {
        for k in 0..steps {
            self.simulate(k)?;
            let stopped = if self.o.realtime {
                self.realtime_commands(k)?
            } else {
                self.lockstep_commands(k)?
            };
            if stopped {
                self.stopped = true;
                break;
            }
        }
        Ok(())
    }

    /// Step `k` of the simulation: moves the robots, sends the deposits due, publishes.
    fn simulate(&mut self, k: u64) -> Result<(), ProcessError> {
        let outputs = self.world.step(&self.commands);
        let sensed = self.world.mapping_outputs();
        let lasers = self.world.laser_outputs();
        for (i, p) in self.world.poses().iter().enumerate() {
            let last = &self.last_pose[i];
            self.distance[i] += ((p.x_m - last.x_m).powi(2) + (p.y_m - last.y_m).powi(2)).sqrt();
        }
        self.last_pose = self.world.poses().to_vec();
        self.send_scripted()?;
        let stamp = now_ns();
        for (i, out) in outputs.iter().enumerate() {
            self.collisions[i] += out.truth.collided as u64;
        }
        self.ports.publish(k, stamp, &outputs, &sensed, &lasers)
    }

    /// Scripted deposits due by now: in the field's queue before its tick for this step.
    fn send_scripted(&mut self) -> Result<(), ProcessError> {
        while let Some((t, _)) = self.scripted.front() {
            if *t > self.world.sim_time_s() + 1e-9 {
                break;
            }
            let (_, m) = self.scripted.pop_front().expect("checked above");
            if let Some(d) = self.depositor.as_mut() {
                d.send(m)?;
                self.deposits_sent += 1;
            }
        }
        Ok(())
    }

    /// On wall time: ticks, waits until the step's time, takes the latest commands; true: stopped.
    fn realtime_commands(&mut self, k: u64) -> Result<bool, ProcessError> {
        self.conductor.tick(k, self.world.sim_time_s(), self.dt)?;
        self.next_wall += Duration::from_secs_f64(self.dt);
        if pheromone_field::shm::node_wait(
            self.node,
            self.next_wall.saturating_duration_since(Instant::now()),
        )
        .is_err()
        {
            return Ok(true);
        }
        for (i, rx) in self.ports.cmds.iter().enumerate() {
            let Some(rx) = rx else { continue };
            if let Some(c) = rx.latest()? {
                self.commands[i] = (c.v_m_per_s, c.omega_rad_per_s);
            }
        }
        Ok(false)
    }

    /// Lockstep: the acknowledgements around the tick, then each command; true: stopped.
    fn lockstep_commands(&mut self, k: u64) -> Result<bool, ProcessError> {
        let (node, stall, t) = (self.node, self.o.stall_timeout, self.world.sim_time_s());
        let collected = self
            .conductor
            .collect(node, k, &self.before_tick, stall)
            .and_then(|()| Ok(self.conductor.tick(k, t, self.dt)?))
            .and_then(|()| self.conductor.collect(node, k, &self.after_tick, stall));
        match collected {
            Ok(()) => {}
            Err(LockstepError::Interrupted { .. }) => return Ok(true),
            Err(e) => return Err(e.into()),
        }
        for (i, rx) in self.ports.cmds.iter().enumerate() {
            let Some(rx) = rx else { continue };
            match await_command(node, rx, k, self.ids[i], stall)? {
                Some(c) => self.commands[i] = c,
                None => return Ok(true),
            }
        }
        Ok(false)
    }

    /// Announces the end (also after a failure, so every role stops), then sums up the run.
    fn finish(self, result: Result<(), ProcessError>) -> Result<WorldSummary, ProcessError> {
        let (steps, sim_time_s) = (self.world.step_count(), self.world.sim_time_s());
        if let Err(e) = self.conductor.finish(steps, sim_time_s, self.dt) {
            eprintln!("world '{}': could not announce the end: {e}", self.o.world);
        }
        result?;
        Ok(WorldSummary {
            steps,
            sim_time_s,
            deposits_sent: self.deposits_sent,
            interrupted: self.stopped,
            startup_s: self.startup.as_secs_f64(),
            participants: if self.o.realtime {
                0
            } else {
                self.participants
            },
            robots: self
                .ids
                .iter()
                .enumerate()
                .map(|(i, &id)| {
                    let p = self.world.poses()[i];
                    RobotSummary {
                        id,
                        true_pose: [p.x_m, p.y_m, p.theta_rad],
                        distance_travelled_m: self.distance[i],
                        collisions: self.collisions[i],
                    }
                })
                .collect(),
        })
    }
}

/// Lockstep: robot `robot`'s command of step `k`, `stall` at most without progress; None: stopped.
fn await_command(
    node: &Node<Svc>,
    rx: &Receiver<CmdMsg>,
    k: u64,
    robot: u32,
    stall: Duration,
) -> Result<Option<(f64, f64)>, ProcessError> {
    let mut deadline = Instant::now() + stall;
    loop {
        match rx.recv_timeout(Duration::from_millis(100))? {
            Some(c) if c.step == k => return Ok(Some((c.v_m_per_s, c.omega_rad_per_s))),
            Some(_) => deadline = Instant::now() + stall,
            None => {}
        }
        if pheromone_field::shm::should_stop(node) {
            return Ok(None);
        }
        if Instant::now() > deadline {
            return Err(ProcessError::Stalled {
                robot,
                step: k,
                timeout_s: stall.as_secs_f64(),
            });
        }
    }
}
