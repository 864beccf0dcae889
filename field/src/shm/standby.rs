//! A standby field: `Standby` mirrors a running field and, when the primary dies, takes over
//! its services (`Takeover` tells what it started from; `StandbyEvent` what `poll` saw).

use std::time::{Duration, Instant};

use iceoryx2::prelude::*;

use super::confirm::ConfirmServer;
use super::server::{create_publisher, FirstFrame, Ports};
use super::{
    check_shm_space, cleanup_dead_nodes, now_ns, open_deposit_service, open_frame_ready_service,
    open_frame_service, retry_attach, service_err, wait_interruptible, AttachError,
    DepositSubscriber, FieldServer, FieldServices, FrameFactory, FramePublisher, FrameSample,
    FrameSubscriber, StandbyError, StartError, Svc, Woken,
};
use crate::engine::{FieldConfig, Stepper};
use crate::messages::{DepositMsg, FrameHeader};

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

/// What `Standby::poll` saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StandbyEvent {
    /// A newer frame of the primary was mirrored.
    Mirrored {
        /// Sequence of the frame mirrored.
        sequence: u64,
    },
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
    pub fn attach(
        node: &Node<Svc>,
        field: &str,
        config: FieldConfig,
    ) -> Result<Self, StandbyError> {
        let names = FieldServices::new(field).map_err(AttachError::from)?;
        config.validate().map_err(|e| StandbyError::Mismatch {
            field: field.into(),
            detail: e.to_string(),
        })?;
        let service = open_frame_service(node, &names)?;
        let frames = service
            .subscriber_builder()
            .buffer_size(1)
            .create()
            .map_err(|e| service_err(&names.frame, "create standby subscriber", e))?;
        let ready_service = open_frame_ready_service(node, &names)?;
        let listener = ready_service
            .listener_builder()
            .create()
            .map_err(|e| service_err(&names.frame_ready, "create listener", e))?;
        let deposits = open_deposit_service(node, &names)?
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
    ) -> Result<Self, StandbyError> {
        retry_attach(
            node,
            field,
            timeout,
            || Self::attach(node, field, config.clone()),
            |e| match e {
                StandbyError::Attach(e) => e.field_not_up_yet(),
                StandbyError::Start(StartError::Service(_)) | StandbyError::Service(_) => true,
                StandbyError::Mismatch { .. }
                | StandbyError::Start(_)
                | StandbyError::Interrupted { .. } => false,
            },
        )
    }

    /// The name of the field mirrored.
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
    fn receive_frames(&mut self) -> Result<bool, StandbyError> {
        let mut fresh = false;
        loop {
            match self.frames.receive() {
                Ok(Some(s)) => {
                    let h = s.user_header();
                    let c = &self.config;
                    if h.geometry() != c.geometry()
                        || h.channels as usize != c.channels.len()
                        || s.payload().len() != c.frame_len()
                        || h.dt_s != c.dt_s()
                    {
                        return Err(StandbyError::Mismatch {
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
                                h.dt_s,
                                c.width,
                                c.height,
                                c.channels.len(),
                                c.cell_size_m,
                                c.origin_x_m,
                                c.origin_y_m,
                                c.dt_s()
                            ),
                        });
                    }
                    self.latest = Some(s);
                    fresh = true;
                }
                Ok(None) => break,
                Err(e) => return Err(service_err(&self.names.frame, "receive", e).into()),
            }
        }
        if fresh {
            self.mirrored += 1;
            self.last_frame_at = Instant::now();
        }
        Ok(fresh)
    }

    /// Takes the deposits queued for the standby: dropped when `keep` is false, else kept.
    fn drain_deposits(&mut self, keep: bool) -> Result<(), StandbyError> {
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
                Err(e) => return Err(service_err(&self.names.deposit, "receive", e).into()),
            }
        }
    }

    /// Waits up to `timeout` for the primary's next frame and mirrors it; tells when the primary
    /// is gone. Where the program owns its signals, a signal that cuts the wait short with no
    /// frame is `StandbyError::Interrupted` (poll again to go on).
    pub fn poll(&mut self, timeout: Duration) -> Result<StandbyEvent, StandbyError> {
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
            let woken = wait_interruptible(&self.listener, timeout, &self.names.frame_ready)?;
            fresh = self.receive_frames()?;
            if !fresh && woken == Woken::Interrupted {
                // The program's own handler ran: its loop looks at its flags, then polls again.
                return Err(StandbyError::Interrupted {
                    service: self.names.frame_ready.clone(),
                });
            }
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
    pub fn take_over(mut self, node: &Node<Svc>) -> Result<(FieldServer, Takeover), StandbyError> {
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
        let stepper = Stepper::new(config).map_err(|source| StartError::Config {
            field: field.to_string(),
            source,
        })?;
        // The mirrored sample is released once the first own frame is computed from it; the
        // mirroring subscription becomes the field's own (it receives only this publisher's
        // frames from now on: the primary is dead and its last frames were taken above).
        let confirm = ConfirmServer::create(node, &names, stepper.config())?;
        let ports = Ports {
            publisher,
            own: frames,
            deposits,
            confirm,
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
