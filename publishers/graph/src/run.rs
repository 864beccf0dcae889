//! Lockstep runs of a `regions` scenario, the same in one process ([`simulate`]) and as
//! processes ([`super::processes`]):
//! - [`GraphWorld`] is the graph's one writer. Each step it opens a [`StepView`] (the state,
//!   the simulated time and the claims of the previous step), then takes every robot's
//!   [`RobotOutput`] and applies the updates in robot order, records captures and releases,
//!   and collects the new claims.
//! - [`GraphRobot`] is one robot's phase machine: leave the dock, move along links, claim a
//!   region, resolve the claim with the other claimants (the paper's contention message and
//!   order, decided by every robot alike), serve, release.
//!
//! A claim made in step k is resolved in step k + 1, once every claimant of step k is known to
//! everyone: the writer publishes them with the next step.

use std::collections::BTreeMap;

use serde::Serialize;

use super::agent::{
    Action, GraphAgent, GraphStrategy, RegionsScenario, RobotProfile, SimParams, Until,
};
use super::conflict::{ContendMsg, RgbRes};
use super::localize::{
    Localization, LocalizationStats, LocalizeConfig, RobotLocalizer, RunLocalization,
};
use super::shm::GraphShmError;
use super::{CaptureOutcome, GraphError, GraphState, GraphUpdate, MAX_LINKS};

/// What a robot sees at the start of a step.
#[derive(Debug, Clone, Copy)]
pub struct StepView<'a> {
    pub step: u64,
    pub time_s: f32,
    pub state: &'a GraphState,
    /// Per region: the robots that claimed it in the previous step.
    pub claims: &'a [Vec<u32>],
}

/// What a robot does in one step.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RobotOutput {
    pub updates: Vec<GraphUpdate>,
    /// The region this robot wants to capture (resolved next step).
    pub claim: Option<usize>,
    /// Its contention message for that claim (sent to every robot).
    pub announce: Option<ContendMsg>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Waiting {
        until_s: f32,
    },
    AtNode {
        node: usize,
    },
    Moving {
        from: usize,
        to: usize,
        left_m: f32,
    },
    Claiming {
        node: usize,
        region: usize,
        step: u64,
    },
    Serving {
        node: usize,
        region: usize,
        since_step: u64,
        until_s: f32,
    },
    Resolving {
        node: usize,
        until_s: f32,
    },
    Idle {
        node: usize,
    },
}

/// One robot of a lockstep run.
#[derive(Debug, Clone)]
pub struct GraphRobot {
    pub agent: GraphAgent,
    params: SimParams,
    dock: usize,
    phase: Phase,
    pub distance_m: f32,
    /// Claims this robot resolved that involved a conflict (more claimants than room; a full
    /// region has none).
    pub conflicts: u32,
    /// Captures the writer refused (the region was full after all).
    pub refused: u32,
    /// Captures this robot won and the writer did not refuse, held or released (the agent's
    /// `capture_count`, which the contention messages carry, counts released ones only).
    pub captured: u32,
    /// Nodes reached, in order (the dock first).
    pub path: Vec<usize>,
    /// Paper 001 Algorithm 1 on landmarks, when the run localizes ([`GraphRobot::localize`]).
    pub localizer: Option<Box<RobotLocalizer>>,
}

/// What a robot reports at the end of a run.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct RobotReport {
    pub robot: u32,
    pub strategy: GraphStrategy,
    pub distance_m: f32,
    /// Regions the writer let this robot capture (held to the end or released).
    pub capture_count: u32,
    pub conflicts: u32,
    pub refused: u32,
    pub battery_pct: f32,
    /// Nodes reached, in order (the dock first).
    pub path: Vec<String>,
    /// What its localizer did, when the run localizes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub localization: Option<LocalizationStats>,
}

impl GraphRobot {
    /// Robot `index` (0-based; id = index + 1) of `scenario`, leaving the dock after
    /// `index × start_interval_s`.
    pub fn new(
        scenario: &RegionsScenario,
        state: &GraphState,
        index: usize,
        strategy: GraphStrategy,
        seed: u64,
    ) -> Result<Self, GraphError> {
        let dock = scenario.dock_node(&state.graph)?;
        let mut agent = GraphAgent::new(
            RobotProfile {
                id: index as u32 + 1,
                task_id: 1,
                task_priority: 1,
                lrf_range_m: 4.0,
                rgb_res: RgbRes::Vga,
            },
            strategy,
            seed,
        );
        scenario.apply_role(&state.graph, &mut agent)?;
        let p = scenario.regions_sim;
        Ok(Self {
            agent,
            params: p,
            dock,
            phase: Phase::Waiting {
                until_s: index as f32 * p.start_interval_s,
            },
            distance_m: 0.0,
            conflicts: 0,
            refused: 0,
            captured: 0,
            path: Vec::new(),
            localizer: None,
        })
    }

    /// Gives this robot a landmark localizer (paper 001 Algorithm 1), starting at the dock.
    pub fn localize(
        &mut self,
        loc: &Localization,
        g: &super::Graph,
        seed: u64,
    ) -> Result<(), GraphError> {
        let (xy, _) = self.truth_xy(g);
        self.localizer = Some(Box::new(RobotLocalizer::new(loc, g, self.id(), seed, xy)?));
        Ok(())
    }

    /// Where the robot truly is (on the straight line between two nodes while it moves), and
    /// its heading while it moves.
    fn truth_xy(&self, g: &super::Graph) -> ([f64; 2], Option<f64>) {
        let at = |n: usize| {
            g.nodes()
                .get(n)
                .map_or([0.0, 0.0], |n| [f64::from(n.x_m), f64::from(n.y_m)])
        };
        match self.phase {
            Phase::Moving { from, to, left_m } => {
                let (a, b) = (at(from), at(to));
                let length_m = g
                    .edge_dirs(from, to)
                    .and_then(|(d, _)| g.link(from, d).ok())
                    .map_or(0.0, |l| l.length_m);
                let f = if length_m > 0.0 {
                    f64::from((left_m / length_m).clamp(0.0, 1.0))
                } else {
                    0.0
                };
                let xy = [b[0] + (a[0] - b[0]) * f, b[1] + (a[1] - b[1]) * f];
                (xy, Some((b[1] - a[1]).atan2(b[0] - a[0])))
            }
            Phase::Waiting { .. } => (at(self.dock), None),
            Phase::AtNode { node }
            | Phase::Claiming { node, .. }
            | Phase::Serving { node, .. }
            | Phase::Resolving { node, .. }
            | Phase::Idle { node } => (at(node), None),
        }
    }

    pub fn id(&self) -> u32 {
        self.agent.profile.id
    }

    pub fn report(&self, g: &super::Graph) -> RobotReport {
        RobotReport {
            robot: self.id(),
            strategy: self.agent.strategy,
            distance_m: self.distance_m,
            capture_count: self.captured,
            conflicts: self.conflicts,
            refused: self.refused,
            battery_pct: self.agent.battery_pct,
            path: self
                .path
                .iter()
                .filter_map(|&n| g.nodes().get(n).map(|n| n.name.clone()))
                .collect(),
            localization: self.localizer.as_ref().map(|l| l.report()),
        }
    }

    /// One step. `contenders(region, step, expected)` returns the contention messages of the
    /// robots that claimed `region` in `step` (this robot's own included).
    pub fn step<F>(&mut self, v: &StepView, mut contenders: F) -> Result<RobotOutput, GraphShmError>
    where
        F: FnMut(usize, u64, usize) -> Result<Vec<ContendMsg>, GraphShmError>,
    {
        let p = self.params;
        let t = v.time_s;
        let id = self.id();
        let mut out = RobotOutput::default();
        self.phase = match self.phase {
            Phase::Waiting { until_s } if until_s <= t => {
                self.path.push(self.dock);
                Phase::AtNode { node: self.dock }
            }
            Phase::Moving { from, to, left_m } => {
                let d = (p.speed_m_per_s * p.dt_s).min(left_m);
                self.distance_m += d;
                self.agent.battery_pct -= d * p.battery_pct_per_m;
                if left_m <= p.speed_m_per_s * p.dt_s {
                    self.agent.came_from = Some(from);
                    self.path.push(to);
                    Phase::AtNode { node: to }
                } else {
                    Phase::Moving {
                        from,
                        to,
                        left_m: left_m - d,
                    }
                }
            }
            Phase::Claiming { node, region, step } => {
                let claimants = v.claims.get(region).map_or(0, |c| c.len());
                let msgs = contenders(region, step, claimants)?;
                self.resolve(v, node, region, &msgs, &mut out)?
            }
            Phase::Serving {
                node,
                region,
                since_step,
                until_s,
            } => {
                let held = v
                    .state
                    .regions
                    .get(region)
                    .map_err(GraphError::from)?
                    .captured_by
                    .contains(&id);
                if v.step > since_step + 1 && !held {
                    // The writer refused the capture: the region filled up after all.
                    self.refused += 1;
                    self.captured -= 1;
                    self.agent.learn_done(region);
                    Phase::AtNode { node }
                } else if until_s <= t {
                    out.updates.push(GraphUpdate::Release { region, robot: id });
                    self.agent.capture_count += 1;
                    self.agent.learn_done(region);
                    Phase::AtNode { node }
                } else {
                    self.phase
                }
            }
            Phase::Resolving { node, until_s } if until_s <= t => Phase::AtNode { node },
            other => other,
        };
        if let Phase::AtNode { node } = self.phase {
            self.phase = match self.agent.decide(v.state, node)? {
                Action::Move { dir, updates } => {
                    out.updates.extend(updates);
                    let l = *v.state.graph.link(node, dir)?;
                    Phase::Moving {
                        from: node,
                        to: l.to,
                        left_m: l.length_m,
                    }
                }
                Action::Capture { region } => {
                    out.claim = Some(region);
                    out.announce = Some(self.agent.contend_msg(region, v.step));
                    Phase::Claiming {
                        node,
                        region,
                        step: v.step,
                    }
                }
                Action::Idle => Phase::Idle { node },
            };
        }
        if self.localizer.is_some() {
            let (xy, heading) = self.truth_xy(&v.state.graph);
            if let Some(loc) = self.localizer.as_mut() {
                // The deposits were chosen with the belief of the step's start (its ρ_t);
                // then the step's motion is localized.
                loc.weigh_deposits(&mut out.updates);
                loc.step(v.state, xy, heading, f64::from(p.dt_s))
                    .map_err(GraphError::from)?;
            }
        }
        Ok(out)
    }

    /// Paper 001 Sec. 5.1: the claimants of a region exchange their messages; every robot sorts
    /// them in the paper's order, and the first `room` win.
    fn resolve(
        &mut self,
        v: &StepView,
        node: usize,
        region: usize,
        msgs: &[ContendMsg],
        out: &mut RobotOutput,
    ) -> Result<Phase, GraphShmError> {
        let p = self.params;
        let id = self.id();
        let r = v.state.regions.get(region).map_err(GraphError::from)?;
        if r.value < 0.0 && r.captured_by.is_empty() && !self.agent.patrol {
            // Served while this robot was on its way: nothing to negotiate.
            self.agent.learn_done(region);
            return Ok(Phase::AtNode { node });
        }
        let room = (r.max_r as usize).saturating_sub(r.captured_by.len());
        let conflict = msgs.len() > room;
        let winners = ContendMsg::winners(msgs, room);
        let delay = if conflict {
            self.conflicts += 1;
            p.conflict_s
        } else {
            0.0
        };
        if winners.contains(&id) {
            out.updates.push(GraphUpdate::Capture { region, robot: id });
            // Counted now (a region held to the end is never released); taken back if the
            // writer refuses it.
            self.captured += 1;
            Ok(Phase::Serving {
                node,
                region,
                since_step: v.step,
                until_s: v.time_s + delay + work_s(v.state, region, &p),
            })
        } else {
            self.agent.learn_done(region);
            Ok(Phase::Resolving {
                node,
                until_s: v.time_s + delay,
            })
        }
    }
}

fn work_s(s: &GraphState, region: usize, p: &SimParams) -> f32 {
    s.regions.regions()[region].shape.area_m2() * p.work_s_per_m2
}

/// One capture of a region (a row of the paper's Table 2).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct Capture {
    pub region: String,
    pub robot: u32,
    pub captured_s: f32,
    /// `None`: still held at the end.
    pub released_s: Option<f32>,
}

/// A node's link values (a row of the paper's Table 3): "NA" where there is no link, "-inf"
/// for a dead end.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct LinkRow {
    pub node: String,
    pub up: String,
    pub down: String,
    pub left: String,
    pub right: String,
}

/// A region at the end (a row of the paper's Table 4).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct AreaRow {
    pub region: String,
    pub max_r: u32,
    /// Robots holding it at the end.
    pub held_by: Vec<u32>,
    /// Every robot that captured it during the run.
    pub captured_by: Vec<u32>,
    pub served: bool,
}

/// What a run did, as the writer saw it.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct RunReport {
    pub scenario: String,
    pub strategy: GraphStrategy,
    pub robots: usize,
    pub seed: u64,
    pub until: Until,
    /// Time until every region was served (or fully captured, `until = captured`; the last
    /// step's time for `until = time`); `None`: not within `max_time_s`.
    pub finish_s: Option<f32>,
    pub steps: u64,
    pub captures: Vec<Capture>,
    /// Claims that met more claimants than the region had room for (a full region: none).
    pub conflicts: u32,
    /// Most robots each region held at once (never above its Max-R).
    pub max_holders: BTreeMap<String, u32>,
    pub links: Vec<LinkRow>,
    pub areas: Vec<AreaRow>,
    pub updates_applied: u64,
    pub updates_rejected: u64,
    pub captures_refused: u64,
    /// Filled in by whoever collects the robots' own reports.
    #[serde(default)]
    pub robot_reports: Vec<RobotReport>,
    /// The robots' localization together, η1 and η2 (runs whose robots localize).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub localization: Option<RunLocalization>,
}

impl RunReport {
    /// The robots' localization together, η1 and η2, from their reports (in robot order):
    /// the same in one process and as processes, where the reports come from the robots.
    pub fn add_localization(&mut self, config: LocalizeConfig) {
        let mut reports: Vec<&RobotReport> = self.robot_reports.iter().collect();
        reports.sort_by_key(|r| r.robot);
        let stats: Vec<&LocalizationStats> = reports
            .iter()
            .filter_map(|r| r.localization.as_ref())
            .collect();
        self.localization = Some(RunLocalization::new(config, &stats));
    }
}

/// The graph's one writer in a lockstep run.
#[derive(Debug, Clone)]
pub struct GraphWorld {
    scenario_name: String,
    params: SimParams,
    strategy: GraphStrategy,
    robots: usize,
    seed: u64,
    pub state: GraphState,
    step: u64,
    claims: Vec<Vec<u32>>,
    captures: Vec<Capture>,
    served: Vec<bool>,
    max_holders: Vec<u32>,
    conflicts: u32,
    finish_s: Option<f32>,
    pub applied: u64,
    pub rejected: u64,
    pub refused: u64,
}

impl GraphWorld {
    pub fn new(
        scenario: &RegionsScenario,
        strategy: GraphStrategy,
        robots: usize,
        seed: u64,
    ) -> Result<Self, GraphError> {
        let state = scenario.state()?;
        let n = state.regions.len();
        Ok(Self {
            scenario_name: scenario.name.clone(),
            params: scenario.regions_sim,
            strategy,
            robots,
            seed,
            state,
            step: 0,
            claims: vec![Vec::new(); n],
            captures: Vec::new(),
            served: vec![false; n],
            max_holders: vec![0; n],
            conflicts: 0,
            finish_s: None,
            applied: 0,
            rejected: 0,
            refused: 0,
        })
    }

    pub fn step(&self) -> u64 {
        self.step
    }

    pub fn time_s(&self) -> f32 {
        self.step as f32 * self.params.dt_s
    }

    pub fn claims(&self) -> &[Vec<u32>] {
        &self.claims
    }

    pub fn view(&self) -> StepView<'_> {
        StepView {
            step: self.step,
            time_s: self.time_s(),
            state: &self.state,
            claims: &self.claims,
        }
    }

    /// The run is over: the goal was reached, or the time is up.
    pub fn finished(&self) -> bool {
        self.finish_s.is_some() || self.time_s() > self.params.max_time_s
    }

    /// Ends the current step with every robot's updates and claim (`(robot id, updates,
    /// claim)`, any order: they are applied in robot order). Malformed updates are counted
    /// and skipped.
    pub fn end_step(&mut self, mut outputs: Vec<(u32, Vec<GraphUpdate>, Option<usize>)>) {
        outputs.sort_by_key(|o| o.0);
        let t = self.time_s();
        let mut claims = vec![Vec::new(); self.state.regions.len()];
        for (robot, updates, claim) in outputs {
            for u in updates {
                match self.state.apply(u) {
                    Ok(Some(CaptureOutcome::Full)) => self.refused += 1,
                    Ok(out) => {
                        self.applied += 1;
                        self.record(u, out, t);
                    }
                    Err(_) => self.rejected += 1,
                }
            }
            match claim {
                Some(r) if r < claims.len() => claims[r].push(robot),
                Some(_) => self.rejected += 1,
                None => {}
            }
        }
        // A claim is a conflict when it meets more claimants than room (a full region has none):
        // the same
        // test every claimant makes on the state it sees next step.
        for (r, c) in claims.iter().enumerate() {
            let region = &self.state.regions.regions()[r];
            let served = region.value < 0.0 && region.captured_by.is_empty();
            let room = (region.max_r as usize).saturating_sub(region.captured_by.len());
            if !c.is_empty() && !served && c.len() > room {
                self.conflicts += 1;
            }
        }
        self.claims = claims;
        if self.finish_s.is_none() && self.goal_reached() {
            self.finish_s = Some(t);
        }
        self.step += 1;
    }

    fn record(&mut self, u: GraphUpdate, out: Option<CaptureOutcome>, t: f32) {
        match (u, out) {
            (GraphUpdate::Capture { region, robot }, Some(CaptureOutcome::Captured)) => {
                let r = &self.state.regions.regions()[region];
                self.max_holders[region] = self.max_holders[region].max(r.captured_by.len() as u32);
                self.captures.push(Capture {
                    region: r.name.clone(),
                    robot,
                    captured_s: t,
                    released_s: None,
                });
            }
            (GraphUpdate::Release { region, robot }, _) => {
                self.served[region] = true;
                let name = &self.state.regions.regions()[region].name;
                if let Some(c) = self
                    .captures
                    .iter_mut()
                    .rev()
                    .find(|c| &c.region == name && c.robot == robot && c.released_s.is_none())
                {
                    c.released_s = Some(t);
                }
            }
            _ => {}
        }
    }

    fn goal_reached(&self) -> bool {
        match self.params.until {
            Until::Served => self.served.iter().all(|&s| s),
            Until::Captured => self
                .state
                .regions
                .regions()
                .iter()
                .all(|r| r.captured_by.len() as u32 >= r.max_r),
            // The goal is the end of max_time_s: reached by the step after which `finished`
            // ends the run on time (the same test, one step ahead), so such a run is not
            // reported "not reached" for running its whole time.
            Until::Time => (self.step + 1) as f32 * self.params.dt_s > self.params.max_time_s,
        }
    }

    pub fn report(&self) -> RunReport {
        let regions = self.state.regions.regions();
        let fmt = |v: Option<f32>| match v {
            None => "NA".to_string(),
            Some(v) if v == f32::NEG_INFINITY => "-inf".to_string(),
            Some(v) => format!("{v}"),
        };
        let links = self
            .state
            .graph
            .nodes()
            .iter()
            .map(|n| {
                let v: [String; MAX_LINKS] = n.links.map(|l| fmt(l.map(|l| l.value)));
                let [up, down, left, right] = v;
                LinkRow {
                    node: n.name.clone(),
                    up,
                    down,
                    left,
                    right,
                }
            })
            .collect();
        let areas = regions
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let mut captured_by: Vec<u32> = Vec::new();
                for c in self.captures.iter().filter(|c| c.region == r.name) {
                    if !captured_by.contains(&c.robot) {
                        captured_by.push(c.robot);
                    }
                }
                AreaRow {
                    region: r.name.clone(),
                    max_r: r.max_r,
                    held_by: r.captured_by.clone(),
                    captured_by,
                    served: self.served[i],
                }
            })
            .collect();
        RunReport {
            scenario: self.scenario_name.clone(),
            strategy: self.strategy,
            robots: self.robots,
            seed: self.seed,
            until: self.params.until,
            finish_s: self.finish_s,
            steps: self.step,
            captures: self.captures.clone(),
            conflicts: self.conflicts,
            max_holders: regions
                .iter()
                .zip(&self.max_holders)
                .map(|(r, &h)| (r.name.clone(), h))
                .collect(),
            links,
            areas,
            updates_applied: self.applied,
            updates_rejected: self.rejected,
            captures_refused: self.refused,
            robot_reports: Vec::new(),
            localization: None,
        }
    }
}

/// Runs `robots` robots with `strategy` on `scenario` in this process, in lockstep, exactly
/// as the processes of [`super::processes`] do.
pub fn simulate(
    scenario: &RegionsScenario,
    strategy: GraphStrategy,
    robots: usize,
    seed: u64,
) -> Result<RunReport, GraphShmError> {
    simulate_with(scenario, strategy, robots, seed, None)
}

/// [`simulate`], with every robot localizing on landmarks when `localization` is given
/// (paper 001 Algorithm 1 coupled to area capture, [`super::localize`]).
pub fn simulate_with(
    scenario: &RegionsScenario,
    strategy: GraphStrategy,
    robots: usize,
    seed: u64,
    localization: Option<&Localization>,
) -> Result<RunReport, GraphShmError> {
    let mut world = GraphWorld::new(scenario, strategy, robots, seed)?;
    let mut fleet: Vec<GraphRobot> = (0..robots)
        .map(|i| GraphRobot::new(scenario, &world.state, i, strategy, seed))
        .collect::<Result<_, _>>()?;
    if let Some(loc) = localization {
        for r in &mut fleet {
            r.localize(loc, &world.state.graph, seed)?;
        }
    }
    // Contention messages announced in a step, read by the claimants in the next.
    let mut announced: Vec<ContendMsg> = Vec::new();
    while !world.finished() {
        let v = world.view();
        let mut outputs = Vec::with_capacity(robots);
        let mut next_announced = Vec::new();
        for r in &mut fleet {
            let out = r.step(&v, |region, step, _| {
                Ok(announced
                    .iter()
                    .filter(|m| m.region as usize == region && m.time_stamp_s == step)
                    .copied()
                    .collect())
            })?;
            next_announced.extend(out.announce);
            outputs.push((r.id(), out.updates, out.claim));
        }
        announced = next_announced;
        world.end_step(outputs);
    }
    let mut report = world.report();
    report.robot_reports = fleet.iter().map(|r| r.report(&world.state.graph)).collect();
    if let Some(loc) = localization {
        report.add_localization(loc.config);
    }
    Ok(report)
}

#[cfg(test)]
mod tests;
