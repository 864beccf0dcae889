//! A mirror's state on its host (`pheromone/F/mirror`, a one-value blackboard (`board`):
//! [`MirrorState`]): written by the mirror each round, read by `pheromone list`, `probe` and
//! `export` without the mirror sending anything, so a mirror whose origin went silent is still
//! seen, and seen as stale.

use iceoryx2::prelude::*;

use super::board::{read_board, Board};
use super::{now_ns, AttachError, FieldServices, StartError, Svc};
use crate::messages::MirrorState;

/// The mirror's side: creates the blackboard and updates its entry.
pub struct MirrorStateWriter {
    board: Board<MirrorState>,
}

impl MirrorStateWriter {
    /// Creates field `field`'s mirror blackboard, stale until [`Self::set`] says otherwise.
    pub fn create(node: &Node<Svc>, field: &str) -> Result<Self, StartError> {
        let names = FieldServices::new(field)?;
        let initial = MirrorState {
            stale: 1,
            ..MirrorState::default()
        };
        Ok(Self {
            board: Board::create(node, &names.mirror, initial)?,
        })
    }

    /// Replaces the mirror's published state.
    pub fn set(&self, state: MirrorState) {
        self.board.set(state);
    }
}

/// What a reader knows of a mirror, now.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MirrorInfo {
    /// No live inputs from the origin: the frames stay at `last_sequence`.
    pub stale: bool,
    /// Seconds since the newest inputs came from the origin (`None` before any).
    pub inputs_age_s: Option<f64>,
    /// Seconds since the mirror went stale (`None` while live).
    pub stale_for_s: Option<f64>,
    /// Times the mirror went stale after following its origin.
    pub stale_periods: u64,
    /// Sequence of the newest frame the mirror published.
    pub last_sequence: u64,
}

impl MirrorInfo {
    fn of(s: MirrorState, now_ns: u64) -> Self {
        let age = |t: u64| (t != 0).then(|| now_ns.saturating_sub(t) as f64 * 1e-9);
        Self {
            stale: s.stale != 0,
            inputs_age_s: age(s.last_inputs_ns),
            stale_for_s: if s.stale != 0 {
                age(s.stale_since_ns)
            } else {
                None
            },
            stale_periods: s.stale_periods,
            last_sequence: s.last_sequence,
        }
    }

    /// "mirror: live", "mirror: no inputs from its origin for 12.3 s" (stale) or "mirror: no
    /// inputs from its origin yet" (stale).
    pub fn describe(&self) -> String {
        match (self.stale, self.inputs_age_s) {
            (false, _) => "mirror: live".to_string(),
            (true, Some(age)) => format!("mirror: no inputs from its origin for {age:.1} s"),
            (true, None) => "mirror: no inputs from its origin yet".to_string(),
        }
    }
}

/// Field `field`'s mirror state, or `None` when the field is not a mirror (no blackboard).
pub fn mirror_info(node: &Node<Svc>, field: &str) -> Result<Option<MirrorInfo>, AttachError> {
    let names = FieldServices::new(field)?;
    Ok(read_board::<MirrorState>(node, &names.mirror)?.map(|s| MirrorInfo::of(s, now_ns())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reader_sees_what_the_mirror_wrote_and_a_plain_field_has_no_state() {
        let node = super::super::create_node(&format!("mstate-{}", std::process::id())).unwrap();
        let field = format!("mstate{}", std::process::id());
        assert_eq!(mirror_info(&node, &field).unwrap(), None);
        let w = MirrorStateWriter::create(&node, &field).unwrap();
        let first = mirror_info(&node, &field).unwrap().unwrap();
        assert!(first.stale && first.inputs_age_s.is_none(), "{first:?}");
        assert_eq!(first.describe(), "mirror: no inputs from its origin yet");
        let now = now_ns();
        w.set(MirrorState {
            stale: 0,
            last_inputs_ns: now,
            last_sequence: 42,
            ..MirrorState::default()
        });
        let live = mirror_info(&node, &field).unwrap().unwrap();
        assert!(!live.stale && live.stale_for_s.is_none(), "{live:?}");
        assert_eq!(live.last_sequence, 42);
        assert_eq!(live.describe(), "mirror: live");
        w.set(MirrorState {
            stale: 1,
            last_inputs_ns: now - 3_000_000_000,
            stale_since_ns: now - 2_000_000_000,
            stale_periods: 1,
            last_sequence: 42,
            ..MirrorState::default()
        });
        let stale = mirror_info(&node, &field).unwrap().unwrap();
        assert!(stale.stale, "{stale:?}");
        assert!(stale.inputs_age_s.unwrap() >= 3.0, "{stale:?}");
        assert!(stale.stale_for_s.unwrap() >= 2.0, "{stale:?}");
        assert!(
            stale
                .describe()
                .starts_with("mirror: no inputs from its origin for 3."),
            "{}",
            stale.describe()
        );
        drop(w);
        assert_eq!(mirror_info(&node, &field).unwrap(), None);
    }
}
