//! Children die with their parent: `PR_SET_PDEATHSIG` set in the child between fork and exec,
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
