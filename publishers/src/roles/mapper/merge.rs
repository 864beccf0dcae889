//! Seed 004's map integration (eqs. 7–10, Algorithm 1): a source map (robot i's, frame Σi) is
//! rotated by θ_ij, translated by d_ij along the bearing α_ji and merged cell by cell into the
//! destination map (robot j's, frame Σj) by averaging.
//!
//! Eqs. 7–10 map a point P of Σi to P* = p_j + d_ij·(cos α_ji, sin α_ji) + R(θ_ij)·(P − p_i),
//! with p_i, p_j the robots' positions in their own frames (the paper's eq. 7 prints
//! y' = x sin θ − y cos θ, which is not a rotation; we read it as + y cos θ). The merge runs
//! over the destination: each destination cell looks up the source cell its centre comes from
//! (the inverse transform, nearest cell), one pass at memory speed.
//!
//! Averaging (our reading, MODELS.md M4): occupancy is averaged in log-odds (the cell's state —
//! free, occupied, unknown — is the paper's probability average's whenever both maps agree, and
//! the pass stays a linear one); a log-odds of exactly 0 (p = 0.5) is *unknown*: a cell unknown
//! in one map takes the other map's occupancy and pheromone, a cell known in both averages
//! both.

use field::{FrameHeader, GridGeometry};

use super::map::{LocalMap, Pose2, MAP_CHANNELS};
use super::MapError;
use crate::messages::PeerObs;

/// A map to merge from: its geometry and both planes, borrowed (a [`LocalMap`] or a map frame
/// in shared memory, zero-copy).
#[derive(Debug, Clone, Copy)]
pub struct MapView<'a> {
    pub geometry: GridGeometry,
    pub occupancy: &'a [f32],
    pub pheromone: &'a [f32],
}

impl<'a> MapView<'a> {
    /// A map frame as published by a mapper: its header must describe exactly `cells`
    /// (`MAP_CHANNELS.len()` planes of width × height, a valid geometry).
    pub fn from_frame(header: &FrameHeader, cells: &'a [f32]) -> Result<Self, MapError> {
        let geometry = GridGeometry {
            width: header.width,
            height: header.height,
            cell_size_m: header.cell_size_m,
            origin_x_m: header.origin_x_m,
            origin_y_m: header.origin_y_m,
        };
        let plane = header.width as usize * header.height as usize;
        if header.channels as usize != MAP_CHANNELS.len()
            || plane.checked_mul(MAP_CHANNELS.len()) != Some(cells.len())
        {
            return Err(MapError::Length {
                channels: header.channels,
                width: header.width,
                height: header.height,
                len: cells.len(),
            });
        }
        geometry.validate().map_err(MapError::Field)?;
        Ok(Self {
            geometry,
            occupancy: &cells[..plane],
            pheromone: &cells[plane..],
        })
    }

    /// The first non-finite cell, as (channel, index, value).
    pub fn first_non_finite(&self) -> Option<(&'static str, usize, f32)> {
        for (name, plane) in MAP_CHANNELS.iter().zip([self.occupancy, self.pheromone]) {
            // One fast pass; the position is looked up only when something is wrong.
            if !plane.iter().all(|v| v.is_finite()) {
                let i = plane.iter().position(|v| !v.is_finite()).expect("found");
                return Some((name, i, plane[i]));
            }
        }
        None
    }

    /// Radius of the smallest disc about the frame's origin that holds the map (m).
    pub fn reach_m(&self) -> f64 {
        reach_m(&self.geometry)
    }
}

fn reach_m(g: &GridGeometry) -> f64 {
    let xs = [g.origin_x_m as f64, (g.origin_x_m + g.width_m()) as f64];
    let ys = [g.origin_y_m as f64, (g.origin_y_m + g.height_m()) as f64];
    xs.iter()
        .flat_map(|x| ys.iter().map(move |y| x.hypot(*y)))
        .fold(0.0, f64::max)
}

/// Eqs. 7–10: Σi (source) → Σj (destination).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MergeTransform {
    /// θ_ij: rotation of Σi relative to Σj.
    pub theta_ij_rad: f64,
    /// d_ij: distance between the robots.
    pub d_ij_m: f64,
    /// α_ji: bearing, in Σj, of robot i seen from robot j.
    pub alpha_ji_rad: f64,
    /// p_i: robot i's position in Σi.
    pub src_robot_m: [f64; 2],
    /// p_j: robot j's position in Σj.
    pub dst_robot_m: [f64; 2],
}

impl MergeTransform {
    /// From a rendezvous: robot j's estimate of itself in Σj (`dst_pose`), robot i's estimate of
    /// itself in Σi (`src_pose`, what i sends with its map) and j's measurement of i (`obs`:
    /// distance, bearing relative to j's heading, i's heading relative to j's).
    pub fn from_measurement(dst_pose: Pose2, src_pose: Pose2, obs: &PeerObs) -> Self {
        Self {
            theta_ij_rad: crate::roles::world::wrap_angle(
                dst_pose[2] + obs.heading_rad - src_pose[2],
            ),
            d_ij_m: obs.range_m,
            alpha_ji_rad: crate::roles::world::wrap_angle(dst_pose[2] + obs.bearing_rad),
            src_robot_m: [src_pose[0], src_pose[1]],
            dst_robot_m: [dst_pose[0], dst_pose[1]],
        }
    }

    /// The exact transform between two frames given their origins in the world.
    pub fn between_frames(src_origin: Pose2, dst_origin: Pose2) -> Self {
        let o = super::map::pose_in_frame(dst_origin, src_origin);
        Self {
            theta_ij_rad: o[2],
            d_ij_m: o[0].hypot(o[1]),
            alpha_ji_rad: o[1].atan2(o[0]),
            src_robot_m: [0.0; 2],
            dst_robot_m: [0.0; 2],
        }
    }

    /// A point of Σi in Σj (eqs. 7–10).
    pub fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.theta_ij_rad.sin_cos();
        let (dx, dy) = (p[0] - self.src_robot_m[0], p[1] - self.src_robot_m[1]);
        let (sa, ca) = self.alpha_ji_rad.sin_cos();
        [
            self.dst_robot_m[0] + self.d_ij_m * ca + c * dx - s * dy,
            self.dst_robot_m[1] + self.d_ij_m * sa + s * dx + c * dy,
        ]
    }

    /// A point of Σj in Σi.
    pub fn inverse(&self, q: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.theta_ij_rad.sin_cos();
        let (sa, ca) = self.alpha_ji_rad.sin_cos();
        let dx = q[0] - self.dst_robot_m[0] - self.d_ij_m * ca;
        let dy = q[1] - self.dst_robot_m[1] - self.d_ij_m * sa;
        [
            self.src_robot_m[0] + c * dx + s * dy,
            self.src_robot_m[1] - s * dx + c * dy,
        ]
    }

    /// How far `p` (of Σi) lands from where `other` puts it (m).
    pub fn displacement_m(&self, other: &MergeTransform, p: [f64; 2]) -> f64 {
        let (a, b) = (self.apply(p), other.apply(p));
        (a[0] - b[0]).hypot(a[1] - b[1])
    }

    /// Refuses a transform that is not finite or places the maps farther apart than their
    /// extents (d_ij beyond both reaches, or a robot outside its own map).
    pub fn validate(&self, src: &GridGeometry, dst: &GridGeometry) -> Result<(), MapError> {
        let values = [
            ("theta_ij_rad", self.theta_ij_rad),
            ("d_ij_m", self.d_ij_m),
            ("alpha_ji_rad", self.alpha_ji_rad),
            ("src_robot_m.x", self.src_robot_m[0]),
            ("src_robot_m.y", self.src_robot_m[1]),
            ("dst_robot_m.x", self.dst_robot_m[0]),
            ("dst_robot_m.y", self.dst_robot_m[1]),
        ];
        if let Some((name, v)) = values.iter().find(|(_, v)| !v.is_finite()) {
            return Err(MapError::Transform {
                name,
                value: *v,
                limit_m: f64::NAN,
            });
        }
        let (rs, rd) = (reach_m(src), reach_m(dst));
        for (name, v, limit_m) in [
            ("d_ij_m", self.d_ij_m.abs(), rs + rd),
            (
                "src_robot_m",
                self.src_robot_m[0].hypot(self.src_robot_m[1]),
                rs,
            ),
            (
                "dst_robot_m",
                self.dst_robot_m[0].hypot(self.dst_robot_m[1]),
                rd,
            ),
        ] {
            if v > limit_m {
                return Err(MapError::Transform {
                    name,
                    value: v,
                    limit_m,
                });
            }
        }
        Ok(())
    }
}

/// What one merge did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MergeStats {
    /// Destination cells that were unknown and took the source's values.
    pub adopted: usize,
    /// Destination cells known in both maps, averaged.
    pub averaged: usize,
}

impl LocalMap {
    /// Merges `src` into this map through `t` (Σsrc → Σthis). A source with a non-finite cell or
    /// a transform [`MergeTransform::validate`] refuses is rejected before any cell changes.
    pub fn merge(&mut self, src: &MapView<'_>, t: &MergeTransform) -> Result<MergeStats, MapError> {
        let geometry = *self.geometry();
        merge_planes(&geometry, &mut self.occupancy, &mut self.pheromone, src, t)
    }
}

/// The merge pass over destination planes of `geometry` (what [`LocalMap::merge`] runs).
pub fn merge_planes(
    geometry: &GridGeometry,
    occupancy: &mut [f32],
    pheromone: &mut [f32],
    src: &MapView<'_>,
    t: &MergeTransform,
) -> Result<MergeStats, MapError> {
    let plane = src.geometry.cells();
    if src.occupancy.len() != plane || src.pheromone.len() != plane {
        return Err(MapError::Length {
            channels: 2,
            width: src.geometry.width,
            height: src.geometry.height,
            len: src.occupancy.len() + src.pheromone.len(),
        });
    }
    t.validate(&src.geometry, geometry)?;
    if let Some((channel, index, value)) = src.first_non_finite() {
        return Err(MapError::NonFiniteCell {
            channel,
            index,
            value,
        });
    }
    // The inverse transform in grid units: source cell coordinates of destination cell (x, y)
    // are g0 + x·gx + y·gy (affine), so each row is a walk of additions.
    let (h, hs) = (geometry.cell_size_m as f64, src.geometry.cell_size_m as f64);
    let centre = |x: f64, y: f64| {
        [
            geometry.origin_x_m as f64 + (x + 0.5) * h,
            geometry.origin_y_m as f64 + (y + 0.5) * h,
        ]
    };
    let to_src_grid = |q: [f64; 2]| {
        let p = t.inverse(q);
        [
            (p[0] - src.geometry.origin_x_m as f64) / hs,
            (p[1] - src.geometry.origin_y_m as f64) / hs,
        ]
    };
    let g0 = to_src_grid(centre(0.0, 0.0));
    let g1 = to_src_grid(centre(1.0, 0.0));
    let g2 = to_src_grid(centre(0.0, 1.0));
    let gx = [g1[0] - g0[0], g1[1] - g0[1]];
    let gy = [g2[0] - g0[0], g2[1] - g0[1]];
    let (w, hgt) = (geometry.width as usize, geometry.height as usize);
    let (sw, sh) = (src.geometry.width as f64, src.geometry.height as f64);
    let sw_u = src.geometry.width as usize;
    let mut stats = MergeStats::default();
    for y in 0..hgt {
        let row = y * w;
        let (mut u, mut v) = (g0[0] + y as f64 * gy[0], g0[1] + y as f64 * gy[1]);
        let drow = &mut occupancy[row..row + w];
        let prow = &mut pheromone[row..row + w];
        for x in 0..w {
            if u >= 0.0 && v >= 0.0 && u < sw && v < sh {
                let i = v as usize * sw_u + u as usize;
                let (so, sp) = (src.occupancy[i], src.pheromone[i]);
                if so != 0.0 {
                    let d = &mut drow[x];
                    if *d == 0.0 {
                        *d = so;
                        prow[x] = sp;
                        stats.adopted += 1;
                    } else {
                        *d = 0.5 * (*d + so);
                        prow[x] = 0.5 * (prow[x] + sp);
                        stats.averaged += 1;
                    }
                }
            }
            u += gx[0];
            v += gx[1];
        }
    }
    Ok(stats)
}
