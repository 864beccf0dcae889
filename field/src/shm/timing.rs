//! The field's tick timing on its host (`pheromone/F/timing`, a one-value blackboard:
//! [`FieldTiming`]), updated after every frame, read by `pheromone list` without the field
//! sending anything.

use iceoryx2::prelude::*;

use super::board::{read_board, Board};
use super::{AttachError, FieldServices, StartError, Svc};
use crate::messages::FieldTiming;

/// The field's side.
pub struct TimingWriter {
    board: Board<FieldTiming>,
}

impl TimingWriter {
    /// Creates field `field`'s timing blackboard, with no tick yet (`max_lateness_ns` =
    /// `u64::MAX`: no deadline so far).
    pub fn create(node: &Node<Svc>, field: &str) -> Result<Self, StartError> {
        let names = FieldServices::new(field)?;
        let initial = FieldTiming {
            max_lateness_ns: u64::MAX,
            ..FieldTiming::default()
        };
        Ok(Self {
            board: Board::create(node, &names.timing, initial)?,
        })
    }

    /// Replaces the published totals.
    pub fn set(&self, timing: FieldTiming) {
        self.board.set(timing);
    }
}

/// What a reader shows of a field's timing.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TimingInfo {
    /// Frames published by the field's run so far.
    pub ticks: u64,
    /// Wall-time ticks that started more than the slack after their deadline.
    pub missed_deadlines: u64,
    /// The latest a tick started after its deadline (ms); `None` while no tick had a
    /// wall-time deadline (lockstep).
    pub max_tick_lateness_ms: Option<f64>,
    /// The longest time between two published frames (ms).
    pub longest_tick_gap_ms: f64,
    /// The longest tick compute (ms).
    pub max_tick_compute_ms: f64,
    /// A tick later than this after its deadline is missed (ms).
    pub deadline_slack_ms: f64,
}

impl From<FieldTiming> for TimingInfo {
    fn from(t: FieldTiming) -> Self {
        let ms = |ns: u64| ns as f64 / 1e6;
        Self {
            ticks: t.ticks,
            missed_deadlines: t.missed_deadlines,
            max_tick_lateness_ms: (t.max_lateness_ns != u64::MAX).then(|| ms(t.max_lateness_ns)),
            longest_tick_gap_ms: ms(t.longest_gap_ns),
            max_tick_compute_ms: ms(t.max_compute_ns),
            deadline_slack_ms: ms(t.slack_ns),
        }
    }
}

/// Field `field`'s timing, or `None` when its process keeps none (an older build, a mirror).
pub fn field_timing(node: &Node<Svc>, field: &str) -> Result<Option<TimingInfo>, AttachError> {
    let names = FieldServices::new(field)?;
    Ok(read_board::<FieldTiming>(node, &names.timing)?.map(TimingInfo::from))
}
