//! The mapper's process loop (`pheromone mapper --robot ID`): one robot's [`Mapper`] fed the
//! robot's pose estimate, its scan and its rendezvous measurement of each step, its local map
//! published as a frame of field `<world>-map-r<ID>` ([`pheromone_field::wire::map_field`]; two channels,
//! [`MAP_CHANNELS`], in the robot's own frame; with own-map steering its robot's follower steers
//! on it, `process::follower`), and Algorithm 1's exchanges made zero-copy: at a
//! rendezvous the mapper holds its peer's map frame in shared memory and merges from it
//! ([`Mapper::accept_frame`]: [`MapView::from_frame`](crate::mapper::MapView::from_frame), which
//! validates it, then the merge).
//!
//! Step k (of the links; the world's step k + 1, the step number the mapper's schedule and its
//! merge events use, as in the single-process runner), in lockstep (the world waits for every
//! mapper's acknowledgement, `role::MAPPER`):
//! 1. on an exchange step, merge the frames (maps of the end of step k − 1) of the peers due in
//!    the rendezvous of step k − 1, placed with both robots' estimates of step k − 1, exactly as
//!    `pheromone_sim::mapping::MappingTeam` does in one process;
//! 2. take the estimate, deposit and scan of step k; publish map frame k (sequence = k);
//! 3. when step k + 1 is an exchange step, wait until every peer of the rendezvous of step k
//!    has published its frame k and keep holding it (no peer publishes frame k + 1 before this
//!    mapper acknowledges step k), and read their estimates of step k; then acknowledge step k.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::process::link::Receiver;
use pheromone_field::process::lockstep::{role, Participant};
use pheromone_field::shm::{AttachError, FieldReader, FrameWriter, Svc};
use pheromone_field::{ChannelSpec, Evaporation, FieldConfig};

use crate::mapper::{
    alignment_error_m, pose_in_frame, true_transform, Mapper, MapperCounters, MergeEvent, Pose2,
    MAP_CHANNELS,
};
use crate::{
    receiver, role_loop, summary_of, ProcessError, RobotServices, RoleOptions, RoleSummary,
};
use pheromone_messages::{PoseMsg, RendezvousMsg, ScanMsg};

/// What a mapper process reports at exit.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapperSummary {
    pub role: RoleSummary,
    /// The field its map is published under.
    pub map_field: String,
    pub counters: MapperCounters,
    /// Scans the map refused (non-finite pose or ray).
    pub scans_rejected: u64,
    /// Steps skipped because the robot's estimate of the step never came.
    pub missing_poses: u64,
    pub merges: Vec<MergeEvent>,
}

/// How long a step may wait for an estimate or a peer's frame in lockstep (the world's stall
/// timeout reports a mapper that waits longer).
pub(super) const STEP_WAIT: Duration = Duration::from_secs(30);
/// The same on wall time, where nobody waits and a late message is skipped.
pub(super) const REALTIME_WAIT: Duration = Duration::from_millis(200);

/// The map frame's field configuration: the map's geometry, [`MAP_CHANNELS`] (occupancy signed,
/// log-odds), one frame per world step of `dt_s`, room for `max_readers` readers.
pub fn map_field_config(mapper: &Mapper, dt_s: f64, max_readers: usize) -> FieldConfig {
    let g = *mapper.map.geometry();
    let mut occupancy = ChannelSpec::new(MAP_CHANNELS[0], Evaporation::None);
    occupancy.signed = true;
    FieldConfig {
        width: g.width,
        height: g.height,
        cell_size_m: g.cell_size_m,
        origin_x_m: g.origin_x_m,
        origin_y_m: g.origin_y_m,
        tick_hz: (1.0 / dt_s) as f32,
        channels: vec![
            occupancy,
            ChannelSpec::new(MAP_CHANNELS[1], Evaporation::None),
        ],
        max_readers,
        ..FieldConfig::default()
    }
}

/// A peer's map frame and estimates, as this mapper reads them.
struct Peer {
    start: Pose2,
    poses: Receiver<PoseMsg>,
    /// The peer's estimate of the last step read, in world coordinates.
    pose: Option<PoseMsg>,
    reader: Option<FieldReader>,
    field: String,
}

/// What a mapper process needs: its robot's [`Mapper`], the world step, and its peers (robot
/// id and start pose: the frame of the peer's map). A scenario builds it (`pheromone_world`'s
/// `Scenario::mapper_setup`).
pub struct MapperSetup {
    pub mapper: Mapper,
    pub dt_s: f64,
    pub peers: Vec<(u32, Pose2)>,
}

/// The mapper process of robot `o.robot`.
pub fn run_mapper(
    node: &Node<Svc>,
    setup: MapperSetup,
    o: &RoleOptions,
) -> Result<MapperSummary, ProcessError> {
    let robot = o.robot;
    let MapperSetup {
        mut mapper,
        dt_s,
        peers: peer_starts,
    } = setup;
    let team = peer_starts.len() + 1;
    let map_field = pheromone_field::wire::map_field(&o.world, robot);
    let mut writer =
        FrameWriter::start(node, &map_field, map_field_config(&mapper, dt_s, team + 4))?;
    let s = RobotServices::new(&o.world, robot);
    let scans = receiver::<ScanMsg>(node, &s.scan)?;
    let rendezvous = receiver::<RendezvousMsg>(node, &s.rendezvous)?;
    let poses = receiver::<PoseMsg>(node, &s.pose)?;
    let mut peers = BTreeMap::new();
    for (id, start) in peer_starts.into_iter().filter(|(id, _)| *id != robot) {
        let ps = RobotServices::new(&o.world, id);
        peers.insert(
            id,
            Peer {
                start,
                poses: receiver::<PoseMsg>(node, &ps.pose)?,
                pose: None,
                reader: None,
                field: pheromone_field::wire::map_field(&o.world, id),
            },
        );
    }
    // The empty map, before the first step: readers attached early see the map's geometry.
    writer.publish(0, 0.0, |out| mapper.map.write_frame(out))?;
    let end = Participant::join(node, &o.world)?;
    let wait = if o.lockstep { STEP_WAIT } else { REALTIME_WAIT };
    let mut summary = summary_of(robot, "mapper");
    let mut merges = Vec::new();
    let mut missing_poses = 0u64;
    let mut previous: Option<RendezvousMsg> = None;
    let mut pose_backlog: Option<PoseMsg> = None;
    let mut rv_backlog: Option<RendezvousMsg> = None;
    let mut attached = false;
    role_loop(
        node,
        &end,
        &scans,
        |m: &ScanMsg| m.step,
        &mut summary,
        |scan| {
            let k = scan.step;
            if !attached {
                // Every mapper created its map before joining, and the world started once all
                // had joined: each peer's map exists. Attached now, each subscription is
                // connected by the peer's next frame, long before the first exchange.
                for p in peers.values_mut() {
                    p.reader = Some(FieldReader::attach_within(node, &p.field, wait)?);
                }
                attached = true;
            }
            // The world counts its steps from 1 (`World::step_count`, what the single-process
            // runner gives the mappers): link step k is the world's step k + 1.
            if let Some(rv) = previous.filter(|_| mapper.exchange_step(k + 1)) {
                exchange(&mut mapper, &mut peers, k, &rv, &mut merges);
            }
            let Some(pose) = recv_step(node, &poses, &mut pose_backlog, k, wait)? else {
                missing_poses += 1;
                eprintln!("mapper r{robot}: step {k}: no estimate of the step; skipped");
                return ack(&end, o, k, robot);
            };
            mapper.on_step(k + 1, &pose, scan);
            previous = recv_step(node, &rendezvous, &mut rv_backlog, k, wait)?;
            writer.publish(k, (k + 1) as f64 * dt_s, |out| mapper.map.write_frame(out))?;
            if let Some(rv) = previous.filter(|_| mapper.exchange_step(k + 2)) {
                hold_peer_frames(node, &writer, &mapper, &mut peers, k, &rv, wait)?;
            }
            ack(&end, o, k, robot)
        },
        // A repeated scan (the world resending a step) changes nothing.
        || Ok(()),
    )?;
    Ok(MapperSummary {
        role: summary,
        map_field,
        scans_rejected: mapper.map.scans_rejected,
        counters: mapper.counters.clone(),
        missing_poses,
        merges,
    })
}

fn ack(end: &Participant, o: &RoleOptions, step: u64, robot: u32) -> Result<(), ProcessError> {
    if o.lockstep {
        end.ack(step, role::MAPPER, robot)?;
    }
    Ok(())
}

/// The message of step `step` on `rx` (older ones are dropped; a newer one is kept in
/// `backlog` for its step). `None` when it did not come within `wait`.
pub(super) fn recv_step<
    T: Copy + std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + HasStep + 'static,
>(
    node: &Node<Svc>,
    rx: &Receiver<T>,
    backlog: &mut Option<T>,
    step: u64,
    wait: Duration,
) -> Result<Option<T>, ProcessError> {
    let deadline = Instant::now() + wait;
    loop {
        if let Some(m) = backlog.take() {
            match m.step().cmp(&step) {
                std::cmp::Ordering::Equal => return Ok(Some(m)),
                std::cmp::Ordering::Greater => {
                    *backlog = Some(m);
                    return Ok(None);
                }
                std::cmp::Ordering::Less => {}
            }
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() || pheromone_field::shm::should_stop(node) {
            return Ok(None);
        }
        *backlog = rx.recv_timeout(left.min(Duration::from_millis(100)))?;
    }
}

/// A message stamped with its world step.
pub(super) trait HasStep {
    fn step(&self) -> u64;
}

impl HasStep for PoseMsg {
    fn step(&self) -> u64 {
        self.step
    }
}

impl HasStep for pheromone_messages::LaserMsg {
    fn step(&self) -> u64 {
        self.step
    }
}

impl HasStep for RendezvousMsg {
    fn step(&self) -> u64 {
        self.step
    }
}

/// After (link) step `k`, before its acknowledgement: for each peer of `rv` this mapper will
/// exchange with at step k + 1, receive the peer's frame k (attaching to its map on first use) and hold
/// it, and read the peer's estimate of step k.
fn hold_peer_frames(
    node: &Node<Svc>,
    writer: &FrameWriter,
    mapper: &Mapper,
    peers: &mut BTreeMap<u32, Peer>,
    k: u64,
    rv: &RendezvousMsg,
    wait: Duration,
) -> Result<(), ProcessError> {
    for obs in rv.peers() {
        if !mapper.due(obs.robot_id, k + 2) {
            continue;
        }
        let Some(p) = peers.get_mut(&obs.robot_id) else {
            continue;
        };
        if p.reader.is_none() {
            p.reader = Some(FieldReader::attach_within(node, &p.field, wait)?);
        }
        let reader = p.reader.as_mut().expect("attached");
        // A reader that attached since our last frame gets it only when we update our
        // connections: do so while waiting, since the peer may be waiting for ours.
        let deadline = Instant::now() + wait;
        let mut held = false;
        while !held && Instant::now() < deadline {
            writer.serve_new_readers()?;
            held = reader
                .wait_until(Duration::from_millis(20), |f| f.header.sequence >= k)?
                .is_some();
            if pheromone_field::shm::should_stop(node) {
                break;
            }
        }
        if !held {
            return Err(AttachError::NoField {
                field: p.field.clone(),
                service: format!("frame {k} of map '{}' did not come", p.field),
            }
            .into());
        }
        p.pose = recv_latest_step(&p.poses, k)?.or(p.pose);
    }
    Ok(())
}

/// The message of step `step` among those queued on `rx` (a peer's estimate of a step is sent
/// before its frame of the step, and its next one only after this mapper's acknowledgement).
fn recv_latest_step<
    T: Copy + std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + HasStep + 'static,
>(
    rx: &Receiver<T>,
    step: u64,
) -> Result<Option<T>, ProcessError> {
    let mut found = None;
    while let Some(m) = rx.try_recv()? {
        if m.step() == step {
            found = Some(m);
        }
    }
    Ok(found)
}

/// Algorithm 1 at (link) step `k` on the rendezvous of step k − 1 (`rv`): the same order,
/// loss refusal and counters as `MappingTeam::exchange`, from the peers' held frames.
fn exchange(
    mapper: &mut Mapper,
    peers: &mut BTreeMap<u32, Peer>,
    k: u64,
    rv: &RendezvousMsg,
    merges: &mut Vec<MergeEvent>,
) {
    for obs in rv.peers() {
        let Some(p) = peers.get(&obs.robot_id) else {
            continue;
        };
        if !mapper.due(obs.robot_id, k + 1) {
            continue;
        }
        let peer_pose = p.pose.filter(|m| m.step + 1 == k);
        let peer_lost = peer_pose.is_none_or(|m| mapper.lost_estimate(&m));
        if mapper.lost() || peer_lost {
            mapper.refuse_lost();
            continue;
        }
        let pose = peer_pose.expect("not lost");
        let src_pose = pose_in_frame(p.start, [pose.x_m, pose.y_m, pose.theta_rad]);
        let Some(sample) = p.reader.as_ref().and_then(|r| r.sample()) else {
            mapper.count_rejected("no_frame");
            continue;
        };
        let header = sample.user_header();
        if header.sequence + 1 != k {
            mapper.count_rejected("stale_frame");
            eprintln!(
                "mapper r{}: step {k}: map of r{} is frame {}, not {}; not merged",
                mapper.id,
                obs.robot_id,
                header.sequence,
                k - 1
            );
            continue;
        }
        // Zero-copy: the view borrows the peer's frame in shared memory; a frame that
        // disagrees with its header is refused and counted by `accept_frame`.
        match mapper.accept_frame(k + 1, header, sample.payload(), src_pose, obs) {
            Ok(t) => merges.push(MergeEvent {
                step: k + 1,
                dst: mapper.id,
                src: obs.robot_id,
                alignment_error_m: alignment_error_m(&t, &true_transform(p.start, mapper.start())),
            }),
            // Counted by `accept_frame`.
            Err(e) => eprintln!(
                "mapper r{}: map of r{}: {e}; not merged",
                mapper.id, obs.robot_id
            ),
        }
    }
}
