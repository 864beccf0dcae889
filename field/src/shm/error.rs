//! The errors of the field's shared memory, one per operation: attaching a process
//! ([`AttachError`]), starting a field ([`StartError`]), sending ([`SendError`]), receiving
//! ([`ReceiveError`]), publishing a frame ([`TickError`]) and a standby's work
//! ([`StandbyError`]). Two errors they share are their own types: a name that cannot be used
//! ([`NameError`]) and a failed iceoryx2 operation ([`ServiceError`], which names the service and
//! the action and keeps iceoryx2's error as its source: `{:#}` or the source chain shows it).
//! [`ShmError`] is their sum, for callers that mix operations (a process loop that attaches,
//! receives and sends): `?` converts each into it, and it displays as the error it holds.
//! Another crate's error that holds a `ShmError` gets the same conversions with
//! [`from_shm_errors!`](crate::from_shm_errors) (`?` applies one `From`, not two).

use std::path::PathBuf;

use crate::wire::LAYOUT_VERSION;

/// The cause of a failed iceoryx2 operation: iceoryx2's own error, kept as the source of a
/// [`ServiceError`] or a name error.
pub type Cause = Box<dyn std::error::Error + Send + Sync + 'static>;

/// An iceoryx2 error type that does not implement `std::error::Error` (e.g. a listener's wait
/// error), kept as it is; it displays as its debug form.
#[derive(Debug)]
pub struct Iceoryx<E: std::fmt::Debug>(pub E);

impl<E: std::fmt::Debug> std::fmt::Display for Iceoryx<E> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}", self.0)
    }
}

impl<E: std::fmt::Debug> std::error::Error for Iceoryx<E> {}

/// An iceoryx2 operation on a service failed: opening or creating it, creating a port,
/// loaning, sending, receiving, waiting, listing.
#[derive(Debug, thiserror::Error)]
#[error("service '{service}': {action} failed")]
pub struct ServiceError {
    /// The service (or `*` for the host's service listing).
    pub service: String,
    /// What was being done ("open", "create subscriber", "send"…).
    pub action: &'static str,
    /// iceoryx2's error.
    #[source]
    pub source: Cause,
}

/// A name that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum NameError {
    /// A field, robot or iceoryx2-domain name is not 1–64 characters of `A–Z a–z 0–9 _ -`
    /// ([`check_name`](super::check_name)).
    #[error("invalid name '{name}': {reason}")]
    Invalid {
        /// The name as given.
        name: String,
        /// What is wrong with it (empty, too long, a character outside the set).
        reason: String,
    },
    /// iceoryx2 refuses a service, node or file-prefix name made from a name.
    #[error("invalid iceoryx2 name '{name}'")]
    Iceoryx {
        /// The service, node or file-prefix name iceoryx2 refused.
        name: String,
        /// iceoryx2's error.
        #[source]
        source: Cause,
    },
}

/// Why a process could not attach: create its iceoryx2 node
/// ([`create_node`](super::create_node)), open a running field's services (a
/// [`FieldReader`](super::FieldReader), a [`DepositPublisher`](super::DepositPublisher), a
/// [`FieldWatch`](super::FieldWatch), a bridge's [`InputsSubscriber`](super::InputsSubscriber)
/// or [`ConfigSubscriber`](super::ConfigSubscriber)), or open a `link` or the `lockstep`.
#[derive(Debug, thiserror::Error)]
pub enum AttachError {
    /// A field, node or service name that cannot be used.
    #[error(transparent)]
    Name(#[from] NameError),
    /// The iceoryx2 domain holds another user's directory or management segment.
    #[error(transparent)]
    Domain(#[from] DomainError),
    /// iceoryx2 could not create the process's node.
    #[error("cannot create the iceoryx2 node '{name}'")]
    Node {
        /// The node's name.
        name: String,
        /// iceoryx2's error.
        #[source]
        source: iceoryx2::node::NodeCreationFailure,
    },
    /// The field's frame or deposit service does not exist: no field of that name runs (yet;
    /// the `attach_within`s retry on it).
    #[error("no field called '{field}' is running (service '{service}' does not exist)")]
    NoField {
        /// The field asked for.
        field: String,
        /// The service that was not found (e.g. `pheromone/F/frame`).
        service: String,
    },
    /// The service exists with other message types: its creator was built with another layout
    /// version.
    #[error(
        "service '{service}' was created with another message layout: this build speaks \
         {ours} (layout v{LAYOUT_VERSION}); rebuild the client and the field from the same version"
    )]
    Layout {
        /// The service whose message types differ.
        service: String,
        /// The type name this build uses (`pheromone::<Name>/v<LAYOUT_VERSION>`).
        ours: &'static str,
    },
    /// The field's current frame, taken by a reader as it attaches, has not as many cells as
    /// its header says.
    #[error("the frame received has {got} cells but its header says {expected}")]
    BadFrame {
        /// Cells the frame holds.
        got: usize,
        /// Cells its header (channels × width × height) says it has.
        expected: usize,
    },
    /// Opening a service, creating a port on it, taking a reader's first frame or announcing a
    /// lockstep join failed (the `attach_within`s retry on it).
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// A signal the program handles itself cut short a wait between attach attempts (its
    /// handler ran; nothing was consumed). Not in a process that called
    /// [`handle_termination_requests`](super::handle_termination_requests).
    #[error("attaching to field '{field}' was interrupted by a signal")]
    Interrupted {
        /// The field being attached to.
        field: String,
    },
}

/// Why a field could not start: a [`FieldServer`](super::FieldServer) (its services, its first
/// frame, its inputs for a bridge), a [`FrameWriter`](super::FrameWriter), or a standby's
/// first own frame.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// The field's name, or a service name made from it, cannot be used.
    #[error(transparent)]
    Name(#[from] NameError),
    /// The configuration is invalid (`FieldConfig::validate`, or a thread count).
    #[error("field '{field}': the configuration is invalid")]
    Config {
        /// The field being started.
        field: String,
        /// The setting at fault.
        #[source]
        source: crate::ConfigError,
    },
    /// A live process publishes the field's frames already.
    #[error("another field process already publishes '{field}'")]
    AlreadyRunning {
        /// The field's name.
        field: String,
    },
    /// /dev/shm has less room than the frame pool needs ([`frame_pool`](super::frame_pool)).
    #[error(
        "the field needs {needed_bytes} bytes of shared memory ({frames} frames of {frame_bytes} \
         bytes) but /dev/shm has {available_bytes} free; shrink the grid or --max-readers, or \
         enlarge /dev/shm"
    )]
    NoMemory {
        /// Bytes the frame pool needs: `frames × frame_bytes`.
        needed_bytes: u64,
        /// Bytes free on /dev/shm.
        available_bytes: u64,
        /// Frames in the pool: `(max_readers + 1) × (1 + READER_BORROWED_FRAMES) + 2`.
        frames: u64,
        /// Bytes of one frame's cells.
        frame_bytes: u64,
    },
    /// The field's frame service exists with other message types: a process of another layout
    /// version created it.
    #[error(
        "service '{service}' was created with another message layout: this build speaks \
         {ours} (layout v{LAYOUT_VERSION}); rebuild the client and the field from the same version"
    )]
    Layout {
        /// The service whose message types differ.
        service: String,
        /// The type name this build uses (`pheromone::<Name>/v<LAYOUT_VERSION>`).
        ours: &'static str,
    },
    /// The restored frame (a checkpoint's, or a standby's last mirrored one) has not the
    /// configuration's number of cells.
    #[error("the restored frame has {got} cells, the configuration needs {expected}")]
    RestoreMismatch {
        /// Cells the restored frame holds.
        got: usize,
        /// Cells the configuration needs (channels × width × height).
        expected: usize,
    },
    /// Creating a service or a port, or publishing the first frame or the configuration, failed.
    #[error(transparent)]
    Service(#[from] ServiceError),
}

/// Why a message was not sent: a deposit
/// ([`DepositPublisher::send`](super::DepositPublisher::send)) or a `link`'s message (the
/// `lockstep`'s clock and acknowledgements among them).
#[derive(Debug, thiserror::Error)]
pub enum SendError {
    /// No field took the deposit: none is subscribed to the deposit service, or its buffer is
    /// full.
    #[error(
        "deposit not delivered: no field is subscribed to '{service}' or its deposit buffer is full"
    )]
    NoSubscriber {
        /// The deposit service (`pheromone/F/deposit`).
        service: String,
    },
    /// iceoryx2 could not send the deposit.
    #[error("deposit on '{service}' not delivered")]
    NotDelivered {
        /// The deposit service.
        service: String,
        /// iceoryx2's error.
        #[source]
        source: Cause,
    },
    /// A confirmed deposit ([`DepositClient`](super::DepositClient)) got no receipt in time:
    /// it may still be applied, once, or not at all.
    #[error(
        "no receipt from the field on '{service}' within {timeout_s} s: the deposit may still be \
         applied (once), or not at all"
    )]
    Unconfirmed {
        /// The confirm service (`pheromone/F/deposit-confirm`).
        service: String,
        /// How long the client waited (s).
        timeout_s: f64,
    },
    /// A signal the program handles itself cut short the wait for a confirmed deposit's receipt
    /// (its handler ran): as with `Unconfirmed`, the deposit may still be applied, once, or not
    /// at all. Not in a process that called
    /// [`handle_termination_requests`](super::handle_termination_requests).
    #[error(
        "the wait for the receipt on '{service}' was interrupted by a signal: the deposit may \
         still be applied (once), or not at all"
    )]
    Interrupted {
        /// The service waited on.
        service: String,
    },
    /// iceoryx2 could not send a link's message or a confirmed deposit, or receive its receipt.
    #[error(transparent)]
    Service(#[from] ServiceError),
}

/// Why a frame or a message could not be received: a reader's
/// ([`FieldReader::update`](super::FieldReader::update) and its waits), a bridge's or a
/// gateway's ([`InputsSubscriber`](super::InputsSubscriber),
/// [`ConfigSubscriber`](super::ConfigSubscriber)), a `link`'s.
#[derive(Debug, thiserror::Error)]
pub enum ReceiveError {
    /// A frame's cells are not as many as its header says.
    #[error("the frame received has {got} cells but its header says {expected}")]
    BadFrame {
        /// Cells the frame holds.
        got: usize,
        /// Cells its header (channels × width × height) says it has.
        expected: usize,
    },
    /// A signal the program handles itself cut the wait short (its handler ran; nothing was
    /// consumed): the program looks at its own flags and waits again if it wants. Not in a
    /// process that called [`handle_termination_requests`](super::handle_termination_requests).
    #[error("the wait on '{service}' was interrupted by a signal")]
    Interrupted {
        /// The service waited on.
        service: String,
    },
    /// Receiving or waiting failed, or a received configuration cannot be read.
    #[error(transparent)]
    Service(#[from] ServiceError),
}

/// Why a field could not publish its next frame: a tick
/// ([`FieldServer::tick`](super::FieldServer::tick)), a mirror's frame
/// ([`FieldServer::apply_inputs`](super::FieldServer::apply_inputs),
/// [`FieldServer::reset_to`](super::FieldServer::reset_to)), a
/// [`FrameWriter::publish`](super::FrameWriter::publish), or the field's work between frames
/// (serving readers that attached, looking at the deposit queue).
#[derive(Debug, thiserror::Error)]
pub enum TickError {
    /// The previous frame the field holds has not the configuration's number of cells.
    #[error("the frame received has {got} cells but its header says {expected}")]
    BadFrame {
        /// Cells the previous frame holds.
        got: usize,
        /// Cells the configuration needs.
        expected: usize,
    },
    /// A mirror's keyframe ([`FieldServer::reset_to`](super::FieldServer::reset_to)) has not
    /// the configuration's number of cells.
    #[error("the restored frame has {got} cells, the configuration needs {expected}")]
    RestoreMismatch {
        /// Cells the restored frame holds.
        got: usize,
        /// Cells the configuration needs (channels × width × height).
        expected: usize,
    },
    /// Draining the deposits, loaning, sending or receiving a frame, publishing its inputs, or
    /// connecting readers failed.
    #[error(transparent)]
    Service(#[from] ServiceError),
}

/// Why a [`Standby`](super::Standby) could not attach, mirror its primary or take over.
#[derive(Debug, thiserror::Error)]
pub enum StandbyError {
    /// Opening the running field's services failed (`attach_within` retries while there is no
    /// field, or the opening failed).
    #[error(transparent)]
    Attach(#[from] AttachError),
    /// The standby's configuration is invalid, or the primary's frames are not of its grid.
    #[error("the standby cannot mirror field '{field}': {detail}")]
    Mismatch {
        /// The field being mirrored.
        field: String,
        /// What differs (the setting, or the frame's size against the grid's).
        detail: String,
    },
    /// Its own frames could not be prepared (/dev/shm too small, the publisher) or the first
    /// published at the takeover.
    #[error(transparent)]
    Start(#[from] StartError),
    /// Receiving the primary's frames or deposits, or waiting for them, failed.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// A signal the program handles itself cut the wait for the primary's next frame short
    /// (only where the program owns its signals, see `shm::stop_when`).
    #[error("the standby's wait on '{service}' was interrupted by a signal")]
    Interrupted {
        /// The frame-ready event service waited on.
        service: String,
    },
}

/// Any error of the field's shared memory, for a caller that mixes operations; `?` converts
/// each per-operation error into it, and it displays as the error it holds.
#[derive(Debug, thiserror::Error)]
pub enum ShmError {
    /// Creating a node or opening services failed.
    #[error(transparent)]
    Attach(#[from] AttachError),
    /// A field could not start.
    #[error(transparent)]
    Start(#[from] StartError),
    /// A deposit or a message was not sent.
    #[error(transparent)]
    Send(#[from] SendError),
    /// A frame or a message could not be received.
    #[error(transparent)]
    Receive(#[from] ReceiveError),
    /// A field could not publish a frame.
    #[error(transparent)]
    Tick(#[from] TickError),
    /// A standby could not attach, mirror or take over.
    #[error(transparent)]
    Standby(#[from] StandbyError),
}

/// A failed iceoryx2 operation `action` on `service`, keeping iceoryx2's error.
pub(crate) fn service_err(
    service: &str,
    action: &'static str,
    e: impl Into<Cause>,
) -> ServiceError {
    ServiceError {
        service: service.to_string(),
        action,
        source: e.into(),
    }
}

/// Implements `From` of each per-operation error of [`shm`](crate::shm) for an error type that
/// holds a [`ShmError`] (`From<ShmError>`, e.g. a `#[from] ShmError` variant), so `?` converts
/// them as it converts a `ShmError` (`?` applies one `From`, not two):
/// `pheromone_field::from_shm_errors!(MyError);`.
#[macro_export]
macro_rules! from_shm_errors {
    ($error:ty) => {
        $crate::from_shm_errors!(
            $error: AttachError,
            StartError,
            SendError,
            ReceiveError,
            TickError,
            StandbyError
        );
    };
    ($error:ty: $($op:ident),+) => {
        $(
            impl ::core::convert::From<$crate::shm::$op> for $error {
                fn from(e: $crate::shm::$op) -> Self {
                    Self::from($crate::shm::ShmError::from(e))
                }
            }
        )+
    };
}

/// Why a domain cannot be used by this user.
#[derive(Debug, thiserror::Error)]
pub enum DomainError {
    /// The domain's root directory, or one of its management segments, is not this user's own.
    #[error(
        "{path} {problem}: another user could read or change this user's iceoryx2 domain; \
         remove it (as its owner or root) or pick another domain with --iox-domain"
    )]
    NotPrivate {
        /// The directory or segment.
        path: PathBuf,
        /// What is wrong with it ("belongs to uid 1001, not to uid 1000", "is mode 777").
        problem: String,
    },
    /// The domain's root directory could not be made or read.
    #[error("cannot prepare iceoryx2's directory {path}: {source}")]
    Io {
        /// The directory.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}
