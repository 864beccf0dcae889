//! The process loop of an antenna robot that reads its antennas from an [`AntennaSource`]
//! (`pheromone follower --strategy antenna --gateway udp://HOST:PORT`): pose → readings →
//! command and status on the robot's services with the world. With a gateway source nothing of
//! the field is opened in shared memory.

use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::process::link::Receiver;
use pheromone_field::process::lockstep::Participant;
use serde::{Deserialize, Serialize};

use crate::follower::antenna_source::{AntennaRobot, AntennaSource, AntennaStepError, SourceStats};
use crate::follower::PoseSource;
use crate::radio::{Exchange, RadioConfig, RadioConfigError, SharedAir};
use crate::{
    receiver, role_loop, sender, summary_of, ProcessError, RobotServices, RoleOptions, RoleSummary,
};
use pheromone_field::shm::Svc;
use pheromone_messages::{CmdMsg, FollowerStatusMsg, PoseMsg, TruthMsg};

/// Deposits an antenna robot makes through its gateway as it goes (a leader laying a trail
/// remotely).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RemoteDeposits {
    /// Amount of each deposit (field units).
    pub amount: f32,
    /// One deposit at the robot's pose every this many steps.
    pub every_steps: u64,
}

/// How an antenna robot runs.
#[derive(Debug, Clone)]
pub struct AntennaRunOptions {
    pub steer_by: PoseSource,
    pub dt_s: f64,
    /// Lockstep: how long a step may wait for the frame of its step before the robot fails.
    pub frame_timeout: Duration,
    pub deposits: Option<RemoteDeposits>,
    /// The simulated shared air (`[radio]`): a step whose request the air does not deliver
    /// reads nothing and keeps the last command.
    pub air: Option<ClientAir>,
}

/// One thin client's view of the simulated shared air ([`SharedAir`]): whether its request of
/// each step gets its reply. Every process that builds it from the same configuration, period
/// and seed sees the same outcomes (the sim's `metrics.radio` too).
#[derive(Debug, Clone)]
pub struct ClientAir {
    air: SharedAir,
    client: u32,
    /// The periods resolved so far.
    resolved: u64,
    last: Exchange,
    stats: RadioClientStats,
}

/// What the air did to one client's requests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RadioClientStats {
    /// The client's index on the air (its robot ID).
    pub client: u32,
    /// Requests (one per step).
    pub sent: u64,
    pub delivered: u64,
    /// Sum of the delivered requests' latencies (ns).
    pub latency_sum_ns: u64,
}

impl ClientAir {
    /// Client `client` of the air of `config` for a control period of `period_s`, from `seed`.
    pub fn new(
        config: &RadioConfig,
        client: u32,
        period_s: f64,
        seed: u64,
    ) -> Result<Self, RadioConfigError> {
        if client >= config.clients {
            return Err(RadioConfigError {
                key: "clients",
                value: config.clients.to_string(),
                expected: "more clients than the highest ID of a robot through the gateway",
            });
        }
        Ok(Self {
            air: SharedAir::new(config, period_s, seed)?,
            client,
            resolved: 0,
            last: Exchange::default(),
            stats: RadioClientStats {
                client,
                ..RadioClientStats::default()
            },
        })
    }

    /// This client's exchange of `step` (period `step` of the air); steps come in order, a
    /// step asked again gets the same answer and is counted once.
    pub fn exchange(&mut self, step: u64) -> Exchange {
        while self.resolved <= step {
            self.last = self.air.next_period()[self.client as usize];
            self.resolved += 1;
            if self.resolved == step + 1 {
                self.stats.sent += 1;
                if self.last.delivered {
                    self.stats.delivered += 1;
                    self.stats.latency_sum_ns += self.last.latency_ns;
                }
            }
        }
        self.last
    }

    pub fn stats(&self) -> RadioClientStats {
        self.stats
    }
}

/// An antenna robot's summary: the role's counters and its source's.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct AntennaRobotSummary {
    pub role: RoleSummary,
    pub source: SourceStats,
    /// With `[radio]`: what the simulated air did to the robot's requests.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radio: Option<RadioClientStats>,
}

/// The antenna robot process: pose (estimate, or the world's truth) → readings from `robot`'s
/// source → command and status. In lockstep each step reads the frame of its step (sequence
/// `step + 1`, see [`crate::follower::antenna_source`]).
pub fn run_antenna_robot<S: AntennaSource>(
    node: &Node<Svc>,
    o: &RoleOptions,
    robot: AntennaRobot<S>,
    run: AntennaRunOptions,
) -> Result<AntennaRobotSummary, ProcessError> {
    let s = RobotServices::new(&o.world, o.robot);
    match run.steer_by {
        PoseSource::Estimate => drive(
            node,
            o,
            robot,
            run,
            receiver::<PoseMsg>(node, &s.pose)?,
            |p: &PoseMsg| *p,
        ),
        PoseSource::Truth => drive(
            node,
            o,
            robot,
            run,
            receiver::<TruthMsg>(node, &s.truth)?,
            pheromone_messages::truth_as_pose,
        ),
    }
}

/// How long one wait for the frame of a step lasts before Ctrl-C and the world's end are looked
/// at again.
const WAIT_SLICE: Duration = Duration::from_millis(100);

/// What one step's wait for its frame gave.
enum StepRead {
    /// The follower's output for this step.
    Out(crate::follower::FollowOutput),
    /// The step's input was refused (the robot stops for this step).
    Rejected(String),
    /// Ctrl-C, or the world ended, while waiting.
    Stop,
}

/// Waits, in slices of [`WAIT_SLICE`], for the reading of frame `want` and the follower's output
/// for pose `p`; no reading within the run's frame timeout is an error naming the source.
fn read_step<S: AntennaSource>(
    robot: &mut AntennaRobot<S>,
    (node, end): (&Node<Svc>, &Participant),
    p: &PoseMsg,
    run: &AntennaRunOptions,
    want: u64,
) -> Result<StepRead, ProcessError> {
    let give_up = Instant::now() + run.frame_timeout;
    loop {
        let slice = (Instant::now() + WAIT_SLICE).min(give_up);
        match robot.step_pose(p, run.dt_s, want, slice) {
            Ok(Some((out, _))) => return Ok(StepRead::Out(out)),
            Ok(None) if Instant::now() < give_up => {
                if end.conductor_gone() || pheromone_field::shm::should_stop(node) {
                    return Ok(StepRead::Stop);
                }
            }
            Ok(None) => {
                return Err(ProcessError::AntennaSource(format!(
                    "{}: no reading from frame {want} (step {}) within {:.1} s",
                    robot.source().name(),
                    p.step,
                    run.frame_timeout.as_secs_f64()
                )))
            }
            Err(AntennaStepError::Input(e)) => return Ok(StepRead::Rejected(e.to_string())),
            Err(AntennaStepError::Source(e)) => {
                return Err(ProcessError::AntennaSource(e.to_string()))
            }
        }
    }
}

/// The run's deposit at pose `p` when this step is one of every `every_steps`. Applied at most
/// once (the client never resends a deposit to the other gateway); a deposit that got no answer
/// is counted by the source, and the robot goes on.
fn deposit_if_due<S: AntennaSource>(
    robot: &mut AntennaRobot<S>,
    run: &AntennaRunOptions,
    p: &PoseMsg,
) {
    let Some(d) = run.deposits else {
        return;
    };
    if d.every_steps > 0 && p.step.is_multiple_of(d.every_steps) {
        let channel = robot.channel();
        if let Err(e) = robot
            .source_mut()
            .deposit(p.x_m as f32, p.y_m as f32, d.amount, channel)
        {
            eprintln!("follower r{}: step {}: deposit: {e}", p.robot_id, p.step);
        }
    }
}

fn drive<
    S: AntennaSource,
    T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static,
>(
    node: &Node<Svc>,
    o: &RoleOptions,
    mut robot: AntennaRobot<S>,
    mut run: AntennaRunOptions,
    poses: Receiver<T>,
    to_pose: impl Fn(&T) -> PoseMsg,
) -> Result<AntennaRobotSummary, ProcessError> {
    let id = o.robot;
    let s = RobotServices::new(&o.world, id);
    let cmds = sender::<CmdMsg>(node, &s.cmd)?;
    let statuses = sender::<FollowerStatusMsg>(node, &s.status)?;
    let end = Participant::join(node, &o.world)?;
    let mut summary = summary_of(id, "follower");
    let last = std::cell::Cell::new(None::<CmdMsg>);
    let mut rejected = 0u64;
    let mut air = run.air.take();
    role_loop(
        node,
        &end,
        &poses,
        |m: &T| to_pose(m).step,
        &mut summary,
        |m| {
            let p = to_pose(m);
            // The air lost this step's request (or its reply): nothing read, the last command
            // held, as a microcontroller keeps its set-points.
            if air.as_mut().is_some_and(|a| !a.exchange(p.step).delivered) {
                let held = last.get().unwrap_or(CmdMsg {
                    robot_id: id,
                    ..Default::default()
                });
                return crate::process::follower::send_step(
                    &cmds,
                    &statuses,
                    &last,
                    p.step,
                    (held, None),
                );
            }
            // Lockstep: the frame the field computed for this step, and no older one.
            let want = if o.lockstep { p.step + 1 } else { 0 };
            let out = match read_step(&mut robot, (node, &end), &p, &run, want)? {
                StepRead::Out(out) => Some(out),
                StepRead::Rejected(e) => {
                    rejected += 1;
                    eprintln!("follower r{id}: step {}: {e}; stopping the robot", p.step);
                    None
                }
                StepRead::Stop => return Ok(()),
            };
            let (cmd, status) = match out {
                Some(out) => (out.cmd, Some(out.status)),
                None => (
                    CmdMsg {
                        robot_id: id,
                        ..Default::default()
                    },
                    None,
                ),
            };
            crate::process::follower::send_step(&cmds, &statuses, &last, p.step, (cmd, status))?;
            if status.is_some() {
                deposit_if_due(&mut robot, &run, &p);
            }
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
    Ok(AntennaRobotSummary {
        role: summary,
        source: robot.source().stats(),
        radio: air.map(|a| a.stats()),
    })
}
