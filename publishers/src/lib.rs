//! # pheromone publishers
//!
//! The robot roles that attach to the field: world (simulator), localizer, depositor and
//! follower. Each is a library type, deterministic for a seed and testable in-process, plus a
//! short process loop.

pub mod depositor;
pub mod follower;
pub mod graph;
pub mod localizer;
pub mod messages;
pub mod metrics;
pub mod observer;
pub mod process;
pub mod process_run;
pub mod record;
pub mod report;
pub mod scenario;
pub mod simulation;
pub mod supervisor;
pub mod world;
