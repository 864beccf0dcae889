//! The series the charts draw, computed from what the run recorded (its [`Recording`]) and the
//! scenario it ran: nothing here is made up or read from anywhere else.
//! - [`probe_curves`]: each probe's readings and the closed form of its channel's model
//!   (seed 000 eqs. 19–22, Figs. 6–8);
//! - [`exploration_over_time`]: the share of sectors each robot, and the team, has visited by
//!   each step (seed 004);
//! - [`path_distances`]: each path-following robot's distance to its path at each step
//!   (seed 002);
//! - [`leader_deposits`]: the peak of each deposit the leader made, by distance along its path,
//!   with where it got lost and where its deposit fell below the follower's threshold (seed
//!   000's corridor, Fig. 23).

use std::collections::BTreeMap;

use pheromone_field::Evaporation;

use pheromone_roles::follower::StrategyKind;
use pheromone_sim::metrics::{
    blind_leader, distance_to_polyline_m, mean_path_error_m, BlindLeader,
};
use pheromone_sim::recording::Recording;
use pheromone_sim::wrong_area::{checkpoints, deposit_below_threshold, ThresholdCrossing};
use pheromone_world::scenario::{BlindLeaderMetric, ExplorationMetric, Scenario};

/// The closed form a probe's readings are compared with: the level `p0` read at `t0_s`,
/// evaporating by the channel's model with the ambient level held fixed (seed 000 eq. 19).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosedForm {
    pub t0_s: f64,
    pub p0: f64,
    /// α·Pa: the level the ambient model decays towards (0 for the other models).
    pub ambient: f64,
    /// e-folding rate K (1/s) of the exponential and ambient models; for a saturating channel
    /// −ln(1 − ρ)/dt.
    pub decay_per_s: f64,
}

impl ClosedForm {
    /// P(t) = Pa + (P0 − Pa)·e^(−K(t − t0)) above the ambient level; a cell at or below it
    /// keeps its level (MODELS.md M1: evaporation never raises a cell).
    pub fn at(&self, t_s: f64) -> f64 {
        if self.p0 <= self.ambient {
            return self.p0;
        }
        self.ambient + (self.p0 - self.ambient) * (-self.decay_per_s * (t_s - self.t0_s)).exp()
    }
}

/// One probe (a point and channel) of the run.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeCurve {
    pub x_m: f32,
    pub y_m: f32,
    pub channel: u32,
    pub channel_name: String,
    /// (t_s, value) in the order recorded.
    pub readings: Vec<(f64, f32)>,
    /// None for a model without a closed form here (`quantum`), or when the ambient level at
    /// the first reading cannot be read (no snapshot of that frame).
    pub closed_form: Option<ClosedForm>,
}

/// The run's probe readings grouped by probe, each with its closed form. P0 is the first
/// reading; the ambient level Pa is the ambient model's own mean (the square window of half-width
/// `radius_m`) around the probe in the snapshot of that frame, times α.
pub fn probe_curves(scenario: &Scenario, rec: &Recording) -> Vec<ProbeCurve> {
    let mut curves: Vec<ProbeCurve> = Vec::new();
    for p in &rec.probes {
        let same = |c: &&mut ProbeCurve| c.x_m == p.x_m && c.y_m == p.y_m && c.channel == p.channel;
        match curves.iter_mut().find(|c| same(c)) {
            Some(c) => c.readings.push((p.t_s, p.value)),
            None => curves.push(ProbeCurve {
                x_m: p.x_m,
                y_m: p.y_m,
                channel: p.channel,
                channel_name: scenario
                    .field
                    .channels
                    .get(p.channel as usize)
                    .map_or_else(|| format!("channel {}", p.channel), |c| c.name.clone()),
                readings: vec![(p.t_s, p.value)],
                closed_form: None,
            }),
        }
    }
    for c in &mut curves {
        c.closed_form = closed_form(scenario, rec, c);
    }
    curves
}

fn closed_form(scenario: &Scenario, rec: &Recording, c: &ProbeCurve) -> Option<ClosedForm> {
    let spec = scenario.field.channels.get(c.channel as usize)?;
    let &(t0_s, p0) = c.readings.first()?;
    let p0 = p0 as f64;
    let dt_s = scenario.world.dt_s;
    let (ambient, decay_per_s) = match spec.evaporation {
        Evaporation::None => (0.0, 0.0),
        Evaporation::Exponential { decay_per_s } => (0.0, decay_per_s as f64),
        Evaporation::Saturating { rho_per_tick } => (0.0, -(1.0 - rho_per_tick as f64).ln() / dt_s),
        Evaporation::Quantum { .. } => return None,
        Evaporation::Ambient {
            decay_per_s,
            alpha,
            radius_m,
        } => {
            let snap = rec
                .snapshots
                .iter()
                .find(|s| (s.t_s - t0_s).abs() < 0.5 * dt_s)?;
            let g = scenario.field.geometry();
            let (x, y) = g.cell_at(c.x_m, c.y_m)?;
            let r = (radius_m / g.cell_size_m).round() as usize;
            let plane = snap.plane(c.channel as usize);
            let pa = pheromone_field::models::ambient_mean_brute(
                plane,
                snap.width as usize,
                x as usize,
                y as usize,
                r,
            );
            (alpha as f64 * pa as f64, decay_per_s as f64)
        }
    };
    Some(ClosedForm {
        t0_s,
        p0,
        ambient,
        decay_per_s,
    })
}

/// The share of the sectors visited by each step's time, per robot and for the team.
#[derive(Debug, Clone, PartialEq)]
pub struct ExplorationSeries {
    pub sectors: u32,
    /// (t_s, share) per robot, one point per recorded step.
    pub per_robot: BTreeMap<u32, Vec<(f64, f64)>>,
    /// (t_s, share visited by at least one robot), at every time any robot recorded.
    pub team: Vec<(f64, f64)>,
}

pub fn exploration_over_time(m: &ExplorationMetric, rec: &Recording) -> ExplorationSeries {
    let n = (m.cols * m.rows) as usize;
    let share = |count: usize| count as f64 / n.max(1) as f64;
    let mut per_robot = BTreeMap::new();
    // (t, sector) of every first visit by a robot, for the team's series.
    let mut visits: Vec<(f64, usize)> = Vec::new();
    let mut times: Vec<f64> = Vec::new();
    for (&id, rows) in &rec.robots {
        let mut seen = vec![false; n];
        let mut count = 0;
        let mut series = Vec::with_capacity(rows.len());
        for r in rows {
            if let Some(s) = m.sector_index(r.true_pose[0], r.true_pose[1]) {
                if !seen[s] {
                    seen[s] = true;
                    count += 1;
                    visits.push((r.t_s, s));
                }
            }
            series.push((r.t_s, share(count)));
            times.push(r.t_s);
        }
        per_robot.insert(id, series);
    }
    visits.sort_by(|a, b| a.0.total_cmp(&b.0));
    times.sort_by(f64::total_cmp);
    times.dedup();
    let mut team_seen = vec![false; n];
    let mut count = 0;
    let mut next = visits.iter().peekable();
    let team = times
        .iter()
        .map(|&t| {
            while let Some(&&(_, s)) = next.peek().filter(|v| v.0 <= t) {
                next.next();
                if !team_seen[s] {
                    team_seen[s] = true;
                    count += 1;
                }
            }
            (t, share(count))
        })
        .collect();
    ExplorationSeries {
        sectors: n as u32,
        per_robot,
        team,
    }
}

/// A robot's distance to its target path over the run.
#[derive(Debug, Clone, PartialEq)]
pub struct PathDistance {
    pub name: String,
    pub robot: u32,
    /// (t_s, distance_m) at every recorded step.
    pub points: Vec<(f64, f64)>,
    /// The metric's window (s).
    pub from_s: f64,
    pub to_s: f64,
    /// The run's metric `mean_path_error_m.<name>`.
    pub mean_m: Option<f64>,
}

pub fn path_distances(scenario: &Scenario, rec: &Recording) -> Vec<PathDistance> {
    scenario
        .metrics
        .paths
        .iter()
        .map(|m| PathDistance {
            name: m.name.clone(),
            robot: m.robot,
            points: rec
                .robots
                .get(&m.robot)
                .map(|rows| {
                    rows.iter()
                        .map(|r| {
                            let p = [r.true_pose[0], r.true_pose[1]];
                            (r.t_s, distance_to_polyline_m(p, &m.points))
                        })
                        .collect()
                })
                .unwrap_or_default(),
            from_s: m.from_s,
            to_s: m.from_s + m.over_s,
            mean_m: mean_path_error_m(m, rec),
        })
        .collect()
}

/// The leader's deposits along its path.
#[derive(Debug, Clone)]
pub struct LeaderDeposits {
    pub leader: u32,
    /// (distance travelled along its true path (m), deposit peak, t_s), one per deposit.
    pub deposits: Vec<(f64, f32, f64)>,
    /// The run's `blind_leader` metric (where the leader got lost, where the follower gave up).
    pub metric: BlindLeader,
    /// The follower's trail threshold (`gradient.abandon_below`, seed 000's 10) when it follows
    /// by gradient: the level below which it rejects a trail.
    pub threshold: Option<f64>,
    /// The leader's first deposit below `threshold`, found as `metrics.wrong_area`'s
    /// `deposit_below_threshold` is (the same function on the same rows).
    pub below_threshold: Option<ThresholdCrossing>,
    /// Seed 000 Fig. 23's stated deposits ([`PAPER_FIG23`]) placed at this run's checkpoints of
    /// the same label: (distance along the path (m), value); empty without a `wrong_area` metric.
    pub paper: Vec<(f64, f64)>,
}

/// The deposits seed 000 states for Fig. 23 (by checkpoint, L1 = 1): 11.35 at L11, 8.15 at L12.
pub const PAPER_FIG23: [(usize, f64); 2] = [(11, 11.35), (12, 8.15)];

impl LeaderDeposits {
    /// The first deposit whose peak fell below the follower's threshold: (distance along the
    /// leader's path (m), t_s).
    pub fn below_threshold_at(&self) -> Option<(f64, f64)> {
        self.below_threshold.as_ref().map(|c| (c.along_m, c.t_s))
    }
}

pub fn leader_deposits(
    scenario: &Scenario,
    m: &BlindLeaderMetric,
    rec: &Recording,
) -> LeaderDeposits {
    let mut deposits = Vec::new();
    if let Some(rows) = rec.robots.get(&m.leader) {
        let mut walked = 0.0;
        let mut prev: Option<[f64; 3]> = None;
        for r in rows {
            if let Some(p) = prev {
                walked += (r.true_pose[0] - p[0]).hypot(r.true_pose[1] - p[1]);
            }
            prev = Some(r.true_pose);
            if let Some(peak) = r.deposit_peak {
                deposits.push((walked, peak, r.t_s));
            }
        }
    }
    let threshold = scenario
        .robots
        .iter()
        .find(|r| r.id == m.follower)
        .and_then(|r| r.follower.as_ref())
        .filter(|f| f.strategy == StrategyKind::Gradient)
        .map(|f| f64::from(f.gradient.abandon_below));
    let paper = match (&scenario.metrics.wrong_area, rec.robots.get(&m.leader)) {
        (Some(_), Some(rows)) => {
            let cps = checkpoints(rows);
            let at = |l: usize| cps.get(l - 1).map(|c| c.along_m);
            PAPER_FIG23
                .iter()
                .filter_map(|&(l, v)| at(l).map(|a| (a, v)))
                .collect()
        }
        _ => Vec::new(),
    };
    let below_threshold = threshold
        .zip(rec.robots.get(&m.leader))
        .and_then(|(t, rows)| deposit_below_threshold(rows, t));
    LeaderDeposits {
        leader: m.leader,
        deposits,
        metric: blind_leader(scenario, m, rec),
        threshold,
        below_threshold,
        paper,
    }
}
