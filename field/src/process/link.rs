//! Small fixed-size messages between processes: an iceoryx2 publish-subscribe service paired
//! with an event service, so receivers sleep in the kernel until a sender notifies them (no
//! polling, no sleeps). Used for poses, sensors, commands and statuses; the field's frames and
//! deposits have their own services in `shm`.

use std::fmt::Debug;
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use crate::shm::{service_err as err, service_name, AttachError, ReceiveError, SendError, Svc};

pub use crate::wire::LinkOptions;

fn pubsub<T: Debug + ZeroCopySend>(
    node: &Node<Svc>,
    service: &str,
    o: LinkOptions,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, T, ()>, AttachError>
{
    use iceoryx2::service::builder::publish_subscribe::{
        PublishSubscribeOpenError as OpenErr, PublishSubscribeOpenOrCreateError as E,
    };
    let name = service_name(service)?;
    let mut attempt = 0;
    loop {
        let result = node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .max_publishers(o.max_publishers)
            .max_subscribers(o.max_subscribers)
            .max_nodes(o.max_publishers + o.max_subscribers)
            .subscriber_max_buffer_size(o.buffer)
            .history_size(1)
            .enable_safe_overflow(o.keep_latest)
            .open_or_create();
        match result {
            Ok(factory) => return Ok(factory),
            // Several processes open or create one service at once: iceoryx2 0.10 can find it
            // created by another and then gone (or not yet complete) when it opens it. Another
            // try sees it settled; a termination request ends the retries.
            Err(E::PublishSubscribeOpenError(OpenErr::DoesNotExist))
                if attempt < OPEN_OR_CREATE_ATTEMPTS
                    && crate::shm::node_wait(node, RETRY_WAIT).is_ok() =>
            {
                attempt += 1;
            }
            Err(E::PublishSubscribeOpenError(OpenErr::IncompatibleTypes)) => {
                return Err(AttachError::Layout {
                    service: service.to_string(),
                    ours: std::any::type_name::<T>(),
                })
            }
            Err(e) => return Err(err(service, "open or create", e).into()),
        }
    }
}

/// Tries of an open-or-create that raced another process's (see `pubsub`).
const OPEN_OR_CREATE_ATTEMPTS: u32 = 50;
/// The wait between two of them.
const RETRY_WAIT: Duration = Duration::from_millis(2);

/// The wake-up event of a link: at least as many notifiers and listeners as the link has senders
/// and receivers (the defaults admit 256 senders and 64 receivers).
fn event(
    node: &Node<Svc>,
    service: &str,
    o: LinkOptions,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, AttachError> {
    let notifiers = o.max_publishers.max(256);
    let listeners = o.max_subscribers.max(64);
    Ok(node
        .service_builder(&service_name(service)?)
        .event()
        .max_notifiers(notifiers)
        .max_listeners(listeners)
        .max_nodes(notifiers + listeners)
        .open_or_create()
        .map_err(|e| err(service, "open or create", e))?)
}

/// The sending end: publishes a message and wakes the receivers.
pub struct Sender<T: Debug + ZeroCopySend + Copy + 'static> {
    service: String,
    factory: iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, T, ()>,
    publisher: Publisher<Svc, T, ()>,
    notifier: Notifier<Svc>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Sender<T> {
    /// `service` carries the messages; `wake` is the event service its receivers listen on
    /// (several links may share one, e.g. every robot's command wakes the world).
    pub fn create(
        node: &Node<Svc>,
        service: &str,
        wake: &str,
        options: LinkOptions,
    ) -> Result<Self, AttachError> {
        let factory = pubsub::<T>(node, service, options)?;
        let publisher = factory
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(|e| err(service, "create publisher", e))?;
        let notifier = event(node, wake, options)?
            .notifier_builder()
            .create()
            .map_err(|e| err(wake, "create notifier", e))?;
        Ok(Self {
            service: service.to_string(),
            factory,
            publisher,
            notifier,
        })
    }

    /// Receivers currently attached to the service.
    pub fn receivers(&self) -> usize {
        use iceoryx2::prelude::PortFactory;
        self.factory.dynamic_config().number_of_subscribers()
    }

    /// Sends a copy of `msg` and notifies; returns how many receivers got it.
    pub fn send(&self, msg: T) -> Result<usize, SendError> {
        let n = self
            .publisher
            .send_copy(msg)
            .map_err(|e| err(&self.service, "send", e))?;
        // A failed wake-up only delays receivers to their own wait deadline; the message is
        // delivered (`n` says to how many).
        let _ = self.notifier.notify();
        Ok(n)
    }
}

/// The receiving end.
pub struct Receiver<T: Debug + ZeroCopySend + Copy + 'static> {
    service: String,
    factory: iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, T, ()>,
    subscriber: Subscriber<Svc, T, ()>,
    listener: Listener<Svc>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Receiver<T> {
    /// Opens (or creates) `service` with `options` and subscribes to it, listening for wake-ups
    /// on the event service `wake` (which several links may share).
    pub fn create(
        node: &Node<Svc>,
        service: &str,
        wake: &str,
        options: LinkOptions,
    ) -> Result<Self, AttachError> {
        let factory = pubsub::<T>(node, service, options)?;
        let subscriber = factory
            .subscriber_builder()
            .buffer_size(options.buffer)
            .create()
            .map_err(|e| err(service, "create subscriber", e))?;
        let listener = event(node, wake, options)?
            .listener_builder()
            .create()
            .map_err(|e| err(wake, "create listener", e))?;
        Ok(Self {
            service: service.to_string(),
            factory,
            subscriber,
            listener,
        })
    }

    /// The next buffered message, if any.
    pub fn try_recv(&self) -> Result<Option<T>, ReceiveError> {
        Ok(self
            .subscriber
            .receive()
            .map(|s| s.map(|s| *s.payload()))
            .map_err(|e| err(&self.service, "receive", e))?)
    }

    /// The newest buffered message, dropping older ones.
    pub fn latest(&self) -> Result<Option<T>, ReceiveError> {
        let mut last = None;
        while let Some(m) = self.try_recv()? {
            last = Some(m);
        }
        Ok(last)
    }

    /// The next message, waiting up to `timeout` for a sender's notification.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<T>, ReceiveError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(m) = self.try_recv()? {
                return Ok(Some(m));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.wait(left)?;
        }
    }

    /// Blocks until a sender notifies (or `timeout`), consuming the notifications.
    /// `ReceiveError::Interrupted` when a signal the program handles cut the wait short (not in
    /// a process that handles termination requests through iceoryx2).
    pub fn wait(&self, timeout: Duration) -> Result<(), ReceiveError> {
        match crate::shm::wait_interruptible(&self.listener, timeout, &self.service)? {
            crate::shm::Woken::Anyway => Ok(()),
            crate::shm::Woken::Interrupted => Err(ReceiveError::Interrupted {
                service: self.service.clone(),
            }),
        }
    }

    /// Senders currently attached to the service (0 once the other side has gone).
    pub fn senders(&self) -> usize {
        use iceoryx2::prelude::PortFactory;
        self.factory.dynamic_config().number_of_publishers()
    }

    /// The listener, to attach to a WaitSet.
    pub fn listener(&self) -> &Listener<Svc> {
        &self.listener
    }
}
