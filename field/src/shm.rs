//! The field in iceoryx2 shared memory: the field process (`FieldServer`), readers
//! (`FieldReader`) and deposit publishers (`DepositPublisher`). This is the crate's only module
//! with `unsafe`.
//!
//! Services for a field called `F` (DESIGN.md):
//! - `pheromone/F/frame`: publish-subscribe of `[f32]` with a `FrameHeader` user header, one
//!   publisher (the field), `history_size(1)` so a late joiner gets the current frame at once;
//! - `pheromone/F/frame-ready`: event, notified after each frame is sent, so readers wait on it;
//! - `pheromone/F/deposit`: publish-subscribe of `DepositMsg`, many publishers, no overflow: a
//!   deposit that does not fit in the field's buffer is refused to its sender, never dropped
//!   silently.
//!
//! Shared-memory use of the frame service, in frames: `(max_readers + 1) × (1 buffered + 2
//! borrowed) + 1 history + 1 loaned` (the `+ 1` reader is the field itself, holding the previous
//! frame). `frame_pool_bytes` computes it; the field refuses to start when /dev/shm lacks it.

use std::time::Duration;

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;

use crate::engine::{FieldConfig, Stepper, TickReport};
use crate::messages::{DepositMsg, FrameHeader, LAYOUT_VERSION};
use crate::sample::FrameView;

/// iceoryx2 service flavour used everywhere: inter-process.
pub type Svc = ipc::Service;

/// Frames a reader may hold at once.
pub const READER_BORROWED_FRAMES: usize = 2;
/// Deposit publishers' and readers' event id for "frame ready".
const FRAME_READY: EventId = EventId::new(0);

/// Everything that can go wrong with the field's shared memory, each naming what it was doing.
#[derive(Debug, thiserror::Error)]
pub enum ShmError {
    #[error("invalid name '{name}': {reason}")]
    Name { name: String, reason: String },
    #[error("cannot create the iceoryx2 node '{name}': {detail}")]
    Node { name: String, detail: String },
    #[error("no field called '{field}' is running (service '{service}' does not exist)")]
    NoField { field: String, service: String },
    #[error(
        "service '{service}' was created with another message layout: this build speaks \
         {ours} (layout v{LAYOUT_VERSION}); rebuild the client and the field from the same version"
    )]
    Layout { service: String, ours: &'static str },
    #[error("service '{service}': {action} failed: {detail}")]
    Service {
        service: String,
        action: &'static str,
        detail: String,
    },
    #[error("another field process already publishes '{field}'")]
    AlreadyRunning { field: String },
    #[error(
        "the field needs {needed_bytes} bytes of shared memory ({frames} frames of {frame_bytes} \
         bytes) but /dev/shm has {available_bytes} free; shrink the grid or --max-readers, or \
         enlarge /dev/shm"
    )]
    NoMemory {
        needed_bytes: u64,
        available_bytes: u64,
        frames: u64,
        frame_bytes: u64,
    },
    #[error("the frame received has {got} cells but its header says {expected}")]
    BadFrame { got: usize, expected: usize },
    #[error("the restored frame has {got} cells, the configuration needs {expected}")]
    RestoreMismatch { got: usize, expected: usize },
    #[error("deposit not delivered: {0}")]
    NotDelivered(String),
}

fn service_err(service: &str, action: &'static str, e: impl std::fmt::Debug) -> ShmError {
    ShmError::Service {
        service: service.to_string(),
        action,
        detail: format!("{e:?}"),
    }
}

/// CLOCK_MONOTONIC in nanoseconds: comparable between processes on one host.
pub fn now_ns() -> u64 {
    use iceoryx2_bb_posix::clock::{ClockType, Time};
    Time::now_with_clock(ClockType::Monotonic)
        .map(|t| t.as_duration().as_nanos() as u64)
        .unwrap_or(0)
}

/// Silences iceoryx2's own log output (e.g. "no config file was loaded") unless `verbose`.
pub fn set_verbose(verbose: bool) {
    set_log_level(if verbose {
        LogLevel::Info
    } else {
        LogLevel::Fatal
    });
}

/// Service names of one field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldServices {
    pub frame: String,
    pub frame_ready: String,
    pub deposit: String,
}

impl FieldServices {
    pub fn new(field: &str) -> Result<Self, ShmError> {
        check_name(field)?;
        Ok(Self {
            frame: format!("pheromone/{field}/frame"),
            frame_ready: format!("pheromone/{field}/frame-ready"),
            deposit: format!("pheromone/{field}/deposit"),
        })
    }
}

/// Field and robot names: 1–64 characters of `[A-Za-z0-9_-]`.
pub fn check_name(name: &str) -> Result<(), ShmError> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if ok {
        Ok(())
    } else {
        Err(ShmError::Name {
            name: name.to_string(),
            reason: "use 1–64 characters from A–Z, a–z, 0–9, '_' and '-'".into(),
        })
    }
}

pub(crate) fn service_name(name: &str) -> Result<ServiceName, ShmError> {
    ServiceName::new(name).map_err(|e| ShmError::Name {
        name: name.to_string(),
        reason: format!("{e:?}"),
    })
}

/// Creates an iceoryx2 node that stops on SIGINT/SIGTERM (`node.wait` then returns an error) and
/// first removes what dead nodes left behind.
pub fn create_node(name: &str) -> Result<Node<Svc>, ShmError> {
    let node_name = NodeName::new(name).map_err(|e| ShmError::Name {
        name: name.to_string(),
        reason: format!("{e:?}"),
    })?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<Svc>()
        .map_err(|e| ShmError::Node {
            name: name.to_string(),
            detail: format!("{e:?}"),
        })?;
    node.try_cleanup_dead_nodes();
    Ok(node)
}

/// Shared memory the frame service needs, in frames and bytes.
pub fn frame_pool(config: &FieldConfig) -> (u64, u64) {
    let subscribers = config.max_readers as u64 + 1;
    let frames = subscribers * (1 + READER_BORROWED_FRAMES as u64) + 1 + 1;
    (frames, frames * config.frame_bytes())
}

/// Free bytes in /dev/shm, if it can be read.
pub fn shm_available_bytes() -> Option<u64> {
    let s = nix::sys::statvfs::statvfs("/dev/shm").ok()?;
    Some(s.blocks_available() as u64 * s.fragment_size() as u64)
}

type FramePublisher = Publisher<Svc, [f32], FrameHeader>;
type FrameSubscriber = Subscriber<Svc, [f32], FrameHeader>;
/// A frame received from shared memory.
pub type FrameSample = Sample<Svc, [f32], FrameHeader>;

fn frame_service(
    node: &Node<Svc>,
    names: &FieldServices,
    config: Option<&FieldConfig>,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [f32], FrameHeader>,
    ShmError,
> {
    let name = service_name(&names.frame)?;
    let builder = node
        .service_builder(&name)
        .publish_subscribe::<[f32]>()
        .user_header::<FrameHeader>();
    match config {
        Some(c) => builder
            .history_size(1)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(READER_BORROWED_FRAMES)
            .max_subscribers(c.max_readers + 1)
            .max_publishers(2)
            .open_or_create()
            .map_err(|e| match e {
                iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                    iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError::IncompatibleTypes,
                ) => ShmError::Layout {
                    service: names.frame.clone(),
                    ours: "pheromone::FrameHeader/v1 + [f32]",
                },
                e => service_err(&names.frame, "open or create", e),
            }),
        None => builder.open().map_err(|e| {
            use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError as E;
            match e {
                E::DoesNotExist => ShmError::NoField {
                    field: names.frame.split('/').nth(1).unwrap_or_default().to_string(),
                    service: names.frame.clone(),
                },
                E::IncompatibleTypes => ShmError::Layout {
                    service: names.frame.clone(),
                    ours: "pheromone::FrameHeader/v1 + [f32]",
                },
                e => service_err(&names.frame, "open", e),
            }
        }),
    }
}

fn frame_ready_service(
    node: &Node<Svc>,
    names: &FieldServices,
    create: bool,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, ShmError> {
    let name = service_name(&names.frame_ready)?;
    let b = node.service_builder(&name).event();
    if create {
        b.max_listeners(1024)
            .max_notifiers(4)
            .open_or_create()
            .map_err(|e| service_err(&names.frame_ready, "open or create", e))
    } else {
        b.open()
            .map_err(|e| service_err(&names.frame_ready, "open", e))
    }
}

fn deposit_service(
    node: &Node<Svc>,
    names: &FieldServices,
    config: Option<&FieldConfig>,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, DepositMsg, ()>,
    ShmError,
> {
    let name = service_name(&names.deposit)?;
    let builder = node
        .service_builder(&name)
        .publish_subscribe::<DepositMsg>();
    match config {
        Some(c) => builder
            .max_publishers(c.max_depositors)
            .max_subscribers(2)
            .subscriber_max_buffer_size(c.deposit_buffer)
            .history_size(0)
            .enable_safe_overflow(false)
            .open_or_create()
            .map_err(|e| service_err(&names.deposit, "open or create", e)),
        None => builder.open().map_err(|e| {
            use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError as E;
            match e {
                E::DoesNotExist => ShmError::NoField {
                    field: names
                        .deposit
                        .split('/')
                        .nth(1)
                        .unwrap_or_default()
                        .to_string(),
                    service: names.deposit.clone(),
                },
                E::IncompatibleTypes => ShmError::Layout {
                    service: names.deposit.clone(),
                    ours: "pheromone::DepositMsg/v1",
                },
                e => service_err(&names.deposit, "open", e),
            }
        }),
    }
}

/// What one `FieldServer::tick` did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickOutcome {
    pub report: TickReport,
    pub sequence: u64,
    pub compute_ns: u64,
    /// Deposits refused this tick (validation), counted by reason in the header.
    pub rejected: u64,
}

/// The field process: the only writer of the grid.
pub struct FieldServer {
    field: String,
    names: FieldServices,
    stepper: Stepper,
    publisher: FramePublisher,
    /// The field's own subscription: holds the previous frame, read by the next tick.
    own: FrameSubscriber,
    previous: Option<FrameSample>,
    deposits: Subscriber<Svc, DepositMsg, ()>,
    notifier: iceoryx2::port::notifier::Notifier<Svc>,
}

impl FieldServer {
    /// Creates the services and publishes the first frame (zeros, or `restore` = header + cells).
    pub fn start(
        node: &Node<Svc>,
        field: &str,
        config: FieldConfig,
        restore: Option<(FrameHeader, &[f32])>,
    ) -> Result<Self, ShmError> {
        let names = FieldServices::new(field)?;
        let mut stepper = Stepper::new(config).map_err(|e| ShmError::Service {
            service: names.frame.clone(),
            action: "configure",
            detail: e.to_string(),
        })?;
        let config = stepper.config().clone();
        let (frames, needed) = frame_pool(&config);
        if let Some(available) = shm_available_bytes() {
            if needed > available {
                return Err(ShmError::NoMemory {
                    needed_bytes: needed,
                    available_bytes: available,
                    frames,
                    frame_bytes: config.frame_bytes(),
                });
            }
        }
        let frame_service = frame_service(node, &names, Some(&config))?;
        if frame_service.dynamic_config().number_of_publishers() > 0 {
            return Err(ShmError::AlreadyRunning {
                field: field.into(),
            });
        }
        let publisher = frame_service
            .publisher_builder()
            .initial_max_slice_len(config.frame_len())
            .allocation_strategy(AllocationStrategy::Static)
            .max_loaned_samples(1)
            .create()
            .map_err(|e| service_err(&names.frame, "create publisher", e))?;
        let own = frame_service
            .subscriber_builder()
            .buffer_size(1)
            .create()
            .map_err(|e| service_err(&names.frame, "create own subscriber", e))?;
        let deposits = deposit_service(node, &names, Some(&config))?
            .subscriber_builder()
            .buffer_size(config.deposit_buffer)
            .create()
            .map_err(|e| service_err(&names.deposit, "create subscriber", e))?;
        let notifier = frame_ready_service(node, &names, true)?
            .notifier_builder()
            .default_event_id(FRAME_READY)
            .create()
            .map_err(|e| service_err(&names.frame_ready, "create notifier", e))?;

        // First frame: zeros, or the restored cells.
        let len = config.frame_len();
        let mut first = publisher
            .loan_slice(len)
            .map_err(|e| service_err(&names.frame, "loan first frame", e))?;
        if let Some((header, cells)) = restore {
            if cells.len() != len {
                return Err(ShmError::RestoreMismatch {
                    got: cells.len(),
                    expected: len,
                });
            }
            first.payload_mut().copy_from_slice(cells);
            stepper.resume_from(&header);
        }
        *first.user_header_mut() = stepper.header(now_ns(), 0, &TickReport::default());
        first
            .send()
            .map_err(|e| service_err(&names.frame, "send", e))?;
        let _ = notifier.notify();
        let previous = own
            .receive()
            .map_err(|e| service_err(&names.frame, "receive own frame", e))?;
        Ok(Self {
            field: field.into(),
            names,
            stepper,
            publisher,
            own,
            previous,
            deposits,
            notifier,
        })
    }

    pub fn field(&self) -> &str {
        &self.field
    }

    pub fn config(&self) -> &FieldConfig {
        self.stepper.config()
    }

    pub fn stepper(&self) -> &Stepper {
        &self.stepper
    }

    /// Connects readers that attached since the last frame and hands them the current frame
    /// (the history). Call it while idle (e.g. a lockstep field waiting for its clock), so a late
    /// reader does not wait for the next tick.
    pub fn serve_new_readers(&self) -> Result<(), ShmError> {
        use iceoryx2::port::update_connections::UpdateConnections;
        self.publisher
            .update_connections()
            .map_err(|e| service_err(&self.names.frame, "update connections", e))
    }

    /// The last published frame.
    pub fn latest(&self) -> Option<(&FrameHeader, FrameView<'_>)> {
        self.previous.as_ref().map(|s| {
            let c = self.stepper.config();
            (
                s.user_header(),
                FrameView::new(c.geometry(), c.channels.len(), s.payload()),
            )
        })
    }

    /// Drains the deposit queue (validating each), computes the next frame from the previous one
    /// straight into a loaned sample, publishes it and wakes the readers.
    pub fn tick(&mut self) -> Result<TickOutcome, ShmError> {
        let mut rejected = 0;
        loop {
            match self.deposits.receive() {
                Ok(Some(sample)) => {
                    if self.stepper.offer(sample.payload()).is_err() {
                        rejected += 1;
                    }
                }
                Ok(None) => break,
                Err(e) => return Err(service_err(&self.names.deposit, "receive", e)),
            }
        }
        let started = now_ns();
        let len = self.stepper.config().frame_len();
        let previous = match self.previous.take() {
            Some(p) => p,
            None => {
                return Err(service_err(
                    &self.names.frame,
                    "tick",
                    "the previous frame was lost",
                ))
            }
        };
        if previous.payload().len() != len {
            return Err(ShmError::BadFrame {
                got: previous.payload().len(),
                expected: len,
            });
        }
        let uninit = self
            .publisher
            .loan_slice_uninit(len)
            .map_err(|e| service_err(&self.names.frame, "loan frame", e))?;
        // SAFETY: the payload lies in an iceoryx2 shared-memory segment: memory the OS handed out
        // zero-filled and that only ever held `f32` frames of this service, so every element is
        // initialized bytes, and every bit pattern is a valid `f32`. `Stepper::step` then
        // overwrites every element before the sample is sent.
        let mut next = unsafe { uninit.assume_init() };
        let report = self.stepper.step(previous.payload(), next.payload_mut());
        drop(previous);
        let done = now_ns();
        let compute_ns = done.saturating_sub(started);
        *next.user_header_mut() = self.stepper.header(done, compute_ns, &report);
        next.send()
            .map_err(|e| service_err(&self.names.frame, "send", e))?;
        let _ = self.notifier.notify();
        self.previous = self
            .own
            .receive()
            .map_err(|e| service_err(&self.names.frame, "receive own frame", e))?;
        Ok(TickOutcome {
            report,
            sequence: self.stepper.sequence,
            compute_ns,
            rejected,
        })
    }
}

/// A frame lent by a `FieldReader`: the header and a sampling view of the cells.
pub struct Frame<'a> {
    pub header: &'a FrameHeader,
    pub view: FrameView<'a>,
}

/// A process's read access to a field: lends the newest frame without copying it.
pub struct FieldReader {
    names: FieldServices,
    subscriber: FrameSubscriber,
    listener: iceoryx2::port::listener::Listener<Svc>,
    latest: Option<FrameSample>,
}

impl FieldReader {
    /// Attaches to the running field `field`; fails with `ShmError::NoField` if there is none.
    pub fn attach(node: &Node<Svc>, field: &str) -> Result<Self, ShmError> {
        let names = FieldServices::new(field)?;
        let subscriber = frame_service(node, &names, None)?
            .subscriber_builder()
            .buffer_size(1)
            .create()
            .map_err(|e| service_err(&names.frame, "create subscriber", e))?;
        let listener = frame_ready_service(node, &names, false)?
            .listener_builder()
            .create()
            .map_err(|e| service_err(&names.frame_ready, "create listener", e))?;
        let mut reader = Self {
            names,
            subscriber,
            listener,
            latest: None,
        };
        reader.update()?;
        Ok(reader)
    }

    /// Attaches, retrying while the field does not exist yet, for at most `timeout`. Waits with
    /// `node.wait` between tries (returns early on a termination request).
    pub fn attach_within(
        node: &Node<Svc>,
        field: &str,
        timeout: Duration,
    ) -> Result<Self, ShmError> {
        retry_attach(node, timeout, || Self::attach(node, field))
    }

    /// Takes the newest frame that has arrived (if any); returns whether it is new.
    pub fn update(&mut self) -> Result<bool, ShmError> {
        let mut fresh = false;
        loop {
            match self.subscriber.receive() {
                Ok(Some(s)) => {
                    if s.payload().len() != s.user_header().len() {
                        return Err(ShmError::BadFrame {
                            got: s.payload().len(),
                            expected: s.user_header().len(),
                        });
                    }
                    self.latest = Some(s);
                    fresh = true;
                }
                Ok(None) => return Ok(fresh),
                Err(e) => return Err(service_err(&self.names.frame, "receive", e)),
            }
        }
    }

    /// Waits up to `timeout` for a frame newer than the one held; returns whether one came.
    pub fn wait_frame(&mut self, timeout: Duration) -> Result<bool, ShmError> {
        if self.update()? {
            return Ok(true);
        }
        self.listener
            .timed_wait(|_| {}, timeout)
            .map_err(|e| service_err(&self.names.frame_ready, "wait", e))?;
        self.update()
    }

    /// Waits (up to `timeout`) until a frame satisfies `pred`; returns it, or `None` on timeout.
    pub fn wait_until(
        &mut self,
        timeout: Duration,
        mut pred: impl FnMut(&Frame<'_>) -> bool,
    ) -> Result<Option<Frame<'_>>, ShmError> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            if self.frame().as_ref().is_some_and(&mut pred) {
                return Ok(self.frame());
            }
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.wait_frame(left.min(Duration::from_millis(100)))?;
        }
    }

    /// The newest frame held, if any.
    pub fn frame(&self) -> Option<Frame<'_>> {
        self.latest.as_ref().map(|s| {
            let h = s.user_header();
            Frame {
                header: h,
                view: FrameView::new(h.geometry(), h.channels as usize, s.payload()),
            }
        })
    }

    /// The raw sample (e.g. to keep holding it past the next update).
    pub fn sample(&self) -> Option<&FrameSample> {
        self.latest.as_ref()
    }
}

/// Publishes deposits to a field.
///
/// iceoryx2 drops samples whose publisher disappears before the subscriber first connected to
/// it, so a publisher that sent deposits waits, when dropped (or on `flush`), until the field has
/// published two more frames — by then its drain loop has taken everything that was sent.
pub struct DepositPublisher {
    names: FieldServices,
    publisher: Publisher<Svc, DepositMsg, ()>,
    frame_ready: iceoryx2::port::listener::Listener<Svc>,
    robot_id: u32,
    unflushed: bool,
    /// Longest wait in `Drop` for the field to take what was sent.
    pub flush_timeout: Duration,
}

impl DepositPublisher {
    pub fn attach(node: &Node<Svc>, field: &str, robot_id: u32) -> Result<Self, ShmError> {
        let names = FieldServices::new(field)?;
        let publisher = deposit_service(node, &names, None)?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(|e| service_err(&names.deposit, "create publisher", e))?;
        let frame_ready = frame_ready_service(node, &names, false)?
            .listener_builder()
            .create()
            .map_err(|e| service_err(&names.frame_ready, "create listener", e))?;
        Ok(Self {
            names,
            publisher,
            frame_ready,
            robot_id,
            unflushed: false,
            flush_timeout: Duration::from_secs(1),
        })
    }

    /// Waits (at most `timeout`) until the field has taken every deposit sent so far; returns
    /// whether it has.
    pub fn flush(&mut self, timeout: Duration) -> bool {
        if !self.unflushed {
            return true;
        }
        let deadline = std::time::Instant::now() + timeout;
        let mut frames = 0u64;
        while frames < 2 {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return false;
            }
            match self.frame_ready.timed_wait(|_| {}, left) {
                Ok(n) => frames += n,
                Err(_) => return false,
            }
        }
        self.unflushed = false;
        true
    }

    pub fn attach_within(
        node: &Node<Svc>,
        field: &str,
        robot_id: u32,
        timeout: Duration,
    ) -> Result<Self, ShmError> {
        retry_attach(node, timeout, || Self::attach(node, field, robot_id))
    }

    /// Sends a deposit, stamped with this publisher's robot id and the monotonic clock. Fails
    /// with `NotDelivered` if no field took it (none running, or its buffer is full).
    pub fn send(&mut self, mut msg: DepositMsg) -> Result<(), ShmError> {
        msg.robot_id = self.robot_id;
        if msg.stamp_ns == 0 {
            msg.stamp_ns = now_ns();
        }
        // Frame events from before this send say nothing about it.
        let _ = self.frame_ready.try_wait(|_| {});
        match self.publisher.send_copy(msg) {
            Ok(0) => Err(ShmError::NotDelivered(format!(
                "no field is subscribed to '{}' or its deposit buffer is full",
                self.names.deposit
            ))),
            Ok(_) => {
                self.unflushed = true;
                Ok(())
            }
            Err(e) => Err(ShmError::NotDelivered(format!("{e:?}"))),
        }
    }
}

impl Drop for DepositPublisher {
    fn drop(&mut self) {
        let timeout = self.flush_timeout;
        self.flush(timeout);
    }
}

fn retry_attach<T>(
    node: &Node<Svc>,
    timeout: Duration,
    mut attach: impl FnMut() -> Result<T, ShmError>,
) -> Result<T, ShmError> {
    let deadline = std::time::Instant::now() + timeout;
    loop {
        match attach() {
            Ok(t) => return Ok(t),
            Err(e @ ShmError::NoField { .. }) | Err(e @ ShmError::Service { .. }) => {
                let left = deadline.saturating_duration_since(std::time::Instant::now());
                if left.is_zero() || node.wait(left.min(Duration::from_millis(20))).is_err() {
                    return Err(e);
                }
            }
            Err(e) => return Err(e),
        }
    }
}
