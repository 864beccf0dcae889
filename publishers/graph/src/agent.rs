//! Robots on the node graph: [`GraphAgent`] with the paper's anti-pheromone strategy
//! ([`GraphStrategy::Pheromone`]: eq. 8 link choice towards regions with room, eq. 9 targets, region
//! capture, dead ends marked −∞) or the baseline ([`GraphStrategy::ShortestPath`]: A* to the nearest
//! region the robot does not know to be taken, no signalling, conflicts resolved on arrival),
//! and the `regions` scenario format ([`RegionsScenario`]: an explicit graph or a map to
//! skeletonize, regions, a dock, timing). Runs are in [`super::run`].

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::conflict::{ContendMsg, RgbRes};
use super::skeleton::{graph_from_mask, FreeMask, SkeletonOptions};
use super::{
    Dir, Graph, GraphConfig, GraphError, GraphState, GraphUpdate, RegionConfig, RegionTable,
};

/// How a robot moves on the graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GraphStrategy {
    /// Paper 001: anti-pheromone on links, region capture, eq. 8 + eq. 9.
    Pheromone,
    /// Baseline: A* to the nearest region, no signalling, conflicts resolved on arrival.
    ShortestPath,
}

impl GraphStrategy {
    pub const ALL: [GraphStrategy; 2] = [GraphStrategy::Pheromone, GraphStrategy::ShortestPath];

    pub fn name(self) -> &'static str {
        match self {
            GraphStrategy::Pheromone => "pheromone",
            GraphStrategy::ShortestPath => "shortest-path",
        }
    }
}

/// A `--strategy` of a graph run that is not one of [`GraphStrategy::ALL`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("unknown graph strategy '{0}' (expected one of: pheromone, shortest-path)")]
pub struct UnknownGraphStrategy(pub String);

impl std::str::FromStr for GraphStrategy {
    type Err = UnknownGraphStrategy;
    fn from_str(s: &str) -> Result<Self, UnknownGraphStrategy> {
        GraphStrategy::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| UnknownGraphStrategy(s.to_string()))
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
    pub strategy: GraphStrategy,
    /// Added to a link when taking it: −1 (anti-pheromone, Sec. 4.1) or positive to make
    /// others follow (Sec. 4.3, surveillance backup).
    pub link_deposit: f32,
    /// Patrol: serve regions again once all have been served (otherwise only regions with
    /// value ≥ 0, never served, are targets).
    pub patrol: bool,
    pub capture_count: u32,
    pub battery_pct: f32,
    /// Sec. 6.2: a robot told where to go drives there by the shortest path (depositing
    /// `link_deposit` on every link it takes) instead of looking for regions.
    pub goal: Option<usize>,
    /// Sec. 4.3 / 6.2: a robot that follows positive pheromone: at each node it takes the
    /// link with the largest positive value (not the one it came by); none: it stays.
    pub follow: bool,
    /// The node this robot came from (set on arrival).
    pub came_from: Option<usize>,
    rng: ChaCha8Rng,
    /// Regions this robot knows to be taken or served (the baseline's only knowledge).
    known_done: Vec<bool>,
}

impl GraphAgent {
    pub fn new(profile: RobotProfile, strategy: GraphStrategy, seed: u64) -> Self {
        Self {
            profile,
            strategy,
            link_deposit: -1.0,
            patrol: false,
            capture_count: 0,
            battery_pct: 100.0,
            goal: None,
            follow: false,
            came_from: None,
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
                // Never served, or held with room left (a sub-region, Max-R > 1).
                r.has_room()
                    && (self.patrol || r.value >= 0.0 || !r.captured_by.is_empty())
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
        if let Some(goal) = self.goal {
            return self.decide_goal(s, node, goal);
        }
        if self.follow {
            return self.decide_follow(s, node);
        }
        match self.strategy {
            GraphStrategy::Pheromone => self.decide_pheromone(s, node),
            GraphStrategy::ShortestPath => self.decide_shortest(s, node),
        }
    }

    fn decide_goal(
        &mut self,
        s: &GraphState,
        node: usize,
        goal: usize,
    ) -> Result<Action, GraphError> {
        let g = &s.graph;
        if node == goal {
            return Ok(Action::Idle);
        }
        let Some((path, _)) = g.astar(node, goal) else {
            return Ok(Action::Idle);
        };
        let (dir, _) = g
            .edge_dirs(node, path[1])
            .expect("consecutive path nodes are linked");
        Ok(Action::Move {
            dir,
            updates: vec![GraphUpdate::AddToLink {
                node,
                dir,
                amount: self.link_deposit,
            }],
        })
    }

    fn decide_follow(&mut self, s: &GraphState, node: usize) -> Result<Action, GraphError> {
        let back = self.came_from;
        let cost = |_: Dir, l: &super::Link| (l.value > 0.0 && Some(l.to) != back).then_some(0.0);
        Ok(
            match s.graph.choose_link_among(node, cost, &mut self.rng)? {
                Some(dir) => Action::Move {
                    dir,
                    updates: Vec::new(),
                },
                None => Action::Idle,
            },
        )
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
        // A link into a terminal node that serves no region is a dead end: mark it −∞ for
        // everyone (the robot's range sensor sees the end of the passage).
        let mut updates: Vec<GraphUpdate> = g
            .node(node)?
            .links()
            .filter(|(_, l)| {
                l.value != super::DEAD_END
                    && g.nodes()[l.to].terminal
                    && s.regions.at_node(l.to).next().is_none()
            })
            .map(|(dir, _)| GraphUpdate::DeadEnd { node, dir })
            .collect();
        match g.choose_link_among(node, cost, &mut self.rng)? {
            Some(dir) => {
                updates.push(GraphUpdate::AddToLink {
                    node,
                    dir,
                    amount: self.link_deposit,
                });
                Ok(Action::Move { dir, updates })
            }
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
    /// When the run is over: every region served once, or every region holding Max-R robots.
    pub until: Until,
}

/// The goal of a `regions` run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Until {
    /// Every region has been captured, served for its work time and released (Fig. 4c).
    Served,
    /// Every region holds Max-R robots (Fig. 7d, Table 4).
    Captured,
    /// Run until `max_time_s` (the pheromone experiment of Sec. 6.2 has no regions to serve).
    Time,
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
            until: Until::Served,
        }
    }
}

/// A node of the graph by name, or the node nearest a point (for graphs extracted from a map,
/// whose node names are generated).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum NodeRef {
    Name(String),
    At([f32; 2]),
}

impl NodeRef {
    pub fn resolve(&self, g: &Graph) -> Result<usize, GraphError> {
        match self {
            NodeRef::Name(n) => g.find(n),
            NodeRef::At([x, y]) => g.nearest_node(*x, *y).ok_or_else(|| {
                GraphError::UnknownNode(format!("nearest to ({x}, {y}): the graph is empty"))
            }),
        }
    }
}

/// `[map]` of a `regions` scenario: an occupancy map as text rows, skeletonized into the graph
/// (paper 001 Fig. 7). The first row is the top (largest y); `#` is a wall, anything else free.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapConfig {
    pub cell_size_m: f32,
    #[serde(default)]
    pub origin_m: [f32; 2],
    pub rows: Vec<String>,
    /// Spurs of the skeleton up to this long are pruned.
    #[serde(default = "default_min_branch_m")]
    pub min_branch_m: f32,
}

fn default_min_branch_m() -> f32 {
    SkeletonOptions::default().min_branch_m
}

impl MapConfig {
    pub fn mask(&self) -> Result<FreeMask, GraphError> {
        let bad = |detail: String| GraphError::Node {
            node: "[map]".into(),
            detail,
        };
        let height = self.rows.len();
        let width = self.rows.first().map_or(0, |r| r.chars().count());
        if height == 0 || width == 0 {
            return Err(bad("rows: the map is empty".into()));
        }
        if let Some((i, r)) = self
            .rows
            .iter()
            .enumerate()
            .find(|(_, r)| r.chars().count() != width)
        {
            return Err(bad(format!(
                "rows[{i}] has {} characters, rows[0] has {width}",
                r.chars().count()
            )));
        }
        let mut free = vec![false; width * height];
        for (i, row) in self.rows.iter().enumerate() {
            let y = height - 1 - i;
            for (x, c) in row.chars().enumerate() {
                free[y * width + x] = c != '#';
            }
        }
        Ok(FreeMask {
            width,
            height,
            cell_size_m: self.cell_size_m,
            origin_m: self.origin_m,
            free,
        })
    }
}

/// The `regions` scenario: a graph (explicit or from a map), its regions, the dock and the
/// timing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionsScenario {
    pub name: String,
    #[serde(default)]
    pub seed: u64,
    /// Robots of a run unless the command line says otherwise.
    #[serde(default = "default_robots")]
    pub robots: Vec<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph: Option<GraphConfig>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map: Option<MapConfig>,
    #[serde(default, rename = "region")]
    pub regions: Vec<RegionConfig>,
    /// The node the robots start from: a name, or `[x, y]` for the nearest node.
    pub dock: NodeRef,
    /// Strategies `pheromone sim` compares unless the command line says otherwise.
    #[serde(default = "all_strategies")]
    pub strategies: Vec<GraphStrategy>,
    /// Robots given a role of their own (Sec. 6.2: one told where to go, one following).
    #[serde(default, rename = "robot", skip_serializing_if = "Vec::is_empty")]
    pub robot_roles: Vec<RobotRole>,
    #[serde(default)]
    pub regions_sim: SimParams,
    /// `[localize]`: the landmarks, sensors and noise of the graph world when its robots
    /// localize (`pheromone sim --localize`; its `deposit` key is set by that flag).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub localize: Option<super::localize::LocalizeConfig>,
}

fn all_strategies() -> Vec<GraphStrategy> {
    GraphStrategy::ALL.to_vec()
}

/// `[[robot]]` of a `regions` scenario: a robot with a role of its own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotRole {
    /// Robot id (1-based).
    pub id: u32,
    /// Drive to this node by the shortest path instead of looking for regions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal: Option<NodeRef>,
    /// Added to every link the robot takes (default −1: anti-pheromone; positive to make
    /// others follow).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_deposit: Option<f32>,
    /// Follow positive pheromone on the links instead of looking for regions.
    #[serde(default)]
    pub follow: bool,
}

fn default_robots() -> Vec<usize> {
    vec![2, 3, 4]
}

/// Paper 001 Fig. 4: a 25 m corridor, regions B, C, A, D, E in increasing distance from the dock
/// (A twice the area of the others), two dead-end side passages.
pub const PAPER_CORRIDOR: &str = include_str!("../../../examples/scenarios/regions.toml");

/// Paper 001 Fig. 7: a map skeletonized into the graph, 8 robots, 7 regions, C with Max-R 2.
pub const PAPER_SKELETON: &str = include_str!("../../../examples/scenarios/regions-skeleton.toml");

/// Paper 001 Sec. 6.2: R1 is sent to region E depositing pheromone; R2 follows it.
pub const PAPER_BACKUP: &str = include_str!("../../../examples/scenarios/regions-backup.toml");

/// Paper 001's corridor with few landmarks (one pair per 4 m, seen within 2 m): ρ_t varies,
/// the captures do not (the corridor is a tree).
pub const REGIONS_SPARSE: &str = include_str!("../../../examples/scenarios/regions-sparse.toml");

/// A loop (two routes to every target) whose left half is unlit: the robots' localization
/// degrades there, and `--localize rho` changes routes, captures and times.
pub const REGIONS_LOOP: &str = include_str!("../../../examples/scenarios/regions-loop.toml");

/// Built-in `regions` scenarios by name.
pub const BUILTIN_REGIONS: [(&str, &str); 5] = [
    ("regions", PAPER_CORRIDOR),
    ("regions-skeleton", PAPER_SKELETON),
    ("regions-backup", PAPER_BACKUP),
    ("regions-sparse", REGIONS_SPARSE),
    ("regions-loop", REGIONS_LOOP),
];

impl RegionsScenario {
    pub fn paper_corridor() -> Self {
        toml::from_str(PAPER_CORRIDOR).expect("the built-in corridor parses")
    }

    pub fn paper_skeleton() -> Self {
        toml::from_str(PAPER_SKELETON).expect("the built-in skeleton map parses")
    }

    /// A built-in scenario by name.
    pub fn builtin(name: &str) -> Option<Self> {
        BUILTIN_REGIONS
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, text)| toml::from_str(text).expect("built-in regions scenarios parse"))
    }

    /// Whether a TOML text is a `regions` scenario (it has a `dock`).
    pub fn looks_like(text: &str) -> bool {
        toml::from_str::<toml::Table>(text).is_ok_and(|t| t.contains_key("dock"))
    }

    /// The graph: explicit, or skeletonized from the map.
    pub fn graph(&self) -> Result<Graph, GraphError> {
        match (&self.graph, &self.map) {
            (Some(g), None) => Graph::explicit(g),
            (None, Some(m)) => graph_from_mask(
                &m.mask()?,
                SkeletonOptions {
                    min_branch_m: m.min_branch_m,
                },
            )
            .map_err(|e| GraphError::Node {
                node: "[map]".into(),
                detail: e.to_string(),
            }),
            _ => Err(GraphError::Node {
                node: self.name.clone(),
                detail: "a regions scenario needs exactly one of [graph] and [map]".into(),
            }),
        }
    }

    /// The graph state the scenario starts from.
    pub fn state(&self) -> Result<GraphState, GraphError> {
        let graph = self.graph()?;
        let mut configs = self.regions.clone();
        for c in &mut configs {
            if let Some(at) = c.at_m.take() {
                let n = NodeRef::At(at).resolve(&graph)?;
                c.node = graph.nodes()[n].name.clone();
            }
        }
        let regions = RegionTable::new(&configs, |n| graph.find(n).ok())?;
        Ok(GraphState { graph, regions })
    }

    /// The settings of a run whose robots localize with deposits weighted by `deposit`: the
    /// scenario's `[localize]` table (or the defaults) with its `deposit` key set by the flag.
    /// Every process of a run builds it alike from the same scenario.
    pub fn localize_config(
        &self,
        deposit: super::localize::DepositWeight,
    ) -> super::localize::LocalizeConfig {
        super::localize::LocalizeConfig {
            deposit,
            ..self.localize.unwrap_or_default()
        }
    }

    pub fn dock_node(&self, g: &Graph) -> Result<usize, GraphError> {
        self.dock.resolve(g)
    }

    /// Applies the scenario's `[[robot]]` role for this agent's id, if any.
    pub fn apply_role(&self, g: &Graph, agent: &mut GraphAgent) -> Result<(), GraphError> {
        let Some(role) = self.robot_roles.iter().find(|r| r.id == agent.profile.id) else {
            return Ok(());
        };
        if let Some(goal) = &role.goal {
            agent.goal = Some(goal.resolve(g)?);
        }
        if let Some(d) = role.link_deposit {
            if !d.is_finite() {
                return Err(GraphError::Amount(d));
            }
            agent.link_deposit = d;
        }
        agent.follow = role.follow;
        Ok(())
    }

    /// Checks what [`RegionsScenario::state`] does not: the dock and the robot roles.
    pub fn validate(&self) -> Result<GraphState, GraphError> {
        let state = self.state()?;
        self.dock_node(&state.graph)?;
        for r in &self.robot_roles {
            let mut probe = GraphAgent::new(
                RobotProfile {
                    id: r.id,
                    task_id: 1,
                    task_priority: 1,
                    lrf_range_m: 4.0,
                    rgb_res: RgbRes::Vga,
                },
                GraphStrategy::Pheromone,
                0,
            );
            self.apply_role(&state.graph, &mut probe)?;
        }
        if let Some(l) = &self.localize {
            l.validate()?;
        }
        if self.strategies.is_empty() || self.robots.is_empty() {
            return Err(GraphError::Node {
                node: self.name.clone(),
                detail: "`strategies` and `robots` must not be empty".into(),
            });
        }
        Ok(state)
    }
}
