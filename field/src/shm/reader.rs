//! Read access to a field: `FieldReader` lends the newest frame (`Frame`) without copying it
//! and tells whether a live field process still publishes it.

use std::time::Duration;

use iceoryx2::prelude::*;

use super::{
    open_frame_ready_service, open_frame_service, retry_attach, service_err, wait_interruptible,
    AttachError, FieldServices, FrameFactory, FrameSample, FrameSubscriber, ReceiveError, Svc,
    Woken,
};
use crate::messages::FrameHeader;
use crate::sample::FrameView;

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
    // Listing fails only on an unreadable node directory: then no dead publisher is known.
    let _ = Node::<Svc>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            if ids.contains(view.id()) {
                dead += 1;
                // Another process may be cleaning it already; it counts as dead either way.
                let _ = view.try_remove_stale_resources();
            }
        }
        CallbackProgression::Continue
    });
    ids.len().saturating_sub(dead)
}

/// How a reader waits for the next frame (`FieldReader::wait_frame_with`).
///
/// A blocking wake-up through the frame event costs what the host's scheduler makes it: on this
/// project's 2-core VM about 20 µs between two busy processes (a small message's hop), and
/// 150–200 µs for a reader that sleeps between frames (its idle vCPU has to be woken by the
/// hypervisor); a reader that polls sees a frame within a few microseconds of its publication
/// but burns its core while it polls. Parsed from `event`, `busy-poll` or `spin:US` (the
/// followers' `--wait`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WaitPolicy {
    /// Sleep on the frame event until the field notifies (no CPU while waiting).
    #[default]
    Event,
    /// Poll for up to this long, then sleep on the event. A frame that comes within the spin is
    /// seen at busy-poll latency; the CPU cost is at most `spin / frame period` of one core (a
    /// 50 µs spin at 100 Hz: ≤ 0.5 %), spent only right after the reader asks for a frame.
    /// Use it when the reader asks shortly before the frame is due.
    Spin(Duration),
    /// Poll until the frame comes (or the timeout): the lowest latency, one core at 100 %.
    BusyPoll,
}

/// A `--wait` value that is not a wait policy.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("wait policy \"{0}\": expected event, busy-poll or spin:MICROSECONDS (e.g. spin:200, at most 1000000)")]
pub struct ParseWaitPolicyError(pub String);

impl std::str::FromStr for WaitPolicy {
    type Err = ParseWaitPolicyError;

    /// `event`, `busy-poll`, or `spin:US` (a spin of US microseconds, 1 to 1 000 000).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = || ParseWaitPolicyError(s.to_string());
        match s {
            "event" => Ok(Self::Event),
            "busy-poll" => Ok(Self::BusyPoll),
            _ => {
                let us: u64 = s
                    .strip_prefix("spin:")
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(err)?;
                if !(1..=1_000_000).contains(&us) {
                    return Err(err());
                }
                Ok(Self::Spin(Duration::from_micros(us)))
            }
        }
    }
}

impl std::fmt::Display for WaitPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Event => f.write_str("event"),
            Self::BusyPoll => f.write_str("busy-poll"),
            Self::Spin(d) => write!(f, "spin:{}", d.as_micros()),
        }
    }
}

/// A frame lent by a `FieldReader`: the header and a sampling view of the cells.
pub struct Frame<'a> {
    /// The frame's header: sequence, field time, geometry, counters.
    pub header: &'a FrameHeader,
    /// The cells, for sampling.
    pub view: FrameView<'a>,
}

impl Frame<'_> {
    /// [`values_into`]: `FrameView::value` of `channel` at every point.
    pub fn values_into(
        &self,
        channel: usize,
        points: &[[f32; 2]],
        values: &mut [f32],
    ) -> Result<(), SampleManyError> {
        values_into(&self.view, channel, points, values)
    }

    /// [`values_and_gradients_into`]: `FrameView::value` and `gradient` at every point.
    pub fn values_and_gradients_into(
        &self,
        channel: usize,
        points: &[[f32; 2]],
        values: &mut [f32],
        gradients: &mut [[f32; 2]],
    ) -> Result<(), SampleManyError> {
        values_and_gradients_into(&self.view, channel, points, values, gradients)
    }
}

/// Why a batch of samples was refused (nothing was written).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SampleManyError {
    /// The channel index names no channel of the frame.
    #[error("channel = {channel}: the frame has {channels} channel(s)")]
    Channel {
        /// The channel asked for.
        channel: usize,
        /// Channels the frame has.
        channels: usize,
    },
    /// An output slice is shorter than the list of points.
    #[error("{what} has room for {got} point(s), {points} point(s) given")]
    Length {
        /// The output slice (`values` or `gradients`).
        what: &'static str,
        /// Its length.
        got: usize,
        /// Number of points given.
        points: usize,
    },
}

fn check_batch(
    view: &FrameView<'_>,
    channel: usize,
    points: usize,
    outputs: &[(&'static str, usize)],
) -> Result<(), SampleManyError> {
    if channel >= view.channels {
        return Err(SampleManyError::Channel {
            channel,
            channels: view.channels,
        });
    }
    for &(what, got) in outputs {
        if got < points {
            return Err(SampleManyError::Length { what, got, points });
        }
    }
    Ok(())
}

/// `view.value(channel, x, y)` for every point `[x, y]` into `values[i]`: a batch in one call,
/// the same numbers as point by point.
pub fn values_into(
    view: &FrameView<'_>,
    channel: usize,
    points: &[[f32; 2]],
    values: &mut [f32],
) -> Result<(), SampleManyError> {
    check_batch(view, channel, points.len(), &[("values", values.len())])?;
    for (p, v) in points.iter().zip(values.iter_mut()) {
        *v = view.value(channel, p[0], p[1]);
    }
    Ok(())
}

/// `view.value` and `view.gradient` for every point into `values[i]` and `gradients[i]`
/// (`[gx, gy]`): a batch in one call, the same numbers as point by point.
pub fn values_and_gradients_into(
    view: &FrameView<'_>,
    channel: usize,
    points: &[[f32; 2]],
    values: &mut [f32],
    gradients: &mut [[f32; 2]],
) -> Result<(), SampleManyError> {
    check_batch(
        view,
        channel,
        points.len(),
        &[("values", values.len()), ("gradients", gradients.len())],
    )?;
    for ((p, v), g) in points
        .iter()
        .zip(values.iter_mut())
        .zip(gradients.iter_mut())
    {
        *v = view.value(channel, p[0], p[1]);
        let (gx, gy) = view.gradient(channel, p[0], p[1]);
        *g = [gx, gy];
    }
    Ok(())
}

/// A process's read access to a field: lends the newest frame without copying it.
///
/// When the field dies the reader keeps its last frame (`frame()` still lends it) and
/// `field_alive` turns false; a field restarted under the same name (or a standby taking over)
/// publishes to the same services, and the reader receives its frames without attaching again.
///
/// Attach to the field `main` (`pheromone field --name main`), wait for a frame, sample it:
///
/// ```no_run
/// use std::time::Duration;
///
/// use pheromone_field::shm::{create_node, FieldReader, ShmError};
/// use pheromone_field::SamplePose;
///
/// fn main() -> Result<(), ShmError> {
///     let node = create_node("my-reader")?;
///     // Retries while the field is not up yet, for at most 5 s.
///     let mut reader = FieldReader::attach_within(&node, "main", Duration::from_secs(5))?;
///     // Sleeps on the frame event until a frame newer than the one held comes (at most 1 s).
///     if reader.wait_frame(Duration::from_secs(1))? {
///         let frame = reader.frame().expect("a frame came");
///         // Channel 0 at (2 m, 3 m), its gradient there, and a robot's two antennas.
///         let value = frame.view.value(0, 2.0, 3.0);
///         let (gx, gy) = frame.view.gradient(0, 2.0, 3.0);
///         let (left, right) = frame.view.antennas(0, SamplePose::new(2.0, 3.0, 0.0), 0.2);
///         println!(
///             "frame {}: {value} (gradient {gx}, {gy}; antennas {left}, {right})",
///             frame.header.sequence
///         );
///     }
///     Ok(())
/// }
/// ```
pub struct FieldReader {
    names: FieldServices,
    service: FrameFactory,
    node_config: Config,
    subscriber: FrameSubscriber,
    listener: iceoryx2::port::listener::Listener<Svc>,
    latest: Option<FrameSample>,
    /// The frame `latest` replaced, released at the start of the next `update`: handing a sample
    /// back writes to the publisher's shared completion queue, which is better done while no new
    /// frame is awaited than between a frame's arrival and the reader holding it.
    replaced: Option<FrameSample>,
    /// The publisher (field process) of the newest frame, and how many publishers this reader
    /// has taken frames from ([`FieldReader::generation`]).
    origin: Option<iceoryx2::identifiers::UniquePublisherId>,
    generation: u64,
}

impl FieldReader {
    /// Attaches to the running field `field`; fails with `AttachError::NoField` if there is
    /// none.
    pub fn attach(node: &Node<Svc>, field: &str) -> Result<Self, AttachError> {
        let names = FieldServices::new(field)?;
        let service = open_frame_service(node, &names)?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(1)
            .create()
            .map_err(|e| service_err(&names.frame, "create subscriber", e))?;
        let listener = open_frame_ready_service(node, &names)?
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
            replaced: None,
            origin: None,
            generation: 0,
        };
        // The current frame (the field's history), if it has come already.
        reader.update().map_err(|e| match e {
            ReceiveError::BadFrame { got, expected } => AttachError::BadFrame { got, expected },
            ReceiveError::Service(e) => AttachError::Service(e),
            ReceiveError::Interrupted { .. } => AttachError::Interrupted {
                field: field.to_string(),
            },
        })?;
        Ok(reader)
    }

    /// Attaches, retrying while the field does not exist yet, for at most `timeout`. Waits with
    /// `node.wait` between tries (returns early on a termination request).
    pub fn attach_within(
        node: &Node<Svc>,
        field: &str,
        timeout: Duration,
    ) -> Result<Self, AttachError> {
        retry_attach(
            node,
            field,
            timeout,
            || Self::attach(node, field),
            AttachError::field_not_up_yet,
        )
    }

    /// Whether a live field process publishes this field. False when no field is attached or
    /// when the field's process died (its leftover ports are then removed, so a restarted field
    /// can take over). Costs a scan of the host's iceoryx2 nodes: call it when frames stop
    /// coming, not per frame.
    pub fn field_alive(&self) -> bool {
        live_frame_publishers(&self.service, &self.node_config) > 0
    }

    /// How many field processes this reader has taken frames from: 0 before its first frame, 1
    /// from then on, and one more each time a restarted field (or a standby that took over)
    /// publishes under the name. A change tells the reader that the field's state may have been
    /// reset (a restart without `--restore` starts empty) and its sequence numbers restarted.
    /// Free: counted as frames arrive.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Readers (subscribers of the frame service) attached now, this one included.
    pub fn readers(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    /// Takes the newest frame that has arrived (if any); returns whether it is new.
    pub fn update(&mut self) -> Result<bool, ReceiveError> {
        // At most `READER_BORROWED_FRAMES` (2) samples are held: `latest` and `replaced`, so the
        // replaced one goes before each receive.
        self.replaced = None;
        let mut fresh = false;
        loop {
            if fresh {
                self.replaced = None;
            }
            match self.subscriber.receive() {
                Ok(Some(s)) => {
                    if s.payload().len() != s.user_header().len() {
                        return Err(ReceiveError::BadFrame {
                            got: s.payload().len(),
                            expected: s.user_header().len(),
                        });
                    }
                    if self.origin != Some(s.origin()) {
                        self.origin = Some(s.origin());
                        self.generation += 1;
                    }
                    self.replaced = self.latest.replace(s);
                    fresh = true;
                }
                Ok(None) => return Ok(fresh),
                Err(e) => return Err(service_err(&self.names.frame, "receive", e).into()),
            }
        }
    }

    /// Waits up to `timeout` for a frame newer than the one held; returns whether one came.
    /// `ReceiveError::Interrupted` when a signal the program handles cut the wait short (not in
    /// a process that called
    /// [`handle_termination_requests`](super::handle_termination_requests)).
    pub fn wait_frame(&mut self, timeout: Duration) -> Result<bool, ReceiveError> {
        if self.update()? {
            return Ok(true);
        }
        let woken = wait_interruptible(&self.listener, timeout, &self.names.frame_ready)?;
        if self.update()? {
            return Ok(true);
        }
        match woken {
            Woken::Anyway => Ok(false),
            Woken::Interrupted => Err(ReceiveError::Interrupted {
                service: self.names.frame_ready.clone(),
            }),
        }
    }

    /// Takes the frame-ready notifications that have arrived, without waiting: after it the
    /// descriptor of [`frame_ready_listener`](Self::frame_ready_listener) is readable again
    /// only for a notification that comes later. Returns how many were taken.
    pub fn take_notifications(&self) -> Result<u64, ReceiveError> {
        self.listener.try_wait(|_| {}).map_err(|e| {
            service_err(
                &self.names.frame_ready,
                "take notifications",
                super::Iceoryx(e),
            )
            .into()
        })
    }

    /// This reader's frame-ready listener, e.g. for its file descriptor (iceoryx2's
    /// `FileDescriptorBased`): readable (`poll`, `epoll`) while a notification of a frame
    /// published since the last [`take_notifications`](Self::take_notifications) is pending.
    pub fn frame_ready_listener(&self) -> &iceoryx2::port::listener::Listener<Svc> {
        &self.listener
    }

    /// Waits up to `timeout` for a frame newer than the one held, the way `policy` says;
    /// returns whether one came. A wake-up for a frame already taken waits again. A signal
    /// the program handles cuts the sleep on the event short with `ReceiveError::Interrupted`;
    /// the polling part of `Spin` and `BusyPoll` makes no system call a signal could cut, so it
    /// ends with `Interrupted` once the program's stop flag is set (`shm::stop_when`), else it
    /// goes on until the frame or the timeout. In a process that handles termination requests
    /// through iceoryx2, Ctrl-C ends the wait with `false` instead.
    pub fn wait_frame_with(
        &mut self,
        policy: WaitPolicy,
        timeout: Duration,
    ) -> Result<bool, ReceiveError> {
        let start = std::time::Instant::now();
        let spin = match policy {
            WaitPolicy::Event => Duration::ZERO,
            WaitPolicy::Spin(d) => d.min(timeout),
            WaitPolicy::BusyPoll => timeout,
        };
        loop {
            if self.update()? {
                return Ok(true);
            }
            if start.elapsed() >= spin {
                break;
            }
            if super::signals::program_stop_flag_set() {
                return Err(ReceiveError::Interrupted {
                    service: self.names.frame_ready.clone(),
                });
            }
            std::hint::spin_loop();
        }
        loop {
            let left = timeout.saturating_sub(start.elapsed());
            if left.is_zero() {
                return Ok(false);
            }
            if self.wait_frame(left)? {
                return Ok(true);
            }
            if super::stop_requested() {
                // Ctrl-C: the caller sees no frame and checks its own termination flag.
                return Ok(false);
            }
        }
    }

    /// Waits (up to `timeout`) until a frame satisfies `pred`; returns it, or `None` on timeout.
    pub fn wait_until(
        &mut self,
        timeout: Duration,
        mut pred: impl FnMut(&Frame<'_>) -> bool,
    ) -> Result<Option<Frame<'_>>, ReceiveError> {
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
