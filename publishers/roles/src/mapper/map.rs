//! [`LocalMap`]: one robot's occupancy grid (log-odds, f32, clamped) and pheromone map in its own
//! frame Σ (origin = its start pose, x along its start heading), updated from its pose estimate
//! and its range scans (seed 004 §3, MODELS.md M4).

use pheromone_field::{
    ChannelSpec, DepositMsg, Evaporation, FieldConfig, FrameHeader, GridGeometry, Stepper,
};

use super::config::{MappingConfig, MergeRule};
use super::MapError;
use pheromone_messages::{PoseMsg, ScanMsg};

/// Channel names of a map frame, in plane order.
pub const MAP_CHANNELS: [&str; 2] = ["occupancy", "pheromone"];

/// A pose (x, y, θ) in some frame.
pub type Pose2 = [f64; 3];

/// `pose` (in the world) expressed in the frame whose origin is `origin` (in the world).
pub fn pose_in_frame(origin: Pose2, pose: Pose2) -> Pose2 {
    let (s, c) = origin[2].sin_cos();
    let (dx, dy) = (pose[0] - origin[0], pose[1] - origin[1]);
    [
        c * dx + s * dy,
        -s * dx + c * dy,
        pheromone_messages::wrap_angle(pose[2] - origin[2]),
    ]
}

/// A pose message (world frame) with its position and heading moved into the frame whose
/// origin is `origin` (a robot's map frame: what own-map steering reads the map at); the rest
/// (step, covariance, stamps) is unchanged.
pub fn pose_msg_in_frame(origin: Pose2, pose: &PoseMsg) -> PoseMsg {
    let p = pose_in_frame(origin, [pose.x_m, pose.y_m, pose.theta_rad]);
    PoseMsg {
        x_m: p[0],
        y_m: p[1],
        theta_rad: p[2],
        ..*pose
    }
}

/// A point of frame `origin` (in the world) in the world.
pub fn point_from_frame(origin: Pose2, p: [f64; 2]) -> [f64; 2] {
    let (s, c) = origin[2].sin_cos();
    [
        origin[0] + c * p[0] - s * p[1],
        origin[1] + s * p[0] + c * p[1],
    ]
}

/// One robot's local map.
#[derive(Debug, Clone)]
pub struct LocalMap {
    geometry: GridGeometry,
    /// Log-odds of occupancy, 0 = unknown, row-major.
    pub occupancy: Vec<f32>,
    /// The robot's own pheromone (and what it merged), row-major.
    pub pheromone: Vec<f32>,
    scratch: Vec<f32>,
    stepper: Stepper,
    logodds_free: f32,
    logodds_occupied: f32,
    logodds_max: f32,
    merge_rule: MergeRule,
    /// Scans refused (non-finite pose or ray).
    pub scans_rejected: u64,
}

impl LocalMap {
    /// An empty map (every cell unknown, no pheromone) of the configured size, centred on the
    /// start pose; `channel` is the field channel whose evaporation the pheromone map follows,
    /// `field_dt_s` the field's tick period (the scenario's per-tick rates are rescaled to one
    /// iteration, the period the pheromone map is stepped with).
    pub fn new(
        config: &MappingConfig,
        channel: &ChannelSpec,
        field_dt_s: f64,
    ) -> Result<Self, MapError> {
        config.validate().map_err(MapError::Config)?;
        let side = config.side_cells();
        let half = 0.5 * side as f32 * config.cell_size_m;
        let mut spec = channel.clone();
        let ticks = (config.iteration_s / field_dt_s).max(1.0);
        if let Evaporation::Saturating { rho_per_tick } = &mut spec.evaporation {
            *rho_per_tick = 1.0 - (1.0 - *rho_per_tick).powf(ticks as f32);
        }
        spec.name = MAP_CHANNELS[1].into();
        let field = FieldConfig {
            width: side,
            height: side,
            cell_size_m: config.cell_size_m,
            origin_x_m: -half,
            origin_y_m: -half,
            tick_hz: (1.0 / config.iteration_s) as f32,
            deposit_buffer: 4096,
            channels: vec![spec],
            ..FieldConfig::default()
        };
        let stepper = Stepper::new(field).map_err(MapError::Field)?;
        let geometry = *stepper.geometry();
        let n = geometry.cells();
        Ok(Self {
            geometry,
            occupancy: vec![0.0; n],
            pheromone: vec![0.0; n],
            scratch: vec![0.0; n],
            stepper,
            logodds_free: config.logodds_free,
            logodds_occupied: config.logodds_occupied,
            logodds_max: config.logodds_max,
            merge_rule: config.merge_rule,
            scans_rejected: 0,
        })
    }

    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The map as a merge source.
    pub fn view(&self) -> MapView<'_> {
        MapView {
            geometry: self.geometry,
            occupancy: &self.occupancy,
            pheromone: &self.pheromone,
        }
    }

    /// How this map merges another ([`MergeRule`]) and its log-odds clamp.
    pub fn merge_rule(&self) -> (MergeRule, f32) {
        (self.merge_rule, self.logodds_max)
    }

    /// Both planes as one frame payload (`MAP_CHANNELS` order), what the mapper publishes.
    pub fn write_frame(&self, out: &mut [f32]) {
        let n = self.geometry.cells();
        out[..n].copy_from_slice(&self.occupancy);
        out[n..2 * n].copy_from_slice(&self.pheromone);
    }

    /// Integrates one scan taken at `pose` (the estimate, in this map's frame): every cell a ray
    /// crosses becomes more free, the cell a ray hit more occupied. A non-finite pose or ray is
    /// refused and counted; the map is unchanged.
    pub fn integrate_scan(&mut self, pose: Pose2, scan: &ScanMsg) -> Result<(), MapError> {
        if !pose.iter().all(|v| v.is_finite()) {
            self.scans_rejected += 1;
            return Err(MapError::NonFinitePose { pose });
        }
        if let Some((i, (b, r, _))) = scan
            .rays()
            .enumerate()
            .find(|(_, (b, r, _))| !(b.is_finite() && r.is_finite() && *r >= 0.0))
        {
            self.scans_rejected += 1;
            return Err(MapError::BadRay {
                ray: i,
                bearing_rad: b,
                range_m: r,
            });
        }
        let h = self.geometry.cell_size_m as f64;
        for (bearing, range, hit) in scan.rays() {
            let a = pose[2] + bearing as f64;
            let (s, c) = a.sin_cos();
            let range = range as f64;
            // Cells along the ray, sampled every half cell, each updated once.
            let n = (range / (0.5 * h)).ceil() as usize;
            let mut last = usize::MAX;
            let end = self.cell_index(pose[0] + c * range, pose[1] + s * range);
            for k in 0..n {
                let t = k as f64 * 0.5 * h;
                let Some(i) = self.cell_index(pose[0] + c * t, pose[1] + s * t) else {
                    break;
                };
                if i == last || (hit && Some(i) == end) {
                    continue;
                }
                last = i;
                self.add(i, self.logodds_free);
            }
            if hit {
                if let Some(i) = end {
                    self.add(i, self.logodds_occupied);
                }
            }
        }
        Ok(())
    }

    fn add(&mut self, i: usize, l: f32) {
        let m = self.logodds_max;
        self.occupancy[i] = (self.occupancy[i] + l).clamp(-m, m);
    }

    /// Index of the cell holding a point of the map's frame.
    pub fn cell_index(&self, x_m: f64, y_m: f64) -> Option<usize> {
        self.geometry
            .cell_at(x_m as f32, y_m as f32)
            .map(|(x, y)| self.geometry.index(x, y))
    }

    /// Queues one of the robot's own deposits (made in the world frame from its estimate) for
    /// the next pheromone step, moved into this map's frame (`start`: the start pose the
    /// estimate's frame is relative to). A deposit the field would refuse is refused here too.
    pub fn deposit(&mut self, start: Pose2, msg: &DepositMsg) -> Result<(), MapError> {
        let p = pose_in_frame(start, [msg.x_m as f64, msg.y_m as f64, 0.0]);
        let (s, c) = (start[2] as f32).sin_cos();
        let (xx, xy, yy) = (msg.cov_xx, msg.cov_xy, msg.cov_yy);
        // Σ' = Rᵀ Σ R with R the start heading's rotation.
        let m = DepositMsg {
            channel: 0,
            x_m: p[0] as f32,
            y_m: p[1] as f32,
            cov_xx: c * c * xx + 2.0 * c * s * xy + s * s * yy,
            cov_xy: (c * c - s * s) * xy + c * s * (yy - xx),
            cov_yy: s * s * xx - 2.0 * c * s * xy + c * c * yy,
            ..*msg
        };
        self.stepper
            .offer(&m)
            .map_err(|r| MapError::Deposit(r.reason.name()))
    }

    /// One iteration of the pheromone map: evaporation over the iteration, then the deposits
    /// queued since the last step.
    pub fn step_pheromone(&mut self) {
        self.stepper.step(&self.pheromone, &mut self.scratch);
        std::mem::swap(&mut self.pheromone, &mut self.scratch);
    }

    /// Cells whose |log-odds| ≥ `threshold` (mapped, free or occupied).
    pub fn mapped_cells(&self, threshold: f32) -> usize {
        self.occupancy
            .iter()
            .filter(|l| l.abs() >= threshold)
            .count()
    }
}

/// The farthest a corner of `g` lies from the origin (m).
pub(super) fn reach_m(g: &GridGeometry) -> f64 {
    let xs = [g.origin_x_m as f64, (g.origin_x_m + g.width_m()) as f64];
    let ys = [g.origin_y_m as f64, (g.origin_y_m + g.height_m()) as f64];
    xs.iter()
        .flat_map(|x| ys.iter().map(move |y| x.hypot(*y)))
        .fold(0.0, f64::max)
}

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
            // Branch-free per chunk (the exponent test vectorizes); early exit between chunks.
            let finite = |c: &[f32]| {
                c.iter().fold(true, |ok, v| {
                    ok & (v.to_bits() & 0x7f80_0000 != 0x7f80_0000)
                })
            };
            if !plane.chunks(1024).all(finite) {
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
