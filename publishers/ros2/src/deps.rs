//! The one place this crate names `pheromone-publishers` (the depositor library, the pose
//! message, the Zenoh session settings of the bridge): repoint these aliases when those modules
//! move crates.

pub use publishers::messages::PoseMsg;
pub use publishers::roles::depositor;

/// The bridge's Zenoh session settings (peer mode, no multicast scouting, listen/connect).
#[cfg(feature = "zenoh")]
pub use publishers::bridge::{listen_locators, session_config, with_admin_space};
