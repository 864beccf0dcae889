//! # pheromone publishers
//!
//! The robot roles that attach to the field: world (simulator), localizer, depositor and
//! follower. Each is a library type, deterministic for a seed and testable in-process, plus a
//! short process loop.

#[cfg(feature = "zenoh")]
pub mod bridge;
pub mod export;
pub mod gateway;
pub mod graph;
pub mod messages;
pub mod report;
pub mod roles;
pub mod sim;
pub mod view;
