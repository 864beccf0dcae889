//! Children die with their parent: `PR_SET_PDEATHSIG` set in the child between fork and exec
//! (or, for `pheromone` children, by the child first thing in `main`: [`die_with_parent_as_asked`]),
//! so a supervisor killed by any signal (SIGKILL included) takes its children with it — each gets
//! SIGTERM and cleans up as on an orderly stop.
//!
//! Linux sends the signal when the *thread* that forked the child exits: a `Supervisor` starts
//! and keeps its children on the thread that runs the run, as every caller here does.
#![allow(unsafe_code)]

use std::os::unix::process::CommandExt;
use std::process::Command;

use nix::errno::Errno;
use nix::sys::signal::Signal;
use nix::unistd::{getpid, getppid};

/// Makes the child started by `command` receive SIGTERM when this process (the spawning
/// thread) dies; a child whose parent died before the request took effect does not start.
pub(crate) fn die_with_parent(command: &mut Command) {
    let parent = getpid();
    // SAFETY: the closure runs in the forked child before exec, where only async-signal-safe
    // calls are allowed: it calls prctl(2) and getppid(2) and builds io::Errors from raw OS codes,
    // none of which allocates or takes a lock.
    unsafe {
        command.pre_exec(move || {
            nix::sys::prctl::set_pdeathsig(Signal::SIGTERM).map_err(std::io::Error::from)?;
            if getppid() != parent {
                // The parent exited between fork and prctl: no signal will come.
                return Err(std::io::Error::from(Errno::ESRCH));
            }
            Ok(())
        });
    }
}

/// The environment variable by which a [`crate::Supervisor`] whose children are `pheromone`
/// processes ([`crate::Supervisor::death_signal_by_child`]) asks each child to request its
/// death signal itself: the supervisor's PID.
pub const DIE_WITH_PARENT_ENV: &str = "PHEROMONE_DIE_WITH_PARENT";

/// Asks the child started by `command` to make the request of [`die_with_parent`] itself, at
/// its start ([`die_with_parent_as_asked`]): no code runs between fork and exec, so the child
/// is started by `posix_spawn` (a `vfork`), not by a `fork` that copies this process's page
/// tables — a sim that has mapped N robots' services would copy them for each of its 3N
/// children (issue 52).
pub(crate) fn ask_child_to_die_with_parent(command: &mut Command) {
    command.env(DIE_WITH_PARENT_ENV, getpid().as_raw().to_string());
}

/// The supervising process asked for by [`DIE_WITH_PARENT_ENV`] ended before this process could
/// request its death signal.
#[derive(Debug, thiserror::Error)]
#[error(
    "the supervising process {parent} ended before this process started (its parent is now {now})"
)]
pub struct ParentGone {
    pub parent: i32,
    pub now: i32,
}

/// Child side of [`DIE_WITH_PARENT_ENV`]: if the variable names a PID, requests SIGTERM when
/// the thread that started this process dies (`PR_SET_PDEATHSIG`), and fails if that process
/// has already gone (this process was re-parented: no signal would come). Call it first thing
/// in `main`, then remove the variable so that this process's own children do not see it.
pub fn die_with_parent_as_asked() -> Result<(), ParentGone> {
    let Some(parent) = std::env::var(DIE_WITH_PARENT_ENV)
        .ok()
        .and_then(|v| v.parse::<i32>().ok())
    else {
        return Ok(());
    };
    // Cannot fail with a valid signal.
    let _ = nix::sys::prctl::set_pdeathsig(Signal::SIGTERM);
    let now = getppid().as_raw();
    if now != parent {
        return Err(ParentGone { parent, now });
    }
    Ok(())
}
