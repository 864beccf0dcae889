//! Real-time scheduling for a process that must keep its period on a shared robot computer:
//! `SCHED_FIFO` at a priority, every page locked in memory (`mlockall`, current and future
//! mappings, so the frame pool is faulted in before the first tick), optionally one CPU.
//!
//! When the OS refuses, the error names what is missing (CAP_SYS_NICE or RLIMIT_RTPRIO,
//! CAP_IPC_LOCK or RLIMIT_MEMLOCK); with `best_effort` the process goes on and reports what it
//! did not get. Threads started afterwards (the tick's row workers) inherit the policy.
#![allow(unsafe_code)]

use nix::sched::{sched_setaffinity, CpuSet};
use nix::sys::mman::{mlockall, MlockAllFlags};
use nix::sys::resource::{getrlimit, Resource};
use nix::unistd::Pid;

/// What to ask the OS for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RealtimeOptions {
    /// `SCHED_FIFO` priority, 1..=99.
    pub priority: i32,
    /// Run on this CPU only.
    pub cpu: Option<usize>,
    /// Go on without what the OS refuses (reported in [`Applied::refused`]).
    pub best_effort: bool,
}

/// What the OS refused.
#[derive(Debug, thiserror::Error)]
pub enum RealtimeError {
    /// The requested priority is outside `SCHED_FIFO`'s 1..=99.
    #[error("--rt-priority {0}: must be a SCHED_FIFO priority from 1 to 99")]
    Priority(i32),
    #[error(
        "SCHED_FIFO priority {priority} refused ({source}): it needs CAP_SYS_NICE (root) or an \
         RLIMIT_RTPRIO of at least {priority} (`ulimit -r`; here {rlimit})"
    )]
    /// `sched_setscheduler` refused `SCHED_FIFO`: the process lacks CAP_SYS_NICE and its
    /// RLIMIT_RTPRIO is below the priority.
    Scheduler {
        /// The priority asked for.
        priority: i32,
        /// The process's soft RLIMIT_RTPRIO, formatted (`unlimited`, a number, or why unknown).
        rlimit: String,
        /// The OS's error.
        source: nix::Error,
    },
    #[error(
        "locking memory (mlockall) refused ({source}): it needs CAP_IPC_LOCK (root) or an \
         RLIMIT_MEMLOCK larger than the process (`ulimit -l`; here {rlimit})"
    )]
    /// `mlockall` refused: the process lacks CAP_IPC_LOCK and its RLIMIT_MEMLOCK is too small.
    Lock {
        /// The process's soft RLIMIT_MEMLOCK, formatted (`unlimited`, bytes, or why unknown).
        rlimit: String,
        /// The OS's error.
        source: nix::Error,
    },
    /// `sched_setaffinity` refused the CPU (it does not exist or is not in the process's set).
    #[error("--rt-cpu {cpu}: pinning refused ({source})")]
    Pin {
        /// The CPU asked for.
        cpu: usize,
        /// The OS's error.
        source: nix::Error,
    },
}

/// What the process got.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Applied {
    /// The `SCHED_FIFO` priority the process runs at; `None` if refused or not asked for.
    pub fifo_priority: Option<i32>,
    /// Whether every page is locked in memory (`mlockall`).
    pub memory_locked: bool,
    /// The CPU the process is pinned to; `None` if refused or not asked for.
    pub cpu: Option<usize>,
    /// With `best_effort`: each refusal's message.
    pub refused: Vec<String>,
}

fn limit(resource: Resource) -> String {
    match getrlimit(resource) {
        Ok((soft, _)) if soft == libc::RLIM_INFINITY => "unlimited".into(),
        Ok((soft, _)) => soft.to_string(),
        Err(e) => format!("unknown: {e}"),
    }
}

/// `SCHED_FIFO` at `priority` for the calling thread (and the threads it starts later).
fn set_fifo(priority: i32) -> Result<(), RealtimeError> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: sched_setscheduler reads the `sched_param` through the pointer for the duration
    // of the call only; `param` is a live, initialised local. pid 0 is the calling thread.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(RealtimeError::Scheduler {
            priority,
            rlimit: limit(Resource::RLIMIT_RTPRIO),
            source: nix::Error::last(),
        })
    }
}

/// `SCHED_FIFO` at `priority` for the calling thread only (no memory locking): a thread of a
/// process that measures or serves something with its loop (`pheromone bench`).
pub fn fifo_for_this_thread(priority: i32) -> Result<(), RealtimeError> {
    if !(1..=99).contains(&priority) {
        return Err(RealtimeError::Priority(priority));
    }
    set_fifo(priority)
}

/// Puts the calling thread back on the default scheduler (`SCHED_OTHER`), e.g. a helper thread
/// of a real-time process that must not compete with its loop. Best effort: a failure leaves
/// the thread as it was.
pub fn default_scheduling_for_this_thread() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: as in `set_fifo`: the pointer is to a live local read during the call only; pid 0
    // is the calling thread. Lowering one's own policy needs no permission.
    let _ = unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &param) };
}

/// Asks for everything `o` names, in order: the CPU, memory locking, then the priority.
pub fn apply(o: &RealtimeOptions) -> Result<Applied, RealtimeError> {
    if !(1..=99).contains(&o.priority) {
        return Err(RealtimeError::Priority(o.priority));
    }
    let mut applied = Applied::default();
    let mut outcome = |r: Result<(), RealtimeError>| -> Result<bool, RealtimeError> {
        match r {
            Ok(()) => Ok(true),
            Err(e) if o.best_effort => {
                applied.refused.push(e.to_string());
                Ok(false)
            }
            Err(e) => Err(e),
        }
    };
    if let Some(cpu) = o.cpu {
        let pin = (|| {
            let mut set = CpuSet::new();
            set.set(cpu)?;
            sched_setaffinity(Pid::from_raw(0), &set)
        })()
        .map_err(|source| RealtimeError::Pin { cpu, source });
        if outcome(pin)? {
            applied.cpu = Some(cpu);
        }
    }
    let lock = mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE).map_err(|source| {
        RealtimeError::Lock {
            rlimit: limit(Resource::RLIMIT_MEMLOCK),
            source,
        }
    });
    applied.memory_locked = outcome(lock)?;
    if outcome(set_fifo(o.priority))? {
        applied.fifo_priority = Some(o.priority);
    }
    Ok(applied)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_priority_outside_1_to_99_is_refused_before_asking_the_os() {
        for p in [0, 100, -5] {
            let o = RealtimeOptions {
                priority: p,
                cpu: None,
                best_effort: true,
            };
            let e = apply(&o).unwrap_err().to_string();
            assert!(e.contains(&format!("--rt-priority {p}")), "{e}");
        }
    }
}
