//! Seed 002's pheromone sources (MODELS.md M3, eqs. 1–4): on a channel with `sources` set, the
//! plane holds one counter C_i per grid node and the field at a point is P = Σ C_i·μ(d_i), μ the
//! channel's Z-shape (eq. 1). Node (i, j) is the corner (origin_x + i·h, origin_y + j·h) of cell
//! (i, j) (the paper's "intersection of the boundary lines of the cells"); the nodes on the grid's
//! far right and top border are not stored.
//!
//! Antennas on such a channel are directional: each sees only the sources inside its field of
//! view (a cone of `fov_deg` about its direction, the heading turned by ±`splay_deg`); the
//! default 180° hides every source behind the line through the two antennas (the paper's
//! "gray area" of Fig. 7). A deposit on such a channel adds its amount to the nearest node's
//! counter (`deposit::prepare`).

use serde::{Deserialize, Serialize};

use crate::error::ConfigError;
use crate::geometry::GridGeometry;
use crate::sample::{antenna_points, FrameView, SamplePose};

/// How a source channel is read: the Z-shape of eq. 1 and each antenna's sensitivity pattern.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceSensing {
    /// Plateau c of μ (m, ≥ 0).
    pub plateau_m: f32,
    /// Width σ of μ's linear fall-off beyond the plateau (m, ≥ 0; c + σ > 0).
    pub slope_m: f32,
    /// Full angle of each antenna's field of view (degrees, in (0, 360]); 180 (default) hides
    /// the half-plane behind the antennas, 360 sees every source.
    #[serde(default = "default_fov_deg")]
    pub fov_deg: f32,
    /// Each antenna's direction turned outward from the heading (degrees, in [0, 90]): the
    /// left one by +splay, the right one by −splay (default 0).
    #[serde(default)]
    pub splay_deg: f32,
}

fn default_fov_deg() -> f32 {
    180.0
}

impl SourceSensing {
    /// A 180° pattern with the given Z-shape.
    pub fn new(plateau_m: f32, slope_m: f32) -> Self {
        Self {
            plateau_m,
            slope_m,
            fov_deg: default_fov_deg(),
            splay_deg: 0.0,
        }
    }

    /// Checks every setting; `channel` names the channel in the error.
    pub fn validate(&self, channel: &str) -> Result<(), ConfigError> {
        let bad = |what: &str, v: f32, why: &str| {
            Err(ConfigError::invalid(
                format!("channel '{channel}' sources.{what}"),
                v,
                why,
            ))
        };
        for (what, v) in [("plateau_m", self.plateau_m), ("slope_m", self.slope_m)] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(what, v, "must be finite and ≥ 0");
            }
        }
        if self.plateau_m + self.slope_m <= 0.0 {
            return bad("slope_m", self.slope_m, "plateau_m + slope_m must be > 0");
        }
        if !(self.fov_deg > 0.0 && self.fov_deg <= 360.0) {
            return bad("fov_deg", self.fov_deg, "must be within (0, 360]");
        }
        if !(0.0..=90.0).contains(&self.splay_deg) {
            return bad("splay_deg", self.splay_deg, "must be within [0, 90]");
        }
        Ok(())
    }

    /// How far a source reaches: c + σ (m).
    pub fn reach_m(&self) -> f32 {
        self.plateau_m + self.slope_m
    }

    /// cos of half the field of view, exact at 180° (0) and 360° (−1).
    fn cos_half_fov(&self) -> f64 {
        if self.fov_deg == 180.0 {
            0.0
        } else if self.fov_deg == 360.0 {
            -1.0
        } else {
            (0.5 * self.fov_deg as f64).to_radians().cos()
        }
    }
}

/// World position of node (i, j).
pub fn node_position(g: &GridGeometry, i: u32, j: u32) -> (f32, f32) {
    (
        g.origin_x_m + i as f32 * g.cell_size_m,
        g.origin_y_m + j as f32 * g.cell_size_m,
    )
}

/// The stored node nearest to (x, y); `None` when it lies off the stored nodes.
pub fn nearest_node(g: &GridGeometry, x_m: f32, y_m: f32) -> Option<(u32, u32)> {
    let i = ((x_m - g.origin_x_m) / g.cell_size_m).round();
    let j = ((y_m - g.origin_y_m) / g.cell_size_m).round();
    let inside = |v: f32, n: u32| v >= 0.0 && v < n as f32;
    (inside(i, g.width) && inside(j, g.height)).then_some((i as u32, j as u32))
}

/// P at (x, y) seen in direction `dir` (a unit vector; `None` = every direction): eq. 4 over the
/// sources within reach and inside the field of view.
pub fn reading(
    view: &FrameView<'_>,
    channel: usize,
    at: (f32, f32),
    dir: Option<(f32, f32)>,
    s: &SourceSensing,
) -> f32 {
    let g = &view.geometry;
    let plane = view.plane(channel);
    let reach = s.reach_m();
    let h = g.cell_size_m;
    let span = |a: f32, o: f32, n: u32| {
        let lo = ((a - reach - o) / h).ceil().max(0.0);
        let hi = ((a + reach - o) / h).floor().min(n as f32 - 1.0);
        (lo as i64, hi as i64)
    };
    let (i0, i1) = span(at.0, g.origin_x_m, g.width);
    let (j0, j1) = span(at.1, g.origin_y_m, g.height);
    let cos_half = s.cos_half_fov();
    let mut sum = 0.0f64;
    for j in j0.max(0)..=j1 {
        for i in i0.max(0)..=i1 {
            let c = plane[g.index(i as u32, j as u32)];
            if c == 0.0 {
                continue;
            }
            let (nx, ny) = node_position(g, i as u32, j as u32);
            let (dx, dy) = (nx - at.0, ny - at.1);
            let d = dx.hypot(dy);
            if d > reach {
                continue;
            }
            if let Some((ux, uy)) = dir {
                let along = dx as f64 * ux as f64 + dy as f64 * uy as f64;
                if d > 0.0 && along < d as f64 * cos_half {
                    continue;
                }
            }
            sum += c as f64 * z_shape(d, s.plateau_m, s.slope_m) as f64;
        }
    }
    sum as f32
}

/// The directional readings (P_L, P_R) of two antennas half a wheel base to each side of the
/// pose (the points of [`FrameView::antennas`]), each seeing only its field of view.
pub fn antennas(
    view: &FrameView<'_>,
    channel: usize,
    pose: SamplePose,
    wheel_base_m: f32,
    s: &SourceSensing,
) -> (f32, f32) {
    let (l, r) = antenna_points(pose, wheel_base_m);
    let splay = s.splay_deg.to_radians();
    let dir = |a: f32| {
        let (sn, c) = a.sin_cos();
        Some((c, sn))
    };
    (
        reading(view, channel, l, dir(pose.theta_rad + splay), s),
        reading(view, channel, r, dir(pose.theta_rad - splay), s),
    )
}

/// Seed 002 eq. 1: μ(x) = 1 for x ≤ c; 1 − (x − c)/σ for c < x ≤ c + σ; 0 beyond.
pub fn z_shape(x: f32, c: f32, sigma: f32) -> f32 {
    if x <= c {
        1.0
    } else if x <= c + sigma && sigma > 0.0 {
        1.0 - (x - c) / sigma
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> GridGeometry {
        GridGeometry::new(40, 40, 0.05).unwrap()
    }

    #[test]
    fn a_reading_is_eq_4_over_the_sources_in_reach() {
        let g = grid();
        let mut cells = vec![0.0; g.cells()];
        // Two sources: C = 2 at node (10, 10) = (0.5, 0.5) m, C = 3 at node (14, 10) = (0.7, 0.5).
        cells[g.index(10, 10)] = 2.0;
        cells[g.index(14, 10)] = 3.0;
        let v = FrameView::new(g, 1, &cells);
        let s = SourceSensing::new(0.05, 0.2);
        // At (0.55, 0.5): d = 0.05 (μ = 1) and d = 0.15 (μ = 1 − 0.1/0.2 = 0.5).
        let p = reading(&v, 0, (0.55, 0.5), None, &s);
        assert!((p - (2.0 + 1.5)).abs() < 1e-5, "{p}");
        // Out of reach of both.
        assert_eq!(reading(&v, 0, (1.5, 1.5), None, &s), 0.0);
    }

    #[test]
    fn sources_behind_the_antennas_are_invisible() {
        let g = grid();
        let mut cells = vec![0.0; g.cells()];
        cells[g.index(10, 10)] = 1.0; // (0.5, 0.5) m
        let v = FrameView::new(g, 1, &cells);
        let s = SourceSensing::new(0.05, 0.2);
        // Heading +x from (0.6, 0.5): the source is behind; heading −x: ahead.
        assert_eq!(reading(&v, 0, (0.6, 0.5), Some((1.0, 0.0)), &s), 0.0);
        assert!(reading(&v, 0, (0.6, 0.5), Some((-1.0, 0.0)), &s) > 0.7);
        // Beside the antenna (on its line) is still seen with 180°.
        assert!(reading(&v, 0, (0.5, 0.6), Some((1.0, 0.0)), &s) > 0.0);
        // A 90° cone does not see a source 60° off its direction; 360° sees everything.
        let narrow = SourceSensing { fov_deg: 90.0, ..s };
        let off = (0.5 - 0.1 * 0.5, 0.5 - 0.1 * 0.866);
        assert_eq!(reading(&v, 0, off, Some((1.0, 0.0)), &narrow), 0.0);
        assert!(reading(&v, 0, off, Some((0.0, 1.0)), &narrow) > 0.0);
        let all = SourceSensing {
            fov_deg: 360.0,
            ..s
        };
        assert!(reading(&v, 0, (0.6, 0.5), Some((1.0, 0.0)), &all) > 0.0);
    }

    #[test]
    fn splayed_antennas_look_outward() {
        let g = grid();
        let mut cells = vec![0.0; g.cells()];
        // A source right of a robot at (1, 1) heading +x, level with its antennas.
        cells[g.index(20, 17)] = 1.0; // (1.0, 0.85) m
        let v = FrameView::new(g, 1, &cells);
        let pose = SamplePose::new(1.0, 1.0, 0.0);
        let narrow = SourceSensing {
            fov_deg: 60.0,
            ..SourceSensing::new(0.05, 0.3)
        };
        // Straight ahead, the right antenna (at y = 0.9) does not see it 90° to its side ...
        assert_eq!(antennas(&v, 0, pose, 0.2, &narrow), (0.0, 0.0));
        // ... turned 75° outward it does; the left one (turned away) still does not.
        let splayed = SourceSensing {
            splay_deg: 75.0,
            ..narrow
        };
        let (pl, pr) = antennas(&v, 0, pose, 0.2, &splayed);
        assert_eq!(pl, 0.0);
        assert!(pr > 0.5, "{pr}");
    }

    #[test]
    fn the_nearest_node_is_a_cell_corner() {
        let g = grid();
        assert_eq!(nearest_node(&g, 0.5, 1.5), Some((10, 30)));
        assert_eq!(nearest_node(&g, 0.524, 0.476), Some((10, 10)));
        assert_eq!(nearest_node(&g, 0.526, 0.476), Some((11, 10)));
        // The far border's nodes are not stored; nothing left of the origin.
        assert_eq!(nearest_node(&g, 2.0, 0.5), None);
        assert_eq!(nearest_node(&g, -0.03, 0.5), None);
    }

    #[test]
    fn a_deposit_on_a_source_channel_reinforces_the_nearest_node_only() {
        use crate::deposit::{prepare, DepositLimits};
        use crate::kernel::{Deposit, Kernel};
        use crate::models::{ChannelSpec, Evaporation};
        let g = grid();
        let mut spec = ChannelSpec::new(
            "trail",
            Evaporation::Quantum {
                quantum: 1.0,
                tau_s: 5.0,
            },
        );
        spec.sources = Some(SourceSensing::new(0.05, 0.2));
        let msg = Deposit {
            channel: 0,
            x_m: 0.52,
            y_m: 0.49,
            kernel: Kernel::ZShape {
                amount: 1.0,
                plateau_m: 0.2,
                slope_m: 0.3,
            },
        }
        .to_msg(1, 0);
        let p = prepare(&msg, &g, &[spec.clone()], &DepositLimits::default()).unwrap();
        let prev = vec![0.0; g.cells()];
        let mut plane = vec![0.0; g.cells()];
        plane[g.index(10, 10)] = 2.0;
        let added = p.apply(&g, &prev, &mut plane, 0.0, 1e30);
        assert_eq!(added, 1.0);
        assert_eq!(plane[g.index(10, 10)], 3.0);
        assert_eq!(plane.iter().filter(|&&v| v != 0.0).count(), 1);
        // Without `sources` the same message is a Z-shape over many cells.
        spec.sources = None;
        let p = prepare(&msg, &g, &[spec], &DepositLimits::default()).unwrap();
        let mut plane = vec![0.0; g.cells()];
        p.apply(&g, &prev, &mut plane, 0.0, 1e30);
        assert!(plane.iter().filter(|&&v| v != 0.0).count() > 100);
    }

    #[test]
    fn a_source_channel_needs_the_quantum_model_and_no_diffusion() {
        use crate::models::{ChannelSpec, Evaporation};
        let mut spec = ChannelSpec::new("trail", Evaporation::None);
        spec.sources = Some(SourceSensing::new(0.05, 0.2));
        let e = spec.validate(0.1, 0.05).unwrap_err().to_string();
        assert!(e.contains("quantum"), "{e}");
        spec.evaporation = Evaporation::Quantum {
            quantum: 1.0,
            tau_s: 1.0,
        };
        assert!(spec.validate(0.1, 0.05).is_ok());
        spec.diffusion_m2_per_s = 1e-4;
        let e = spec.validate(0.1, 0.05).unwrap_err().to_string();
        assert!(e.contains("diffuse"), "{e}");
    }

    #[test]
    fn settings_out_of_range_are_refused_by_name() {
        let mut s = SourceSensing::new(0.05, 0.2);
        assert!(s.validate("c").is_ok());
        s.fov_deg = 0.0;
        assert!(s.validate("c").unwrap_err().to_string().contains("fov_deg"));
        s.fov_deg = 180.0;
        s.splay_deg = 91.0;
        assert!(s
            .validate("c")
            .unwrap_err()
            .to_string()
            .contains("splay_deg"));
        let zero = SourceSensing::new(0.0, 0.0);
        assert!(zero.validate("c").is_err());
    }
}
