//! Watches a multi-process run: subscribes to every robot's truth, pose, command and status,
//! reads the field's frames (no copy, except for the snapshots it keeps), and builds the same
//! [`Recording`] a single-process run does.
//!
//! It takes part in the lockstep (`pheromone_field::process::lockstep`): it joins the run, and acknowledges each
//! frame once it has recorded it, so it sees every frame, and takes probes and snapshots from
//! the same frames a single-process run does ([`FrameSchedule`]).
//!
//! What each depositor sent is not on any service the observer reads: it runs a copy of each
//! robot's [`Depositor`] (the same library type, deterministic) on the poses it receives, which
//! are the depositor process's input, and records the peak of each deposit that copy makes.
//!
//! With `--record` it also hands what it sees to a [`McapFeed`] (the MCAP file of the run),
//! after acknowledging each frame; the feed's writer thread serializes and writes.
//!
//! When the scenario maps (seed 004), it also receives each robot's scan and rendezvous
//! measurement from the world and, at the end, runs the run's [`MappingTeam`] on them and on the
//! poses, step by step, as the single-process runner does.

use std::collections::BTreeMap;
use std::time::Duration;

use iceoryx2::node::Node;
use pheromone_field::process::link::Receiver;
use pheromone_field::process::lockstep::{self, Participant};
use pheromone_field::shm::{AttachError, FieldReader, ShmError, Svc};
use pheromone_field::wire::{ready_service as wake, ROBOT_LINK};

use crate::recording::{deposit_peak, Recording, RobotSample};
use crate::ros_feed::McapFeed;
use crate::ros_record::McapTotals;
use crate::single::{sigma_max_m, FrameSchedule};
use pheromone_messages::{
    CmdMsg, FollowerState, FollowerStatusMsg, PoseMsg, RendezvousMsg, ScanMsg, TruthMsg,
};
use pheromone_roles::depositor::Depositor;
use pheromone_roles::RobotServices;
use pheromone_ros2::record::RecordError;
use pheromone_world::scenario::Scenario;
use pheromone_world::team::MappingTeam;

struct RobotLinks {
    id: u32,
    truth: Receiver<TruthMsg>,
    pose: Receiver<PoseMsg>,
    cmd: Receiver<CmdMsg>,
    status: Receiver<FollowerStatusMsg>,
    /// A copy of the robot's depositor, fed the same poses, for the deposits' peaks.
    depositor: Option<Depositor>,
    /// Rows by step, filled as the messages of that step arrive.
    rows: BTreeMap<u64, RobotSample>,
    /// Seed 004's inputs by step, when the scenario maps: the scan and rendezvous links, and
    /// per step the pose, the scan and the rendezvous measurement.
    mapping: Option<(Receiver<ScanMsg>, Receiver<RendezvousMsg>)>,
    poses: BTreeMap<u64, PoseMsg>,
    sensed: BTreeMap<u64, (Option<ScanMsg>, Option<RendezvousMsg>)>,
}

/// The observer of one run.
pub struct Observer {
    robots: Vec<RobotLinks>,
    field: FieldReader,
    lockstep: Participant,
    frames: FrameSchedule,
    /// Seed 004's mappers, run at the end on what the world and the localizers sent.
    team: Option<MappingTeam>,
    rec: Recording,
    /// Sequence of the newest frame recorded.
    last_sequence: Option<u64>,
    last_frame_time_s: f64,
    /// `--record`: the run's MCAP file.
    mcap: Option<McapFeed>,
}

impl Observer {
    /// Attaches to the robots' services of world `world` and to field `field` (waiting up to
    /// `timeout` for it), then joins the run.
    pub fn new(
        node: &Node<Svc>,
        scenario: &Scenario,
        world: &str,
        field: &str,
        timeout: Duration,
    ) -> Result<Self, AttachError> {
        // The robots' links as the roles create them: in lockstep the observer is at most a
        // step behind, far less than a link's buffer.
        let options = ROBOT_LINK;
        let mut robots = Vec::new();
        for r in &scenario.world.robots {
            let s = RobotServices::new(world, r.id);
            robots.push(RobotLinks {
                id: r.id,
                truth: Receiver::create(node, &s.truth, &wake(&s.truth), options)?,
                pose: Receiver::create(node, &s.pose, &wake(&s.pose), options)?,
                cmd: Receiver::create(node, &s.cmd, &wake(&s.cmd), options)?,
                status: Receiver::create(node, &s.status, &wake(&s.status), options)?,
                // Settings a depositor refuses fail the run when its process starts (and the
                // single-process run before it starts): no copy is needed then.
                depositor: scenario
                    .roles(r.id)
                    .and_then(|x| x.depositor.clone())
                    .and_then(|c| Depositor::new(c).ok()),
                rows: BTreeMap::new(),
                mapping: match scenario.mapping() {
                    Some(_) => Some((
                        Receiver::create(node, &s.scan, &wake(&s.scan), options)?,
                        Receiver::create(node, &s.rendezvous, &wake(&s.rendezvous), options)?,
                    )),
                    None => None,
                },
                poses: BTreeMap::new(),
                sensed: BTreeMap::new(),
            });
        }
        // `[mapping]` was validated with the scenario; a team that still cannot be built leaves
        // the run without its mapping metrics, and says so.
        let team = MappingTeam::new(scenario).unwrap_or_else(|e| {
            eprintln!("observer: mapping: {e}");
            None
        });
        let field = FieldReader::attach_within(node, field, timeout)?;
        let lockstep = Participant::join(node, world)?;
        Ok(Self {
            robots,
            field,
            lockstep,
            frames: FrameSchedule::new(scenario),
            team,
            rec: Recording::default(),
            last_sequence: None,
            last_frame_time_s: -1.0,
            mcap: None,
        })
    }

    /// Waits up to `timeout` for a frame, records it and acknowledges its step; drains every
    /// robot queue.
    pub fn poll(&mut self, timeout: Duration) -> Result<(), ShmError> {
        self.field.wait_frame(timeout)?;
        self.drain()?;
        self.look_at_frame()
    }

    fn drain(&mut self) -> Result<(), ShmError> {
        for r in &mut self.robots {
            while let Some(t) = r.truth.try_recv()? {
                let row = r
                    .rows
                    .entry(t.step)
                    .or_insert_with(|| empty_row(t.sim_time_s));
                row.t_s = t.sim_time_s;
                row.true_pose = [t.x_m, t.y_m, t.theta_rad];
                if let Some(f) = self.mcap.as_mut() {
                    f.truth(r.id, t.step, t.sim_time_s, row.true_pose);
                }
            }
            while let Some(p) = r.pose.try_recv()? {
                if r.mapping.is_some() {
                    r.poses.insert(p.step, p);
                }
                let row = r.rows.entry(p.step).or_insert_with(|| empty_row(f64::NAN));
                row.est_pose = Some([p.x_m, p.y_m, p.theta_rad]);
                row.est_sigma_m = Some(sigma_max_m(&p));
                let deposit = r
                    .depositor
                    .as_mut()
                    .and_then(|d| d.process(&p).ok().flatten());
                if r.depositor.is_some() {
                    row.deposit_peak = deposit.as_ref().map(deposit_peak);
                }
                if let Some(f) = self.mcap.as_mut() {
                    f.pose(r.id, &p, deposit);
                }
            }
            if let Some((scans, rvs)) = &r.mapping {
                while let Some(m) = scans.try_recv()? {
                    r.sensed.entry(m.step).or_default().0 = Some(m);
                }
                while let Some(m) = rvs.try_recv()? {
                    r.sensed.entry(m.step).or_default().1 = Some(m);
                }
            }
            while let Some(c) = r.cmd.try_recv()? {
                let row = r.rows.entry(c.step).or_insert_with(|| empty_row(f64::NAN));
                row.v_m_per_s = c.v_m_per_s;
                row.omega_rad_per_s = c.omega_rad_per_s;
            }
            while let Some(s) = r.status.try_recv()? {
                let row = r.rows.entry(s.step).or_insert_with(|| empty_row(f64::NAN));
                row.state = FollowerState::from_code(s.state);
                row.sensed_level = Some(s.sensed_level);
            }
        }
        Ok(())
    }

    fn look_at_frame(&mut self) -> Result<(), ShmError> {
        let Some(frame) = self.field.frame() else {
            return Ok(());
        };
        let sequence = frame.header.sequence;
        if self.last_sequence.is_some_and(|s| sequence <= s) {
            return Ok(());
        }
        self.last_sequence = Some(sequence);
        self.last_frame_time_s = frame.header.sim_time_s;
        // Frame k + 1 is the field's tick for step k; the first frame (0) is no step's, and a
        // single-process run never looks at it.
        let Some(step) = sequence.checked_sub(1) else {
            return Ok(());
        };
        self.frames
            .on_frame(&mut self.rec, frame.header.sim_time_s, &frame.view);
        let (t_s, applied) = (frame.header.sim_time_s, frame.header.deposits_this_tick);
        self.lockstep.ack(step, lockstep::role::OBSERVER, 0)?;
        if let Some(f) = self.mcap.as_mut() {
            f.step(step, t_s, applied, &self.rec);
        }
        Ok(())
    }

    /// `--record`: hands what it sees from now on to `feed`.
    pub fn record_to(&mut self, feed: McapFeed) {
        self.mcap = Some(feed);
    }

    /// The recording; the last frame seen is pictured if it was not.
    pub fn finish(self) -> Recording {
        self.finish_with_mcap().0
    }

    /// The recording, and with `--record` the MCAP file finished (its last frame included).
    pub fn finish_with_mcap(mut self) -> (Recording, Option<Result<McapTotals, RecordError>>) {
        if let Err(e) = self.drain() {
            eprintln!("observer: the last robot messages could not be read: {e}");
        }
        for r in &mut self.robots {
            let rows: Vec<RobotSample> = std::mem::take(&mut r.rows)
                .into_values()
                .filter(|row| row.t_s.is_finite())
                .collect();
            self.rec.robots.insert(r.id, rows);
        }
        if let Some(frame) = self.field.frame() {
            self.frames
                .finish(&mut self.rec, frame.header.sim_time_s, frame.view.cells);
        }
        if let Some(mut team) = self.team.take() {
            // Steps are numbered from 0 on the links; the single-process runner counts the
            // world's steps from 1.
            let steps: Vec<u64> = self
                .robots
                .first()
                .map(|r| r.sensed.keys().copied().collect())
                .unwrap_or_default();
            for k in steps {
                let mut poses = Vec::new();
                let mut sensed = Vec::new();
                for r in &self.robots {
                    let (Some(p), Some((Some(scan), Some(rv)))) =
                        (r.poses.get(&k), r.sensed.get(&k))
                    else {
                        break;
                    };
                    poses.push(*p);
                    sensed.push((*scan, *rv));
                }
                if poses.len() == self.robots.len() {
                    team.step(k + 1, &poses, &sensed);
                } else {
                    eprintln!("observer: step {k}: a robot's pose, scan or rendezvous is missing; mapping stops there");
                    break;
                }
            }
            self.rec.mapping = Some(team.finish());
        }
        let mcap = self.mcap.take().map(|f| f.finish(&self.rec));
        (self.rec, mcap)
    }

    /// The header of the newest frame seen: the field's counters up to it.
    pub fn last_header(&self) -> Option<pheromone_field::FrameHeader> {
        self.field.frame().map(|f| *f.header)
    }

    /// Field time of the newest frame seen.
    pub fn sim_time_s(&self) -> Option<f64> {
        (self.last_frame_time_s >= 0.0).then_some(self.last_frame_time_s)
    }

    /// Sets the walls to draw and the channel they are marked on (if any).
    pub fn set_walls(&mut self, walls: Vec<([f64; 2], [f64; 2])>, wall_channel: Option<usize>) {
        self.rec.walls = walls;
        self.rec.wall_channel = wall_channel;
    }
}

fn empty_row(t_s: f64) -> RobotSample {
    RobotSample {
        t_s,
        true_pose: [f64::NAN; 3],
        est_pose: None,
        est_sigma_m: None,
        v_m_per_s: 0.0,
        omega_rad_per_s: 0.0,
        state: None,
        sensed_level: None,
        deposit_peak: None,
    }
}
