//! One value a process keeps current for readers on its host: an iceoryx2 blackboard with a
//! single entry. The writer updates it in place (no send, no queue); a reader opens it and
//! copies the value whenever it looks, even when the writer sends nothing else. Behind
//! [`super::MirrorStateWriter`] (`pheromone/F/mirror`) and the field's timing
//! (`pheromone/F/timing`).

use iceoryx2::port::writer::{EntryHandleMut, Writer};
use iceoryx2::prelude::*;
use iceoryx2::service::builder::blackboard::BlackboardOpenError;
use iceoryx2::service::port_factory::blackboard::PortFactory;

use super::{service_err, service_name, AttachError, StartError, Svc};

/// The blackboard's one key.
const KEY: u64 = 0;
/// Readers at once (`list`, `probe`, `export`, views…).
const MAX_READERS: usize = 64;

/// The writer's side of a one-value blackboard.
pub(crate) struct Board<T: Copy + ZeroCopySend + 'static> {
    // Dropped in this order: the entry, the writer port, the service.
    entry: EntryHandleMut<Svc, u64, T>,
    _writer: Writer<Svc, u64>,
    _service: PortFactory<Svc, u64>,
}

impl<T: Copy + ZeroCopySend + core::fmt::Debug + 'static> Board<T> {
    /// Creates blackboard `service` holding `initial`.
    pub(crate) fn create(node: &Node<Svc>, service: &str, initial: T) -> Result<Self, StartError> {
        let created = node
            .service_builder(&service_name(service)?)
            .blackboard_creator::<u64>()
            .max_readers(MAX_READERS)
            .add::<T>(KEY, initial)
            .create()
            .map_err(|e| service_err(service, "create", e))?;
        let writer = created
            .writer_builder()
            .create()
            .map_err(|e| service_err(service, "create writer", e))?;
        let entry = writer
            .entry::<T>(&KEY)
            .map_err(|e| service_err(service, "open the entry", e))?;
        Ok(Self {
            entry,
            _writer: writer,
            _service: created,
        })
    }

    pub(crate) fn set(&self, value: T) {
        self.entry.update_with_copy(value);
    }
}

/// The value on blackboard `service` now, or `None` when no process keeps one.
pub(crate) fn read_board<T: Copy + ZeroCopySend + core::fmt::Debug + 'static>(
    node: &Node<Svc>,
    service: &str,
) -> Result<Option<T>, AttachError> {
    let opened = match node
        .service_builder(&service_name(service)?)
        .blackboard_opener::<u64>()
        .open()
    {
        Ok(s) => s,
        Err(BlackboardOpenError::DoesNotExist) => return Ok(None),
        Err(e) => return Err(service_err(service, "open", e).into()),
    };
    let reader = opened
        .reader_builder()
        .create()
        .map_err(|e| service_err(service, "create reader", e))?;
    let entry = reader
        .entry::<T>(&KEY)
        .map_err(|e| service_err(service, "open the entry", e))?;
    let value = *entry.get();
    Ok(Some(value))
}
