//! The one place this crate names the project's other crates (the depositor library of `roles`,
//! the pose and truth messages of `messages`, the Zenoh session settings of `bridge`).

pub use pheromone_messages::{PoseMsg, TruthMsg};
pub use pheromone_roles::depositor;

/// The bridge's TLS and credential settings, its admin-space switch and the listening ports it
/// reads there.
#[cfg(feature = "zenoh")]
pub use pheromone_bridge::{listen_locators, with_admin_space, Security};
