//! Deposits into a field: `DepositPublisher` sends `DepositMsg`s to the field's deposit service
//! and, before it goes away, waits until the field has taken them.

use std::time::Duration;

use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;

use super::confirm::DepositClient;
use super::{
    now_ns, open_deposit_ready, open_deposit_service, open_frame_ready_service, retry_attach,
    service_err, AttachError, FieldServices, SendError, Svc,
};
use crate::messages::DepositMsg;

/// Publishes deposits to a field.
///
/// iceoryx2 drops samples whose publisher disappears before the subscriber first connected to
/// it, so a publisher that sent deposits waits, when dropped (or on `flush`), until the field has
/// taken everything that was sent: it sends a flush request on the confirm service
/// ([`super::DepositClient::flush`]), which the field answers once it has drained its queue
/// (the deposits are then applied in that frame, or refused and counted in its header).
///
/// Attach to the field `main` as robot 7 and deposit:
///
/// ```no_run
/// use std::time::Duration;
///
/// use pheromone_field::shm::{create_node, DepositPublisher, ShmError};
/// use pheromone_field::{Deposit, Kernel};
///
/// fn main() -> Result<(), ShmError> {
///     let node = create_node("my-depositor")?;
///     let mut depositor = DepositPublisher::attach_within(&node, "main", 7, Duration::from_secs(5))?;
///     // Seed 000's ellipse kernel on channel 0 at (2 m, 3 m): amount 0.2, the pose covariance
///     // [xx, xy, yy] (m²), cut off at 1 m, γ capped at 100.
///     let deposit = Deposit {
///         channel: 0,
///         x_m: 2.0,
///         y_m: 3.0,
///         kernel: Kernel::Ellipse { tau: 0.2, cov_m2: [0.01, 0.0, 0.01], range_m: 1.0, gamma_max: 100.0 },
///     };
///     depositor.send(deposit.into())?;
///     // Waits until the field has taken it (dropping the publisher waits too).
///     let taken = depositor.flush(Duration::from_secs(1));
///     println!("deposit taken by the field: {taken}");
///     Ok(())
/// }
/// ```
pub struct DepositPublisher {
    names: FieldServices,
    publisher: Publisher<Svc, DepositMsg, ()>,
    frame_ready: iceoryx2::port::listener::Listener<Svc>,
    /// Wakes a field that publishes on deposit; `None` when the field had no such event when
    /// this publisher attached (its deposits then wait for the field's next regular tick).
    deposit_ready: Option<iceoryx2::port::notifier::Notifier<Svc>>,
    /// Flush requests; `None` when the field's confirm service could not be opened (the flush
    /// then waits for two frames instead).
    confirm: Option<DepositClient>,
    robot_id: u32,
    unflushed: bool,
    /// Longest wait in `Drop` for the field to take what was sent.
    pub flush_timeout: Duration,
}

impl DepositPublisher {
    /// Opens field `field`'s deposit services now, depositing as robot `robot_id`; fails (e.g.
    /// [`AttachError::NoField`]) if the field is not running. The confirm service, used for
    /// flushes, is optional.
    pub fn attach(node: &Node<Svc>, field: &str, robot_id: u32) -> Result<Self, AttachError> {
        let names = FieldServices::new(field)?;
        let publisher = open_deposit_service(node, &names)?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(|e| service_err(&names.deposit, "create publisher", e))?;
        let frame_ready = open_frame_ready_service(node, &names)?
            .listener_builder()
            .create()
            .map_err(|e| service_err(&names.frame_ready, "create listener", e))?;
        let deposit_ready = open_deposit_ready(node, &names);
        let confirm = DepositClient::attach(node, field, robot_id).ok();
        Ok(Self {
            names,
            publisher,
            frame_ready,
            deposit_ready,
            confirm,
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
        if let Some(c) = &mut self.confirm {
            let flushed = matches!(c.flush(timeout), Ok(super::Receipt::Flushed { .. }));
            self.unflushed &= !flushed;
            return flushed;
        }
        let deadline = std::time::Instant::now() + timeout;
        let mut frames = 0u64;
        while frames < 2 {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return false;
            }
            match super::listener_timed_wait(&self.frame_ready, left) {
                Ok(n) => frames += n,
                Err(_) => return false,
            }
        }
        self.unflushed = false;
        true
    }

    /// As [`DepositPublisher::attach`], retrying for at most `timeout` while the field is not
    /// up yet (its services do not exist, or are being created).
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

    /// Sends a deposit, stamped with this publisher's robot id and the monotonic clock. Fails
    /// with `SendError::NoSubscriber` if no field took it (none running, or its buffer is full).
    pub fn send(&mut self, mut msg: DepositMsg) -> Result<(), SendError> {
        msg.robot_id = self.robot_id;
        self.send_as(msg)
    }

    /// Sends a deposit (stamped with this publisher's robot id) on the field's confirm service
    /// and waits at most `timeout` for its receipt, as [`super::DepositClient::deposit`]: the
    /// field's answer (applied in frame N, refused for a reason, or forwarded by a mirror), or
    /// `SendError::Unconfirmed` (it may still be applied, once). A field without the confirm
    /// service is `SendError::NoSubscriber` on it.
    pub fn send_confirmed(
        &mut self,
        msg: DepositMsg,
        timeout: Duration,
    ) -> Result<super::Receipt, SendError> {
        match &mut self.confirm {
            Some(c) => c.deposit(msg, timeout),
            None => Err(SendError::NoSubscriber {
                service: self.names.deposit_confirm.clone(),
            }),
        }
    }

    /// Sends a deposit with the robot ID it carries (a gateway that deposits for its clients);
    /// otherwise as [`send`](Self::send).
    pub fn send_as(&mut self, mut msg: DepositMsg) -> Result<(), SendError> {
        if msg.stamp_ns == 0 {
            msg.stamp_ns = now_ns();
        }
        // Frame events from before this send say nothing about it.
        // Draining can only fail on a broken listener, which the flush's own wait reports.
        let _ = self.frame_ready.try_wait(|_| {});
        match self.publisher.send_copy(msg) {
            Ok(0) => Err(SendError::NoSubscriber {
                service: self.names.deposit.clone(),
            }),
            Ok(_) => {
                self.unflushed = true;
                self.wake_field();
                Ok(())
            }
            Err(e) => Err(SendError::NotDelivered {
                service: self.names.deposit.clone(),
                source: e.into(),
            }),
        }
    }
}

impl DepositPublisher {
    /// Tells a field that publishes on deposit that one is waiting. A failed notify only delays
    /// the deposit to the field's next regular tick.
    fn wake_field(&self) {
        if let Some(n) = &self.deposit_ready {
            let _ = n.notify();
        }
    }
}

impl Drop for DepositPublisher {
    fn drop(&mut self) {
        let timeout = self.flush_timeout;
        self.flush(timeout);
    }
}
