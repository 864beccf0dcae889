//! Walls: the [`WallConfig`] of a world (axis-aligned rectangles and polylines), their
//! [`Segment`]s, the segment geometry, and the uniform-grid index that answers the world's
//! queries — a robot's disc touching a wall, a move sweeping into one (no tunnelling through
//! thin walls), a wall hiding a landmark from the sensor.

use serde::{Deserialize, Serialize};

use super::{Segment, WorldError};

/// A wall: an axis-aligned rectangle or a polyline of segments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum WallConfig {
    /// Solid axis-aligned rectangle.
    Rect {
        min_x_m: f64,
        min_y_m: f64,
        max_x_m: f64,
        max_y_m: f64,
    },
    /// Thin wall along consecutive points; `closed` joins the last point to the first.
    Polyline {
        points_m: Vec<[f64; 2]>,
        #[serde(default)]
        closed: bool,
    },
}

/// The segments of `walls` (a rectangle as its four edges); a degenerate or non-finite wall is
/// an error naming its index.
pub fn wall_segments(walls: &[WallConfig]) -> Result<Vec<Segment>, WorldError> {
    let mut segs = Vec::new();
    for (index, wall) in walls.iter().enumerate() {
        match wall {
            WallConfig::Rect {
                min_x_m,
                min_y_m,
                max_x_m,
                max_y_m,
            } => {
                let (x0, y0, x1, y1) = (*min_x_m, *min_y_m, *max_x_m, *max_y_m);
                if ![x0, y0, x1, y1].iter().all(|v| v.is_finite()) {
                    return Err(WorldError::InvalidWall {
                        index,
                        reason: "non-finite corner",
                    });
                }
                if x1 < x0 || y1 < y0 {
                    return Err(WorldError::InvalidWall {
                        index,
                        reason: "max below min",
                    });
                }
                let c = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
                for k in 0..4 {
                    segs.push(Segment {
                        a_m: c[k],
                        b_m: c[(k + 1) % 4],
                    });
                }
            }
            WallConfig::Polyline { points_m, closed } => {
                if points_m.len() < 2 {
                    return Err(WorldError::InvalidWall {
                        index,
                        reason: "a polyline needs at least two points",
                    });
                }
                if !points_m.iter().flatten().all(|v| v.is_finite()) {
                    return Err(WorldError::InvalidWall {
                        index,
                        reason: "non-finite point",
                    });
                }
                for w in points_m.windows(2) {
                    segs.push(Segment {
                        a_m: w[0],
                        b_m: w[1],
                    });
                }
                if *closed && points_m.len() > 2 {
                    segs.push(Segment {
                        a_m: points_m[points_m.len() - 1],
                        b_m: points_m[0],
                    });
                }
            }
        }
    }
    Ok(segs)
}

pub(super) fn inside_rect(walls: &[WallConfig], p: [f64; 2]) -> bool {
    walls.iter().any(|w| match w {
        WallConfig::Rect {
            min_x_m,
            min_y_m,
            max_x_m,
            max_y_m,
        } => p[0] >= *min_x_m && p[0] <= *max_x_m && p[1] >= *min_y_m && p[1] <= *max_y_m,
        WallConfig::Polyline { .. } => false,
    })
}

// ---------------------------------------------------------------------------------------------
// Geometry

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = sub(b, a);
    let len2 = dot(ab, ab);
    let t = if len2 > 0.0 {
        (dot(sub(p, a), ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let q = [a[0] + t * ab[0], a[1] + t * ab[1]];
    let d = sub(p, q);
    d[0].hypot(d[1])
}

/// Parameter t ∈ [0, 1] along p→p2 where it meets q→q2, if the segments properly cross or touch.
pub(super) fn segment_intersection(
    p: [f64; 2],
    p2: [f64; 2],
    q: [f64; 2],
    q2: [f64; 2],
) -> Option<f64> {
    let d = sub(p2, p);
    let e = sub(q2, q);
    let denom = cross(d, e);
    if denom.abs() < 1e-15 {
        return None;
    }
    let qp = sub(q, p);
    let t = cross(qp, e) / denom;
    let u = cross(qp, d) / denom;
    ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then_some(t)
}

fn segment_segment_distance(p: [f64; 2], p2: [f64; 2], q: [f64; 2], q2: [f64; 2]) -> f64 {
    if segment_intersection(p, p2, q, q2).is_some() {
        return 0.0;
    }
    point_segment_distance(p, q, q2)
        .min(point_segment_distance(p2, q, q2))
        .min(point_segment_distance(q, p, p2))
        .min(point_segment_distance(q2, p, p2))
}

/// Wall segments bucketed in a uniform grid so queries cost O(nearby walls).
#[derive(Debug, Clone)]
pub(super) struct SegmentIndex {
    pub(super) segments: Vec<Segment>,
    origin_m: [f64; 2],
    cell_m: f64,
    nx: usize,
    ny: usize,
    cells: Vec<Vec<u32>>,
}

impl SegmentIndex {
    const MAX_CELLS: usize = 1 << 20;

    pub(super) fn new(segments: Vec<Segment>, cell_hint_m: f64) -> Self {
        if segments.is_empty() {
            return Self {
                segments,
                origin_m: [0.0; 2],
                cell_m: 1.0,
                nx: 0,
                ny: 0,
                cells: Vec::new(),
            };
        }
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for s in &segments {
            for p in [s.a_m, s.b_m] {
                for k in 0..2 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        let extent = [(hi[0] - lo[0]).max(1e-9), (hi[1] - lo[1]).max(1e-9)];
        let mut cell_m = cell_hint_m.max(1e-3);
        while (extent[0] / cell_m).ceil() * (extent[1] / cell_m).ceil() > Self::MAX_CELLS as f64 {
            cell_m *= 2.0;
        }
        let nx = ((extent[0] / cell_m).ceil() as usize).max(1);
        let ny = ((extent[1] / cell_m).ceil() as usize).max(1);
        let mut index = Self {
            segments,
            origin_m: lo,
            cell_m,
            nx,
            ny,
            cells: vec![Vec::new(); nx * ny],
        };
        for (k, s) in index.segments.iter().enumerate() {
            let (x0, x1, y0, y1) = index.cell_range(
                [s.a_m[0].min(s.b_m[0]), s.a_m[1].min(s.b_m[1])],
                [s.a_m[0].max(s.b_m[0]), s.a_m[1].max(s.b_m[1])],
            );
            for cy in y0..=y1 {
                for cx in x0..=x1 {
                    index.cells[cy * nx + cx].push(k as u32);
                }
            }
        }
        index
    }

    /// Inclusive cell ranges covering a box (clamped to the grid).
    fn cell_range(&self, lo: [f64; 2], hi: [f64; 2]) -> (usize, usize, usize, usize) {
        let to_cell = |v: f64, o: f64, n: usize| -> usize {
            let c = ((v - o) / self.cell_m).floor();
            if c <= 0.0 {
                0
            } else {
                (c as usize).min(n - 1)
            }
        };
        (
            to_cell(lo[0], self.origin_m[0], self.nx),
            to_cell(hi[0], self.origin_m[0], self.nx),
            to_cell(lo[1], self.origin_m[1], self.ny),
            to_cell(hi[1], self.origin_m[1], self.ny),
        )
    }

    /// Calls `f` on every segment whose cell overlaps the box (a segment may repeat); stops
    /// and returns true as soon as `f` does.
    pub(super) fn any_near(
        &self,
        lo: [f64; 2],
        hi: [f64; 2],
        mut f: impl FnMut(&Segment) -> bool,
    ) -> bool {
        if self.cells.is_empty() {
            return false;
        }
        let grid_hi = [
            self.origin_m[0] + self.nx as f64 * self.cell_m,
            self.origin_m[1] + self.ny as f64 * self.cell_m,
        ];
        if hi[0] < self.origin_m[0]
            || hi[1] < self.origin_m[1]
            || lo[0] > grid_hi[0]
            || lo[1] > grid_hi[1]
        {
            return false;
        }
        let (x0, x1, y0, y1) = self.cell_range(lo, hi);
        for cy in y0..=y1 {
            for cx in x0..=x1 {
                for &k in &self.cells[cy * self.nx + cx] {
                    if f(&self.segments[k as usize]) {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Whether a disc of `radius_m` at `p` overlaps a wall segment.
    pub(super) fn clearance_below(&self, p: [f64; 2], radius_m: f64) -> bool {
        let lo = [p[0] - radius_m, p[1] - radius_m];
        let hi = [p[0] + radius_m, p[1] + radius_m];
        self.any_near(lo, hi, |s| {
            point_segment_distance(p, s.a_m, s.b_m) < radius_m - 1e-9
        })
    }

    /// Whether sweeping a disc of `radius_m` from `p0` to `p1` (the chord of the step's arc)
    /// brings it closer than its radius to a wall it was not already that close to. A robot
    /// touching a wall may still move along it or away from it.
    pub(super) fn blocks_move(&self, p0: [f64; 2], p1: [f64; 2], radius_m: f64) -> bool {
        let lo = [p0[0].min(p1[0]) - radius_m, p0[1].min(p1[1]) - radius_m];
        let hi = [p0[0].max(p1[0]) + radius_m, p0[1].max(p1[1]) + radius_m];
        self.any_near(lo, hi, |s| {
            let d_path = segment_segment_distance(p0, p1, s.a_m, s.b_m);
            d_path < radius_m && d_path < point_segment_distance(p0, s.a_m, s.b_m) - 1e-12
        })
    }

    /// Whether a wall crosses the sight line from `from` to `to` before reaching `to`
    /// (a landmark on a wall's surface stays visible).
    pub(super) fn occludes(&self, from: [f64; 2], to: [f64; 2]) -> bool {
        let len = sub(to, from);
        let len_m = len[0].hypot(len[1]);
        let t_max = 1.0 - 1e-6 / len_m.max(1e-9);
        let lo = [from[0].min(to[0]), from[1].min(to[1])];
        let hi = [from[0].max(to[0]), from[1].max(to[1])];
        self.any_near(lo, hi, |s| {
            segment_intersection(from, to, s.a_m, s.b_m).is_some_and(|t| t < t_max)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::one_robot;
    use crate::{World, WorldPose};
    use approx::assert_relative_eq;
    use std::f64::consts::PI;

    #[test]
    fn wall_blocks_robot() {
        let mut cfg = one_robot(WorldPose::default());
        cfg.walls = vec![
            WallConfig::Rect {
                min_x_m: 1.0,
                min_y_m: -1.0,
                max_x_m: 1.2,
                max_y_m: 1.0,
            },
            WallConfig::Polyline {
                points_m: vec![[-1.0, -1.0], [-1.0, 1.0]],
                closed: false,
            },
        ];
        let mut world = World::new(cfg, 3).unwrap();
        let mut collided = false;
        for _ in 0..50 {
            let out = world.step(&[(1.0, 0.0)]);
            collided |= out[0].truth.collided == 1;
            if out[0].truth.collided == 1 {
                assert_eq!(out[0].sensor.v_m_per_s, 0.0);
            }
        }
        assert!(collided);
        let x = world.poses()[0].x_m;
        assert!(x <= 1.0 - 0.2 + 1e-9, "robot passed the wall: x = {x}");
        assert!(x > 0.6, "robot stopped far from the wall: x = {x}");
        // It can still turn in place (8 × π/8) and drive away, until the thin polyline stops it.
        for _ in 0..8 {
            world.step(&[(0.0, PI / 8.0 / world.config().dt_s)]);
        }
        assert_relative_eq!(world.poses()[0].theta_rad, PI, epsilon = 1e-9);
        for _ in 0..60 {
            world.step(&[(1.0, 0.0)]);
        }
        let x = world.poses()[0].x_m;
        assert!(x >= -1.0 + 0.2 - 1e-9, "robot passed the polyline: x = {x}");
        assert!(x < -0.6, "robot stopped far from the polyline: x = {x}");
        assert!(world.is_free(world.poses()[0].x_m, world.poses()[0].y_m));
    }

    #[test]
    fn fast_robot_does_not_tunnel_through_thin_wall() {
        let mut cfg = one_robot(WorldPose::default());
        cfg.robot_radius_m = 0.05;
        cfg.dt_s = 1.0;
        cfg.walls = vec![WallConfig::Polyline {
            points_m: vec![[0.5, -1.0], [0.5, 1.0]],
            closed: false,
        }];
        let mut world = World::new(cfg, 3).unwrap();
        let out = world.step(&[(2.0, 0.0)]); // would jump to x = 2
        assert_eq!(out[0].truth.collided, 1);
        assert_eq!(world.poses()[0].x_m, 0.0);
    }
}
