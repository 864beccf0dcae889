//! The planar geometry that robots and the simulator share: a pose in the world frame
//! ([`WorldPose`]), point landmarks ([`Landmark`]), wall segments ([`Segment`]), the noise of
//! odometry and range/bearing sensing ([`NoiseConfig`]) and `sinc` for the motion model. The
//! robot stack (localizers, followers) reads them from here; the simulator
//! (`pheromone_world`) produces them. None of them is a wire message.

use serde::{Deserialize, Serialize};

/// A planar pose: metres and radians, θ counter-clockwise from +x.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldPose {
    /// x position in the world frame (m).
    pub x_m: f64,
    /// y position in the world frame (m).
    pub y_m: f64,
    /// Heading (rad, counter-clockwise from +x); not necessarily wrapped.
    pub theta_rad: f64,
}

impl WorldPose {
    /// A pose from its coordinates (m, m, rad).
    pub fn new(x_m: f64, y_m: f64, theta_rad: f64) -> Self {
        Self {
            x_m,
            y_m,
            theta_rad,
        }
    }

    /// Every coordinate is finite.
    pub fn is_finite(&self) -> bool {
        self.x_m.is_finite() && self.y_m.is_finite() && self.theta_rad.is_finite()
    }
}

/// sin(x)/x, exact near 0.
pub fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        1.0 - x * x / 6.0
    } else {
        x.sin() / x
    }
}

/// d/dx of sin(x)/x, exact near 0.
pub fn sinc_derivative(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        -x / 3.0 + x * x * x / 30.0
    } else {
        (x * x.cos() - x.sin()) / (x * x)
    }
}

/// A point landmark with a signature (0 = no signature / ambiguous).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Landmark {
    /// x position in the world frame (m).
    pub x_m: f64,
    /// y position in the world frame (m).
    pub y_m: f64,
    /// Identifying signature sensed with the landmark; 0 (the default) = none / ambiguous.
    #[serde(default)]
    pub signature: u32,
}

/// A wall segment from `a_m` to `b_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// One end, `[x, y]` in the world frame (m).
    pub a_m: [f64; 2],
    /// The other end, `[x, y]` in the world frame (m).
    pub b_m: [f64; 2],
}

/// Sensor and odometry noise. The α's are those of the velocity motion model (seed 001
/// Algorithm 1 line 5): σ_v² = α1·v² + α2·ω², σ_ω² = α3·v² + α4·ω².
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NoiseConfig {
    /// Standard deviation of the measured range.
    pub range_sigma_m: f64,
    /// Standard deviation of the measured bearing.
    pub bearing_sigma_rad: f64,
    /// (m/s)² of v-noise per (m/s)² of v.
    pub alpha1: f64,
    /// (m/s)² of v-noise per (rad/s)² of ω.
    pub alpha2: f64,
    /// (rad/s)² of ω-noise per (m/s)² of v.
    pub alpha3: f64,
    /// (rad/s)² of ω-noise per (rad/s)² of ω.
    pub alpha4: f64,
}

impl Default for NoiseConfig {
    fn default() -> Self {
        Self {
            range_sigma_m: 0.05,
            bearing_sigma_rad: 0.02,
            alpha1: 0.01,
            alpha2: 0.001,
            alpha3: 0.001,
            alpha4: 0.01,
        }
    }
}

impl NoiseConfig {
    /// No noise at all (for tests and ground-truth runs).
    pub fn zero() -> Self {
        Self {
            range_sigma_m: 0.0,
            bearing_sigma_rad: 0.0,
            alpha1: 0.0,
            alpha2: 0.0,
            alpha3: 0.0,
            alpha4: 0.0,
        }
    }

    /// Variances (σ_v², σ_ω²) of the control noise for a command (seed 001 Algorithm 1 line 5).
    pub fn control_variances(&self, v_m_per_s: f64, omega_rad_per_s: f64) -> (f64, f64) {
        let (v2, w2) = (v_m_per_s * v_m_per_s, omega_rad_per_s * omega_rad_per_s);
        (
            self.alpha1 * v2 + self.alpha2 * w2,
            self.alpha3 * v2 + self.alpha4 * w2,
        )
    }

    /// The first field that is negative or not finite.
    pub fn validate(&self) -> Result<(), (&'static str, f64)> {
        let fields = [
            ("range_sigma_m", self.range_sigma_m),
            ("bearing_sigma_rad", self.bearing_sigma_rad),
            ("alpha1", self.alpha1),
            ("alpha2", self.alpha2),
            ("alpha3", self.alpha3),
            ("alpha4", self.alpha4),
        ];
        for (name, value) in fields {
            if !(value.is_finite() && value >= 0.0) {
                return Err((name, value));
            }
        }
        Ok(())
    }
}
