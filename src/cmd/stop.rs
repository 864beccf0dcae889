//! Which signal asked this process to stop: SIGINT (Ctrl-C) or SIGTERM, for `pheromone sim` and
//! `pheromone field`, which then write what they have and exit with 128 + the signal's number
//! (130, 143), as a shell reports a process that a signal ended.
//!
//! iceoryx2 installs its own handler for both, once per process, and consumes what it records
//! when a node waits, so it cannot tell afterwards which one arrived. Ours is installed after
//! it and chains to it (signal-hook calls the previous handler first), so iceoryx2 still sees
//! every stop request where it waits.

use std::fmt;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use signal_hook::consts::{SIGINT, SIGTERM};

static LAST: OnceLock<Arc<AtomicUsize>> = OnceLock::new();

/// Records SIGINT and SIGTERM from now on, beside iceoryx2's handler (installed first here).
pub fn install() -> anyhow::Result<()> {
    // iceoryx2 installs its handler when first used; installed later, it would replace ours.
    // At the start no signal is pending, so the one this reads and clears is none.
    let _ = iceoryx2_bb_posix::signal::SignalHandler::last_signal();
    let flag = LAST.get_or_init(|| Arc::new(AtomicUsize::new(0)));
    for s in [SIGINT, SIGTERM] {
        signal_hook::flag::register_usize(s, Arc::clone(flag), s as usize)?;
    }
    Ok(())
}

/// The last of SIGINT or SIGTERM received since `install`, if any.
pub fn requested() -> Option<i32> {
    match LAST.get()?.load(Ordering::Relaxed) {
        0 => None,
        s => i32::try_from(s).ok(),
    }
}

/// The process was stopped by `signal` after writing what it had: it exits with
/// 128 + `signal` (130 for SIGINT, 143 for SIGTERM).
#[derive(Debug)]
pub struct Stopped {
    pub signal: i32,
}

impl Stopped {
    /// Stopped by the signal received, SIGINT if none was recorded (iceoryx2 saw one first).
    pub fn by_requested() -> Self {
        Self {
            signal: requested().unwrap_or(SIGINT),
        }
    }

    /// The exit status: 128 + the signal's number.
    pub fn exit_status(&self) -> u8 {
        u8::try_from(128 + self.signal).unwrap_or(1)
    }

    /// The signal's name: `SIGINT`, `SIGTERM`.
    pub fn name(&self) -> &'static str {
        match self.signal {
            SIGINT => "SIGINT",
            SIGTERM => "SIGTERM",
            _ => "a signal",
        }
    }
}

impl fmt::Display for Stopped {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "stopped by {}", self.name())
    }
}

impl std::error::Error for Stopped {}
