//! The field's frame as `grid_map_msgs/msg/GridMap` (every channel a float32 layer) and as one
//! `nav_msgs/msg/OccupancyGrid` per channel, serialized to CDR straight from the frame's cells.
//!
//! Layouts. The field stores each channel row-major from its lower-left corner: cell `(x, y)`
//! at `y·width + x`, centred at `origin + (x + ½, y + ½)·cell_size`.
//! - OccupancyGrid has the same layout (row-major from `info.origin`): the data is the channel
//!   in order, scaled.
//! - grid_map stores a layer column-major from the corner of largest x and y (its index
//!   `(i, j)` counts cells along −x and −y): element `k` of a layer is the field's cell
//!   `width·height − 1 − k`, i.e. the plane read back to front. The layout's dimensions are
//!   `column_index` (size `height`, stride `width·height`) and `row_index` (size `width`,
//!   stride `width`), as `grid_map_ros` writes them; `info.pose` is the field's centre.
//!
//! OccupancyGrid values ([`Occupancy`], `--occupancy`): by default a fixed scale, the same for
//! every frame (`linear`: `round(100·(v − min)/(max − min))` clamped to 0–100, with `min` and
//! `max` given, 0 and 1 by default), or `binary` (100 from `max` up, else 0), or the per-frame
//! scale of before (`frame`: `min(0, smallest value)` to the largest value of the channel in
//! this frame; not comparable between frames). `trail = free` inverts the value (`100 − value`):
//! a trail is then free space and the rest cost. A cell with no data (a non-finite value, or a
//! value under `unknown_below` when given) is −1 in every mode. The message has no field for
//! the scale (its `MapMetaData` holds only geometry): the GridMap topic carries the values
//! themselves.

use pheromone_field::geometry::GridGeometry;

use crate::cdr::CdrWriter;

/// A ROS time (`builtin_interfaces/msg/Time`); ordered by time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct Stamp {
    pub sec: i32,
    pub nanosec: u32,
}

impl Stamp {
    /// From nanoseconds since the epoch (negative times are clamped to 0).
    pub fn from_ns(ns: i64) -> Self {
        let ns = ns.max(0);
        Self {
            sec: (ns / 1_000_000_000).min(i32::MAX as i64) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }

    /// From seconds (a simulated time), rounded to the nanosecond.
    pub fn from_secs(t_s: f64) -> Self {
        Self::from_ns((t_s * 1e9).round() as i64)
    }

    pub fn as_ns(self) -> i64 {
        self.sec as i64 * 1_000_000_000 + self.nanosec as i64
    }
}

/// One frame to publish: its geometry, channels, stamp and frame id, and its cells (all
/// channels, `channel, y, x`), borrowed from the shared frame.
#[derive(Debug, Clone, Copy)]
pub struct FrameRef<'a> {
    pub geometry: GridGeometry,
    pub channels: usize,
    pub cells: &'a [f32],
    pub stamp: Stamp,
    pub frame_id: &'a str,
}

impl<'a> FrameRef<'a> {
    pub fn plane(&self, channel: usize) -> &'a [f32] {
        let n = self.geometry.cells();
        &self.cells[channel * n..(channel + 1) * n]
    }
}

/// The name of channel `c`'s layer (and of its OccupancyGrid topic).
pub fn layer_name(c: usize) -> String {
    format!("channel_{c}")
}

/// A `std_msgs/msg/Header`.
pub(crate) fn header(w: &mut CdrWriter, stamp: Stamp, frame_id: &str) {
    w.i32(stamp.sec);
    w.u32(stamp.nanosec);
    w.string(frame_id);
}

/// A `geometry_msgs/msg/Pose` at `(x, y, 0)` with the identity orientation.
fn flat_pose(w: &mut CdrWriter, x_m: f64, y_m: f64) {
    for v in [x_m, y_m, 0.0, 0.0, 0.0, 0.0, 1.0] {
        w.f64(v);
    }
}

/// The frame as a CDR `grid_map_msgs/msg/GridMap`.
pub fn grid_map_cdr(f: &FrameRef<'_>) -> Vec<u8> {
    let g = &f.geometry;
    let (wc, hc) = (g.width as usize, g.height as usize);
    let n = wc * hc;
    let mut w = CdrWriter::with_capacity(256 + f.frame_id.len() + f.channels * (96 + 4 * n));
    header(&mut w, f.stamp, f.frame_id);
    let res = g.cell_size_m as f64;
    let (lx, ly) = (wc as f64 * res, hc as f64 * res);
    w.f64(res);
    w.f64(lx);
    w.f64(ly);
    flat_pose(
        &mut w,
        g.origin_x_m as f64 + lx / 2.0,
        g.origin_y_m as f64 + ly / 2.0,
    );
    w.seq_len(f.channels);
    for c in 0..f.channels {
        w.string(&layer_name(c));
    }
    w.seq_len(0);
    w.seq_len(f.channels);
    for c in 0..f.channels {
        w.seq_len(2);
        w.string("column_index");
        w.u32(hc as u32);
        w.u32(n as u32);
        w.string("row_index");
        w.u32(wc as u32);
        w.u32(wc as u32);
        w.u32(0);
        let plane = f.plane(c);
        w.f32_seq_from(n, |k| plane[n - 1 - k]);
    }
    w.u16(0);
    w.u16(0);
    w.finish()
}

/// How a channel's values become occupancy (0–100, −1 unknown): `--occupancy` (see the module
/// documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Occupancy {
    pub mode: OccupancyMode,
    /// The value that is 0 (`linear`).
    pub min: f32,
    /// The value that is 100 (`linear`), the threshold of `binary`.
    pub max: f32,
    /// `true`: a trail is free space (`100 − value`); `false`: a trail is cost.
    pub trail_free: bool,
    /// Cells under this value have no data (−1); non-finite cells always.
    pub unknown_below: Option<f32>,
}

/// The scale of [`Occupancy`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OccupancyMode {
    /// Fixed: `min` → 0, `max` → 100, linear between, clamped.
    Linear,
    /// Fixed: 100 from `max` up, else 0.
    Binary,
    /// Per channel and frame: `min(0, smallest)` → 0, largest → 100 (not comparable between
    /// frames).
    Frame,
}

impl OccupancyMode {
    pub const NAMES: [&'static str; 3] = ["linear", "binary", "frame"];

    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "linear" => Some(Self::Linear),
            "binary" => Some(Self::Binary),
            "frame" => Some(Self::Frame),
            _ => None,
        }
    }
}

impl Default for Occupancy {
    /// Linear from 0 to 1, trail = cost, no data only where a value is not finite.
    fn default() -> Self {
        Self {
            mode: OccupancyMode::Linear,
            min: 0.0,
            max: 1.0,
            trail_free: false,
            unknown_below: None,
        }
    }
}

/// The scale of one channel in one frame: [`Occupancy`] with `frame`'s bounds resolved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OccupancyScale {
    pub lo: f32,
    pub hi: f32,
    binary: bool,
    trail_free: bool,
    unknown_below: f32,
}

impl OccupancyScale {
    /// The scale `o` gives `plane`.
    pub fn new(o: &Occupancy, plane: &[f32]) -> Self {
        let (lo, hi) = match o.mode {
            OccupancyMode::Frame => {
                let (mut lo, mut hi) = (0.0f32, f32::NEG_INFINITY);
                for &v in plane.iter().filter(|v| v.is_finite()) {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
                (lo, hi)
            }
            _ => (o.min, o.max),
        };
        Self {
            lo,
            hi,
            binary: o.mode == OccupancyMode::Binary,
            trail_free: o.trail_free,
            unknown_below: o.unknown_below.unwrap_or(f32::NEG_INFINITY),
        }
    }

    /// The per-frame scale of `plane`, trail = cost (`--occupancy frame`).
    pub fn of(plane: &[f32]) -> Self {
        let o = Occupancy {
            mode: OccupancyMode::Frame,
            ..Occupancy::default()
        };
        Self::new(&o, plane)
    }

    /// The occupancy value (0–100, or −1 for no data) of `v`.
    #[inline]
    pub fn value(&self, v: f32) -> i8 {
        if !v.is_finite() || v < self.unknown_below {
            return -1;
        }
        let span = self.hi - self.lo;
        let x = if self.binary {
            if v >= self.hi {
                100
            } else {
                0
            }
        } else if span.is_finite() && span > 0.0 {
            // round(t) clamped to 0..=100, without `f32::round` (a libm call per cell on
            // x86-64's baseline, which kept the loop from vectorizing: issue 46's cost):
            // t + 0.5 in f64 is exact, so its truncation is round-half-away-from-zero.
            let t = (100.0 * (v - self.lo) / span).clamp(0.0, 100.0);
            (t as f64 + 0.5) as i8
        } else {
            0
        };
        if self.trail_free {
            100 - x
        } else {
            x
        }
    }
}

impl OccupancyScale {
    /// Each cell of `plane` as [`value`](Self::value) gives it, one byte a cell into `out`: the
    /// linear scale in a loop without branches, which the compiler vectorizes (issue 46: the
    /// per-cell `value` was most of `pheromone ros2`'s CPU).
    pub fn fill(&self, plane: &[f32], out: &mut [u8]) {
        let span = self.hi - self.lo;
        if self.binary || !(span.is_finite() && span > 0.0) {
            for (o, &v) in out.iter_mut().zip(plane) {
                *o = self.value(v) as u8;
            }
            return;
        }
        let (lo, unknown_below, flip) = (self.lo, self.unknown_below, self.trail_free);
        for (o, &v) in out.iter_mut().zip(plane) {
            let t = (100.0 * (v - lo) / span).clamp(0.0, 100.0);
            let x = (t as f64 + 0.5) as i32;
            let x = if flip { 100 - x } else { x };
            let known = v.is_finite() && v >= unknown_below;
            *o = if known { x as u8 } else { u8::MAX };
        }
    }
}

/// Channel `channel` of the frame as a CDR `nav_msgs/msg/OccupancyGrid` with occupancy `o`, and
/// its scale.
pub fn occupancy_grid_cdr(
    f: &FrameRef<'_>,
    channel: usize,
    o: &Occupancy,
) -> (Vec<u8>, OccupancyScale) {
    let g = &f.geometry;
    let n = g.cells();
    let plane = f.plane(channel);
    let scale = OccupancyScale::new(o, plane);
    let mut w = CdrWriter::with_capacity(160 + f.frame_id.len() + n);
    header(&mut w, f.stamp, f.frame_id);
    w.i32(f.stamp.sec);
    w.u32(f.stamp.nanosec);
    w.f32(g.cell_size_m);
    w.u32(g.width);
    w.u32(g.height);
    flat_pose(&mut w, g.origin_x_m as f64, g.origin_y_m as f64);
    w.byte_seq_with(n, |out| scale.fill(plane, out));
    (w.finish(), scale)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cdr::CdrReader;

    fn frame(cells: &[f32]) -> FrameRef<'_> {
        FrameRef {
            geometry: GridGeometry::new(3, 2, 0.5)
                .unwrap()
                .with_origin(-1.0, 2.0)
                .unwrap(),
            channels: 2,
            cells,
            stamp: Stamp { sec: 7, nanosec: 9 },
            frame_id: "map",
        }
    }

    #[test]
    fn grid_map_layers_are_the_planes_back_to_front() {
        let cells: Vec<f32> = (0..12).map(|v| v as f32).collect();
        let b = grid_map_cdr(&frame(&cells));
        let mut r = CdrReader::new(&b).unwrap();
        assert_eq!(r.i32("sec").unwrap(), 7);
        assert_eq!(r.u32("ns").unwrap(), 9);
        assert_eq!(r.string("frame").unwrap(), "map");
        let info: Vec<f64> = (0..10).map(|_| r.f64("info").unwrap()).collect();
        assert_eq!(&info[..5], &[0.5, 1.5, 1.0, -0.25, 2.5]);
        assert_eq!(r.u32("layers").unwrap(), 2);
        assert_eq!(r.string("l0").unwrap(), "channel_0");
        assert_eq!(r.string("l1").unwrap(), "channel_1");
        assert_eq!(r.u32("basic").unwrap(), 0);
        assert_eq!(r.u32("data").unwrap(), 2);
        for c in 0..2 {
            assert_eq!(r.u32("dims").unwrap(), 2);
            assert_eq!(r.string("d0").unwrap(), "column_index");
            assert_eq!((r.u32("").unwrap(), r.u32("").unwrap()), (2, 6));
            assert_eq!(r.string("d1").unwrap(), "row_index");
            assert_eq!((r.u32("").unwrap(), r.u32("").unwrap()), (3, 3));
            assert_eq!(r.u32("offset").unwrap(), 0);
            assert_eq!(r.u32("n").unwrap(), 6);
            for k in 0..6 {
                let v = f32::from_bits(r.u32("v").unwrap());
                assert_eq!(v, (c * 6 + 5 - k) as f32);
            }
        }
    }

    #[test]
    fn occupancy_is_scaled_from_min_zero_to_max() {
        let s = OccupancyScale::of(&[0.0, 2.0, 4.0, 1.0]);
        assert_eq!((s.lo, s.hi), (0.0, 4.0));
        assert_eq!(s.value(1.0), 25);
        assert_eq!(s.value(4.0), 100);
        let neg = OccupancyScale::of(&[-1.0, 1.0]);
        assert_eq!(neg.value(0.0), 50);
        assert_eq!(OccupancyScale::of(&[0.0, 0.0]).value(0.0), 0);
        let cells: Vec<f32> = (0..12).map(|v| v as f32).collect();
        let frame_mode = Occupancy {
            mode: OccupancyMode::Frame,
            ..Occupancy::default()
        };
        let (b, scale) = occupancy_grid_cdr(&frame(&cells), 1, &frame_mode);
        assert_eq!((scale.lo, scale.hi), (0.0, 11.0));
        let tail = &b[b.len() - 6..];
        let want: Vec<u8> = (6..12)
            .map(|v| (100.0 * v as f32 / 11.0).round() as u8)
            .collect();
        assert_eq!(tail, &want[..]);
        let n = u32::from_le_bytes(b[b.len() - 10..b.len() - 6].try_into().unwrap());
        assert_eq!(n, 6);
    }

    #[test]
    fn occupancy_rounds_as_f32_round_does_at_every_half() {
        // The scale's own rounding (no libm call) against `f32::round`: every value whose
        // scaled t lies within a few ulps of a k + 0.5 boundary, and a sweep of the range.
        let linear = Occupancy {
            max: 3.7,
            min: -0.2,
            ..Occupancy::default()
        };
        let s = OccupancyScale::new(&linear, &[]);
        let reference = |v: f32| {
            let span = s.hi - s.lo;
            (100.0 * (v - s.lo) / span).round().clamp(0.0, 100.0) as i8
        };
        let mut checked = 0;
        for k in -2..=102 {
            let at = s.lo + (k as f32 + 0.5) / 100.0 * (s.hi - s.lo);
            let mut v = at;
            for _ in 0..64 {
                v = f32::from_bits(v.to_bits() - 1);
            }
            for _ in 0..128 {
                assert_eq!(s.value(v), reference(v), "v = {v:e}");
                v = f32::from_bits(v.to_bits() + 1);
                checked += 1;
            }
        }
        for i in 0..100_000 {
            let v = -1.0 + 6.0 * i as f32 / 100_000.0;
            assert_eq!(s.value(v), reference(v), "v = {v:e}");
            checked += 1;
        }
        assert!(checked > 100_000);
        // `fill` (the loop the node runs) equals `value` cell by cell, in every mode.
        let mut plane: Vec<f32> = (0..20_000)
            .map(|i| -1.0 + 6.0 * i as f32 / 20_000.0)
            .collect();
        plane.extend([f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0, 3.7, -0.2]);
        let mut out = vec![0u8; plane.len()];
        for o in [
            linear,
            Occupancy {
                trail_free: true,
                unknown_below: Some(0.1),
                ..linear
            },
            Occupancy {
                mode: OccupancyMode::Binary,
                ..linear
            },
            Occupancy {
                mode: OccupancyMode::Frame,
                ..linear
            },
        ] {
            let s = OccupancyScale::new(&o, &plane);
            s.fill(&plane, &mut out);
            for (v, got) in plane.iter().zip(&out) {
                assert_eq!(*got as i8, s.value(*v), "{o:?}: v = {v:e}");
            }
        }
    }

    #[test]
    fn fixed_scales_invert_and_mark_missing_data() {
        let linear = Occupancy {
            max: 2.0,
            ..Occupancy::default()
        };
        let plane = [0.0, 0.5, 1.0, 4.0, -1.0, f32::NAN];
        let s = OccupancyScale::new(&linear, &plane);
        let got: Vec<i8> = plane.iter().map(|&v| s.value(v)).collect();
        assert_eq!(got, [0, 25, 50, 100, 0, -1]);
        // The same value, the same occupancy, whatever else the frame holds.
        assert_eq!(OccupancyScale::new(&linear, &[0.5, 100.0]).value(0.5), 25);
        let free = Occupancy {
            trail_free: true,
            unknown_below: Some(1e-3),
            ..linear
        };
        let s = OccupancyScale::new(&free, &plane);
        let got: Vec<i8> = plane.iter().map(|&v| s.value(v)).collect();
        assert_eq!(got, [-1, 75, 50, 0, -1, -1]);
        let binary = Occupancy {
            mode: OccupancyMode::Binary,
            max: 1.0,
            ..Occupancy::default()
        };
        let s = OccupancyScale::new(&binary, &plane);
        let got: Vec<i8> = plane.iter().map(|&v| s.value(v)).collect();
        assert_eq!(got, [0, 0, 100, 100, 0, -1]);
        assert_eq!(
            OccupancyMode::from_name("frame"),
            Some(OccupancyMode::Frame)
        );
        assert_eq!(OccupancyMode::from_name("log"), None);
    }
}
