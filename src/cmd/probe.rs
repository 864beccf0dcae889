//! `pheromone probe`: a minimal reader for scripts, tests and first steps (the same as the
//! `read` example).

use std::time::Duration;

use clap::Args;
use iceoryx2::prelude::Node;
use pheromone_field::shm::{create_node, mirror_info, FieldReader, Frame, Svc};

use super::{bad, seconds_or_zero};

/// Read a running field: wait for a frame, print its header and the value at a point.
///
/// With --above or --below it waits (up to --timeout) until the value at the point crosses that
/// level, and exits with status 1 if it never does. With --follow it prints a line (the
/// header and the value) --rate-hz times a second, from the newest frame, until Ctrl-C, like
/// `ros2 topic echo`.
#[derive(Args, Debug)]
pub struct ProbeArgs {
    /// Field name.
    #[arg(long, default_value = "main")]
    pub field: String,
    /// World x of the probe point (m).
    #[arg(long, value_parser = super::f32_any(), default_value_t = 0.0, allow_negative_numbers = true)]
    pub x: f32,
    /// World y of the probe point (m).
    #[arg(long, value_parser = super::f32_any(), default_value_t = 0.0, allow_negative_numbers = true)]
    pub y: f32,
    /// Channel index.
    #[arg(long, value_parser = super::int::<usize>(0, 63), default_value_t = 0)]
    pub channel: usize,
    /// Wait until the value is above this level.
    #[arg(long, value_parser = super::f32_any(), conflicts_with = "below")]
    pub above: Option<f32>,
    /// Wait until the value is below this level.
    #[arg(long, value_parser = super::f32_any())]
    pub below: Option<f32>,
    /// Seconds to wait for the field and the condition.
    #[arg(long, value_parser = super::secs0(), default_value_t = 10.0)]
    pub timeout: f64,
    /// Print one JSON object on stdout.
    #[arg(long, conflicts_with = "follow")]
    pub json: bool,
    /// Print the newest frame's header and value at the point --rate-hz times a second until
    /// Ctrl-C (exit status 0).
    #[arg(long, conflicts_with_all = ["above", "below"])]
    pub follow: bool,
    /// Lines per second with --follow.
    #[arg(long, value_parser = super::f64_pos(1e4), default_value_t = 10.0, value_name = "R", requires = "follow")]
    pub rate_hz: f64,
}

pub fn run_probe(a: ProbeArgs) -> anyhow::Result<()> {
    if a.follow && !(a.rate_hz.is_finite() && a.rate_hz > 0.0 && a.rate_hz <= 10_000.0) {
        return Err(bad(format!(
            "--rate-hz {}: must be a number of lines per second in (0, 10000]",
            a.rate_hz
        )));
    }
    let timeout = seconds_or_zero("timeout", a.timeout)?;
    let node = create_node(&format!("probe-{}", std::process::id()))?;
    let mut reader = FieldReader::attach_within(&node, &a.field, timeout)?;
    if a.follow {
        return follow(&a, &node, reader, timeout);
    }
    let (x, y, ch) = (a.x, a.y, a.channel);
    let pred = |v: f32| match (a.above, a.below) {
        (Some(l), _) => v > l,
        (_, Some(l)) => v < l,
        _ => true,
    };
    // Wait in slices so Ctrl-C (or SIGTERM) is seen between them.
    let deadline = std::time::Instant::now() + timeout;
    let met = loop {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        let slice = left.min(Duration::from_millis(200));
        if reader
            .wait_until(slice, |f| {
                ch < f.view.channels && pred(f.view.value(ch, x, y))
            })?
            .is_some()
        {
            break true;
        }
        if left.is_zero() {
            break false;
        }
        if node.wait(Duration::ZERO).is_err() {
            anyhow::bail!(
                "interrupted before the value at ({x}, {y}) channel {ch} reached the condition"
            );
        }
    };
    let frame = if met { reader.frame() } else { None };
    let Some(frame) = frame else {
        let last = reader.frame().map(|f| {
            f.view
                .value(ch.min(f.view.channels.saturating_sub(1)), x, y)
        });
        anyhow::bail!(
            "the value at ({x}, {y}) channel {ch} did not reach the condition within {} s (last value {last:?})",
            a.timeout
        );
    };
    if ch >= frame.view.channels {
        return Err(bad(format!(
            "--channel {ch}: the field has {} channel(s)",
            frame.view.channels
        )));
    }
    let h = frame.header;
    let value = frame.view.value(ch, x, y);
    let mirror = mirror_info(&node, &a.field)?;
    if let Some(m) = mirror.filter(|m| m.stale) {
        eprintln!(
            "field '{}' is stale ({}): frame {} may be behind its origin",
            a.field,
            m.describe(),
            h.sequence
        );
    }
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "field": a.field, "sequence": h.sequence, "sim_time_s": h.sim_time_s,
                "width": h.width, "height": h.height, "channels": h.channels, "cell_size_m": h.cell_size_m,
                "deposits_applied": h.deposits_applied, "deposits_rejected": h.deposits_rejected_total(),
                "x": x, "y": y, "channel": ch, "value": value, "mirror": mirror,
            })
        );
    } else {
        println!("{}", probe_line(&frame, x, y, ch));
    }
    Ok(())
}

/// One line of `probe`: the frame's header and the value at (x, y) of channel `ch`.
fn probe_line(frame: &Frame<'_>, x: f32, y: f32, ch: usize) -> String {
    let h = frame.header;
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

/// `probe --follow`: a line from the newest frame every 1/rate s, waiting on the node (which
/// returns on Ctrl-C or SIGTERM: exit status 0), as iceoryx2's examples loop.
fn follow(
    a: &ProbeArgs,
    node: &Node<Svc>,
    mut reader: FieldReader,
    timeout: Duration,
) -> anyhow::Result<()> {
    let period = Duration::from_secs_f64(1.0 / a.rate_hz);
    let (x, y, ch) = (a.x, a.y, a.channel);
    if reader.frame().is_none() {
        reader.wait_frame(timeout)?;
    }
    loop {
        reader.update()?;
        match reader.frame() {
            Some(frame) if ch >= frame.view.channels => {
                return Err(bad(format!(
                    "--channel {ch}: the field has {} channel(s)",
                    frame.view.channels
                )));
            }
            Some(frame) => println!("{}", probe_line(&frame, x, y, ch)),
            None => eprintln!("field '{}': no frame yet", a.field),
        }
        if node.wait(period).is_err() {
            return Ok(());
        }
    }
}
