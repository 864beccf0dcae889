//! What a frame becomes on ROS 2: its topics and their messages, shared by the Zenoh node and
//! the MCAP recorder.

use pheromone_field::shm::{now_ns, FieldReader};

use crate::grid::{grid_map_cdr, layer_name, occupancy_grid_cdr, FrameRef, Occupancy, Stamp};
use crate::rmw_zenoh::{resolve_topic, NameError};
use crate::types::{TypeInfo, GRID_MAP, OCCUPANCY_GRID};

/// The field's topics (absolute names) and types: index 0 is the GridMap, index `1 + c` channel
/// `c`'s OccupancyGrid.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldTopics {
    pub names: Vec<String>,
    pub types: Vec<TypeInfo>,
}

impl FieldTopics {
    /// `<ns>/pheromone/grid_map` and `<ns>/pheromone/occupancy/channel_<c>`.
    pub fn new(namespace: &str, channels: usize) -> Result<Self, NameError> {
        let mut names = vec![resolve_topic(namespace, "pheromone/grid_map")?];
        let mut types = vec![TypeInfo::of(GRID_MAP)];
        let occ = TypeInfo::of(OCCUPANCY_GRID);
        for c in 0..channels {
            names.push(resolve_topic(
                namespace,
                &format!("pheromone/occupancy/{}", layer_name(c)),
            )?);
            types.push(occ.clone());
        }
        Ok(Self { names, types })
    }
}

/// Nanoseconds since the epoch now.
pub fn wall_now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i64)
}

/// The wall-clock time of a CLOCK_MONOTONIC stamp (a frame's `stamp_ns`).
pub fn wall_from_monotonic_ns(mono_ns: u64) -> i64 {
    let age = now_ns().saturating_sub(mono_ns) as i64;
    wall_now_ns() - age
}

/// The time base of a session's stamps (docs/ros2.md, "Time"): one per session, so every topic
/// of it can be compared with every other.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TimeBase {
    /// The wall clock (a live field): a frame's CLOCK_MONOTONIC stamp carried over to the
    /// wall clock.
    #[default]
    Wall,
    /// Simulated time (a simulated run): a frame's field time `sim_time_s`, which in lockstep
    /// is the world's time after the step (the scenario's field ticks once per world step).
    Sim,
}

impl TimeBase {
    pub fn name(self) -> &'static str {
        match self {
            TimeBase::Wall => "wall",
            TimeBase::Sim => "sim",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        [TimeBase::Wall, TimeBase::Sim]
            .into_iter()
            .find(|t| t.name() == name)
    }

    /// A frame's stamp in this time base.
    pub fn frame_stamp(self, h: &pheromone_field::messages::FrameHeader) -> Stamp {
        match self {
            TimeBase::Wall => Stamp::from_ns(wall_from_monotonic_ns(h.stamp_ns)),
            TimeBase::Sim => Stamp::from_secs(h.sim_time_s),
        }
    }
}

/// The messages of the reader's current frame, in topic order (see [`FieldTopics`]), stamped in
/// `time`, with the frame's sequence and monotonic stamp; `None` before the first frame. Each
/// message is serialized straight from the shared frame.
pub fn frame_messages(
    reader: &FieldReader,
    frame_id: &str,
    time: TimeBase,
    occupancy: &Occupancy,
) -> Option<FrameMessages> {
    let frame = reader.frame()?;
    let h = frame.header;
    let geometry = h.geometry();
    let n = geometry.cells();
    let channels = h.channels as usize;
    let cells = reader.sample()?.payload();
    let f = FrameRef {
        geometry,
        channels,
        cells: &cells[..channels * n],
        stamp: time.frame_stamp(h),
        frame_id,
    };
    Some(FrameMessages {
        sequence: h.sequence,
        stamp_mono_ns: h.stamp_ns,
        stamp: f.stamp,
        channels,
        messages: frame_cdr_with(&f, occupancy),
    })
}

/// A frame's messages in topic order (see [`FieldTopics`]): the GridMap, then each channel's
/// OccupancyGrid with the default occupancy scale ([`Occupancy::default`]). What `sim --record`
/// writes.
pub fn frame_cdr(f: &FrameRef<'_>) -> Vec<Vec<u8>> {
    frame_cdr_with(f, &Occupancy::default())
}

/// [`frame_cdr`] with occupancy `o`: what `pheromone ros2` publishes and `pheromone record`
/// writes.
pub fn frame_cdr_with(f: &FrameRef<'_>, o: &Occupancy) -> Vec<Vec<u8>> {
    let mut messages = Vec::with_capacity(1 + f.channels);
    messages.push(grid_map_cdr(f));
    for c in 0..f.channels {
        messages.push(occupancy_grid_cdr(f, c, o).0);
    }
    messages
}

/// `rosgraph_msgs/msg/Clock` at `stamp`, in CDR.
pub fn clock_cdr(stamp: Stamp) -> Vec<u8> {
    let mut w = crate::cdr::CdrWriter::with_capacity(12);
    w.i32(stamp.sec);
    w.u32(stamp.nanosec);
    w.finish()
}

/// One frame's messages.
#[derive(Debug, Clone)]
pub struct FrameMessages {
    pub sequence: u64,
    pub stamp_mono_ns: u64,
    pub stamp: Stamp,
    pub channels: usize,
    pub messages: Vec<Vec<u8>>,
}
