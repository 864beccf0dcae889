//! The process loops: each role is a library type driven by a short loop that waits on iceoryx2
//! events (never sleeps). In lockstep (the default) the world conducts every step as
//! `pheromone_field::process::lockstep` describes: each role joins the run after creating its ports, a depositor
//! acknowledges each step once its deposit is sent, and a follower steers on the frame the field
//! computed for the step, so a run as processes gives the single-process answer.

use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::process::link::{Receiver, Sender};
use pheromone_field::process::lockstep::{LockstepError, Participant};
use pheromone_field::shm::{AttachError, ShmError, Svc};
use pheromone_field::ConfigError;

use crate::depositor::DepositorConfigError;
use crate::follower::FollowerConfigError;
use crate::localizer::LocalizerError;

/// Why a role's loop stopped with an error. The set-up errors (`scenario: …`) keep the error of
/// the scenario part that was refused as their source.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Shm(#[from] ShmError),
    /// The configuration a role was built from (a scenario, the world it describes) refused a
    /// part: that part's error is the source.
    #[error("scenario: {0}")]
    Setup(#[source] Box<dyn std::error::Error + Send + Sync + 'static>),
    /// The field of a single-process run cannot be built.
    #[error("scenario: {0}")]
    Field(#[source] ConfigError),
    #[error("scenario: {}{source}", robot_prefix(.robot))]
    Depositor {
        /// The robot, where the error names it.
        robot: Option<u32>,
        #[source]
        source: DepositorConfigError,
    },
    #[error("scenario: robot {robot}: {source}")]
    Follower {
        robot: u32,
        #[source]
        source: FollowerConfigError,
    },
    #[error("scenario: {0}")]
    Localizer(#[source] LocalizerError),
    #[error("scenario: mapping: {0}")]
    Mapping(#[source] crate::mapper::MapError),
    #[error("scenario: robot {robot} has no mapper: the scenario does not map ([mapping]) or the robot is not in the world")]
    NotMapping { robot: u32 },
    #[error("scenario: robot {robot} has no [[robot]] entry")]
    NoRoles { robot: u32 },
    #[error("scenario: robot {robot} is not in the world")]
    NotInWorld { robot: u32 },
    #[error("scenario: robot {robot}: `{key}` = {region:?} restricts the known map of the EKF; EKF-SLAM (--slam) has no map to restrict")]
    SlamRegion {
        robot: u32,
        key: &'static str,
        region: [f64; 4],
    },
    #[error("scenario: interrupted while waiting for the robot processes")]
    Interrupted(#[source] LockstepError),
    #[error(transparent)]
    Lockstep(#[from] LockstepError),
    /// An antenna robot got no readings from its source (gateway, or the field).
    #[error("antenna readings: {0}")]
    AntennaSource(String),
    #[error("robot {robot} sent no command for step {step} within {timeout_s} s (is its follower running?)")]
    Stalled {
        robot: u32,
        step: u64,
        timeout_s: f64,
    },
}

pheromone_field::from_shm_errors!(ProcessError);

pub use pheromone_field::wire::RobotServices;
use pheromone_field::wire::{ready_service as wake, ROBOT_LINK};

/// `robot N: ` where an error names the robot.
fn robot_prefix(robot: &Option<u32>) -> String {
    robot.map(|r| format!("robot {r}: ")).unwrap_or_default()
}

/// A sender of `T` on robot link `service` (with its `…-ready` wake-up event).
pub fn sender<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    service: &str,
) -> Result<Sender<T>, AttachError> {
    Sender::create(node, service, &wake(service), ROBOT_LINK)
}

/// A receiver of `T` on robot link `service` (woken by its `…-ready` event).
pub fn receiver<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    service: &str,
) -> Result<Receiver<T>, AttachError> {
    Receiver::create(node, service, &wake(service), ROBOT_LINK)
}

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
    /// How a reader of the field (the follower) waits for the frame of its step in lockstep
    /// (`FieldReader::wait_frame_with`); the result is the same for every policy, only the
    /// latency and the CPU spent waiting differ.
    pub frame_wait: pheromone_field::shm::WaitPolicy,
}

/// Runs `on_step` for every new message on `rx` until the world ends or a termination request.
/// A message with a step already handled calls `on_repeat` instead.
pub(crate) fn role_loop<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
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
        if pheromone_field::shm::should_stop(node) {
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
        if pheromone_field::shm::should_stop(node) {
            return Ok(());
        }
    }
}

/// How long a role keeps handling its queue after the world announced the end.
const END_DRAIN: Duration = Duration::from_secs(3);

/// A role's summary before its first step.
pub(crate) fn summary_of(robot: u32, role: &str) -> RoleSummary {
    RoleSummary {
        robot,
        role: role.to_string(),
        ..Default::default()
    }
}

/// A simulated time as a message stamp (ns), the same in every mode.
pub fn sim_stamp_ns(sim_time_s: f64) -> u64 {
    (sim_time_s * 1e9).round() as u64
}
