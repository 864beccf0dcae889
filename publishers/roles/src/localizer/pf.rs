//! [`ParticleFilter`]: Monte Carlo localization (seed 000's particle filter; Thrun et al.,
//! Probabilistic Robotics Table 8.2) with the laser of seed 000 Table 1.
//!
//! - Prediction: each particle moves by the velocity motion model with its own control drawn
//!   from the control noise M_t (σ_v² = α1·v² + α2·ω², σ_ω² = α3·v² + α4·ω²).
//! - Laser: a likelihood field ([`DistanceGrid`]): each returned beam's end point scores
//!   z_hit·N(d; 0, σ_hit²) + z_rand/range_max, d its distance to the nearest wall; beams
//!   without a return are skipped. `beam_stride` uses every k-th beam.
//! - Free space (`free_space`, issue 48 part 4): a particle off the free space (on a wall, or
//!   not reachable from the start pose: inside solid building) weighs [`OFF_FREE_SPACE_LOG`];
//!   a beam whose path from the particle up to its reading less a margin (3σ_hit + 7.5 % of
//!   the range; all of `range_max` for a beam without a return) crosses a wall scores
//!   [`THROUGH_WALL_FACTOR`] of z_rand/range_max: the beam passed where the map has a wall.
//! - Landmarks (`use_landmarks`): each observation scores the best landmark of a compatible
//!   signature with N(ν; 0, Q_t), its Mahalanobis distance² capped at `landmark_d2_cap` (an
//!   outlier costs at most that much).
//! - Low-variance resampling (Table 4.4) when the effective sample size 1/Σw² falls below
//!   `resample_fraction`·M.
//! - The estimate is the weighted mean (θ on the circle) and the particles' weighted covariance,
//!   the Σ that drives seed 000's uncertainty-aware deposits.
//!
//! Seeded (`ChaCha8Rng`): a run is the same for the same seed and inputs.

use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::likelihood::DistanceGrid;
use super::models::{pose_msg, signatures_match, valid_covariance3, velocity_motion};
use super::{
    check_message, invalid, CheckedFilter, EkfConfig, EkfCounters, InputLimits, LocalizerError,
    UpdateStats,
};
use pheromone_messages::{wrap_angle, Landmark, Segment, WorldPose};
use pheromone_messages::{LandmarkObs, LaserMsg, PoseMsg, SensorMsg, MAX_LASER_BEAMS};

/// Fewest particles a filter may have.
pub const MIN_PARTICLES: usize = 10;
/// Most particles a filter may have.
pub const MAX_PARTICLES: usize = 100_000;

/// Log-weight added to a particle off the free space: never accepted while any particle is on it.
pub const OFF_FREE_SPACE_LOG: f64 = -1.0e4;
/// Likelihood factor of a beam that passed through a wall of the map (against z_rand/range_max).
pub const THROUGH_WALL_FACTOR: f64 = 1.0e-4;

/// Settings of [`ParticleFilter`] (`[robot.pf]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PfConfig {
    /// Number of particles M, in [`MIN_PARTICLES`, `MAX_PARTICLES`].
    pub particles: usize,
    /// σ of the likelihood field's Gaussian.
    pub sigma_hit_m: f64,
    /// Weight of the Gaussian part; z_rand = 1 − z_hit.
    pub z_hit: f64,
    /// Use every k-th beam (≥ 1).
    pub beam_stride: usize,
    /// Cell size of the distance grid.
    pub grid_cell_m: f64,
    /// Weigh the landmark observations too.
    pub use_landmarks: bool,
    /// Cap of a landmark observation's Mahalanobis distance².
    pub landmark_d2_cap: f64,
    /// Resample when the effective sample size is below this share of M, in (0, 1].
    pub resample_fraction: f64,
    /// Reject particles off the free space and beams through walls (see the module).
    pub free_space: bool,
}

impl Default for PfConfig {
    fn default() -> Self {
        Self {
            particles: 500,
            sigma_hit_m: 0.1,
            z_hit: 0.9,
            beam_stride: 4,
            grid_cell_m: 0.05,
            use_landmarks: true,
            landmark_d2_cap: 25.0,
            resample_fraction: 0.5,
            free_space: true,
        }
    }
}

impl PfConfig {
    pub fn validate(&self) -> Result<(), LocalizerError> {
        let m = self.particles;
        if !(MIN_PARTICLES..=MAX_PARTICLES).contains(&m) {
            return Err(invalid("pf.particles", m as f64, "in [10, 100000]"));
        }
        let checks = [
            (
                "pf.sigma_hit_m",
                self.sigma_hit_m,
                self.sigma_hit_m > 0.0 && self.sigma_hit_m <= 10.0,
            ),
            ("pf.z_hit", self.z_hit, self.z_hit > 0.0 && self.z_hit < 1.0),
            (
                "pf.grid_cell_m",
                self.grid_cell_m,
                self.grid_cell_m >= 0.005 && self.grid_cell_m <= 1.0,
            ),
            (
                "pf.landmark_d2_cap",
                self.landmark_d2_cap,
                self.landmark_d2_cap > 0.0 && self.landmark_d2_cap <= 1e6,
            ),
            (
                "pf.resample_fraction",
                self.resample_fraction,
                self.resample_fraction > 0.0 && self.resample_fraction <= 1.0,
            ),
        ];
        for (key, value, ok) in checks {
            if !ok {
                return Err(invalid(
                    key,
                    value,
                    "finite and in its range (see PfConfig)",
                ));
            }
        }
        if !(1..=MAX_LASER_BEAMS).contains(&self.beam_stride) {
            return Err(invalid(
                "pf.beam_stride",
                self.beam_stride as f64,
                "in [1, 256]",
            ));
        }
        Ok(())
    }
}

/// Parses `--particles N`: an integer in [`MIN_PARTICLES`, `MAX_PARTICLES`]; the error names
/// the flag and the text.
pub fn parse_particles(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(n) if (MIN_PARTICLES..=MAX_PARTICLES).contains(&n) => Ok(n),
        _ => Err(format!(
            "--particles {text:?}: expected an integer in [{MIN_PARTICLES}, {MAX_PARTICLES}]"
        )),
    }
}

/// Monte Carlo localization with a likelihood-field laser model (see the module).
#[derive(Debug, Clone)]
pub struct ParticleFilter {
    config: EkfConfig,
    pf: PfConfig,
    map: Vec<Landmark>,
    grid: DistanceGrid,
    particles: Vec<[f64; 3]>,
    log_w: Vec<f64>,
    rng: ChaCha8Rng,
    mean: Vector3<f64>,
    cov: Matrix3<f64>,
    last_used: u32,
    counters: EkfCounters,
    resamples: u64,
}

impl ParticleFilter {
    /// `pf.particles` particles drawn from N(`initial_pose`, `initial_cov`) among `walls`
    /// (distance grid cap 5σ_hit, margin 1 m). The loss script and the landmark region are
    /// EKF-only.
    pub fn new(
        config: EkfConfig,
        pf: PfConfig,
        map: Vec<Landmark>,
        walls: &[Segment],
        initial_pose: WorldPose,
        initial_cov: Matrix3<f64>,
        seed: u64,
    ) -> Result<Self, LocalizerError> {
        config.validate()?;
        pf.validate()?;
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
        let mut grid = DistanceGrid::new(walls, 1.0, pf.grid_cell_m, 5.0 * pf.sigma_hit_m)?;
        grid.mark_free_from(mean.x, mean.y);
        let l = (initial_cov + Matrix3::identity() * 1e-15)
            .cholesky()
            .ok_or(LocalizerError::InvalidInitialState)?
            .l();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let particles = (0..pf.particles)
            .map(|_| {
                let n = Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal));
                let p = mean + l * n;
                [p.x, p.y, wrap_angle(p.z)]
            })
            .collect();
        let mut f = Self {
            config,
            pf,
            map,
            grid,
            particles,
            log_w: vec![0.0; pf.particles],
            rng,
            mean,
            cov: initial_cov,
            last_used: 0,
            counters: EkfCounters::default(),
            resamples: 0,
        };
        f.estimate();
        Ok(f)
    }

    pub fn mean(&self) -> Vector3<f64> {
        self.mean
    }

    pub fn covariance(&self) -> Matrix3<f64> {
        self.cov
    }

    pub fn counters(&self) -> &EkfCounters {
        &self.counters
    }

    /// Resamplings so far.
    pub fn resamples(&self) -> u64 {
        self.resamples
    }

    pub fn particles(&self) -> &[[f64; 3]] {
        &self.particles
    }

    /// The estimate as a message (covariance row-major; `stamp_ns` 0 for the process loop).
    pub fn to_msg(&self, robot_id: u32, step: u64) -> PoseMsg {
        pose_msg(&self.mean, &self.cov, robot_id, step, self.last_used)
    }

    /// One world step: prediction, landmark and laser weights, resampling, estimate. The sensor
    /// message and the scan are checked first; a rejection leaves the filter untouched.
    pub fn step_with_laser(
        &mut self,
        msg: &SensorMsg,
        laser: Option<&LaserMsg>,
    ) -> Result<UpdateStats, LocalizerError> {
        let checked = check_message(&self.config.limits, msg).and_then(|()| match laser {
            Some(l) => check_laser(l),
            None => Ok(()),
        });
        self.counters.counted(checked)?;
        self.predict_unchecked(msg.v_m_per_s, msg.omega_rad_per_s, msg.dt_s);
        let stats = self.weigh_landmarks(msg.observations());
        if let Some(l) = laser {
            self.weigh_laser(l);
        }
        self.finish_update();
        Ok(stats)
    }

    /// Adds each particle's laser log-likelihood (likelihood field).
    pub fn weigh_laser(&mut self, laser: &LaserMsg) {
        let beams = self.beams(laser);
        let rand = self.z_rand_density(laser);
        for (p, lw) in self.particles.iter().zip(self.log_w.iter_mut()) {
            *lw += Self::beams_log_likelihood(&self.grid, &self.pf, *p, &beams, rand);
        }
    }

    /// The log-likelihood of `laser` seen from `pose`: the laser's and the free space's terms
    /// (what a particle there would add to its log-weight).
    pub fn pose_log_likelihood(&self, pose: [f64; 3], laser: &LaserMsg) -> f64 {
        let beams = self.beams(laser);
        let rand = self.z_rand_density(laser);
        let free = self.pf.free_space && !self.grid.is_free(pose[0], pose[1]);
        Self::beams_log_likelihood(&self.grid, &self.pf, pose, &beams, rand)
            + if free { OFF_FREE_SPACE_LOG } else { 0.0 }
    }

    /// The beams used (angle, range, returned): every `beam_stride`-th; without a return only
    /// with `free_space`.
    fn beams(&self, laser: &LaserMsg) -> Vec<(f64, f64, bool)> {
        laser
            .beams()
            .step_by(self.pf.beam_stride)
            .filter(|b| b.2 || self.pf.free_space)
            .map(|(a, r, hit)| (f64::from(a), f64::from(r), hit))
            .collect()
    }

    fn z_rand_density(&self, laser: &LaserMsg) -> f64 {
        (1.0 - self.pf.z_hit) / f64::from(laser.range_max_m).max(1e-3)
    }

    /// Σ over `beams` of ln(z_hit·N(d; 0, σ²) + z_rand/range_max) for a returned beam, or
    /// ln(THROUGH_WALL_FACTOR) (times z_rand/range_max for a returned beam) when its path up to
    /// its reading less the margin crosses a wall (with `free_space`).
    fn beams_log_likelihood(
        grid: &DistanceGrid,
        pf: &PfConfig,
        p: [f64; 3],
        beams: &[(f64, f64, bool)],
        rand: f64,
    ) -> f64 {
        let sigma = pf.sigma_hit_m;
        let norm = pf.z_hit / (std::f64::consts::TAU.sqrt() * sigma);
        let inv_2s2 = 0.5 / (sigma * sigma);
        let through = THROUGH_WALL_FACTOR.ln();
        let mut sum = 0.0;
        for &(a, r, hit) in beams {
            let angle = p[2] + a;
            let clear_m = r - 3.0 * sigma - 0.075 * r;
            if pf.free_space && clear_m > 0.0 && !grid.ray_clear(p[0], p[1], angle, clear_m) {
                sum += through + if hit { rand.ln() } else { 0.0 };
            } else if hit {
                let (s, c) = angle.sin_cos();
                let d = grid.distance_m(p[0] + r * c, p[1] + r * s);
                sum += (norm * (-d * d * inv_2s2).exp() + rand).ln();
            }
        }
        sum
    }

    /// Adds [`OFF_FREE_SPACE_LOG`] to each particle off the free space (with `free_space`).
    fn weigh_free_space(&mut self) {
        if !self.pf.free_space {
            return;
        }
        for (p, lw) in self.particles.iter().zip(self.log_w.iter_mut()) {
            if !self.grid.is_free(p[0], p[1]) {
                *lw += OFF_FREE_SPACE_LOG;
            }
        }
    }

    /// Adds each particle's landmark log-likelihood; what was matched.
    fn weigh_landmarks(&mut self, observations: &[LandmarkObs]) -> UpdateStats {
        let mut stats = UpdateStats::default();
        if !self.pf.use_landmarks {
            return stats;
        }
        let (sr, sb) = (
            self.config.noise.range_sigma_m,
            self.config.noise.bearing_sigma_rad,
        );
        let cap = self.pf.landmark_d2_cap;
        for obs in observations {
            let candidates: Vec<&Landmark> = self
                .map
                .iter()
                .filter(|l| signatures_match(obs.signature, l.signature))
                .collect();
            if candidates.is_empty() {
                stats.unmatched += 1;
                continue;
            }
            stats.used += 1;
            let (r, b) = (f64::from(obs.range_m), f64::from(obs.bearing_rad));
            for (p, lw) in self.particles.iter().zip(self.log_w.iter_mut()) {
                let best = candidates
                    .iter()
                    .map(|l| {
                        let (dx, dy) = (l.x_m - p[0], l.y_m - p[1]);
                        let nr = (r - dx.hypot(dy)) / sr;
                        let nb = wrap_angle(b - (dy.atan2(dx) - p[2])) / sb;
                        nr * nr + nb * nb
                    })
                    .fold(cap, f64::min);
                *lw -= 0.5 * best;
            }
        }
        self.counters.observations_used += u64::from(stats.used);
        self.counters.observations_unmatched += u64::from(stats.unmatched);
        self.last_used = stats.used;
        stats
    }

    /// Normalizes the weights, resamples when they degenerate, and computes the estimate.
    fn finish_update(&mut self) {
        self.weigh_free_space();
        let max = self.log_w.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if !max.is_finite() {
            self.log_w.fill(0.0);
        } else {
            self.log_w.iter_mut().for_each(|w| *w -= max);
        }
        let w = self.weights();
        let n_eff = 1.0 / w.iter().map(|x| x * x).sum::<f64>();
        self.estimate();
        if n_eff < self.pf.resample_fraction * self.particles.len() as f64 {
            self.resample(&w);
        }
    }

    /// Normalized weights.
    fn weights(&self) -> Vec<f64> {
        let w: Vec<f64> = self.log_w.iter().map(|l| l.exp()).collect();
        let total: f64 = w.iter().sum();
        w.iter().map(|x| x / total).collect()
    }

    /// Low-variance resampling (Probabilistic Robotics Table 4.4).
    fn resample(&mut self, w: &[f64]) {
        let m = self.particles.len();
        let step = 1.0 / m as f64;
        let r = self.rng.random::<f64>() * step;
        let mut c = w[0];
        let mut i = 0;
        let mut next = Vec::with_capacity(m);
        for k in 0..m {
            let u = r + k as f64 * step;
            while u > c && i + 1 < m {
                i += 1;
                c += w[i];
            }
            next.push(self.particles[i]);
        }
        self.particles = next;
        self.log_w.fill(0.0);
        self.resamples += 1;
    }

    /// Weighted mean (θ on the circle) and weighted covariance of the particles.
    fn estimate(&mut self) {
        let w = self.weights();
        let (mut x, mut y, mut s, mut c) = (0.0, 0.0, 0.0, 0.0);
        for (p, wi) in self.particles.iter().zip(&w) {
            x += wi * p[0];
            y += wi * p[1];
            s += wi * p[2].sin();
            c += wi * p[2].cos();
        }
        let mean = Vector3::new(x, y, s.atan2(c));
        let mut cov = Matrix3::zeros();
        for (p, wi) in self.particles.iter().zip(&w) {
            let d = Vector3::new(p[0] - mean.x, p[1] - mean.y, wrap_angle(p[2] - mean.z));
            cov += *wi * d * d.transpose();
        }
        let cov = (cov + cov.transpose()) * 0.5;
        if mean.iter().all(|v| v.is_finite()) && cov.iter().all(|v| v.is_finite()) {
            self.mean = mean;
            self.cov = cov;
        }
    }
}

/// A scan is usable: `count` within the message, every valid range finite and ≥ 0.
pub(super) fn check_laser(l: &LaserMsg) -> Result<(), LocalizerError> {
    if l.count as usize > MAX_LASER_BEAMS {
        return Err(LocalizerError::BadLaser {
            beam: l.count as usize,
            range_m: f64::NAN,
        });
    }
    let header = [l.angle_min_rad, l.angle_step_rad, l.range_max_m];
    if !header.iter().all(|v| v.is_finite()) || l.range_max_m <= 0.0 {
        return Err(LocalizerError::BadLaser {
            beam: 0,
            range_m: f64::from(l.range_max_m),
        });
    }
    for (i, (_, r, _)) in l.beams().enumerate() {
        if !(r.is_finite() && r >= 0.0) {
            return Err(LocalizerError::BadLaser {
                beam: i,
                range_m: f64::from(r),
            });
        }
    }
    Ok(())
}

impl CheckedFilter for ParticleFilter {
    fn limits(&self) -> &InputLimits {
        &self.config.limits
    }

    fn counters_mut(&mut self) -> &mut EkfCounters {
        &mut self.counters
    }

    fn predict_unchecked(&mut self, v: f64, w: f64, dt: f64) {
        let (var_v, var_w) = self.config.noise.control_variances(v, w);
        let (sv, sw) = (var_v.sqrt(), var_w.sqrt());
        for p in self.particles.iter_mut() {
            let nv = v + sv * self.rng.sample::<f64, _>(StandardNormal);
            let nw = w + sw * self.rng.sample::<f64, _>(StandardNormal);
            let (d, ..) = velocity_motion(p[2], nv, nw, dt);
            *p = [p[0] + d.x, p[1] + d.y, wrap_angle(p[2] + d.z)];
        }
        self.counters.predictions += 1;
    }

    /// Landmark weights, resampling and estimate (no laser).
    fn update_unchecked(&mut self, observations: &[LandmarkObs]) -> UpdateStats {
        let stats = self.weigh_landmarks(observations);
        self.finish_update();
        stats
    }
}
