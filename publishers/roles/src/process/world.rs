//! The world's process loop: it simulates, and conducts the lockstep of the run.

use std::time::{Duration, Instant};

use field::lockstep::{self, Conductor, LockstepError};
use field::shm::{now_ns, DepositPublisher, Svc};
use iceoryx2::node::Node;

use crate::scenario::{Scenario, WORLD_DEPOSITOR_ID};
use crate::world::World;
use crate::{receiver, sender, ProcessError, RobotServices};
use messages::{CmdMsg, RendezvousMsg, ScanMsg, SensorMsg, TruthMsg};

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
/// scenario's scripted deposits and conducts the lockstep (`field::lockstep`).
pub fn run_world(
    node: &Node<Svc>,
    scenario: &Scenario,
    o: &WorldOptions,
) -> Result<WorldSummary, ProcessError> {
    let started = Instant::now();
    let mut world =
        World::new(scenario.world.clone(), scenario.seed).map_err(ProcessError::World)?;
    if let Some(m) = scenario.mapping() {
        world.enable_mapping(m, scenario.seed);
    }
    let ids: Vec<u32> = scenario.world.robots.iter().map(|r| r.id).collect();
    let mut conductor = Conductor::create(node, &o.world, !o.realtime)?;
    let mut sensors = Vec::new();
    let mut truths = Vec::new();
    let mut cmds = Vec::new();
    // Seed 004's scan and rendezvous of each robot, when the scenario maps.
    let mut mapping = Vec::new();
    for &id in &ids {
        let s = RobotServices::new(&o.world, id);
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
    for id in mapper_robots(scenario, o.mapped) {
        after_tick.push((lockstep::role::MAPPER, id));
    }
    let participants = lockstep_participants(scenario, o.observed, o.mapped);
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
            Err(e @ LockstepError::Interrupted { .. }) => return Err(ProcessError::Interrupted(e)),
            Err(e) => return Err(e.into()),
        };
    }
    let mut scripted = std::collections::VecDeque::from(scenario.scripted(world.wall_segments())?);
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
    let dt = scenario.world.dt_s;
    let mut next_wall = Instant::now();
    let mut stopped = false;
    let mut run = || -> Result<(), ProcessError> {
        for k in 0..steps {
            let outputs = world.step(&commands);
            let sensed = world.mapping_outputs();
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
            for ((scan_tx, rv_tx), (scan, rv)) in mapping.iter_mut().zip(&sensed) {
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
                        commands[i] = (c.v_m_per_s, c.omega_rad_per_s);
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
                            commands[i] = (c.v_m_per_s, c.omega_rad_per_s);
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
