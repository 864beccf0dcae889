//! `FrameWriter`: publishes frames that another computation made (a mapper's local map), on the
//! services of a field, so every reader of fields (`FieldReader`, `pheromone probe`, `list`,
//! `export`, the Python package) reads them unchanged.
//!
//! It creates the field's frame, frame-ready and deposit services exactly as `FieldServer` does
//! (same layout, same limits), but takes no deposits: nobody subscribes to its deposit service,
//! so a deposit sent to it is refused to its sender (`SendError::NoSubscriber`). It keeps one
//! subscription of its own frames, as a field does, so `pheromone list` counts its readers the
//! same way.

use iceoryx2::prelude::*;

use super::server::create_publisher;
use super::{
    check_shm_space, create_deposit_service, create_frame_ready_service, create_frame_service,
    now_ns, service_err, DepositFactory, FieldServices, FramePublisher, FrameSubscriber,
    StartError, Svc, TickError,
};
use crate::engine::FieldConfig;
use crate::messages::FrameHeader;
use crate::wire::LAYOUT_VERSION;

/// The publisher of a field whose frames the caller writes.
pub struct FrameWriter {
    field: String,
    names: FieldServices,
    config: FieldConfig,
    publisher: FramePublisher,
    notifier: iceoryx2::port::notifier::Notifier<Svc>,
    /// Held so the frame service counts this writer as a field counts itself.
    _own: FrameSubscriber,
    /// Held so the deposit service exists while the frames do (`pheromone list` opens it).
    _deposits: DepositFactory,
}

impl FrameWriter {
    /// Creates field `field`'s services for frames of `config`'s geometry and channels (its
    /// deposit and evaporation settings are not used). Fails if another process publishes it.
    pub fn start(node: &Node<Svc>, field: &str, config: FieldConfig) -> Result<Self, StartError> {
        let names = FieldServices::new(field)?;
        config.validate().map_err(|source| StartError::Config {
            field: field.to_string(),
            source,
        })?;
        check_shm_space(&config)?;
        let frame_service = create_frame_service(node, &names, &config)?;
        if frame_service.dynamic_config().number_of_publishers() > 0 {
            return Err(StartError::AlreadyRunning {
                field: field.into(),
            });
        }
        let ready_service = create_frame_ready_service(node, &names)?;
        let own = frame_service
            .subscriber_builder()
            .buffer_size(1)
            .create()
            .map_err(|e| service_err(&names.frame, "create own subscriber", e))?;
        // The deposit service must exist for `FieldWatch`; a subscriber would accept deposits
        // nobody applies, so there is none: the factory alone keeps the service.
        let deposits = create_deposit_service(node, &names, &config)?;
        let (publisher, notifier) =
            create_publisher(&names, &config, &frame_service, &ready_service)?;
        Ok(Self {
            field: field.into(),
            names,
            config,
            publisher,
            notifier,
            _own: own,
            _deposits: deposits,
        })
    }

    /// The name of the field written.
    pub fn field(&self) -> &str {
        &self.field
    }

    /// `f32` cells of one frame.
    pub fn frame_len(&self) -> usize {
        self.config.frame_len()
    }

    /// Publishes one frame numbered `sequence` at field time `sim_time_s`: `write` fills every
    /// cell of the loaned sample (zeroed before), then the frame is sent and readers are woken.
    pub fn publish(
        &mut self,
        sequence: u64,
        sim_time_s: f64,
        write: impl FnOnce(&mut [f32]),
    ) -> Result<(), TickError> {
        let len = self.frame_len();
        let mut sample = self
            .publisher
            .loan_slice(len)
            .map_err(|e| service_err(&self.names.frame, "loan frame", e))?;
        let started = now_ns();
        write(sample.payload_mut());
        let g = self.config.geometry();
        let done = now_ns();
        *sample.user_header_mut() = FrameHeader {
            layout_version: LAYOUT_VERSION,
            channels: self.config.channels.len() as u32,
            width: g.width,
            height: g.height,
            sequence,
            stamp_ns: done,
            sim_time_s,
            cell_size_m: g.cell_size_m,
            origin_x_m: g.origin_x_m,
            origin_y_m: g.origin_y_m,
            dt_s: self.config.dt_s(),
            tick_compute_ns: done.saturating_sub(started),
            ..FrameHeader::default()
        };
        sample
            .send()
            .map_err(|e| service_err(&self.names.frame, "send", e))?;
        // A failed wake-up only delays readers to their own wait deadline; the frame is out.
        let _ = self.notifier.notify();
        Ok(())
    }

    /// Connects readers that attached since the last frame and hands them the current frame.
    pub fn serve_new_readers(&self) -> Result<(), TickError> {
        use iceoryx2::port::update_connections::UpdateConnections;
        Ok(self
            .publisher
            .update_connections()
            .map_err(|e| service_err(&self.names.frame, "update connections", e))?)
    }
}
