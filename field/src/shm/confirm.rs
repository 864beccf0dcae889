//! Confirmed deposits: the request-response service `pheromone/F/deposit-confirm`.
//!
//! A client sends a [`DepositMsg`]; the field takes it at its next tick with the deposits of
//! that tick, publishes the frame, and answers a [`DepositReceipt`] (applied in frame N, or
//! refused with the reason) before it wakes the readers. A flush request
//! ([`KERNEL_FLUSH`]) deposits nothing: the field takes the requests *before* it drains the
//! publish-subscribe deposit queue, so its receipt says that everything the same process
//! published before it has been taken.
//!
//! Semantics (docs/field.md): at most once. A deposit is applied once or not at all; a client
//! that gave up waiting (timeout) or was killed does not know which, and a deposit whose sender
//! died before the field connected to it is not applied.

use std::time::{Duration, Instant};

use iceoryx2::active_request::ActiveRequest;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;

use super::{
    open_deposit_ready, open_frame_ready_service, retry_attach, service_err, service_name,
    wait_interruptible, AttachError, FieldServices, SendError, ServiceError, StartError, Svc,
    TickError, Woken,
};
use crate::engine::{FieldConfig, Stepper};
use crate::messages::{
    DepositMsg, DepositReceipt, KERNEL_FLUSH, RECEIPT_APPLIED, RECEIPT_FLUSHED, RECEIPT_FORWARDED,
    RECEIPT_REJECTED,
};
use crate::reject::RejectReason;
use crate::wire;

pub(super) type ConfirmFactory = iceoryx2::service::port_factory::request_response::PortFactory<
    Svc,
    DepositMsg,
    (),
    DepositReceipt,
    (),
>;
type Request = ActiveRequest<Svc, DepositMsg, (), DepositReceipt, ()>;

/// Opens or creates the confirm service of a field that starts.
fn create_confirm_service(
    node: &Node<Svc>,
    names: &FieldServices,
    c: &FieldConfig,
) -> Result<ConfirmFactory, StartError> {
    Ok(node
        .service_builder(&service_name(&names.deposit_confirm)?)
        .request_response::<DepositMsg, DepositReceipt>()
        .max_clients(c.max_depositors)
        .max_servers(wire::CONFIRM_SERVERS)
        .max_nodes(c.max_depositors + wire::CONFIRM_SERVERS)
        .max_active_requests_per_client(wire::CONFIRM_ACTIVE_REQUESTS)
        .max_response_buffer_size(wire::CONFIRM_ACTIVE_REQUESTS)
        .open_or_create()
        .map_err(|e| service_err(&names.deposit_confirm, "open or create", e))?)
}

/// Opens the confirm service of a running field.
pub(super) fn open_confirm_service(
    node: &Node<Svc>,
    names: &FieldServices,
) -> Result<ConfirmFactory, AttachError> {
    use iceoryx2::service::builder::request_response::RequestResponseOpenError as E;
    node.service_builder(&service_name(&names.deposit_confirm)?)
        .request_response::<DepositMsg, DepositReceipt>()
        .open()
        .map_err(|e| match e {
            E::DoesNotExist => AttachError::NoField {
                field: field_of(names),
                service: names.deposit_confirm.clone(),
            },
            e => service_err(&names.deposit_confirm, "open", e).into(),
        })
}

fn field_of(names: &FieldServices) -> String {
    names
        .deposit_confirm
        .split('/')
        .nth(1)
        .unwrap_or_default()
        .to_string()
}

/// What the field did with a request, known when it took it.
enum Taken {
    Applied,
    Rejected(RejectReason),
    Flush,
}

/// The field's side: the requests taken this tick, answered once their frame is out.
pub(super) struct ConfirmServer {
    service: String,
    server: Server<Svc, DepositMsg, (), DepositReceipt, ()>,
    held: Vec<(Request, Taken)>,
}

impl ConfirmServer {
    pub(super) fn create(
        node: &Node<Svc>,
        names: &FieldServices,
        config: &FieldConfig,
    ) -> Result<Self, StartError> {
        let server = create_confirm_service(node, names, config)?
            .server_builder()
            .create()
            .map_err(|e| service_err(&names.deposit_confirm, "create server", e))?;
        Ok(Self {
            service: names.deposit_confirm.clone(),
            server,
            held: Vec::new(),
        })
    }

    /// Whether requests wait for the next tick.
    pub(super) fn waiting(&self) -> Result<bool, ServiceError> {
        self.server
            .has_requests()
            .map_err(|e| service_err(&self.service, "look at the queue", e))
    }

    /// Takes every waiting request, offering its deposit to `stepper`; returns how many it
    /// refused (counted in the stepper like any refused deposit).
    pub(super) fn take(&mut self, stepper: &mut Stepper) -> Result<u64, ServiceError> {
        let mut rejected = 0;
        while let Some(request) = self
            .server
            .receive()
            .map_err(|e| service_err(&self.service, "receive", e))?
        {
            let msg = *request.payload();
            let taken = if msg.kernel == KERNEL_FLUSH {
                Taken::Flush
            } else {
                match stepper.offer(&msg) {
                    Ok(()) => Taken::Applied,
                    Err(r) => {
                        rejected += 1;
                        Taken::Rejected(r.reason)
                    }
                }
            };
            self.held.push((request, taken));
        }
        Ok(rejected)
    }

    /// A mirror: takes every waiting request's deposit to forward it, and answers
    /// `RECEIPT_FORWARDED` (flush requests: `RECEIPT_FLUSHED`, as the mirror's own queue is
    /// drained after them).
    pub(super) fn take_forwarded(&mut self, out: &mut Vec<DepositMsg>) -> Result<(), TickError> {
        while let Some(request) = self
            .server
            .receive()
            .map_err(|e| service_err(&self.service, "receive", e))?
        {
            let msg = *request.payload();
            let status = if msg.kernel == KERNEL_FLUSH {
                RECEIPT_FLUSHED
            } else {
                out.push(msg);
                RECEIPT_FORWARDED
            };
            // A client that went away no longer waits for its receipt.
            let _ = request.send_copy(DepositReceipt {
                sequence: 0,
                status,
                reason: 0,
            });
        }
        Ok(())
    }

    /// Answers every request taken since the last frame: frame `sequence` holds them.
    pub(super) fn answer(&mut self, sequence: u64) {
        for (request, taken) in self.held.drain(..) {
            let (status, reason) = match taken {
                Taken::Applied => (RECEIPT_APPLIED, 0),
                Taken::Rejected(r) => (RECEIPT_REJECTED, r as u32),
                Taken::Flush => (RECEIPT_FLUSHED, 0),
            };
            // A client that went away (timed out, killed) no longer waits for its receipt.
            let _ = request.send_copy(DepositReceipt {
                sequence,
                status,
                reason,
            });
        }
    }
}

/// What the field did with a confirmed deposit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Receipt {
    /// In frame `sequence`.
    Applied {
        /// The first frame that holds the deposit.
        sequence: u64,
    },
    /// Refused at frame `sequence` (and counted in its header under `reason`).
    Rejected {
        /// The frame whose header counts the refusal.
        sequence: u64,
        /// Why the field refused it.
        reason: RejectReason,
    },
    /// Every deposit published before the flush is in frame `sequence` or earlier.
    Flushed {
        /// The frame by which every earlier deposit was applied or refused.
        sequence: u64,
    },
    /// A mirror forwards it to its origin.
    Forwarded,
}

impl Receipt {
    /// The receipt a field sent; `None` for a status or reason this build does not know.
    pub fn from_wire(r: &DepositReceipt) -> Option<Self> {
        let sequence = r.sequence;
        match r.status {
            RECEIPT_APPLIED => Some(Self::Applied { sequence }),
            RECEIPT_REJECTED => RejectReason::ALL
                .get(r.reason as usize)
                .map(|&reason| Self::Rejected { sequence, reason }),
            RECEIPT_FLUSHED => Some(Self::Flushed { sequence }),
            RECEIPT_FORWARDED => Some(Self::Forwarded),
            _ => None,
        }
    }
}

/// Deposits that wait for the field's answer ([`Receipt`]), for one-off senders: `pheromone
/// deposit`, scripts. A loop that deposits every step uses `DepositPublisher` instead.
pub struct DepositClient {
    names: FieldServices,
    client: Client<Svc, DepositMsg, (), DepositReceipt, ()>,
    frame_ready: iceoryx2::port::listener::Listener<Svc>,
    deposit_ready: Option<iceoryx2::port::notifier::Notifier<Svc>>,
    robot_id: u32,
}

impl DepositClient {
    /// Opens field `field`'s confirm service now, depositing as robot `robot_id`; fails (e.g.
    /// [`AttachError::NoField`]) if the field is not running.
    pub fn attach(node: &Node<Svc>, field: &str, robot_id: u32) -> Result<Self, AttachError> {
        let names = FieldServices::new(field)?;
        let client = open_confirm_service(node, &names)?
            .client_builder()
            .create()
            .map_err(|e| service_err(&names.deposit_confirm, "create client", e))?;
        let frame_ready = open_frame_ready_service(node, &names)?
            .listener_builder()
            .create()
            .map_err(|e| service_err(&names.frame_ready, "create listener", e))?;
        let deposit_ready = open_deposit_ready(node, &names);
        Ok(Self {
            names,
            client,
            frame_ready,
            deposit_ready,
            robot_id,
        })
    }

    /// As [`DepositClient::attach`], retrying for at most `timeout` while the field is not up
    /// yet (its services do not exist, or are being created).
    pub fn attach_within(
        node: &Node<Svc>,
        field: &str,
        robot_id: u32,
        timeout: Duration,
    ) -> Result<Self, AttachError> {
        retry_attach(
            node,
            field,
            timeout,
            || Self::attach(node, field, robot_id),
            AttachError::field_not_up_yet,
        )
    }

    /// Sends a deposit (stamped with this client's robot id) and waits at most `timeout` for
    /// the field's receipt. `SendError::Unconfirmed` after the timeout: the deposit may still be
    /// applied, once.
    pub fn deposit(
        &mut self,
        mut msg: DepositMsg,
        timeout: Duration,
    ) -> Result<Receipt, SendError> {
        msg.robot_id = self.robot_id;
        if msg.stamp_ns == 0 {
            msg.stamp_ns = super::now_ns();
        }
        self.request(msg, timeout)
    }

    /// Waits (at most `timeout`) until the field has taken every deposit this process
    /// published before, through any port.
    pub fn flush(&mut self, timeout: Duration) -> Result<Receipt, SendError> {
        let msg = DepositMsg {
            robot_id: self.robot_id,
            kernel: KERNEL_FLUSH,
            ..DepositMsg::default()
        };
        self.request(msg, timeout)
    }

    fn request(&mut self, msg: DepositMsg, timeout: Duration) -> Result<Receipt, SendError> {
        let service = &self.names.deposit_confirm;
        // Frame events from before this request say nothing about it; a broken listener shows
        // in the wait below.
        let _ = self.frame_ready.try_wait(|_| {});
        // A field that is starting has its service before its server is connected: a request
        // that reached no server reached nobody, so it is sent again (for at most
        // SERVER_GRACE) after the field's next frame.
        let grace_end = Instant::now() + timeout.min(SERVER_GRACE);
        let pending = loop {
            let pending = self
                .client
                .send_copy(msg)
                .map_err(|e| service_err(service, "send", e))?;
            if pending.number_of_server_connections() > 0 {
                break pending;
            }
            drop(pending);
            if Instant::now() >= grace_end {
                return Err(SendError::NoSubscriber {
                    service: service.clone(),
                });
            }
            if wait_interruptible(&self.frame_ready, RECEIPT_POLL, service)? == Woken::Interrupted {
                return Err(SendError::Interrupted {
                    service: service.clone(),
                });
            }
        };
        if let Some(n) = &self.deposit_ready {
            // A failed wake-up only delays the deposit to the field's next regular tick.
            let _ = n.notify();
        }
        wait_receipt(&pending, &self.frame_ready, service, timeout)
    }
}

/// Waits for the receipt of `pending`, waking on each frame (the field answers before it
/// wakes the readers) and every [`RECEIPT_POLL`].
fn wait_receipt(
    pending: &PendingResponse<Svc, DepositMsg, (), DepositReceipt, ()>,
    frame_ready: &iceoryx2::port::listener::Listener<Svc>,
    service: &str,
    timeout: Duration,
) -> Result<Receipt, SendError> {
    let deadline = Instant::now() + timeout;
    // Only a request made while it waits cuts it short: a flush on drop after the loop ended on
    // Ctrl-C still waits for the field.
    let mark = super::signals::stop_mark();
    loop {
        if let Some(r) = pending
            .receive()
            .map_err(|e| service_err(service, "receive receipt", e))?
        {
            return Receipt::from_wire(&r).ok_or_else(|| {
                service_err(
                    service,
                    "read receipt",
                    format!("unknown status {} or reason {}", r.status, r.reason),
                )
                .into()
            });
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() || super::signals::stopped_since(mark) {
            return Err(SendError::Unconfirmed {
                service: service.to_string(),
                timeout_s: timeout.as_secs_f64(),
            });
        }
        // A stale mirror answers ("forwarded") without publishing a frame: look again at least
        // every RECEIPT_POLL.
        if wait_interruptible(frame_ready, left.min(RECEIPT_POLL), service)? == Woken::Interrupted {
            return Err(SendError::Interrupted {
                service: service.to_string(),
            });
        }
    }
}

/// How long a deposit client waits for a frame before it looks for its receipt again.
const RECEIPT_POLL: Duration = Duration::from_millis(20);

/// How long a deposit that reached no server is sent again (a field starting up).
const SERVER_GRACE: Duration = Duration::from_secs(1);
