//! [`Ukf`]: landmark-based unscented Kalman filter localization (seed 000 eqs. 6–8) with the
//! models of the EKF (`models.rs`): the velocity motion model with control noise M_t and
//! range/bearing observations with noise Q_t, maximum-likelihood association inside a χ² gate.
//!
//! - Prediction: 2n + 1 sigma points (eq. 6) of the state augmented with the control noise
//!   (n = 5: x, y, θ, ε_v, ε_ω), each moved by the motion model with its noisy control (eq. 7);
//!   mean and covariance from the weighted points (eq. 8).
//! - Correction, one observation after the other: sigma points of (μ̄, Σ̄) (n = 3) through the
//!   observation model; predicted measurement, its covariance S (+ Q_t) and the cross
//!   covariance Σ_xz from the weighted points (eq. 8); K = Σ_xz S⁻¹.
//! - Weights (seed 000 after eq. 6): λ = α²(n + κ) − n, w_m⁰ = λ/(n + λ),
//!   w_c⁰ = w_m⁰ + 1 − α² + β, w⁽ⁱ⁾ = 1/(2(n + λ)). Angles are averaged on the circle and their
//!   deviations wrapped to (−π, π].

use nalgebra::{Cholesky, Matrix2, SMatrix, SVector, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::models::{
    control_noise, measurement_noise, pose_msg, signatures_match, symmetrize3, valid_covariance3,
    velocity_motion,
};
use super::{
    invalid, CheckedFilter, EkfConfig, EkfCounters, InputLimits, LocalizerError, UpdateStats,
};
use pheromone_messages::{wrap_angle, Landmark, WorldPose};
use pheromone_messages::{LandmarkObs, PoseMsg};

/// The UKF's scaling parameters (seed 000 eq. 6: α, κ; β for w_c⁰).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UkfConfig {
    /// Spread of the sigma points, in (0, 1].
    pub alpha: f64,
    /// Prior knowledge of the distribution (2 is optimal for a Gaussian), ≥ 0.
    pub beta: f64,
    /// Secondary scaling, ≥ 0.
    pub kappa: f64,
}

impl Default for UkfConfig {
    fn default() -> Self {
        Self {
            alpha: 1.0,
            beta: 2.0,
            kappa: 0.0,
        }
    }
}

impl UkfConfig {
    pub fn validate(&self) -> Result<(), LocalizerError> {
        if !(self.alpha > 0.0 && self.alpha <= 1.0) {
            return Err(invalid("ukf.alpha", self.alpha, "in (0, 1]"));
        }
        if !(self.beta.is_finite() && self.beta >= 0.0) {
            return Err(invalid("ukf.beta", self.beta, "finite and >= 0"));
        }
        if !(self.kappa.is_finite() && self.kappa >= 0.0 && self.kappa <= 100.0) {
            return Err(invalid("ukf.kappa", self.kappa, "in [0, 100]"));
        }
        Ok(())
    }

    /// λ, (w_m⁰, w_c⁰) and w⁽ⁱ⁾ for dimension `n`.
    fn weights(&self, n: usize) -> (f64, f64, f64, f64) {
        let n = n as f64;
        let lambda = self.alpha.powi(2) * (n + self.kappa) - n;
        let wm0 = lambda / (n + lambda);
        let wc0 = wm0 + 1.0 - self.alpha.powi(2) + self.beta;
        (lambda, wm0, wc0, 0.5 / (n + lambda))
    }
}

/// Sigma points of (mean, cov) (seed 000 eq. 6): column 0 the mean, then ± the columns of
/// √((n + λ)Σ) (Cholesky). `None` when Σ is not positive definite.
fn sigma_points<const N: usize>(
    mean: &SVector<f64, N>,
    cov: &SMatrix<f64, N, N>,
    lambda: f64,
) -> Option<Vec<SVector<f64, N>>> {
    let scaled = cov * (N as f64 + lambda);
    let l = Cholesky::new(scaled + SMatrix::<f64, N, N>::identity() * 1e-15)?.l();
    let mut pts = Vec::with_capacity(2 * N + 1);
    pts.push(*mean);
    for i in 0..N {
        pts.push(mean + l.column(i));
    }
    for i in 0..N {
        pts.push(mean - l.column(i));
    }
    Some(pts)
}

/// Weighted circular mean of angles.
fn circular_mean(angles: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (s, c) = angles.fold((0.0, 0.0), |(s, c), (w, a)| {
        (s + w * a.sin(), c + w * a.cos())
    });
    s.atan2(c)
}

/// Landmark-based UKF localization (seed 000 eqs. 6–8).
#[derive(Debug, Clone)]
pub struct Ukf {
    config: EkfConfig,
    ukf: UkfConfig,
    map: Vec<Landmark>,
    mean: Vector3<f64>,
    cov: SMatrix<f64, 3, 3>,
    last_used: u32,
    counters: EkfCounters,
}

/// A matched observation: predicted measurement, S, Σ_xz.
struct Predicted {
    z_hat: Vector2<f64>,
    s: Matrix2<f64>,
    cross: SMatrix<f64, 3, 2>,
}

impl Ukf {
    /// A filter over the known `map` starting at `initial_pose` with `initial_cov`. The loss
    /// script ([`LossConfig`](super::LossConfig)) and the landmark region are EKF-only.
    pub fn new(
        config: EkfConfig,
        ukf: UkfConfig,
        map: Vec<Landmark>,
        initial_pose: WorldPose,
        initial_cov: SMatrix<f64, 3, 3>,
    ) -> Result<Self, LocalizerError> {
        config.validate()?;
        ukf.validate()?;
        if let Some(t) = config.loss.after_s {
            return Err(invalid(
                "loss.after_s",
                t,
                "unset: the loss script is EKF-only",
            ));
        }
        let mean = Vector3::new(
            initial_pose.x_m,
            initial_pose.y_m,
            wrap_angle(initial_pose.theta_rad),
        );
        if !mean.iter().all(|v| v.is_finite()) || !valid_covariance3(&initial_cov) {
            return Err(LocalizerError::InvalidInitialState);
        }
        if map
            .iter()
            .any(|l| !(l.x_m.is_finite() && l.y_m.is_finite()))
        {
            return Err(invalid("map", f64::NAN, "finite coordinates"));
        }
        Ok(Self {
            config,
            ukf,
            map,
            mean,
            cov: symmetrize3(&initial_cov),
            last_used: 0,
            counters: EkfCounters::default(),
        })
    }

    pub fn mean(&self) -> Vector3<f64> {
        self.mean
    }

    pub fn covariance(&self) -> SMatrix<f64, 3, 3> {
        self.cov
    }

    pub fn counters(&self) -> &EkfCounters {
        &self.counters
    }

    /// The estimate as a message (covariance row-major; `stamp_ns` 0 for the process loop).
    pub fn to_msg(&self, robot_id: u32, step: u64) -> PoseMsg {
        pose_msg(&self.mean, &self.cov, robot_id, step, self.last_used)
    }

    /// The observation model through the sigma points of (μ, Σ) for landmark `lm` (eq. 7–8).
    fn predict_obs(&self, pts: &[Vector3<f64>], lm: &Landmark) -> Option<Predicted> {
        let (_, wm0, wc0, wi) = self.ukf.weights(3);
        let w = |i: usize| if i == 0 { (wm0, wc0) } else { (wi, wi) };
        let mut zs = Vec::with_capacity(pts.len());
        for p in pts {
            let (dx, dy) = (lm.x_m - p.x, lm.y_m - p.y);
            let r = dx.hypot(dy);
            if r < 1e-6 {
                return None;
            }
            zs.push(Vector2::new(r, wrap_angle(dy.atan2(dx) - p.z)));
        }
        let r_hat: f64 = zs.iter().enumerate().map(|(i, z)| w(i).0 * z.x).sum();
        let b_hat = circular_mean(zs.iter().enumerate().map(|(i, z)| (w(i).0, z.y)));
        let z_hat = Vector2::new(r_hat, b_hat);
        let mut s = measurement_noise(&self.config.noise);
        let mut cross = SMatrix::<f64, 3, 2>::zeros();
        for (i, (z, p)) in zs.iter().zip(pts).enumerate() {
            let dz = Vector2::new(z.x - z_hat.x, wrap_angle(z.y - z_hat.y));
            let mut dx = p - self.mean;
            dx.z = wrap_angle(dx.z);
            s += w(i).1 * dz * dz.transpose();
            cross += w(i).1 * dx * dz.transpose();
        }
        Some(Predicted { z_hat, s, cross })
    }

    /// Maximum-likelihood association inside the χ² gate, then the correction.
    fn correct(&mut self, obs: &LandmarkObs, stats: &mut UpdateStats) {
        let (lambda, ..) = self.ukf.weights(3);
        let Some(pts) = sigma_points(&self.mean, &self.cov, lambda) else {
            stats.unmatched += 1;
            return;
        };
        let mut best: Option<(f64, Predicted, Vector2<f64>)> = None;
        let mut any = false;
        for lm in self
            .map
            .iter()
            .filter(|l| signatures_match(obs.signature, l.signature))
        {
            let Some(p) = self.predict_obs(&pts, lm) else {
                continue;
            };
            any = true;
            let nu = Vector2::new(
                f64::from(obs.range_m) - p.z_hat.x,
                wrap_angle(f64::from(obs.bearing_rad) - p.z_hat.y),
            );
            let Some(s_inv) = p.s.try_inverse() else {
                continue;
            };
            let d2 = (nu.transpose() * s_inv * nu)[(0, 0)];
            let score = d2 + p.s.determinant().ln();
            if d2 <= self.config.gate_chi2 && best.as_ref().is_none_or(|b| score < b.0) {
                best = Some((score, p, nu));
            }
        }
        let Some((_, p, nu)) = best else {
            if any {
                stats.gated += 1;
            } else {
                stats.unmatched += 1;
            }
            return;
        };
        let Some(s_inv) = p.s.try_inverse() else {
            return;
        };
        let k = p.cross * s_inv;
        let mut mean = self.mean + k * nu;
        mean.z = wrap_angle(mean.z);
        let cov = symmetrize3(&(self.cov - k * p.s * k.transpose()));
        if mean.iter().all(|v| v.is_finite()) && valid_covariance3(&cov) {
            self.mean = mean;
            self.cov = cov;
            stats.used += 1;
        } else {
            stats.gated += 1;
        }
    }
}

impl CheckedFilter for Ukf {
    fn limits(&self) -> &InputLimits {
        &self.config.limits
    }

    fn counters_mut(&mut self) -> &mut EkfCounters {
        &mut self.counters
    }

    /// Augmented sigma points (x, y, θ, ε_v, ε_ω) through the motion model (eqs. 6–8).
    fn predict_unchecked(&mut self, v: f64, w: f64, dt: f64) {
        let m = control_noise(&self.config.noise, v, w, 1.0);
        let mut mean = SVector::<f64, 5>::zeros();
        mean.fixed_rows_mut::<3>(0).copy_from(&self.mean);
        let mut cov = SMatrix::<f64, 5, 5>::zeros();
        cov.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.cov);
        cov.fixed_view_mut::<2, 2>(3, 3).copy_from(&m);
        let (lambda, wm0, wc0, wi) = self.ukf.weights(5);
        self.counters.predictions += 1;
        let Some(pts) = sigma_points(&mean, &cov, lambda) else {
            // Σ not positive definite (cannot happen for a valid Σ): move the mean only.
            let (delta, ..) = velocity_motion(self.mean.z, v, w, dt);
            self.mean += delta;
            self.mean.z = wrap_angle(self.mean.z);
            return;
        };
        let moved: Vec<Vector3<f64>> = pts
            .iter()
            .map(|p| {
                let (delta, ..) = velocity_motion(p[2], v + p[3], w + p[4], dt);
                Vector3::new(p[0] + delta.x, p[1] + delta.y, wrap_angle(p[2] + delta.z))
            })
            .collect();
        let w_of = |i: usize| if i == 0 { (wm0, wc0) } else { (wi, wi) };
        let x: f64 = moved.iter().enumerate().map(|(i, p)| w_of(i).0 * p.x).sum();
        let y: f64 = moved.iter().enumerate().map(|(i, p)| w_of(i).0 * p.y).sum();
        let th = circular_mean(moved.iter().enumerate().map(|(i, p)| (w_of(i).0, p.z)));
        let new_mean = Vector3::new(x, y, th);
        let mut new_cov = SMatrix::<f64, 3, 3>::zeros();
        for (i, p) in moved.iter().enumerate() {
            let mut d = p - new_mean;
            d.z = wrap_angle(d.z);
            new_cov += w_of(i).1 * d * d.transpose();
        }
        let new_cov = symmetrize3(&new_cov);
        if new_mean.iter().all(|v| v.is_finite()) && valid_covariance3(&new_cov) {
            self.mean = new_mean;
            self.cov = new_cov;
        }
    }

    fn update_unchecked(&mut self, observations: &[LandmarkObs]) -> UpdateStats {
        let mut stats = UpdateStats::default();
        for obs in observations {
            self.correct(obs, &mut stats);
        }
        self.counters.observations_used += u64::from(stats.used);
        self.counters.observations_gated += u64::from(stats.gated);
        self.counters.observations_unmatched += u64::from(stats.unmatched);
        self.last_used = stats.used;
        stats
    }
}
