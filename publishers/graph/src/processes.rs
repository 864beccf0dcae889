//! A `regions` run as processes, in lockstep: one graph writer ([`run_graph_writer`], the
//! `pheromone graph` process) owns the [`GraphWorld`] and the clock; every robot is its own
//! process ([`run_graph_robot`], `pheromone graph-robot`).
//!
//! Each step the writer publishes a [`GraphSnapshot`] (state, step, time, the claims of the
//! previous step). Every robot reads it without a copy, runs [`GraphRobot::step`], sends its
//! updates and, for a claim, its contention message to every robot, then a step-done message.
//! When all robots are done the writer applies the updates in robot order and opens the next
//! step. Claimants exchange their messages over the contention service and decide alike.
//!
//! A run whose robots localize ([`RobotOptions::localization`], `graph-robot --localize`):
//! each robot process owns its localizer, an on-robot filter fed by the robot's own true motion
//! on the graph and seeded per robot exactly as in one process, so its steps are the same. Its
//! ρ_t-weighted link deposits go out in the ordinary update messages (the amount is already
//! there); its landmark counts and step times travel once, in its end-of-run report, from which
//! whoever collects the reports builds the run's η1, η2 ([`super::run::RunReport::add_localization`]).

use std::time::Duration;

use iceoryx2::node::Node;
use pheromone_field::process::link::{Receiver, Sender};
use pheromone_field::process::lockstep::{self, JoinWatch};
use pheromone_field::shm::{now_ns, Svc};

use super::agent::{GraphStrategy, RegionsScenario};
use super::localize::Localization;
use super::run::{GraphRobot, GraphWorld, RobotReport, RunReport, StepView};
use super::shm::{
    graph_services, kind, Contention, GraphReader, GraphShmError, GraphSnapshot, GraphUpdateMsg,
    GraphUpdater, MAX_GRAPH_ROBOTS, NO_CLAIM, SNAPSHOT_LINK, UPDATE_LINK,
};
use super::GraphUpdate;

/// Options of the graph writer.
#[derive(Debug, Clone)]
pub struct WriterOptions {
    /// Name of the graph (its services are `pheromone/<NAME>/…`).
    pub name: String,
    pub robots: usize,
    pub strategy: GraphStrategy,
    pub seed: u64,
    /// How long to wait for every robot to attach.
    pub attach_timeout: Duration,
    /// How long one step may wait for the robots before the run fails.
    pub stall_timeout: Duration,
}

#[derive(Debug, thiserror::Error)]
pub enum GraphRunError {
    #[error(transparent)]
    Shm(#[from] GraphShmError),
    #[error("robots {robots}: a graph run takes 1 to {max}")]
    Robots { robots: usize, max: usize },
    #[error("graph '{name}': {listening} of {robots} robots listen for contention messages after {waited_s:.1} s")]
    NoListeners {
        name: String,
        listening: usize,
        robots: usize,
        waited_s: f64,
    },
    #[error(transparent)]
    Lockstep(#[from] pheromone_field::process::lockstep::LockstepError),
    #[error("graph '{name}': the writer is gone (last step seen: {step})")]
    WriterGone { name: String, step: u64 },
    #[error("graph '{0}': interrupted")]
    Interrupted(String),
}

impl From<pheromone_field::shm::ShmError> for GraphRunError {
    fn from(e: pheromone_field::shm::ShmError) -> Self {
        GraphRunError::Shm(e.into())
    }
}

pheromone_field::from_shm_errors!(GraphRunError);

impl From<super::GraphError> for GraphRunError {
    fn from(e: super::GraphError) -> Self {
        GraphRunError::Shm(e.into())
    }
}

/// The graph writer: runs the clock until the goal is reached or the time is up, and reports
/// what the run did.
pub fn run_graph_writer(
    node: &Node<Svc>,
    scenario: &RegionsScenario,
    o: &WriterOptions,
) -> Result<RunReport, GraphRunError> {
    if o.robots == 0 || o.robots > MAX_GRAPH_ROBOTS {
        return Err(GraphRunError::Robots {
            robots: o.robots,
            max: MAX_GRAPH_ROBOTS,
        });
    }
    let mut world = GraphWorld::new(scenario, o.strategy, o.robots, o.seed)?;
    let [(snap, snap_wake), (upd, upd_wake), _] = graph_services(&o.name);
    let snapshots: Sender<GraphSnapshot> = Sender::create(node, &snap, &snap_wake, SNAPSHOT_LINK)?;
    let updates: Receiver<GraphUpdateMsg> = Receiver::create(node, &upd, &upd_wake, UPDATE_LINK)?;
    let joins = JoinWatch::create(node, &o.name)?;
    // Every robot reads the first snapshot: wait until all are attached.
    // The lockstep of `pheromone_field::process::lockstep`: every robot joins once its ports exist.
    joins.wait(node, o.robots, "graph robots", o.attach_timeout, || {
        snapshots.receivers().min(updates.senders())
    })?;
    let publish = |world: &GraphWorld, finished: bool| -> Result<(), GraphShmError> {
        let mut s = GraphSnapshot::from_state(&world.state)?;
        s.seq = world.step() + 1;
        s.stamp_ns = now_ns();
        s.step = world.step();
        s.sim_time_s = world.time_s() as f64;
        s.finished = finished as u32;
        s.updates_applied = world.applied;
        s.updates_rejected = world.rejected;
        s.captures_refused = world.refused;
        s.set_claims(world.claims());
        snapshots.send(s)?;
        Ok(())
    };
    let result = (|| -> Result<(), GraphRunError> {
        while !world.finished() {
            publish(&world, false)?;
            let step = world.step();
            let mut outputs: Vec<(u32, Vec<GraphUpdate>, Option<usize>)> = (1..=o.robots as u32)
                .map(|id| (id, Vec::new(), None))
                .collect();
            let mut missing: Vec<u32> = (1..=o.robots as u32).collect();
            let rejected = &mut world.rejected;
            lockstep::collect_step(
                node,
                &o.name,
                step,
                &mut missing,
                o.stall_timeout,
                |id| format!("graph-robot R{id}"),
                |timeout| {
                    let Some(m) = updates.recv_timeout(timeout)? else {
                        return Ok(None);
                    };
                    let i = m.robot_id.wrapping_sub(1) as usize;
                    if i >= o.robots || m.step != step {
                        *rejected += 1;
                        return Ok(None);
                    }
                    if m.kind == kind::STEP_DONE {
                        outputs[i].2 = (m.region != NO_CLAIM).then_some(m.region as usize);
                        return Ok(Some(m.robot_id));
                    }
                    match m.update() {
                        Ok(u) => outputs[i].1.push(u),
                        Err(_) => *rejected += 1,
                    }
                    Ok(None)
                },
            )?;
            world.end_step(outputs);
        }
        Ok(())
    })();
    // Announce the end also after a failure, so every robot stops. After a failure that error
    // is the one to report; after a run that went well, a robot that never hears of the end
    // is one.
    let announced = publish(&world, true);
    match (&result, announced) {
        (Err(_), Err(e)) => eprintln!("graph '{}': could not announce the end: {e}", o.name),
        (Ok(()), Err(e)) => return Err(e.into()),
        (_, Ok(())) => {}
    }
    result?;
    Ok(world.report())
}

/// Options of one robot process.
#[derive(Clone)]
pub struct RobotOptions<'a> {
    /// Name of the graph to attach to.
    pub name: String,
    /// 0-based index of the robot (id = index + 1).
    pub index: usize,
    pub robots: usize,
    pub strategy: GraphStrategy,
    pub seed: u64,
    /// How long to wait for the other robots and for each step.
    pub timeout: Duration,
    /// The robot localizes on landmarks (paper 001 Algorithm 1): it owns its filter and its
    /// sensors, seeded per robot as in one process, and weighs its link deposits by ρ_t
    /// before they go out in its update messages.
    pub localization: Option<Localization<'a>>,
}

/// One robot process: index `o.index` (id = index + 1) of `o.robots`.
pub fn run_graph_robot(
    node: &Node<Svc>,
    scenario: &RegionsScenario,
    o: &RobotOptions,
) -> Result<RobotReport, GraphRunError> {
    let (name, robots, timeout) = (o.name.as_str(), o.robots, o.timeout);
    let base = scenario.state()?;
    let mut robot = GraphRobot::new(scenario, &base, o.index, o.strategy, o.seed)?;
    if let Some(loc) = &o.localization {
        robot.localize(loc, &base.graph, o.seed)?;
    }
    let mut reader = GraphReader::attach(node, name)?;
    let updater = GraphUpdater::attach(node, name, robot.id())?;
    let mut contention = Contention::attach(node, name)?;
    // Every port of this robot exists: tell the writer (`pheromone_field::process::lockstep`).
    let _joined = lockstep::announce_join(node, name)?;
    if !contention.wait_listeners(robots, timeout)? {
        return Err(GraphRunError::NoListeners {
            name: name.to_string(),
            listening: contention.listeners(),
            robots,
            waited_s: timeout.as_secs_f64(),
        });
    }
    let mut seq = 0u64;
    let mut last_step = None;
    loop {
        let snap = loop {
            if let Some(s) = reader.wait_newer(seq, Duration::from_millis(100))? {
                break *s;
            }
            if pheromone_field::shm::should_stop(node) {
                return Err(GraphRunError::Interrupted(name.to_string()));
            }
            if reader.writers() == 0 && seq > 0 {
                return Err(GraphRunError::WriterGone {
                    name: name.to_string(),
                    step: last_step.unwrap_or(0),
                });
            }
        };
        seq = snap.seq;
        if snap.finished != 0 {
            return Ok(robot.report(&base.graph));
        }
        // Claims of the previous step are resolved in this one; anything older is stale.
        contention.drain(snap.step.saturating_sub(1))?;
        let state = snap.apply_to(&base)?;
        let claims = snap.claims();
        let view = StepView {
            step: snap.step,
            time_s: snap.sim_time_s as f32,
            state: &state,
            claims: &claims,
        };
        let out = robot.step(&view, |region, step, expected| {
            contention.collect(region as u32, step, expected, timeout)
        })?;
        for u in out.updates {
            updater.send_at(snap.step, u)?;
        }
        if let Some(m) = &out.announce {
            contention.announce(m)?;
        }
        updater.step_done(snap.step, out.claim)?;
        last_step = Some(snap.step);
    }
}
