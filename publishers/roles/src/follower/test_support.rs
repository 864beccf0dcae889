//! Test helpers shared by the follower strategies' unit tests: synthetic fields, a unicycle
//! robot and the closed-loop simulation.

use pheromone_field::{FrameView, GridGeometry, SamplePose};

use super::{wrap_angle, Decision, FollowerStrategy};

/// A one-channel synthetic field sampled at cell centres.
pub(super) fn synth(
    width_m: f32,
    height_m: f32,
    cell_m: f32,
    f: impl Fn(f32, f32) -> f32,
) -> (GridGeometry, Vec<f32>) {
    let g = GridGeometry::new(
        (width_m / cell_m).round() as u32,
        (height_m / cell_m).round() as u32,
        cell_m,
    )
    .unwrap();
    let mut cells = vec![0.0; g.cells()];
    for y in 0..g.height {
        for x in 0..g.width {
            let (wx, wy) = g.world_from_grid(x, y);
            cells[g.index(x, y)] = f(wx, wy);
        }
    }
    (g, cells)
}

/// Unicycle kinematics over one step (midpoint heading), in f64.
#[derive(Debug, Clone, Copy)]
pub(super) struct Robot {
    pub(super) x: f64,
    pub(super) y: f64,
    pub(super) th: f64,
}

impl Robot {
    pub(super) fn new(x: f64, y: f64, th: f64) -> Self {
        Self { x, y, th }
    }
    pub(super) fn pose(&self) -> SamplePose {
        SamplePose::new(self.x as f32, self.y as f32, self.th as f32)
    }
    pub(super) fn advance(&mut self, d: &Decision, dt: f64) {
        let mid = self.th + 0.5 * d.omega_rad_per_s * dt;
        self.x += d.v_m_per_s * mid.cos() * dt;
        self.y += d.v_m_per_s * mid.sin() * dt;
        self.th = wrap_angle(self.th + d.omega_rad_per_s * dt);
    }
}

pub(super) fn simulate(
    s: &mut dyn FollowerStrategy,
    frame: &FrameView<'_>,
    mut r: Robot,
    dt: f64,
    steps: usize,
) -> Vec<(Robot, Decision)> {
    (0..steps)
        .map(|_| {
            let d = s.decide(frame, r.pose(), dt);
            r.advance(&d, dt);
            (r, d)
        })
        .collect()
}

pub(super) fn gaussian_ridge(d: f32, amp: f32, sigma: f32) -> f32 {
    amp * (-d * d / (2.0 * sigma * sigma)).exp()
}

/// Signed angle (rad, counter-clockwise positive) a trace sweeps around `centre`.
pub(super) fn swept_rad(trace: &[(Robot, Decision)], centre: (f64, f64)) -> f64 {
    let polar = |r: &Robot| (r.y - centre.1).atan2(r.x - centre.0);
    trace
        .windows(2)
        .map(|w| wrap_angle(polar(&w[1].0) - polar(&w[0].0)))
        .sum()
}

pub(super) fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n as f64
}

/// Half the field (left of the robot) is saturated with pheromone.
pub(super) fn half_field() -> (GridGeometry, Vec<f32>) {
    synth(10.0, 10.0, 0.1, |_, y| if y > 5.0 { 0.9 } else { 0.1 })
}
