//! A running field's configuration as it publishes it on `pheromone/F/config` (TOML, history
//! 1; see `inputs`), for clients that check a deposit with the field's own rules before
//! sending it (`pheromone gateway`). The field hands it to a new subscriber when it next
//! publishes a frame.

use iceoryx2::port::subscriber::Subscriber;

use super::inputs::config_service;
use super::{service_err, AttachError, FieldServices, ReceiveError, Svc};
use crate::engine::FieldConfig;

/// A subscriber to a field's configuration.
pub struct ConfigSubscriber {
    service: String,
    subscriber: Subscriber<Svc, [u8], ()>,
}

impl ConfigSubscriber {
    /// Subscribes to field `field`'s configuration (one of `wire::CONFIG_SUBSCRIBERS` slots).
    pub fn attach(node: &iceoryx2::node::Node<Svc>, field: &str) -> Result<Self, AttachError> {
        let names = FieldServices::new(field)?;
        let subscriber = config_service::<AttachError>(node, &names)?
            .subscriber_builder()
            .create()
            .map_err(|e| service_err(&names.config, "create subscriber", e))?;
        Ok(Self {
            service: names.config,
            subscriber,
        })
    }

    /// The newest configuration received, if one arrived since the last call.
    pub fn latest(&self) -> Result<Option<FieldConfig>, ReceiveError> {
        let mut last = None;
        while let Some(s) = self
            .subscriber
            .receive()
            .map_err(|e| service_err(&self.service, "receive", e))?
        {
            last = Some(String::from_utf8_lossy(s.payload()).into_owned());
        }
        Ok(last
            .map(|text| {
                FieldConfig::from_toml(&text)
                    .map_err(|e| service_err(&self.service, "read the configuration", e))
            })
            .transpose()?)
    }
}
