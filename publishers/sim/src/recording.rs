//! What a simulation run records, whichever way it ran (one process in lockstep, or separate
//! processes observed from outside): per-robot time series, field snapshots at chosen times and
//! probe readings. `pheromone_report` turns a [`Recording`] into files.

use std::collections::BTreeMap;

use serde::Serialize;

use pheromone_messages::FollowerState;

/// One row of a robot's time series (one world step).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RobotSample {
    /// Simulated time (s).
    pub t_s: f64,
    /// True pose from the world: x (m), y (m), θ (rad).
    pub true_pose: [f64; 3],
    /// The localizer's estimate, if it has published one for this step.
    pub est_pose: Option<[f64; 3]>,
    /// √(largest eigenvalue of the estimate's position covariance) (m).
    pub est_sigma_m: Option<f64>,
    /// Commanded forward speed (m/s) and turn rate (rad/s).
    pub v_m_per_s: f64,
    pub omega_rad_per_s: f64,
    /// The follower's state and the level it sensed, if the robot has a follower.
    pub state: Option<FollowerState>,
    pub sensed_level: Option<f32>,
    /// The peak of the deposit the robot's depositor sent at this step, if it sent one:
    /// γ = τ/det Σxy capped at γmax for the ellipse kernels (seed 000 eq. 12), ρt for a
    /// saturating deposit, the amount for a Z-shape ([`deposit_peak`]).
    pub deposit_peak: Option<f32>,
}

/// The value a deposit adds at its centre, before any saturation by what the cell holds: γ of
/// seed 000 eq. 12 (as the field computes it) for the ellipse kernels, the amount otherwise.
pub fn deposit_peak(m: &pheromone_field::DepositMsg) -> f32 {
    use pheromone_field::deposit::{gamma, ErrorEllipse};
    match pheromone_field::KernelKind::from_code(m.kernel) {
        Some(pheromone_field::KernelKind::Ellipse | pheromone_field::KernelKind::Paper) => gamma(
            m.amount,
            ErrorEllipse::from_cov(m.cov_xx, m.cov_xy, m.cov_yy).det(),
            m.gamma_max,
        ),
        _ => m.amount,
    }
}

/// A copy of the field at one time (planes `channel, y, x`, as in shared memory).
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    pub t_s: f64,
    pub width: u32,
    pub height: u32,
    pub cell_size_m: f32,
    pub channels: Vec<String>,
    pub planes: Vec<f32>,
}

impl Snapshot {
    /// The plane of channel `c` (`height` rows of `width` cells, row 0 at y = 0).
    pub fn plane(&self, c: usize) -> &[f32] {
        let n = self.width as usize * self.height as usize;
        &self.planes[c * n..(c + 1) * n]
    }
}

/// A probe: the field value at a point and time, recorded during the run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ProbeReading {
    pub t_s: f64,
    pub x_m: f32,
    pub y_m: f32,
    pub channel: u32,
    pub value: f32,
}

/// Everything a run recorded.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    /// Time series by robot id.
    pub robots: BTreeMap<u32, Vec<RobotSample>>,
    pub snapshots: Vec<Snapshot>,
    pub probes: Vec<ProbeReading>,
    /// Wall segments of the world, ([x0, y0], [x1, y1]) in metres, to draw on the pictures.
    pub walls: Vec<([f64; 2], [f64; 2])>,
    /// The channel the world marks its walls on (`[mark_walls]`), if any: the pictures scale
    /// the pheromone channels on their own, without it.
    pub wall_channel: Option<usize>,
    /// Seed 004's final local maps and merges, when the scenario maps.
    pub mapping: Option<pheromone_world::team::MappingRecord>,
}

impl Recording {
    /// Distance travelled by a robot along its true trajectory (m).
    pub fn distance_travelled_m(&self, robot: u32) -> f64 {
        self.robots
            .get(&robot)
            .map(|rows| {
                rows.windows(2)
                    .map(|w| {
                        let (a, b) = (w[0].true_pose, w[1].true_pose);
                        ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()
                    })
                    .sum()
            })
            .unwrap_or(0.0)
    }

    /// First time the robot's follower reported the trail abandoned (stopping, or exploring
    /// on its own as `leader_lost`), if ever.
    pub fn trail_abandoned_at_s(&self, robot: u32) -> Option<f64> {
        self.first_in_state(robot, |s| {
            matches!(s, FollowerState::TrailAbandoned | FollowerState::LeaderLost)
        })
        .map(|r| r.t_s)
    }

    /// The first sample of the robot whose follower state satisfies `pred`.
    pub fn first_in_state(
        &self,
        robot: u32,
        pred: impl Fn(FollowerState) -> bool,
    ) -> Option<&RobotSample> {
        self.robots
            .get(&robot)
            .and_then(|rows| rows.iter().find(|r| r.state.is_some_and(&pred)))
    }
}
