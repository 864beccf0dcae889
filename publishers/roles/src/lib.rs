//! The robot roles, each a library type (deterministic for a seed, testable in-process) plus a
//! short process loop in its `run` module: the world (simulator and lockstep conductor), the
//! localizer (EKF, EKF-SLAM), the depositor and the follower (gradient, antenna, route, sector
//! strategies). [`role_loop`] holds what every role's loop shares: the robots' service names,
//! the options and summary of a role, and the loop that handles one message per step.

pub mod depositor;
pub mod follower;
pub mod localizer;
pub mod mapper;
pub mod role_loop;
pub mod scenario;
mod scenario_error;
mod scenario_map;
mod scenario_mapping;
pub mod world;

pub use depositor::run::run_depositor;
pub use follower::run::run_follower;
pub use localizer::run::{run_localizer, Filter};
pub use mapper::run::{run_mapper, MapperSummary};
pub(crate) use role_loop::{receiver, role_loop, sender, summary_of};
pub use role_loop::{sim_stamp_ns, ProcessError, RobotServices, RoleOptions, RoleSummary};
pub use world::run::{
    lockstep_participants, mapper_robots, run_world, RobotSummary, WorldOptions, WorldSummary,
    WORLD_DEPOSITOR_ID,
};
