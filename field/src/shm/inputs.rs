//! The inputs of each frame for a bridge to mirrors (docs/mirror-wire.md): `pheromone/F/inputs`
//! carries, per published frame, an `InputsHeader` and the deposits the tick applied in the order
//! applied; `pheromone/F/config` holds the field's configuration as TOML (history 1), so a mirror
//! builds the same `Stepper`. Also the byte views of wire types the bridge sends over the network.

// The byte views of wire types reinterpret plain `#[repr(C)]` numbers as bytes and back.
#![allow(unsafe_code)]

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use super::{
    service_err, service_name, AttachError, FieldServices, NameError, ReceiveError, ServiceError,
    StartError, Svc, TickError,
};
use crate::messages::{DepositMsg, InputsHeader};
use crate::wire::{self, ZeroCopySend};

/// The bytes of a wire type (plain `#[repr(C)]` numbers, see `wire_type!`).
pub fn wire_bytes<T: ZeroCopySend + Copy>(v: &T) -> &[u8] {
    // SAFETY: wire types are `#[repr(C)]` numbers and arrays of numbers without padding (their
    // sizes are pinned by `wire_type!`), so all `size_of::<T>()` bytes are initialized.
    unsafe { std::slice::from_raw_parts(v as *const T as *const u8, std::mem::size_of::<T>()) }
}

/// The bytes of a slice of wire types.
pub fn wire_slice_bytes<T: ZeroCopySend + Copy>(v: &[T]) -> &[u8] {
    // SAFETY: as `wire_bytes`, for `v.len()` contiguous values.
    unsafe { std::slice::from_raw_parts(v.as_ptr() as *const u8, std::mem::size_of_val(v)) }
}

/// Reads a wire type from the start of `bytes` (any alignment); `None` if too short.
pub fn wire_from_bytes<T: ZeroCopySend + Copy + Default>(bytes: &[u8]) -> Option<T> {
    let n = std::mem::size_of::<T>();
    if bytes.len() < n {
        return None;
    }
    let mut v = T::default();
    // SAFETY: `v` is `n` writable bytes; every bit pattern is a valid wire type (numbers only),
    // and `bytes` holds at least `n` bytes that do not overlap `v`.
    unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), &mut v as *mut T as *mut u8, n) };
    Some(v)
}

/// Reads `bytes.len() / size_of::<T>()` wire values; `None` unless the length is a multiple.
pub fn wire_vec_from_bytes<T: ZeroCopySend + Copy + Default>(bytes: &[u8]) -> Option<Vec<T>> {
    let n = std::mem::size_of::<T>();
    if !bytes.len().is_multiple_of(n) {
        return None;
    }
    bytes.chunks_exact(n).map(wire_from_bytes).collect()
}

/// Floats from little-endian bytes (a keyframe's cells).
pub fn f32s_from_bytes(bytes: &[u8]) -> Option<Vec<f32>> {
    if !bytes.len().is_multiple_of(4) {
        return None;
    }
    Some(
        bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
    )
}

type InputsFactory = iceoryx2::service::port_factory::publish_subscribe::PortFactory<
    Svc,
    [DepositMsg],
    InputsHeader,
>;
pub(super) type ConfigFactory =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [u8], ()>;

/// Opens or creates `pheromone/F/inputs` (the field's side and the bridge's alike; `E`: the
/// error of the caller's operation).
fn inputs_service<E: From<NameError> + From<ServiceError>>(
    node: &Node<Svc>,
    names: &FieldServices,
) -> Result<InputsFactory, E> {
    Ok(node
        .service_builder(&service_name(&names.inputs)?)
        .publish_subscribe::<[DepositMsg]>()
        .user_header::<InputsHeader>()
        .subscriber_max_buffer_size(wire::INPUTS_SUBSCRIBER_BUFFER)
        .max_subscribers(wire::INPUTS_SUBSCRIBERS)
        .max_publishers(wire::FRAME_PUBLISHERS)
        .history_size(0)
        .open_or_create()
        .map_err(|e| service_err(&names.inputs, "open or create", e))?)
}

/// Opens or creates `pheromone/F/config` (`E`: the error of the caller's operation).
pub(super) fn config_service<E: From<NameError> + From<ServiceError>>(
    node: &Node<Svc>,
    names: &FieldServices,
) -> Result<ConfigFactory, E> {
    Ok(node
        .service_builder(&service_name(&names.config)?)
        .publish_subscribe::<[u8]>()
        .history_size(1)
        .subscriber_max_buffer_size(1)
        .max_subscribers(wire::CONFIG_SUBSCRIBERS)
        .max_publishers(wire::FRAME_PUBLISHERS)
        .open_or_create()
        .map_err(|e| service_err(&names.config, "open or create", e))?)
}

/// The field's side: publishes each frame's inputs (`FieldServer::publish_inputs`).
pub struct InputsPublisher {
    service: String,
    publisher: Publisher<Svc, [DepositMsg], InputsHeader>,
    // Its history hands the configuration to every bridge that attaches (on the connection
    // update each `send` makes).
    config: Publisher<Svc, [u8], ()>,
    /// This run's id, written into every [`InputsHeader`](crate::messages::InputsHeader): a
    /// restarted field has another, so a mirror knows the sequence started again.
    pub epoch: u64,
}

impl InputsPublisher {
    /// Creates both services and publishes `config_toml` once (history 1).
    pub fn create(
        node: &Node<Svc>,
        names: &FieldServices,
        config_toml: &str,
        max_deposits: usize,
    ) -> Result<Self, StartError> {
        let publisher = inputs_service::<StartError>(node, names)?
            .publisher_builder()
            .initial_max_slice_len(max_deposits.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .max_loaned_samples(1)
            .create()
            .map_err(|e| service_err(&names.inputs, "create publisher", e))?;
        let config = config_service::<StartError>(node, names)?
            .publisher_builder()
            .initial_max_slice_len(config_toml.len().max(1))
            .create()
            .map_err(|e| service_err(&names.config, "create publisher", e))?;
        config
            .loan_slice_uninit(config_toml.len())
            .map_err(|e| service_err(&names.config, "loan", e))?
            .write_from_slice(config_toml.as_bytes())
            .send()
            .map_err(|e| service_err(&names.config, "send", e))?;
        let epoch = super::now_ns() ^ ((std::process::id() as u64) << 40);
        Ok(Self {
            service: names.inputs.clone(),
            publisher,
            config,
            epoch,
        })
    }

    /// Connects subscribers that attached since the last send, handing them the configuration
    /// (its history): an idle lockstep field calls it, so a gateway that attached before the
    /// first clock knows the channels (their `sources`) before it answers for the first frame.
    pub fn serve_new_subscribers(&self) -> Result<(), TickError> {
        use iceoryx2::port::update_connections::UpdateConnections;
        self.config
            .update_connections()
            .map_err(|e| service_err(&self.service, "update connections", e))?;
        Ok(())
    }

    /// Publishes the inputs of one frame.
    pub fn send(&self, mut header: InputsHeader, deposits: &[DepositMsg]) -> Result<(), TickError> {
        header.epoch = self.epoch;
        header.count = deposits.len() as u32;
        let mut sample = self
            .publisher
            .loan_slice_uninit(deposits.len())
            .map_err(|e| service_err(&self.service, "loan", e))?;
        *sample.user_header_mut() = header;
        let sample = sample.write_from_slice(deposits);
        sample
            .send()
            .map_err(|e| service_err(&self.service, "send", e))?;
        use iceoryx2::port::update_connections::UpdateConnections;
        self.config
            .update_connections()
            .map_err(|e| service_err(&self.service, "update connections", e))?;
        Ok(())
    }
}

/// The bridge's side: each frame's inputs and the configuration of a running field.
pub struct InputsSubscriber {
    service: String,
    subscriber: Subscriber<Svc, [DepositMsg], InputsHeader>,
    config: Subscriber<Svc, [u8], ()>,
    config_service: String,
}

impl InputsSubscriber {
    /// Subscribes to field `field`'s inputs and configuration services (opening or creating
    /// them, so the bridge may start before the field).
    pub fn attach(node: &Node<Svc>, field: &str) -> Result<Self, AttachError> {
        let names = FieldServices::new(field)?;
        let subscriber = inputs_service::<AttachError>(node, &names)?
            .subscriber_builder()
            .buffer_size(wire::INPUTS_SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| service_err(&names.inputs, "create subscriber", e))?;
        let config = config_service::<AttachError>(node, &names)?
            .subscriber_builder()
            .create()
            .map_err(|e| service_err(&names.config, "create subscriber", e))?;
        Ok(Self {
            service: names.inputs,
            subscriber,
            config,
            config_service: names.config,
        })
    }

    /// The configuration the field published (its latest), if one arrived.
    pub fn config_toml(&self) -> Result<Option<String>, ReceiveError> {
        let mut last = None;
        while let Some(s) = self
            .config
            .receive()
            .map_err(|e| service_err(&self.config_service, "receive", e))?
        {
            last = Some(String::from_utf8_lossy(s.payload()).into_owned());
        }
        Ok(last)
    }

    /// The next frame's inputs, if any.
    pub fn receive(&self) -> Result<Option<(InputsHeader, Vec<DepositMsg>)>, ReceiveError> {
        Ok(self
            .subscriber
            .receive()
            .map_err(|e| service_err(&self.service, "receive", e))?
            .map(|s| (*s.user_header(), s.payload().to_vec())))
    }
}
