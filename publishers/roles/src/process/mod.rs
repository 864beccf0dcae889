//! The process loop of each role: set up from its configuration, then a short loop that waits on its
//! inputs (iceoryx2 events) and publishes its outputs, in lockstep with the world.

pub mod depositor;
pub mod follower;
pub mod follower_antenna;
pub mod follower_remote;
pub mod localizer;
pub mod mapper;
pub mod role_loop;
