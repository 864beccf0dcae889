//! # pheromone field
//!
//! A virtual pheromone field for several processes on one host: geometry, the models of the
//! seed papers (MODELS.md M1–M4), the fused tick engine, sampling, the shared-memory message
//! types and the iceoryx2 service (`shm`). `unsafe` is denied (`unsafe_code`) except in the
//! files that allow it: `shm/server.rs`, `shm/inputs.rs`, `simd.rs`, `wire.rs` (`wire_type!`) and
//! `realtime.rs` (`sched_setscheduler`).

pub mod ambient;
pub mod checkpoint;
pub mod deposit;
pub mod engine;
pub mod error;
pub mod geometry;
pub mod kernel;
pub mod link;
pub mod lockstep;
pub mod messages;
pub mod models;
mod plan;
pub mod realtime;
mod reject;
pub mod run;
pub mod sample;
pub mod shm;
pub mod simd;
pub mod tune;
pub mod wire;

pub use deposit::{DepositLimits, RejectReason, Rejection};
pub use engine::{FieldConfig, OwnedField, Stepper, TickReport};
pub use error::ConfigError;
pub use geometry::GridGeometry;
pub use kernel::{Deposit, EllipseRule, Kernel, KernelParams, PoseEstimate, PoseRejection};
pub use messages::{DepositMsg, FrameHeader, KernelKind};
pub use models::{ChannelSpec, Evaporation};
pub use sample::{FrameView, SamplePose};
