//! Robots on the node graph: [`GraphAgent`] with the paper's anti-pheromone strategy
//! ([`Strategy::Pheromone`]: eq. 8 link choice towards regions with room, eq. 9 targets, region
//! capture) or the baseline ([`Strategy::ShortestPath`]: A* to the nearest region the robot
//! does not know to be taken, no signalling, conflicts resolved on arrival), and [`simulate`], a
//! single-process lockstep run of the paper's corridor (Sec. 6, regions A–E and a dock) that
//! reports the time until every region has been served.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::conflict::{ContendMsg, RgbRes};
use super::{
    CaptureOutcome, Dir, Graph, GraphConfig, GraphError, GraphState, GraphUpdate, RegionConfig,
    RegionTable,
};

/// How a robot moves on the graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Strategy {
    /// Seed 001: anti-pheromone on links, region capture, eq. 8 + eq. 9.
    Pheromone,
    /// Baseline: A* to the nearest region, no signalling, conflicts resolved on arrival.
    ShortestPath,
}

impl Strategy {
    pub fn name(self) -> &'static str {
        match self {
            Strategy::Pheromone => "pheromone",
            Strategy::ShortestPath => "shortest-path",
        }
    }
}

/// What a robot tells contenders (Listing 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotProfile {
    pub id: u32,
    pub task_id: u32,
    pub task_priority: u32,
    pub lrf_range_m: f32,
    pub rgb_res: RgbRes,
}

/// The next thing a robot does at a node.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Take link `dir`, sending `updates` (the deposit on the link) to the graph's writer.
    Move { dir: Dir, updates: Vec<GraphUpdate> },
    /// Try to capture the region at this node (contending with any other robot trying now).
    Capture { region: usize },
    /// Nothing left that this robot can do.
    Idle,
}

/// One robot's decisions on the graph; deterministic for a seed.
#[derive(Debug, Clone)]
pub struct GraphAgent {
    pub profile: RobotProfile,
    pub strategy: Strategy,
    /// Added to a link when taking it: −1 (anti-pheromone, Sec. 4.1) or positive to make
    /// others follow (Sec. 4.3, surveillance backup).
    pub link_deposit: f32,
    /// Patrol: serve regions again once all have been served (otherwise only regions with
    /// value ≥ 0, never served, are targets).
    pub patrol: bool,
    pub capture_count: u32,
    pub battery_pct: f32,
    rng: ChaCha8Rng,
    /// Regions this robot knows to be taken or served (the baseline's only knowledge).
    known_done: Vec<bool>,
}

impl GraphAgent {
    pub fn new(profile: RobotProfile, strategy: Strategy, seed: u64) -> Self {
        Self {
            profile,
            strategy,
            link_deposit: -1.0,
            patrol: false,
            capture_count: 0,
            battery_pct: 100.0,
            rng: ChaCha8Rng::seed_from_u64(seed ^ (profile.id as u64).wrapping_mul(0x9E37_79B9)),
            known_done: Vec::new(),
        }
    }

    /// The contention message this robot sends for `region` at `time_stamp_s`.
    pub fn contend_msg(&self, region: usize, time_stamp_s: u64) -> ContendMsg {
        ContendMsg {
            robot_id: self.profile.id,
            time_stamp_s,
            battery_pct: self.battery_pct.clamp(0.0, 100.0) as u8,
            capture_count: self.capture_count,
            task_id: self.profile.task_id,
            task_priority: self.profile.task_priority,
            lrf_range_m: self.profile.lrf_range_m,
            rgb_res: self.profile.rgb_res,
            region: region as u32,
        }
    }

    /// Remembers that `region` is taken or served (the baseline learns it on arrival).
    pub fn learn_done(&mut self, region: usize) {
        if self.known_done.len() <= region {
            self.known_done.resize(region + 1, false);
        }
        self.known_done[region] = true;
    }

    fn knows_done(&self, region: usize) -> bool {
        self.known_done.get(region).copied().unwrap_or(false)
    }

    /// Eq. 9 for this robot: the regions it may head for now.
    fn claimable(&self, s: &GraphState) -> Vec<usize> {
        let regions = s.regions.regions();
        let admitted: Vec<usize> = (0..regions.len())
            .filter(|&i| {
                let r = &regions[i];
                r.has_room()
                    && (self.patrol || r.value >= 0.0)
                    && !r.captured_by.contains(&self.profile.id)
            })
            .collect();
        let Some(best) = admitted
            .iter()
            .map(|&i| regions[i].value)
            .max_by(f32::total_cmp)
        else {
            return Vec::new();
        };
        admitted
            .into_iter()
            .filter(|&i| regions[i].value == best)
            .collect()
    }

    /// The next action at `node`, given the latest state.
    pub fn decide(&mut self, s: &GraphState, node: usize) -> Result<Action, GraphError> {
        match self.strategy {
            Strategy::Pheromone => self.decide_pheromone(s, node),
            Strategy::ShortestPath => self.decide_shortest(s, node),
        }
    }

    fn decide_pheromone(&mut self, s: &GraphState, node: usize) -> Result<Action, GraphError> {
        let targets = self.claimable(s);
        if let Some(&r) = targets
            .iter()
            .find(|&&r| s.regions.regions()[r].node == node)
        {
            return Ok(Action::Capture { region: r });
        }
        // A link is worth taking if a target lies beyond it without coming back through here;
        // among those, eq. 8 (largest value), then the shortest way to a target, then a
        // seeded coin.
        let g = &s.graph;
        let cost = |_: Dir, l: &super::Link| -> Option<f32> {
            let d = g.distances_from(l.to, Some(node));
            let best = targets
                .iter()
                .map(|&r| d[s.regions.regions()[r].node])
                .fold(f32::INFINITY, f32::min);
            best.is_finite().then_some(l.length_m + best)
        };
        match g.choose_link_among(node, cost, &mut self.rng)? {
            Some(dir) => Ok(Action::Move {
                dir,
                updates: vec![GraphUpdate::AddToLink {
                    node,
                    dir,
                    amount: self.link_deposit,
                }],
            }),
            None => Ok(Action::Idle),
        }
    }

    fn decide_shortest(&mut self, s: &GraphState, node: usize) -> Result<Action, GraphError> {
        let g = &s.graph;
        let d = g.distances_from(node, None);
        let target = (0..s.regions.len())
            .filter(|&r| !self.knows_done(r))
            .filter(|&r| d[s.regions.regions()[r].node].is_finite())
            .min_by(|&a, &b| {
                let da = d[s.regions.regions()[a].node];
                let db = d[s.regions.regions()[b].node];
                da.total_cmp(&db).then(a.cmp(&b))
            });
        let Some(r) = target else {
            return Ok(Action::Idle);
        };
        let goal = s.regions.regions()[r].node;
        if goal == node {
            return Ok(Action::Capture { region: r });
        }
        let (path, _) = g.astar(node, goal).expect("reachable: distance is finite");
        let (dir, _) = g
            .edge_dirs(node, path[1])
            .expect("consecutive path nodes are linked");
        Ok(Action::Move {
            dir,
            updates: Vec::new(),
        })
    }
}

/// Timing of a corridor run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimParams {
    pub speed_m_per_s: f32,
    /// Work time per m² of region (the paper's Tw for a region is area × this).
    pub work_s_per_m2: f32,
    /// Time robots spend resolving a conflict by local communication.
    pub conflict_s: f32,
    /// Robots leave the dock one after another, this far apart.
    pub start_interval_s: f32,
    pub dt_s: f32,
    /// A run that has not served every region by then is reported unfinished.
    pub max_time_s: f32,
    /// Battery used per metre driven (%).
    pub battery_pct_per_m: f32,
}

impl Default for SimParams {
    fn default() -> Self {
        Self {
            speed_m_per_s: 0.5,
            work_s_per_m2: 3.0,
            conflict_s: 10.0,
            start_interval_s: 2.0,
            dt_s: 0.05,
            max_time_s: 3600.0,
            battery_pct_per_m: 0.1,
        }
    }
}

/// The `regions` scenario: a graph, its regions, the dock and the timing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionsScenario {
    pub name: String,
    #[serde(default)]
    pub seed: u64,
    pub graph: GraphConfig,
    #[serde(rename = "region")]
    pub regions: Vec<RegionConfig>,
    /// The node the robots start from.
    pub dock: String,
    #[serde(default)]
    pub regions_sim: SimParams,
}

/// Seed 001 Fig. 4: a 25 m corridor, regions B, C, A, D, E in increasing distance from the dock
/// (A twice the area of the others), two dead-end side passages.
pub const PAPER_CORRIDOR: &str = include_str!("../../../examples/scenarios/regions.toml");

impl RegionsScenario {
    pub fn paper_corridor() -> Self {
        toml::from_str(PAPER_CORRIDOR).expect("the built-in corridor parses")
    }

    /// The graph state the scenario starts from.
    pub fn state(&self) -> Result<GraphState, GraphError> {
        let graph = Graph::explicit(&self.graph)?;
        let regions = RegionTable::new(&self.regions, |n| graph.find(n).ok())?;
        Ok(GraphState { graph, regions })
    }
}

/// One service of a region.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Service {
    pub region: String,
    pub robot: u32,
    pub start_s: f32,
    pub end_s: f32,
}

/// What a corridor run did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimReport {
    pub strategy: Strategy,
    pub robots: usize,
    /// Time until every region had been served once (`None`: not within `max_time_s`).
    pub finish_s: Option<f32>,
    pub services: Vec<Service>,
    /// Contention exchanges (two or more robots, or a robot meeting a holder).
    pub conflicts: u32,
    pub distance_m: Vec<f32>,
    /// Most robots any region held at once (never above its Max-R).
    pub max_holders: Vec<u32>,
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
        to: usize,
        left_m: f32,
    },
    Serving {
        node: usize,
        region: usize,
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

/// Runs `robots` robots with `strategy` on `scenario` until every region has been served.
pub fn simulate(
    scenario: &RegionsScenario,
    strategy: Strategy,
    robots: usize,
    seed: u64,
) -> Result<SimReport, GraphError> {
    let p = scenario.regions_sim;
    let mut state = scenario.state()?;
    let dock = state.graph.find(&scenario.dock)?;
    let n_regions = state.regions.len();
    let mut agents: Vec<GraphAgent> = (0..robots)
        .map(|i| {
            GraphAgent::new(
                RobotProfile {
                    id: i as u32 + 1,
                    task_id: 1,
                    task_priority: 1,
                    lrf_range_m: 4.0,
                    rgb_res: RgbRes::Vga,
                },
                strategy,
                seed,
            )
        })
        .collect();
    let mut phases: Vec<Phase> = (0..robots)
        .map(|i| Phase::Waiting {
            until_s: i as f32 * p.start_interval_s,
        })
        .collect();
    let mut report = SimReport {
        strategy,
        robots,
        finish_s: None,
        services: Vec::new(),
        conflicts: 0,
        distance_m: vec![0.0; robots],
        max_holders: vec![0; n_regions],
    };
    let mut served = vec![false; n_regions];
    let mut t = 0.0f32;
    let mut step: u64 = 0;
    while t <= p.max_time_s {
        // Advance movement, work and waiting.
        for i in 0..robots {
            phases[i] = match phases[i] {
                Phase::Waiting { until_s } if until_s <= t => Phase::AtNode { node: dock },
                Phase::Moving { to, left_m } => {
                    let d = p.speed_m_per_s * p.dt_s;
                    report.distance_m[i] += d.min(left_m);
                    agents[i].battery_pct -= d.min(left_m) * p.battery_pct_per_m;
                    if left_m <= d {
                        Phase::AtNode { node: to }
                    } else {
                        Phase::Moving {
                            to,
                            left_m: left_m - d,
                        }
                    }
                }
                Phase::Serving {
                    node,
                    region,
                    until_s,
                } if until_s <= t => {
                    state.apply(GraphUpdate::Release {
                        region,
                        robot: agents[i].profile.id,
                    })?;
                    agents[i].capture_count += 1;
                    agents[i].learn_done(region);
                    if !served[region] {
                        served[region] = true;
                        report.services.push(Service {
                            region: state.regions.regions()[region].name.clone(),
                            robot: agents[i].profile.id,
                            start_s: until_s - work_s(&state, region, &p),
                            end_s: until_s,
                        });
                    }
                    Phase::AtNode { node }
                }
                Phase::Resolving { node, until_s } if until_s <= t => Phase::AtNode { node },
                other => other,
            };
        }
        if served.iter().all(|&s| s) {
            report.finish_s = Some(t);
            return Ok(report);
        }
        // Decisions, in robot order (the one writer applies updates in arrival order).
        let mut claims: Vec<Vec<usize>> = vec![Vec::new(); n_regions];
        for i in 0..robots {
            let Phase::AtNode { node } = phases[i] else {
                continue;
            };
            match agents[i].decide(&state, node)? {
                Action::Move { dir, updates } => {
                    for u in updates {
                        state.apply(u)?;
                    }
                    let l = *state.graph.link(node, dir)?;
                    phases[i] = Phase::Moving {
                        to: l.to,
                        left_m: l.length_m,
                    };
                }
                Action::Capture { region } => claims[region].push(i),
                Action::Idle => phases[i] = Phase::Idle { node },
            }
        }
        // Captures, with conflict resolution.
        for (region, claimants) in claims.iter().enumerate() {
            if claimants.is_empty() {
                continue;
            }
            let r = state.regions.get(region)?.clone();
            let room = (r.max_r as usize).saturating_sub(r.captured_by.len());
            let node = r.node;
            let already_served = r.value < 0.0 && !agents[claimants[0]].patrol;
            if already_served && r.captured_by.is_empty() {
                // Seen on arrival: it has been served; nothing to negotiate.
                for &i in claimants {
                    agents[i].learn_done(region);
                    phases[i] = Phase::AtNode { node };
                }
                continue;
            }
            let conflict = claimants.len() > room || !r.captured_by.is_empty();
            let msgs: Vec<ContendMsg> = claimants
                .iter()
                .map(|&i| agents[i].contend_msg(region, step))
                .collect();
            let winners = if already_served {
                Vec::new()
            } else {
                ContendMsg::winners(&msgs, room)
            };
            if conflict {
                report.conflicts += 1;
            }
            let delay = if conflict { p.conflict_s } else { 0.0 };
            for &i in claimants {
                let id = agents[i].profile.id;
                if winners.contains(&id) {
                    let out = state.apply(GraphUpdate::Capture { region, robot: id })?;
                    debug_assert_eq!(out, Some(CaptureOutcome::Captured));
                    phases[i] = Phase::Serving {
                        node,
                        region,
                        until_s: t + delay + work_s(&state, region, &p),
                    };
                } else {
                    agents[i].learn_done(region);
                    phases[i] = Phase::Resolving {
                        node,
                        until_s: t + delay,
                    };
                }
            }
            let holders = state.regions.get(region)?.captured_by.len() as u32;
            report.max_holders[region] = report.max_holders[region].max(holders);
        }
        step += 1;
        t = step as f32 * p.dt_s;
    }
    Ok(report)
}

fn work_s(s: &GraphState, region: usize, p: &SimParams) -> f32 {
    s.regions.regions()[region].shape.area_m2() * p.work_s_per_m2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corridor_distances_follow_the_paper_order() {
        let sc = RegionsScenario::paper_corridor();
        let s = sc.state().unwrap();
        let dock = s.graph.find("dock").unwrap();
        let d = s.graph.distances_from(dock, None);
        let mut names: Vec<(f32, &str)> = s
            .regions
            .regions()
            .iter()
            .map(|r| (d[r.node], r.name.as_str()))
            .collect();
        names.sort_by(|a, b| a.0.total_cmp(&b.0));
        let order: Vec<&str> = names.iter().map(|x| x.1).collect();
        assert_eq!(order, ["B", "C", "A", "D", "E"]);
    }

    #[test]
    fn two_robots_split_like_table_2() {
        let sc = RegionsScenario::paper_corridor();
        let r = simulate(&sc, Strategy::Pheromone, 2, 1).unwrap();
        let who = |name: &str| r.services.iter().find(|s| s.region == name).unwrap().robot;
        // Table 2, two robots: R1 serves B then A; R2 serves C, D, E.
        assert_eq!(
            [who("A"), who("B"), who("C"), who("D"), who("E")],
            [1, 1, 2, 2, 2],
            "{:?}",
            r.services
        );
        assert!(r.finish_s.is_some());
        assert!(r.max_holders.iter().all(|&h| h <= 1));
    }

    #[test]
    fn four_robots_first_round_like_table_2() {
        let sc = RegionsScenario::paper_corridor();
        let r = simulate(&sc, Strategy::Pheromone, 4, 1).unwrap();
        let who = |name: &str| r.services.iter().find(|s| s.region == name).unwrap().robot;
        // Table 2, four robots, Tw1: A R3, B R1, C R2, D R4.
        assert_eq!([who("A"), who("B"), who("C"), who("D")], [3, 1, 2, 4]);
    }

    /// Fig. 4c in simulated time: region capture finishes before shortest path with conflict
    /// resolution, which spends time in conflicts the capture avoids.
    #[test]
    fn capture_beats_shortest_path_in_simulated_time() {
        let sc = RegionsScenario::paper_corridor();
        for n in 2..=4 {
            let ph = simulate(&sc, Strategy::Pheromone, n, 1).unwrap();
            let sp = simulate(&sc, Strategy::ShortestPath, n, 1).unwrap();
            assert!(
                ph.finish_s.unwrap() < sp.finish_s.unwrap(),
                "{n}: {ph:?} {sp:?}"
            );
            assert!(ph.conflicts < sp.conflicts, "{n}: {ph:?} {sp:?}");
        }
    }

    #[test]
    fn every_run_finishes_within_max_r() {
        let sc = RegionsScenario::paper_corridor();
        for strategy in [Strategy::Pheromone, Strategy::ShortestPath] {
            for n in 1..=4 {
                let r = simulate(&sc, strategy, n, 1).unwrap();
                assert!(r.finish_s.is_some(), "{strategy:?} {n}: {r:?}");
                assert_eq!(r.services.len(), 5);
                assert!(r.max_holders.iter().all(|&h| h <= 1), "{r:?}");
            }
        }
    }
}
