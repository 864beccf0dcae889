//! Watches a multi-process run from outside, without taking part in the lockstep: subscribes to
//! every robot's truth, pose, command and status, reads the field's frames (no copy, except for
//! the snapshots it keeps), and builds the same [`Recording`] a single-process run does.
//!
//! It must attach before the world starts (it creates the robots' services if they are not there
//! yet, with buffers large enough for the steps between two of its polls). Probes and snapshots
//! are taken from the first frame it sees at or after the requested time, and carry that frame's
//! time.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use field::link::{LinkOptions, Receiver};
use field::shm::{FieldReader, ShmError, Svc};
use iceoryx2::node::Node;

use crate::messages::{CmdMsg, FollowerState, FollowerStatusMsg, PoseMsg, TruthMsg};
use crate::process::RobotServices;
use crate::record::{ProbeReading, Recording, RobotSample};
use crate::scenario::Scenario;
use crate::simulation::{sigma_max_m, snapshot};

/// Messages buffered per robot service between two polls.
const BUFFER: usize = 4096;

struct RobotLinks {
    id: u32,
    truth: Receiver<TruthMsg>,
    pose: Receiver<PoseMsg>,
    cmd: Receiver<CmdMsg>,
    status: Receiver<FollowerStatusMsg>,
    /// Rows by step, filled as the messages of that step arrive.
    rows: BTreeMap<u64, RobotSample>,
}

/// The observer of one run.
pub struct Observer {
    robots: Vec<RobotLinks>,
    field: Option<FieldReader>,
    field_name: String,
    scenario: Scenario,
    probes: VecDeque<(f64, usize)>,
    snapshots: VecDeque<f64>,
    rec: Recording,
    last_frame_time_s: f64,
}

impl Observer {
    /// Attaches to the robots' services of world `world`; the field is attached when it appears.
    pub fn new(
        node: &Node<Svc>,
        scenario: &Scenario,
        world: &str,
        field: &str,
    ) -> Result<Self, ShmError> {
        let options = LinkOptions {
            buffer: BUFFER,
            ..LinkOptions::default()
        };
        let mut robots = Vec::new();
        for r in &scenario.world.robots {
            let s = RobotServices::new(world, r.id);
            let wake = |x: &str| format!("{x}-ready");
            robots.push(RobotLinks {
                id: r.id,
                truth: Receiver::create(node, &s.truth, &wake(&s.truth), options)?,
                pose: Receiver::create(node, &s.pose, &wake(&s.pose), options)?,
                cmd: Receiver::create(node, &s.cmd, &wake(&s.cmd), options)?,
                status: Receiver::create(node, &s.status, &wake(&s.status), options)?,
                rows: BTreeMap::new(),
            });
        }
        let probes = scenario.probe_schedule();
        let mut snapshots = scenario.snapshots_s.clone();
        snapshots.sort_by(f64::total_cmp);
        Ok(Self {
            robots,
            field: None,
            field_name: field.to_string(),
            scenario: scenario.clone(),
            probes: probes.into(),
            snapshots: snapshots.into(),
            rec: Recording::default(),
            last_frame_time_s: -1.0,
        })
    }

    /// Drains every queue and looks at the newest frame; waits up to `timeout` for a frame.
    pub fn poll(&mut self, node: &Node<Svc>, timeout: Duration) -> Result<(), ShmError> {
        if self.field.is_none() {
            self.field = FieldReader::attach(node, &self.field_name).ok();
        }
        match self.field.as_mut() {
            Some(reader) => {
                reader.wait_frame(timeout)?;
            }
            None => {
                let _ = node.wait(timeout);
            }
        }
        self.drain()?;
        self.look_at_frame();
        Ok(())
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
            }
            while let Some(p) = r.pose.try_recv()? {
                let row = r.rows.entry(p.step).or_insert_with(|| empty_row(f64::NAN));
                row.est_pose = Some([p.x_m, p.y_m, p.theta_rad]);
                row.est_sigma_m = Some(sigma_max_m(&p));
            }
            while let Some(c) = r.cmd.try_recv()? {
                let row = r.rows.entry(c.step).or_insert_with(|| empty_row(f64::NAN));
                row.v_mps = c.v_mps;
                row.omega_radps = c.omega_radps;
            }
            while let Some(s) = r.status.try_recv()? {
                let row = r.rows.entry(s.step).or_insert_with(|| empty_row(f64::NAN));
                row.state = FollowerState::from_code(s.state);
                row.sensed_level = Some(s.sensed_level);
            }
        }
        Ok(())
    }

    fn look_at_frame(&mut self) {
        let Some(frame) = self.field.as_ref().and_then(|r| r.frame()) else {
            return;
        };
        let t = frame.header.sim_time_s;
        if t <= self.last_frame_time_s {
            return;
        }
        self.last_frame_time_s = t;
        while self.probes.front().is_some_and(|(pt, _)| *pt <= t + 1e-9) {
            let (_, i) = self.probes.pop_front().expect("checked");
            let p = &self.scenario.probes[i];
            self.rec.probes.push(ProbeReading {
                t_s: t,
                x: p.x_m,
                y: p.y_m,
                channel: p.channel,
                value: frame.view.value(p.channel as usize, p.x_m, p.y_m),
            });
        }
        let half_dt = 0.5 * self.scenario.world.dt_secs;
        let mut due = false;
        while self.snapshots.front().is_some_and(|s| *s <= t + half_dt) {
            self.snapshots.pop_front();
            due = true;
        }
        if due || t + half_dt >= self.scenario.duration_s {
            let cells = frame.view.cells;
            if self.rec.snapshots.last().is_none_or(|s| s.t_s < t) {
                self.rec
                    .snapshots
                    .push(snapshot(&self.scenario.field, t, cells));
            }
        }
    }

    /// The recording; the last frame seen is pictured if the end was not.
    pub fn finish(mut self, node: &Node<Svc>) -> Recording {
        let _ = self.drain();
        let _ = node;
        for r in &mut self.robots {
            let rows: Vec<RobotSample> = std::mem::take(&mut r.rows)
                .into_values()
                .filter(|row| row.t_s.is_finite())
                .collect();
            self.rec.robots.insert(r.id, rows);
        }
        if self.rec.snapshots.is_empty()
            || self.last_frame_time_s > self.rec.snapshots.last().map_or(-1.0, |s| s.t_s)
        {
            if let Some(frame) = self.field.as_ref().and_then(|r| r.frame()) {
                self.rec.snapshots.push(snapshot(
                    &self.scenario.field,
                    frame.header.sim_time_s,
                    frame.view.cells,
                ));
            }
        }
        self.rec
    }

    /// Field time of the newest frame seen.
    pub fn sim_time_s(&self) -> Option<f64> {
        (self.last_frame_time_s >= 0.0).then_some(self.last_frame_time_s)
    }

    /// Sets the walls to draw.
    pub fn set_walls(&mut self, walls: Vec<([f64; 2], [f64; 2])>) {
        self.rec.walls = walls;
    }
}

fn empty_row(t_s: f64) -> RobotSample {
    RobotSample {
        t_s,
        true_pose: [f64::NAN; 3],
        est_pose: None,
        est_sigma_m: None,
        v_mps: 0.0,
        omega_radps: 0.0,
        state: None,
        sensed_level: None,
    }
}
