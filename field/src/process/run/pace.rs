//! How the field's loop waits for its next frame (`Pace`): on wall time (`Metronome`), on wall
//! time or sooner for deposits (`OnDeposit`, woken by `DepositWake`), or once per step of a
//! simulated world (`Lockstep`).

use super::*;

/// How the loop waits for its ticks: the world's clock (lockstep), wall time and deposits, or
/// wall time alone; a wall-time deadline one period from now.
pub(super) fn pace(
    o: &FieldRunOptions,
    period: Duration,
    clock: Option<Participant>,
    deposit_wake: Option<DepositWake>,
) -> Box<dyn Pace> {
    let metronome = Metronome {
        period,
        deadline: Instant::now() + period,
        late: None,
        spin: o.spin,
    };
    match (clock, deposit_wake) {
        (Some(clock), _) => Box::new(Lockstep {
            clock,
            last_step: None,
            field: o.name.clone(),
        }),
        (None, Some(wake)) => Box::new(OnDeposit {
            wake,
            metronome,
            early_frames: 0,
        }),
        (None, None) => Box::new(metronome),
    }
}

/// Whether the loop ticks again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Next {
    Tick,
    /// The run ends (Ctrl-C / SIGTERM, the world's end).
    Stop,
}

/// How the field waits for its next frame: on wall time ([`Metronome`]), on wall time or
/// sooner for deposits ([`OnDeposit`]), or once per step of a simulated world ([`Lockstep`]).
pub(super) trait Pace {
    /// Waits until the next frame is due (serving readers that attach meanwhile).
    /// `last_frame_at`: when the previous frame was published.
    fn next_tick(
        &mut self,
        node: &Node<Svc>,
        server: &FieldServer,
        last_frame_at: Instant,
    ) -> Result<Next, ShmError>;

    /// How late the tick `next_tick` just allowed started after its wall-time deadline (`None`:
    /// it had none — a lockstep step or a frame for deposits).
    fn lateness(&self) -> Option<Duration> {
        None
    }

    /// Computes and publishes the frame.
    fn tick(
        &mut self,
        server: &mut FieldServer,
        _last_frame_at: Instant,
    ) -> Result<TickOutcome, ShmError> {
        Ok(server.tick()?)
    }

    /// Frames published between ticks because deposits arrived (a field that publishes on
    /// deposit), else `None`.
    fn frames_on_deposit(&self) -> Option<u64> {
        None
    }
}

/// Ticks on wall time, one per `period`.
struct Metronome {
    period: Duration,
    deadline: Instant,
    /// How late the last tick started after its deadline.
    late: Option<Duration>,
    /// Poll for this long before each deadline instead of sleeping.
    spin: Duration,
}

impl Metronome {
    /// The next deadline, one period on; a field that fell behind does not burst to catch up.
    /// Notes how late this tick is.
    fn advance(&mut self) {
        self.late = Some(Instant::now().saturating_duration_since(self.deadline));
        self.deadline += self.period;
        if self.deadline + self.period < Instant::now() {
            self.deadline = Instant::now() + self.period;
        }
    }
}

impl Pace for Metronome {
    fn next_tick(
        &mut self,
        node: &Node<Svc>,
        server: &FieldServer,
        _last_frame_at: Instant,
    ) -> Result<Next, ShmError> {
        let wake = spin::sleep_until(self.deadline, self.spin);
        if !wait_serving_readers(node, server, wake)?
            || spin::poll_until::<ShmError>(self.deadline, || Ok(false))? == spin::Polled::Stop
        {
            return Ok(Next::Stop); // SIGINT / SIGTERM
        }
        self.advance();
        Ok(Next::Tick)
    }

    fn lateness(&self) -> Option<Duration> {
        self.late
    }
}

/// Ticks on wall time, and publishes sooner when deposits arrive
/// (`FieldRunOptions::publish_on_deposit`); every frame steps by the real time since the last.
struct OnDeposit {
    wake: DepositWake,
    metronome: Metronome,
    early_frames: u64,
}

impl Pace for OnDeposit {
    fn next_tick(
        &mut self,
        node: &Node<Svc>,
        server: &FieldServer,
        last_frame_at: Instant,
    ) -> Result<Next, ShmError> {
        match self
            .wake
            .wait(node, server, &self.metronome, last_frame_at)?
        {
            Wake::Stop => return Ok(Next::Stop),
            Wake::Deposit => {
                self.early_frames += 1;
                self.metronome.late = None;
            }
            Wake::Tick => self.metronome.advance(),
        }
        Ok(Next::Tick)
    }

    fn lateness(&self) -> Option<Duration> {
        self.metronome.late
    }

    fn tick(
        &mut self,
        server: &mut FieldServer,
        last_frame_at: Instant,
    ) -> Result<TickOutcome, ShmError> {
        // Stepped by the real time since the last frame (at most one period).
        Ok(server.tick_dt(last_frame_at.elapsed().as_secs_f32())?)
    }

    fn frames_on_deposit(&self) -> Option<u64> {
        Some(self.early_frames)
    }
}

/// One tick per step of a simulated world's clock, acknowledged once published.
struct Lockstep {
    clock: Participant,
    /// The last step ticked (a step the clock repeats is not ticked again).
    last_step: Option<u64>,
    /// The field's name, for the log.
    field: String,
}

impl Pace for Lockstep {
    fn next_tick(
        &mut self,
        node: &Node<Svc>,
        server: &FieldServer,
        _last_frame_at: Instant,
    ) -> Result<Next, ShmError> {
        loop {
            match self.clock.next_clock(Duration::from_millis(20))? {
                Some(msg) if msg.finished != 0 => return Ok(Next::Stop),
                Some(msg) if self.last_step.is_some_and(|s| msg.step <= s) => continue,
                Some(msg) => {
                    self.last_step = Some(msg.step);
                    break;
                }
                None => {
                    if crate::shm::should_stop(node) {
                        return Ok(Next::Stop);
                    }
                    if self.clock.conductor_gone() {
                        eprintln!(
                            "field '{}': the world's clock is gone without announcing the end; stopping",
                            self.field
                        );
                        return Ok(Next::Stop);
                    }
                    // Idle between steps: late readers still get the current frame.
                    server.serve_new_readers()?;
                }
            }
        }
        if crate::shm::should_stop(node) {
            return Ok(Next::Stop);
        }
        Ok(Next::Tick)
    }

    fn tick(
        &mut self,
        server: &mut FieldServer,
        _last_frame_at: Instant,
    ) -> Result<TickOutcome, ShmError> {
        let out = server.tick()?;
        if let Some(step) = self.last_step {
            self.clock.ack(step, lockstep::role::FIELD, 0)?;
        }
        Ok(out)
    }
}

/// Longest wait of a field that publishes on deposit before it serves readers that attached.
const IDLE_SLICE: Duration = Duration::from_millis(100);

/// What woke a field that publishes on deposit.
enum Wake {
    /// The regular tick is due.
    Tick,
    /// Deposits wait and the minimum interval since the last frame has passed.
    Deposit,
    /// Ctrl-C / SIGTERM.
    Stop,
}

/// Waits for the next tick or, sooner, for deposits (`FieldRunOptions::publish_on_deposit`):
/// depositors notify the field's `deposit-ready` event after each deposit.
pub(super) struct DepositWake {
    listener: iceoryx2::port::listener::Listener<Svc>,
    min_interval: Duration,
}

impl DepositWake {
    pub(super) fn new(
        node: &Node<Svc>,
        field: &str,
        config: &FieldConfig,
        min_interval: Duration,
    ) -> Result<Self, StartError> {
        let names = crate::shm::FieldServices::new(field)?;
        let listener = crate::shm::create_deposit_ready_service(node, &names, config)?
            .listener_builder()
            .create()
            .map_err(|e| crate::shm::service_err(&names.deposit_ready, "create listener", e))?;
        Ok(Self {
            listener,
            min_interval,
        })
    }

    fn wait(
        &self,
        node: &Node<Svc>,
        server: &FieldServer,
        metronome: &Metronome,
        last_frame_at: Instant,
    ) -> Result<Wake, TickError> {
        let deadline = metronome.deadline;
        let poll_from = spin::sleep_until(deadline, metronome.spin);
        loop {
            if crate::shm::should_stop(node) {
                return Ok(Wake::Stop);
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(Wake::Tick);
            }
            // Events can coalesce or come from deposits already taken: the queue decides.
            if server.deposits_waiting()? {
                let earliest = last_frame_at + self.min_interval;
                if now < earliest {
                    if earliest >= deadline {
                        continue_until(node, deadline);
                        return Ok(Wake::Tick);
                    }
                    continue_until(node, earliest);
                }
                // Drain the events that woke us; the deposits go into this frame.
                let _ = self.listener.try_wait(|_| {});
                return Ok(Wake::Deposit);
            }
            if now >= poll_from {
                match spin::poll_until(deadline, || server.deposits_waiting())? {
                    spin::Polled::Ready => continue,
                    spin::Polled::Deadline => return Ok(Wake::Tick),
                    spin::Polled::Stop => return Ok(Wake::Stop),
                }
            }
            // In slices of at most 100 ms: readers that attached meanwhile get the current frame
            // without waiting for a tick (which can be far off at a low tick rate).
            let slice = poll_from.saturating_duration_since(now).min(IDLE_SLICE);
            match crate::shm::listener_timed_wait(&self.listener, slice) {
                Ok(0) => server.serve_new_readers()?,
                Ok(_) | Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => {}
                Err(e) => {
                    return Err(crate::shm::service_err(
                        "deposit-ready",
                        "wait",
                        crate::shm::Iceoryx(e),
                    )
                    .into())
                }
            }
        }
    }
}

/// Waits on the node until `deadline` in slices of at most `IDLE_SLICE`, between which a reader
/// that attached meanwhile gets the current frame without waiting for the tick, which can be far
/// off at a low tick rate (at 10 Hz and above this is one wait). False on a termination request.
fn wait_serving_readers(
    node: &Node<Svc>,
    server: &FieldServer,
    deadline: Instant,
) -> Result<bool, TickError> {
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Ok(true);
        }
        if !wait_or_stop(node, left.min(IDLE_SLICE)) {
            return Ok(false);
        }
        if left > IDLE_SLICE {
            server.serve_new_readers()?;
        }
    }
}

/// Waits on the node until `until` (a termination request ends it early; the caller's next
/// check sees it).
fn continue_until(node: &Node<Svc>, until: Instant) {
    // Interrupted or not, the caller's next `should_stop` sees a termination request (latched).
    let _ = crate::shm::node_wait(node, until.saturating_duration_since(Instant::now()));
}
