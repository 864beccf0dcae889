//! Grid geometry: size, cell size, origin and the transforms between world metres and cells.
//!
//! Cells are stored as channel planes, each row-major: index = `channel·W·H + y·W + x`.
//! Cell `(x, y)` covers `[origin_x + x·h, origin_x + (x+1)·h) × [origin_y + y·h, …)`; its centre is
//! at `origin + (x + ½, y + ½)·h`.

use serde::{Deserialize, Serialize};

use crate::error::ConfigError;

/// Largest width or height accepted, in cells (a 65536² single-channel grid is 16 GiB).
pub const MAX_SIDE_CELLS: u32 = 65_536;

/// The grid of a field: its size in cells, the side of a (square) cell and where its corner
/// sits in the world frame. Every plane of every channel uses it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridGeometry {
    /// Cells along x (1 to [`MAX_SIDE_CELLS`]).
    pub width: u32,
    /// Cells along y (1 to [`MAX_SIDE_CELLS`]).
    pub height: u32,
    /// Side h of a square cell (m, finite and > 0).
    pub cell_size_m: f32,
    /// World x of the grid's lower-left corner, the left edge of column 0 (m, default 0).
    #[serde(default)]
    pub origin_x_m: f32,
    /// World y of the grid's lower-left corner, the lower edge of row 0 (m, default 0).
    #[serde(default)]
    pub origin_y_m: f32,
}

impl GridGeometry {
    /// A `width × height` grid of `cell_size_m` cells with its corner at the world origin;
    /// fails as [`GridGeometry::validate`] does.
    pub fn new(width: u32, height: u32, cell_size_m: f32) -> Result<Self, ConfigError> {
        let g = Self {
            width,
            height,
            cell_size_m,
            origin_x_m: 0.0,
            origin_y_m: 0.0,
        };
        g.validate()?;
        Ok(g)
    }

    /// The same grid with its lower-left corner moved to (`origin_x_m`, `origin_y_m`) (m);
    /// fails if the origin is not finite.
    pub fn with_origin(mut self, origin_x_m: f32, origin_y_m: f32) -> Result<Self, ConfigError> {
        self.origin_x_m = origin_x_m;
        self.origin_y_m = origin_y_m;
        self.validate()?;
        Ok(self)
    }

    /// Checks the sizes (1 to [`MAX_SIDE_CELLS`] cells per side), that the cell size is finite
    /// and > 0 and that the origin is finite; the error names the first setting that fails.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (name, v) in [("width", self.width), ("height", self.height)] {
            if v == 0 || v > MAX_SIDE_CELLS {
                return Err(ConfigError::invalid(
                    name,
                    v,
                    format!("must be between 1 and {MAX_SIDE_CELLS} cells"),
                ));
            }
        }
        if !(self.cell_size_m.is_finite() && self.cell_size_m > 0.0) {
            return Err(ConfigError::invalid(
                "cell_size_m",
                self.cell_size_m,
                "must be a finite number of metres > 0",
            ));
        }
        for (name, v) in [
            ("origin_x_m", self.origin_x_m),
            ("origin_y_m", self.origin_y_m),
        ] {
            if !v.is_finite() {
                return Err(ConfigError::invalid(name, v, "must be finite"));
            }
        }
        Ok(())
    }

    /// Cells per plane.
    pub fn cells(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Extent of the grid along x (m): `width · cell_size_m`.
    pub fn width_m(&self) -> f32 {
        self.width as f32 * self.cell_size_m
    }

    /// Extent of the grid along y (m): `height · cell_size_m`.
    pub fn height_m(&self) -> f32 {
        self.height as f32 * self.cell_size_m
    }

    /// Continuous grid coordinates (cell units, cell centres at `i + 0.5`) of a world point.
    pub fn grid_from_world(&self, x_m: f32, y_m: f32) -> (f32, f32) {
        (
            (x_m - self.origin_x_m) / self.cell_size_m,
            (y_m - self.origin_y_m) / self.cell_size_m,
        )
    }

    /// World position of the centre of cell `(x, y)`.
    pub fn world_from_grid(&self, x: u32, y: u32) -> (f32, f32) {
        (
            self.origin_x_m + (x as f32 + 0.5) * self.cell_size_m,
            self.origin_y_m + (y as f32 + 0.5) * self.cell_size_m,
        )
    }

    /// The cell that contains a world point, if it is inside the grid.
    pub fn cell_at(&self, x_m: f32, y_m: f32) -> Option<(u32, u32)> {
        let (gx, gy) = self.grid_from_world(x_m, y_m);
        if gx >= 0.0 && gy >= 0.0 && (gx as u32) < self.width && (gy as u32) < self.height {
            Some((gx as u32, gy as u32))
        } else {
            None
        }
    }

    /// Index of cell `(x, y)` within a plane.
    #[inline]
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }

    /// Inclusive cell range `[x0, x1] × [y0, y1]` of cells whose centres may lie within
    /// `radius_m` of a world point, clipped to the grid; `None` if it misses the grid.
    pub fn cell_box(&self, x_m: f32, y_m: f32, radius_m: f32) -> Option<CellBox> {
        let (gx, gy) = self.grid_from_world(x_m, y_m);
        let r = radius_m / self.cell_size_m;
        let x0 = (gx - r - 0.5).floor().max(0.0);
        let y0 = (gy - r - 0.5).floor().max(0.0);
        let x1 = (gx + r - 0.5).ceil().min(self.width as f32 - 1.0);
        let y1 = (gy + r - 0.5).ceil().min(self.height as f32 - 1.0);
        if !(x0 <= x1 && y0 <= y1) {
            return None;
        }
        Some(CellBox {
            x0: x0 as u32,
            y0: y0 as u32,
            x1: x1 as u32,
            y1: y1 as u32,
        })
    }
}

/// An inclusive rectangle of cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellBox {
    /// First column (inclusive), ≤ `x1`.
    pub x0: u32,
    /// First row (inclusive), ≤ `y1`.
    pub y0: u32,
    /// Last column (inclusive).
    pub x1: u32,
    /// Last row (inclusive).
    pub y1: u32,
}

impl CellBox {
    /// Number of cells in the box.
    pub fn cells(&self) -> usize {
        (self.x1 - self.x0 + 1) as usize * (self.y1 - self.y0 + 1) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn world_and_grid_round_trip() {
        let g = GridGeometry::new(100, 50, 0.1)
            .unwrap()
            .with_origin(-5.0, 2.0)
            .unwrap();
        let (wx, wy) = g.world_from_grid(10, 20);
        assert_relative_eq!(wx, -5.0 + 1.05, epsilon = 1e-5);
        assert_relative_eq!(wy, 2.0 + 2.05, epsilon = 1e-5);
        assert_eq!(g.cell_at(wx, wy), Some((10, 20)));
        assert_eq!(g.cell_at(-5.01, 2.5), None);
        assert_eq!(g.cell_at(5.0, 2.5), None);
    }

    #[test]
    fn bad_sizes_are_refused_with_the_field_name() {
        let e = GridGeometry::new(0, 10, 0.1).unwrap_err().to_string();
        assert!(e.contains("width") && e.contains('0'), "{e}");
        let e = GridGeometry::new(10, 10, f32::NAN).unwrap_err().to_string();
        assert!(e.contains("cell_size_m"), "{e}");
    }

    #[test]
    fn cell_box_clips_to_the_grid() {
        let g = GridGeometry::new(10, 10, 1.0).unwrap();
        // Centres within 1 m of (0.5, 0.5): cells 0 and 1 on each axis.
        let b = g.cell_box(0.5, 0.5, 1.0).unwrap();
        assert_eq!((b.x0, b.y0, b.x1, b.y1), (0, 0, 1, 1));
        assert!(g.cell_box(-50.0, 0.5, 1.0).is_none());
    }
}
