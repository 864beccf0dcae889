//! The loops of `pheromone bridge` and `pheromone field --mirror`: a started [`Bridge`] or
//! [`Mirror`] stepped until Ctrl-C/SIGTERM or its duration, with the shared housekeeping
//! (`pheromone_field::process::run::Housekeeping`: dead nodes cleaned up every second, a status line every 5 s).

use std::sync::mpsc;
use std::time::Duration;

use iceoryx2::node::Node;
use pheromone_field::process::run::Housekeeping;
use pheromone_field::shm::Svc;

use super::{Bridge, BridgeError, BridgeStats, Mirror, MirrorStats, Security};

/// How long one step waits for Zenoh messages.
const STEP: Duration = Duration::from_millis(20);
/// The period of the status line on stderr.
const STATUS_EVERY: Duration = Duration::from_secs(5);

impl Bridge {
    /// Steps the bridge until the node is asked to stop (Ctrl-C, SIGTERM) or `duration` has
    /// passed, then closes it; what it did.
    pub fn run(
        mut self,
        node: &Node<Svc>,
        duration: Option<Duration>,
    ) -> Result<BridgeStats, BridgeError> {
        let mut chores = Housekeeping::new(STATUS_EVERY)
            .with_cleanup()
            .until(duration);
        while chores.running(node) {
            self.step(STEP)?;
            if chores.due(node) {
                eprintln!("{}", self.status_line());
            }
        }
        let stats = self.stats;
        self.close();
        Ok(stats)
    }

    /// The periodic status line.
    pub fn status_line(&self) -> String {
        let s = &self.stats;
        format!(
            "bridge '{}': frame {}, {} inputs ({} deposits), {} keyframes, {} checksums, {} deposits forwarded{}",
            self.options().field,
            s.last_sequence,
            s.inputs_sent,
            s.deposits_in_inputs,
            s.keyframes_sent,
            s.checksums_sent,
            s.deposits_forwarded,
            if self.field_alive() { "" } else { "; the field is not running" }
        )
    }
}

/// What a mirror's run ends with.
#[derive(Debug, Clone, Copy)]
pub struct MirrorRun {
    pub stats: MirrorStats,
    /// Whether the mirror was stale at the end.
    pub stale: bool,
}

impl Mirror {
    /// Steps the mirror until the node is asked to stop (Ctrl-C, SIGTERM) or `duration` has
    /// passed, then closes it; fails with [`BridgeError::Refused`] when the bridge refuses the
    /// connection for good (the session itself would retry forever, logging nothing).
    pub fn run(
        mut self,
        node: &Node<Svc>,
        duration: Option<Duration>,
    ) -> Result<MirrorRun, BridgeError> {
        let endpoint = self.options().connect.join(", ");
        let refused = watch_refusal(
            self.options().security.clone(),
            self.options().connect.clone(),
        );
        let mut chores = Housekeeping::new(STATUS_EVERY)
            .with_cleanup()
            .until(duration);
        while chores.running(node) {
            if let Ok(why) = refused.try_recv() {
                let field = self.options().field.clone();
                self.close();
                return Err(BridgeError::Refused {
                    field,
                    endpoint,
                    why,
                });
            }
            self.step(node, STEP)?;
            if chores.due(node) {
                eprintln!("{}", self.status_line());
            }
        }
        let run = MirrorRun {
            stats: self.stats,
            stale: self.is_stale(),
        };
        self.close();
        Ok(run)
    }

    /// The periodic status line.
    pub fn status_line(&self) -> String {
        let s = &self.stats;
        format!(
            "mirror '{}': {} at frame {}, {} frames applied, {} keyframes, checksums {} matched / {} mismatched, {} gaps, {} rejected",
            self.options().field,
            if self.is_stale() { "stale" } else { "live" },
            s.last_sequence,
            s.frames_applied,
            s.keyframes_applied,
            s.checksums_matched,
            s.checksum_mismatches,
            s.gaps,
            s.rejected_inputs + s.rejected_keyframes + s.rejected_other
        )
    }
}

/// Until a connection to the bridge opens: one attempt at a time (to each endpoint in turn), a
/// second apart, in a thread of its own (an attempt may take as long as a TCP connect and a TLS
/// handshake), whose refusal for good (a certificate, CA or password the bridge does not
/// accept) is sent on the channel.
fn watch_refusal(security: Security, endpoints: Vec<String>) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || loop {
        for endpoint in &endpoints {
            match super::try_connect(&security, endpoint) {
                Ok(()) => return,
                Err(e) => {
                    if let Some(why) = super::refusal(&e) {
                        let _ = tx.send(why);
                        return;
                    }
                }
            }
        }
        // The period between two connection attempts (a cadence, not a wait for a condition:
        // the attempt itself is what waits for the bridge).
        std::thread::sleep(Duration::from_secs(1));
    });
    rx
}
