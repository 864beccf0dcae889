//! The robot stack: the roles that run on a robot, each a library type (deterministic for a
//! seed, testable in-process) plus a short process loop in [`process`]: the localizer (EKF, UKF,
//! particle filter, EKF-SLAM), the depositor, the follower (gradient, antenna, route, sector
//! strategies) and seed 004's mapper. Nothing here knows the simulator: a role takes its own
//! configuration ([`LocalizerSetup`], [`MapperSetup`], `DepositorConfig`, `FollowerConfig`) and
//! the messages of `pheromone-messages`; the simulated world, the scenario files that build
//! these configurations and the lockstep conductor are `pheromone-world`. `process::role_loop` holds
//! what every role's loop shares: the robots' service names, the options and summary of a role,
//! and the loop that handles one message per step.

pub mod depositor;
pub mod follower;
pub mod localizer;
pub mod mapper;
pub mod process;
/// Seed 002's shared air between a gateway's thin clients (the remote antenna robot's radio).
pub use pheromone_gateway::radio;

pub use process::depositor::run_depositor;
pub use process::follower::{run_follower, OwnMap};
pub use process::localizer::{run_localizer, Filter, LocalizerSetup};
pub use process::mapper::{run_mapper, MapperSetup, MapperSummary};
pub use process::role_loop::{
    receiver, sender, sim_stamp_ns, ProcessError, RobotServices, RoleOptions, RoleSummary,
};
pub(crate) use process::role_loop::{role_loop, summary_of};
