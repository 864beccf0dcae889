//! Landmark-based EKF localization (seed 001 Algorithm 1) and EKF-SLAM.
//!
//! - [`Ekf`]: state (x, y, θ) and its 3×3 covariance (nalgebra). Prediction with the velocity
//!   motion model (Algorithm 1 lines 2–7), correction with range/bearing/signature observations
//!   of known landmarks with maximum-likelihood association (lines 8–25), optionally restricted
//!   to a subset of landmarks (lines 10–14, [`Ekf::set_landmark_filter`]). A [`LossConfig`]
//!   makes the filter lose its localization on purpose, as the leader of seed 000 does.
//! - [`EkfSlam`]: the same models with unknown landmarks added to the state (3 + 2N), the large
//!   covariance algebra block by block on nalgebra's `DMatrix`.
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

mod ekf;
pub mod graph_filter;
mod likelihood;
mod models;
mod pf;
mod slam;
#[cfg(test)]
pub(crate) mod test_support;
#[cfg(test)]
mod tests_filters;
mod ukf;

pub use ekf::Ekf;
pub use likelihood::DistanceGrid;
pub use pf::{parse_particles, ParticleFilter, PfConfig, MAX_PARTICLES, MIN_PARTICLES};
pub use slam::{EkfSlam, SlamLandmark};
pub use ukf::{Ukf, UkfConfig};

/// Which filter a localizer runs (`--filter`, the scenario's `filter` key of a robot).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FilterKind {
    /// Landmark EKF (seed 001 Algorithm 1), the default.
    #[default]
    Ekf,
    /// Landmark UKF (seed 000 eqs. 6–8).
    Ukf,
    /// Particle filter with the laser (Monte Carlo localization).
    Pf,
}

impl FilterKind {
    pub const NAMES: [&'static str; 3] = ["ekf", "ukf", "pf"];

    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }
}

impl std::str::FromStr for FilterKind {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        match text {
            "ekf" => Ok(Self::Ekf),
            "ukf" => Ok(Self::Ukf),
            "pf" => Ok(Self::Pf),
            _ => Err(format!("--filter {text:?}: expected one of ekf, ukf, pf")),
        }
    }
}

use serde::{Deserialize, Serialize};
use thiserror::Error;

use pheromone_messages::NoiseConfig;
use pheromone_messages::{LandmarkObs, SensorMsg, MAX_OBSERVATIONS};

/// Inputs beyond these limits are rejected as absurd.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InputLimits {
    /// Largest accepted time step.
    #[serde(alias = "max_dt_secs")]
    pub max_dt_s: f64,
    /// Largest accepted |v| of the odometry.
    #[serde(alias = "max_speed_mps")]
    pub max_speed_m_per_s: f64,
    /// Largest accepted |ω| of the odometry.
    #[serde(alias = "max_turn_rate_radps")]
    pub max_turn_rate_rad_per_s: f64,
    /// Largest accepted observed range.
    pub max_range_m: f64,
}

impl Default for InputLimits {
    fn default() -> Self {
        Self {
            max_dt_s: 1.0,
            max_speed_m_per_s: 10.0,
            max_turn_rate_rad_per_s: 20.0,
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
    /// While lost, the filter integrates the odometry's turn rate with this bias (rad/s,
    /// counter-clockwise positive): an uncalibrated gyro or a wheel that slips, which the
    /// landmarks corrected before. The estimate then curves away from the true path, so the
    /// robot believes it is somewhere else (seed 000 Fig. 1: Bob estimates A, truly at B).
    pub heading_drift_rad_per_s: f64,
}

impl Default for LossConfig {
    fn default() -> Self {
        Self {
            after_s: None,
            landmark_dropout: 1.0,
            noise_inflation: 10.0,
            ambiguous_signatures: false,
            heading_drift_rad_per_s: 0.0,
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
        if !loss.heading_drift_rad_per_s.is_finite() {
            return Err(invalid(
                "loss.heading_drift_rad_per_s",
                loss.heading_drift_rad_per_s,
                "finite",
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
    #[error("odometry is not finite: v = {v_m_per_s} m/s, omega = {omega_rad_per_s} rad/s")]
    NonFiniteOdometry {
        v_m_per_s: f64,
        omega_rad_per_s: f64,
    },
    /// Odometry beyond [`InputLimits`].
    #[error("odometry is absurd: v = {v_m_per_s} m/s, omega = {omega_rad_per_s} rad/s exceed the limits")]
    AbsurdOdometry {
        v_m_per_s: f64,
        omega_rad_per_s: f64,
    },
    /// `dt` not finite, ≤ 0 or above `max_dt_s`.
    #[error("dt_s = {dt_s} is not in (0, {max_dt_s}]")]
    BadDt { dt_s: f64, max_dt_s: f64 },
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
    /// A laser scan's beam count, header or a range is unusable.
    #[error("laser scan: beam {beam}: range {range_m} m is not finite and >= 0 (or the count/header is bad)")]
    BadLaser { beam: usize, range_m: f64 },
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
    /// Landmark comparisons of the EKF's association: for every observation, each landmark of
    /// the filter in effect (seed 001 Algorithm 1 line 15: the whole map, or L_set).
    pub landmarks_compared: u64,
    pub rejected_non_finite_odometry: u64,
    pub rejected_absurd_odometry: u64,
    pub rejected_bad_dt: u64,
    pub rejected_non_finite_observation: u64,
    pub rejected_bad_range: u64,
    pub rejected_bad_count: u64,
    pub rejected_bad_laser: u64,
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
            + self.rejected_bad_laser
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
            LocalizerError::BadLaser { .. } => self.rejected_bad_laser += 1,
            LocalizerError::InvalidConfig { .. }
            | LocalizerError::InvalidRegion { .. }
            | LocalizerError::InvalidInitialState
            | LocalizerError::LandmarkIndexOutOfRange { .. } => {}
        }
    }
    /// Counts a failed input check by reason and passes its result on.
    fn counted(&mut self, checked: Result<(), LocalizerError>) -> Result<(), LocalizerError> {
        if let Err(e) = &checked {
            self.count(e);
        }
        checked
    }
}

/// What [`Ekf`] and [`EkfSlam`] share: every input is checked first (a rejection is counted by
/// reason and leaves the state untouched), then the filter's own step runs.
pub trait CheckedFilter {
    /// The input limits the checks apply.
    fn limits(&self) -> &InputLimits;
    /// The counters checks and steps add to.
    fn counters_mut(&mut self) -> &mut EkfCounters;
    /// Prediction with checked odometry (seed 001 Algorithm 1 lines 2–7).
    fn predict_unchecked(&mut self, v_m_per_s: f64, omega_rad_per_s: f64, dt_s: f64);
    /// Correction with checked observations (lines 8–25), one after the other.
    fn update_unchecked(&mut self, observations: &[LandmarkObs]) -> UpdateStats;

    /// Prediction with the velocity motion model; the odometry is checked first.
    fn predict(
        &mut self,
        v_m_per_s: f64,
        omega_rad_per_s: f64,
        dt_s: f64,
    ) -> Result<(), LocalizerError> {
        let checked = check_odometry(self.limits(), v_m_per_s, omega_rad_per_s, dt_s);
        self.counters_mut().counted(checked)?;
        self.predict_unchecked(v_m_per_s, omega_rad_per_s, dt_s);
        Ok(())
    }

    /// Correction with landmark observations. All are checked first; one bad observation
    /// rejects the whole set.
    fn update(&mut self, observations: &[LandmarkObs]) -> Result<UpdateStats, LocalizerError> {
        let checked = check_observations(self.limits(), observations);
        self.counters_mut().counted(checked)?;
        Ok(self.update_unchecked(observations))
    }

    /// One world step: prediction with the message's odometry and `dt_s`, then correction with
    /// its observations. The whole message is checked before either is applied.
    fn step(&mut self, msg: &SensorMsg) -> Result<UpdateStats, LocalizerError> {
        let checked = check_message(self.limits(), msg);
        self.counters_mut().counted(checked)?;
        self.predict_unchecked(msg.v_m_per_s, msg.omega_rad_per_s, msg.dt_s);
        Ok(self.update_unchecked(msg.observations()))
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
// EKF-SLAM settings

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

// ---------------------------------------------------------------------------------------------
// Input checks shared by Ekf and EkfSlam

fn check_odometry(
    limits: &InputLimits,
    v_m_per_s: f64,
    omega_rad_per_s: f64,
    dt_s: f64,
) -> Result<(), LocalizerError> {
    if !(v_m_per_s.is_finite() && omega_rad_per_s.is_finite()) {
        return Err(LocalizerError::NonFiniteOdometry {
            v_m_per_s,
            omega_rad_per_s,
        });
    }
    if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= limits.max_dt_s) {
        return Err(LocalizerError::BadDt {
            dt_s,
            max_dt_s: limits.max_dt_s,
        });
    }
    if v_m_per_s.abs() > limits.max_speed_m_per_s
        || omega_rad_per_s.abs() > limits.max_turn_rate_rad_per_s
    {
        return Err(LocalizerError::AbsurdOdometry {
            v_m_per_s,
            omega_rad_per_s,
        });
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
    check_odometry(limits, msg.v_m_per_s, msg.omega_rad_per_s, msg.dt_s)?;
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
        ("limits.max_dt_s", limits.max_dt_s),
        ("limits.max_speed_m_per_s", limits.max_speed_m_per_s),
        (
            "limits.max_turn_rate_rad_per_s",
            limits.max_turn_rate_rad_per_s,
        ),
        ("limits.max_range_m", limits.max_range_m),
    ];
    for (name, value) in positive {
        if value.is_nan() || value <= 0.0 {
            return Err(invalid(name, value, "> 0"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::localizer::test_support::{corridor, initial_cov, CAPTURED};
    use pheromone_messages::WorldPose;

    #[test]
    fn malformed_landmark_region_is_rejected_naming_the_key() {
        let map = corridor().landmarks;
        let start = WorldPose::new(10.0, 2.0, 0.0);
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
}
