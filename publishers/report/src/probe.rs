//! `pheromone probe`: the value of a running field at a point — waited for until it crosses a
//! level ([`wait_for`]), or printed line by line from the newest frame ([`follow`]). Both wait on
//! the node, so Ctrl-C or SIGTERM (as iceoryx2 reports them to it) ends them.

use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::shm::{FieldReader, Frame, ShmError, Svc};

/// The point and channel probed.
#[derive(Debug, Clone, Copy)]
pub struct ProbePoint {
    pub x: f32,
    pub y: f32,
    pub channel: usize,
}

/// The level the value must cross.
#[derive(Debug, Clone, Copy)]
pub enum Level {
    /// Any value (the first frame).
    Any,
    Above(f32),
    Below(f32),
}

impl Level {
    fn met(self, v: f32) -> bool {
        match self {
            Level::Any => true,
            Level::Above(l) => v > l,
            Level::Below(l) => v < l,
        }
    }
}

/// Why a probe failed.
#[derive(Debug, thiserror::Error)]
pub enum ProbeError {
    #[error(transparent)]
    Shm(#[from] ShmError),
    #[error("interrupted before the value at ({}, {}) channel {} reached the condition", .0.x, .0.y, .0.channel)]
    Interrupted(ProbePoint),
    /// The field has no channel `channel` (the user's input).
    #[error("--channel {channel}: the field has {channels} channel(s)")]
    NoChannel { channel: usize, channels: usize },
}

pheromone_field::from_shm_errors!(ProbeError);

/// Waits up to `timeout` (in slices, so that Ctrl-C or SIGTERM is seen between them) until the
/// value at `p` meets `level`; whether it did.
pub fn wait_for(
    node: &Node<Svc>,
    reader: &mut FieldReader,
    p: ProbePoint,
    level: Level,
    timeout: Duration,
) -> Result<bool, ProbeError> {
    let deadline = Instant::now() + timeout;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let slice = left.min(Duration::from_millis(200));
        if reader
            .wait_until(slice, |f| {
                p.channel < f.view.channels && level.met(f.view.value(p.channel, p.x, p.y))
            })?
            .is_some()
        {
            return Ok(true);
        }
        if left.is_zero() {
            return Ok(false);
        }
        if pheromone_field::shm::should_stop(node) {
            return Err(ProbeError::Interrupted(p));
        }
    }
}

/// The value at `p` in the frame `reader` holds (the channel clamped to the field's), if any.
pub fn last_value(reader: &FieldReader, p: ProbePoint) -> Option<f32> {
    reader.frame().map(|f| {
        f.view
            .value(p.channel.min(f.view.channels.saturating_sub(1)), p.x, p.y)
    })
}

/// One line of `probe`: the frame's header and the value at `p`.
pub fn probe_line(frame: &Frame<'_>, p: ProbePoint) -> String {
    let h = frame.header;
    let (x, y, ch) = (p.x, p.y, p.channel);
    format!(
        "frame {} at t = {:.2} s ({}×{}×{}, {} m): value at ({x}, {y}) channel {ch} = {}; \
         deposits {} applied, {} rejected",
        h.sequence,
        h.sim_time_s,
        h.width,
        h.height,
        h.channels,
        h.cell_size_m,
        frame.view.value(ch, x, y),
        h.deposits_applied,
        h.deposits_rejected_total()
    )
}

/// `probe --follow`: a line from the newest frame on stdout every `period`, waiting on the node
/// (which returns on Ctrl-C or SIGTERM: `Ok`), as iceoryx2's examples loop.
pub fn follow(
    node: &Node<Svc>,
    field: &str,
    mut reader: FieldReader,
    p: ProbePoint,
    period: Duration,
    timeout: Duration,
) -> Result<(), ProbeError> {
    if reader.frame().is_none() {
        reader.wait_frame(timeout)?;
    }
    loop {
        reader.update()?;
        match reader.frame() {
            Some(frame) if p.channel >= frame.view.channels => {
                return Err(ProbeError::NoChannel {
                    channel: p.channel,
                    channels: frame.view.channels,
                });
            }
            Some(frame) => println!("{}", probe_line(&frame, p)),
            None => eprintln!("field '{field}': no frame yet"),
        }
        if pheromone_field::shm::node_wait(node, period).is_err() {
            return Ok(());
        }
    }
}
