//! `pheromone view`: a live web page of a running field (issue 17).
//!
//! This module is the pure part: the newest frame → a downsampled snapshot the page draws
//! ([`snapshot`], [`downsample`]), the query parsing of the API ([`parse_frame_query`]), the
//! statistics measured from the frames seen ([`StatsTracker`]) and the robots' recent paths
//! ([`RobotPaths`]). [`server`] is the HTTP side: one loop, the field read with a `FieldReader`
//! (no copy of the frame; only the downsampled snapshot is built per request); [`http`] reads
//! each request's head on a thread of its own, with bounds.
//!
//! Why its own small HTTP/1.x server: the view serves a handful of GETs per second to one page
//! on loopback, in the same loop that polls the field's iceoryx2 ports (which are not `Send`),
//! where an async stack (axum, tokio, hyper) would add a runtime and ~60 crates for nothing the
//! view needs. `tiny_http`, used before, reads a request line of any length into memory (a
//! 32 MiB query took the view from 19 to 52 MB, 84 MB at its peak); [`http`] stops at 4 KiB.
//!
//! Downsampling is a *max-magnitude pool*: each output cell takes the input value of largest
//! magnitude in its block, sign kept. A narrow trail or a small blob stays visible at any zoom
//! (a mean would smear it out), and anti-pheromone troughs are kept as well as peaks. Every
//! output value is a value of the frame, so the frame's min and max (computed at full
//! resolution, with the hottest cell's position) bound the snapshot.

pub mod http;
pub mod server;

use std::collections::{BTreeMap, VecDeque};
use std::fmt;

use pheromone_field::deposit::RejectReason;
use pheromone_field::messages::FrameHeader;
use serde::Serialize;

/// Largest `max_side` a request may ask for.
pub const MAX_SIDE_LIMIT: usize = 4096;

/// Positions kept per robot for its recent path.
pub const PATH_LENGTH: usize = 200;

/// A bad query parameter: its name, the value given and what is wrong (answered with a 400).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QueryError {
    pub param: String,
    pub value: String,
    pub reason: String,
}

impl fmt::Display for QueryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}: {}", self.param, self.value, self.reason)
    }
}

impl std::error::Error for QueryError {}

fn query_error(param: &str, value: &str, reason: impl Into<String>) -> QueryError {
    QueryError {
        param: shown(param),
        value: shown(value),
        reason: reason.into(),
    }
}

/// Longest part of a request an error message repeats (chars); longer ones are cut with `…`.
pub const ECHO_MAX_CHARS: usize = 32;

/// `s` as an error message may repeat it: at most [`ECHO_MAX_CHARS`] chars.
fn shown(s: &str) -> String {
    match s.char_indices().nth(ECHO_MAX_CHARS) {
        Some((at, _)) => format!("{}…", &s[..at]),
        None => s.to_string(),
    }
}

/// What `/api/frame` was asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameQuery {
    pub channel: u32,
    pub max_side: usize,
}

/// Parses `channel=C&max_side=N` (both optional: channel 0, `default_max_side`). Unknown
/// parameters, repeated ones, non-numbers and `max_side` outside 1..=[`MAX_SIDE_LIMIT`] are
/// errors. The channel is checked against the frame with [`FrameQuery::check_channel`].
pub fn parse_frame_query(
    query: Option<&str>,
    default_max_side: usize,
) -> Result<FrameQuery, QueryError> {
    let mut channel = None;
    let mut max_side = None;
    for pair in query.unwrap_or("").split('&').filter(|p| !p.is_empty()) {
        let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
        let slot = match key {
            "channel" => &mut channel,
            "max_side" => &mut max_side,
            _ => return Err(query_error(key, value, "unknown parameter")),
        };
        if slot.is_some() {
            return Err(query_error(key, value, "given twice"));
        }
        let n: u64 = value
            .parse()
            .map_err(|_| query_error(key, value, "not a non-negative integer"))?;
        *slot = Some(n);
    }
    let max_side = match max_side {
        None => default_max_side,
        Some(n) if (1..=MAX_SIDE_LIMIT as u64).contains(&n) => n as usize,
        Some(n) => {
            return Err(query_error(
                "max_side",
                &n.to_string(),
                format!("must be between 1 and {MAX_SIDE_LIMIT}"),
            ))
        }
    };
    let channel = match channel {
        None => 0,
        Some(c) => {
            u32::try_from(c).map_err(|_| query_error("channel", &c.to_string(), "out of range"))?
        }
    };
    Ok(FrameQuery { channel, max_side })
}

impl FrameQuery {
    /// The channel must name one of the frame's `channels`.
    pub fn check_channel(&self, channels: u32) -> Result<(), QueryError> {
        if self.channel < channels {
            Ok(())
        } else {
            Err(query_error(
                "channel",
                &self.channel.to_string(),
                format!("the field has {channels} channel(s), 0..{channels}"),
            ))
        }
    }
}

/// A plane pooled down to at most `max_side` cells a side.
#[derive(Debug, Clone, PartialEq)]
pub struct Downsampled {
    pub width: usize,
    pub height: usize,
    /// Input cells per output cell along each axis.
    pub factor: usize,
    /// Row-major, row 0 at the grid's origin (lowest y), like the frame.
    pub cells: Vec<f32>,
}

/// Pools `plane` (`width × height`, row-major) by an integer factor, the smallest that brings
/// both sides to at most `max_side` (`max_side` ≥ 1); edge blocks are partial. Each output
/// cell is the finite value of largest magnitude in its block (0 if it has none), so no NaN or
/// infinity ever reaches the page.
pub fn downsample(plane: &[f32], width: usize, height: usize, max_side: usize) -> Downsampled {
    assert_eq!(plane.len(), width * height, "plane length");
    let max_side = max_side.max(1);
    let factor = width.max(height).div_ceil(max_side).max(1);
    let (ow, oh) = (width.div_ceil(factor), height.div_ceil(factor));
    let mut cells = vec![0.0f32; ow * oh];
    // Row by row through the input (cache friendly): each input row updates one output row.
    let mut best = vec![0.0f32; ow];
    for oy in 0..oh {
        best.iter_mut().for_each(|b| *b = 0.0);
        for y in oy * factor..((oy + 1) * factor).min(height) {
            let row = &plane[y * width..(y + 1) * width];
            for (b, block) in best.iter_mut().zip(row.chunks(factor)) {
                for &v in block {
                    if v.is_finite() && v.abs() > b.abs() {
                        *b = v;
                    }
                }
            }
        }
        cells[oy * ow..(oy + 1) * ow].copy_from_slice(&best);
    }
    Downsampled {
        width: ow,
        height: oh,
        factor,
        cells,
    }
}

/// The finite extremes of a plane and where its largest value is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extremes {
    pub min: f32,
    pub max: f32,
    /// Index of the (first) cell holding `max`.
    pub argmax: usize,
}

/// Min, max and argmax over the finite cells (all 0 for an empty or all-NaN plane).
pub fn extremes(plane: &[f32]) -> Extremes {
    let mut e = Extremes {
        min: f32::INFINITY,
        max: f32::NEG_INFINITY,
        argmax: 0,
    };
    for (i, &v) in plane.iter().enumerate() {
        if !v.is_finite() {
            continue;
        }
        if v > e.max {
            e.max = v;
            e.argmax = i;
        }
        e.min = e.min.min(v);
    }
    if e.max < e.min {
        e = Extremes {
            min: 0.0,
            max: 0.0,
            argmax: 0,
        };
    }
    e
}

/// The hottest cell of a frame, at full resolution.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Hottest {
    pub value: f32,
    pub col: u32,
    pub row: u32,
    /// Its centre in world metres.
    pub x_m: f32,
    pub y_m: f32,
}

/// What `/api/frame` answers: one channel of the newest frame, downsampled.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameSnapshot {
    pub sequence: u64,
    pub sim_time_s: f64,
    pub channel: u32,
    pub channels: u32,
    /// Downsampled grid.
    pub width: usize,
    pub height: usize,
    pub factor: usize,
    /// Cell size of the downsampled grid (m).
    pub cell_size_m: f32,
    pub origin_x_m: f32,
    pub origin_y_m: f32,
    /// The frame's own grid.
    pub source_width: u32,
    pub source_height: u32,
    pub source_cell_size_m: f32,
    /// Finite extremes of the channel at full resolution.
    pub min: f32,
    pub max: f32,
    pub hottest: Hottest,
    pub pool: &'static str,
    /// Row-major, row 0 at `origin_y_m`.
    pub cells: Vec<f32>,
}

/// One channel of a frame, downsampled to at most `max_side` a side. `cells` is the whole
/// frame (every channel); the caller has checked `channel`.
pub fn snapshot(
    header: &FrameHeader,
    cells: &[f32],
    channel: u32,
    max_side: usize,
) -> FrameSnapshot {
    let (w, h) = (header.width as usize, header.height as usize);
    let plane = &cells[channel as usize * w * h..(channel as usize + 1) * w * h];
    let d = downsample(plane, w, h, max_side);
    let e = extremes(plane);
    let (col, row) = ((e.argmax % w.max(1)) as u32, (e.argmax / w.max(1)) as u32);
    let (x_m, y_m) = header.geometry().world_from_grid(col, row);
    FrameSnapshot {
        sequence: header.sequence,
        sim_time_s: header.sim_time_s,
        channel,
        channels: header.channels,
        width: d.width,
        height: d.height,
        factor: d.factor,
        cell_size_m: header.cell_size_m * d.factor as f32,
        origin_x_m: header.origin_x_m,
        origin_y_m: header.origin_y_m,
        source_width: header.width,
        source_height: header.height,
        source_cell_size_m: header.cell_size_m,
        min: e.min,
        max: e.max,
        hottest: Hottest {
            value: e.max,
            col,
            row,
            x_m,
            y_m,
        },
        pool: "max-magnitude",
        cells: d.cells,
    }
}

/// How far back the tick rate is measured.
const RATE_WINDOW_NS: u64 = 2_000_000_000;

/// Statistics from the frame headers the view has seen.
#[derive(Debug, Default)]
pub struct StatsTracker {
    /// (sequence, stamp_ns) of frames seen in the last [`RATE_WINDOW_NS`].
    seen: VecDeque<(u64, u64)>,
    last: Option<FrameHeader>,
    frames_seen: u64,
    longest_gap_ns: u64,
}

/// What `/api/stats` answers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stats {
    pub field: String,
    /// `waiting` (no frame yet), `live`, `stalled` (its process is there but no new frame for
    /// five tick periods, at least 1 s), `stopped` (no process publishes its frames: it died or
    /// stopped; its last frame is still served).
    pub state: &'static str,
    /// The state in words, as the page shows it.
    pub status: String,
    /// Seconds since the view last saw a new frame.
    pub last_frame_age_s: Option<f64>,
    /// Whether a frame has been seen at all.
    pub attached: bool,
    pub sequence: u64,
    pub sim_time_s: f64,
    pub channels: u32,
    pub width: u32,
    pub height: u32,
    pub cell_size_m: f32,
    /// Ticks per second from sequence numbers over publish stamps of the last 2 s.
    pub tick_hz: f64,
    pub tick_compute_ms: f64,
    pub deposits_applied: u64,
    pub deposits_this_tick: u32,
    pub deposits_rejected: BTreeMap<&'static str, u64>,
    pub deposits_rejected_total: u64,
    /// Subscribers of the frame service (the view included), if known.
    pub readers: Option<usize>,
    /// Longest stamp gap between two consecutive frames (sequence + 1) the view saw; it sees
    /// most but not necessarily all frames.
    pub longest_tick_gap_ms: f64,
    pub frames_seen: u64,
}

impl StatsTracker {
    /// Records a frame header (called for each new frame the view takes).
    pub fn record(&mut self, h: &FrameHeader) {
        if let Some(last) = &self.last {
            if h.sequence == last.sequence {
                return;
            }
            if h.sequence < last.sequence {
                // A restarted field (or a restored checkpoint): start measuring again.
                self.seen.clear();
            } else if h.sequence == last.sequence + 1 {
                self.longest_gap_ns = self
                    .longest_gap_ns
                    .max(h.stamp_ns.saturating_sub(last.stamp_ns));
            }
        }
        self.frames_seen += 1;
        self.seen.push_back((h.sequence, h.stamp_ns));
        while self
            .seen
            .front()
            .is_some_and(|&(_, t)| h.stamp_ns.saturating_sub(t) > RATE_WINDOW_NS)
            && self.seen.len() > 2
        {
            self.seen.pop_front();
        }
        self.last = Some(*h);
    }

    /// Ticks per second over the window (0 with fewer than two frames).
    pub fn tick_hz(&self) -> f64 {
        match (self.seen.front(), self.seen.back()) {
            (Some(&(s0, t0)), Some(&(s1, t1))) if t1 > t0 && s1 > s0 => {
                (s1 - s0) as f64 / ((t1 - t0) as f64 * 1e-9)
            }
            _ => 0.0,
        }
    }

    pub fn stats(&self, field: &str, readers: Option<usize>) -> Stats {
        let h = self.last.unwrap_or_default();
        Stats {
            field: field.to_string(),
            state: if self.last.is_some() {
                "live"
            } else {
                "waiting"
            },
            status: String::new(),
            last_frame_age_s: None,
            attached: self.last.is_some(),
            sequence: h.sequence,
            sim_time_s: h.sim_time_s,
            channels: h.channels,
            width: h.width,
            height: h.height,
            cell_size_m: h.cell_size_m,
            tick_hz: self.tick_hz(),
            tick_compute_ms: h.tick_compute_ns as f64 / 1e6,
            deposits_applied: h.deposits_applied,
            deposits_this_tick: h.deposits_this_tick,
            deposits_rejected: RejectReason::ALL
                .iter()
                .map(|r| (r.name(), h.deposits_rejected[*r as usize]))
                .collect(),
            deposits_rejected_total: h.deposits_rejected_total(),
            readers,
            longest_tick_gap_ms: self.longest_gap_ns as f64 / 1e6,
            frames_seen: self.frames_seen,
        }
    }
}

/// One robot's newest pose and recent path, as `/api/robots` answers it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobotTrack {
    pub id: u32,
    pub x_m: f64,
    pub y_m: f64,
    pub theta_rad: f64,
    pub step: u64,
    /// Up to [`PATH_LENGTH`] recent positions `[x, y]`, oldest first.
    pub path: Vec<[f64; 2]>,
}

/// The robots' recent paths, [`PATH_LENGTH`] positions each.
#[derive(Debug, Default)]
pub struct RobotPaths {
    tracks: BTreeMap<u32, (pheromone_messages::PoseMsg, VecDeque<[f64; 2]>)>,
}

impl RobotPaths {
    /// Adds a pose of robot `id`; a pose with a non-finite position is ignored.
    pub fn push(&mut self, id: u32, pose: pheromone_messages::PoseMsg) {
        if !(pose.x_m.is_finite() && pose.y_m.is_finite() && pose.theta_rad.is_finite()) {
            return;
        }
        let (last, path) = self.tracks.entry(id).or_default();
        *last = pose;
        if path.back() != Some(&[pose.x_m, pose.y_m]) {
            path.push_back([pose.x_m, pose.y_m]);
        }
        while path.len() > PATH_LENGTH {
            path.pop_front();
        }
    }

    pub fn tracks(&self) -> Vec<RobotTrack> {
        self.tracks
            .iter()
            .map(|(&id, (p, path))| RobotTrack {
                id,
                x_m: p.x_m,
                y_m: p.y_m,
                theta_rad: p.theta_rad,
                step: p.step,
                path: path.iter().copied().collect(),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests;
