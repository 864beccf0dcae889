//! The landmark [`Ekf`] as the pose filter of graph robots (seed 001 Algorithm 1 coupled to
//! area capture, `pheromone_graph::localize`): `pheromone-graph` defines what a filter must do, this
//! crate (which depends on it) supplies the EKF.

use nalgebra::Matrix3;
use pheromone_graph::localize::{
    FilterStep, GraphLandmark, LocalizeConfig, Observation, Odometry, PoseFilter,
};
use pheromone_messages::LandmarkObs;

use super::{CheckedFilter, Ekf, EkfConfig, InputLimits};
use pheromone_messages::{Landmark, NoiseConfig, WorldPose};

/// A graph robot's EKF: association restricted to the L_set it is given each step.
#[derive(Debug, Clone)]
pub struct GraphEkf {
    ekf: Ekf,
}

impl GraphEkf {
    /// The EKF of a graph world with `config`'s noise over `map`, starting at `start`
    /// (x, y, θ) with `config`'s initial σ. Turns at nodes take one step (|ω| up to π / dt),
    /// so the turn-rate limit is 100 rad/s.
    pub fn new(
        config: &LocalizeConfig,
        map: &[GraphLandmark],
        start: [f64; 3],
    ) -> Result<Self, super::LocalizerError> {
        let [alpha1, alpha2, alpha3, alpha4] = config.alpha;
        let cfg = EkfConfig {
            noise: NoiseConfig {
                range_sigma_m: config.range_sigma_m,
                bearing_sigma_rad: config.bearing_sigma_rad,
                alpha1,
                alpha2,
                alpha3,
                alpha4,
            },
            limits: InputLimits {
                max_turn_rate_rad_per_s: 100.0,
                ..InputLimits::default()
            },
            ..EkfConfig::default()
        };
        let map = map
            .iter()
            .map(|l| Landmark {
                x_m: l.x_m,
                y_m: l.y_m,
                signature: l.signature,
            })
            .collect();
        let (sm, sr) = (config.initial_sigma_m, config.initial_sigma_rad);
        let cov = Matrix3::from_diagonal(&nalgebra::Vector3::new(sm * sm, sm * sm, sr * sr));
        let ekf = Ekf::new(cfg, map, WorldPose::new(start[0], start[1], start[2]), cov)?;
        Ok(Self { ekf })
    }

    pub fn ekf(&self) -> &Ekf {
        &self.ekf
    }
}

/// Builds a boxed [`GraphEkf`]: the `make_filter` of a `pheromone_graph::localize::Localization`.
pub fn make_graph_ekf(
    config: &LocalizeConfig,
    map: &[GraphLandmark],
    start: [f64; 3],
) -> Result<Box<dyn PoseFilter>, String> {
    GraphEkf::new(config, map, start)
        .map(|f| Box::new(f) as Box<dyn PoseFilter>)
        .map_err(|e| e.to_string())
}

impl PoseFilter for GraphEkf {
    fn step(
        &mut self,
        odometry: Odometry,
        observations: &[Observation],
        candidates: Option<&[usize]>,
    ) -> Result<FilterStep, String> {
        if self.ekf.landmark_filter() != candidates {
            self.ekf
                .set_landmark_filter(candidates.map(<[usize]>::to_vec))
                .map_err(|e| e.to_string())?;
        }
        let before = self.ekf.counters().landmarks_compared;
        self.ekf
            .predict(odometry.v_m_per_s, odometry.omega_rad_per_s, odometry.dt_s)
            .map_err(|e| e.to_string())?;
        let obs: Vec<LandmarkObs> = observations
            .iter()
            .map(|o| LandmarkObs {
                range_m: o.range_m as f32,
                bearing_rad: o.bearing_rad as f32,
                signature: o.signature,
                _pad: 0,
            })
            .collect();
        let stats = self.ekf.update(&obs).map_err(|e| e.to_string())?;
        Ok(FilterStep {
            compared: self.ekf.counters().landmarks_compared - before,
            used: stats.used,
        })
    }

    fn mean(&self) -> [f64; 3] {
        let m = self.ekf.mean();
        [m.x, m.y, m.z]
    }

    fn covariance(&self) -> [[f64; 3]; 3] {
        let c = self.ekf.covariance();
        std::array::from_fn(|i| std::array::from_fn(|j| c[(i, j)]))
    }

    fn boxed_clone(&self) -> Box<dyn PoseFilter> {
        Box::new(self.clone())
    }
}

#[cfg(test)]
mod tests;
