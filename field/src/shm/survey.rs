//! The fields running on a host (`pheromone list`): found through iceoryx2's service listing
//! (`ipc::Service::list`, frame services named `pheromone/F/frame`, [`wire::field_of_frame_service`]),
//! then attached to for a window of time to measure the tick rate and read the port counts.

use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern;

use super::mirror_state::{mirror_info, MirrorInfo};
use super::timing::{field_timing, TimingInfo};
use super::{
    service_err, AttachError, FieldReader, FieldWatch, Iceoryx, ServiceError, ShmError, Svc,
};
use crate::wire;

/// What `pheromone list` shows of one field.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FieldInfo {
    /// The field's name (`F` of `pheromone/F/frame`).
    pub name: String,
    /// Grid width in cells. This and the other frame facts below are `None` (JSON `null`) for
    /// a field whose process is there but sent the survey no frame (stopped with SIGSTOP, or
    /// hung): only a frame says them.
    pub width: Option<u32>,
    /// Grid height in cells.
    pub height: Option<u32>,
    /// Channel planes per frame.
    pub channels: Option<u32>,
    /// Side of a square cell (m).
    pub cell_size_m: Option<f32>,
    /// Sequence of the newest frame seen.
    pub sequence: Option<u64>,
    /// Field time of the newest frame (s).
    pub sim_time_s: Option<f64>,
    /// Frames published per second over the window: the sequence difference between the first
    /// and the last frame seen over the difference of their publish stamps.
    pub tick_hz: f64,
    /// Readers: subscribers of the frame service, without the field's own subscription, a
    /// standby's, and the survey's.
    pub readers: usize,
    /// Depositors: publishers of the deposit service.
    pub depositors: usize,
    /// A new frame came during the window ("alive"); otherwise "stale" (the field died, or it
    /// is paused, e.g. waiting for its clock).
    pub alive: bool,
    /// A live process publishes the frames.
    pub publisher_alive: bool,
    /// The field is a mirror of a field on another host (`field --mirror`): its own account
    /// of whether it follows its origin (`null` for a field that is not a mirror).
    pub mirror: Option<MirrorInfo>,
    /// How well the field keeps its period: missed deadlines, the latest tick start, the
    /// longest gap between frames (`null` for a field that keeps no timing, e.g. a mirror).
    pub timing: Option<TimingInfo>,
    /// Every reader slot of the field is taken (`--max-readers`), so the survey could not read
    /// it: its frame facts are unknown (`null`), its port counts are the services' own.
    pub readers_full: bool,
}

impl FieldInfo {
    /// A field the survey got no frame of: its frame facts `None`, not alive; `readers` and
    /// `depositors` are its services' counts.
    fn without_frame(
        name: String,
        (readers, depositors): (usize, usize),
        publisher_alive: bool,
        readers_full: bool,
        mirror: Option<MirrorInfo>,
        timing: Option<TimingInfo>,
    ) -> Self {
        Self {
            name,
            width: None,
            height: None,
            channels: None,
            cell_size_m: None,
            sequence: None,
            sim_time_s: None,
            tick_hz: 0.0,
            readers,
            depositors,
            alive: false,
            publisher_alive,
            mirror,
            timing,
            readers_full,
        }
    }
}

/// The fields whose every reader slot is taken: what their services say, without a frame.
fn listed_full(
    node: &Node<Svc>,
    full: Vec<(String, FieldWatch)>,
) -> Result<Vec<FieldInfo>, ShmError> {
    let mut out = Vec::with_capacity(full.len());
    for (name, watch) in full {
        let status = watch.status();
        let readers = status
            .subscribers
            .saturating_sub(status.deposit_subscribers);
        out.push(FieldInfo::without_frame(
            name.clone(),
            (readers, status.depositors),
            status.publishers > 0,
            true,
            mirror_info(node, &name)?,
            field_timing(node, &name)?,
        ));
    }
    Ok(out)
}

/// Names of the fields whose frame service exists on this host, sorted.
pub fn field_names(config: &Config) -> Result<Vec<String>, ServiceError> {
    let mut names = Vec::new();
    Svc::list(config, |s| {
        if matches!(
            s.static_details.messaging_pattern(),
            MessagingPattern::PublishSubscribe(_)
        ) {
            if let Some(f) = wire::field_of_frame_service(s.static_details.name().as_str()) {
                names.push(f.to_string());
            }
        }
        CallbackProgression::Continue
    })
    .map_err(|e| service_err("*", "list services", Iceoryx(e)))?;
    names.sort();
    names.dedup();
    Ok(names)
}

/// Attaches to every field on the host, waits for each one's first frame (a new subscriber
/// gets the current frame with the publisher's next send; at most `window`), then waits
/// `window` on the node (Ctrl-C ends the wait early) and reports each one, its rate over the
/// time between its first frame and the end. A field whose process is there but that sent no
/// frame (stopped, hung) is reported without its frame facts and `alive: false`; one that went
/// away while it was being attached to, or whose process is gone and sent no frame, is left out.
pub fn survey(node: &Node<Svc>, window: Duration) -> Result<Vec<FieldInfo>, ShmError> {
    let mut open = Vec::new();
    let mut full = Vec::new();
    for name in field_names(node.config()).map_err(AttachError::from)? {
        match (
            FieldReader::attach(node, &name),
            FieldWatch::open(node, &name),
        ) {
            (Ok(reader), Ok(watch)) => open.push((name, reader, watch, None)),
            (Err(AttachError::NoField { .. }), _) | (_, Err(AttachError::NoField { .. })) => {}
            // Every reader slot taken (or another port limit): listed without its frame.
            (Err(AttachError::Service(_)), Ok(watch)) => full.push((name, watch)),
            (Err(e), _) | (_, Err(e)) => return Err(e.into()),
        }
    }
    let started = Instant::now();
    for (_, reader, _, first) in &mut open {
        let left = window.saturating_sub(started.elapsed());
        if reader.frame().is_none() {
            reader.wait_frame(left)?;
        }
        *first = reader
            .frame()
            .map(|f| (f.header.sequence, f.header.stamp_ns, Instant::now()));
    }
    let _ = crate::shm::node_wait(node, window);
    let mut out = Vec::with_capacity(open.len());
    for (name, mut reader, watch, first) in open {
        reader.update()?;
        let status = watch.status();
        let publisher_alive = reader.field_alive();
        let mirror = mirror_info(node, &name)?;
        let timing = field_timing(node, &name)?;
        // The field and a standby each hold one frame subscriber and one deposit subscriber.
        let own = status.deposit_subscribers + 1;
        let (Some(frame), Some((first_seq, first_stamp_ns, first_at))) = (reader.frame(), first)
        else {
            if publisher_alive {
                out.push(FieldInfo::without_frame(
                    name,
                    (status.subscribers.saturating_sub(own), status.depositors),
                    publisher_alive,
                    false,
                    mirror,
                    timing,
                ));
            }
            continue;
        };
        let h = frame.header;
        let ticks = h.sequence.saturating_sub(first_seq);
        // Over the frames' own publish stamps when they advanced (no rounding to whole ticks
        // within the window), else over the wall time waited.
        let stamped_s = h.stamp_ns.saturating_sub(first_stamp_ns) as f64 * 1e-9;
        let elapsed_s = if ticks > 0 && stamped_s > 0.0 {
            stamped_s
        } else {
            first_at.elapsed().as_secs_f64().max(1e-9)
        };
        out.push(FieldInfo {
            name,
            width: Some(h.width),
            height: Some(h.height),
            channels: Some(h.channels),
            cell_size_m: Some(h.cell_size_m),
            sequence: Some(h.sequence),
            sim_time_s: Some(h.sim_time_s),
            tick_hz: ticks as f64 / elapsed_s,
            readers: status.subscribers.saturating_sub(own),
            depositors: status.depositors,
            alive: ticks > 0,
            publisher_alive,
            mirror,
            timing,
            readers_full: false,
        });
    }
    out.extend(listed_full(node, full)?);
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}
