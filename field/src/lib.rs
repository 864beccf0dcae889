//! # pheromone field
//!
//! A virtual pheromone field for several processes on one host. A program that reads a field and
//! deposits into it needs only the root of this crate (or `use pheromone_field::prelude::*`):
//! [`create_node`], [`FieldReader`] (zero-copy frames, sampling, gradients), [`DepositPublisher`]
//! and [`DepositClient`] (deposits, confirmed with a [`Receipt`]), their errors, [`Deposit`] and
//! [`Kernel`].
//!
//! Below that: the grid's geometry, the models of the seed papers (MODELS.md M1–M4), the fused
//! tick engine (`engine`), sampling (`sample`), the shared-memory services (`shm`), and what the
//! processes around a field need (`process`: the field loop, links, lockstep, real-time,
//! checkpoints). `unsafe` is denied (`unsafe_code`) except in the files that allow it:
//! `shm/server.rs`, `shm/inputs.rs`, `simd.rs`, `wire.rs` (`wire_type!`) and
//! `process/realtime.rs` (`sched_setscheduler`).

#![warn(missing_docs)]

mod ambient;
pub mod deposit;
pub mod engine;
pub mod error;
pub mod geometry;
pub mod infile;
pub mod kernel;
pub mod messages;
pub mod models;
pub mod outfile;
mod plan;
pub mod process;
mod reject;
pub mod sample;
pub mod shm;
mod simd;
pub mod sources;
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
pub use shm::{
    create_node, AttachError, DepositClient, DepositPublisher, FieldReader, Receipt, ReceiveError,
    SendError,
};

/// The client API in one import: attach to a field, read its frames, deposit into it.
pub mod prelude {
    pub use crate::shm::{
        create_node, AttachError, DepositClient, DepositPublisher, FieldReader, Receipt,
        ReceiveError, SendError,
    };
    pub use crate::{Deposit, FrameView, Kernel, SamplePose};
}
