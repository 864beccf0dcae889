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
//!
//! Crashes (README "Reliability"): a process killed with SIGKILL leaves its ports behind;
//! `cleanup_dead_nodes` (which the field calls once a second, and every process calls when it
//! creates its node) removes them, which also returns the frames a dead reader held to the
//! field's pool. Readers tell a dead field with `FieldReader::field_alive`, keep their last frame
//! and receive the frames of a field restarted under the same name. A `Standby` mirrors a running
//! field and becomes its publisher when the primary dies.

use std::time::{Duration, Instant};

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
    #[error("the standby cannot mirror field '{field}': {detail}")]
    StandbyMismatch { field: String, detail: String },
}

/// Waits on a listener; a signal that interrupts the wait (any caught one, not only Ctrl-C) is
/// a spurious wake-up, since callers loop on their own deadline and see Ctrl-C through
/// `node.wait`.
pub(crate) fn wait_interruptible(
    listener: &iceoryx2::port::listener::Listener<Svc>,
    timeout: Duration,
    service: &str,
) -> Result<(), ShmError> {
    match listener.timed_wait(|_| {}, timeout) {
        Ok(_) | Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => Ok(()),
        Err(e) => Err(service_err(service, "wait", e)),
    }
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
    // SIGINT and SIGTERM wait (blocked, pending) until the node exists and iceoryx2's handler
    // is installed: a process stopped while its node is half-created leaves an entry that no
    // cleanup can remove. A signal that came meanwhile is handled at the unblock, and the
    // node's next `wait` reports it.
    use nix::sys::signal::{pthread_sigmask, SigSet, SigmaskHow, Signal};
    let mut termination = SigSet::empty();
    termination.add(Signal::SIGINT);
    termination.add(Signal::SIGTERM);
    let mut previous = SigSet::empty();
    let blocked = pthread_sigmask(
        SigmaskHow::SIG_BLOCK,
        Some(&termination),
        Some(&mut previous),
    )
    .is_ok();
    let node = NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<Svc>()
        .map_err(|e| ShmError::Node {
            name: name.to_string(),
            detail: format!("{e:?}"),
        });
    // Installs iceoryx2's signal handler (installed on first use). A wait that fails took a
    // termination request an earlier node of this process had not yet seen: raised again below.
    let seen_before = node.as_ref().is_ok_and(|n| n.wait(Duration::ZERO).is_err());
    if blocked {
        // Restoring the mask the thread had cannot fail with a valid `how`.
        let _ = pthread_sigmask(SigmaskHow::SIG_SETMASK, Some(&previous), None);
    }
    if seen_before {
        // Raising a signal the process handles cannot fail.
        let _ = nix::sys::signal::raise(Signal::SIGTERM);
    }
    let node = node?;
    node.try_cleanup_dead_nodes();
    Ok(node)
}

/// Removes the ports and services that processes killed without cleaning up left behind (their
/// readers' borrowed frames then return to the publisher's pool on its next send). Returns how
/// many dead nodes were cleaned.
pub fn cleanup_dead_nodes(node: &Node<Svc>) -> u64 {
    node.try_cleanup_dead_nodes().cleanups + remove_leftover_tags(node.config())
}

/// Removes what dead nodes of `config` left behind (the cleanup of [`cleanup_dead_nodes`], for
/// a process without a node of its own, e.g. a test after a run); returns how many it removed.
pub fn cleanup_dead_nodes_of(config: &Config) -> u64 {
    let mut cleaned = 0;
    let mut dead = Vec::new();
    // Listing fails only on an unreadable node directory: then there is nothing to clean.
    let _ = Node::<Svc>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    });
    for view in dead {
        if view.try_remove_stale_resources().is_ok() {
            cleaned += 1;
        }
    }
    cleaned + remove_leftover_tags(config)
}

/// iceoryx2 0.10 leaves the port and service tag files of a node killed while it was creating
/// its node or ports (upstream issue #1967; its cleanup then also looks under the default
/// prefix), so the node's directory is never removed and the node shows as dead forever. The
/// regular cleanup has removed what those ports held by then: remove the tags of nodes still
/// dead, and clean them up again. Returns how many nodes this removed.
fn remove_leftover_tags(config: &Config) -> u64 {
    use iceoryx2::node::NodeView;
    let mut dead = Vec::new();
    // Listing fails only on an unreadable node directory: then there is nothing to clean.
    let _ = Node::<Svc>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    });
    let node_dir = std::path::PathBuf::from(config.global.node_dir().to_string());
    let suffixes = [
        config.global.node.port_tag_suffix.to_string(),
        config.global.node.service_tag_suffix.to_string(),
    ];
    let mut removed = 0;
    for view in dead {
        let dir = node_dir.join(view.id().value().to_string());
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if suffixes.iter().any(|s| name.ends_with(s.as_str())) {
                // A tag another cleaner removed first is gone either way.
                let _ = std::fs::remove_file(e.path());
            }
        }
        if view.try_remove_stale_resources().is_ok() {
            removed += 1;
        }
    }
    removed
}

/// Publishers of the frame service whose process is alive. Publishers of dead processes are
/// cleaned up on the way (so a restarted or standby field can take their place).
fn live_frame_publishers(factory: &FrameFactory, config: &Config) -> usize {
    use iceoryx2::node::NodeView;
    let mut ids = Vec::new();
    factory.dynamic_config().list_publishers(|p| {
        ids.push(p.node_id);
        CallbackProgression::Continue
    });
    if ids.is_empty() {
        return 0;
    }
    let mut dead = 0;
    let _ = Node::<Svc>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            if ids.contains(view.id()) {
                dead += 1;
                let _ = view.try_remove_stale_resources();
            }
        }
        CallbackProgression::Continue
    });
    ids.len().saturating_sub(dead)
}

/// Whether a frame publisher of a live process is attached. Looks only at the nodes of the frame
/// service and removes nothing (cheap enough to call every tick period while frames are late).
fn primary_alive(factory: &FrameFactory, own_node: &iceoryx2::identifiers::UniqueNodeId) -> bool {
    use iceoryx2::node::NodeView;
    use iceoryx2::service::port_factory::PortFactory as _;
    let mut ids = Vec::new();
    factory.dynamic_config().list_publishers(|p| {
        if p.node_id != *own_node {
            ids.push(p.node_id);
        }
        CallbackProgression::Continue
    });
    let mut alive = false;
    let listed = factory.nodes(|state| {
        match &state {
            NodeState::Dead(view) if ids.contains(view.id()) => {}
            other if ids.contains(other.node_id()) => alive = true,
            _ => {}
        }
        CallbackProgression::Continue
    });
    // A publisher whose node cannot be inspected counts as alive (never steal a live field).
    alive || listed.is_err()
}

/// Ports attached to a field's services, as the services record them (ports of processes that
/// died count until `cleanup_dead_nodes` removed them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FieldStatus {
    /// Frame publishers (1 while a field runs).
    pub publishers: usize,
    /// Frame subscribers: readers, a standby, and the field's own subscription.
    pub subscribers: usize,
    /// Deposit publishers.
    pub depositors: usize,
    /// Deposit subscribers: the field, and a standby.
    pub deposit_subscribers: usize,
}

/// Watches the ports attached to a field's services. Opening a service cleans up dead nodes
/// that use it; watching does not, so the counts show what the field itself has cleaned.
pub struct FieldWatch {
    frames: FrameFactory,
    deposits: iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, DepositMsg, ()>,
}

impl FieldWatch {
    /// Opens field `field`'s services; `ShmError::NoField` if they do not exist.
    pub fn open(node: &Node<Svc>, field: &str) -> Result<Self, ShmError> {
        let names = FieldServices::new(field)?;
        Ok(Self {
            frames: frame_service(node, &names, None)?,
            deposits: deposit_service(node, &names, None)?,
        })
    }

    pub fn status(&self) -> FieldStatus {
        let (f, d) = (self.frames.dynamic_config(), self.deposits.dynamic_config());
        FieldStatus {
            publishers: f.number_of_publishers(),
            subscribers: f.number_of_subscribers(),
            depositors: d.number_of_publishers(),
            deposit_subscribers: d.number_of_subscribers(),
        }
    }
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
type FrameFactory =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [f32], FrameHeader>;
type DepositSubscriber = Subscriber<Svc, DepositMsg, ()>;
type EventFactory = iceoryx2::service::port_factory::event::PortFactory<Svc>;
/// A frame received from shared memory.
pub type FrameSample = Sample<Svc, [f32], FrameHeader>;

fn frame_service(
    node: &Node<Svc>,
    names: &FieldServices,
    config: Option<&FieldConfig>,
) -> Result<FrameFactory, ShmError> {
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
            // Every reader's process, the field, a standby and a spare (iceoryx2's default
            // admits 20 nodes whatever the readers).
            .max_nodes(c.max_readers + 4)
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
        // Listeners: every reader and every deposit publisher (which waits for frames to flush).
        b.max_listeners(1024)
            .max_notifiers(4)
            .max_nodes(1028)
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
            .max_nodes(c.max_depositors + 2)
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
    deposits: DepositSubscriber,
    notifier: iceoryx2::port::notifier::Notifier<Svc>,
}

/// The ports of a running field.
struct Ports {
    publisher: FramePublisher,
    own: FrameSubscriber,
    deposits: DepositSubscriber,
    notifier: iceoryx2::port::notifier::Notifier<Svc>,
}

fn check_shm_space(config: &FieldConfig) -> Result<(), ShmError> {
    let (frames, needed) = frame_pool(config);
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
    Ok(())
}

fn create_publisher(
    names: &FieldServices,
    config: &FieldConfig,
    frame_service: &FrameFactory,
    ready_service: &EventFactory,
) -> Result<(FramePublisher, iceoryx2::port::notifier::Notifier<Svc>), ShmError> {
    let publisher = frame_service
        .publisher_builder()
        .initial_max_slice_len(config.frame_len())
        .allocation_strategy(AllocationStrategy::Static)
        .max_loaned_samples(1)
        .create()
        .map_err(|e| service_err(&names.frame, "create publisher", e))?;
    let notifier = ready_service
        .notifier_builder()
        .default_event_id(FRAME_READY)
        .create()
        .map_err(|e| service_err(&names.frame_ready, "create notifier", e))?;
    Ok((publisher, notifier))
}

/// How a field's first frame is made.
enum FirstFrame<'a> {
    Zeros,
    /// Publish these cells as they are, resuming the header's counters (restore).
    Restore(FrameHeader, &'a [f32]),
    /// Compute the next frame from these cells with the pending deposits (takeover).
    Continue(FrameHeader, &'a [f32]),
}

impl FieldServer {
    /// Creates the services and publishes the first frame (zeros, or `restore` = header + cells).
    pub fn start(
        node: &Node<Svc>,
        field: &str,
        config: FieldConfig,
        restore: Option<(FrameHeader, &[f32])>,
    ) -> Result<Self, ShmError> {
        let first = match restore {
            Some((h, cells)) => FirstFrame::Restore(h, cells),
            None => FirstFrame::Zeros,
        };
        Self::start_inner(node, field, config, first)
    }

    fn start_inner(
        node: &Node<Svc>,
        field: &str,
        config: FieldConfig,
        first_frame: FirstFrame<'_>,
    ) -> Result<Self, ShmError> {
        let names = FieldServices::new(field)?;
        let stepper = Stepper::new(config).map_err(|e| ShmError::Service {
            service: names.frame.clone(),
            action: "configure",
            detail: e.to_string(),
        })?;
        let config = stepper.config().clone();
        check_shm_space(&config)?;
        let frame_service = frame_service(node, &names, Some(&config))?;
        if frame_service.dynamic_config().number_of_publishers() > 0 {
            return Err(ShmError::AlreadyRunning {
                field: field.into(),
            });
        }
        let ready_service = frame_ready_service(node, &names, true)?;
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
        let (publisher, notifier) =
            create_publisher(&names, &config, &frame_service, &ready_service)?;
        Self::launch(
            field,
            names,
            stepper,
            Ports {
                publisher,
                own,
                deposits,
                notifier,
            },
            first_frame,
            &[],
        )
    }

    /// Publishes the first frame with ports created beforehand (by `start_inner`, or by a standby
    /// long before it takes over).
    fn launch(
        field: &str,
        names: FieldServices,
        mut stepper: Stepper,
        ports: Ports,
        first_frame: FirstFrame<'_>,
        pending: &[DepositMsg],
    ) -> Result<Self, ShmError> {
        let Ports {
            publisher,
            own,
            deposits,
            notifier,
        } = ports;
        let config = stepper.config().clone();
        // First frame: zeros, the restored cells, or the next frame computed from them.
        let len = config.frame_len();
        let mut first = publisher
            .loan_slice(len)
            .map_err(|e| service_err(&names.frame, "loan first frame", e))?;
        if let FirstFrame::Restore(_, cells) | FirstFrame::Continue(_, cells) = &first_frame {
            if cells.len() != len {
                return Err(ShmError::RestoreMismatch {
                    got: cells.len(),
                    expected: len,
                });
            }
        }
        match first_frame {
            FirstFrame::Zeros => {
                *first.user_header_mut() = stepper.header(now_ns(), 0, &TickReport::default());
            }
            FirstFrame::Restore(header, cells) => {
                first.payload_mut().copy_from_slice(cells);
                stepper.resume_from(&header);
                *first.user_header_mut() = stepper.header(now_ns(), 0, &TickReport::default());
            }
            FirstFrame::Continue(header, cells) => {
                stepper.resume_from(&header);
                for d in pending {
                    let _ = stepper.offer(d);
                }
                let started = now_ns();
                let report = stepper.step(cells, first.payload_mut());
                let done = now_ns();
                *first.user_header_mut() =
                    stepper.header(done, done.saturating_sub(started), &report);
            }
        }
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
///
/// When the field dies the reader keeps its last frame (`frame()` still lends it) and
/// `field_alive` turns false; a field restarted under the same name (or a standby taking over)
/// publishes to the same services, and the reader receives its frames without attaching again.
pub struct FieldReader {
    names: FieldServices,
    service: FrameFactory,
    node_config: Config,
    subscriber: FrameSubscriber,
    listener: iceoryx2::port::listener::Listener<Svc>,
    latest: Option<FrameSample>,
}

impl FieldReader {
    /// Attaches to the running field `field`; fails with `ShmError::NoField` if there is none.
    pub fn attach(node: &Node<Svc>, field: &str) -> Result<Self, ShmError> {
        let names = FieldServices::new(field)?;
        let service = frame_service(node, &names, None)?;
        let subscriber = service
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
            service,
            node_config: node.config().clone(),
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

    /// Whether a live field process publishes this field. False when no field is attached or
    /// when the field's process died (its leftover ports are then removed, so a restarted field
    /// can take over). Costs a scan of the host's iceoryx2 nodes: call it when frames stop
    /// coming, not per frame.
    pub fn field_alive(&self) -> bool {
        live_frame_publishers(&self.service, &self.node_config) > 0
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
        wait_interruptible(&self.listener, timeout, &self.names.frame_ready)?;
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

/// What `Standby::poll` saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StandbyEvent {
    /// A newer frame of the primary was mirrored.
    Mirrored { sequence: u64 },
    /// No newer frame; the primary is alive, or silent for less than the takeover threshold.
    Waiting,
    /// The primary is gone (no publisher, or its process died): call `Standby::take_over`.
    PrimaryGone,
}

/// What a takeover started from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Takeover {
    /// Sequence number of the last frame mirrored from the primary (0 if none came).
    pub last_mirrored_sequence: u64,
    /// Its monotonic stamp (ns).
    pub last_mirrored_stamp_ns: u64,
    /// When the standby found the primary gone (ns).
    pub detected_stamp_ns: u64,
    /// Stamp of the standby's first own frame (ns).
    pub first_stamp_ns: u64,
    /// Deposits received after the last mirrored frame, applied to the first own frame.
    pub deposits_carried: usize,
}

/// A standby field: mirrors a running field (its frames and its deposit stream) and, when the
/// primary dies, becomes the publisher of the same services, continuing from the last frame.
///
/// Frames are mirrored without a copy (the standby holds the newest sample, as a reader does);
/// the one copy happens at takeover, when the first own frame is computed from it. The standby
/// is hot: it creates its publisher and notifier when it attaches (the frame service admits two
/// publishers; it sends nothing until it takes over), so a takeover costs about one tick. This
/// doubles the field's frame pool in /dev/shm, and while a standby runs, readers count the field
/// as alive even if the primary died (the standby is about to serve it). Run one standby per field.
///
/// Deposits: the standby subscribes to the deposit service beside the primary, so every deposit
/// reaches both. When a frame of the primary arrives, the standby drops what it has queued (the
/// primary took those deposits before publishing that frame, or takes them into the next one);
/// deposits that arrive after that are kept and applied to the first frame after a takeover.
/// Lost at a takeover are at most the deposits the primary took after its last published frame
/// and those that reached the standby between the primary's drain and the standby's reception of
/// that frame: less than one tick. None is applied twice.
pub struct Standby {
    field: String,
    names: FieldServices,
    config: FieldConfig,
    service: FrameFactory,
    own_node: iceoryx2::identifiers::UniqueNodeId,
    /// Mirrors the primary's frames now; the field's own subscription after the takeover.
    frames: FrameSubscriber,
    listener: iceoryx2::port::listener::Listener<Svc>,
    deposits: DepositSubscriber,
    publisher: FramePublisher,
    notifier: iceoryx2::port::notifier::Notifier<Svc>,
    pending: Vec<DepositMsg>,
    latest: Option<FrameSample>,
    last_frame_at: Instant,
    silence_limit: Duration,
    /// Frames of the primary mirrored so far.
    pub mirrored: u64,
    /// Deposits kept for a takeover but dropped because more than `deposit_buffer` queued up.
    pub dropped: u64,
}

impl Standby {
    /// Attaches to the running field `field` as its standby. `config` must describe the same
    /// grid (checked against every mirrored frame). The primary counts as gone once it sent no
    /// frame for two tick periods and its process is dead or its publisher absent.
    pub fn attach(node: &Node<Svc>, field: &str, config: FieldConfig) -> Result<Self, ShmError> {
        let names = FieldServices::new(field)?;
        config.validate().map_err(|e| ShmError::StandbyMismatch {
            field: field.into(),
            detail: e.to_string(),
        })?;
        let service = frame_service(node, &names, None)?;
        let frames = service
            .subscriber_builder()
            .buffer_size(1)
            .create()
            .map_err(|e| service_err(&names.frame, "create standby subscriber", e))?;
        let ready_service = frame_ready_service(node, &names, false)?;
        let listener = ready_service
            .listener_builder()
            .create()
            .map_err(|e| service_err(&names.frame_ready, "create listener", e))?;
        let deposits = deposit_service(node, &names, None)?
            .subscriber_builder()
            .buffer_size(config.deposit_buffer)
            .create()
            .map_err(|e| service_err(&names.deposit, "create standby subscriber", e))?;
        check_shm_space(&config)?;
        let (publisher, notifier) = create_publisher(&names, &config, &service, &ready_service)?;
        let silence_limit = Duration::from_secs_f64(2.0 / config.tick_hz as f64);
        let mut standby = Self {
            field: field.into(),
            names,
            pending: Vec::with_capacity(config.deposit_buffer),
            config,
            service,
            own_node: *node.id(),
            frames,
            listener,
            deposits,
            publisher,
            notifier,
            latest: None,
            last_frame_at: Instant::now(),
            silence_limit,
            mirrored: 0,
            dropped: 0,
        };
        standby.receive_frames()?;
        Ok(standby)
    }

    /// Attaches, retrying while the primary does not exist yet, for at most `timeout`.
    pub fn attach_within(
        node: &Node<Svc>,
        field: &str,
        config: FieldConfig,
        timeout: Duration,
    ) -> Result<Self, ShmError> {
        retry_attach(node, timeout, || Self::attach(node, field, config.clone()))
    }

    pub fn field(&self) -> &str {
        &self.field
    }

    /// The newest mirrored frame's header.
    pub fn latest(&self) -> Option<&FrameHeader> {
        self.latest.as_ref().map(|s| s.user_header())
    }

    /// Deposits kept for a takeover right now.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// Takes the newest frame that arrived, checks it fits the configuration; returns whether
    /// one came.
    fn receive_frames(&mut self) -> Result<bool, ShmError> {
        let mut fresh = false;
        loop {
            match self.frames.receive() {
                Ok(Some(s)) => {
                    let h = s.user_header();
                    let c = &self.config;
                    if h.geometry() != c.geometry()
                        || h.channels as usize != c.channels.len()
                        || s.payload().len() != c.frame_len()
                        || h.dt_secs != c.dt_secs()
                    {
                        return Err(ShmError::StandbyMismatch {
                            field: self.field.clone(),
                            detail: format!(
                                "the primary publishes {}×{} cells × {} channel(s) of {} m at \
                                 ({}, {}), dt {} s; this standby is configured for {}×{} × {} of \
                                 {} m at ({}, {}), dt {} s (start it with the primary's \
                                 configuration)",
                                h.width,
                                h.height,
                                h.channels,
                                h.cell_size_m,
                                h.origin_x_m,
                                h.origin_y_m,
                                h.dt_secs,
                                c.width,
                                c.height,
                                c.channels.len(),
                                c.cell_size_m,
                                c.origin_x_m,
                                c.origin_y_m,
                                c.dt_secs()
                            ),
                        });
                    }
                    self.latest = Some(s);
                    fresh = true;
                }
                Ok(None) => break,
                Err(e) => return Err(service_err(&self.names.frame, "receive", e)),
            }
        }
        if fresh {
            self.mirrored += 1;
            self.last_frame_at = Instant::now();
        }
        Ok(fresh)
    }

    /// Takes the deposits queued for the standby: dropped when `keep` is false, else kept.
    fn drain_deposits(&mut self, keep: bool) -> Result<(), ShmError> {
        loop {
            match self.deposits.receive() {
                Ok(Some(d)) => {
                    if !keep {
                        continue;
                    }
                    if self.pending.len() < self.config.deposit_buffer {
                        self.pending.push(*d.payload());
                    } else {
                        self.dropped += 1;
                    }
                }
                Ok(None) => return Ok(()),
                Err(e) => return Err(service_err(&self.names.deposit, "receive", e)),
            }
        }
    }

    /// Waits up to `timeout` for the primary's next frame and mirrors it; tells when the primary
    /// is gone.
    pub fn poll(&mut self, timeout: Duration) -> Result<StandbyEvent, ShmError> {
        let mut fresh = self.receive_frames()?;
        if !fresh {
            // Wake up no later than when the silence reaches the takeover threshold.
            let until_limit = self
                .silence_limit
                .saturating_sub(self.last_frame_at.elapsed());
            let timeout = if until_limit.is_zero() {
                timeout
            } else {
                timeout.min(until_limit)
            };
            wait_interruptible(&self.listener, timeout, &self.names.frame_ready)?;
            fresh = self.receive_frames()?;
        }
        if fresh {
            self.pending.clear();
            self.drain_deposits(false)?;
            let sequence = self.latest().map(|h| h.sequence).unwrap_or(0);
            return Ok(StandbyEvent::Mirrored { sequence });
        }
        self.drain_deposits(true)?;
        if self.last_frame_at.elapsed() >= self.silence_limit
            && !primary_alive(&self.service, &self.own_node)
        {
            return Ok(StandbyEvent::PrimaryGone);
        }
        Ok(StandbyEvent::Waiting)
    }

    /// Becomes the field: creates the publisher (after removing what the dead primary left) and
    /// publishes the next frame, computed from the last mirrored one with the deposits kept
    /// since. Call it after `poll` said `PrimaryGone`.
    pub fn take_over(mut self, node: &Node<Svc>) -> Result<(FieldServer, Takeover), ShmError> {
        let detected_stamp_ns = now_ns();
        // Frames the primary sent just before it died are still queued: take them first.
        if self.receive_frames()? {
            self.pending.clear();
            self.drain_deposits(false)?;
        }
        self.drain_deposits(true)?;
        let Standby {
            field,
            names,
            config,
            frames,
            deposits,
            publisher,
            notifier,
            pending,
            latest,
            ..
        } = self;
        let (last_sequence, last_stamp) = latest
            .as_ref()
            .map(|s| (s.user_header().sequence, s.user_header().stamp_ns))
            .unwrap_or((0, 0));
        let first = match &latest {
            Some(s) => FirstFrame::Continue(*s.user_header(), s.payload()),
            None => FirstFrame::Zeros,
        };
        let stepper = Stepper::new(config).map_err(|e| ShmError::Service {
            service: names.frame.clone(),
            action: "configure",
            detail: e.to_string(),
        })?;
        // The mirrored sample is released once the first own frame is computed from it; the
        // mirroring subscription becomes the field's own (it receives only this publisher's
        // frames from now on: the primary is dead and its last frames were taken above).
        let ports = Ports {
            publisher,
            own: frames,
            deposits,
            notifier,
        };
        let server = FieldServer::launch(&field, names, stepper, ports, first, &pending)?;
        drop(latest);
        // Now free what the dead primary left (its ports, its frames, its reader slot).
        cleanup_dead_nodes(node);
        let first_stamp_ns = server
            .latest()
            .map(|(h, _)| h.stamp_ns)
            .unwrap_or_else(now_ns);
        Ok((
            server,
            Takeover {
                last_mirrored_sequence: last_sequence,
                last_mirrored_stamp_ns: last_stamp,
                detected_stamp_ns,
                first_stamp_ns,
                deposits_carried: pending.len(),
            },
        ))
    }
}
