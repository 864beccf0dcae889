//! The field in iceoryx2 shared memory: the field process (`FieldServer`), readers
//! (`FieldReader`) and deposit publishers (`DepositPublisher`). Two of its files allow `unsafe`:
//! `server.rs` (the frame loan) and `inputs.rs` (byte views of wire types).
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
//! frame). `frame_pool` computes it; the field refuses to start when /dev/shm lacks it.
//!
//! Crashes (docs/reliability.md): a process killed with SIGKILL leaves its ports behind;
//! `cleanup_dead_nodes` (which the field calls once a second, and every process calls when it
//! creates its node) removes them, which also returns the frames a dead reader held to the
//! field's pool. Readers tell a dead field with `FieldReader::field_alive`, keep their last frame
//! and receive the frames of a field restarted under the same name. A `Standby` mirrors a running
//! field and becomes its publisher when the primary dies.
//!
//! Errors, one per operation (`error`): `create_node` and every attach return an
//! `AttachError` (`NoField` when no such field runs, `Layout` for another layout version);
//! `FieldServer::start` and `FrameWriter::start` a `StartError`; `DepositPublisher::send` a
//! `SendError` (`NoSubscriber` when no field took the deposit); `FieldReader::update` and its
//! waits a `ReceiveError`; `FieldServer::tick` and the other frame publications a `TickError`;
//! `Standby` a `StandbyError`. Names fail with a `NameError`; every failed iceoryx2 operation is
//! a `ServiceError` inside them. `ShmError` is their sum, for callers that mix operations
//! (`from_shm_errors!` for an error of another crate that holds one).
//!
//! Submodules: `server` (`FieldServer`), `reader` (`FieldReader`), `deposit`
//! (`DepositPublisher`), `standby` (`Standby`), `survey` (the fields of a host, for
//! `pheromone list`), `writer` (`FrameWriter`, frames computed elsewhere: a mapper's map) and
//! `error`, all re-exported here; this file holds what they share (names, nodes, service
//! builders, frame pool sizing).

mod board;
mod config;
mod confirm;
mod deposit;
mod domain;
mod error;
mod half_created;
mod inputs;
mod mirror_state;
mod reader;
mod server;
mod signals;
mod standby;
mod survey;
mod timing;
mod writer;

use std::time::Duration;

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;

use crate::engine::FieldConfig;
use crate::messages::{DepositMsg, FrameHeader};
use crate::wire;

pub use config::ConfigSubscriber;
pub use confirm::{DepositClient, Receipt};
pub use deposit::DepositPublisher;
pub use domain::{domain_config, domain_config_for, domain_config_of, IOX_DOMAIN_ENV};
pub(crate) use error::service_err;
pub use error::{
    AttachError, Cause, DomainError, Iceoryx, NameError, ReceiveError, SendError, ServiceError,
    ShmError, StandbyError, StartError, TickError,
};
pub use half_created::remove_half_created_services;
pub use inputs::{
    f32s_from_bytes, wire_bytes, wire_from_bytes, wire_slice_bytes, wire_vec_from_bytes,
    InputsPublisher, InputsSubscriber,
};
pub use mirror_state::{mirror_info, MirrorInfo, MirrorStateWriter};
pub use reader::{
    values_and_gradients_into, values_into, FieldReader, Frame, ParseWaitPolicyError,
    SampleManyError, WaitPolicy,
};
pub use server::{FieldServer, TickOutcome};
pub use signals::{
    handle_termination_requests, handles_termination_requests, node_wait, should_stop, stop_mark,
    stop_requested, stop_when, stopped_since, StopMark,
};
pub use standby::{Standby, StandbyEvent, Takeover};
pub use survey::{field_names, survey, FieldInfo};
pub use timing::{field_timing, TimingInfo, TimingWriter};
pub use writer::FrameWriter;

/// iceoryx2 service flavour used everywhere: inter-process.
pub type Svc = ipc::Service;

pub use crate::wire::READER_BORROWED_FRAMES;
/// Deposit publishers' and readers' event id for "frame ready".
const FRAME_READY: EventId = EventId::new(0);

/// Waits on the node for `d`; `false` once the process was asked to stop: SIGINT or SIGTERM in a
/// process that called [`handle_termination_requests`], or the program's flag ([`stop_when`]).
/// Any other signal that cuts the sleep short (SIGCONT after a SIGSTOP or Ctrl-Z, SIGCHLD, a
/// signal the program handles itself…) is not a request to stop, although `node.wait` reports
/// it as an interrupt.
pub fn wait_or_stop(node: &Node<Svc>, d: Duration) -> bool {
    use iceoryx2::node::NodeWaitFailure;
    match node_wait(node, d) {
        Ok(()) => !should_stop(node),
        Err(NodeWaitFailure::TerminationRequest) => false,
        Err(NodeWaitFailure::Interrupt) => !stop_requested(),
    }
}

/// The notifier of the field's `deposit-ready` event, if the field has one.
fn open_deposit_ready(
    node: &Node<Svc>,
    names: &FieldServices,
) -> Option<iceoryx2::port::notifier::Notifier<Svc>> {
    open_deposit_ready_service(node, names)
        .ok()?
        .notifier_builder()
        .create()
        .ok()
}

/// A listener's timed wait that never blocks for good. iceoryx2 0.10's listener hands the timeout
/// to its socket's `SO_RCVTIMEO` as a `timeval`: one under a microsecond becomes {0, 0}, which
/// means *no* timeout, and the wait then lasts until the next event (a field waiting for a
/// deposit that its follower sends only after the next frame never woke). Below a microsecond
/// this only takes the events already there.
pub fn listener_timed_wait(
    listener: &iceoryx2::port::listener::Listener<Svc>,
    timeout: Duration,
) -> Result<u64, iceoryx2::port::listener::ListenerWaitError> {
    if timeout < Duration::from_micros(1) {
        listener.try_wait(|_| {})
    } else {
        listener.timed_wait(|_| {}, timeout)
    }
}

/// How a listener's wait ended ([`wait_interruptible`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Woken {
    /// An event, the timeout, or (in a process that handles termination requests itself) a
    /// signal: the caller looks at what it waits for and loops on its own deadline.
    Anyway,
    /// A signal cut the wait short (`EINTR`): the program's own handler ran. Returned only where
    /// the program owns its signals (`signals.rs`), so its loop can look at its flags.
    Interrupted,
}

/// Waits on a listener. A signal that interrupts the wait is a spurious wake-up in a process
/// that handles termination requests through iceoryx2 (callers loop on their own deadline and
/// see Ctrl-C through `stop_requested`); elsewhere it is [`Woken::Interrupted`].
pub(crate) fn wait_interruptible(
    listener: &iceoryx2::port::listener::Listener<Svc>,
    timeout: Duration,
    service: &str,
) -> Result<Woken, ServiceError> {
    match listener_timed_wait(listener, timeout) {
        Ok(_) => Ok(Woken::Anyway),
        Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => {
            Ok(if handles_termination_requests() {
                Woken::Anyway
            } else {
                Woken::Interrupted
            })
        }
        Err(e) => Err(service_err(service, "wait", Iceoryx(e))),
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

pub use crate::wire::FieldServices;

impl FieldServices {
    /// The service names of field `field`, once its name is checked.
    pub fn new(field: &str) -> Result<Self, NameError> {
        check_name(field)?;
        Ok(Self::of(field))
    }
}

/// Field and robot names: 1–64 characters of `[A-Za-z0-9_-]`.
pub fn check_name(name: &str) -> Result<(), NameError> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if ok {
        Ok(())
    } else {
        Err(NameError::Invalid {
            name: name.to_string(),
            reason: "use 1–64 characters from A–Z, a–z, 0–9, '_' and '-'".into(),
        })
    }
}

pub(crate) fn service_name(name: &str) -> Result<ServiceName, NameError> {
    ServiceName::new(name).map_err(|e| NameError::Iceoryx {
        name: name.to_string(),
        source: e.into(),
    })
}

/// Creates an iceoryx2 node and first removes what dead nodes left behind. The node installs no
/// signal handler, unless the program called [`handle_termination_requests`]: then it stops on
/// SIGINT/SIGTERM (`node.wait` returns an error).
pub fn create_node(name: &str) -> Result<Node<Svc>, AttachError> {
    create_node_with(name, domain_config()?)
}

/// As [`create_node`], in iceoryx2 domain `domain` whatever the environment says (a test that
/// stands for two hosts).
pub fn create_node_in(name: &str, domain: Option<&str>) -> Result<Node<Svc>, AttachError> {
    create_node_with(name, domain_config_of(domain)?)
}

fn create_node_with(name: &str, mut domain: Config) -> Result<Node<Svc>, AttachError> {
    let supervised = cleaned_by_supervisor();
    if supervised {
        // iceoryx2's own walks: of every node, as the node is created and dropped; of every
        // node attached to a service, as the service is opened (the lockstep's clock and
        // acknowledgement services have every participant attached).
        domain.global.node.cleanup_dead_nodes_on_creation = false;
        domain.global.node.cleanup_dead_nodes_on_destruction = false;
        domain.global.service.cleanup_dead_nodes_on_open = false;
        // 3N processes start at once: at 256 robots on 2 cores one try at opening or creating a
        // service took iceoryx2's whole 1 s and a follower gave up (issue 52).
        domain.global.creation_timeout = domain.global.creation_timeout.max(RUN_CREATION_TIMEOUT);
    }
    let node_name = NodeName::new(name).map_err(|e| NameError::Iceoryx {
        name: name.to_string(),
        source: Box::new(Iceoryx(e)),
    })?;
    // SIGINT and SIGTERM wait (blocked, pending, in this thread) until the node exists (and,
    // where the program asked for it, iceoryx2's handler is installed): a process stopped while
    // its node is half-created leaves an entry that no cleanup can remove. A signal that came
    // meanwhile is handled at the unblock — by the program's own handler, or by iceoryx2's, and
    // the node's next `wait` reports it.
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
    domain::guard_domain(&domain, !supervised)?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(&domain)
        .signal_handling_mode(signals::node_signal_mode())
        .create::<Svc>()
        .map_err(|e| AttachError::Node {
            name: name.to_string(),
            source: e,
        });
    // Where the program asked for iceoryx2's handling: installs its signal handler (installed on
    // first use); a request it already recorded is latched (`node_wait`). Elsewhere nothing is
    // installed or consumed.
    if handles_termination_requests() {
        if let Ok(n) = &node {
            let _ = node_wait(n, Duration::ZERO);
        }
    }
    if blocked {
        // Restoring the mask the thread had cannot fail with a valid `how`.
        let _ = pthread_sigmask(SigmaskHow::SIG_SETMASK, Some(&previous), None);
    }
    let node = node?;
    if !supervised {
        domain::seal_management_segments(node.config());
        cleanup_dead_nodes(&node);
        remove_half_created_services(node.config());
    }
    Ok(node)
}

/// Set (to `1`) by a supervisor in the environment of the children it starts (`pheromone sim`'s
/// roles, field and world): it has removed what dead nodes left before it started them and does
/// so again after they stop, and a child that dies ends the run. Its children then skip the
/// cleanup at node creation (ours and iceoryx2's, also iceoryx2's at the node's end and as a
/// service is opened) and the field's periodic one: each walk reads the details of every
/// node of the host (a TOML file each), so N children walking N nodes made a run's start-up grow
/// as N² (issue 52: 64 robots, 194 processes, started in 226 s in a debug build, 67 s of it at 32).
pub const CLEANED_BY_SUPERVISOR_ENV: &str = "PHEROMONE_CLEANED_BY_SUPERVISOR";

/// How long a process of a sim's run retries opening or creating a service another creates.
const RUN_CREATION_TIMEOUT: Duration = Duration::from_secs(10);

/// Whether this process's supervisor removes what dead nodes leave ([`CLEANED_BY_SUPERVISOR_ENV`]).
pub fn cleaned_by_supervisor() -> bool {
    std::env::var_os(CLEANED_BY_SUPERVISOR_ENV).is_some_and(|v| v == "1")
}

/// Removes the ports and services that processes killed without cleaning up left behind (their
/// readers' borrowed frames then return to the publisher's pool on its next send). Returns how
/// many dead nodes were cleaned.
pub fn cleanup_dead_nodes(node: &Node<Svc>) -> u64 {
    cleanup_dead_nodes_of(node.config())
}

/// Removes what dead nodes of `config` left behind (the cleanup of [`cleanup_dead_nodes`], also
/// for a process without a node of its own, e.g. a test after a run); returns how many it
/// removed.
///
/// iceoryx2 0.10 leaves the port tag files of a dead node that had no service of its own
/// (upstream issue #1967): its cleanup has removed the ports' resources by then, but the node's
/// directory is not empty, the removal of the node fails and it shows as dead forever. Only for
/// such a node — one whose cleanup *this* call ran and saw fail — are the tags removed and the
/// cleanup run again. A node another process is cleaning, or one that died since the listing,
/// keeps its tags: they are what its cleanup needs to find its services and ports, and removing
/// them would leave those in /dev/shm for good.
pub fn cleanup_dead_nodes_of(config: &Config) -> u64 {
    cleanup_listed_dead_nodes(config) + remove_orphan_node_dirs(config)
}

/// iceoryx2 0.10 lists a node by its monitor token: a process SIGKILLed while it created or
/// cleaned a node can leave that node's directory (its details file) without a token, so no
/// listing shows it and no cleanup removes it. Removes such directories of `config`'s prefix
/// whose process is gone (the details name it), and empty ones older than a minute; a node being
/// created now has a live process. Returns how many it removed.
fn remove_orphan_node_dirs(config: &Config) -> u64 {
    use iceoryx2::node::NodeView;
    let node_dir = std::path::PathBuf::from(config.global.node_dir().to_string());
    let Ok(entries) = std::fs::read_dir(&node_dir) else {
        return 0;
    };
    let mut listed = Vec::new();
    // Listing fails only on an unreadable node directory: then nothing is removed below.
    if Node::<Svc>::list(config, |state| {
        listed.push(match &state {
            NodeState::Alive(v) => v.id().value().to_string(),
            NodeState::Dead(v) => v.id().value().to_string(),
            NodeState::Inaccessible(id) | NodeState::Undefined(id) => id.value().to_string(),
        });
        CallbackProgression::Continue
    })
    .is_err()
    {
        return 0;
    }
    let details = format!(
        "{}node{}",
        config.global.prefix, config.global.node.static_config_suffix
    );
    let mut removed = 0;
    for dir in entries.flatten() {
        let name = dir.file_name().to_string_lossy().into_owned();
        if listed.contains(&name) || !dir.path().is_dir() {
            continue;
        }
        let files: Vec<_> = match std::fs::read_dir(dir.path()) {
            Ok(f) => f.flatten().map(|e| e.path()).collect(),
            Err(_) => continue,
        };
        let orphan = if files.is_empty() {
            dir.metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age > Duration::from_secs(60))
        } else {
            let Some(d) = files
                .iter()
                .find(|f| f.file_name().is_some_and(|n| n == details.as_str()))
            else {
                continue; // another prefix's node, or not a node
            };
            let pid = std::fs::read_to_string(d).ok().and_then(|t| {
                t.lines()
                    .find_map(|l| {
                        l.strip_prefix("process = ")
                            .map(|v| v.trim().parse::<i32>())
                    })
                    .and_then(Result::ok)
            });
            // ESRCH: no such process. Anything else (alive, or not ours to signal) keeps it.
            pid.is_some_and(|p| {
                nix::sys::signal::kill(nix::unistd::Pid::from_raw(p), None)
                    == Err(nix::errno::Errno::ESRCH)
            })
        };
        if !orphan {
            continue;
        }
        for f in &files {
            // A file another cleaner removed first is gone either way.
            let _ = std::fs::remove_file(f);
        }
        if std::fs::remove_dir(dir.path()).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// The cleanup of every node the listing shows dead (see [`cleanup_dead_nodes_of`]).
fn cleanup_listed_dead_nodes(config: &Config) -> u64 {
    use iceoryx2::node::{NodeCleanupFailure, NodeView};
    let mut cleaned = 0;
    let mut failed = Vec::new();
    for view in dead_nodes(config) {
        let id = *view.id();
        match view.try_remove_stale_resources() {
            Ok(()) => cleaned += 1,
            Err(
                NodeCleanupFailure::ResourcesAlreadyCleanedUp
                | NodeCleanupFailure::AnotherInstanceIsCleaningUpTheNode
                | NodeCleanupFailure::Interrupt,
            ) => {}
            Err(_) => failed.push(id),
        }
    }
    // A node whose cleanup failed: its port tags go first (#1967); its service tags only if
    // that was not enough (a service it was creating when it was killed cannot be read).
    let node_dir = std::path::PathBuf::from(config.global.node_dir().to_string());
    for suffix in [
        &config.global.node.port_tag_suffix,
        &config.global.node.service_tag_suffix,
    ] {
        if failed.is_empty() {
            break;
        }
        let suffix = suffix.to_string();
        for view in dead_nodes(config) {
            let id = *view.id();
            if !failed.contains(&id) {
                continue;
            }
            let dir = node_dir.join(id.value().to_string());
            if let Ok(entries) = std::fs::read_dir(&dir) {
                for e in entries.flatten() {
                    if e.file_name().to_string_lossy().ends_with(suffix.as_str()) {
                        // A tag that is gone already is what this wants.
                        let _ = std::fs::remove_file(e.path());
                    }
                }
            }
            if view.try_remove_stale_resources().is_ok() {
                cleaned += 1;
                failed.retain(|f| *f != id);
            }
        }
    }
    // Killed while it created or dropped its node (or emptied by a cleaner of another prefix):
    // a dead monitor token whose node directory is missing or empty, nothing to read or hold,
    // which iceoryx2 lists for good. The directory and the token files go.
    for view in dead_nodes(config) {
        let id = view.id().value().to_string();
        let dir = node_dir.join(&id);
        if std::fs::read_dir(&dir).is_ok_and(|mut d| d.next().is_some())
            || (dir.exists() && std::fs::remove_dir(&dir).is_err())
        {
            continue;
        }
        let token = format!("{}{id}.node_monitor", config.global.prefix);
        for e in std::fs::read_dir(&node_dir).into_iter().flatten().flatten() {
            if e.file_name().to_string_lossy().starts_with(&token) {
                let _ = std::fs::remove_file(e.path());
            }
        }
        cleaned += 1;
    }
    cleaned
}

/// The nodes of `config` whose process is gone.
fn dead_nodes(config: &Config) -> Vec<iceoryx2::node::DeadNodeView<Svc>> {
    let mut dead = Vec::new();
    // Listing fails only on an unreadable node directory: then there is nothing to clean.
    let _ = Node::<Svc>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    });
    dead
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
    /// Clients of the confirm service (`DepositClient`s, and the flush port of each
    /// `DepositPublisher`).
    pub confirm_clients: usize,
}

/// Watches the ports attached to a field's services. Opening a service cleans up dead nodes
/// that use it; watching does not, so the counts show what the field itself has cleaned.
pub struct FieldWatch {
    frames: FrameFactory,
    deposits: DepositFactory,
    confirm: confirm::ConfirmFactory,
}

impl FieldWatch {
    /// Opens field `field`'s services; `AttachError::NoField` if they do not exist.
    pub fn open(node: &Node<Svc>, field: &str) -> Result<Self, AttachError> {
        let names = FieldServices::new(field)?;
        Ok(Self {
            frames: open_frame_service(node, &names)?,
            deposits: open_deposit_service(node, &names)?,
            confirm: confirm::open_confirm_service(node, &names)?,
        })
    }

    /// The port counts now.
    pub fn status(&self) -> FieldStatus {
        let (f, d) = (self.frames.dynamic_config(), self.deposits.dynamic_config());
        FieldStatus {
            publishers: f.number_of_publishers(),
            subscribers: f.number_of_subscribers(),
            depositors: d.number_of_publishers(),
            deposit_subscribers: d.number_of_subscribers(),
            confirm_clients: self.confirm.dynamic_config().number_of_clients(),
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
type DepositFactory =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, DepositMsg, ()>;
type EventFactory = iceoryx2::service::port_factory::event::PortFactory<Svc>;
/// A frame received from shared memory.
pub type FrameSample = Sample<Svc, [f32], FrameHeader>;

/// The frame service's builder.
fn frame_builder(
    node: &Node<Svc>,
    name: &ServiceName,
) -> iceoryx2::service::builder::publish_subscribe::Builder<[f32], FrameHeader, Svc> {
    node.service_builder(name)
        .publish_subscribe::<[f32]>()
        .user_header::<FrameHeader>()
}

/// Opens a running field's frame service.
fn open_frame_service(
    node: &Node<Svc>,
    names: &FieldServices,
) -> Result<FrameFactory, AttachError> {
    frame_builder(node, &service_name(&names.frame)?)
        .open()
        .map_err(|e| open_failure(&names.frame, wire::type_name_of::<FrameHeader>(), e))
}

/// Opens or creates the frame service of a field that starts.
fn create_frame_service(
    node: &Node<Svc>,
    names: &FieldServices,
    c: &FieldConfig,
) -> Result<FrameFactory, StartError> {
    use iceoryx2::service::builder::publish_subscribe::{
        PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError as E,
    };
    frame_builder(node, &service_name(&names.frame)?)
        .history_size(wire::FRAME_HISTORY)
        .subscriber_max_buffer_size(wire::FRAME_SUBSCRIBER_BUFFER)
        .subscriber_max_borrowed_samples(READER_BORROWED_FRAMES)
        // The readers and the field's own subscription.
        .max_subscribers(c.max_readers + 1)
        .max_publishers(wire::FRAME_PUBLISHERS)
        .max_nodes(c.max_readers + wire::FRAME_EXTRA_NODES)
        .open_or_create()
        .map_err(|e| match e {
            E::PublishSubscribeOpenError(PublishSubscribeOpenError::IncompatibleTypes) => {
                StartError::Layout {
                    service: names.frame.clone(),
                    ours: wire::type_name_of::<FrameHeader>(),
                }
            }
            e => service_err(&names.frame, "open or create", e).into(),
        })
}

/// Why opening the existing publish-subscribe service `service` of a field (whose messages are
/// `ours`) failed.
fn open_failure(
    service: &str,
    ours: &'static str,
    e: iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError,
) -> AttachError {
    use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError as E;
    match e {
        E::DoesNotExist => AttachError::NoField {
            field: service.split('/').nth(1).unwrap_or_default().to_string(),
            service: service.to_string(),
        },
        E::IncompatibleTypes => AttachError::Layout {
            service: service.to_string(),
            ours,
        },
        e => service_err(service, "open", e).into(),
    }
}

/// Opens a running field's `frame-ready` event.
fn open_frame_ready_service(
    node: &Node<Svc>,
    names: &FieldServices,
) -> Result<EventFactory, AttachError> {
    Ok(node
        .service_builder(&service_name(&names.frame_ready)?)
        .event()
        .open()
        .map_err(|e| service_err(&names.frame_ready, "open", e))?)
}

/// Opens or creates the `frame-ready` event of a field that starts.
fn create_frame_ready_service(
    node: &Node<Svc>,
    names: &FieldServices,
) -> Result<EventFactory, StartError> {
    Ok(node
        .service_builder(&service_name(&names.frame_ready)?)
        .event()
        .max_listeners(wire::FRAME_READY_LISTENERS)
        .max_notifiers(wire::FRAME_READY_NOTIFIERS)
        .max_nodes(wire::FRAME_READY_LISTENERS + wire::FRAME_READY_NOTIFIERS)
        .open_or_create()
        .map_err(|e| service_err(&names.frame_ready, "open or create", e))?)
}

/// Opens a field's `deposit-ready` event, which exists when the field publishes on deposit:
/// depositors notify it after each deposit.
fn open_deposit_ready_service(
    node: &Node<Svc>,
    names: &FieldServices,
) -> Result<EventFactory, AttachError> {
    Ok(node
        .service_builder(&service_name(&names.deposit_ready)?)
        .event()
        .open()
        .map_err(|e| service_err(&names.deposit_ready, "open", e))?)
}

/// Opens or creates the `deposit-ready` event of a field that publishes on deposit, with room
/// for `max_depositors` notifiers.
pub(crate) fn create_deposit_ready_service(
    node: &Node<Svc>,
    names: &FieldServices,
    c: &FieldConfig,
) -> Result<EventFactory, StartError> {
    let notifiers = c.max_depositors + wire::DEPOSIT_READY_EXTRA_NOTIFIERS;
    Ok(node
        .service_builder(&service_name(&names.deposit_ready)?)
        .event()
        .max_listeners(wire::DEPOSIT_READY_LISTENERS)
        .max_notifiers(notifiers)
        .max_nodes(wire::DEPOSIT_READY_LISTENERS + notifiers)
        .open_or_create()
        .map_err(|e| service_err(&names.deposit_ready, "open or create", e))?)
}

/// Opens a running field's deposit service.
fn open_deposit_service(
    node: &Node<Svc>,
    names: &FieldServices,
) -> Result<DepositFactory, AttachError> {
    node.service_builder(&service_name(&names.deposit)?)
        .publish_subscribe::<DepositMsg>()
        .open()
        .map_err(|e| open_failure(&names.deposit, wire::type_name_of::<DepositMsg>(), e))
}

/// Opens or creates the deposit service of a field that starts.
fn create_deposit_service(
    node: &Node<Svc>,
    names: &FieldServices,
    c: &FieldConfig,
) -> Result<DepositFactory, StartError> {
    Ok(node
        .service_builder(&service_name(&names.deposit)?)
        .publish_subscribe::<DepositMsg>()
        .max_publishers(c.max_depositors)
        .max_subscribers(wire::DEPOSIT_SUBSCRIBERS)
        .max_nodes(c.max_depositors + wire::DEPOSIT_SUBSCRIBERS)
        .subscriber_max_buffer_size(c.deposit_buffer)
        .history_size(wire::DEPOSIT_HISTORY)
        .enable_safe_overflow(false)
        .open_or_create()
        .map_err(|e| service_err(&names.deposit, "open or create", e))?)
}

fn check_shm_space(config: &FieldConfig) -> Result<(), StartError> {
    let (frames, needed) = frame_pool(config);
    if let Some(available) = shm_available_bytes() {
        if needed > available {
            return Err(StartError::NoMemory {
                needed_bytes: needed,
                available_bytes: available,
                frames,
                frame_bytes: config.frame_bytes(),
            });
        }
    }
    Ok(())
}

/// Calls `attach` until it succeeds, for at most `timeout`, while its error is one `retry`
/// accepts (no field yet, a service half-made); waits with `node.wait` between tries. Returns
/// early with the last error on a termination request (a process that handles them through
/// iceoryx2), and with `AttachError::Interrupted` when a signal the program handles itself cuts
/// a wait short.
fn retry_attach<T, E: From<AttachError>>(
    node: &Node<Svc>,
    field: &str,
    timeout: Duration,
    mut attach: impl FnMut() -> Result<T, E>,
    retry: impl Fn(&E) -> bool,
) -> Result<T, E> {
    use iceoryx2::node::NodeWaitFailure;
    let deadline = std::time::Instant::now() + timeout;
    loop {
        match attach() {
            Ok(t) => return Ok(t),
            Err(e) if retry(&e) => {
                let left = deadline.saturating_duration_since(std::time::Instant::now());
                if left.is_zero() {
                    return Err(e);
                }
                match node_wait(node, left.min(Duration::from_millis(20))) {
                    Ok(()) => {}
                    Err(NodeWaitFailure::Interrupt) if !handles_termination_requests() => {
                        return Err(AttachError::Interrupted {
                            field: field.to_string(),
                        }
                        .into())
                    }
                    Err(_) => return Err(e),
                }
            }
            Err(e) => return Err(e),
        }
    }
}

impl AttachError {
    /// The field may not be up yet: its services do not exist, or opening them failed (they
    /// are being created). What the `attach_within`s retry on.
    pub(crate) fn field_not_up_yet(&self) -> bool {
        matches!(self, Self::NoField { .. } | Self::Service(_))
    }
}
