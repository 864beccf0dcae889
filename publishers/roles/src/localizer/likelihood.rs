//! The likelihood field of the particle filter's laser model (Thrun et al., Probabilistic
//! Robotics §6.4): a precomputed grid of the distance from each cell centre to the nearest wall
//! segment, capped at `cap_m`; and the free space (issue 48 part 4): the cells reachable from
//! the filter's start without crossing a wall ([`DistanceGrid::mark_free_from`]), and whether a
//! beam's path from a pose crosses no wall ([`DistanceGrid::ray_clear`], exact against the
//! segments). An end-point model
//! alone scores a pose shifted by a corridor's width as well as the truth (each end point lands
//! on *a* wall); these checks reject a pose inside solid building and one whose beams would
//! have passed through a wall.

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
    /// A wall runs within one cell of the cell's centre (any 4-connected step across a
    /// segment lands in such a cell, so they close off what a wall closes off).
    wall: Vec<bool>,
    /// Reachable from the seed of [`DistanceGrid::mark_free_from`] (all true before).
    free: Vec<bool>,
    /// Whether the space beyond the grid is reachable (the seed's region touches the border).
    outside_free: bool,
    /// The walls, and each one's bounding box [min x, min y, max x, max y].
    segments: Vec<Segment>,
    boxes: Vec<[f64; 4]>,
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
            wall: vec![false; width * height],
            free: vec![true; width * height],
            outside_free: true,
            segments: segments.to_vec(),
            boxes: segments
                .iter()
                .map(|s| {
                    [
                        s.a_m[0].min(s.b_m[0]),
                        s.a_m[1].min(s.b_m[1]),
                        s.a_m[0].max(s.b_m[0]),
                        s.a_m[1].max(s.b_m[1]),
                    ]
                })
                .collect(),
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
        let reach = self.cap_m.max(2.0 * self.cell_m);
        let (x0, x1) = (
            s.a_m[0].min(s.b_m[0]) - reach,
            s.a_m[0].max(s.b_m[0]) + reach,
        );
        let (y0, y1) = (
            s.a_m[1].min(s.b_m[1]) - reach,
            s.a_m[1].max(s.b_m[1]) + reach,
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
                let raw = point_segment_distance(c, s);
                let k = j * self.width + i;
                self.dist_m[k] = self.dist_m[k].min(raw.min(self.cap_m) as f32);
                self.wall[k] |= raw <= self.cell_m;
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

    /// The cell of a point, if it lies on the grid.
    #[inline]
    fn cell_of(&self, x_m: f64, y_m: f64) -> Option<usize> {
        let fx = (x_m - self.origin_m[0]) / self.cell_m;
        let fy = (y_m - self.origin_m[1]) / self.cell_m;
        if !(fx >= 0.0 && fy >= 0.0) {
            return None;
        }
        let (i, j) = (fx as usize, fy as usize);
        (i < self.width && j < self.height).then_some(j * self.width + i)
    }

    /// Restricts the free space to the cells reachable from (`x_m`, `y_m`) by 4-connected steps
    /// through cells without a wall (a flood fill). Beyond the grid counts as free only if the
    /// fill reaches the grid's border. A seed on a wall cell or off the grid leaves everything
    /// free (nothing to fill from).
    pub fn mark_free_from(&mut self, x_m: f64, y_m: f64) {
        let Some(seed) = self.cell_of(x_m, y_m).filter(|&k| !self.wall[k]) else {
            return;
        };
        let (w, h) = (self.width, self.height);
        let mut free = vec![false; w * h];
        let mut stack = vec![seed];
        free[seed] = true;
        let mut border = false;
        while let Some(k) = stack.pop() {
            let (i, j) = (k % w, k / w);
            border |= i == 0 || j == 0 || i + 1 == w || j + 1 == h;
            let next = [
                (i > 0).then(|| k - 1),
                (i + 1 < w).then(|| k + 1),
                (j > 0).then(|| k - w),
                (j + 1 < h).then(|| k + w),
            ];
            for n in next.into_iter().flatten() {
                if !free[n] && !self.wall[n] {
                    free[n] = true;
                    stack.push(n);
                }
            }
        }
        self.free = free;
        self.outside_free = border;
    }

    /// The point lies in free space: not on a wall cell, and reachable from the seed of
    /// [`DistanceGrid::mark_free_from`] (never inside solid building or a closed-off room).
    #[inline]
    pub fn is_free(&self, x_m: f64, y_m: f64) -> bool {
        match self.cell_of(x_m, y_m) {
            Some(k) => self.free[k] && !self.wall[k],
            None => self.outside_free && x_m.is_finite() && y_m.is_finite(),
        }
    }

    /// No wall crosses the ray from (`x_m`, `y_m`) along `angle_rad` over `length_m`: an exact
    /// ray–segment test against the walls whose bounding box meets the ray's. A crossing
    /// within `CORNER_TOLERANCE_M` of a segment's end does not count: a beam that grazes a
    /// corner (where two walls meet, or a door post) may pass on either side of it within the
    /// laser's noise, and the true pose must not pay for it.
    pub fn ray_clear(&self, x_m: f64, y_m: f64, angle_rad: f64, length_m: f64) -> bool {
        let (s, c) = angle_rad.sin_cos();
        let (dx, dy) = (c * length_m, s * length_m);
        let (bx0, bx1) = (x_m.min(x_m + dx), x_m.max(x_m + dx));
        let (by0, by1) = (y_m.min(y_m + dy), y_m.max(y_m + dy));
        for (seg, bb) in self.segments.iter().zip(&self.boxes) {
            if bb[2] < bx0 || bb[0] > bx1 || bb[3] < by0 || bb[1] > by1 {
                continue;
            }
            let (ex, ey) = (seg.b_m[0] - seg.a_m[0], seg.b_m[1] - seg.a_m[1]);
            let denom = dx * ey - dy * ex;
            if denom == 0.0 {
                continue; // parallel: a beam along a wall does not pass through it
            }
            let (wx, wy) = (seg.a_m[0] - x_m, seg.a_m[1] - y_m);
            let t = (wx * ey - wy * ex) / denom;
            let u = (wx * dy - wy * dx) / denom;
            let len = ex.hypot(ey);
            let tol = (CORNER_TOLERANCE_M / len).min(0.5);
            if (0.0..=1.0).contains(&t) && u >= tol && u <= 1.0 - tol {
                return false;
            }
        }
        true
    }
}

/// A beam crossing a wall this close to the wall's end (m) is not counted as passing through.
pub const CORNER_TOLERANCE_M: f64 = 0.1;

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

    fn rect(min: [f64; 2], max: [f64; 2]) -> Vec<Segment> {
        let c = [min, [max[0], min[1]], max, [min[0], max[1]]];
        (0..4)
            .map(|k| Segment {
                a_m: c[k],
                b_m: c[(k + 1) % 4],
            })
            .collect()
    }

    #[test]
    fn the_free_space_is_what_the_start_reaches_and_rays_stop_at_walls() {
        // Two 3 m corridors side by side; the robot starts in the lower one.
        let mut segs = rect([0.0, 0.0], [30.0, 3.0]);
        segs.extend(rect([0.0, 3.0], [30.0, 6.0]));
        let mut g = DistanceGrid::new(&segs, 1.0, 0.05, 0.5).unwrap();
        assert!(g.is_free(10.0, 4.5), "everything is free before a fill");
        g.mark_free_from(10.0, 1.5);
        assert!(g.is_free(10.0, 1.5) && g.is_free(0.2, 0.2) && g.is_free(29.8, 2.8));
        assert!(!g.is_free(10.0, 4.5), "the closed-off corridor");
        assert!(
            !g.is_free(10.0, 3.0) && !g.is_free(10.0, 3.03),
            "on the wall"
        );
        assert!(
            !g.is_free(10.0, -0.5) && !g.is_free(40.0, 1.0),
            "outside the building"
        );
        assert!(!g.is_free(f64::NAN, 1.0));
        // Along the corridor and up to just short of a wall: clear; through a wall: not.
        assert!(g.ray_clear(1.0, 1.5, 0.0, 28.0));
        assert!(g.ray_clear(10.0, 1.5, std::f64::consts::FRAC_PI_2, 1.35));
        assert!(!g.ray_clear(10.0, 1.5, std::f64::consts::FRAC_PI_2, 2.0));
        assert!(
            !g.ray_clear(10.0, 1.5, 0.6, 4.0),
            "a slanted ray through the north wall"
        );
        for k in 0..360 {
            let a = f64::from(k).to_radians();
            // From the centre a wall is 1.5 m off at least, and within 4 m in every direction.
            assert!(g.ray_clear(10.0, 1.5, a, 1.4), "{k}°");
            let cross = (1.5 / a.sin().abs()).min(30.0);
            if cross < 3.9 {
                assert!(!g.ray_clear(10.0, 1.5, a, cross + 0.1), "{k}°");
            }
        }
        // An open building: the fill reaches the border, so beyond the grid is free.
        let mut open = DistanceGrid::new(&segs[..2], 1.0, 0.05, 0.5).unwrap();
        open.mark_free_from(10.0, 1.5);
        assert!(open.is_free(100.0, 100.0) && open.is_free(10.0, -0.5));
    }
}
