//! [`EkfSlam`]: EKF-SLAM with the models of seed 001 Algorithm 1. The robot pose and N
//! landmarks form one state (3 + 2N); unknown landmarks join it from their first observation,
//! and the large covariance algebra (prediction of the cross-covariances, the sparse-H
//! correction in Joseph form, landmark initialisation) runs on nalgebra's dynamic matrices,
//! block by block (the robot's 3 rows or columns, a landmark's 2) so that no step costs more
//! than O(n²).

use nalgebra::{DMatrix, Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};

use super::models::{
    control_noise, innovation, measurement_noise, pose_msg, predict_measurement, score,
    signatures_match, symmetrize3, valid_covariance3, velocity_motion,
};
use super::{
    invalid, validate_common, CheckedFilter, EkfCounters, EkfSlamConfig, InputLimits,
    LocalizerError, SlamAssociation, UpdateStats,
};
use pheromone_messages::{wrap_angle, WorldPose};
use pheromone_messages::{LandmarkObs, PoseMsg};

/// A landmark estimated by [`EkfSlam`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlamLandmark {
    pub x_m: f64,
    pub y_m: f64,
    pub signature: u32,
    /// Position covariance, row-major `[xx, xy, yx, yy]`.
    pub cov: [f64; 4],
}

/// EKF-SLAM: the robot pose and N landmarks in one state (3 + 2N), covariance a dense `DMatrix`.
/// Prediction and correction use the models of seed 001 Algorithm 1; landmarks are initialised
/// from their first observation with the inverse-measurement Jacobians.
#[derive(Debug, Clone)]
pub struct EkfSlam {
    config: EkfSlamConfig,
    mean: Vec<f64>,
    cov: DMatrix<f64>,
    signatures: Vec<u32>,
    last_used: u32,
    counters: EkfCounters,
}

impl EkfSlam {
    /// An empty map with the robot at `initial_pose` with `initial_cov`.
    pub fn new(
        config: EkfSlamConfig,
        initial_pose: WorldPose,
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
            cov: DMatrix::from_fn(3, 3, |i, j| c[(i, j)]),
            signatures: Vec::new(),
            last_used: 0,
            counters: EkfCounters::default(),
        })
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
        let li = 3 + 2 * j;
        // P = Σ Hᵀ (n × 2), from the robot's and the landmark's columns only.
        let p = self.cov.fixed_columns::<3>(0) * hr.transpose()
            + self.cov.fixed_columns::<2>(li) * hm.transpose();
        let k = &p * s_inv; // K = P S⁻¹ (seed 001 Algorithm 1 line 22)
        let ks = &k * s;
        let mut new_mean = self.mean.clone();
        for (i, m) in new_mean.iter_mut().enumerate() {
            *m += k[(i, 0)] * nu.x + k[(i, 1)] * nu.y; // line 23
        }
        new_mean[2] = wrap_angle(new_mean[2]);
        let mut cov = self.cov.clone();
        let (k_t, p_t) = (k.transpose(), p.transpose());
        cov.gemm(-1.0, &k, &p_t, 1.0);
        cov.gemm(-1.0, &p, &k_t, 1.0);
        cov.gemm(1.0, &ks, &k_t, 1.0);
        symmetrize(&mut cov);
        let finite = new_mean.iter().all(|v| v.is_finite()) && cov.iter().all(|v| v.is_finite());
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
        let cross = gr * self.cov.fixed_rows::<3>(0); // Σm· = Gr Σr· (2 × n)
        self.cov.resize_mut(n + 2, n + 2, 0.0);
        self.cov.view_mut((n, 0), (2, n)).copy_from(&cross);
        self.cov.view_mut((0, n), (n, 2)).tr_copy_from(&cross);
        for i in 0..2 {
            for k in 0..2 {
                self.cov[(n + i, n + k)] = smm[(i, k)];
            }
        }
        self.mean.push(self.mean[0] + r * c);
        self.mean.push(self.mean[1] + r * s);
        self.signatures.push(obs.signature);
    }

    pub fn pose(&self) -> WorldPose {
        WorldPose::new(self.mean[0], self.mean[1], self.mean[2])
    }

    /// The robot block of the covariance.
    pub fn robot_covariance(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| self.cov[(i, j)])
    }

    /// The full state covariance ((3 + 2N) × (3 + 2N)).
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.cov
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
        symmetric && self.cov.clone().cholesky().is_some()
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

impl CheckedFilter for EkfSlam {
    fn limits(&self) -> &InputLimits {
        &self.config.limits
    }

    fn counters_mut(&mut self) -> &mut EkfCounters {
        &mut self.counters
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
            let cross = g * self.cov.view((0, 3), (3, n - 3)); // G Σr· (3 × (n − 3))
            self.cov.view_mut((0, 3), (3, n - 3)).copy_from(&cross);
            self.cov.view_mut((3, 0), (n - 3, 3)).tr_copy_from(&cross);
        }
        for i in 0..3 {
            for j in 0..3 {
                self.cov[(i, j)] = srr[(i, j)];
            }
        }
        self.counters.predictions += 1;
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

fn symmetrize(cov: &mut DMatrix<f64>) {
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
    use crate::localizer::test_support::{arena, some_obs, OMEGA_RADPS, V_MPS};
    use pheromone_world::World;

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
        let cov = slam.covariance().clone();
        let mut obs = some_obs();
        obs[0].range_m = f32::NAN;
        assert!(slam.update(&obs).is_err());
        assert!(slam.predict(0.1, f64::NAN, 0.1).is_err());
        assert_eq!(slam.state(), &state[..]);
        assert_eq!(slam.covariance(), &cov);
        assert_eq!(slam.counters().rejected_total(), 2);
    }
}
