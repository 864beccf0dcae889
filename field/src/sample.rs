//! Reading the field: bilinear value, gradient, the two virtual antennas (seed 002, MODELS.md M3)
//! and IAS-SS sector means (seed 004, MODELS.md M4). Works on any borrowed frame — a shared-memory
//! sample or an owned buffer.

use crate::geometry::GridGeometry;

/// A read-only view of a frame: geometry, channel count and the planes (`channel, y, x`).
///
/// A [`FieldReader`](crate::shm::FieldReader) lends one for each frame (`reader.frame()?.view`,
/// see its example); any buffer of the right length is one too:
///
/// ```
/// use pheromone_field::{FrameView, GridGeometry, SamplePose};
///
/// // 4 × 4 cells of 0.5 m, one channel; cell (2, 1), centred at (1.25 m, 0.75 m), holds 1.
/// let geometry = GridGeometry::new(4, 4, 0.5).unwrap();
/// let mut cells = vec![0.0f32; geometry.cells()];
/// cells[geometry.index(2, 1)] = 1.0;
/// let view = FrameView::new(geometry, 1, &cells);
///
/// assert_eq!(view.value(0, 1.25, 0.75), 1.0);
/// // Half-way between two cell centres, bilinear.
/// assert_eq!(view.value(0, 1.0, 0.75), 0.5);
/// // Uphill toward the cell along +x.
/// assert_eq!(view.gradient(0, 0.75, 0.75), (1.0, 0.0));
/// // A robot at (1.25 m, 0.5 m) heading +x with a 0.5 m wheel base: the cell is on its left.
/// let (left, right) = view.antennas(0, SamplePose::new(1.25, 0.5, 0.0), 0.5);
/// assert!(left > right);
/// ```
#[derive(Debug, Clone, Copy)]
pub struct FrameView<'a> {
    /// The grid every plane is laid out on.
    pub geometry: GridGeometry,
    /// Number of channel planes in `cells`.
    pub channels: usize,
    /// All planes, channel after channel, each row-major: `channels · geometry.cells()` values.
    pub cells: &'a [f32],
}

/// A planar pose: position (m) and heading θ (rad, counter-clockwise from +x).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SamplePose {
    /// x position in the world frame (m).
    pub x_m: f32,
    /// y position in the world frame (m).
    pub y_m: f32,
    /// Heading (rad, counter-clockwise from +x).
    pub theta_rad: f32,
}

impl SamplePose {
    /// A pose from its coordinates (m, m, rad).
    pub fn new(x_m: f32, y_m: f32, theta_rad: f32) -> Self {
        Self {
            x_m,
            y_m,
            theta_rad,
        }
    }
}

impl<'a> FrameView<'a> {
    /// A view of `cells` as `channels` planes of `geometry`.
    ///
    /// # Panics
    ///
    /// If `cells.len()` is not `channels · geometry.cells()`.
    pub fn new(geometry: GridGeometry, channels: usize, cells: &'a [f32]) -> Self {
        assert_eq!(
            cells.len(),
            channels * geometry.cells(),
            "frame length does not match its geometry"
        );
        Self {
            geometry,
            channels,
            cells,
        }
    }

    /// One channel's plane.
    pub fn plane(&self, channel: usize) -> &'a [f32] {
        let n = self.geometry.cells();
        &self.cells[channel * n..(channel + 1) * n]
    }

    /// Value of cell `(x, y)`.
    pub fn cell(&self, channel: usize, x: u32, y: u32) -> f32 {
        self.plane(channel)[self.geometry.index(x, y)]
    }

    /// Bilinear interpolation between cell centres; 0 outside the grid, edge cells extend to the
    /// border.
    pub fn value(&self, channel: usize, x_m: f32, y_m: f32) -> f32 {
        let g = &self.geometry;
        let (gx, gy) = g.grid_from_world(x_m, y_m);
        if !(gx >= 0.0 && gy >= 0.0 && gx <= g.width as f32 && gy <= g.height as f32) {
            return 0.0;
        }
        let fx = (gx - 0.5).clamp(0.0, (g.width - 1) as f32);
        let fy = (gy - 0.5).clamp(0.0, (g.height - 1) as f32);
        let (x0, y0) = (fx.floor() as u32, fy.floor() as u32);
        let (x1, y1) = ((x0 + 1).min(g.width - 1), (y0 + 1).min(g.height - 1));
        let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
        let p = self.plane(channel);
        let v = |x, y| p[g.index(x, y)];
        let top = v(x0, y0) * (1.0 - tx) + v(x1, y0) * tx;
        let bottom = v(x0, y1) * (1.0 - tx) + v(x1, y1) * tx;
        top * (1.0 - ty) + bottom * ty
    }

    /// ∇P (per metre) by central differences of the bilinear value one cell apart
    /// (seed 000 eqs. 15–16).
    pub fn gradient(&self, channel: usize, x_m: f32, y_m: f32) -> (f32, f32) {
        let h = self.geometry.cell_size_m;
        let gx =
            (self.value(channel, x_m + h, y_m) - self.value(channel, x_m - h, y_m)) / (2.0 * h);
        let gy =
            (self.value(channel, x_m, y_m + h) - self.value(channel, x_m, y_m - h)) / (2.0 * h);
        (gx, gy)
    }

    /// Readings `(P_L, P_R)` of two antennas half a wheel base to each side of the pose
    /// (MODELS.md M3: left = μ + (b/2)(−sin θ, cos θ), right = μ − (b/2)(−sin θ, cos θ)).
    pub fn antennas(&self, channel: usize, pose: SamplePose, wheel_base_m: f32) -> (f32, f32) {
        let (l, r) = antenna_points(pose, wheel_base_m);
        (self.value(channel, l.0, l.1), self.value(channel, r.0, r.1))
    }

    /// Mean pheromone τ_s in each of `2·half_sectors + 1` equal sectors spanning [−90°, 90°]
    /// around the heading, over the half-disc of radius `radius_m` (seed 004, sensing at R_D).
    /// Sector 0 is the rightmost (−90°), the last the leftmost (+90°). Samples are spaced about
    /// one cell apart (at most 64 radially and 64 across a sector).
    pub fn sector_means(
        &self,
        channel: usize,
        pose: SamplePose,
        radius_m: f32,
        half_sectors: usize,
    ) -> Vec<f32> {
        let mut out = vec![0.0; 2 * half_sectors + 1];
        self.sector_means_into(channel, pose, radius_m, &mut out);
        out
    }

    /// [`sector_means`](Self::sector_means) into `out`, one mean per sector (`out.len()` of
    /// them, odd: `2·half_sectors + 1`), without allocating (the C ABI's sampling).
    pub fn sector_means_into(
        &self,
        channel: usize,
        pose: SamplePose,
        radius_m: f32,
        out: &mut [f32],
    ) {
        let n = out.len();
        let width = std::f32::consts::PI / n as f32;
        let h = self.geometry.cell_size_m;
        let radial = ((radius_m / h).ceil() as usize).clamp(1, 64);
        for (s, mean) in out.iter_mut().enumerate() {
            let a0 = pose.theta_rad - std::f32::consts::FRAC_PI_2 + s as f32 * width;
            let mut sum = 0.0f64;
            let mut count = 0usize;
            for i in 0..radial {
                let r = radius_m * (i as f32 + 0.5) / radial as f32;
                let across = ((r * width / h).ceil() as usize).clamp(1, 64);
                for j in 0..across {
                    let a = a0 + width * (j as f32 + 0.5) / across as f32;
                    sum +=
                        self.value(channel, pose.x_m + r * a.cos(), pose.y_m + r * a.sin()) as f64;
                    count += 1;
                }
            }
            *mean = (sum / count as f64) as f32;
        }
    }

    /// Sum of a channel's cells.
    pub fn total(&self, channel: usize) -> f64 {
        self.plane(channel).iter().map(|&v| v as f64).sum()
    }

    /// Largest cell of a channel.
    pub fn max(&self, channel: usize) -> f32 {
        self.plane(channel)
            .iter()
            .copied()
            .fold(f32::NEG_INFINITY, f32::max)
    }

    /// Number of cells (all channels) that are NaN or infinite.
    pub fn non_finite_cells(&self) -> usize {
        self.cells.iter().filter(|v| !v.is_finite()).count()
    }
}

/// World positions of the left and right antenna (MODELS.md M3 convention).
pub fn antenna_points(pose: SamplePose, wheel_base_m: f32) -> ((f32, f32), (f32, f32)) {
    let half = 0.5 * wheel_base_m;
    let (s, c) = pose.theta_rad.sin_cos();
    let (ox, oy) = (-s * half, c * half);
    (
        (pose.x_m + ox, pose.y_m + oy),
        (pose.x_m - ox, pose.y_m - oy),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn ramp() -> (GridGeometry, Vec<f32>) {
        let g = GridGeometry::new(20, 10, 0.5).unwrap();
        // P = 2·x_m + 3·y_m at cell centres.
        let mut cells = vec![0.0; g.cells()];
        for y in 0..10 {
            for x in 0..20 {
                let (wx, wy) = g.world_from_grid(x, y);
                cells[g.index(x, y)] = 2.0 * wx + 3.0 * wy;
            }
        }
        (g, cells)
    }

    #[test]
    fn bilinear_reproduces_a_plane_and_its_gradient() {
        let (g, cells) = ramp();
        let f = FrameView::new(g, 1, &cells);
        assert_relative_eq!(f.value(0, 3.3, 2.1), 2.0 * 3.3 + 3.0 * 2.1, epsilon = 1e-4);
        let (gx, gy) = f.gradient(0, 4.0, 2.5);
        assert_relative_eq!(gx, 2.0, epsilon = 1e-3);
        assert_relative_eq!(gy, 3.0, epsilon = 1e-3);
        assert_eq!(f.value(0, -1.0, 2.0), 0.0);
    }

    #[test]
    fn antennas_sit_left_and_right_of_the_heading() {
        // Heading +y: left is −x, right is +x.
        let ((lx, ly), (rx, ry)) =
            antenna_points(SamplePose::new(1.0, 1.0, std::f32::consts::FRAC_PI_2), 0.4);
        assert_relative_eq!(lx, 0.8, epsilon = 1e-6);
        assert_relative_eq!(ly, 1.0, epsilon = 1e-6);
        assert_relative_eq!(rx, 1.2, epsilon = 1e-6);
        assert_relative_eq!(ry, 1.0, epsilon = 1e-6);
        let (g, cells) = ramp();
        let f = FrameView::new(g, 1, &cells);
        let (pl, pr) = f.antennas(
            0,
            SamplePose::new(5.0, 2.5, std::f32::consts::FRAC_PI_2),
            0.4,
        );
        assert!(
            pr > pl,
            "field grows with x, so the right antenna (+x) reads more"
        );
    }

    #[test]
    fn sectors_see_the_side_with_pheromone() {
        let g = GridGeometry::new(40, 40, 0.25).unwrap();
        let mut cells = vec![0.0; g.cells()];
        // Pheromone everywhere with y > 5 m (left of a robot at (5,5) heading +x).
        for y in 0..40 {
            for x in 0..40 {
                if g.world_from_grid(x, y).1 > 5.0 {
                    cells[g.index(x, y)] = 1.0;
                }
            }
        }
        let f = FrameView::new(g, 1, &cells);
        let s = f.sector_means(0, SamplePose::new(5.0, 5.0, 0.0), 2.0, 2);
        assert_eq!(s.len(), 5);
        assert!(s[0] < 0.05 && s[1] < 0.05, "{s:?}");
        assert!(s[3] > 0.9 && s[4] > 0.9, "{s:?}");
    }
}
