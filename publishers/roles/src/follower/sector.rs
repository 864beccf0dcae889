//! The sector strategies of seed 004: `inverse` (IAS-SS: sector means at distance R_D, the
//! subsets U and V, p(s) ∝ 1 − τ_s by eq. 1, steering θ(t) = θ(t−1) + γ·A_s* by eq. 2) and
//! `uniform` (the paper's baseline: a sector drawn uniformly, same steering).

use std::f64::consts::{FRAC_PI_2, PI};

use pheromone_field::{FrameView, SamplePose};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{
    check_nonneg, check_positive, invalid, wrap_angle, Decision, FollowerConfigError,
    FollowerStrategy, StrategyKind,
};
use pheromone_messages::FollowerState;

/// Settings of the `inverse` and `uniform` strategies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SectorConfig {
    /// R_D, the sensing distance (m): sectors are averaged over the half-disc of this radius.
    pub radius_m: f32,
    /// S: there are 2S + 1 sectors of π/(2S + 1) over [−90°, 90°].
    pub half_sectors: usize,
    /// |U|: the lowest-pheromone sectors always in the draw (inverse only, ≥ 1).
    pub u_count: usize,
    /// |V|: other sectors drawn uniformly at random into the draw (inverse only).
    pub v_count: usize,
    /// γ ∈ [0, 1] of eq. 2: θ(t) = θ(t−1) + γ·A_s*.
    pub gamma: f64,
    /// Constant forward speed (m/s).
    #[serde(alias = "v_mps")]
    pub v_m_per_s: f64,
    /// Turn-rate limit (rad/s).
    #[serde(alias = "omega_max_radps")]
    pub omega_max_rad_per_s: f64,
    /// A new sector is drawn every this many seconds (one seed 004 iteration); 0 = every step.
    /// In between the robot turns toward the heading of eq. 2 at up to `omega_max_rad_per_s`.
    pub decision_period_s: f64,
    /// τ_s = clamp(sector mean / this, 0, 1). 1 for a saturating channel; a negative value reads
    /// anti-pheromone (negative cells) as τ > 0.
    pub saturation_level: f32,
    /// A channel that marks obstacles (e.g. the scenario's `mark_walls`): a sector whose mean on
    /// it exceeds `obstacle_level` counts as saturated (τ_s = 1), so IAS-SS steers away from
    /// walls the way seed 004's robots do where pheromone builds up along them.
    pub obstacle_channel: Option<u32>,
    /// See `obstacle_channel`.
    pub obstacle_level: f32,
    /// Set: `obstacle_channel` holds occupancy log-odds (a robot's own map, steering on it):
    /// a sector's obstacle figure is then the share of its sample points whose log-odds are
    /// ≥ this (cells the robot has seen occupied), blocked above `obstacle_level`.
    pub obstacle_logodds: Option<f32>,
}

impl Default for SectorConfig {
    fn default() -> Self {
        Self {
            radius_m: 1.0,
            half_sectors: 4,
            u_count: 2,
            v_count: 2,
            gamma: 0.5,
            v_m_per_s: 0.3,
            omega_max_rad_per_s: 1.5,
            decision_period_s: 0.0,
            saturation_level: 1.0,
            obstacle_channel: None,
            obstacle_level: 0.05,
            obstacle_logodds: None,
        }
    }
}

impl SectorConfig {
    pub fn validate(&self) -> Result<(), FollowerConfigError> {
        check_positive("sectors.radius_m", self.radius_m as f64)?;
        if self.half_sectors > 90 {
            return Err(invalid(
                "sectors.half_sectors",
                self.half_sectors,
                "must be ≤ 90",
            ));
        }
        let n = 2 * self.half_sectors + 1;
        if self.u_count == 0 || self.u_count > n {
            return Err(invalid(
                "sectors.u_count",
                self.u_count,
                "must be between 1 and 2·half_sectors + 1",
            ));
        }
        if self.v_count > n {
            return Err(invalid(
                "sectors.v_count",
                self.v_count,
                "must be ≤ 2·half_sectors + 1",
            ));
        }
        if !(0.0..=1.0).contains(&self.gamma) {
            return Err(invalid(
                "sectors.gamma",
                self.gamma,
                "must be within [0, 1]",
            ));
        }
        check_nonneg("sectors.v_m_per_s", self.v_m_per_s)?;
        check_positive("sectors.omega_max_rad_per_s", self.omega_max_rad_per_s)?;
        check_nonneg("sectors.decision_period_s", self.decision_period_s)?;
        check_nonneg("sectors.obstacle_level", self.obstacle_level as f64)?;
        if let Some(l) = self.obstacle_logodds {
            check_positive("sectors.obstacle_logodds", l as f64)?;
        }
        if !(self.saturation_level.is_finite() && self.saturation_level != 0.0) {
            return Err(invalid(
                "sectors.saturation_level",
                self.saturation_level,
                "must be finite and ≠ 0",
            ));
        }
        Ok(())
    }

    /// Number of sectors, 2S + 1.
    pub fn sectors(&self) -> usize {
        2 * self.half_sectors + 1
    }
}

/// A_s: the centre angle of sector `s` of `n` relative to the heading (rad); sector 0 is the
/// rightmost, as in `FrameView::sector_means`.
pub fn sector_angle(s: usize, n: usize) -> f64 {
    -FRAC_PI_2 + (s as f64 + 0.5) * PI / n as f64
}

/// Seed 004 eq. 1 over the drawn sectors `members` (U ∪ V): p(s) = (1 − τ_s)/Σ(1 − τ_i), τ
/// clamped to [0, 1]. If every member is saturated (Σ = 0) the draw is uniform over them.
pub fn inverse_probabilities(taus: &[f32], members: &[usize]) -> Vec<f64> {
    let w: Vec<f64> = members
        .iter()
        .map(|&s| 1.0 - (taus[s] as f64).clamp(0.0, 1.0))
        .collect();
    let total: f64 = w.iter().sum();
    if total > 0.0 {
        w.iter().map(|wi| wi / total).collect()
    } else {
        vec![1.0 / members.len() as f64; members.len()]
    }
}

/// The subsets of seed 004: U = the `u_count` lowest-pheromone sectors (ties broken at random,
/// so an empty field has no side bias), V = `v_count` of the others drawn uniformly. Returns
/// U ∪ V, U first.
pub fn draw_members(
    rng: &mut ChaCha8Rng,
    taus: &[f32],
    u_count: usize,
    v_count: usize,
) -> Vec<usize> {
    let n = taus.len();
    let mut order: Vec<usize> = (0..n).collect();
    // Fisher–Yates, then a stable sort: equal τ keep a random order.
    for i in (1..n).rev() {
        let j = rng.random_range(0..=i);
        order.swap(i, j);
    }
    order.sort_by(|&a, &b| taus[a].total_cmp(&taus[b]));
    let u = u_count.clamp(1, n);
    let rest = &order[u..];
    let picked = rand::seq::index::sample(rng, rest.len(), v_count.min(rest.len()));
    let mut members = order[..u].to_vec();
    members.extend(picked.iter().map(|i| rest[i]));
    members
}

/// Draws one sector by seed 004 eqs. 1 (U ∪ V, p ∝ 1 − τ).
pub fn choose_inverse(rng: &mut ChaCha8Rng, taus: &[f32], u_count: usize, v_count: usize) -> usize {
    let members = draw_members(rng, taus, u_count, v_count);
    let p = inverse_probabilities(taus, &members);
    let mut r = rng.random::<f64>();
    for (s, ps) in members.iter().zip(&p) {
        if r < *ps {
            return *s;
        }
        r -= ps;
    }
    *members.last().expect("at least one member")
}

/// Per sector of `n` over [−90°, 90°] about the heading, the share of its sample points (the
/// points [`FrameView::sector_means`] averages) whose value on `channel` is ≥ `level`: how much
/// of a sector a robot's own occupancy grid has seen occupied.
pub fn sector_shares_at_least(
    frame: &FrameView<'_>,
    channel: usize,
    pose: SamplePose,
    radius_m: f32,
    n: usize,
    level: f32,
) -> Vec<f32> {
    let width = std::f32::consts::PI / n as f32;
    let h = frame.geometry.cell_size_m;
    let radial = ((radius_m / h).ceil() as usize).clamp(1, 64);
    (0..n)
        .map(|s| {
            let a0 = pose.theta_rad - std::f32::consts::FRAC_PI_2 + s as f32 * width;
            let (mut hits, mut count) = (0usize, 0usize);
            for i in 0..radial {
                let r = radius_m * (i as f32 + 0.5) / radial as f32;
                let across = ((r * width / h).ceil() as usize).clamp(1, 64);
                for j in 0..across {
                    let a = a0 + width * (j as f32 + 0.5) / across as f32;
                    let v = frame.value(channel, pose.x_m + r * a.cos(), pose.y_m + r * a.sin());
                    hits += (v >= level) as usize;
                    count += 1;
                }
            }
            hits as f32 / count as f32
        })
        .collect()
}

/// What the sector strategies share: sensing, the RNG, and the eq. 2 steering.
#[derive(Debug, Clone)]
struct SectorSteer {
    channel: usize,
    config: SectorConfig,
    rng: ChaCha8Rng,
    goal_heading_rad: Option<f64>,
    since_decision_s: f64,
    last_sector: Option<usize>,
    decisions: u64,
}

#[derive(Debug, Clone, Copy)]
enum SectorRule {
    Inverse,
    Uniform,
}

impl SectorSteer {
    fn new(channel: usize, config: SectorConfig, seed: u64) -> Result<Self, FollowerConfigError> {
        config.validate()?;
        Ok(Self {
            channel,
            config,
            rng: ChaCha8Rng::seed_from_u64(seed),
            goal_heading_rad: None,
            since_decision_s: 0.0,
            last_sector: None,
            decisions: 0,
        })
    }

    /// τ_s of every sector, normalized and clamped to [0, 1]; sectors blocked on the obstacle
    /// channel (if any) count as saturated.
    fn taus(&self, frame: &FrameView<'_>, pose: SamplePose) -> Vec<f32> {
        let c = &self.config;
        let mut taus: Vec<f32> = frame
            .sector_means(self.channel, pose, c.radius_m, c.half_sectors)
            .into_iter()
            .map(|m| {
                let t = m / c.saturation_level;
                if t.is_finite() {
                    t.clamp(0.0, 1.0)
                } else {
                    1.0
                }
            })
            .collect();
        if let Some(blocked) = self.obstacles(frame, pose) {
            for (t, b) in taus.iter_mut().zip(blocked) {
                if b.is_nan() || b > c.obstacle_level {
                    *t = 1.0;
                }
            }
        }
        taus
    }

    /// Each sector's obstacle figure: the mean of the obstacle channel, or with
    /// `obstacle_logodds` the share of its points seen occupied; `None` without one.
    fn obstacles(&self, frame: &FrameView<'_>, pose: SamplePose) -> Option<Vec<f32>> {
        let c = &self.config;
        let oc = c.obstacle_channel.map(|o| o as usize)?;
        if oc >= frame.channels {
            return None;
        }
        Some(match c.obstacle_logodds {
            Some(level) => sector_shares_at_least(frame, oc, pose, c.radius_m, c.sectors(), level),
            None => frame.sector_means(oc, pose, c.radius_m, c.half_sectors),
        })
    }

    /// 1 for the sectors blocked on the obstacle channel, 0 for the others.
    fn obstacle_taus(&self, frame: &FrameView<'_>, pose: SamplePose) -> Vec<f32> {
        let c = &self.config;
        match self.obstacles(frame, pose) {
            Some(b) => b
                .into_iter()
                .map(|b| if b <= c.obstacle_level { 0.0 } else { 1.0 })
                .collect(),
            None => vec![0.0; c.sectors()],
        }
    }

    fn decide(
        &mut self,
        rule: SectorRule,
        frame: &FrameView<'_>,
        pose: SamplePose,
        dt_s: f64,
    ) -> Decision {
        let c = &self.config;
        let level = frame.value(self.channel, pose.x_m, pose.y_m);
        let theta = pose.theta_rad as f64;
        let due = self.goal_heading_rad.is_none()
            || c.decision_period_s == 0.0
            // (a small tolerance so that ten steps of 0.1 s make one period of 1 s)
            || self.since_decision_s >= c.decision_period_s - 1e-9;
        if due {
            let n = c.sectors();
            let s = match rule {
                SectorRule::Inverse => {
                    let taus = self.taus(frame, pose);
                    choose_inverse(&mut self.rng, &taus, c.u_count, c.v_count)
                }
                SectorRule::Uniform => {
                    // Uniform over the sectors not blocked by an obstacle (all if all are).
                    let open: Vec<usize> = match c.obstacle_channel {
                        Some(_) => {
                            let taus = self.obstacle_taus(frame, pose);
                            (0..n).filter(|&i| taus[i] < 1.0).collect()
                        }
                        None => Vec::new(),
                    };
                    if open.is_empty() {
                        self.rng.random_range(0..n)
                    } else {
                        open[self.rng.random_range(0..open.len())]
                    }
                }
            };
            // Seed 004 eq. 2: θ(t) = θ(t−1) + γ·A_s*.
            self.goal_heading_rad = Some(theta + self.config.gamma * sector_angle(s, n));
            self.since_decision_s = 0.0;
            self.last_sector = Some(s);
            self.decisions += 1;
        }
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            self.since_decision_s += dt_s;
            dt_s
        } else {
            f64::INFINITY
        };
        let c = &self.config;
        let err = wrap_angle(self.goal_heading_rad.unwrap_or(theta) - theta);
        Decision {
            v_m_per_s: c.v_m_per_s,
            omega_rad_per_s: (err / dt).clamp(-c.omega_max_rad_per_s, c.omega_max_rad_per_s),
            state: FollowerState::Exploring,
            sensed_level: level,
        }
    }

    fn reset(&mut self) {
        self.goal_heading_rad = None;
        self.since_decision_s = 0.0;
        self.last_sector = None;
    }
}

/// The two sector strategies of seed 004, sharing one steering core:
/// - `inverse` (IAS-SS): each decision senses τ_s in 2S + 1 sectors at R_D, draws a sector from
///   U ∪ V with p(s) ∝ 1 − τ_s (eq. 1) and sets the heading goal θ(t−1) + γ·A_s* (eq. 2);
/// - `uniform` (the paper's baseline): the sector is drawn uniformly from all 2S + 1.
///
/// The command is ω = wrap(goal − θ)/dt clamped to ±`omega_max_rad_per_s` (= γ·A_s*/dt when a sector
/// is drawn every step and the clamp is not reached), at the constant speed `v_m_per_s`. State is
/// always `Exploring`.
#[derive(Debug, Clone)]
pub struct SectorStrategy {
    core: SectorSteer,
    rule: SectorRule,
}

impl SectorStrategy {
    /// The IAS-SS strategy (`inverse`).
    pub fn inverse(
        channel: usize,
        config: SectorConfig,
        seed: u64,
    ) -> Result<Self, FollowerConfigError> {
        Ok(Self {
            core: SectorSteer::new(channel, config, seed)?,
            rule: SectorRule::Inverse,
        })
    }

    /// The uniform baseline (`uniform`).
    pub fn uniform(
        channel: usize,
        config: SectorConfig,
        seed: u64,
    ) -> Result<Self, FollowerConfigError> {
        Ok(Self {
            core: SectorSteer::new(channel, config, seed)?,
            rule: SectorRule::Uniform,
        })
    }

    /// The sector drawn at the last decision (0 = rightmost).
    pub fn last_sector(&self) -> Option<usize> {
        self.core.last_sector
    }

    /// Decisions taken so far.
    pub fn decisions(&self) -> u64 {
        self.core.decisions
    }

    pub fn config(&self) -> &SectorConfig {
        &self.core.config
    }
}

impl FollowerStrategy for SectorStrategy {
    fn name(&self) -> &'static str {
        match self.rule {
            SectorRule::Inverse => StrategyKind::Inverse.name(),
            SectorRule::Uniform => StrategyKind::Uniform.name(),
        }
    }

    fn channel(&self) -> usize {
        self.core.channel
    }

    fn decide(&mut self, frame: &FrameView<'_>, pose: SamplePose, dt_s: f64) -> Decision {
        self.core.decide(self.rule, frame, pose, dt_s)
    }

    fn reset(&mut self) {
        self.core.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::follower::test_support::{half_field, Robot};

    // ---- sector strategies ----

    #[test]
    fn eq1_probabilities_are_inverse_to_pheromone() {
        let taus = [0.0f32, 0.5, 0.75, 1.0, 2.0, -1.0];
        let p = inverse_probabilities(&taus, &[0, 1, 2, 3]);
        let expect = [1.0 / 1.75, 0.5 / 1.75, 0.25 / 1.75, 0.0];
        for (a, b) in p.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{p:?}");
        }
        // Clamped to [0, 1]; all saturated → uniform over the members.
        assert_eq!(inverse_probabilities(&taus, &[3, 4]), vec![0.5, 0.5]);
        assert_eq!(inverse_probabilities(&taus, &[5, 0]), vec![0.5, 0.5]);
    }

    #[test]
    fn u_holds_the_lowest_sectors_and_v_the_others() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let taus = [0.9f32, 0.1, 0.8, 0.05, 0.7, 0.6, 0.95];
        for _ in 0..50 {
            let m = draw_members(&mut rng, &taus, 2, 3);
            assert_eq!(&m[..2], &[3, 1]);
            assert_eq!(m.len(), 5);
            let mut v = m[2..].to_vec();
            v.sort_unstable();
            v.dedup();
            assert_eq!(v.len(), 3);
            assert!(v.iter().all(|s| ![1, 3].contains(s)));
        }
        // Ties are broken at random: on an empty field U is not always the rightmost sectors.
        let flat = [0.0f32; 9];
        let firsts: std::collections::HashSet<usize> = (0..100)
            .map(|_| draw_members(&mut rng, &flat, 1, 0)[0])
            .collect();
        assert!(firsts.len() >= 7, "{firsts:?}");
    }

    #[test]
    fn inverse_prefers_low_pheromone_sectors_over_uniform() {
        let (g, cells) = half_field();
        let frame = FrameView::new(g, 1, &cells);
        let pose = SamplePose::new(5.0, 5.0, 0.0);
        let cfg = SectorConfig::default();
        let taus = frame.sector_means(0, pose, cfg.radius_m, cfg.half_sectors);
        let low: Vec<bool> = taus.iter().map(|&t| t < 0.5).collect();
        assert_eq!(low.iter().filter(|&&l| l).count(), 4, "{taus:?}");
        assert!(
            taus.iter()
                .all(|&t| !(0.2..0.8).contains(&t) || t == taus[4]),
            "{taus:?}"
        );

        let n = 2000;
        let mut inverse = SectorStrategy::inverse(0, cfg.clone(), 42).unwrap();
        let mut uniform = SectorStrategy::uniform(0, cfg, 42).unwrap();
        let (mut k_inv, mut k_uni) = (0usize, 0usize);
        for _ in 0..n {
            inverse.decide(&frame, pose, 0.1);
            uniform.decide(&frame, pose, 0.1);
            k_inv += low[inverse.last_sector().unwrap()] as usize;
            k_uni += low[uniform.last_sector().unwrap()] as usize;
        }
        assert_eq!(
            (inverse.decisions(), uniform.decisions()),
            (n as u64, n as u64)
        );
        let (p1, p2) = (k_inv as f64 / n as f64, k_uni as f64 / n as f64);
        let pooled = (k_inv + k_uni) as f64 / (2 * n) as f64;
        let z = (p1 - p2) / (pooled * (1.0 - pooled) * 2.0 / n as f64).sqrt();
        assert!(z > 3.0, "inverse {p1:.3} vs uniform {p2:.3}: z = {z:.2}");
        // Uniform picks a low sector about 4/9 of the time.
        assert!((p2 - 4.0 / 9.0).abs() < 0.05, "uniform share {p2:.3}");
    }

    #[test]
    fn sector_steering_follows_eq2_and_is_deterministic() {
        let (g, cells) = half_field();
        let frame = FrameView::new(g, 1, &cells);
        let pose = SamplePose::new(5.0, 5.0, 0.4);
        let cfg = SectorConfig {
            omega_max_rad_per_s: 100.0,
            ..SectorConfig::default()
        };
        let n = cfg.sectors();
        let mut s = SectorStrategy::inverse(0, cfg.clone(), 1).unwrap();
        for _ in 0..20 {
            let d = s.decide(&frame, pose, 0.1);
            let a = sector_angle(s.last_sector().unwrap(), n);
            // ω = γ·A_s*/dt (eq. 2 over one step).
            assert!((d.omega_rad_per_s - 0.5 * a / 0.1).abs() < 1e-5, "{d:?}");
            assert_eq!((d.v_m_per_s, d.state), (0.3, FollowerState::Exploring));
        }
        // Clamped turn rate.
        let mut c = SectorStrategy::inverse(0, SectorConfig::default(), 1).unwrap();
        assert!(c.decide(&frame, pose, 0.01).omega_rad_per_s.abs() <= 1.5);
        // Same seed, same choices; another seed, other choices.
        let run = |seed| {
            let mut s = SectorStrategy::inverse(0, cfg.clone(), seed).unwrap();
            (0..50)
                .map(|_| {
                    s.decide(&frame, pose, 0.1);
                    s.last_sector().unwrap()
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
    }

    #[test]
    fn on_an_occupancy_grid_a_sector_with_cells_seen_occupied_is_blocked() {
        // A robot's own map: occupancy log-odds (channel 0), pheromone (channel 1, empty). A
        // wall seen occupied (log-odds 2) 1 m to the robot's left; free cells (−1) elsewhere.
        let g = pheromone_field::GridGeometry {
            width: 50,
            height: 50,
            cell_size_m: 0.2,
            origin_x_m: -5.0,
            origin_y_m: -5.0,
        };
        let n = g.cells();
        let mut cells = vec![0.0f32; 2 * n];
        for y in 0..g.height {
            for x in 0..g.width {
                let (_, wy) = g.world_from_grid(x, y);
                cells[g.index(x, y)] = if (wy - 1.0).abs() < 0.15 { 2.0 } else { -1.0 };
            }
        }
        let frame = FrameView::new(g, 2, &cells);
        let pose = SamplePose::new(0.0, 0.0, 0.0);
        let shares = sector_shares_at_least(&frame, 0, pose, 2.0, 9, 0.4);
        // Sector 0 is the rightmost (−90°), 8 the leftmost (+90°): the wall is on the left.
        assert!(shares[..4].iter().all(|s| *s == 0.0), "{shares:?}");
        assert!(shares[6..].iter().all(|s| *s > 0.02), "{shares:?}");
        let cfg = SectorConfig {
            radius_m: 2.0,
            obstacle_channel: Some(0),
            obstacle_logodds: Some(0.4),
            obstacle_level: 0.02,
            ..SectorConfig::default()
        };
        let mut s = SectorStrategy::uniform(1, cfg.clone(), 3).unwrap();
        for _ in 0..200 {
            s.decide(&frame, pose, 0.1);
            assert!(s.last_sector().unwrap() < 6, "drew a blocked sector");
        }
        // Without the log-odds reading the mean of the plane (negative: mostly free) blocks
        // nothing.
        let mut plain = SectorStrategy::uniform(
            1,
            SectorConfig {
                obstacle_logodds: None,
                ..cfg.clone()
            },
            3,
        )
        .unwrap();
        let drawn: std::collections::HashSet<usize> = (0..200)
            .map(|_| {
                plain.decide(&frame, pose, 0.1);
                plain.last_sector().unwrap()
            })
            .collect();
        assert!(drawn.iter().any(|&k| k >= 6), "{drawn:?}");
        let bad = SectorConfig {
            obstacle_logodds: Some(f32::NAN),
            ..cfg
        };
        let e = SectorStrategy::inverse(1, bad, 0).unwrap_err().to_string();
        assert!(
            e.contains("sectors.obstacle_logodds") && e.contains("NaN"),
            "{e}"
        );
    }

    #[test]
    fn decision_period_holds_the_heading_goal() {
        let (g, cells) = half_field();
        let frame = FrameView::new(g, 1, &cells);
        let cfg = SectorConfig {
            decision_period_s: 1.0,
            ..SectorConfig::default()
        };
        let mut s = SectorStrategy::uniform(0, cfg, 9).unwrap();
        let mut r = Robot::new(5.0, 5.0, 0.0);
        let mut goal = None;
        for k in 0..40 {
            let d = s.decide(&frame, r.pose(), 0.1);
            if k % 10 == 0 {
                let a = sector_angle(s.last_sector().unwrap(), 9);
                goal = Some(r.th + 0.5 * a);
            }
            assert!(d.omega_rad_per_s.abs() <= 1.5 + 1e-12);
            r.advance(&d, 0.1);
            if k % 10 == 9 {
                assert!(
                    wrap_angle(goal.unwrap() - r.th).abs() < 1e-5,
                    "goal not reached by step {k}"
                );
            }
        }
        assert_eq!(s.decisions(), 4);
    }
}
