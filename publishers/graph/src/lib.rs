//! Node-graph signalling (paper 001, MODELS.md M2): the passages of the map as a graph of nodes
//! with up to [`MAX_LINKS`] diverging links (up, down, left, right), each carrying an `f32`
//! pheromone value (positive attracts, negative repels, −∞ marks a dead end), plus a table of
//! service regions that robots capture, serve and release.
//!
//! Everything here is pure (no shared memory): the graph, eq. 8 link choice with seeded ties,
//! A* / Dijkstra on the graph, the update rules ([`GraphState::apply`]). [`region`] holds the
//! region table with its Max-R rule, [`conflict`] the paper's contention message and order,
//! [`skeleton`] graph extraction from an occupancy grid, [`shm`] the one-writer iceoryx2 service
//! and [`agent`] the robot agents and a single-process simulation of the paper's corridor.

pub mod agent;
pub mod compare;
pub mod conflict;
pub mod localize;
pub mod processes;
pub mod region;
pub mod run;
pub mod shm;
pub mod skeleton;
pub mod tables;

use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

use rand::Rng;
use serde::{Deserialize, Serialize};

pub use conflict::{ContendMsg, RgbRes};
pub use region::{CaptureOutcome, Region, RegionConfig, RegionError, RegionShape, RegionTable};

/// Diverging links a node can have (the paper's simulator: up, down, left, right).
pub const MAX_LINKS: usize = 4;

/// The value of a link into a dead end once a robot has found it.
pub const DEAD_END: f32 = f32::NEG_INFINITY;

/// Direction of a link leaving a node (world axes: `Up` = +y, `Right` = +x).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Dir {
    Up = 0,
    Down = 1,
    Left = 2,
    Right = 3,
}

impl Dir {
    pub const ALL: [Dir; MAX_LINKS] = [Dir::Up, Dir::Down, Dir::Left, Dir::Right];

    pub fn index(self) -> usize {
        self as usize
    }

    pub fn from_index(i: usize) -> Option<Dir> {
        Dir::ALL.get(i).copied()
    }

    pub fn name(self) -> &'static str {
        match self {
            Dir::Up => "up",
            Dir::Down => "down",
            Dir::Left => "left",
            Dir::Right => "right",
        }
    }

    fn angle_rad(self) -> f32 {
        use std::f32::consts::{FRAC_PI_2, PI};
        match self {
            Dir::Right => 0.0,
            Dir::Up => FRAC_PI_2,
            Dir::Left => PI,
            Dir::Down => -FRAC_PI_2,
        }
    }

    /// The directions ordered by how close they are to the vector `(dx, dy)` (closest first).
    pub fn by_closeness(dx: f32, dy: f32) -> [Dir; MAX_LINKS] {
        let a = dy.atan2(dx);
        let mut dirs = Dir::ALL;
        let off = |d: Dir| {
            let mut x = (d.angle_rad() - a).abs() % std::f32::consts::TAU;
            if x > std::f32::consts::PI {
                x = std::f32::consts::TAU - x;
            }
            x
        };
        dirs.sort_by(|p, q| off(*p).total_cmp(&off(*q)).then(p.cmp(q)));
        dirs
    }
}

/// One diverging link: where it leads, how long it is and its pheromone value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Link {
    pub to: usize,
    pub length_m: f32,
    /// Positive = pheromone (attracts), negative = anti-pheromone (repels), −∞ = dead end.
    pub value: f32,
}

/// A node on the map's passages.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    pub name: String,
    pub x_m: f32,
    pub y_m: f32,
    /// A terminal node ends a passage (the paper's red nodes).
    pub terminal: bool,
    pub links: [Option<Link>; MAX_LINKS],
}

impl Node {
    pub fn degree(&self) -> usize {
        self.links.iter().flatten().count()
    }

    /// `(direction, link)` of every link.
    pub fn links(&self) -> impl Iterator<Item = (Dir, &Link)> + '_ {
        Dir::ALL
            .into_iter()
            .zip(self.links.iter())
            .filter_map(|(d, l)| l.as_ref().map(|l| (d, l)))
    }
}

/// Why a graph or an update is refused; each variant names the thing and the value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GraphError {
    #[error("graph node '{node}': {detail}")]
    Node { node: String, detail: String },
    #[error("graph link '{from}' -> '{to}': {detail}")]
    Link {
        from: String,
        to: String,
        detail: String,
    },
    #[error("graph: unknown node '{0}'")]
    UnknownNode(String),
    #[error("graph: node index {0} out of range")]
    NodeIndex(usize),
    #[error("graph: node {node} has no link {dir:?}")]
    NoLink { node: usize, dir: Dir },
    #[error("graph: link amount {0} is not finite")]
    Amount(f32),
    #[error(transparent)]
    Region(#[from] RegionError),
    #[error(transparent)]
    Localize(#[from] localize::LocalizeError),
}

/// `[[graph.node]]` of a scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeConfig {
    pub name: String,
    pub x_m: f32,
    pub y_m: f32,
    /// Default: a node with exactly one link is terminal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub terminal: Option<bool>,
}

/// `[[graph.link]]` of a scenario: a passage between two nodes, usable both ways. Directions
/// default to the axis closest to the passage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkConfig {
    pub from: String,
    pub to: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_dir: Option<Dir>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub to_dir: Option<Dir>,
    /// Initial value on both directions (default 0: never visited).
    #[serde(default)]
    pub value: f32,
}

/// `[graph]` of a scenario: nodes and links given explicitly.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraphConfig {
    #[serde(default, rename = "node")]
    pub nodes: Vec<NodeConfig>,
    #[serde(default, rename = "link")]
    pub links: Vec<LinkConfig>,
}

/// The node graph with its link values.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Graph {
    nodes: Vec<Node>,
}

impl Graph {
    /// An empty graph; add nodes and edges with [`Graph::add_node`] and [`Graph::add_edge`].
    pub fn new() -> Self {
        Self::default()
    }

    /// The graph a scenario gives explicitly.
    pub fn explicit(config: &GraphConfig) -> Result<Self, GraphError> {
        let mut g = Graph::new();
        for n in &config.nodes {
            g.add_node(&n.name, n.x_m, n.y_m)?;
        }
        for l in &config.links {
            let a = g.find(&l.from)?;
            let b = g.find(&l.to)?;
            if !l.value.is_finite() {
                return Err(GraphError::Link {
                    from: l.from.clone(),
                    to: l.to.clone(),
                    detail: format!("initial value {} is not finite", l.value),
                });
            }
            g.add_edge(a, b, l.from_dir, l.to_dir)?;
            let (da, db) = g.edge_dirs(a, b).expect("edge just added");
            g.node_mut(a).links[da.index()].as_mut().unwrap().value = l.value;
            g.node_mut(b).links[db.index()].as_mut().unwrap().value = l.value;
        }
        g.mark_terminals();
        for n in &config.nodes {
            if let Some(t) = n.terminal {
                let i = g.find(&n.name)?;
                g.nodes[i].terminal = t;
            }
        }
        Ok(g)
    }

    /// Adds a node; names must be unique and positions finite.
    pub fn add_node(&mut self, name: &str, x_m: f32, y_m: f32) -> Result<usize, GraphError> {
        if name.is_empty() || self.nodes.iter().any(|n| n.name == name) {
            return Err(GraphError::Node {
                node: name.to_string(),
                detail: "names must be non-empty and unique".into(),
            });
        }
        if !x_m.is_finite() || !y_m.is_finite() {
            return Err(GraphError::Node {
                node: name.to_string(),
                detail: format!("position ({x_m}, {y_m}) is not finite"),
            });
        }
        self.nodes.push(Node {
            name: name.to_string(),
            x_m,
            y_m,
            terminal: false,
            links: [None; MAX_LINKS],
        });
        Ok(self.nodes.len() - 1)
    }

    /// Links `a` and `b` both ways with value 0. A direction not given is the free one closest
    /// to the passage's axis; more than [`MAX_LINKS`] links on a node is an error.
    pub fn add_edge(
        &mut self,
        a: usize,
        b: usize,
        dir_a: Option<Dir>,
        dir_b: Option<Dir>,
    ) -> Result<(), GraphError> {
        let (na, nb) = (self.node(a)?.clone(), self.node(b)?.clone());
        let err = |detail: String| GraphError::Link {
            from: na.name.clone(),
            to: nb.name.clone(),
            detail,
        };
        if a == b {
            return Err(err("a node cannot link to itself".into()));
        }
        if self.edge_dirs(a, b).is_some() {
            return Err(err("the nodes are already linked".into()));
        }
        let length_m = (nb.x_m - na.x_m).hypot(nb.y_m - na.y_m);
        if length_m <= 0.0 {
            return Err(err("the nodes are at the same position".into()));
        }
        let pick = |n: &Node, want: Option<Dir>, dx: f32, dy: f32| -> Result<Dir, GraphError> {
            match want {
                Some(d) if n.links[d.index()].is_some() => Err(err(format!(
                    "node '{}' already has a link {}",
                    n.name,
                    d.name()
                ))),
                Some(d) => Ok(d),
                None => Dir::by_closeness(dx, dy)
                    .into_iter()
                    .find(|d| n.links[d.index()].is_none())
                    .ok_or_else(|| {
                        err(format!(
                            "node '{}' already has {MAX_LINKS} links (the most a node may have)",
                            n.name
                        ))
                    }),
            }
        };
        let da = pick(&na, dir_a, nb.x_m - na.x_m, nb.y_m - na.y_m)?;
        let db = pick(&nb, dir_b, na.x_m - nb.x_m, na.y_m - nb.y_m)?;
        self.nodes[a].links[da.index()] = Some(Link {
            to: b,
            length_m,
            value: 0.0,
        });
        self.nodes[b].links[db.index()] = Some(Link {
            to: a,
            length_m,
            value: 0.0,
        });
        Ok(())
    }

    /// Marks every node with exactly one link terminal (and the others not).
    pub fn mark_terminals(&mut self) {
        for n in &mut self.nodes {
            n.terminal = n.degree() == 1;
        }
    }

    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    pub fn node(&self, i: usize) -> Result<&Node, GraphError> {
        self.nodes.get(i).ok_or(GraphError::NodeIndex(i))
    }

    fn node_mut(&mut self, i: usize) -> &mut Node {
        &mut self.nodes[i]
    }

    /// Index of the node called `name`.
    pub fn find(&self, name: &str) -> Result<usize, GraphError> {
        self.nodes
            .iter()
            .position(|n| n.name == name)
            .ok_or_else(|| GraphError::UnknownNode(name.to_string()))
    }

    /// The node nearest to a world point.
    pub fn nearest_node(&self, x_m: f32, y_m: f32) -> Option<usize> {
        (0..self.nodes.len()).min_by(|&i, &j| {
            let d = |k: usize| (self.nodes[k].x_m - x_m).hypot(self.nodes[k].y_m - y_m);
            d(i).total_cmp(&d(j))
        })
    }

    pub fn link(&self, node: usize, dir: Dir) -> Result<&Link, GraphError> {
        self.node(node)?.links[dir.index()]
            .as_ref()
            .ok_or(GraphError::NoLink { node, dir })
    }

    fn link_mut(&mut self, node: usize, dir: Dir) -> Result<&mut Link, GraphError> {
        self.node(node)?;
        self.nodes[node].links[dir.index()]
            .as_mut()
            .ok_or(GraphError::NoLink { node, dir })
    }

    /// The directions of the edge `a`–`b` at `a` and at `b`.
    pub fn edge_dirs(&self, a: usize, b: usize) -> Option<(Dir, Dir)> {
        let da = self.nodes.get(a)?.links().find(|(_, l)| l.to == b)?.0;
        let db = self.nodes.get(b)?.links().find(|(_, l)| l.to == a)?.0;
        Some((da, db))
    }

    /// Adds `amount` to a link's value (−1 per traversal = anti-pheromone, positive = pheromone).
    /// A dead end stays −∞.
    pub fn add_to_link(&mut self, node: usize, dir: Dir, amount: f32) -> Result<f32, GraphError> {
        if !amount.is_finite() {
            return Err(GraphError::Amount(amount));
        }
        let l = self.link_mut(node, dir)?;
        l.value += amount;
        Ok(l.value)
    }

    /// Marks a link as leading into a dead end (−∞).
    pub fn set_dead_end(&mut self, node: usize, dir: Dir) -> Result<(), GraphError> {
        self.link_mut(node, dir)?.value = DEAD_END;
        Ok(())
    }

    /// Eq. 8: the link with the largest value; ties broken at random by `rng` (seeded, so the
    /// choice is reproducible). A −∞ link is chosen only if every link of the node is −∞.
    pub fn choose_link<R: Rng>(&self, node: usize, rng: &mut R) -> Result<Option<Dir>, GraphError> {
        self.choose_link_among(node, |_, _| Some(0.0), rng)
    }

    /// Eq. 8 over the links `cost` admits (`Some`): the largest value first, then the lowest
    /// cost, then a seeded random pick among what is still tied. −∞ links lose to any other
    /// admitted link.
    pub fn choose_link_among<R: Rng>(
        &self,
        node: usize,
        cost: impl Fn(Dir, &Link) -> Option<f32>,
        rng: &mut R,
    ) -> Result<Option<Dir>, GraphError> {
        let cands: Vec<(Dir, f32, f32)> = self
            .node(node)?
            .links()
            .filter_map(|(d, l)| cost(d, l).map(|c| (d, l.value, c)))
            .collect();
        let key = |a: &(Dir, f32, f32), b: &(Dir, f32, f32)| {
            a.1.total_cmp(&b.1).then(b.2.total_cmp(&a.2))
        };
        let Some(best) = cands.iter().max_by(|a, b| key(a, b)).copied() else {
            return Ok(None);
        };
        let ties: Vec<Dir> = cands
            .iter()
            .filter(|c| key(c, &best) == Ordering::Equal)
            .map(|c| c.0)
            .collect();
        Ok(Some(ties[rng.random_range(0..ties.len())]))
    }

    /// A* from `from` to `to` over link lengths (link values are ignored): the node path and its
    /// length, or `None` if `to` cannot be reached.
    pub fn astar(&self, from: usize, to: usize) -> Option<(Vec<usize>, f32)> {
        let goal = self.nodes.get(to)?;
        self.nodes.get(from)?;
        let h = |i: usize| (self.nodes[i].x_m - goal.x_m).hypot(self.nodes[i].y_m - goal.y_m);
        let mut g = vec![f32::INFINITY; self.nodes.len()];
        let mut prev = vec![usize::MAX; self.nodes.len()];
        let mut open = BinaryHeap::new();
        g[from] = 0.0;
        open.push(Open(h(from), from));
        while let Some(Open(_, i)) = open.pop() {
            if i == to {
                let mut path = vec![to];
                while *path.last().unwrap() != from {
                    path.push(prev[*path.last().unwrap()]);
                }
                path.reverse();
                return Some((path, g[to]));
            }
            for (_, l) in self.nodes[i].links() {
                let cand = g[i] + l.length_m;
                if cand < g[l.to] {
                    g[l.to] = cand;
                    prev[l.to] = i;
                    open.push(Open(cand + h(l.to), l.to));
                }
            }
        }
        None
    }

    /// Dijkstra distances (m) from `from` to every node, never passing through `blocked`.
    pub fn distances_from(&self, from: usize, blocked: Option<usize>) -> Vec<f32> {
        let mut d = vec![f32::INFINITY; self.nodes.len()];
        if from >= self.nodes.len() || Some(from) == blocked {
            return d;
        }
        let mut open = BinaryHeap::new();
        d[from] = 0.0;
        open.push(Open(0.0, from));
        while let Some(Open(di, i)) = open.pop() {
            if di > d[i] {
                continue;
            }
            for (_, l) in self.nodes[i].links() {
                if Some(l.to) == blocked {
                    continue;
                }
                let cand = di + l.length_m;
                if cand < d[l.to] {
                    d[l.to] = cand;
                    open.push(Open(cand, l.to));
                }
            }
        }
        d
    }

    /// All link values by node name and direction (for reports, like the paper's Table 3).
    pub fn value_table(&self) -> HashMap<String, [Option<f32>; MAX_LINKS]> {
        self.nodes
            .iter()
            .map(|n| (n.name.clone(), n.links.map(|l| l.map(|l| l.value))))
            .collect()
    }
}

/// Min-heap entry (cost, node).
#[derive(PartialEq)]
struct Open(f32, usize);
impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

/// A small update a robot sends to the graph's one writer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GraphUpdate {
    /// Add `amount` to the link `dir` of `node` (−1 after taking it; positive to attract).
    AddToLink { node: usize, dir: Dir, amount: f32 },
    /// The link `dir` of `node` leads into a dead end: −∞.
    DeadEnd { node: usize, dir: Dir },
    /// `robot` captures `region` (refused when it holds Max-R robots already).
    Capture { region: usize, robot: u32 },
    /// `robot` releases `region`.
    Release { region: usize, robot: u32 },
}

/// The graph and its regions: what the one writer owns and publishes.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GraphState {
    pub graph: Graph,
    pub regions: RegionTable,
}

impl GraphState {
    /// Applies one update; a refused capture is `Ok(CaptureOutcome::Full)`, not an error.
    pub fn apply(&mut self, u: GraphUpdate) -> Result<Option<CaptureOutcome>, GraphError> {
        match u {
            GraphUpdate::AddToLink { node, dir, amount } => {
                self.graph.add_to_link(node, dir, amount)?;
                Ok(None)
            }
            GraphUpdate::DeadEnd { node, dir } => {
                self.graph.set_dead_end(node, dir)?;
                Ok(None)
            }
            GraphUpdate::Capture { region, robot } => {
                Ok(Some(self.regions.capture(region, robot)?))
            }
            GraphUpdate::Release { region, robot } => {
                self.regions.release(region, robot)?;
                Ok(None)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn star() -> Graph {
        let cfg: GraphConfig = toml::from_str(
            r#"
            [[node]]
            name = "c"
            x_m = 0.0
            y_m = 0.0
            [[node]]
            name = "u"
            x_m = 0.0
            y_m = 1.0
            [[node]]
            name = "r"
            x_m = 2.0
            y_m = 0.0
            [[node]]
            name = "l"
            x_m = -1.0
            y_m = 0.0
            [[link]]
            from = "c"
            to = "u"
            [[link]]
            from = "c"
            to = "r"
            [[link]]
            from = "c"
            to = "l"
            value = -2.0
            "#,
        )
        .unwrap();
        Graph::explicit(&cfg).unwrap()
    }

    #[test]
    fn explicit_graph_gets_directions_and_terminals() {
        let g = star();
        let c = g.find("c").unwrap();
        assert_eq!(g.link(c, Dir::Up).unwrap().to, g.find("u").unwrap());
        assert_eq!(g.link(c, Dir::Right).unwrap().length_m, 2.0);
        assert_eq!(g.link(c, Dir::Left).unwrap().value, -2.0);
        assert!(g.link(c, Dir::Down).is_err());
        assert!(!g.nodes()[c].terminal);
        assert!(g.nodes()[g.find("u").unwrap()].terminal);
    }

    #[test]
    fn bad_graphs_name_the_culprit() {
        let mut cfg = GraphConfig::default();
        cfg.nodes.push(NodeConfig {
            name: "a".into(),
            x_m: 0.0,
            y_m: 0.0,
            terminal: None,
        });
        cfg.links.push(LinkConfig {
            from: "a".into(),
            to: "zz".into(),
            from_dir: None,
            to_dir: None,
            value: 0.0,
        });
        let e = Graph::explicit(&cfg).unwrap_err().to_string();
        assert!(e.contains("'zz'"), "{e}");
        let mut g = Graph::new();
        let c = g.add_node("c", 0.0, 0.0).unwrap();
        for (i, (x, y)) in [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)]
            .into_iter()
            .enumerate()
        {
            let n = g.add_node(&format!("n{i}"), x, y).unwrap();
            g.add_edge(c, n, None, None).unwrap();
        }
        let n = g.add_node("fifth", 1.0, 1.0).unwrap();
        let e = g.add_edge(c, n, None, None).unwrap_err().to_string();
        assert!(e.contains("already has 4 links"), "{e}");
    }

    #[test]
    fn astar_and_dijkstra_agree() {
        let g = star();
        let (u, r) = (g.find("u").unwrap(), g.find("r").unwrap());
        let (path, len) = g.astar(u, r).unwrap();
        assert_eq!(path, vec![u, g.find("c").unwrap(), r]);
        assert_eq!(len, 3.0);
        assert_eq!(g.distances_from(u, None)[r], 3.0);
        assert!(g.distances_from(u, Some(g.find("c").unwrap()))[r].is_infinite());
    }

    #[test]
    fn choice_prefers_largest_value_then_cost() {
        let mut g = star();
        let c = g.find("c").unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        // up 0, right 0, left −2: cheapest of the tied (up, 1 m) wins on cost.
        let d = g
            .choose_link_among(c, |_, l| Some(l.length_m), &mut rng)
            .unwrap();
        assert_eq!(d, Some(Dir::Up));
        g.add_to_link(c, Dir::Up, -1.0).unwrap();
        g.add_to_link(c, Dir::Right, -1.0).unwrap();
        g.add_to_link(c, Dir::Right, 5.0).unwrap();
        assert_eq!(g.choose_link(c, &mut rng).unwrap(), Some(Dir::Right));
        g.set_dead_end(c, Dir::Right).unwrap();
        assert_eq!(g.add_to_link(c, Dir::Right, 10.0).unwrap(), DEAD_END);
        assert!(g.add_to_link(c, Dir::Up, f32::NAN).is_err());
    }
}
