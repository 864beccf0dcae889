//! The graph in shared memory, the same design as the grid: one writer ([`GraphServer`]) owns
//! the [`GraphState`], applies small [`GraphUpdateMsg`]s from robots and publishes immutable
//! fixed-size [`GraphSnapshot`]s; robots read them with [`GraphReader`] and send updates with
//! [`GraphUpdater`]. Contention messages (Listing 1's JSON) travel in fixed-size
//! [`ContendWire`] buffers over [`Contention`]. Safe iceoryx2 API only (via `pheromone_field::process::link`).
//!
//! Services of a graph `G`: `pheromone/G/graph` (+ `-ready`), `pheromone/G/graph-update`
//! (+ `-ready`), `pheromone/G/contend` (+ `-ready`).

use std::fmt;
use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::process::link::{Receiver, Sender};
use pheromone_field::shm::{now_ns, ShmError, Svc};

use super::conflict::{ConflictError, ContendMsg};
use super::{CaptureOutcome, Dir, GraphError, GraphState, GraphUpdate, MAX_LINKS};

/// Most nodes a snapshot carries.
pub const MAX_NODES: usize = 64;
/// Most regions a snapshot carries.
pub const MAX_REGIONS: usize = 16;
/// Most robots one region may hold (Max-R) in a snapshot.
pub const MAX_CAPTURERS: usize = 8;
/// `link_to` of a missing link.
pub const NO_LINK: u32 = u32::MAX;
/// Bytes of JSON a contention message may carry.
pub const CONTEND_BYTES: usize = 504;
/// Most robots a lockstep graph run may have (claims of one step per region).
pub const MAX_GRAPH_ROBOTS: usize = 16;
/// `GraphUpdateMsg::region` of a step-done message without a claim.
pub const NO_CLAIM: u32 = u32::MAX;

/// One node of a snapshot; links indexed by [`Dir`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct NodeSlot {
    pub x_m: f32,
    pub y_m: f32,
    pub terminal: u32,
    pub link_to: [u32; MAX_LINKS],
    pub link_value: [f32; MAX_LINKS],
    pub link_length_m: [f32; MAX_LINKS],
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(
    NodeSlot,
    "GraphNodeSlot",
    size = 12 + 12 * MAX_LINKS,
    align = 4
);

impl NodeSlot {
    pub const EMPTY: NodeSlot = NodeSlot {
        x_m: 0.0,
        y_m: 0.0,
        terminal: 0,
        link_to: [NO_LINK; MAX_LINKS],
        link_value: [0.0; MAX_LINKS],
        link_length_m: [0.0; MAX_LINKS],
    };
}

/// One region of a snapshot.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct RegionSlot {
    pub node: u32,
    pub max_r: u32,
    pub n_captured: u32,
    pub value: f32,
    pub captured_by: [u32; MAX_CAPTURERS],
    /// Lockstep runs: robots that claimed the region in the previous step.
    pub n_claims: u32,
    pub claims: [u32; MAX_GRAPH_ROBOTS],
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(
    RegionSlot,
    "GraphRegionSlot",
    size = 20 + 4 * (MAX_CAPTURERS + MAX_GRAPH_ROBOTS),
    align = 4
);

impl RegionSlot {
    pub const EMPTY: RegionSlot = RegionSlot {
        node: 0,
        max_r: 0,
        n_captured: 0,
        value: 0.0,
        captured_by: [0; MAX_CAPTURERS],
        n_claims: 0,
        claims: [0; MAX_GRAPH_ROBOTS],
    };
}

/// An immutable published state of the graph and its regions (≈5 KiB).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct GraphSnapshot {
    pub seq: u64,
    pub stamp_ns: u64,
    pub updates_applied: u64,
    /// Updates refused as malformed (unknown kind, node, link, region, non-finite amount).
    pub updates_rejected: u64,
    /// Capture attempts refused because the region held Max-R robots.
    pub captures_refused: u64,
    /// Lockstep runs: the step this snapshot opens and its simulated time.
    pub step: u64,
    pub sim_time_s: f64,
    /// Lockstep runs: 1 when the run has ended and robots should stop.
    pub finished: u32,
    pub n_nodes: u32,
    pub n_regions: u32,
    pub _pad: u32,
    pub nodes: [NodeSlot; MAX_NODES],
    pub regions: [RegionSlot; MAX_REGIONS],
}

// repr(C): numbers and arrays of `NodeSlot` and `RegionSlot` only.
pheromone_field::wire_type!(
    GraphSnapshot,
    "GraphSnapshot",
    size = 72 + 60 * MAX_NODES + 116 * MAX_REGIONS,
    align = 8
);

impl GraphSnapshot {
    pub const EMPTY: GraphSnapshot = GraphSnapshot {
        seq: 0,
        stamp_ns: 0,
        updates_applied: 0,
        updates_rejected: 0,
        captures_refused: 0,
        step: 0,
        sim_time_s: 0.0,
        finished: 0,
        n_nodes: 0,
        n_regions: 0,
        _pad: 0,
        nodes: [NodeSlot::EMPTY; MAX_NODES],
        regions: [RegionSlot::EMPTY; MAX_REGIONS],
    };

    /// Writes a state into a snapshot; fails if it exceeds the fixed capacities.
    pub fn from_state(s: &GraphState) -> Result<Self, GraphShmError> {
        check_fits(s)?;
        let mut snap = Self::EMPTY;
        snap.n_nodes = s.graph.len() as u32;
        snap.n_regions = s.regions.len() as u32;
        for (slot, n) in snap.nodes.iter_mut().zip(s.graph.nodes()) {
            slot.x_m = n.x_m;
            slot.y_m = n.y_m;
            slot.terminal = n.terminal as u32;
            for (d, l) in n.links() {
                slot.link_to[d.index()] = l.to as u32;
                slot.link_value[d.index()] = l.value;
                slot.link_length_m[d.index()] = l.length_m;
            }
        }
        for (slot, r) in snap.regions.iter_mut().zip(s.regions.regions()) {
            slot.node = r.node as u32;
            slot.max_r = r.max_r;
            slot.n_captured = r.captured_by.len() as u32;
            slot.value = r.value;
            slot.captured_by[..r.captured_by.len()].copy_from_slice(&r.captured_by);
        }
        Ok(snap)
    }

    /// Lockstep runs: per region, the robots that claimed it in the previous step.
    pub fn claims(&self) -> Vec<Vec<u32>> {
        self.regions[..(self.n_regions as usize).min(MAX_REGIONS)]
            .iter()
            .map(|r| r.claims[..(r.n_claims as usize).min(MAX_GRAPH_ROBOTS)].to_vec())
            .collect()
    }

    /// Lockstep runs: records the claims of a step (at most [`MAX_GRAPH_ROBOTS`] per region).
    pub fn set_claims(&mut self, claims: &[Vec<u32>]) {
        for (slot, c) in self.regions.iter_mut().zip(claims) {
            let n = c.len().min(MAX_GRAPH_ROBOTS);
            slot.n_claims = n as u32;
            slot.claims[..n].copy_from_slice(&c[..n]);
        }
    }

    /// `base` (the same graph and regions, from the same scenario) with this snapshot's link
    /// values and captures; an error if the structure differs.
    pub fn apply_to(&self, base: &GraphState) -> Result<GraphState, GraphShmError> {
        if self.n_nodes as usize != base.graph.len()
            || self.n_regions as usize != base.regions.len()
        {
            return Err(SnapshotMismatch::Size {
                nodes: self.n_nodes,
                regions: self.n_regions,
                scenario_nodes: base.graph.len(),
                scenario_regions: base.regions.len(),
            }
            .into());
        }
        let mut s = base.clone();
        for (i, slot) in self.nodes[..self.n_nodes as usize].iter().enumerate() {
            let n = &base.graph.nodes()[i];
            for d in Dir::ALL {
                let to = n.links[d.index()].map(|l| l.to as u32).unwrap_or(NO_LINK);
                if to != slot.link_to[d.index()] {
                    return Err(SnapshotMismatch::Link {
                        node: n.name.clone(),
                        dir: d.name(),
                        snapshot: slot.link_to[d.index()],
                        scenario: to,
                    }
                    .into());
                }
                if to != NO_LINK {
                    let v = slot.link_value[d.index()];
                    let l = s.graph.nodes[i].links[d.index()].as_mut().unwrap();
                    l.value = v;
                }
            }
        }
        for (i, slot) in self.regions[..self.n_regions as usize].iter().enumerate() {
            let k = (slot.n_captured as usize).min(MAX_CAPTURERS);
            s.regions.set_state(i, &slot.captured_by[..k], slot.value);
        }
        Ok(s)
    }
}

fn check_fits(s: &GraphState) -> Result<(), GraphShmError> {
    let too = |what: &'static str, count: usize, max: usize| {
        Err(GraphShmError::TooBig { what, count, max })
    };
    if s.graph.len() > MAX_NODES {
        return too("nodes", s.graph.len(), MAX_NODES);
    }
    if s.regions.len() > MAX_REGIONS {
        return too("regions", s.regions.len(), MAX_REGIONS);
    }
    if let Some(r) = s
        .regions
        .regions()
        .iter()
        .find(|r| r.max_r as usize > MAX_CAPTURERS)
    {
        return too("max_r of a region", r.max_r as usize, MAX_CAPTURERS);
    }
    Ok(())
}

/// Update kinds on the wire.
pub mod kind {
    pub const ADD_TO_LINK: u32 = 0;
    pub const DEAD_END: u32 = 1;
    pub const CAPTURE: u32 = 2;
    pub const RELEASE: u32 = 3;
    /// Lockstep runs: the robot has sent every update of `step`; `region` is its claim or
    /// [`super::NO_CLAIM`].
    pub const STEP_DONE: u32 = 4;
}

/// A robot's update to the graph.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct GraphUpdateMsg {
    pub stamp_ns: u64,
    /// Lockstep runs: the step the update belongs to (0 otherwise).
    pub step: u64,
    pub robot_id: u32,
    /// One of [`kind`].
    pub kind: u32,
    pub node: u32,
    /// [`Dir`] index.
    pub dir: u32,
    pub region: u32,
    pub amount: f32,
    pub _pad: u32,
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(GraphUpdateMsg, "GraphUpdateMsg", size = 48, align = 8);

impl GraphUpdateMsg {
    pub fn new(robot_id: u32, u: GraphUpdate) -> Self {
        let mut m = GraphUpdateMsg {
            stamp_ns: now_ns(),
            robot_id,
            ..Default::default()
        };
        match u {
            GraphUpdate::AddToLink { node, dir, amount } => {
                m.kind = kind::ADD_TO_LINK;
                m.node = node as u32;
                m.dir = dir.index() as u32;
                m.amount = amount;
            }
            GraphUpdate::DeadEnd { node, dir } => {
                m.kind = kind::DEAD_END;
                m.node = node as u32;
                m.dir = dir.index() as u32;
            }
            GraphUpdate::Capture { region, robot } => {
                m.kind = kind::CAPTURE;
                m.region = region as u32;
                m.robot_id = robot;
            }
            GraphUpdate::Release { region, robot } => {
                m.kind = kind::RELEASE;
                m.region = region as u32;
                m.robot_id = robot;
            }
        }
        m
    }

    /// The update, or why the message is malformed.
    pub fn update(&self) -> Result<GraphUpdate, MalformedUpdate> {
        let dir = || Dir::from_index(self.dir as usize).ok_or(MalformedUpdate::Dir(self.dir));
        Ok(match self.kind {
            kind::ADD_TO_LINK => GraphUpdate::AddToLink {
                node: self.node as usize,
                dir: dir()?,
                amount: self.amount,
            },
            kind::DEAD_END => GraphUpdate::DeadEnd {
                node: self.node as usize,
                dir: dir()?,
            },
            kind::CAPTURE => GraphUpdate::Capture {
                region: self.region as usize,
                robot: self.robot_id,
            },
            kind::RELEASE => GraphUpdate::Release {
                region: self.region as usize,
                robot: self.robot_id,
            },
            kind::STEP_DONE => return Err(MalformedUpdate::StepDone),
            k => return Err(MalformedUpdate::Kind(k)),
        })
    }
}

/// Listing 1's JSON text in a fixed-size buffer.
#[derive(Clone, Copy, PartialEq)]
#[repr(C)]
pub struct ContendWire {
    pub len: u32,
    pub text: [u8; CONTEND_BYTES],
}

// repr(C): numbers and arrays of numbers only.
pheromone_field::wire_type!(
    ContendWire,
    "ContendWire",
    size = 4 + CONTEND_BYTES,
    align = 4
);

impl fmt::Debug for ContendWire {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = (self.len as usize).min(CONTEND_BYTES);
        write!(
            f,
            "ContendWire({})",
            String::from_utf8_lossy(&self.text[..n])
        )
    }
}

impl ContendWire {
    pub fn encode(m: &ContendMsg) -> Result<Self, ConflictError> {
        let json = m.to_json();
        if json.len() > CONTEND_BYTES {
            return Err(ConflictError::TooLong {
                len: json.len(),
                max: CONTEND_BYTES,
            });
        }
        let mut w = ContendWire {
            len: json.len() as u32,
            text: [0; CONTEND_BYTES],
        };
        w.text[..json.len()].copy_from_slice(json.as_bytes());
        Ok(w)
    }

    pub fn decode(&self) -> Result<ContendMsg, ConflictError> {
        let n = self.len as usize;
        if n > CONTEND_BYTES {
            return Err(ConflictError::TooLong {
                len: n,
                max: CONTEND_BYTES,
            });
        }
        let text = std::str::from_utf8(&self.text[..n]).map_err(ConflictError::Utf8)?;
        ContendMsg::from_json(text)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum GraphShmError {
    #[error(transparent)]
    Shm(#[from] ShmError),
    #[error("the graph has {count} {what}; a snapshot holds at most {max}")]
    TooBig {
        what: &'static str,
        count: usize,
        max: usize,
    },
    #[error("graph snapshot does not match the scenario: {0}")]
    Mismatch(#[from] SnapshotMismatch),
    #[error("graph update on '{0}' was not delivered (no graph server, or its buffer is full)")]
    NotDelivered(String),
    #[error(transparent)]
    Graph(#[from] GraphError),
    #[error(transparent)]
    Conflict(#[from] ConflictError),
}

pheromone_field::from_shm_errors!(GraphShmError);

/// How a snapshot's structure differs from the scenario's graph.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SnapshotMismatch {
    #[error("snapshot has {nodes} nodes and {regions} regions, the scenario {scenario_nodes} and {scenario_regions}")]
    Size {
        nodes: u32,
        regions: u32,
        scenario_nodes: usize,
        scenario_regions: usize,
    },
    #[error("node '{node}' link {dir}: snapshot leads to {snapshot}, the scenario to {scenario}")]
    Link {
        node: String,
        dir: &'static str,
        snapshot: u32,
        scenario: u32,
    },
}

/// Why a [`GraphUpdateMsg`] is not an update.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MalformedUpdate {
    #[error("unknown link direction {0}")]
    Dir(u32),
    #[error("a step-done message is not an update")]
    StepDone,
    #[error("unknown update kind {0}")]
    Kind(u32),
}

/// Why the server did not apply an update message.
#[derive(Debug, thiserror::Error)]
pub enum UpdateRejected {
    #[error(transparent)]
    Malformed(#[from] MalformedUpdate),
    /// The graph refused it (unknown node, link, region …).
    #[error(transparent)]
    Refused(#[from] GraphError),
}

pub use pheromone_field::wire::graph_services;
pub(crate) use pheromone_field::wire::{
    GRAPH_CONTEND_LINK as CONTEND_LINK, GRAPH_SNAPSHOT_LINK as SNAPSHOT_LINK,
    GRAPH_UPDATE_LINK as UPDATE_LINK,
};

/// Counters of the server.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServerCounters {
    pub applied: u64,
    pub rejected: u64,
    pub captures_refused: u64,
}

/// The graph's one writer.
pub struct GraphServer {
    state: GraphState,
    snapshots: Sender<GraphSnapshot>,
    updates: Receiver<GraphUpdateMsg>,
    seq: u64,
    counters: ServerCounters,
    readers_seen: usize,
}

impl GraphServer {
    /// Creates the services and publishes the first snapshot.
    pub fn create(node: &Node<Svc>, name: &str, state: GraphState) -> Result<Self, GraphShmError> {
        check_fits(&state)?;
        let [(snap, snap_wake), (upd, upd_wake), _] = graph_services(name);
        let snapshots = Sender::create(node, &snap, &snap_wake, SNAPSHOT_LINK)?;
        let updates = Receiver::create(node, &upd, &upd_wake, UPDATE_LINK)?;
        let mut s = Self {
            state,
            snapshots,
            updates,
            seq: 0,
            counters: ServerCounters::default(),
            readers_seen: 0,
        };
        s.publish()?;
        Ok(s)
    }

    pub fn state(&self) -> &GraphState {
        &self.state
    }

    pub fn counters(&self) -> ServerCounters {
        self.counters
    }

    /// Publishes the current state as a new snapshot.
    pub fn publish(&mut self) -> Result<(), GraphShmError> {
        let mut snap = GraphSnapshot::from_state(&self.state)?;
        self.seq += 1;
        snap.seq = self.seq;
        snap.stamp_ns = now_ns();
        snap.updates_applied = self.counters.applied;
        snap.updates_rejected = self.counters.rejected;
        snap.captures_refused = self.counters.captures_refused;
        self.snapshots.send(snap)?;
        Ok(())
    }

    /// Applies one update message in arrival order; a malformed one is counted, never applied.
    pub fn apply(&mut self, m: &GraphUpdateMsg) -> Result<Option<CaptureOutcome>, UpdateRejected> {
        let r = m
            .update()
            .map_err(UpdateRejected::from)
            .and_then(|u| Ok(self.state.apply(u)?));
        match &r {
            Ok(Some(CaptureOutcome::Full)) => self.counters.captures_refused += 1,
            Ok(_) => self.counters.applied += 1,
            Err(_) => self.counters.rejected += 1,
        }
        r
    }

    /// Waits up to `timeout` for updates, applies every one buffered and publishes a snapshot if
    /// there were any, or if readers attached since the last one (so they get the current state
    /// at once). Returns how many updates it took.
    pub fn serve_once(&mut self, timeout: Duration) -> Result<usize, GraphShmError> {
        let readers = self.snapshots.receivers();
        if readers != self.readers_seen {
            self.readers_seen = readers;
            self.publish()?;
        }
        let mut n = 0;
        let mut next = self.updates.recv_timeout(timeout)?;
        while let Some(m) = next {
            // A rejected update is counted in `counters.rejected` (what the snapshots report);
            // the server goes on with the next one.
            let _ = self.apply(&m);
            n += 1;
            next = self.updates.try_recv()?;
        }
        if n > 0 {
            self.publish()?;
        }
        Ok(n)
    }
}

/// Reads a graph's snapshots.
pub struct GraphReader {
    snapshots: Receiver<GraphSnapshot>,
    latest: Option<GraphSnapshot>,
}

impl GraphReader {
    pub fn attach(node: &Node<Svc>, name: &str) -> Result<Self, GraphShmError> {
        let [(snap, snap_wake), _, _] = graph_services(name);
        Ok(Self {
            snapshots: Receiver::create(node, &snap, &snap_wake, SNAPSHOT_LINK)?,
            latest: None,
        })
    }

    /// Takes in whatever arrived; the newest snapshot seen so far.
    pub fn poll(&mut self) -> Result<Option<&GraphSnapshot>, GraphShmError> {
        if let Some(s) = self.snapshots.latest()? {
            self.latest = Some(s);
        }
        Ok(self.latest.as_ref())
    }

    /// Waits (on the server's event) until a snapshot with `seq > after` arrives or `timeout`.
    /// Writers publishing the graph (0 once the writer is gone).
    pub fn writers(&self) -> usize {
        self.snapshots.senders()
    }

    pub fn wait_newer(
        &mut self,
        after: u64,
        timeout: Duration,
    ) -> Result<Option<&GraphSnapshot>, GraphShmError> {
        let deadline = Instant::now() + timeout;
        loop {
            self.poll()?;
            if self.latest.as_ref().is_some_and(|s| s.seq > after) {
                return Ok(self.latest.as_ref());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.snapshots.wait(left)?;
        }
    }
}

/// Sends a robot's updates to the graph server. Updates the server has not taken yet are lost
/// if the updater is dropped (iceoryx2 drops a gone publisher's samples): keep it until the
/// effect shows in a snapshot.
pub struct GraphUpdater {
    service: String,
    robot_id: u32,
    updates: Sender<GraphUpdateMsg>,
}

impl GraphUpdater {
    pub fn attach(node: &Node<Svc>, name: &str, robot_id: u32) -> Result<Self, GraphShmError> {
        let [_, (upd, upd_wake), _] = graph_services(name);
        Ok(Self {
            updates: Sender::create(node, &upd, &upd_wake, UPDATE_LINK)?,
            service: upd,
            robot_id,
        })
    }

    /// Sends one update; an error if the server did not get it.
    pub fn send(&self, u: GraphUpdate) -> Result<(), GraphShmError> {
        match self.updates.send(GraphUpdateMsg::new(self.robot_id, u))? {
            0 => Err(GraphShmError::NotDelivered(self.service.clone())),
            _ => Ok(()),
        }
    }

    /// Lockstep runs: an update belonging to `step`.
    pub fn send_at(&self, step: u64, u: GraphUpdate) -> Result<(), GraphShmError> {
        let mut m = GraphUpdateMsg::new(self.robot_id, u);
        m.step = step;
        self.deliver(m)
    }

    /// Lockstep runs: every update of `step` has been sent; `claim` is the region this robot
    /// wants to capture (resolved with the other claimants in the next step).
    pub fn step_done(&self, step: u64, claim: Option<usize>) -> Result<(), GraphShmError> {
        self.deliver(GraphUpdateMsg {
            stamp_ns: now_ns(),
            step,
            robot_id: self.robot_id,
            kind: kind::STEP_DONE,
            region: claim.map_or(NO_CLAIM, |r| r as u32),
            ..Default::default()
        })
    }

    fn deliver(&self, m: GraphUpdateMsg) -> Result<(), GraphShmError> {
        match self.updates.send(m)? {
            0 => Err(GraphShmError::NotDelivered(self.service.clone())),
            _ => Ok(()),
        }
    }
}

/// The contention channel every robot of a graph shares.
pub struct Contention {
    tx: Sender<ContendWire>,
    rx: Receiver<ContendWire>,
    /// Received messages not asked for yet (another region, or a later step).
    pending: Vec<ContendMsg>,
    /// Messages that could not be read (counted, skipped).
    pub malformed: u64,
}

impl Contention {
    pub fn attach(node: &Node<Svc>, name: &str) -> Result<Self, GraphShmError> {
        let [_, _, (c, c_wake)] = graph_services(name);
        Ok(Self {
            tx: Sender::create(node, &c, &c_wake, CONTEND_LINK)?,
            rx: Receiver::create(node, &c, &c_wake, CONTEND_LINK)?,
            pending: Vec::new(),
            malformed: 0,
        })
    }

    /// Robots (including this one) listening for contention messages.
    pub fn listeners(&self) -> usize {
        self.tx.receivers()
    }

    /// Waits until at least `n` robots listen for contention messages (`false` on timeout);
    /// claims announced before a robot listens never reach it.
    pub fn wait_listeners(&self, n: usize, timeout: Duration) -> Result<bool, GraphShmError> {
        let deadline = Instant::now() + timeout;
        loop {
            if self.listeners() >= n {
                return Ok(true);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(false);
            }
            // Attaching makes no event; re-check at least every 10 ms.
            self.rx.wait(left.min(Duration::from_millis(10)))?;
        }
    }

    /// Announces this robot's claim to everyone listening (itself included).
    pub fn announce(&self, m: &ContendMsg) -> Result<usize, GraphShmError> {
        Ok(self.tx.send(ContendWire::encode(m)?)?)
    }

    /// Moves what has arrived into the pending list and drops messages stamped before
    /// `oldest_wanted`: a robot that claims nothing for a long time must not let its receive
    /// buffer fill up, or later messages would be discarded for it.
    pub fn drain(&mut self, oldest_wanted: u64) -> Result<(), GraphShmError> {
        while let Some(w) = self.rx.try_recv()? {
            match w.decode() {
                Ok(m) => self.pending.push(m),
                Err(_) => self.malformed += 1,
            }
        }
        self.pending.retain(|m| m.time_stamp_s >= oldest_wanted);
        Ok(())
    }

    /// The messages for `region` stamped `time_stamp_s` (one per robot), waiting until
    /// `expected` have arrived or `timeout` has passed. Messages for other regions or later
    /// stamps are kept for later calls; older ones are dropped.
    pub fn collect(
        &mut self,
        region: u32,
        time_stamp_s: u64,
        expected: usize,
        timeout: Duration,
    ) -> Result<Vec<ContendMsg>, GraphShmError> {
        let deadline = Instant::now() + timeout;
        loop {
            while let Some(w) = self.rx.try_recv()? {
                match w.decode() {
                    Ok(m) => self.pending.push(m),
                    Err(_) => self.malformed += 1,
                }
            }
            let mut got: Vec<ContendMsg> = Vec::new();
            for m in &self.pending {
                if m.region == region
                    && m.time_stamp_s == time_stamp_s
                    && !got.iter().any(|g| g.robot_id == m.robot_id)
                {
                    got.push(*m);
                }
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if got.len() >= expected || left.is_zero() {
                self.pending.retain(|m| {
                    m.time_stamp_s > time_stamp_s
                        || (m.time_stamp_s == time_stamp_s && m.region != region)
                });
                return Ok(got);
            }
            self.rx.wait(left)?;
        }
    }
}

#[cfg(test)]
mod tests;
