//! What the observer of a run as processes hands to `--record` ([`SimMcap`]): the same poses,
//! deposits and frames, in the same order, as the single-process runner hands it, so both
//! modes write the same file for a seed.
//!
//! The poses are the world's truths and the localizers' poses the observer receives. A
//! localizer whose robot has no depositor does not acknowledge before the tick, so its pose of
//! step k may come after the frame of step k (before the frame of step k + 1, when the robot
//! has a follower that waits for it): each step is held until every robot's truth and pose of
//! it are in ([`HOLD_STEPS`] steps at most), then its poses, deposits and frames go out
//! together, in the single-process runner's order. The
//! deposits the field applied are on no service it reads: it predicts them, as the field makes
//! them, from what it has — the scenario's scripted deposits due by the step's time (the world
//! sends them) and the deposits its copies of the robots' depositors make — checked with the
//! field's own validation (`pheromone_field::deposit::prepare`) and put in the field's canonical order
//! (the world's first, then by robot id). Each step's count is compared with the
//! `deposits_this_tick` of the field's frame; a step where they differ is counted
//! ([`McapTotals::deposit_mismatches`]) and said once on stderr.

use std::collections::{BTreeMap, VecDeque};

use pheromone_field::deposit::prepare;
use pheromone_field::{DepositMsg, FieldConfig, GridGeometry};
use pheromone_messages::PoseMsg;
use pheromone_ros2::record::RecordError;
use pheromone_world::scenario::Scenario;

use crate::recording::Recording;
use crate::ros_record::{McapTotals, PoseRow, SimMcap};

/// The most steps held back waiting for a late pose; the oldest then goes out without it.
pub const HOLD_STEPS: usize = 64;

/// A step the field has ticked, waiting for its poses.
struct Tick {
    step: u64,
    t_s: f64,
    deposits: Vec<DepositMsg>,
    /// The recording's snapshots once this step's frame was recorded.
    snapshots: usize,
}

/// One robot's messages of the steps not recorded yet.
#[derive(Default)]
struct Pending {
    id: u32,
    /// Step → (simulated time, true pose).
    truths: BTreeMap<u64, (f64, [f64; 3])>,
    poses: BTreeMap<u64, PoseMsg>,
    /// Step → the deposit the robot's depositor made.
    deposits: BTreeMap<u64, DepositMsg>,
}

/// The observer's side of `--record`.
pub struct McapFeed {
    out: SimMcap,
    scripted: VecDeque<(f64, DepositMsg)>,
    field: FieldConfig,
    geometry: GridGeometry,
    /// In the world's order of robots, as the single-process runner writes them.
    robots: Vec<Pending>,
    held: VecDeque<Tick>,
}

impl McapFeed {
    /// `scripted`: the scenario's scripted deposits (`Scenario::scripted`), by time.
    pub fn new(out: SimMcap, scenario: &Scenario, scripted: Vec<(f64, DepositMsg)>) -> Self {
        Self {
            out,
            scripted: scripted.into(),
            field: scenario.field.clone(),
            geometry: scenario.field.geometry(),
            robots: scenario
                .world
                .robots
                .iter()
                .map(|r| Pending {
                    id: r.id,
                    ..Pending::default()
                })
                .collect(),
            held: VecDeque::new(),
        }
    }

    fn robot(&mut self, id: u32) -> Option<&mut Pending> {
        self.robots.iter_mut().find(|r| r.id == id)
    }

    /// Robot `id`'s true pose of `step`, at simulated time `t_s`.
    pub fn truth(&mut self, id: u32, step: u64, t_s: f64, pose: [f64; 3]) {
        if let Some(r) = self.robot(id) {
            r.truths.insert(step, (t_s, pose));
        }
    }

    /// Robot `id`'s estimate, and the deposit the copy of its depositor made of it.
    pub fn pose(&mut self, id: u32, p: &PoseMsg, deposit: Option<DepositMsg>) {
        if let Some(r) = self.robot(id) {
            r.poses.insert(p.step, *p);
            if let Some(d) = deposit {
                r.deposits.insert(p.step, d);
            }
        }
    }

    /// The field's frame of `step` (field time `frame_t_s`) says it applied `applied` deposits,
    /// and `rec` has recorded it: the step is held until its poses are in, then written with
    /// its deposits and frames.
    pub fn step(&mut self, step: u64, frame_t_s: f64, applied: u32, rec: &Recording) {
        let t_s = self
            .robots
            .iter()
            .find_map(|r| r.truths.get(&step).map(|t| t.0))
            .unwrap_or(frame_t_s);
        let deposits = self.deposits_of(step, t_s, applied);
        self.held.push_back(Tick {
            step,
            t_s,
            deposits,
            snapshots: rec.snapshots.len(),
        });
        while let Some(t) = self.held.front() {
            let complete = self
                .robots
                .iter()
                .all(|r| r.truths.contains_key(&t.step) && r.poses.contains_key(&t.step));
            if !complete && self.held.len() <= HOLD_STEPS {
                break;
            }
            let t = self.held.pop_front().expect("checked");
            self.release(t, rec);
        }
    }

    /// Writes a held step: the poses up to it, its deposits, the frames recorded with it.
    fn release(&mut self, t: Tick, rec: &Recording) {
        self.rows_through(Some(t.step));
        self.out.deposits(t.t_s, &t.deposits);
        self.out.frames_up_to(rec, t.snapshots);
    }

    /// The deposits the field applied at `step` (simulated time `t_s`), as predicted; `applied`
    /// is the field's own count.
    fn deposits_of(&mut self, step: u64, t_s: f64, applied: u32) -> Vec<DepositMsg> {
        let mut list = Vec::new();
        while self
            .scripted
            .front()
            .is_some_and(|(ts, _)| *ts <= t_s + 1e-9)
        {
            list.push(self.scripted.pop_front().expect("checked").1);
        }
        let mut mine: Vec<DepositMsg> = self
            .robots
            .iter_mut()
            .filter_map(|r| r.deposits.remove(&step))
            .collect();
        mine.sort_by_key(|d| d.robot_id);
        list.extend(mine);
        // The field's canonical order: the world's (id u32::MAX) first, then by robot id.
        list.sort_by_key(|d| d.robot_id.wrapping_add(1));
        let limits = &self.field.limits;
        list.retain(|d| prepare(d, &self.geometry, &self.field.channels, limits).is_ok());
        if list.len() != applied as usize {
            if self.out.deposit_mismatches == 0 {
                eprintln!(
                    "sim --record: step {step}: the field applied {applied} deposit(s), the \
                     observer expected {}; the recorded deposits may differ from the field's",
                    list.len()
                );
            }
            self.out.deposit_mismatches += 1;
        }
        list
    }

    /// Sends the rows of every step up to `last` (all when None) that have a true pose.
    fn rows_through(&mut self, last: Option<u64>) {
        let mut steps: Vec<u64> = Vec::new();
        for r in &self.robots {
            steps.extend(
                r.truths
                    .keys()
                    .take_while(|k| last.is_none_or(|l| **k <= l)),
            );
        }
        steps.sort_unstable();
        steps.dedup();
        let mut rows = Vec::new();
        for k in steps {
            for r in &mut self.robots {
                if let Some((t_s, truth)) = r.truths.remove(&k) {
                    rows.push(PoseRow {
                        robot: r.id,
                        t_s,
                        truth,
                        estimate: r.poses.remove(&k),
                    });
                }
            }
        }
        for r in &mut self.robots {
            // Estimates of steps already recorded (or without a truth) are not kept.
            match last {
                Some(l) => r.poses.retain(|k, _| *k > l),
                None => r.poses.clear(),
            }
        }
        self.out.poses(rows);
    }

    /// The steps still held, the remaining rows and frames, then the file's end.
    pub fn finish(mut self, rec: &Recording) -> Result<McapTotals, RecordError> {
        while let Some(t) = self.held.pop_front() {
            self.release(t, rec);
        }
        self.rows_through(None);
        self.out.frames(rec);
        self.out.finish()
    }
}
