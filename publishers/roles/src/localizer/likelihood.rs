//! The likelihood field of the particle filter's laser model (Thrun et al., Probabilistic
//! Robotics §6.4): a precomputed grid of the distance from each cell centre to the nearest wall
//! segment, capped at `cap_m`.

use super::{invalid, LocalizerError};
use pheromone_messages::Segment;

/// Most cells a grid may have.
pub const MAX_GRID_CELLS: usize = 16_000_000;

/// Distance to the nearest wall on a grid (row-major, cell (0, 0) at `origin_m`).
#[derive(Debug, Clone)]
pub struct DistanceGrid {
    origin_m: [f64; 2],
    cell_m: f64,
    width: usize,
    height: usize,
    cap_m: f64,
    dist_m: Vec<f32>,
}

fn point_segment_distance(p: [f64; 2], s: &Segment) -> f64 {
    let (ax, ay) = (s.a_m[0], s.a_m[1]);
    let (dx, dy) = (s.b_m[0] - ax, s.b_m[1] - ay);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - ax) * dx + (p[1] - ay) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - ax - t * dx).hypot(p[1] - ay - t * dy)
}

impl DistanceGrid {
    /// The grid over the walls' bounding box grown by `margin_m`, cells of `cell_m`, distances
    /// capped at `cap_m` (each segment updates only the cells within `cap_m` of it).
    pub fn new(
        segments: &[Segment],
        margin_m: f64,
        cell_m: f64,
        cap_m: f64,
    ) -> Result<Self, LocalizerError> {
        if !(cell_m.is_finite() && cell_m > 0.0) {
            return Err(invalid("pf.grid_cell_m", cell_m, "finite and > 0"));
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for s in segments {
            for p in [s.a_m, s.b_m] {
                for k in 0..2 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        if segments.is_empty() {
            (lo, hi) = ([0.0; 2], [0.0; 2]);
        }
        let origin_m = [lo[0] - margin_m, lo[1] - margin_m];
        let width = ((hi[0] - lo[0] + 2.0 * margin_m) / cell_m).ceil() as usize + 1;
        let height = ((hi[1] - lo[1] + 2.0 * margin_m) / cell_m).ceil() as usize + 1;
        if width.saturating_mul(height) > MAX_GRID_CELLS {
            return Err(invalid(
                "pf.grid_cell_m",
                cell_m,
                "coarse enough for at most 16 million cells over the walls",
            ));
        }
        let mut grid = Self {
            origin_m,
            cell_m,
            width,
            height,
            cap_m,
            dist_m: vec![cap_m as f32; width * height],
        };
        for s in segments {
            grid.stamp(s);
        }
        Ok(grid)
    }

    fn stamp(&mut self, s: &Segment) {
        let cell = |v: f64, o: f64, n: usize| {
            (((v - o) / self.cell_m).floor().max(0.0) as usize).min(n - 1)
        };
        let (x0, x1) = (
            s.a_m[0].min(s.b_m[0]) - self.cap_m,
            s.a_m[0].max(s.b_m[0]) + self.cap_m,
        );
        let (y0, y1) = (
            s.a_m[1].min(s.b_m[1]) - self.cap_m,
            s.a_m[1].max(s.b_m[1]) + self.cap_m,
        );
        let (i0, i1) = (
            cell(x0, self.origin_m[0], self.width),
            cell(x1, self.origin_m[0], self.width),
        );
        let (j0, j1) = (
            cell(y0, self.origin_m[1], self.height),
            cell(y1, self.origin_m[1], self.height),
        );
        for j in j0..=j1 {
            for i in i0..=i1 {
                let c = [
                    self.origin_m[0] + (i as f64 + 0.5) * self.cell_m,
                    self.origin_m[1] + (j as f64 + 0.5) * self.cell_m,
                ];
                let d = point_segment_distance(c, s).min(self.cap_m) as f32;
                let slot = &mut self.dist_m[j * self.width + i];
                *slot = slot.min(d);
            }
        }
    }

    /// Distance (m) from the point to the nearest wall, by its cell; `cap_m` outside the grid.
    #[inline]
    pub fn distance_m(&self, x_m: f64, y_m: f64) -> f64 {
        let fx = (x_m - self.origin_m[0]) / self.cell_m;
        let fy = (y_m - self.origin_m[1]) / self.cell_m;
        if !(fx >= 0.0 && fy >= 0.0) {
            return self.cap_m;
        }
        let (i, j) = (fx as usize, fy as usize);
        if i >= self.width || j >= self.height {
            return self.cap_m;
        }
        f64::from(self.dist_m[j * self.width + i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_are_to_the_nearest_segment_within_a_cell_and_capped() {
        let segs = [
            Segment {
                a_m: [0.0, 0.0],
                b_m: [4.0, 0.0],
            },
            Segment {
                a_m: [4.0, 0.0],
                b_m: [4.0, 3.0],
            },
        ];
        let g = DistanceGrid::new(&segs, 1.0, 0.05, 2.0).unwrap();
        let half_diag = 0.05 * std::f64::consts::SQRT_2 / 2.0;
        for (p, want) in [
            ([1.0, 0.5], 0.5),
            ([3.8, 1.0], 0.2),
            ([-0.6, 0.0], 0.6),
            ([2.0, 2.9], 2.0), // 2.9 from the first, 2.0 from the second
            ([1.0, 2.9], 2.0), // capped
        ] {
            let d = g.distance_m(p[0], p[1]);
            assert!((d - want).abs() <= half_diag + 1e-6, "{p:?}: {d} vs {want}");
        }
        assert_eq!(g.distance_m(100.0, 0.0), 2.0);
        assert_eq!(g.distance_m(f64::NAN, 0.0), 2.0);
        assert!(DistanceGrid::new(&segs, 1.0, 0.0, 2.0).is_err());
        assert!(DistanceGrid::new(&segs, 1e4, 1e-3, 2.0).is_err());
    }
}
