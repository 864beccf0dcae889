//! ROS 2 without ROS: the field on ROS 2 topics through Zenoh, in the wire format of
//! `rmw_zenoh_cpp` (ROS 2's Zenoh middleware), with messages in CDR (docs/ros2.md).
//!
//! - [`types`]: message descriptions, DDS type names, RIHS01 type hashes, `ros2msg` schemas.
//! - [`cdr`]: the CDR writer and reader.
//! - [`grid`]: a frame as `grid_map_msgs/msg/GridMap` and `nav_msgs/msg/OccupancyGrid`.
//! - [`pose`]: `geometry_msgs/msg/PoseWithCovarianceStamped` → the depositor's pose.
//! - [`robot`]: poses (`PoseWithCovarianceStamped`), paths (`nav_msgs/msg/Path`) and deposits
//!   (`pheromone_msgs/msg/Deposit`), what `pheromone sim --record` writes besides the field.
//! - [`robots`]: a simulated world's robots (truth and localizer links) as pose and path
//!   messages, for the node's `--world`.
//! - [`rmw_zenoh`]: rmw_zenoh's key expressions, liveliness tokens, GIDs and attachments.
//! - [`frames`]: the topics of a field and the messages of its current frame.
//! - [`record`]: ROS 2 MCAP files.
//! - `session` (feature `zenoh`): the Zenoh session configured as rmw_zenoh configures a node's.
//! - `node` (feature `zenoh`): the node itself — publishers, `--deposit-from` subscriptions.
//! - [`run`]: the loops of `pheromone ros2` (`Ros2Node::run`, feature `zenoh`) and `pheromone
//!   record` (`record_field`).

pub mod cdr;
pub mod deps;
pub mod frames;
pub mod grid;
#[cfg(feature = "zenoh")]
pub mod node;
pub mod pose;
pub mod record;
pub mod rmw_zenoh;
pub mod robot;
pub mod robots;
pub mod run;
#[cfg(feature = "zenoh")]
pub mod session;
pub mod types;
