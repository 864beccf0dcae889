//! `pheromone probe`: a minimal reader for scripts, tests and first steps (the same as the
//! `read` example). The waits are `pheromone_report::probe`.

use std::time::Duration;

use clap::Args;
use iceoryx2::prelude::Node;
use pheromone_field::shm::{create_node, mirror_info, FieldReader, Frame, Svc};
use pheromone_report::probe::{
    follow, last_value, probe_line, wait_for, Level, ProbeError, ProbePoint,
};

use super::bad_from;

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
    let timeout = Duration::from_secs_f64(a.timeout);
    let node = create_node(&format!("probe-{}", std::process::id()))?;
    let mut reader = FieldReader::attach_within(&node, &a.field, timeout)?;
    let p = ProbePoint {
        x: a.x,
        y: a.y,
        channel: a.channel,
    };
    if a.follow {
        let period = Duration::from_secs_f64(1.0 / a.rate_hz);
        return follow(&node, &a.field, reader, p, period, timeout).map_err(probe_error);
    }
    let level = match (a.above, a.below) {
        (Some(l), _) => Level::Above(l),
        (_, Some(l)) => Level::Below(l),
        _ => Level::Any,
    };
    let met = wait_for(&node, &mut reader, p, level, timeout).map_err(probe_error)?;
    let frame = if met { reader.frame() } else { None };
    let Some(frame) = frame else {
        anyhow::bail!(
            "the value at ({}, {}) channel {} did not reach the condition within {} s (last value {:?})",
            p.x,
            p.y,
            p.channel,
            a.timeout,
            last_value(&reader, p)
        );
    };
    if p.channel >= frame.view.channels {
        return Err(probe_error(ProbeError::NoChannel {
            channel: p.channel,
            channels: frame.view.channels,
        }));
    }
    print_probe(&a, &node, &frame, p)
}

/// A channel the field does not have is the user's input (exit status 2).
fn probe_error(e: ProbeError) -> anyhow::Error {
    match e {
        ProbeError::NoChannel { .. } => bad_from(e),
        e => e.into(),
    }
}

/// The probe's output: the frame's header and the value, as a line or one JSON object.
fn print_probe(
    a: &ProbeArgs,
    node: &Node<Svc>,
    frame: &Frame<'_>,
    p: ProbePoint,
) -> anyhow::Result<()> {
    let h = frame.header;
    let value = frame.view.value(p.channel, p.x, p.y);
    let mirror = mirror_info(node, &a.field)?;
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
                "x": p.x, "y": p.y, "channel": p.channel, "value": value, "mirror": mirror,
            })
        );
    } else {
        println!("{}", probe_line(frame, p));
    }
    Ok(())
}
