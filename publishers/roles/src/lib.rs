//! The robot roles, each a library type (deterministic for a seed, testable in-process) plus a
//! short process loop in its `run` module: the world (simulator and lockstep conductor), the
//! localizer (EKF, EKF-SLAM), the depositor and the follower (gradient, antenna, route, sector
//! strategies). [`role_loop`] holds what every role's loop shares: the robots' service names,
//! the options and summary of a role, and the loop that handles one message per step.

pub mod depositor;
pub mod follower;
pub mod localizer;
pub mod mapper;
pub mod process;
pub mod scenario;
pub mod team;
pub mod world;

pub use process::depositor::run_depositor;
pub use process::follower::{run_follower, OwnMap};
pub use process::localizer::{run_localizer, Filter};
pub use process::mapper::{run_mapper, MapperSummary};
pub(crate) use process::role_loop::{receiver, role_loop, sender, summary_of};
pub use process::role_loop::{sim_stamp_ns, ProcessError, RobotServices, RoleOptions, RoleSummary};
pub use process::world::{
    lockstep_participants, mapper_robots, run_world, RobotSummary, WorldOptions, WorldSummary,
};
pub use scenario::WORLD_DEPOSITOR_ID;
