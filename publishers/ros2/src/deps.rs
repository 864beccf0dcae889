//! The one place this crate names the project's other crates (the depositor library of `roles`,
//! the pose and truth messages of `messages`, the Zenoh session settings of `bridge`).

pub use messages::{PoseMsg, TruthMsg};
pub use roles::depositor;

/// The bridge's Zenoh session settings (peer mode, no multicast scouting, listen/connect).
#[cfg(feature = "zenoh")]
pub use bridge::{listen_locators, session_config_with, with_admin_space, Security};
