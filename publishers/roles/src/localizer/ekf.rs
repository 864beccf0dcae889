//! [`Ekf`]: landmark-based EKF localization with a known map (seed 001 Algorithm 1):
//! prediction with the velocity motion model (lines 2–7), correction with maximum-likelihood
//! association among the landmarks of an optional filter (lines 8–25, lines 10–14 for the
//! filter), and the deliberate loss of localization of seed 000
//! ([`LossConfig`](super::LossConfig)).

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Vector2, Vector3};

use super::models::{
    control_noise, innovation, measurement_noise, pose_msg, predict_measurement, score,
    signatures_match, symmetrize3, valid_covariance3, velocity_motion,
};
use super::{
    invalid, CheckedFilter, EkfConfig, EkfCounters, InputLimits, LocalizerError, UpdateStats,
};
use pheromone_messages::{wrap_angle, Landmark, WorldPose};
use pheromone_messages::{LandmarkObs, PoseMsg};

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
        initial_pose: WorldPose,
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

    /// Whether the [`LossConfig`](super::LossConfig) is in effect.
    pub fn is_lost(&self) -> bool {
        self.config.loss.after_s.is_some_and(|t| self.time_s >= t)
    }

    /// Mean (x, y, θ), θ in (−π, π].
    pub fn mean(&self) -> Vector3<f64> {
        self.mean
    }

    pub fn pose(&self) -> WorldPose {
        WorldPose::new(self.mean.x, self.mean.y, self.mean.z)
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

impl CheckedFilter for Ekf {
    fn limits(&self) -> &InputLimits {
        &self.config.limits
    }

    fn counters_mut(&mut self) -> &mut EkfCounters {
        &mut self.counters
    }

    fn predict_unchecked(&mut self, v: f64, w: f64, dt: f64) {
        let lost = self.is_lost();
        // While lost, the turn rate is read with the configured drift (LossConfig).
        let w = if lost {
            w + self.config.loss.heading_drift_rad_per_s
        } else {
            w
        };
        let (delta, g, vj) = velocity_motion(self.mean.z, v, w, dt);
        let inflation = if lost {
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
            // Line 15: every landmark of L_set is compared with the observation.
            self.counters.landmarks_compared +=
                self.filter.as_ref().map_or(self.map.len(), Vec::len) as u64;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::localizer::test_support::{
        arena, corridor, initial_cov, some_obs, CAPTURED, OMEGA_RADPS, V_MPS,
    };
    use crate::localizer::LossConfig;
    use pheromone_messages::SensorMsg;
    use pheromone_world::World;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    /// A start pose drawn from N(truth, initial_cov) so the NEES is consistent from step 0.
    fn perturbed_start(truth: WorldPose, rng: &mut ChaCha8Rng) -> WorldPose {
        let d = initial_cov().map(f64::sqrt);
        let mut n = || rng.sample::<f64, _>(StandardNormal);
        WorldPose::new(
            truth.x_m + d[(0, 0)] * n(),
            truth.y_m + d[(1, 1)] * n(),
            truth.theta_rad + d[(2, 2)] * n(),
        )
    }

    fn nees(mean: &Vector3<f64>, cov: &Matrix3<f64>, truth: WorldPose) -> f64 {
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
        mut each: impl FnMut(&Ekf, WorldPose, &UpdateStats),
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

    #[test]
    fn bad_input_is_rejected_counted_and_leaves_state_unchanged() {
        let mut ekf = Ekf::new(
            EkfConfig::default(),
            arena().landmarks,
            WorldPose::new(10.0, 7.0, 0.0),
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
            dt_s: 0.1,
            v_m_per_s: 0.5,
            count: 2,
            ..SensorMsg::default()
        };
        msg.observations[0] = some_obs()[0];
        msg.observations[1].bearing_rad = f32::NAN;
        assert_eq!(ekf.step(&msg), Err(E::NonFiniteObservation { index: 1 }));
        msg.dt_s = f64::NAN;
        assert!(matches!(ekf.step(&msg), Err(E::BadDt { .. })));
        msg.dt_s = 0.1;
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
        let start = WorldPose::new(1.0, 1.0, 0.0);
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
    fn a_heading_drift_while_lost_curves_the_estimate_away_from_a_straight_path() {
        // Straight odometry at 0.5 m/s for 10 s, no landmarks: lost from 2 s on with a drift of
        // 0.1 rad/s, the estimate turns 0.8 rad on an arc of radius 5 m; unlost, it goes straight.
        let run = |after_s: Option<f64>| {
            let cfg = EkfConfig {
                loss: LossConfig {
                    after_s,
                    heading_drift_rad_per_s: 0.1,
                    noise_inflation: 1.0,
                    ..LossConfig::default()
                },
                ..EkfConfig::default()
            };
            let mut ekf = Ekf::new(
                cfg,
                Vec::new(),
                WorldPose::new(0.0, 0.0, 0.0),
                initial_cov(),
            )
            .unwrap();
            for _ in 0..100 {
                ekf.predict(0.5, 0.0, 0.1).unwrap();
            }
            ekf.mean()
        };
        let lost = run(Some(1.95));
        let (phi, r) = (0.8f64, 5.0f64);
        assert!((lost.z - phi).abs() < 1e-9, "heading {}", lost.z);
        let (x, y) = (1.0 + r * phi.sin(), r * (1.0 - phi.cos()));
        assert!(
            (lost.x - x).abs() < 0.01 && (lost.y - y).abs() < 0.01,
            "{lost:?} vs ({x:.3}, {y:.3})"
        );
        let never = run(None);
        assert!((never.x - 5.0).abs() < 1e-9 && never.y.abs() < 1e-9 && never.z == 0.0);
        let mut bad = EkfConfig::default();
        bad.loss.heading_drift_rad_per_s = f64::NAN;
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("loss.heading_drift_rad_per_s"), "{e}");
    }

    #[test]
    fn loss_dropout_drops_the_configured_share() {
        let cfg = EkfConfig {
            loss: LossConfig {
                after_s: Some(0.0),
                landmark_dropout: 0.5,
                noise_inflation: 1.0,
                ambiguous_signatures: false,
                heading_drift_rad_per_s: 0.0,
            },
            ..EkfConfig::default()
        };
        let mut ekf = Ekf::new(
            cfg,
            arena().landmarks,
            WorldPose::new(10.0, 7.0, 0.0),
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
            WorldPose::new(1.0, 2.0, 3.0),
            cov,
        )
        .unwrap();
        let msg = ekf.to_msg(4, 17);
        assert_eq!((msg.robot_id, msg.step, msg.stamp_ns), (4, 17, 0));
        assert_eq!((msg.x_m, msg.y_m, msg.theta_rad), (1.0, 2.0, 3.0));
        assert_eq!(msg.cov, [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 1.0]);
        assert_eq!(msg.cov_xy(), [4.0, 1.0, 3.0]);
    }
}
