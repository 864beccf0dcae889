//! Landmark-based EKF localization (seed 001 Algorithm 1) and EKF-SLAM.
//!
//! - [`Ekf`]: state (x, y, θ) and its 3×3 covariance (nalgebra). Prediction with the velocity
//!   motion model (Algorithm 1 lines 2–7), correction with range/bearing/signature observations
//!   of known landmarks with maximum-likelihood association (lines 8–25), optionally restricted
//!   to a subset of landmarks (lines 10–14, [`Ekf::set_landmark_filter`]). A [`LossConfig`]
//!   makes the filter lose its localization on purpose, as the leader of seed 000 does.
//! - [`EkfSlam`]: the same models with unknown landmarks added to the state (3 + 2N), the large
//!   covariance algebra in `faer`.
//!
//! Bad input (non-finite or absurd odometry, a bad `dt`, non-finite or negative ranges) is
//! rejected with a [`LocalizerError`] and counted by reason in [`EkfCounters`]; a rejected
//! input never touches the state.
//!
//! Deviations from the paper (MODELS.md M2 rules where it is silent):
//! - The signature is used for association only (a landmark matches an observation when the
//!   signatures are equal or either is 0), not as a third measurement dimension with σ_s
//!   (Algorithm 1 lines 8, 17, 18: its row of H is zero, so it never changes the estimate).
//! - Algorithm 1 line 18 as printed has sign errors in H; the Jacobian of line 17 is used:
//!   H = [[−δx/√q, −δy/√q, 0], [δy/q, −δx/q, −1]].
//! - Lines 3, 4 and 6 are evaluated in the equivalent chord form (sin(θ+ωΔt) − sin θ =
//!   2 cos(θ+ωΔt/2) sin(ωΔt/2)), which is identical for ω ≠ 0 and has the straight-line limit
//!   at ω = 0.
//! - Line 21's argmax is taken among the landmarks inside a χ² gate; no landmark inside the
//!   gate means the observation is not used.
//! - Line 24 is replaced by the Joseph form (I − KH)Σ(I − KH)ᵀ + KQKᵀ, then symmetrized.

pub mod run;

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par, Side};
use nalgebra::{Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::messages::{LandmarkObs, PoseMsg, SensorMsg, MAX_OBSERVATIONS};
use crate::roles::world::{sinc, sinc_derivative, wrap_angle, Landmark, NoiseConfig, Pose2};

/// Inputs beyond these limits are rejected as absurd.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InputLimits {
    /// Largest accepted time step.
    pub max_dt_secs: f64,
    /// Largest accepted |v| of the odometry.
    pub max_speed_mps: f64,
    /// Largest accepted |ω| of the odometry.
    pub max_turn_rate_radps: f64,
    /// Largest accepted observed range.
    pub max_range_m: f64,
}

impl Default for InputLimits {
    fn default() -> Self {
        Self {
            max_dt_secs: 1.0,
            max_speed_mps: 10.0,
            max_turn_rate_radps: 20.0,
            max_range_m: 1000.0,
        }
    }
}

/// Makes the filter lose its localization on purpose (the "leader lost" of seed 000): from
/// `after_s` of filter time on, observations are dropped (or their signatures made ambiguous)
/// and the motion noise is inflated, so the covariance grows.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossConfig {
    /// Filter time (sum of predicted `dt`) from which the robot is lost; `None` = never.
    pub after_s: Option<f64>,
    /// Fraction of observations dropped while lost, in [0, 1] (deterministic: an error
    /// accumulator drops exactly this share).
    pub landmark_dropout: f64,
    /// Factor (≥ 1) on the control noise M_t while lost.
    pub noise_inflation: f64,
    /// While lost, the kept observations lose their signatures (association by likelihood
    /// only, so wrong matches become possible).
    pub ambiguous_signatures: bool,
}

impl Default for LossConfig {
    fn default() -> Self {
        Self {
            after_s: None,
            landmark_dropout: 1.0,
            noise_inflation: 10.0,
            ambiguous_signatures: false,
        }
    }
}

/// Settings of [`Ekf`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EkfConfig {
    /// Model noise: α1..α4 for M_t (line 5), σ_r and σ_φ for Q_t (line 8).
    pub noise: NoiseConfig,
    /// χ² gate on the Mahalanobis distance of an innovation (2 DOF; 9.21 = 99 %).
    pub gate_chi2: f64,
    pub limits: InputLimits,
    pub loss: LossConfig,
    /// `landmark_region_m = [min_x, min_y, max_x, max_y]` (m, world frame): the captured area
    /// of seed 001 Algorithm 1 lines 10–14. When set, [`Ekf::new`] restricts association to the
    /// map landmarks inside this axis-aligned box (edges included), so an observation is
    /// compared only with l(A_c) instead of the whole map; an observation of a landmark outside
    /// finds no candidate and counts as `observations_unmatched`. A box holding no landmark is
    /// allowed (every observation is then unmatched). Unset (the default) = the whole map.
    /// Must be finite with min < max. `pheromone localizer --landmark-region` overrides it; the
    /// filter can be changed later with [`Ekf::set_landmark_filter`]. EKF with a known map
    /// only: EKF-SLAM refuses it.
    pub landmark_region_m: Option<[f64; 4]>,
}

impl Default for EkfConfig {
    fn default() -> Self {
        Self {
            noise: NoiseConfig::default(),
            gate_chi2: 9.21,
            limits: InputLimits::default(),
            loss: LossConfig::default(),
            landmark_region_m: None,
        }
    }
}

impl EkfConfig {
    /// Checks every setting (what [`Ekf::new`] checks besides the map and the initial state).
    pub fn validate(&self) -> Result<(), LocalizerError> {
        validate_common(&self.noise, &self.limits, self.gate_chi2)?;
        let loss = &self.loss;
        if let Some(t) = loss.after_s {
            if !t.is_finite() {
                return Err(invalid("loss.after_s", t, "finite"));
            }
        }
        if !(0.0..=1.0).contains(&loss.landmark_dropout) {
            return Err(invalid(
                "loss.landmark_dropout",
                loss.landmark_dropout,
                "in [0, 1]",
            ));
        }
        if !(loss.noise_inflation.is_finite() && loss.noise_inflation >= 1.0) {
            return Err(invalid(
                "loss.noise_inflation",
                loss.noise_inflation,
                "finite and >= 1",
            ));
        }
        if let Some(region) = self.landmark_region_m {
            check_landmark_region(region, LANDMARK_REGION_KEY)?;
        }
        Ok(())
    }
}

/// The [`EkfConfig`] key of the captured area.
pub const LANDMARK_REGION_KEY: &str = "landmark_region_m";
/// The `pheromone localizer` flag that overrides [`LANDMARK_REGION_KEY`].
pub const LANDMARK_REGION_FLAG: &str = "--landmark-region";

/// Checks a landmark region `[min_x, min_y, max_x, max_y]` (m): finite, min_x < max_x and
/// min_y < max_y. `key` names the setting in the error.
pub fn check_landmark_region(
    region: [f64; 4],
    key: &'static str,
) -> Result<[f64; 4], LocalizerError> {
    let bad = |expected| LocalizerError::InvalidRegion {
        key,
        value: format!("{region:?}"),
        expected,
    };
    if !region.iter().all(|v| v.is_finite()) {
        return Err(bad("four finite numbers [min_x, min_y, max_x, max_y]"));
    }
    let [min_x, min_y, max_x, max_y] = region;
    if !(min_x < max_x && min_y < max_y) {
        return Err(bad("min_x < max_x and min_y < max_y"));
    }
    Ok(region)
}

/// Parses the `--landmark-region XMIN,YMIN,XMAX,YMAX` flag (m) and checks it like
/// [`check_landmark_region`]; the error names the flag and the text given.
pub fn parse_landmark_region(text: &str) -> Result<[f64; 4], LocalizerError> {
    let bad = |expected| LocalizerError::InvalidRegion {
        key: LANDMARK_REGION_FLAG,
        value: format!("{text:?}"),
        expected,
    };
    let numbers: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad("four comma-separated numbers XMIN,YMIN,XMAX,YMAX in metres"))?;
    let region: [f64; 4] = numbers
        .try_into()
        .map_err(|_| bad("four comma-separated numbers XMIN,YMIN,XMAX,YMAX in metres"))?;
    check_landmark_region(region, LANDMARK_REGION_FLAG).map_err(|e| match e {
        LocalizerError::InvalidRegion { expected, .. } => bad(expected),
        other => other,
    })
}

/// Why an input or a setting was rejected.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum LocalizerError {
    /// Odometry v or ω is NaN or infinite.
    #[error("odometry is not finite: v = {v_mps} m/s, omega = {omega_radps} rad/s")]
    NonFiniteOdometry { v_mps: f64, omega_radps: f64 },
    /// Odometry beyond [`InputLimits`].
    #[error("odometry is absurd: v = {v_mps} m/s, omega = {omega_radps} rad/s exceed the limits")]
    AbsurdOdometry { v_mps: f64, omega_radps: f64 },
    /// `dt` not finite, ≤ 0 or above `max_dt_secs`.
    #[error("dt_secs = {dt_secs} is not in (0, {max_dt_secs}]")]
    BadDt { dt_secs: f64, max_dt_secs: f64 },
    /// An observation's range or bearing is NaN or infinite.
    #[error("observation {index} is not finite")]
    NonFiniteObservation { index: usize },
    /// An observation's range is negative or beyond `max_range_m`.
    #[error("observation {index}: range {range_m} m is negative or beyond {max_range_m} m")]
    BadRange {
        index: usize,
        range_m: f64,
        max_range_m: f64,
    },
    /// A sensor message claims more observations than it can carry.
    #[error("sensor message count {count} exceeds {max}")]
    BadObservationCount { count: u32, max: usize },
    /// A setting is out of range.
    #[error("localizer config: `{field}` = {value} is invalid ({expected})")]
    InvalidConfig {
        field: String,
        value: f64,
        expected: &'static str,
    },
    /// The initial mean is not finite or the covariance not symmetric positive semi-definite.
    #[error("initial state: mean not finite or covariance not symmetric positive semi-definite")]
    InvalidInitialState,
    /// A landmark region (`landmark_region_m`, `--landmark-region`) is not four finite numbers
    /// with min < max.
    #[error("`{key}` = {value} is invalid ({expected})")]
    InvalidRegion {
        key: &'static str,
        value: String,
        expected: &'static str,
    },
    /// A landmark filter names a landmark the map does not have.
    #[error("landmark index {index} is out of range (the map has {len})")]
    LandmarkIndexOutOfRange { index: usize, len: usize },
}

/// What the filter did, including rejections by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EkfCounters {
    pub predictions: u64,
    /// Observations that corrected the state.
    pub observations_used: u64,
    /// Observations whose best candidate lay outside the χ² gate.
    pub observations_gated: u64,
    /// Observations with no candidate landmark (signature or filter).
    pub observations_unmatched: u64,
    /// Observations dropped by [`LossConfig`].
    pub observations_dropped: u64,
    /// Landmarks added to the state (EKF-SLAM).
    pub landmarks_added: u64,
    pub rejected_non_finite_odometry: u64,
    pub rejected_absurd_odometry: u64,
    pub rejected_bad_dt: u64,
    pub rejected_non_finite_observation: u64,
    pub rejected_bad_range: u64,
    pub rejected_bad_count: u64,
}

impl EkfCounters {
    /// All rejected inputs.
    pub fn rejected_total(&self) -> u64 {
        self.rejected_non_finite_odometry
            + self.rejected_absurd_odometry
            + self.rejected_bad_dt
            + self.rejected_non_finite_observation
            + self.rejected_bad_range
            + self.rejected_bad_count
    }

    fn count(&mut self, e: &LocalizerError) {
        match e {
            LocalizerError::NonFiniteOdometry { .. } => self.rejected_non_finite_odometry += 1,
            LocalizerError::AbsurdOdometry { .. } => self.rejected_absurd_odometry += 1,
            LocalizerError::BadDt { .. } => self.rejected_bad_dt += 1,
            LocalizerError::NonFiniteObservation { .. } => {
                self.rejected_non_finite_observation += 1
            }
            LocalizerError::BadRange { .. } => self.rejected_bad_range += 1,
            LocalizerError::BadObservationCount { .. } => self.rejected_bad_count += 1,
            LocalizerError::InvalidConfig { .. }
            | LocalizerError::InvalidRegion { .. }
            | LocalizerError::InvalidInitialState
            | LocalizerError::LandmarkIndexOutOfRange { .. } => {}
        }
    }
}

/// What one correction did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UpdateStats {
    /// Observations that corrected the state.
    pub used: u32,
    /// Observations outside the gate.
    pub gated: u32,
    /// Observations with no candidate landmark.
    pub unmatched: u32,
    /// Observations dropped by the loss knob.
    pub dropped: u32,
    /// Landmarks added (EKF-SLAM).
    pub added: u32,
}

// ---------------------------------------------------------------------------------------------
// Models shared by Ekf and EkfSlam

/// Velocity motion model: the pose change, G_t and V_t (seed 001 Algorithm 1 lines 3, 4, 6).
///
/// Written with sin(θ+ωΔt) − sin θ = 2 cos(θ+a) sin a and cos θ − cos(θ+ωΔt) = 2 sin(θ+a) sin a,
/// a = ωΔt/2, so that −(v/ω) sin θ + (v/ω) sin(θ+ωΔt) = vΔt·sinc(a)·cos(θ+a): the same values
/// for ω ≠ 0, and the straight-line limit (vΔt cos θ, vΔt sin θ) at ω = 0.
fn velocity_motion(
    theta: f64,
    v: f64,
    w: f64,
    dt: f64,
) -> (Vector3<f64>, Matrix3<f64>, Matrix3x2<f64>) {
    let a = 0.5 * w * dt;
    let (s, ds) = (sinc(a), sinc_derivative(a));
    let (c_mid, s_mid) = ((theta + a).cos(), (theta + a).sin());
    let dx = v * dt * s * c_mid;
    let dy = v * dt * s * s_mid;
    let delta = Vector3::new(dx, dy, w * dt); // line 6
    #[rustfmt::skip]
    let g = Matrix3::new( // line 3
        1.0, 0.0, -dy,
        0.0, 1.0, dx,
        0.0, 0.0, 1.0,
    );
    let half_vdt2 = 0.5 * v * dt * dt;
    #[rustfmt::skip]
    let vj = Matrix3x2::new( // line 4
        dt * s * c_mid, half_vdt2 * (ds * c_mid - s * s_mid),
        dt * s * s_mid, half_vdt2 * (ds * s_mid + s * c_mid),
        0.0, dt,
    );
    (delta, g, vj)
}

/// Control noise M_t (seed 001 Algorithm 1 line 5), times `inflation`.
fn control_noise(noise: &NoiseConfig, v: f64, w: f64, inflation: f64) -> Matrix2<f64> {
    let (var_v, var_w) = noise.control_variances(v, w);
    Matrix2::new(inflation * var_v, 0.0, 0.0, inflation * var_w)
}

/// Measurement noise Q_t (seed 001 Algorithm 1 line 8, without the signature row).
fn measurement_noise(noise: &NoiseConfig) -> Matrix2<f64> {
    Matrix2::new(
        noise.range_sigma_m.powi(2),
        0.0,
        0.0,
        noise.bearing_sigma_rad.powi(2),
    )
}

/// Predicted range/bearing of a landmark and the Jacobian w.r.t. the robot pose (seed 001
/// Algorithm 1 lines 16–18, line 18 with corrected signs). The Jacobian w.r.t. the landmark is
/// the negated first two columns. `None` when the landmark sits on the robot.
fn predict_measurement(
    robot: &Vector3<f64>,
    lm_x: f64,
    lm_y: f64,
) -> Option<(Vector2<f64>, Matrix2x3<f64>)> {
    let dx = lm_x - robot.x;
    let dy = lm_y - robot.y;
    let q = dx * dx + dy * dy; // line 16
    if q < 1e-12 {
        return None;
    }
    let sq = q.sqrt();
    let z_hat = Vector2::new(sq, wrap_angle(dy.atan2(dx) - robot.z)); // line 17
    #[rustfmt::skip]
    let h = Matrix2x3::new( // line 18
        -dx / sq, -dy / sq, 0.0,
        dy / q, -dx / q, -1.0,
    );
    Some((z_hat, h))
}

fn innovation(obs: &LandmarkObs, z_hat: &Vector2<f64>) -> Vector2<f64> {
    Vector2::new(
        f64::from(obs.range_m) - z_hat.x,
        wrap_angle(f64::from(obs.bearing_rad) - z_hat.y),
    )
}

/// Mahalanobis distance² and −2·log-likelihood (line 21) of an innovation.
fn score(nu: &Vector2<f64>, s: &Matrix2<f64>) -> Option<(f64, f64)> {
    let det = s.determinant();
    if !(det.is_finite() && det > 0.0) {
        return None;
    }
    let s_inv = s.try_inverse()?;
    let d2 = (nu.transpose() * s_inv * nu)[(0, 0)];
    let neg2_log_l = d2 + (std::f64::consts::TAU.powi(2) * det).ln();
    Some((d2, neg2_log_l))
}

fn signatures_match(observed: u32, landmark: u32) -> bool {
    observed == 0 || landmark == 0 || observed == landmark
}

fn check_odometry(
    limits: &InputLimits,
    v_mps: f64,
    omega_radps: f64,
    dt_secs: f64,
) -> Result<(), LocalizerError> {
    if !(v_mps.is_finite() && omega_radps.is_finite()) {
        return Err(LocalizerError::NonFiniteOdometry { v_mps, omega_radps });
    }
    if !(dt_secs.is_finite() && dt_secs > 0.0 && dt_secs <= limits.max_dt_secs) {
        return Err(LocalizerError::BadDt {
            dt_secs,
            max_dt_secs: limits.max_dt_secs,
        });
    }
    if v_mps.abs() > limits.max_speed_mps || omega_radps.abs() > limits.max_turn_rate_radps {
        return Err(LocalizerError::AbsurdOdometry { v_mps, omega_radps });
    }
    Ok(())
}

fn check_observations(limits: &InputLimits, obs: &[LandmarkObs]) -> Result<(), LocalizerError> {
    for (index, o) in obs.iter().enumerate() {
        if !(o.range_m.is_finite() && o.bearing_rad.is_finite()) {
            return Err(LocalizerError::NonFiniteObservation { index });
        }
        let range_m = f64::from(o.range_m);
        if range_m < 0.0 || range_m > limits.max_range_m {
            return Err(LocalizerError::BadRange {
                index,
                range_m,
                max_range_m: limits.max_range_m,
            });
        }
    }
    Ok(())
}

/// Checks a whole sensor message: odometry, `dt`, count and observations.
fn check_message(limits: &InputLimits, msg: &SensorMsg) -> Result<(), LocalizerError> {
    check_odometry(limits, msg.v_mps, msg.omega_radps, msg.dt_secs)?;
    if msg.count as usize > MAX_OBSERVATIONS {
        return Err(LocalizerError::BadObservationCount {
            count: msg.count,
            max: MAX_OBSERVATIONS,
        });
    }
    check_observations(limits, msg.observations())
}

fn invalid(field: impl Into<String>, value: f64, expected: &'static str) -> LocalizerError {
    LocalizerError::InvalidConfig {
        field: field.into(),
        value,
        expected,
    }
}

fn validate_common(
    noise: &NoiseConfig,
    limits: &InputLimits,
    gate_chi2: f64,
) -> Result<(), LocalizerError> {
    noise
        .validate()
        .map_err(|(f, v)| invalid(format!("noise.{f}"), v, "finite and >= 0"))?;
    if !(noise.range_sigma_m > 0.0 && noise.bearing_sigma_rad > 0.0) {
        return Err(invalid(
            "noise.range_sigma_m / noise.bearing_sigma_rad",
            noise.range_sigma_m.min(noise.bearing_sigma_rad),
            "> 0: Q_t must be invertible",
        ));
    }
    let positive = [
        ("gate_chi2", gate_chi2),
        ("limits.max_dt_secs", limits.max_dt_secs),
        ("limits.max_speed_mps", limits.max_speed_mps),
        ("limits.max_turn_rate_radps", limits.max_turn_rate_radps),
        ("limits.max_range_m", limits.max_range_m),
    ];
    for (name, value) in positive {
        if value.is_nan() || value <= 0.0 {
            return Err(invalid(name, value, "> 0"));
        }
    }
    Ok(())
}

/// Whether a 3×3 covariance is finite, symmetric and positive semi-definite.
fn valid_covariance3(cov: &Matrix3<f64>) -> bool {
    if !cov.iter().all(|v| v.is_finite()) {
        return false;
    }
    let scale = cov.abs().max().max(1e-300);
    if (cov - cov.transpose()).abs().max() > 1e-9 * scale {
        return false;
    }
    cov.symmetric_eigenvalues().min() >= -1e-12 * scale
}

fn symmetrize3(cov: &Matrix3<f64>) -> Matrix3<f64> {
    (cov + cov.transpose()) * 0.5
}

fn pose_msg(
    mean: &Vector3<f64>,
    cov: &Matrix3<f64>,
    robot_id: u32,
    step: u64,
    used: u32,
) -> PoseMsg {
    let mut flat = [0.0; 9];
    for r in 0..3 {
        for c in 0..3 {
            flat[r * 3 + c] = cov[(r, c)];
        }
    }
    PoseMsg {
        stamp_ns: 0,
        step,
        robot_id,
        landmarks_used: used,
        x_m: mean.x,
        y_m: mean.y,
        theta_rad: mean.z,
        cov: flat,
    }
}

// ---------------------------------------------------------------------------------------------
// EKF localization with a known map

/// Landmark-based EKF localization (seed 001 Algorithm 1).
#[derive(Debug, Clone)]
pub struct Ekf {
    config: EkfConfig,
    map: Vec<Landmark>,
    filter: Option<Vec<usize>>,
    mean: Vector3<f64>,
    cov: Matrix3<f64>,
    time_s: f64,
    dropout_acc: f64,
    last_used: u32,
    counters: EkfCounters,
}

impl Ekf {
    /// A filter over the known `map`, starting at `initial_pose` with `initial_cov` (symmetric
    /// positive semi-definite; zero means "known exactly").
    pub fn new(
        config: EkfConfig,
        map: Vec<Landmark>,
        initial_pose: Pose2,
        initial_cov: Matrix3<f64>,
    ) -> Result<Self, LocalizerError> {
        config.validate()?;
        for (i, lm) in map.iter().enumerate() {
            if !(lm.x_m.is_finite() && lm.y_m.is_finite()) {
                return Err(invalid(format!("map[{i}]"), f64::NAN, "finite coordinates"));
            }
        }
        let mean = Vector3::new(
            initial_pose.x_m,
            initial_pose.y_m,
            wrap_angle(initial_pose.theta_rad),
        );
        if !mean.iter().all(|v| v.is_finite()) || !valid_covariance3(&initial_cov) {
            return Err(LocalizerError::InvalidInitialState);
        }
        let mut ekf = Self {
            config,
            map,
            filter: None,
            mean,
            cov: symmetrize3(&initial_cov),
            time_s: 0.0,
            dropout_acc: 0.0,
            last_used: 0,
            counters: EkfCounters::default(),
        };
        if let Some([min_x, min_y, max_x, max_y]) = config.landmark_region_m {
            // Algorithm 1 lines 10–11: only the landmarks of the captured area, l(A_c, m).
            ekf.filter = Some(ekf.landmarks_in_region(min_x, min_y, max_x, max_y));
        }
        Ok(ekf)
    }

    /// The landmark filter in effect: map indices association runs over, `None` = all.
    pub fn landmark_filter(&self) -> Option<&[usize]> {
        self.filter.as_deref()
    }

    /// Prediction with the velocity motion model (seed 001 Algorithm 1 lines 2–7). While lost
    /// (see [`LossConfig`]) M_t is multiplied by `noise_inflation`.
    pub fn predict(
        &mut self,
        v_mps: f64,
        omega_radps: f64,
        dt_secs: f64,
    ) -> Result<(), LocalizerError> {
        if let Err(e) = check_odometry(&self.config.limits, v_mps, omega_radps, dt_secs) {
            self.counters.count(&e);
            return Err(e);
        }
        self.predict_unchecked(v_mps, omega_radps, dt_secs);
        Ok(())
    }

    fn predict_unchecked(&mut self, v: f64, w: f64, dt: f64) {
        let (delta, g, vj) = velocity_motion(self.mean.z, v, w, dt);
        let inflation = if self.is_lost() {
            self.config.loss.noise_inflation
        } else {
            1.0
        };
        let m = control_noise(&self.config.noise, v, w, inflation); // line 5
        let mut mean = self.mean + delta; // line 6
        mean.z = wrap_angle(mean.z);
        let cov = g * self.cov * g.transpose() + vj * m * vj.transpose(); // line 7
        self.mean = mean;
        self.cov = symmetrize3(&cov);
        self.time_s += dt;
        self.counters.predictions += 1;
    }

    /// Correction with landmark observations (seed 001 Algorithm 1 lines 8–25), one observation
    /// after the other. All observations are checked first; one bad observation rejects the
    /// whole set and leaves the state untouched.
    pub fn update(&mut self, observations: &[LandmarkObs]) -> Result<UpdateStats, LocalizerError> {
        if let Err(e) = check_observations(&self.config.limits, observations) {
            self.counters.count(&e);
            return Err(e);
        }
        Ok(self.update_unchecked(observations))
    }

    /// One world step: prediction with the message's odometry and `dt_secs`, then correction
    /// with its observations. The whole message is checked before either is applied.
    pub fn step(&mut self, msg: &SensorMsg) -> Result<UpdateStats, LocalizerError> {
        if let Err(e) = check_message(&self.config.limits, msg) {
            self.counters.count(&e);
            return Err(e);
        }
        self.predict_unchecked(msg.v_mps, msg.omega_radps, msg.dt_secs);
        Ok(self.update_unchecked(msg.observations()))
    }

    fn update_unchecked(&mut self, observations: &[LandmarkObs]) -> UpdateStats {
        let mut stats = UpdateStats::default();
        let q = measurement_noise(&self.config.noise); // line 8
        let lost = self.is_lost();
        for obs in observations {
            // line 9
            let mut obs = *obs;
            if lost {
                self.dropout_acc += self.config.loss.landmark_dropout;
                if self.dropout_acc >= 1.0 - 1e-12 {
                    self.dropout_acc -= 1.0;
                    stats.dropped += 1;
                    continue;
                }
                if self.config.loss.ambiguous_signatures {
                    obs.signature = 0;
                }
            }
            match self.associate(&obs, &q) {
                Association::Matched { z_hat, h, s } => {
                    self.correct(&obs, &z_hat, &h, &s, &q);
                    stats.used += 1;
                }
                Association::Gated => stats.gated += 1,
                Association::NoCandidate => stats.unmatched += 1,
            }
        }
        self.counters.observations_used += u64::from(stats.used);
        self.counters.observations_gated += u64::from(stats.gated);
        self.counters.observations_unmatched += u64::from(stats.unmatched);
        self.counters.observations_dropped += u64::from(stats.dropped);
        self.last_used = stats.used;
        stats
    }

    /// Maximum-likelihood association (seed 001 Algorithm 1 lines 10–21) among the landmarks of
    /// the filter (lines 10–14) with a compatible signature, inside the χ² gate.
    fn associate(&self, obs: &LandmarkObs, q: &Matrix2<f64>) -> Association {
        let mut best: Option<(f64, Association)> = None;
        let mut any_candidate = false;
        let mut consider = |lm: &Landmark| {
            if !signatures_match(obs.signature, lm.signature) {
                return;
            }
            let Some((z_hat, h)) = predict_measurement(&self.mean, lm.x_m, lm.y_m) else {
                return;
            };
            any_candidate = true;
            let s = h * self.cov * h.transpose() + q; // line 19
            let nu = innovation(obs, &z_hat);
            let Some((d2, neg2_log_l)) = score(&nu, &s) else {
                return;
            };
            if d2 <= self.config.gate_chi2 && best.as_ref().is_none_or(|b| neg2_log_l < b.0) {
                best = Some((neg2_log_l, Association::Matched { z_hat, h, s }));
                // line 21
            }
        };
        match &self.filter {
            Some(indices) => indices.iter().for_each(|&i| consider(&self.map[i])),
            None => self.map.iter().for_each(&mut consider),
        }
        match best {
            Some((_, matched)) => matched,
            None if any_candidate => Association::Gated,
            None => Association::NoCandidate,
        }
    }

    /// Kalman correction (seed 001 Algorithm 1 lines 22–24, line 24 in Joseph form).
    fn correct(
        &mut self,
        obs: &LandmarkObs,
        z_hat: &Vector2<f64>,
        h: &Matrix2x3<f64>,
        s: &Matrix2<f64>,
        q: &Matrix2<f64>,
    ) {
        let Some(s_inv) = s.try_inverse() else {
            return;
        };
        let k = self.cov * h.transpose() * s_inv; // line 22
        let mut mean = self.mean + k * innovation(obs, z_hat); // line 23
        mean.z = wrap_angle(mean.z);
        let i_kh = Matrix3::identity() - k * h;
        let cov = symmetrize3(&(i_kh * self.cov * i_kh.transpose() + k * q * k.transpose()));
        if mean.iter().all(|v| v.is_finite()) && cov.iter().all(|v| v.is_finite()) {
            self.mean = mean;
            self.cov = cov;
        }
    }

    /// Restricts association to these map indices (seed 001 Algorithm 1 lines 10–14: the
    /// landmarks of the captured area, or of the free areas); `None` = the whole map.
    pub fn set_landmark_filter(
        &mut self,
        indices: Option<Vec<usize>>,
    ) -> Result<(), LocalizerError> {
        if let Some(bad) = indices
            .as_ref()
            .and_then(|v| v.iter().find(|&&i| i >= self.map.len()))
        {
            return Err(LocalizerError::LandmarkIndexOutOfRange {
                index: *bad,
                len: self.map.len(),
            });
        }
        self.filter = indices;
        Ok(())
    }

    /// Indices of the map landmarks inside an axis-aligned region (the l(A_i) of seed 001
    /// eq. 12), for [`Ekf::set_landmark_filter`].
    pub fn landmarks_in_region(
        &self,
        min_x_m: f64,
        min_y_m: f64,
        max_x_m: f64,
        max_y_m: f64,
    ) -> Vec<usize> {
        self.map
            .iter()
            .enumerate()
            .filter(|(_, l)| {
                l.x_m >= min_x_m && l.x_m <= max_x_m && l.y_m >= min_y_m && l.y_m <= max_y_m
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// Whether the [`LossConfig`] is in effect.
    pub fn is_lost(&self) -> bool {
        self.config.loss.after_s.is_some_and(|t| self.time_s >= t)
    }

    /// Mean (x, y, θ), θ in (−π, π].
    pub fn mean(&self) -> Vector3<f64> {
        self.mean
    }

    pub fn pose(&self) -> Pose2 {
        Pose2::new(self.mean.x, self.mean.y, self.mean.z)
    }

    pub fn covariance(&self) -> Matrix3<f64> {
        self.cov
    }

    /// Filter time: the sum of the predicted `dt`.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    pub fn counters(&self) -> &EkfCounters {
        &self.counters
    }

    pub fn map(&self) -> &[Landmark] {
        &self.map
    }

    /// The estimate as a message (covariance row-major; `stamp_ns` 0 for the process loop).
    pub fn to_msg(&self, robot_id: u32, step: u64) -> PoseMsg {
        pose_msg(&self.mean, &self.cov, robot_id, step, self.last_used)
    }
}

enum Association {
    Matched {
        z_hat: Vector2<f64>,
        h: Matrix2x3<f64>,
        s: Matrix2<f64>,
    },
    Gated,
    NoCandidate,
}

// ---------------------------------------------------------------------------------------------
// EKF-SLAM

/// How [`EkfSlam`] decides which landmark an observation belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SlamAssociation {
    /// Signatures are distinct landmark ids; an unseen signature is a new landmark. Signature 0
    /// falls back to maximum likelihood.
    Signature,
    /// Maximum likelihood among compatible landmarks; an observation farther than
    /// `new_landmark_chi2` from every landmark starts a new one.
    MaximumLikelihood,
}

/// Settings of [`EkfSlam`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EkfSlamConfig {
    pub noise: NoiseConfig,
    pub association: SlamAssociation,
    /// χ² gate for matching (2 DOF).
    pub gate_chi2: f64,
    /// Maximum-likelihood mode: a Mahalanobis distance² above this to every landmark makes a
    /// new landmark (between `gate_chi2` and this, the observation is ignored as ambiguous).
    pub new_landmark_chi2: f64,
    /// The state holds at most this many landmarks; further new ones are ignored.
    pub max_landmarks: usize,
    pub limits: InputLimits,
}

impl Default for EkfSlamConfig {
    fn default() -> Self {
        Self {
            noise: NoiseConfig::default(),
            association: SlamAssociation::Signature,
            gate_chi2: 9.21,
            new_landmark_chi2: 50.0,
            max_landmarks: 1000,
            limits: InputLimits::default(),
        }
    }
}

/// A landmark estimated by [`EkfSlam`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlamLandmark {
    pub x_m: f64,
    pub y_m: f64,
    pub signature: u32,
    /// Position covariance, row-major `[xx, xy, yx, yy]`.
    pub cov: [f64; 4],
}

/// EKF-SLAM: the robot pose and N landmarks in one state (3 + 2N), covariance in `faer`.
/// Prediction and correction use the models of seed 001 Algorithm 1; landmarks are initialised
/// from their first observation with the inverse-measurement Jacobians.
#[derive(Debug, Clone)]
pub struct EkfSlam {
    config: EkfSlamConfig,
    mean: Vec<f64>,
    cov: Mat<f64>,
    signatures: Vec<u32>,
    last_used: u32,
    counters: EkfCounters,
}

impl EkfSlam {
    /// An empty map with the robot at `initial_pose` with `initial_cov`.
    pub fn new(
        config: EkfSlamConfig,
        initial_pose: Pose2,
        initial_cov: Matrix3<f64>,
    ) -> Result<Self, LocalizerError> {
        validate_common(&config.noise, &config.limits, config.gate_chi2)?;
        if !(config.new_landmark_chi2 >= config.gate_chi2 && config.new_landmark_chi2.is_finite()) {
            return Err(invalid(
                "new_landmark_chi2",
                config.new_landmark_chi2,
                "finite and >= gate_chi2",
            ));
        }
        let mean = vec![
            initial_pose.x_m,
            initial_pose.y_m,
            wrap_angle(initial_pose.theta_rad),
        ];
        if !mean.iter().all(|v| v.is_finite()) || !valid_covariance3(&initial_cov) {
            return Err(LocalizerError::InvalidInitialState);
        }
        let c = symmetrize3(&initial_cov);
        Ok(Self {
            config,
            mean,
            cov: Mat::from_fn(3, 3, |i, j| c[(i, j)]),
            signatures: Vec::new(),
            last_used: 0,
            counters: EkfCounters::default(),
        })
    }

    /// Prediction (seed 001 Algorithm 1 lines 2–7): only the robot block and the robot–landmark
    /// cross-covariances change.
    pub fn predict(
        &mut self,
        v_mps: f64,
        omega_radps: f64,
        dt_secs: f64,
    ) -> Result<(), LocalizerError> {
        if let Err(e) = check_odometry(&self.config.limits, v_mps, omega_radps, dt_secs) {
            self.counters.count(&e);
            return Err(e);
        }
        self.predict_unchecked(v_mps, omega_radps, dt_secs);
        Ok(())
    }

    fn predict_unchecked(&mut self, v: f64, w: f64, dt: f64) {
        let n = self.mean.len();
        let (delta, g, vj) = velocity_motion(self.mean[2], v, w, dt);
        let m = control_noise(&self.config.noise, v, w, 1.0);
        self.mean[0] += delta.x;
        self.mean[1] += delta.y;
        self.mean[2] = wrap_angle(self.mean[2] + delta.z);
        let srr = self.robot_covariance();
        let srr = symmetrize3(&(g * srr * g.transpose() + vj * m * vj.transpose()));
        if n > 3 {
            let gf = Mat::from_fn(3, 3, |i, j| g[(i, j)]);
            let mut cross = Mat::<f64>::zeros(3, n - 3);
            matmul(
                &mut cross,
                Accum::Replace,
                &gf,
                self.cov.submatrix(0, 3, 3, n - 3),
                1.0,
                Par::Seq,
            );
            self.cov.submatrix_mut(0, 3, 3, n - 3).copy_from(&cross);
            self.cov
                .submatrix_mut(3, 0, n - 3, 3)
                .copy_from(cross.transpose());
        }
        for i in 0..3 {
            for j in 0..3 {
                self.cov[(i, j)] = srr[(i, j)];
            }
        }
        self.counters.predictions += 1;
    }

    /// Correction with observations; unknown landmarks join the state.
    pub fn update(&mut self, observations: &[LandmarkObs]) -> Result<UpdateStats, LocalizerError> {
        if let Err(e) = check_observations(&self.config.limits, observations) {
            self.counters.count(&e);
            return Err(e);
        }
        Ok(self.update_unchecked(observations))
    }

    /// One world step: prediction then correction, the message checked first.
    pub fn step(&mut self, msg: &SensorMsg) -> Result<UpdateStats, LocalizerError> {
        if let Err(e) = check_message(&self.config.limits, msg) {
            self.counters.count(&e);
            return Err(e);
        }
        self.predict_unchecked(msg.v_mps, msg.omega_radps, msg.dt_secs);
        Ok(self.update_unchecked(msg.observations()))
    }

    fn update_unchecked(&mut self, observations: &[LandmarkObs]) -> UpdateStats {
        let mut stats = UpdateStats::default();
        let q = measurement_noise(&self.config.noise);
        for obs in observations {
            match self.associate(obs, &q) {
                SlamMatch::Existing(j) => {
                    self.correct(j, obs, &q);
                    stats.used += 1;
                }
                SlamMatch::New => {
                    if self.signatures.len() < self.config.max_landmarks {
                        self.add_landmark(obs, &q);
                        stats.added += 1;
                    } else {
                        stats.unmatched += 1;
                    }
                }
                SlamMatch::Gated => stats.gated += 1,
            }
        }
        self.counters.observations_used += u64::from(stats.used);
        self.counters.observations_gated += u64::from(stats.gated);
        self.counters.observations_unmatched += u64::from(stats.unmatched);
        self.counters.landmarks_added += u64::from(stats.added);
        self.last_used = stats.used;
        stats
    }

    /// Innovation, Jacobians (robot 2×3, landmark 2×2) and S for landmark `j`.
    fn landmark_terms(
        &self,
        j: usize,
        obs: &LandmarkObs,
        q: &Matrix2<f64>,
    ) -> Option<LandmarkTerms> {
        let li = 3 + 2 * j;
        let robot = Vector3::new(self.mean[0], self.mean[1], self.mean[2]);
        let (z_hat, hr) = predict_measurement(&robot, self.mean[li], self.mean[li + 1])?;
        let hm = -hr.fixed_columns::<2>(0).into_owned();
        let c = &self.cov;
        let srr = self.robot_covariance();
        let srm = Matrix3x2::from_fn(|i, k| c[(i, li + k)]);
        let smm = Matrix2::from_fn(|i, k| c[(li + i, li + k)]);
        let s = hr * srr * hr.transpose()
            + hr * srm * hm.transpose()
            + hm * srm.transpose() * hr.transpose()
            + hm * smm * hm.transpose()
            + q;
        Some(LandmarkTerms {
            nu: innovation(obs, &z_hat),
            hr,
            hm,
            s: symmetrize2(&s),
        })
    }

    fn associate(&self, obs: &LandmarkObs, q: &Matrix2<f64>) -> SlamMatch {
        if self.config.association == SlamAssociation::Signature && obs.signature != 0 {
            return match self.signatures.iter().position(|&s| s == obs.signature) {
                None => SlamMatch::New,
                Some(j) => match self
                    .landmark_terms(j, obs, q)
                    .and_then(|t| score(&t.nu, &t.s))
                {
                    Some((d2, _)) if d2 <= self.config.gate_chi2 => SlamMatch::Existing(j),
                    _ => SlamMatch::Gated,
                },
            };
        }
        let mut best: Option<(f64, usize)> = None;
        let mut min_d2 = f64::INFINITY;
        for (j, &sig) in self.signatures.iter().enumerate() {
            if !signatures_match(obs.signature, sig) {
                continue;
            }
            let Some((d2, neg2_log_l)) = self
                .landmark_terms(j, obs, q)
                .and_then(|t| score(&t.nu, &t.s))
            else {
                continue;
            };
            min_d2 = min_d2.min(d2);
            if d2 <= self.config.gate_chi2 && best.is_none_or(|b| neg2_log_l < b.0) {
                best = Some((neg2_log_l, j));
            }
        }
        match best {
            Some((_, j)) => SlamMatch::Existing(j),
            None if min_d2 > self.config.new_landmark_chi2 => SlamMatch::New,
            None => SlamMatch::Gated,
        }
    }

    /// Kalman correction with landmark `j`, H sparse (robot and landmark columns only), the
    /// covariance update in the expanded Joseph form Σ − KPᵀ − PKᵀ + KSKᵀ, P = ΣHᵀ, which is
    /// algebraically (I − KH)Σ(I − KH)ᵀ + KQKᵀ at O(n²) cost, then symmetrized.
    fn correct(&mut self, j: usize, obs: &LandmarkObs, q: &Matrix2<f64>) {
        let Some(LandmarkTerms { nu, hr, hm, s }) = self.landmark_terms(j, obs, q) else {
            return;
        };
        let Some(s_inv) = s.try_inverse() else {
            return;
        };
        let n = self.mean.len();
        let li = 3 + 2 * j;
        let hr_t = Mat::from_fn(3, 2, |i, k| hr[(k, i)]);
        let hm_t = Mat::from_fn(2, 2, |i, k| hm[(k, i)]);
        let mut p = Mat::<f64>::zeros(n, 2); // P = Σ Hᵀ
        matmul(
            &mut p,
            Accum::Replace,
            self.cov.submatrix(0, 0, n, 3),
            &hr_t,
            1.0,
            Par::Seq,
        );
        matmul(
            &mut p,
            Accum::Add,
            self.cov.submatrix(0, li, n, 2),
            &hm_t,
            1.0,
            Par::Seq,
        );
        let s_inv_f = Mat::from_fn(2, 2, |i, k| s_inv[(i, k)]);
        let s_f = Mat::from_fn(2, 2, |i, k| s[(i, k)]);
        let k = &p * &s_inv_f; // K = P S⁻¹ (seed 001 Algorithm 1 line 22)
        let ks = &k * &s_f;
        let mut new_mean = self.mean.clone();
        for (i, m) in new_mean.iter_mut().enumerate() {
            *m += k[(i, 0)] * nu.x + k[(i, 1)] * nu.y; // line 23
        }
        new_mean[2] = wrap_angle(new_mean[2]);
        let mut cov = self.cov.clone();
        matmul(&mut cov, Accum::Add, &k, p.transpose(), -1.0, Par::Seq);
        matmul(&mut cov, Accum::Add, &p, k.transpose(), -1.0, Par::Seq);
        matmul(&mut cov, Accum::Add, &ks, k.transpose(), 1.0, Par::Seq);
        symmetrize(&mut cov);
        let finite = new_mean.iter().all(|v| v.is_finite())
            && (0..n).all(|c| (0..n).all(|r| cov[(r, c)].is_finite()));
        if finite {
            self.mean = new_mean;
            self.cov = cov;
        }
    }

    /// Adds a landmark from its first observation: m = (x + r cos(φ+θ), y + r sin(φ+θ)),
    /// Σmm = Gr Σrr Grᵀ + Gz Q Gzᵀ, Σm· = Gr Σr·.
    fn add_landmark(&mut self, obs: &LandmarkObs, q: &Matrix2<f64>) {
        let n = self.mean.len();
        let (r, phi) = (f64::from(obs.range_m), f64::from(obs.bearing_rad));
        let a = self.mean[2] + phi;
        let (c, s) = (a.cos(), a.sin());
        #[rustfmt::skip]
        let gr = Matrix2x3::new(
            1.0, 0.0, -r * s,
            0.0, 1.0, r * c,
        );
        #[rustfmt::skip]
        let gz = Matrix2::new(
            c, -r * s,
            s, r * c,
        );
        let smm =
            symmetrize2(&(gr * self.robot_covariance() * gr.transpose() + gz * q * gz.transpose()));
        let gr_f = Mat::from_fn(2, 3, |i, k| gr[(i, k)]);
        let mut cross = Mat::<f64>::zeros(2, n);
        matmul(
            &mut cross,
            Accum::Replace,
            &gr_f,
            self.cov.submatrix(0, 0, 3, n),
            1.0,
            Par::Seq,
        );
        self.cov.resize_with(n + 2, n + 2, |_, _| 0.0);
        self.cov.submatrix_mut(n, 0, 2, n).copy_from(&cross);
        self.cov
            .submatrix_mut(0, n, n, 2)
            .copy_from(cross.transpose());
        for i in 0..2 {
            for k in 0..2 {
                self.cov[(n + i, n + k)] = smm[(i, k)];
            }
        }
        self.mean.push(self.mean[0] + r * c);
        self.mean.push(self.mean[1] + r * s);
        self.signatures.push(obs.signature);
    }

    pub fn pose(&self) -> Pose2 {
        Pose2::new(self.mean[0], self.mean[1], self.mean[2])
    }

    /// The robot block of the covariance.
    pub fn robot_covariance(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| self.cov[(i, j)])
    }

    /// The full state covariance ((3 + 2N) × (3 + 2N)).
    pub fn covariance(&self) -> MatRef<'_, f64> {
        self.cov.as_ref()
    }

    /// The full state (x, y, θ, m1x, m1y, …).
    pub fn state(&self) -> &[f64] {
        &self.mean
    }

    /// Landmark estimates in the order they were added.
    pub fn landmarks(&self) -> Vec<SlamLandmark> {
        self.signatures
            .iter()
            .enumerate()
            .map(|(j, &signature)| {
                let li = 3 + 2 * j;
                SlamLandmark {
                    x_m: self.mean[li],
                    y_m: self.mean[li + 1],
                    signature,
                    cov: [
                        self.cov[(li, li)],
                        self.cov[(li, li + 1)],
                        self.cov[(li + 1, li)],
                        self.cov[(li + 1, li + 1)],
                    ],
                }
            })
            .collect()
    }

    /// Whether the full covariance is symmetric positive definite (Cholesky succeeds).
    pub fn covariance_is_spd(&self) -> bool {
        let n = self.mean.len();
        let symmetric = (0..n).all(|i| (0..i).all(|j| self.cov[(i, j)] == self.cov[(j, i)]));
        symmetric && self.cov.llt(Side::Lower).is_ok()
    }

    pub fn counters(&self) -> &EkfCounters {
        &self.counters
    }

    /// The robot pose estimate as a message.
    pub fn to_msg(&self, robot_id: u32, step: u64) -> PoseMsg {
        let mean = Vector3::new(self.mean[0], self.mean[1], self.mean[2]);
        pose_msg(
            &mean,
            &self.robot_covariance(),
            robot_id,
            step,
            self.last_used,
        )
    }
}

/// Innovation ν, Jacobians w.r.t. the robot (2×3) and the landmark (2×2), and S of one
/// landmark in [`EkfSlam`].
struct LandmarkTerms {
    nu: Vector2<f64>,
    hr: Matrix2x3<f64>,
    hm: Matrix2<f64>,
    s: Matrix2<f64>,
}

enum SlamMatch {
    Existing(usize),
    New,
    Gated,
}

fn symmetrize2(m: &Matrix2<f64>) -> Matrix2<f64> {
    (m + m.transpose()) * 0.5
}

fn symmetrize(cov: &mut Mat<f64>) {
    let n = cov.nrows();
    for c in 0..n {
        for r in (c + 1)..n {
            let v = 0.5 * (cov[(r, c)] + cov[(c, r)]);
            cov[(r, c)] = v;
            cov[(c, r)] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::roles::world::{RobotConfig, WallConfig, World, WorldConfig};
    use approx::assert_relative_eq;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    const V_MPS: f64 = 0.6;
    const OMEGA_RADPS: f64 = 0.2;

    /// A 20 m × 20 m walled arena with a 4 × 4 grid of landmarks (signatures 1..=16); the robot
    /// starts at (10, 7) facing +x, so (0.6 m/s, 0.2 rad/s) drives a circle of radius 3 m.
    fn arena() -> WorldConfig {
        let landmarks = (0..16)
            .map(|k| Landmark {
                x_m: 2.5 + 5.0 * (k % 4) as f64,
                y_m: 2.5 + 5.0 * (k / 4) as f64,
                signature: k as u32 + 1,
            })
            .collect();
        WorldConfig {
            robots: vec![RobotConfig {
                id: 1,
                start: Pose2::new(10.0, 7.0, 0.0),
                noise: None,
            }],
            walls: vec![WallConfig::Polyline {
                points_m: vec![[0.0, 0.0], [20.0, 0.0], [20.0, 20.0], [0.0, 20.0]],
                closed: true,
            }],
            landmarks,
            ..WorldConfig::default()
        }
    }

    fn initial_cov() -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::new(
            0.05f64.powi(2),
            0.05f64.powi(2),
            0.02f64.powi(2),
        ))
    }

    /// A start pose drawn from N(truth, initial_cov) so the NEES is consistent from step 0.
    fn perturbed_start(truth: Pose2, rng: &mut ChaCha8Rng) -> Pose2 {
        let d = initial_cov().map(f64::sqrt);
        let mut n = || rng.sample::<f64, _>(StandardNormal);
        Pose2::new(
            truth.x_m + d[(0, 0)] * n(),
            truth.y_m + d[(1, 1)] * n(),
            truth.theta_rad + d[(2, 2)] * n(),
        )
    }

    fn nees(mean: &Vector3<f64>, cov: &Matrix3<f64>, truth: Pose2) -> f64 {
        let e = Vector3::new(
            truth.x_m - mean.x,
            truth.y_m - mean.y,
            wrap_angle(truth.theta_rad - mean.z),
        );
        (e.transpose() * cov.try_inverse().unwrap() * e)[(0, 0)]
    }

    fn det_xy(cov: &Matrix3<f64>) -> f64 {
        cov.fixed_view::<2, 2>(0, 0).determinant()
    }

    fn assert_spd(cov: &Matrix3<f64>) {
        assert_eq!(*cov, cov.transpose(), "covariance not symmetric");
        assert!(
            cov.cholesky().is_some(),
            "covariance not positive definite: {cov}"
        );
    }

    /// Runs the EKF on the arena for `steps`, calling `each` after every step.
    fn run_ekf(
        seed: u64,
        steps: usize,
        config: EkfConfig,
        mut each: impl FnMut(&Ekf, Pose2, &UpdateStats),
    ) -> Ekf {
        let world_cfg = arena();
        let map = world_cfg.landmarks.clone();
        let mut world = World::new(world_cfg, seed).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
        let start = perturbed_start(world.poses()[0], &mut rng);
        let mut ekf = Ekf::new(config, map, start, initial_cov()).unwrap();
        for _ in 0..steps {
            let out = world.step(&[(V_MPS, OMEGA_RADPS)]);
            assert_eq!(out[0].truth.collided, 0);
            let stats = ekf.step(&out[0].sensor).unwrap();
            each(&ekf, world.poses()[0], &stats);
        }
        ekf
    }

    #[test]
    fn prediction_matches_algorithm_1() {
        // seed 001 Algorithm 1 lines 3, 4, 6 literally, for ω ≠ 0.
        let (th, v, w, dt): (f64, f64, f64, f64) = (0.4, 0.9, 0.7, 0.1);
        let r = v / w;
        let th2 = th + w * dt;
        let lit_delta = Vector3::new(
            -r * th.sin() + r * th2.sin(),
            r * th.cos() - r * th2.cos(),
            w * dt,
        );
        #[rustfmt::skip]
        let lit_g = Matrix3::new(
            1.0, 0.0, -r * th.cos() + r * th2.cos(),
            0.0, 1.0, -r * th.sin() + r * th2.sin(),
            0.0, 0.0, 1.0,
        );
        #[rustfmt::skip]
        let lit_v = Matrix3x2::new(
            (-th.sin() + th2.sin()) / w,
            v * (th.sin() - th2.sin()) / (w * w) + v * th2.cos() * dt / w,
            (th.cos() - th2.cos()) / w,
            -v * (th.cos() - th2.cos()) / (w * w) + v * th2.sin() * dt / w,
            0.0, dt,
        );
        let (delta, g, vj) = velocity_motion(th, v, w, dt);
        assert_relative_eq!(delta, lit_delta, epsilon = 1e-12);
        assert_relative_eq!(g, lit_g, epsilon = 1e-12);
        assert_relative_eq!(vj, lit_v, epsilon = 1e-10);

        // ω = 0: straight line, and the Jacobians equal finite differences of the motion.
        let (delta, g, vj) = velocity_motion(th, v, 0.0, dt);
        assert_relative_eq!(
            delta,
            Vector3::new(v * dt * th.cos(), v * dt * th.sin(), 0.0),
            epsilon = 1e-15
        );
        let h = 1e-6;
        let d_theta = (velocity_motion(th + h, v, 0.0, dt).0
            - velocity_motion(th - h, v, 0.0, dt).0)
            / (2.0 * h);
        let d_v = (velocity_motion(th, v + h, 0.0, dt).0 - velocity_motion(th, v - h, 0.0, dt).0)
            / (2.0 * h);
        let d_w = (velocity_motion(th, v, h, dt).0 - velocity_motion(th, v, -h, dt).0) / (2.0 * h);
        assert_relative_eq!(
            g.column(2).into_owned(),
            d_theta + Vector3::z(),
            epsilon = 1e-8
        );
        assert_relative_eq!(vj.column(0).into_owned(), d_v, epsilon = 1e-8);
        assert_relative_eq!(vj.column(1).into_owned(), d_w, epsilon = 1e-8);
    }

    #[test]
    fn measurement_jacobian_matches_finite_differences() {
        // Checks the corrected signs of seed 001 Algorithm 1 line 18.
        let robot = Vector3::new(1.0, -2.0, 0.7);
        let (lx, ly) = (4.0, 1.5);
        let (_, h) = predict_measurement(&robot, lx, ly).unwrap();
        let eps = 1e-6;
        for k in 0..3 {
            let mut plus = robot;
            let mut minus = robot;
            plus[k] += eps;
            minus[k] -= eps;
            let zp = predict_measurement(&plus, lx, ly).unwrap().0;
            let zm = predict_measurement(&minus, lx, ly).unwrap().0;
            let numeric = Vector2::new(
                (zp.x - zm.x) / (2.0 * eps),
                wrap_angle(zp.y - zm.y) / (2.0 * eps),
            );
            assert_relative_eq!(h.column(k).into_owned(), numeric, epsilon = 1e-7);
        }
    }

    /// NEES consistency: the filter's error is as large as its covariance says.
    ///
    /// NEES of consecutive steps is strongly correlated (measured autocorrelation 0.75 at lag 1,
    /// ≈ 0 at lag 50 steps), so a plain time average over all steps of one run does not follow
    /// χ²(3N)/N. The average here is over N nearly independent samples: every 50th step of 20
    /// independent runs (N = 120); its two-sided 95 % bounds of χ²(3N)/N by the normal
    /// approximation are 3 ± 1.96·√(6/N).
    #[test]
    fn nees_is_consistent_and_covariance_stays_spd() {
        let (runs, steps, spacing) = (20u64, 300, 50);
        let mut samples = Vec::new();
        let mut max_err_m: f64 = 0.0;
        for seed in 0..runs {
            let mut k = 0;
            let ekf = run_ekf(seed, steps, EkfConfig::default(), |ekf, truth, _| {
                assert_spd(&ekf.covariance());
                k += 1;
                if k % spacing == 0 {
                    samples.push(nees(&ekf.mean(), &ekf.covariance(), truth));
                }
                max_err_m =
                    max_err_m.max((ekf.mean().x - truth.x_m).hypot(ekf.mean().y - truth.y_m));
            });
            // The χ² gate (99 %) drops only a few true associations.
            let c = ekf.counters();
            assert_eq!(c.observations_unmatched, 0);
            assert!(c.observations_gated * 50 < c.observations_used, "{c:?}");
        }
        let n = samples.len() as f64;
        assert_eq!(n, 120.0);
        let avg = samples.iter().sum::<f64>() / n;
        let half_width = 1.96 * (6.0 / n).sqrt();
        assert!(
            (avg - 3.0).abs() <= half_width,
            "average NEES {avg:.3} outside [{:.3}, {:.3}]",
            3.0 - half_width,
            3.0 + half_width
        );
        assert!(max_err_m < 0.3, "position error reached {max_err_m} m");
    }

    fn some_obs() -> Vec<LandmarkObs> {
        vec![
            LandmarkObs {
                range_m: 2.0,
                bearing_rad: 0.3,
                signature: 6,
                _pad: 0,
            },
            LandmarkObs {
                range_m: 3.0,
                bearing_rad: -1.0,
                signature: 7,
                _pad: 0,
            },
        ]
    }

    #[test]
    fn bad_input_is_rejected_counted_and_leaves_state_unchanged() {
        let mut ekf = Ekf::new(
            EkfConfig::default(),
            arena().landmarks,
            Pose2::new(10.0, 7.0, 0.0),
            initial_cov(),
        )
        .unwrap();
        ekf.predict(0.5, 0.1, 0.1).unwrap();
        let (mean, cov, t) = (ekf.mean(), ekf.covariance(), ekf.time_s());
        let before = *ekf.counters();

        use LocalizerError as E;
        assert!(matches!(
            ekf.predict(f64::NAN, 0.0, 0.1),
            Err(E::NonFiniteOdometry { .. })
        ));
        assert!(matches!(
            ekf.predict(0.5, f64::INFINITY, 0.1),
            Err(E::NonFiniteOdometry { .. })
        ));
        for dt in [0.0, -0.1, f64::NAN, f64::INFINITY, 5.0] {
            assert!(
                matches!(ekf.predict(0.5, 0.0, dt), Err(E::BadDt { .. })),
                "dt {dt}"
            );
        }
        assert!(matches!(
            ekf.predict(1e6, 0.0, 0.1),
            Err(E::AbsurdOdometry { .. })
        ));
        let mut obs = some_obs();
        obs[1].range_m = f32::NAN;
        assert_eq!(ekf.update(&obs), Err(E::NonFiniteObservation { index: 1 }));
        obs[1].range_m = 3.0;
        obs[1].bearing_rad = f32::NEG_INFINITY;
        assert_eq!(ekf.update(&obs), Err(E::NonFiniteObservation { index: 1 }));
        obs[1].bearing_rad = 0.0;
        obs[0].range_m = -1.0;
        assert!(matches!(
            ekf.update(&obs),
            Err(E::BadRange { index: 0, .. })
        ));
        // A message with good odometry but a NaN observation: prediction is not applied either.
        let mut msg = SensorMsg {
            dt_secs: 0.1,
            v_mps: 0.5,
            count: 2,
            ..SensorMsg::default()
        };
        msg.observations[0] = some_obs()[0];
        msg.observations[1].bearing_rad = f32::NAN;
        assert_eq!(ekf.step(&msg), Err(E::NonFiniteObservation { index: 1 }));
        msg.dt_secs = f64::NAN;
        assert!(matches!(ekf.step(&msg), Err(E::BadDt { .. })));
        msg.dt_secs = 0.1;
        msg.count = 33;
        assert!(matches!(
            ekf.step(&msg),
            Err(E::BadObservationCount { count: 33, .. })
        ));
        msg.count = 2;

        assert_eq!(ekf.mean(), mean);
        assert_eq!(ekf.covariance(), cov);
        assert_eq!(ekf.time_s(), t);
        let c = ekf.counters();
        assert_eq!(c.predictions, before.predictions);
        assert_eq!(c.rejected_non_finite_odometry, 2);
        assert_eq!(c.rejected_bad_dt, 6);
        assert_eq!(c.rejected_absurd_odometry, 1);
        assert_eq!(c.rejected_non_finite_observation, 3);
        assert_eq!(c.rejected_bad_range, 1);
        assert_eq!(c.rejected_bad_count, 1);
        assert_eq!(c.rejected_total(), 14);
        // And it still works afterwards.
        msg.observations[1] = some_obs()[1];
        assert!(ekf.step(&msg).is_ok());
    }

    #[test]
    fn bad_config_and_initial_state_are_rejected() {
        let map = arena().landmarks;
        let start = Pose2::new(1.0, 1.0, 0.0);
        let mut cfg = EkfConfig::default();
        cfg.noise.range_sigma_m = 0.0;
        assert!(matches!(
            Ekf::new(cfg, map.clone(), start, initial_cov()),
            Err(LocalizerError::InvalidConfig { .. })
        ));
        let mut cfg = EkfConfig::default();
        cfg.loss.noise_inflation = 0.5;
        assert!(matches!(
            Ekf::new(cfg, map.clone(), start, initial_cov()),
            Err(LocalizerError::InvalidConfig { .. })
        ));
        let mut asym = initial_cov();
        asym[(0, 1)] = 1e-3;
        let mut neg = initial_cov();
        neg[(2, 2)] = -1.0;
        let mut nan = initial_cov();
        nan[(1, 1)] = f64::NAN;
        for bad in [asym, neg, nan] {
            assert_eq!(
                Ekf::new(EkfConfig::default(), map.clone(), start, bad).unwrap_err(),
                LocalizerError::InvalidInitialState
            );
        }
        // A zero covariance ("known start") is fine.
        assert!(Ekf::new(EkfConfig::default(), map, start, Matrix3::zeros()).is_ok());
    }

    #[test]
    fn losing_localization_grows_det_sigma_xy() {
        let loss_at_s = 10.0;
        let lost_cfg = EkfConfig {
            loss: LossConfig {
                after_s: Some(loss_at_s),
                ..LossConfig::default()
            },
            ..EkfConfig::default()
        };
        let mut det_at_loss = 0.0;
        let mut max_det_before: f64 = 0.0;
        let lost = run_ekf(3, 400, lost_cfg, |ekf, _, _| {
            let det = det_xy(&ekf.covariance());
            assert_spd(&ekf.covariance());
            if ekf.time_s() < loss_at_s - 1e-9 {
                assert!(!ekf.is_lost());
                max_det_before = max_det_before.max(det);
            } else if det_at_loss == 0.0 {
                det_at_loss = det;
            }
        });
        let healthy = run_ekf(3, 400, EkfConfig::default(), |_, _, _| {});
        assert!(lost.is_lost());
        assert!(lost.counters().observations_dropped > 100);
        let det_end = det_xy(&lost.covariance());
        assert!(
            det_end > 1e3 * det_at_loss,
            "det Σxy grew only from {det_at_loss:e} to {det_end:e}"
        );
        assert!(det_end > 1e3 * det_xy(&healthy.covariance()));
        assert!(
            max_det_before < 1e-4,
            "det before the loss {max_det_before:e}"
        );
        assert_eq!(lost.to_msg(1, 400).landmarks_used, 0);
    }

    #[test]
    fn loss_dropout_drops_the_configured_share() {
        let cfg = EkfConfig {
            loss: LossConfig {
                after_s: Some(0.0),
                landmark_dropout: 0.5,
                noise_inflation: 1.0,
                ambiguous_signatures: false,
            },
            ..EkfConfig::default()
        };
        let mut ekf = Ekf::new(
            cfg,
            arena().landmarks,
            Pose2::new(10.0, 7.0, 0.0),
            initial_cov(),
        )
        .unwrap();
        let mut obs = some_obs();
        obs.extend(some_obs());
        let stats = ekf.update(&obs).unwrap();
        assert_eq!(stats.dropped, 2);
        assert_eq!(stats.used + stats.gated + stats.unmatched, 2);
    }

    #[test]
    fn landmark_filter_restricts_association() {
        let world_cfg = arena();
        let map = world_cfg.landmarks.clone();
        let mut world = World::new(world_cfg, 5).unwrap();
        let start = world.poses()[0];
        let mut ekf = Ekf::new(EkfConfig::default(), map, start, initial_cov()).unwrap();
        assert_eq!(
            ekf.set_landmark_filter(Some(vec![3, 16])),
            Err(LocalizerError::LandmarkIndexOutOfRange { index: 16, len: 16 })
        );
        // The captured area: the centre square holds landmarks 5, 6, 9, 10 (seed 001 eq. 12).
        let area = ekf.landmarks_in_region(5.0, 5.0, 15.0, 15.0);
        assert_eq!(area, vec![5, 6, 9, 10]);
        let area_sigs: Vec<u32> = area.iter().map(|&i| ekf.map()[i].signature).collect();
        ekf.set_landmark_filter(Some(area)).unwrap();
        let (mut inside, mut outside) = (0, 0);
        for _ in 0..300 {
            let out = world.step(&[(V_MPS, OMEGA_RADPS)]);
            for o in out[0].sensor.observations() {
                if area_sigs.contains(&o.signature) {
                    inside += 1;
                } else {
                    outside += 1;
                }
            }
            ekf.step(&out[0].sensor).unwrap();
        }
        let c = *ekf.counters();
        assert!(outside > 0, "the run never saw a landmark outside the area");
        assert_eq!(c.observations_used + c.observations_gated, inside);
        assert_eq!(c.observations_unmatched, outside);
        // An empty set matches nothing (Algorithm 1 lines 10–14 with no landmarks).
        ekf.set_landmark_filter(Some(Vec::new())).unwrap();
        let out = world.step(&[(V_MPS, OMEGA_RADPS)]);
        let stats = ekf.step(&out[0].sensor).unwrap();
        assert_eq!(stats.used, 0);
        assert_eq!(stats.unmatched, out[0].sensor.count);
        ekf.set_landmark_filter(None).unwrap();
        let out = world.step(&[(V_MPS, OMEGA_RADPS)]);
        assert!(ekf.step(&out[0].sensor).unwrap().used > 0);
    }

    /// A 40 m × 4 m walled corridor with two rows of landmarks every 2 m (signatures 1..=40);
    /// the robot starts at (10, 2) facing +x.
    fn corridor() -> WorldConfig {
        let landmarks = (0..40)
            .map(|k| Landmark {
                x_m: 1.0 + 2.0 * (k / 2) as f64,
                y_m: if k % 2 == 0 { 0.5 } else { 3.5 },
                signature: k as u32 + 1,
            })
            .collect();
        WorldConfig {
            robots: vec![RobotConfig {
                id: 1,
                start: Pose2::new(10.0, 2.0, 0.0),
                noise: None,
            }],
            walls: vec![WallConfig::Polyline {
                points_m: vec![[0.0, 0.0], [40.0, 0.0], [40.0, 4.0], [0.0, 4.0]],
                closed: true,
            }],
            landmarks,
            ..WorldConfig::default()
        }
    }

    /// The captured area of the corridor: x in [8, 24] m, 16 of the 40 landmarks (40 %, as in
    /// seed 001 Fig. 6).
    const CAPTURED: [f64; 4] = [8.0, 0.0, 24.0, 4.0];

    #[test]
    fn landmark_region_m_restricts_association_to_the_captured_area() {
        let world_cfg = corridor();
        let map = world_cfg.landmarks.clone();
        let inside_sigs: Vec<u32> = map
            .iter()
            .filter(|l| (CAPTURED[0]..=CAPTURED[2]).contains(&l.x_m))
            .map(|l| l.signature)
            .collect();
        assert_eq!(inside_sigs.len(), 16);
        let cfg = EkfConfig {
            landmark_region_m: Some(CAPTURED),
            ..EkfConfig::default()
        };
        let mut world = World::new(world_cfg, 7).unwrap();
        let start = world.poses()[0];
        let mut ekf = Ekf::new(cfg, map.clone(), start, initial_cov()).unwrap();
        let mut whole = Ekf::new(EkfConfig::default(), map, start, initial_cov()).unwrap();
        let filter = ekf.landmark_filter().unwrap().to_vec();
        let filter_sigs: Vec<u32> = filter.iter().map(|&i| ekf.map()[i].signature).collect();
        assert_eq!(filter_sigs, inside_sigs);
        assert_eq!(whole.landmark_filter(), None);

        // 20 s at 0.5 m/s: from x = 10 to x = 20, inside the area, seeing landmarks on both
        // sides of it (5 m sensor range).
        let (mut inside, mut outside, mut max_err_m) = (0u64, 0u64, 0.0f64);
        for _ in 0..200 {
            let out = world.step(&[(0.5, 0.0)]);
            assert_eq!(out[0].truth.collided, 0);
            let sensor = &out[0].sensor;
            let seen_inside = sensor
                .observations()
                .iter()
                .filter(|o| inside_sigs.contains(&o.signature))
                .count() as u32;
            inside += u64::from(seen_inside);
            outside += u64::from(sensor.count - seen_inside);
            let stats = ekf.step(sensor).unwrap();
            // Per step: exactly the observations of landmarks outside the area find no
            // candidate; the others are associated (or gated) among the area's landmarks.
            assert_eq!(stats.unmatched, sensor.count - seen_inside);
            assert_eq!(stats.used + stats.gated, seen_inside);
            whole.step(sensor).unwrap();
            let t = world.poses()[0];
            assert!(
                (CAPTURED[0]..=CAPTURED[2]).contains(&t.x_m),
                "left the area"
            );
            max_err_m = max_err_m.max((ekf.mean().x - t.x_m).hypot(ekf.mean().y - t.y_m));
        }
        let c = *ekf.counters();
        assert!(outside > 50, "only {outside} observations outside the area");
        assert_eq!(c.observations_unmatched, outside);
        assert_eq!(c.observations_used + c.observations_gated, inside);
        assert!(c.observations_used * 10 > inside * 9, "{c:?}");
        // The whole-map filter uses the outside landmarks too.
        let w = *whole.counters();
        assert_eq!(w.observations_unmatched, 0);
        assert!(w.observations_used > c.observations_used);
        // Still localized on the area's landmarks alone.
        assert!(max_err_m < 0.2, "position error reached {max_err_m} m");
        assert_spd(&ekf.covariance());
    }

    #[test]
    fn landmark_region_m_without_landmarks_is_allowed_and_matches_nothing() {
        let world_cfg = corridor();
        let map = world_cfg.landmarks.clone();
        let cfg = EkfConfig {
            // Between the two rows: no landmark inside.
            landmark_region_m: Some([8.0, 1.0, 24.0, 3.0]),
            ..EkfConfig::default()
        };
        let mut world = World::new(world_cfg, 3).unwrap();
        let mut ekf = Ekf::new(cfg, map, world.poses()[0], initial_cov()).unwrap();
        assert_eq!(ekf.landmark_filter(), Some(&[][..]));
        let out = world.step(&[(0.5, 0.0)]);
        assert!(out[0].sensor.count > 0);
        let stats = ekf.step(&out[0].sensor).unwrap();
        assert_eq!((stats.used, stats.gated), (0, 0));
        assert_eq!(stats.unmatched, out[0].sensor.count);
        assert_eq!(
            ekf.counters().observations_unmatched,
            u64::from(out[0].sensor.count)
        );
    }

    #[test]
    fn malformed_landmark_region_is_rejected_naming_the_key() {
        let map = corridor().landmarks;
        let start = Pose2::new(10.0, 2.0, 0.0);
        let bad_regions = [
            [f64::NAN, 0.0, 24.0, 4.0],
            [8.0, f64::NEG_INFINITY, 24.0, 4.0],
            [8.0, 0.0, f64::INFINITY, 4.0],
            [24.0, 0.0, 8.0, 4.0],
            [8.0, 0.0, 8.0, 4.0],
            [8.0, 4.0, 24.0, 0.0],
            [8.0, 2.0, 24.0, 2.0],
        ];
        for region in bad_regions {
            let cfg = EkfConfig {
                landmark_region_m: Some(region),
                ..EkfConfig::default()
            };
            let e = Ekf::new(cfg, map.clone(), start, initial_cov()).unwrap_err();
            assert!(
                matches!(
                    e,
                    LocalizerError::InvalidRegion {
                        key: LANDMARK_REGION_KEY,
                        ..
                    }
                ),
                "{region:?}: {e:?}"
            );
            let text = e.to_string();
            assert!(
                text.contains("`landmark_region_m`") && text.contains(&format!("{region:?}")),
                "{text}"
            );
        }
        // The key parses from TOML; a misspelt key is still refused.
        let cfg: EkfConfig = toml::from_str("landmark_region_m = [8.0, 0.0, 24, 4]").unwrap();
        assert_eq!(cfg.landmark_region_m, Some(CAPTURED));
        assert!(toml::from_str::<EkfConfig>("landmark_region = [8.0, 0.0, 24, 4]").is_err());
        assert!(toml::from_str::<EkfConfig>("landmark_region_m = [8.0, 0.0, 24]").is_err());
        // A scenario with a bad region fails validation naming the robot and the key.
        let mut scenario = crate::sim::scenario::Scenario::load("trail").unwrap();
        scenario.robots[0].localizer.landmark_region_m = Some([1.0, 1.0, 0.0, 2.0]);
        let e = scenario.validate().unwrap_err();
        assert!(
            e.contains("localizer") && e.contains("`landmark_region_m`"),
            "{e}"
        );
    }

    #[test]
    fn landmark_region_flag_parses_four_numbers_or_names_the_flag() {
        assert_eq!(parse_landmark_region("8,0,24,4"), Ok(CAPTURED));
        assert_eq!(
            parse_landmark_region("-5.5, -1 ,1e1,2"),
            Ok([-5.5, -1.0, 10.0, 2.0])
        );
        for text in [
            "",
            "1,2,3",
            "1,2,3,4,5",
            "a,0,1,1",
            "0;0;1;1",
            "nan,0,1,1",
            "0,0,inf,1",
            "5,0,1,3",
            "0,3,1,3",
        ] {
            let e = parse_landmark_region(text).unwrap_err();
            let msg = e.to_string();
            assert!(
                msg.contains("--landmark-region") && msg.contains(&format!("{text:?}")),
                "{text}: {msg}"
            );
        }
    }

    #[test]
    fn ekf_slam_refuses_landmark_region_m() {
        let mut scenario = crate::sim::scenario::Scenario::load("trail").unwrap();
        let id = scenario.robots[0].id;
        scenario.robots[0].localizer.landmark_region_m = Some(CAPTURED);
        assert!(crate::roles::Filter::for_robot(&scenario, id, false).is_ok());
        let e = crate::roles::Filter::for_robot(&scenario, id, true)
            .err()
            .expect("EKF-SLAM accepted a landmark region");
        assert!(e.to_string().contains("landmark_region_m"), "{e}");
    }

    #[test]
    fn maximum_likelihood_association_without_signatures() {
        let mut world_cfg = arena();
        for lm in &mut world_cfg.landmarks {
            lm.signature = 0;
        }
        let map = world_cfg.landmarks.clone();
        let mut world = World::new(world_cfg, 11).unwrap();
        let mut ekf = Ekf::new(EkfConfig::default(), map, world.poses()[0], initial_cov()).unwrap();
        let mut seen = 0;
        for _ in 0..300 {
            let out = world.step(&[(V_MPS, OMEGA_RADPS)]);
            seen += out[0].sensor.count as u64;
            ekf.step(&out[0].sensor).unwrap();
            let t = world.poses()[0];
            let err = (ekf.mean().x - t.x_m).hypot(ekf.mean().y - t.y_m);
            assert!(err < 0.3, "position error {err} m");
        }
        assert!(ekf.counters().observations_used as f64 > 0.95 * seen as f64);
    }

    #[test]
    fn to_msg_is_row_major() {
        #[rustfmt::skip]
        let cov = Matrix3::new(
            4.0, 1.0, 0.5,
            1.0, 3.0, 0.2,
            0.5, 0.2, 1.0,
        );
        let ekf = Ekf::new(
            EkfConfig::default(),
            Vec::new(),
            Pose2::new(1.0, 2.0, 3.0),
            cov,
        )
        .unwrap();
        let msg = ekf.to_msg(4, 17);
        assert_eq!((msg.robot_id, msg.step, msg.stamp_ns), (4, 17, 0));
        assert_eq!((msg.x_m, msg.y_m, msg.theta_rad), (1.0, 2.0, 3.0));
        assert_eq!(msg.cov, [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 1.0]);
        assert_eq!(msg.cov_xy(), [4.0, 1.0, 3.0]);
    }

    fn run_slam(
        seed: u64,
        steps: usize,
        config: EkfSlamConfig,
        signatures: bool,
    ) -> (EkfSlam, World) {
        let mut world_cfg = arena();
        if !signatures {
            for lm in &mut world_cfg.landmarks {
                lm.signature = 0;
            }
        }
        let mut world = World::new(world_cfg, seed).unwrap();
        let start_cov = Matrix3::from_diagonal_element(1e-6);
        let mut slam = EkfSlam::new(config, world.poses()[0], start_cov).unwrap();
        for _ in 0..steps {
            let out = world.step(&[(V_MPS, OMEGA_RADPS)]);
            slam.step(&out[0].sensor).unwrap();
        }
        (slam, world)
    }

    /// Distance from an estimated landmark to the nearest true one.
    fn nearest_truth_m(world: &World, lm: &SlamLandmark) -> (usize, f64) {
        world
            .config()
            .landmarks
            .iter()
            .enumerate()
            .map(|(i, t)| (i, (t.x_m - lm.x_m).hypot(t.y_m - lm.y_m)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap()
    }

    #[test]
    fn slam_with_signatures_converges_to_the_landmarks() {
        let (slam, world) = run_slam(21, 500, EkfSlamConfig::default(), true);
        let lms = slam.landmarks();
        assert!(lms.len() >= 4, "only {} landmarks", lms.len());
        assert_eq!(slam.state().len(), 3 + 2 * lms.len());
        assert!(slam.covariance_is_spd());
        for lm in &lms {
            let truth = world.config().landmarks[lm.signature as usize - 1];
            let err = (truth.x_m - lm.x_m).hypot(truth.y_m - lm.y_m);
            // Within 0.3 m, and within its own 99.9 % ellipse.
            let cov = Matrix2::new(lm.cov[0], lm.cov[1], lm.cov[2], lm.cov[3]);
            let e = Vector2::new(truth.x_m - lm.x_m, truth.y_m - lm.y_m);
            let d2 = (e.transpose() * cov.try_inverse().unwrap() * e)[(0, 0)];
            assert!(
                err < 0.3 && d2 < 13.8,
                "landmark {} off by {err} m (d² {d2})",
                lm.signature
            );
        }
        let t = world.poses()[0];
        let p = slam.pose();
        assert!((p.x_m - t.x_m).hypot(p.y_m - t.y_m) < 0.2);
        let msg = slam.to_msg(1, 500);
        assert_eq!(msg.cov[1], msg.cov[3]);
    }

    #[test]
    fn slam_maximum_likelihood_adds_each_landmark_once() {
        let config = EkfSlamConfig {
            association: SlamAssociation::MaximumLikelihood,
            ..EkfSlamConfig::default()
        };
        let (slam, world) = run_slam(23, 400, config, false);
        let lms = slam.landmarks();
        let mut matched = std::collections::HashSet::new();
        for lm in &lms {
            let (i, err) = nearest_truth_m(&world, lm);
            assert!(err < 0.3, "landmark near {} off by {err} m", i);
            assert!(matched.insert(i), "landmark {i} added twice");
        }
        assert!(lms.len() >= 4);
        assert!(slam.covariance_is_spd());
    }

    #[test]
    fn slam_rejects_bad_input_without_touching_the_state() {
        let (mut slam, _) = run_slam(2, 50, EkfSlamConfig::default(), true);
        let state = slam.state().to_vec();
        let cov = slam.covariance().to_owned();
        let mut obs = some_obs();
        obs[0].range_m = f32::NAN;
        assert!(slam.update(&obs).is_err());
        assert!(slam.predict(0.1, f64::NAN, 0.1).is_err());
        assert_eq!(slam.state(), &state[..]);
        assert!(slam.covariance() == cov.as_ref());
        assert_eq!(slam.counters().rejected_total(), 2);
    }
}
