//! Paper 001 Sec. 5 (Algorithm 1) coupled to area capture: graph robots localize on landmarks.
//!
//! - [`graph_landmarks`] places the world's landmarks along the links of the graph (both sides
//!   of each passage, every `landmark_spacing_m`), each with a signature.
//! - [`Sensing`] simulates, from a robot's true motion on the graph, noisy odometry (the
//!   velocity motion model's control with the α1..α4 noise of Algorithm 1 line 5) and noisy
//!   range-bearing-signature observations of the landmarks in range; seeded, deterministic.
//! - [`PoseFilter`] is the filter a robot runs. The landmark EKF lives in `pheromone-roles`
//!   (`pheromone_roles::localizer::graph_filter`), which depends on this crate; a run is given a
//!   [`MakeFilter`] that builds one per robot.
//! - [`RobotLocalizer`]: each step, the robot matches its observations only against Algorithm 1
//!   lines 10–14's L_set ([`crate::RegionTable::landmark_set`]): a region holder against its
//!   region's landmarks l(A_i), the others against the landmarks of the free areas
//!   l(A) − l(A_c). The comparisons are counted, and the same step is also run (on a copy of the
//!   filter, whose result is thrown away) against the whole map and timed, for η1 and η2
//!   (eq. 13, Fig. 6).
//! - Node deposits are weighted by ρ_t ([`rho_t`], eq. 4): ρ_t = min(1, ρ_ref² / √det Σxy).

use std::collections::BTreeMap;
use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::{Graph, GraphState, GraphUpdate};

/// How a localizing robot weighs what it deposits on a link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepositWeight {
    /// The robot's `link_deposit` as it is (−1: Sec. 4.1).
    Constant,
    /// `link_deposit` × ρ_t of the robot's belief when it chose the link (eqs. 3–4).
    Rho,
}

impl DepositWeight {
    pub fn name(self) -> &'static str {
        match self {
            DepositWeight::Constant => "constant",
            DepositWeight::Rho => "rho",
        }
    }
}

impl std::str::FromStr for DepositWeight {
    type Err = LocalizeError;
    fn from_str(s: &str) -> Result<Self, LocalizeError> {
        match s {
            "constant" => Ok(DepositWeight::Constant),
            "rho" => Ok(DepositWeight::Rho),
            _ => Err(LocalizeError::UnknownWeight(s.to_string())),
        }
    }
}

/// The graph world's landmarks, sensors and noise, and how deposits are weighted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalizeConfig {
    pub deposit: DepositWeight,
    /// Distance between landmarks along a passage.
    pub landmark_spacing_m: f64,
    /// Landmarks stand this far to each side of a passage's centre line.
    pub landmark_offset_m: f64,
    /// Landmark signatures cycle through 1..=signatures (a few distinguishable kinds).
    pub signatures: u32,
    /// Landmarks closer than this are observed.
    pub sensor_range_m: f64,
    pub range_sigma_m: f64,
    pub bearing_sigma_rad: f64,
    /// Control noise of Algorithm 1 line 5 (α1..α4), used by the world and by the filter.
    pub alpha: [f64; 4],
    /// The starting belief's standard deviations (x and y, then θ).
    pub initial_sigma_m: f64,
    pub initial_sigma_rad: f64,
    /// ρ_t = 1 while √det Σxy ≤ ρ_ref² (a 1-σ ellipse no larger than a circle of this radius).
    pub rho_ref_m: f64,
    /// An unlit stretch: no landmark inside this rectangle, `[min_x, min_y, max_x, max_y]` (m).
    /// A robot crossing it runs on odometry alone, so its belief spreads and its ρ_t falls.
    /// All zeros (the default): none.
    pub unlit_rect_m: [f64; 4],
}

impl Default for LocalizeConfig {
    fn default() -> Self {
        Self::new(DepositWeight::Constant)
    }
}

impl LocalizeConfig {
    pub fn new(deposit: DepositWeight) -> Self {
        Self {
            deposit,
            landmark_spacing_m: 1.0,
            landmark_offset_m: 0.5,
            signatures: 8,
            sensor_range_m: 3.0,
            range_sigma_m: 0.05,
            bearing_sigma_rad: 0.02,
            alpha: [0.01, 0.001, 0.001, 0.01],
            initial_sigma_m: 0.05,
            initial_sigma_rad: 0.02,
            rho_ref_m: 0.05,
            unlit_rect_m: [0.0; 4],
        }
    }

    /// Whether (x, y) lies in the unlit rectangle (`unlit_rect_m`; an empty one holds nothing).
    pub fn unlit(&self, x_m: f64, y_m: f64) -> bool {
        let [x0, y0, x1, y1] = self.unlit_rect_m;
        x0 < x1 && y0 < y1 && (x0..=x1).contains(&x_m) && (y0..=y1).contains(&y_m)
    }

    /// Every setting finite and in range; the error names the key and the value.
    pub fn validate(&self) -> Result<(), LocalizeError> {
        let positive = [
            ("landmark_spacing_m", self.landmark_spacing_m),
            ("sensor_range_m", self.sensor_range_m),
            ("range_sigma_m", self.range_sigma_m),
            ("bearing_sigma_rad", self.bearing_sigma_rad),
            ("initial_sigma_m", self.initial_sigma_m),
            ("initial_sigma_rad", self.initial_sigma_rad),
            ("rho_ref_m", self.rho_ref_m),
        ];
        for (key, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(LocalizeError::Config { key, value });
            }
        }
        let non_negative = [
            ("landmark_offset_m", self.landmark_offset_m),
            ("alpha[0]", self.alpha[0]),
            ("alpha[1]", self.alpha[1]),
            ("alpha[2]", self.alpha[2]),
            ("alpha[3]", self.alpha[3]),
        ];
        for (key, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(LocalizeError::Config { key, value });
            }
        }
        // Finite, and each max no less than its min.
        const UNLIT: [&str; 4] = [
            "unlit_rect_m[0]",
            "unlit_rect_m[1]",
            "unlit_rect_m[2]",
            "unlit_rect_m[3]",
        ];
        for (i, v) in self.unlit_rect_m.into_iter().enumerate() {
            if !v.is_finite() || (i >= 2 && v < self.unlit_rect_m[i - 2]) {
                return Err(LocalizeError::Config {
                    key: UNLIT[i],
                    value: v,
                });
            }
        }
        if self.signatures == 0 {
            return Err(LocalizeError::Config {
                key: "signatures",
                value: 0.0,
            });
        }
        Ok(())
    }
}

/// Why localization on the graph failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LocalizeError {
    #[error("localization: `{key}` = {value} is invalid (finite, > 0; offsets and α >= 0)")]
    Config { key: &'static str, value: f64 },
    #[error("unknown deposit weight '{0}' (expected constant or rho)")]
    UnknownWeight(String),
    #[error("robot R{robot}: covariance {cov:?} is not finite and positive semi-definite")]
    Covariance { robot: u32, cov: [[f64; 3]; 3] },
    #[error("robot R{robot}: filter: {detail}")]
    Filter { robot: u32, detail: String },
}

/// A landmark: position and signature.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GraphLandmark {
    pub x_m: f64,
    pub y_m: f64,
    pub signature: u32,
}

/// Odometry of one step: the control of the velocity motion model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Odometry {
    pub v_m_per_s: f64,
    pub omega_rad_per_s: f64,
    pub dt_s: f64,
}

/// One observation of a landmark (robot frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    pub range_m: f64,
    pub bearing_rad: f64,
    pub signature: u32,
}

/// What one filter step did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FilterStep {
    /// Landmark comparisons of the association (observations × landmarks of the set).
    pub compared: u64,
    /// Observations that corrected the state.
    pub used: u32,
}

/// A pose filter on the landmark map (Algorithm 1).
pub trait PoseFilter: Send {
    /// Prediction with `odometry`, then each observation matched only against the map indices
    /// `candidates` (Algorithm 1 lines 10–14; `None` = the whole map).
    fn step(
        &mut self,
        odometry: Odometry,
        observations: &[Observation],
        candidates: Option<&[usize]>,
    ) -> Result<FilterStep, String>;
    /// Mean (x, y, θ).
    fn mean(&self) -> [f64; 3];
    /// Covariance of (x, y, θ).
    fn covariance(&self) -> [[f64; 3]; 3];
    fn boxed_clone(&self) -> Box<dyn PoseFilter>;
}

impl Clone for Box<dyn PoseFilter> {
    fn clone(&self) -> Self {
        self.boxed_clone()
    }
}

/// Builds a robot's filter over the map, starting at a pose.
pub type MakeFilter = dyn Fn(&LocalizeConfig, &[GraphLandmark], [f64; 3]) -> Result<Box<dyn PoseFilter>, String>
    + Sync;

/// A run whose robots localize: the settings and the filter they build.
#[derive(Clone, Copy)]
pub struct Localization<'a> {
    pub config: LocalizeConfig,
    pub make_filter: &'a MakeFilter,
}

/// The landmarks of the graph world: along every link (each once), every `landmark_spacing_m`
/// from half a spacing on, one on each side of the centre line; signatures cycle 1..=N.
pub fn graph_landmarks(g: &Graph, c: &LocalizeConfig) -> Vec<GraphLandmark> {
    let mut out = Vec::new();
    for (a, node) in g.nodes().iter().enumerate() {
        for (_, l) in node.links() {
            if l.to <= a {
                continue;
            }
            let b = &g.nodes()[l.to];
            let (ax, ay) = (f64::from(node.x_m), f64::from(node.y_m));
            let (dx, dy) = (f64::from(b.x_m) - ax, f64::from(b.y_m) - ay);
            let len = dx.hypot(dy);
            if len <= 0.0 {
                continue;
            }
            let (ux, uy) = (dx / len, dy / len);
            let count = ((len / c.landmark_spacing_m).floor() as usize).max(1);
            let step = len / count as f64;
            for k in 0..count {
                let s = (k as f64 + 0.5) * step;
                for side in [1.0, -1.0] {
                    let off = side * c.landmark_offset_m;
                    let (x_m, y_m) = (ax + ux * s - uy * off, ay + uy * s + ux * off);
                    if c.unlit(x_m, y_m) {
                        continue;
                    }
                    out.push(GraphLandmark {
                        x_m,
                        y_m,
                        signature: (out.len() as u32 % c.signatures) + 1,
                    });
                }
            }
        }
    }
    out
}

/// ρ_t of a covariance (eq. 4, MODELS.md M2): min(1, ρ_ref² / √det Σxy), 1 for a zero Σxy.
/// A covariance that is not finite, or whose position block is not positive semi-definite,
/// is refused.
pub fn rho_t(cov: &[[f64; 3]; 3], rho_ref_m: f64, robot: u32) -> Result<f64, LocalizeError> {
    let det = cov[0][0] * cov[1][1] - cov[0][1] * cov[1][0];
    let finite = cov.iter().flatten().all(|v| v.is_finite());
    if !finite || cov[0][0] < 0.0 || cov[1][1] < 0.0 || det < 0.0 {
        return Err(LocalizeError::Covariance { robot, cov: *cov });
    }
    if det == 0.0 {
        return Ok(1.0);
    }
    Ok((rho_ref_m * rho_ref_m / det.sqrt()).min(1.0))
}

fn wrap(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w <= -std::f64::consts::PI {
        w + std::f64::consts::TAU
    } else {
        w
    }
}

/// The world's sensors for one robot: noisy odometry and observations, seeded.
#[derive(Debug, Clone)]
pub struct Sensing {
    rng: ChaCha8Rng,
    config: LocalizeConfig,
}

impl Sensing {
    pub fn new(config: LocalizeConfig, seed: u64, robot: u32) -> Self {
        let stream = seed ^ 0x10ca_112e ^ u64::from(robot).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        Self {
            rng: ChaCha8Rng::seed_from_u64(stream),
            config,
        }
    }

    fn normal(&mut self) -> f64 {
        self.rng.sample(StandardNormal)
    }

    /// The odometry of the true motion `from` → `to` over `dt_s`, with Algorithm 1 line 5's
    /// noise: v ~ N(v, α1 v² + α2 ω²), ω ~ N(ω, α3 v² + α4 ω²).
    pub fn odometry(&mut self, from: [f64; 3], to: [f64; 3], dt_s: f64) -> Odometry {
        let v = (to[0] - from[0]).hypot(to[1] - from[1]) / dt_s;
        let w = wrap(to[2] - from[2]) / dt_s;
        let [a1, a2, a3, a4] = self.config.alpha;
        let sv = (a1 * v * v + a2 * w * w).sqrt();
        let sw = (a3 * v * v + a4 * w * w).sqrt();
        Odometry {
            v_m_per_s: v + sv * self.normal(),
            omega_rad_per_s: w + sw * self.normal(),
            dt_s,
        }
    }

    /// Range, bearing and signature of every landmark within range of the true pose.
    pub fn observe(&mut self, truth: [f64; 3], map: &[GraphLandmark]) -> Vec<Observation> {
        let mut out = Vec::new();
        for lm in map {
            let (dx, dy) = (lm.x_m - truth[0], lm.y_m - truth[1]);
            let r = dx.hypot(dy);
            if r > self.config.sensor_range_m {
                continue;
            }
            let range_m = (r + self.config.range_sigma_m * self.normal()).max(0.0);
            let bearing_rad =
                wrap(dy.atan2(dx) - truth[2] + self.config.bearing_sigma_rad * self.normal());
            out.push(Observation {
                range_m,
                bearing_rad,
                signature: lm.signature,
            });
        }
        out
    }
}

/// Association work and time of one class of steps (Algorithm 1 lines 10–14).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MatchWork {
    pub steps: u64,
    /// Σ over the steps of |L_set|, the landmarks the robot matched against.
    pub landmarks_considered: u64,
    /// Σ of |LM|, the whole map, over the same steps.
    pub landmarks_whole_map: u64,
    /// Landmark comparisons made (observation × landmark of L_set).
    pub compared: u64,
    /// Comparisons the same steps make against the whole map.
    pub compared_whole_map: u64,
    /// Time of the filter steps with L_set, and of the same steps against the whole map.
    pub step_ns: u64,
    pub step_whole_map_ns: u64,
}

impl MatchWork {
    /// Whole map over L_set, by comparisons (eq. 13 counted).
    pub fn eta_by_count(&self) -> Option<f64> {
        (self.compared > 0).then(|| self.compared_whole_map as f64 / self.compared as f64)
    }

    /// Whole map over L_set, by wall-clock time per step (Fig. 6 measured; varies with load).
    pub fn eta_by_time(&self) -> Option<f64> {
        (self.step_ns > 0).then(|| self.step_whole_map_ns as f64 / self.step_ns as f64)
    }

    fn add(&mut self, o: &MatchWork) {
        self.steps += o.steps;
        self.landmarks_considered += o.landmarks_considered;
        self.landmarks_whole_map += o.landmarks_whole_map;
        self.compared += o.compared;
        self.compared_whole_map += o.compared_whole_map;
        self.step_ns += o.step_ns;
        self.step_whole_map_ns += o.step_whole_map_ns;
    }
}

/// A robot's localization over a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LocalizationStats {
    /// |LM|: landmarks of the whole map.
    pub landmarks: usize,
    /// Steps of a region holder: L_set = its region's landmarks (η1).
    pub holding: MatchWork,
    /// Steps without a region while others hold some: L_set = the free areas' landmarks (η2).
    pub free: MatchWork,
    /// Steps while nothing is captured: L_set = the whole map.
    pub open: MatchWork,
    /// Holder steps by region: (landmarks of the region, the work).
    pub by_region: BTreeMap<String, (usize, MatchWork)>,
    pub observations: u64,
    pub observations_used: u64,
    /// Link deposits made, and their smallest and largest ρ_t and amount.
    pub deposits: u64,
    pub rho_min: f64,
    pub rho_max: f64,
    pub deposit_min: f32,
    pub deposit_max: f32,
    pub position_error_max_m: f64,
    pub position_error_mean_m: f64,
}

impl LocalizationStats {
    /// The robots' stats together (by-region work summed; extremes over all).
    pub fn merge(all: &[&LocalizationStats]) -> LocalizationStats {
        let mut m = LocalizationStats {
            rho_min: f64::INFINITY,
            rho_max: f64::NEG_INFINITY,
            deposit_min: f32::INFINITY,
            deposit_max: f32::NEG_INFINITY,
            ..Default::default()
        };
        let mut steps = 0u64;
        for s in all {
            m.landmarks = m.landmarks.max(s.landmarks);
            m.holding.add(&s.holding);
            m.free.add(&s.free);
            m.open.add(&s.open);
            for (name, (n, w)) in &s.by_region {
                let e = m.by_region.entry(name.clone()).or_default();
                e.0 = *n;
                e.1.add(w);
            }
            m.observations += s.observations;
            m.observations_used += s.observations_used;
            if s.deposits > 0 {
                m.rho_min = m.rho_min.min(s.rho_min);
                m.rho_max = m.rho_max.max(s.rho_max);
                m.deposit_min = m.deposit_min.min(s.deposit_min);
                m.deposit_max = m.deposit_max.max(s.deposit_max);
            }
            m.deposits += s.deposits;
            m.position_error_max_m = m.position_error_max_m.max(s.position_error_max_m);
            let n = s.holding.steps + s.free.steps + s.open.steps;
            m.position_error_mean_m += s.position_error_mean_m * n as f64;
            steps += n;
        }
        if steps > 0 {
            m.position_error_mean_m /= steps as f64;
        }
        if m.deposits == 0 {
            (m.rho_min, m.rho_max, m.deposit_min, m.deposit_max) = (0.0, 0.0, 0.0, 0.0);
        }
        m
    }
}

/// Which class a step's L_set belongs to.
enum StepClass<'a> {
    Holding(&'a str),
    Free,
    Open,
}

/// One robot's localizer on the graph: its filter, its sensors, its true pose and its stats.
#[derive(Clone)]
pub struct RobotLocalizer {
    robot: u32,
    config: LocalizeConfig,
    map: Vec<GraphLandmark>,
    map_xy: Vec<[f64; 2]>,
    filter: Box<dyn PoseFilter>,
    sensing: Sensing,
    truth: [f64; 3],
    rho: f64,
    error_sum_m: f64,
    pub stats: LocalizationStats,
}

impl std::fmt::Debug for RobotLocalizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RobotLocalizer")
            .field("robot", &self.robot)
            .field("truth", &self.truth)
            .field("mean", &self.filter.mean())
            .field("rho", &self.rho)
            .finish()
    }
}

impl RobotLocalizer {
    /// Robot `robot` starting (exactly known up to the initial σ) at `start_xy`, heading +x.
    pub fn new(
        loc: &Localization,
        g: &Graph,
        robot: u32,
        seed: u64,
        start_xy: [f64; 2],
    ) -> Result<Self, LocalizeError> {
        loc.config.validate()?;
        let map = graph_landmarks(g, &loc.config);
        let truth = [start_xy[0], start_xy[1], 0.0];
        let filter = (loc.make_filter)(&loc.config, &map, truth)
            .map_err(|detail| LocalizeError::Filter { robot, detail })?;
        let map_xy = map.iter().map(|l| [l.x_m, l.y_m]).collect();
        let rho = rho_t(&filter.covariance(), loc.config.rho_ref_m, robot)?;
        Ok(Self {
            robot,
            config: loc.config,
            stats: LocalizationStats {
                landmarks: map.len(),
                rho_min: f64::INFINITY,
                rho_max: f64::NEG_INFINITY,
                deposit_min: f32::INFINITY,
                deposit_max: f32::NEG_INFINITY,
                ..Default::default()
            },
            map,
            map_xy,
            filter,
            sensing: Sensing::new(loc.config, seed, robot),
            truth,
            rho,
            error_sum_m: 0.0,
        })
    }

    /// ρ_t of the current belief.
    pub fn rho(&self) -> f64 {
        self.rho
    }

    /// Weighs this step's link deposits (those the robot decided on with its current belief)
    /// by ρ_t, or leaves them as they are ([`DepositWeight::Constant`]); records them.
    pub fn weigh_deposits(&mut self, updates: &mut [GraphUpdate]) {
        let rho = self.rho;
        for u in updates {
            if let GraphUpdate::AddToLink { amount, .. } = u {
                if self.config.deposit == DepositWeight::Rho {
                    *amount = (f64::from(*amount) * rho) as f32;
                }
                let s = &mut self.stats;
                s.deposits += 1;
                s.rho_min = s.rho_min.min(rho);
                s.rho_max = s.rho_max.max(rho);
                s.deposit_min = s.deposit_min.min(*amount);
                s.deposit_max = s.deposit_max.max(*amount);
            }
        }
    }

    /// One step: the robot truly moved to `xy` (heading `heading_rad`, or kept); the world
    /// gives odometry and observations, and the filter runs Algorithm 1 with the L_set of the
    /// robot's standing in `state` (lines 10–14). A region holder's or a free robot's step is
    /// run and timed once more against the whole map on a copy of the filter.
    pub fn step(
        &mut self,
        state: &GraphState,
        xy: [f64; 2],
        heading_rad: Option<f64>,
        dt_s: f64,
    ) -> Result<(), LocalizeError> {
        let now = [xy[0], xy[1], heading_rad.unwrap_or(self.truth[2])];
        let odometry = self.sensing.odometry(self.truth, now, dt_s);
        self.truth = now;
        let obs = self.sensing.observe(now, &self.map);
        let regions = &state.regions;
        let held = regions.held_by(self.robot);
        let anyone_holds = regions.regions().iter().any(|r| !r.captured_by.is_empty());
        let class = match held {
            Some(i) => StepClass::Holding(&regions.regions()[i].name),
            None if anyone_holds => StepClass::Free,
            None => StepClass::Open,
        };
        let set = match class {
            StepClass::Open => None,
            _ => Some(regions.landmark_set(self.robot, &self.map_xy)),
        };
        // The whole-map twin runs first on odd steps, second on even ones (cache effects).
        let mut twin = set.as_ref().map(|_| self.filter.boxed_clone());
        let steps = self.stats.holding.steps + self.stats.free.steps + self.stats.open.steps;
        let mut whole = None;
        let whole_first = !steps.is_multiple_of(2);
        if whole_first {
            whole = twin
                .as_mut()
                .map(|t| timed(t.as_mut(), odometry, &obs, None));
        }
        let (own, own_ns) = timed(self.filter.as_mut(), odometry, &obs, set.as_deref());
        if !whole_first {
            whole = twin
                .as_mut()
                .map(|t| timed(t.as_mut(), odometry, &obs, None));
        }
        let robot = self.robot;
        let err = |detail| LocalizeError::Filter { robot, detail };
        let own = own.map_err(err)?;
        let (whole, whole_ns) = match whole {
            Some((w, ns)) => (w.map_err(err)?, ns),
            None => (own, own_ns),
        };
        let work = MatchWork {
            steps: 1,
            landmarks_considered: set.as_ref().map_or(self.map.len(), Vec::len) as u64,
            landmarks_whole_map: self.map.len() as u64,
            compared: own.compared,
            compared_whole_map: whole.compared,
            step_ns: own_ns,
            step_whole_map_ns: whole_ns,
        };
        let s = &mut self.stats;
        match class {
            StepClass::Holding(name) => {
                let e = s.by_region.entry(name.to_string()).or_default();
                e.0 = work.landmarks_considered as usize;
                e.1.add(&work);
                s.holding.add(&work);
            }
            StepClass::Free => s.free.add(&work),
            StepClass::Open => s.open.add(&work),
        }
        s.observations += obs.len() as u64;
        s.observations_used += u64::from(own.used);
        let mean = self.filter.mean();
        let e = (mean[0] - now[0]).hypot(mean[1] - now[1]);
        s.position_error_max_m = s.position_error_max_m.max(e);
        self.error_sum_m += e;
        s.position_error_mean_m = self.error_sum_m / (steps + 1) as f64;
        self.rho = rho_t(&self.filter.covariance(), self.config.rho_ref_m, robot)?;
        Ok(())
    }

    /// The stats to report (extremes of a robot that never deposited are 0).
    pub fn report(&self) -> LocalizationStats {
        let mut s = self.stats.clone();
        if s.deposits == 0 {
            (s.rho_min, s.rho_max, s.deposit_min, s.deposit_max) = (0.0, 0.0, 0.0, 0.0);
        }
        s
    }
}

fn timed(
    f: &mut dyn PoseFilter,
    odometry: Odometry,
    obs: &[Observation],
    set: Option<&[usize]>,
) -> (Result<FilterStep, String>, u64) {
    let t0 = Instant::now();
    let r = f.step(odometry, obs, set);
    (r, t0.elapsed().as_nanos() as u64)
}

/// A run's localization: its settings, every robot's stats together, and η1, η2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunLocalization {
    pub config: LocalizeConfig,
    pub all: LocalizationStats,
    /// Eq. 13 from the landmark counts of the steps: Σ|LM| / Σ|L_set| (holders: η1, free
    /// robots while others hold regions: η2).
    pub eta1_eq13: Option<f64>,
    pub eta2_eq13: Option<f64>,
    /// The same from the landmark comparisons made.
    pub eta1_compared: Option<f64>,
    pub eta2_compared: Option<f64>,
    /// A wall-clock figure, not a result: time of the steps against the whole map over time
    /// with L_set (Fig. 6 measured). It moves with the machine's load (0.12–14.7 for one
    /// configuration); η is [`Self::eta1_eq13`] / [`Self::eta1_compared`], from counts.
    pub eta1_wall_clock: Option<f64>,
    pub eta2_wall_clock: Option<f64>,
    /// Mean time of a localization step (ns): holders with L_set and against the whole map.
    pub holding_step_ns: Option<f64>,
    pub holding_step_whole_map_ns: Option<f64>,
    pub free_step_ns: Option<f64>,
    pub free_step_whole_map_ns: Option<f64>,
}

impl RunLocalization {
    pub fn new(config: LocalizeConfig, robots: &[&LocalizationStats]) -> Self {
        let all = LocalizationStats::merge(robots);
        let eq13 = |w: &MatchWork| {
            (w.landmarks_considered > 0)
                .then(|| w.landmarks_whole_map as f64 / w.landmarks_considered as f64)
        };
        let per_step = |ns: u64, w: &MatchWork| (w.steps > 0).then(|| ns as f64 / w.steps as f64);
        Self {
            config,
            eta1_eq13: eq13(&all.holding),
            eta2_eq13: eq13(&all.free),
            eta1_compared: all.holding.eta_by_count(),
            eta2_compared: all.free.eta_by_count(),
            eta1_wall_clock: all.holding.eta_by_time(),
            eta2_wall_clock: all.free.eta_by_time(),
            holding_step_ns: per_step(all.holding.step_ns, &all.holding),
            holding_step_whole_map_ns: per_step(all.holding.step_whole_map_ns, &all.holding),
            free_step_ns: per_step(all.free.step_ns, &all.free),
            free_step_whole_map_ns: per_step(all.free.step_whole_map_ns, &all.free),
            all,
        }
    }
}

#[cfg(test)]
mod tests;
