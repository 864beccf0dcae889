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
//! Averaging ([`MergeRule`], MODELS.md M4): `average` (seed 004, the default) averages every
//! cell of the overlap, occupancy as probabilities p = σ(log-odds) (an unknown cell, log-odds
//! exactly 0, is p = 0.5) and pheromone as levels; the result is the same whichever map merges
//! the other. `adopt-unknown` averages in log-odds where both maps know a cell, and a cell
//! unknown in one map takes the other map's occupancy and pheromone.

use pheromone_field::GridGeometry;

use super::config::MergeRule;
use super::map::{reach_m, LocalMap, MapView, Pose2};
pub use super::merge_logodds::{average_logodds, average_logodds_bound};
use super::MapError;
use pheromone_messages::PeerObs;

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
            theta_ij_rad: pheromone_messages::wrap_angle(
                dst_pose[2] + obs.heading_rad - src_pose[2],
            ),
            d_ij_m: obs.range_m,
            alpha_ji_rad: pheromone_messages::wrap_angle(dst_pose[2] + obs.bearing_rad),
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
    /// Destination cells that were unknown and took the source's values (`adopt-unknown`,
    /// `max`).
    pub adopted: usize,
    /// Destination cells averaged: known in both maps (`adopt-unknown`), known or marked in
    /// either (`average`; a cell unknown and unmarked in both stays as it is); with `max`, the
    /// cells combined by the maximum (a known or marked source cell not adopted).
    pub averaged: usize,
}

impl LocalMap {
    /// Merges `src` into this map through `t` (Σsrc → Σthis). A source with a non-finite cell or
    /// a transform [`MergeTransform::validate`] refuses is rejected before any cell changes.
    pub fn merge(&mut self, src: &MapView<'_>, t: &MergeTransform) -> Result<MergeStats, MapError> {
        let geometry = *self.geometry();
        let rule = self.merge_rule();
        merge_planes(
            &geometry,
            (&mut self.occupancy, &mut self.pheromone),
            src,
            t,
            rule,
        )
    }
}

/// The merge pass over destination planes (occupancy, pheromone) of `geometry` (what
/// [`LocalMap::merge`] runs), by `rule` with log-odds clamped to ±`logodds_max`: the reference
/// pass's result (`merge_planes_reference`) bit for bit by `AdoptUnknown`, and by `Average`
/// bit for bit in the pheromone plane and the counts and within [`average_logodds_bound`] in
/// the occupancy plane; each run of destination cells merged eight at a time where the CPU has
/// AVX2 (`merge_simd`; `Average` for a `logodds_max` up to 8, the default 4).
pub fn merge_planes(
    geometry: &GridGeometry,
    planes: (&mut [f32], &mut [f32]),
    src: &MapView<'_>,
    t: &MergeTransform,
    rule: (MergeRule, f32),
) -> Result<MergeStats, MapError> {
    let runs = super::merge_simd::Runs::detect();
    merge_with(geometry, planes, src, t, (runs, rule))
}

/// The reference merge pass: every run of destination cells one cell at a time. Kept for the
/// tests and the bench, which compare [`merge_planes`] with it.
#[doc(hidden)]
pub fn merge_planes_reference(
    geometry: &GridGeometry,
    planes: (&mut [f32], &mut [f32]),
    src: &MapView<'_>,
    t: &MergeTransform,
    rule: (MergeRule, f32),
) -> Result<MergeStats, MapError> {
    let runs = super::merge_simd::Runs::Scalar;
    merge_with(geometry, planes, src, t, (runs, rule))
}

fn merge_with(
    geometry: &GridGeometry,
    (occupancy, pheromone): (&mut [f32], &mut [f32]),
    src: &MapView<'_>,
    t: &MergeTransform,
    (runs, rule): (super::merge_simd::Runs, (MergeRule, f32)),
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
    // The fast test over both planes (AVX2 where the CPU has it); where it fails, the first
    // non-finite cell is looked up for the error.
    let finite = runs.all_finite(src.occupancy) && runs.all_finite(src.pheromone);
    let bad = if finite { None } else { src.first_non_finite() };
    if let Some((channel, index, value)) = bad {
        return Err(MapError::NonFiniteCell {
            channel,
            index,
            value,
        });
    }
    let [g0, gx, gy] = lookup(geometry, src, t);
    let (w, hgt) = (geometry.width as usize, geometry.height as usize);
    let (sw, sh) = (src.geometry.width as usize, src.geometry.height as usize);
    let mut stats = MergeStats::default();
    // The destination is walked in tiles of TILE_ROWS × TILE_COLS cells: a rotated source is
    // read along a slant, and a tile's source cells (a rotated square of about the same size)
    // stay in cache while the tile's rows reuse them, where whole rows would evict them between
    // one destination row and the next. Each cell is independent, so the order changes nothing
    // in the result.
    const TILE_ROWS: usize = 32;
    const TILE_COLS: usize = 128;
    let mut spans: Vec<Option<(usize, usize)>> = Vec::with_capacity(TILE_ROWS);
    for y_band in (0..hgt).step_by(TILE_ROWS) {
        let band = y_band..(y_band + TILE_ROWS).min(hgt);
        // The destination cells of each row whose centre falls inside the source, found once
        // (the lookup is linear in x), so the inner loop has no bounds test of its own.
        spans.clear();
        spans.extend(band.clone().map(|y| {
            let (u0, v0) = (g0[0] + y as f64 * gy[0], g0[1] + y as f64 * gy[1]);
            row_span(u0, v0, gx, sw as f64, sh as f64, w)
        }));
        for x_tile in (0..w).step_by(TILE_COLS) {
            for (y, span) in band.clone().zip(&spans) {
                let Some((lo, hi)) = *span else { continue };
                let (x_lo, x_hi) = (lo.max(x_tile), hi.min(x_tile + TILE_COLS));
                if x_lo >= x_hi {
                    continue;
                }
                let (a, b) = merge_run(
                    occupancy,
                    pheromone,
                    src,
                    (y * w + x_lo, x_hi - x_lo),
                    [g0[0] + y as f64 * gy[0], g0[1] + y as f64 * gy[1]],
                    x_lo,
                    gx,
                    (sw, sh),
                    (runs, rule),
                );
                stats.adopted += a;
                stats.averaged += b;
            }
        }
    }
    Ok(stats)
}

/// The inverse transform in source grid units: the source cell coordinates of destination cell
/// (x, y) are `g0 + x·gx + y·gy` (affine), so each row is a walk of additions. Returns
/// `[g0, gx, gy]`.
fn lookup(geometry: &GridGeometry, src: &MapView<'_>, t: &MergeTransform) -> [[f64; 2]; 3] {
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
    [
        g0,
        [g1[0] - g0[0], g1[1] - g0[1]],
        [g2[0] - g0[0], g2[1] - g0[1]],
    ]
}

/// 1.0 in the 32.32 fixed point of [`merge_run`]'s walk.
const FIXED_ONE: f64 = (1u64 << 32) as f64;

/// Merges `len` destination cells from index `start` on (row cells x_lo.., whose source
/// coordinates are (u0 + x·gx[0], v0 + x·gx[1]), all inside the source); returns the cells
/// (adopted, averaged).
#[allow(clippy::too_many_arguments)]
#[inline]
fn merge_run(
    occupancy: &mut [f32],
    pheromone: &mut [f32],
    src: &MapView<'_>,
    (start, len): (usize, usize),
    [u0, v0]: [f64; 2],
    x_lo: usize,
    gx: [f64; 2],
    (sw, sh): (usize, usize),
    (runs, (rule, logodds_max)): (super::merge_simd::Runs, (MergeRule, f32)),
) -> (usize, usize) {
    let drow = &mut occupancy[start..start + len];
    let prow = &mut pheromone[start..start + len];
    // The walk in 32.32 fixed point: one integer add per axis and a shift give the source cell,
    // where a float-to-usize conversion per axis (saturating, as Rust's `as` is) cost most of
    // the loop. A run is at most a tile wide, so the step's rounding (≤ 2⁻³² cell per step)
    // moves a lookup only for a centre within about 2⁻²⁵ cell of a cell edge.
    let fixed = |c: f64| (c * FIXED_ONE).round() as i64;
    let walk = super::merge_simd::Walk {
        u: fixed(u0 + x_lo as f64 * gx[0]),
        v: fixed(v0 + x_lo as f64 * gx[1]),
        du: fixed(gx[0]),
        dv: fixed(gx[1]),
        sw,
        sh,
    };
    match rule {
        MergeRule::AdoptUnknown => runs.run(drow, prow, src.occupancy, src.pheromone, &walk),
        MergeRule::Average => runs.average(
            (drow, prow),
            (src.occupancy, src.pheromone),
            &walk,
            logodds_max,
        ),
        MergeRule::Max => max_run((drow, prow), src, &walk),
    }
}

/// The `max` ablation over one run, one cell at a time: a cell unknown in one map takes the
/// other's occupancy, a cell known in both the larger log-odds; pheromone the larger level.
/// Returns (adopted: unknown here, known in the source; combined: known in both, or marked).
fn max_run(
    (drow, prow): (&mut [f32], &mut [f32]),
    src: &MapView<'_>,
    walk: &super::merge_simd::Walk,
) -> (usize, usize) {
    let (mut adopted, mut combined) = (0usize, 0usize);
    for ((d, p), i) in drow.iter_mut().zip(prow.iter_mut()).zip(walk.indices()) {
        let (so, sp) = (src.occupancy[i], src.pheromone[i]);
        if *d == 0.0 && so != 0.0 {
            *d = so;
            *p = p.max(sp);
            adopted += 1;
        } else if so != 0.0 || sp != 0.0 {
            // Here a known source cell meets a known destination cell (else the branch above).
            if so != 0.0 {
                *d = d.max(so);
            }
            *p = p.max(sp);
            combined += 1;
        }
    }
    (adopted, combined)
}

/// The cells x in [x_lo, x_hi) of a destination row whose source coordinates
/// (u0 + x·gx[0], v0 + x·gx[1]) lie in [0, sw) × [0, sh), or `None` when there are none. The
/// set is an interval (the lookup is affine in x); its ends are solved for, then nudged so that
/// every cell inside passes the exact test the per-cell walk would apply and none outside does.
fn row_span(u0: f64, v0: f64, gx: [f64; 2], sw: f64, sh: f64, w: usize) -> Option<(usize, usize)> {
    let inside = |x: usize| {
        let (u, v) = (u0 + x as f64 * gx[0], v0 + x as f64 * gx[1]);
        u >= 0.0 && v >= 0.0 && u < sw && v < sh
    };
    // Solve 0 <= c0 + x·g < limit for x in reals, per axis.
    let (mut lo, mut hi) = (0.0f64, w as f64);
    for (c0, g, limit) in [(u0, gx[0], sw), (v0, gx[1], sh)] {
        if g == 0.0 {
            if !(c0 >= 0.0 && c0 < limit) {
                return None;
            }
        } else {
            let (a, b) = ((0.0 - c0) / g, (limit - c0) / g);
            let (a, b) = if a < b { (a, b) } else { (b, a) };
            lo = lo.max(a);
            hi = hi.min(b);
        }
    }
    // NaN bounds (never expected) also fall here: `partial_cmp` is then `None`.
    if lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less) {
        // Rounding can still leave a cell at the edge: check around the estimate.
        let x = lo.clamp(0.0, w as f64) as usize;
        return (x.saturating_sub(1)..(x + 2).min(w))
            .find(|&x| inside(x))
            .map(|x| (x, x + 1));
    }
    let mut x_lo = (lo.ceil().max(0.0) as usize).min(w);
    let mut x_hi = (hi.ceil().max(0.0) as usize).min(w);
    while x_lo > 0 && inside(x_lo - 1) {
        x_lo -= 1;
    }
    while x_lo < x_hi && !inside(x_lo) {
        x_lo += 1;
    }
    while x_hi < w && inside(x_hi) {
        x_hi += 1;
    }
    while x_hi > x_lo && !inside(x_hi - 1) {
        x_hi -= 1;
    }
    (x_lo < x_hi).then_some((x_lo, x_hi))
}

/// One merge: robot `dst` merged the map of `src` at world step `step`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MergeEvent {
    pub step: u64,
    pub dst: u32,
    pub src: u32,
    /// Alignment error (m): the largest displacement, between the transform measured and the
    /// true one, of the source map's origin and of the source robot's position.
    pub alignment_error_m: f64,
}

/// The true transform from `src`'s map frame into `dst`'s (their true start poses).
pub fn true_transform(src_start: Pose2, dst_start: Pose2) -> MergeTransform {
    MergeTransform::between_frames(src_start, dst_start)
}

/// Alignment error of a merge (see [`MergeEvent::alignment_error_m`]).
pub fn alignment_error_m(measured: &MergeTransform, truth: &MergeTransform) -> f64 {
    measured
        .displacement_m(truth, [0.0, 0.0])
        .max(measured.displacement_m(truth, measured.src_robot_m))
}
