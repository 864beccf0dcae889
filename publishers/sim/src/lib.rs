//! Running a scenario: its file format (`pheromone_world::scenario`), the single-process runner ([`single`]),
//! the run as separate processes ([`processes`]) with its supervisor (`pheromone_supervisor`) and [`observer`],
//! what a run records ([`recording`]; as a ROS 2 MCAP file, [`ros_record`] and the observer's
//! [`ros_feed`]) and the metrics computed from it ([`metrics`], seed 000's
//! `wrong_area` in [`wrong_area`]), and seed 004's grid of experiments ([`sweep`], its statistics in
//! [`sweep_stats`], the paper's own figures beside it in [`paper`], split over a scheduler's tasks
//! and joined again in [`sweep_shard`]), and seed 004's comparison of
//! two strategies over seeds ([`trials`], `sim --trials`), and seed 001's constant against
//! ρ_t-weighted link deposits over seeds ([`localize_trials`], `sim <regions scenario> --trials`).

pub mod exploration;
pub mod localize_trials;
pub mod metrics;
pub mod observer;
pub mod paper;
pub mod processes;
pub mod radio;
pub mod recording;
pub mod ros_feed;
pub mod ros_record;
pub mod single;
pub mod sweep;
pub mod sweep_shard;
pub mod sweep_stats;
pub mod trail_sweep;
pub mod trials;
pub mod wrong_area;
