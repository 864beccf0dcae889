//! The field process: `FieldServer` creates the field's services, publishes the first frame
//! and then one frame per `tick`, computed straight into a loaned shared-memory sample.

// The loaned frame is taken as initialized (`assume_init`) before `compute` overwrites it.
#![allow(unsafe_code)]

use iceoryx2::prelude::*;

use super::confirm::ConfirmServer;
use super::inputs::InputsPublisher;
use super::{
    check_shm_space, create_deposit_service, create_frame_ready_service, create_frame_service,
    now_ns, service_err, DepositSubscriber, EventFactory, FieldServices, FrameFactory,
    FramePublisher, FrameSample, FrameSubscriber, ServiceError, StartError, Svc, TickError,
    FRAME_READY,
};
use crate::engine::{FieldConfig, Stepper, TickReport};
use crate::messages::{DepositMsg, FrameHeader, InputsHeader};
use crate::sample::FrameView;

/// What one `FieldServer::tick` did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickOutcome {
    /// Deposits applied and mass added by the tick.
    pub report: TickReport,
    /// Sequence number of the frame the tick published.
    pub sequence: u64,
    /// Compute time of the tick (ns), as written into the frame header.
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
    /// Confirmed deposits, answered once their frame is out.
    confirm: ConfirmServer,
    notifier: iceoryx2::port::notifier::Notifier<Svc>,
    /// Each frame's inputs for a bridge (`publish_inputs`).
    inputs: Option<InputsPublisher>,
}

/// The ports of a running field.
pub(super) struct Ports {
    pub(super) publisher: FramePublisher,
    pub(super) own: FrameSubscriber,
    pub(super) deposits: DepositSubscriber,
    pub(super) confirm: ConfirmServer,
    pub(super) notifier: iceoryx2::port::notifier::Notifier<Svc>,
}

pub(super) fn create_publisher(
    names: &FieldServices,
    config: &FieldConfig,
    frame_service: &FrameFactory,
    ready_service: &EventFactory,
) -> Result<(FramePublisher, iceoryx2::port::notifier::Notifier<Svc>), ServiceError> {
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
pub(super) enum FirstFrame<'a> {
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
    ) -> Result<Self, StartError> {
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
    ) -> Result<Self, StartError> {
        let names = FieldServices::new(field)?;
        let stepper = Stepper::new(config).map_err(|source| StartError::Config {
            field: field.to_string(),
            source,
        })?;
        let config = stepper.config().clone();
        check_shm_space(&config)?;
        let frame_service = create_frame_service(node, &names, &config)?;
        if frame_service.dynamic_config().number_of_publishers() > 0 {
            return Err(StartError::AlreadyRunning {
                field: field.into(),
            });
        }
        let ready_service = create_frame_ready_service(node, &names)?;
        let own = frame_service
            .subscriber_builder()
            .buffer_size(1)
            .create()
            .map_err(|e| service_err(&names.frame, "create own subscriber", e))?;
        let deposits = create_deposit_service(node, &names, &config)?
            .subscriber_builder()
            .buffer_size(config.deposit_buffer)
            .create()
            .map_err(|e| service_err(&names.deposit, "create subscriber", e))?;
        let (publisher, notifier) =
            create_publisher(&names, &config, &frame_service, &ready_service)?;
        let confirm = ConfirmServer::create(node, &names, &config)?;
        Self::launch(
            field,
            names,
            stepper,
            Ports {
                publisher,
                own,
                deposits,
                confirm,
                notifier,
            },
            first_frame,
            &[],
        )
    }

    /// Publishes the first frame with ports created beforehand (by `start_inner`, or by a standby
    /// long before it takes over).
    pub(super) fn launch(
        field: &str,
        names: FieldServices,
        mut stepper: Stepper,
        ports: Ports,
        first_frame: FirstFrame<'_>,
        pending: &[DepositMsg],
    ) -> Result<Self, StartError> {
        let Ports {
            publisher,
            own,
            deposits,
            confirm,
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
                return Err(StartError::RestoreMismatch {
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
                    // A rejection is counted in the stepper (and so in the next header).
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
        // A failed wake-up only delays readers to their own wait deadline; the frame is out.
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
            confirm,
            notifier,
            inputs: None,
        })
    }

    /// From now on, publishes each frame's inputs on `pheromone/F/inputs` and the configuration
    /// on `pheromone/F/config`, for `pheromone bridge`. Returns the run's epoch.
    pub fn publish_inputs(&mut self, node: &Node<Svc>) -> Result<u64, StartError> {
        let config = self.stepper.config();
        let toml = toml::to_string(config)
            .map_err(|e| service_err(&self.names.config, "serialize the configuration", e))?;
        let p = InputsPublisher::create(node, &self.names, &toml, config.deposit_buffer)?;
        let epoch = p.epoch;
        self.inputs = Some(p);
        Ok(epoch)
    }

    /// Takes the deposits offered on this host without applying them (a mirror forwards them to
    /// its origin, which applies them and sends them back in its inputs).
    pub fn take_local_deposits(&mut self) -> Result<Vec<DepositMsg>, TickError> {
        let mut out = Vec::new();
        // Confirm requests first, as a tick takes them (a flush answers after the queue).
        self.confirm.take_forwarded(&mut out)?;
        while let Some(sample) = self
            .deposits
            .receive()
            .map_err(|e| service_err(&self.names.deposit, "receive", e))?
        {
            out.push(*sample.payload());
        }
        Ok(out)
    }

    /// A mirror: publishes `cells` with `header`'s sequence and counters (a keyframe), dropping
    /// whatever frame came before.
    pub fn reset_to(&mut self, header: &FrameHeader, cells: &[f32]) -> Result<(), TickError> {
        let len = self.stepper.config().frame_len();
        if cells.len() != len {
            return Err(TickError::RestoreMismatch {
                got: cells.len(),
                expected: len,
            });
        }
        self.stepper.resume_from(header);
        self.publish_with(|stepper, _deposits, _prev, next| {
            next.copy_from_slice(cells);
            let _ = stepper;
            TickReport::default()
        })
        .map(|_| ())
    }

    /// A mirror: computes the next frame from the previous one with the origin's inputs of that
    /// frame (`Stepper::replay`) and publishes it with the origin's sequence. Returns the
    /// deposits this stepper refused (0 with the origin's configuration).
    pub fn apply_inputs(
        &mut self,
        header: &InputsHeader,
        deposits: &[DepositMsg],
    ) -> Result<u32, TickError> {
        let mut refused = 0;
        self.stepper.sequence = header.sequence.wrapping_sub(1);
        self.publish_with(|stepper, _deposits, prev, next| {
            let (report, r) = stepper.replay(
                prev,
                next,
                deposits,
                header.sim_time_before_s,
                header.dt_s,
                header.dt_time_s,
            );
            refused = r;
            report
        })?;
        Ok(refused)
    }

    /// Loans the next frame, lets `compute` fill it from the previous one, publishes it.
    fn publish_with(
        &mut self,
        compute: impl FnOnce(&mut Stepper, &DepositSubscriber, &[f32], &mut [f32]) -> TickReport,
    ) -> Result<(TickReport, u64), TickError> {
        let started = now_ns();
        let len = self.stepper.config().frame_len();
        let previous = match self.previous.take() {
            Some(p) => p,
            None => {
                return Err(
                    service_err(&self.names.frame, "tick", "the previous frame was lost").into(),
                )
            }
        };
        if previous.payload().len() != len {
            return Err(TickError::BadFrame {
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
        // initialized bytes, and every bit pattern is a valid `f32`. `compute` (a `Stepper` step
        // or a copy of a whole keyframe) overwrites every element before the sample is sent.
        let mut next = unsafe { uninit.assume_init() };
        let report = compute(
            &mut self.stepper,
            &self.deposits,
            previous.payload(),
            next.payload_mut(),
        );
        drop(previous);
        let done = now_ns();
        let compute_ns = done.saturating_sub(started);
        *next.user_header_mut() = self.stepper.header(done, compute_ns, &report);
        next.send()
            .map_err(|e| service_err(&self.names.frame, "send", e))?;
        // Receipts before the wake-up: a client woken by this frame finds its answer.
        self.confirm.answer(self.stepper.sequence);
        // A failed wake-up only delays readers to their own wait deadline; the frame is out.
        let _ = self.notifier.notify();
        self.previous = self
            .own
            .receive()
            .map_err(|e| service_err(&self.names.frame, "receive own frame", e))?;
        if let Some(inputs) = &self.inputs {
            let (before, dt_s, dt_time_s) = self.stepper.last_step();
            let c = &self.stepper.counters;
            inputs.send(
                InputsHeader {
                    sequence: self.stepper.sequence,
                    epoch: 0,
                    stamp_ns: done,
                    sim_time_before_s: before,
                    dt_time_s,
                    deposits_applied: c.applied,
                    deposits_rejected_total: c.rejected_total(),
                    dt_s,
                    count: 0,
                },
                self.stepper.applied(),
            )?;
        }
        Ok((report, compute_ns))
    }

    /// The field's name.
    pub fn field(&self) -> &str {
        &self.field
    }

    /// The configuration the field runs with.
    pub fn config(&self) -> &FieldConfig {
        self.stepper.config()
    }

    /// The engine: counters, clock and sequence of the last frame.
    pub fn stepper(&self) -> &Stepper {
        &self.stepper
    }

    /// Threads of each tick's evaporation pass (`Stepper::set_threads`: rows split across
    /// threads, bit-identical to one thread).
    pub fn set_threads(&mut self, threads: usize) -> Result<(), crate::ConfigError> {
        self.stepper.set_threads(threads)
    }

    /// Connects readers that attached since the last frame and hands them the current frame
    /// (the history), and the configuration to its new subscribers. Call it while idle (e.g. a
    /// lockstep field waiting for its clock), so a late reader does not wait for the next tick.
    pub fn serve_new_readers(&self) -> Result<(), TickError> {
        use iceoryx2::port::update_connections::UpdateConnections;
        if let Some(inputs) = &self.inputs {
            inputs.serve_new_subscribers()?;
        }
        Ok(self
            .publisher
            .update_connections()
            .map_err(|e| service_err(&self.names.frame, "update connections", e))?)
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

    /// The cells of the last published frame.
    pub fn latest_cells(&self) -> Option<&[f32]> {
        self.previous.as_ref().map(|s| s.payload())
    }

    /// Whether deposits wait in the queue for the next tick.
    pub fn deposits_waiting(&self) -> Result<bool, TickError> {
        let queued = self
            .deposits
            .has_samples()
            .map_err(|e| service_err(&self.names.deposit, "look at the queue", e))?;
        Ok(queued || self.confirm.waiting()?)
    }

    /// Drains the deposit queue (validating each), computes the next frame from the previous one
    /// straight into a loaned sample, publishes it and wakes the readers.
    pub fn tick(&mut self) -> Result<TickOutcome, TickError> {
        self.tick_by(None)
    }

    /// As `tick`, stepping the field by `dt_s` seconds instead of one tick period (clamped to
    /// (0, period]; see `Stepper::step_dt`): a field that publishes as soon as deposits arrive.
    pub fn tick_dt(&mut self, dt_s: f32) -> Result<TickOutcome, TickError> {
        self.tick_by(Some(dt_s))
    }

    fn tick_by(&mut self, dt_s: Option<f32>) -> Result<TickOutcome, TickError> {
        // Confirm requests before the queue: a flush request's receipt then covers every
        // deposit its process published before it.
        let mut rejected = self.confirm.take(&mut self.stepper)?;
        rejected += drain(&self.deposits, &mut self.stepper)
            .map_err(|e| service_err(&self.names.deposit, "receive", e))?;
        // Publishing on deposit, what arrives during the evaporation pass joins this frame.
        let mut late = Ok(0);
        let (report, compute_ns) =
            self.publish_with(|stepper, deposits, prev, next| match dt_s {
                None => stepper.step(prev, next),
                Some(dt) => stepper.step_dt_then(prev, next, dt, |s| late = drain(deposits, s)),
            })?;
        rejected += late.map_err(|e| service_err(&self.names.deposit, "receive", e))?;
        Ok(TickOutcome {
            report,
            sequence: self.stepper.sequence,
            compute_ns,
            rejected,
        })
    }
}

/// Offers every deposit waiting in the queue to `stepper`; returns how many it refused.
fn drain(
    deposits: &DepositSubscriber,
    stepper: &mut Stepper,
) -> Result<u64, iceoryx2::port::ReceiveError> {
    let mut rejected = 0;
    while let Some(sample) = deposits.receive()? {
        if stepper.offer(sample.payload()).is_err() {
            rejected += 1;
        }
    }
    Ok(rejected)
}
