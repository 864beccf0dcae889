//! Who owns SIGINT and SIGTERM: the program, never this library unless the program says so.
//!
//! By default (a library embedded in a robot node, the C ABI, a Rust program that keeps its own
//! signal handling) nothing here installs, replaces or consumes a signal handler: nodes are built
//! with iceoryx2's `SignalHandlingMode::Disabled`, iceoryx2's global `SignalHandler` (which
//! installs handlers for 13 signals the first time it is asked anything) is never asked, and a
//! wait that a signal cuts short (`EINTR`, whatever handler the program installed) returns an
//! "interrupted" error (`ReceiveError::Interrupted`, `SendError::Interrupted`,
//! `AttachError::Interrupted`) so the program's loop can look at its own flags.
//!
//! The library's loops (the field's run loop `process::run::run_field`, lockstep, the roles'
//! loops, `Housekeeping`) end on a stop request. A program that owns its signals tells them
//! which flag means "stop" with [`stop_when`] (its own handler sets the flag, e.g. signal-hook's
//! `flag::register`); a signal wakes their waits, and they look at the flag ([`should_stop`]).
//!
//! A program that wants iceoryx2's handling instead — the `pheromone` binary, the examples —
//! calls [`handle_termination_requests`] once, first thing in `main`: from then on every node
//! this process creates handles termination requests (its `wait` fails on SIGINT/SIGTERM), the
//! waits treat other interruptions as spurious wake-ups, and [`stop_requested`] reports Ctrl-C.
//!
//! iceoryx2 keeps one record of the last signal and every `Node::wait` that looks at it clears
//! it: a wait whose error a caller ignores (a sleep) swallowed the request, and the loop's next
//! check saw nothing (a field at 0.4 Hz then ran on after SIGINT). So a request, once seen by
//! any of this module's functions, is latched for the life of the process, and the library
//! waits on a node only through [`node_wait`] (clippy's `disallowed-methods` keeps it so). A
//! wait that belongs to an orderly end (a publisher's flush when dropped, after its loop ended
//! on the request) is cut only by a request made while it waits ([`stop_mark`]).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use iceoryx2::node::Node;

use super::Svc;

static PROCESS_HANDLES_TERMINATION: AtomicBool = AtomicBool::new(false);

/// How many termination requests this process has seen (iceoryx2's record, read and cleared by
/// a node's wait or by [`stop_requested`]); more than 0: latched.
static TERMINATIONS: AtomicU64 = AtomicU64::new(0);

fn termination_seen() -> bool {
    TERMINATIONS.load(Ordering::SeqCst) > 0
}

/// The program's stop flag ([`stop_when`]).
static PROGRAM_STOP_FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// For a program that keeps its own signal handling: the library's loops end once `flag` is
/// true (the program's SIGINT/SIGTERM handler sets it; a signal also wakes their waits, so they
/// end within one of their wait slices). Only the program's `main` calls it, once; a second call
/// with another flag returns false and changes nothing. Installs no handler.
pub fn stop_when(flag: Arc<AtomicBool>) -> bool {
    PROGRAM_STOP_FLAG.set(flag).is_ok()
}

/// Whether the program's own stop flag ([`stop_when`]) is set.
pub(crate) fn program_stop_flag_set() -> bool {
    PROGRAM_STOP_FLAG
        .get()
        .is_some_and(|f| f.load(Ordering::SeqCst))
}

/// Whether a loop on `node` should end now: a termination request (in a program that called
/// [`handle_termination_requests`]) or the program's stop flag ([`stop_when`]). Waits nothing.
pub fn should_stop(node: &Node<Svc>) -> bool {
    node_wait(node, Duration::ZERO).is_err() || program_stop_flag_set()
}

/// `node.wait(d)` that loses no termination request: a request it reads is latched, and once
/// one was seen every later call still sleeps its `d` (a caller that ignores the result to
/// sleep never spins) and then reports `TerminationRequest`. `Interrupt`: another signal cut
/// the sleep short (the request, if it was one, is seen by the next check).
pub fn node_wait(node: &Node<Svc>, d: Duration) -> Result<(), iceoryx2::node::NodeWaitFailure> {
    use iceoryx2::node::NodeWaitFailure;
    #[allow(clippy::disallowed_methods)] // the one place that calls it
    let waited = node.wait(d);
    match waited {
        Err(NodeWaitFailure::TerminationRequest) => {
            TERMINATIONS.fetch_add(1, Ordering::SeqCst);
            waited
        }
        Ok(()) if termination_seen() => Err(NodeWaitFailure::TerminationRequest),
        _ => waited,
    }
}

/// For a program's `main`, never for a library: from now on this process's nodes install
/// iceoryx2's SIGINT/SIGTERM handler (replacing the program's own) and `node.wait` fails on a
/// termination request; waits then end without error on Ctrl-C (they report no frame) instead
/// of returning "interrupted". Cannot be undone. Call it before creating any node.
pub fn handle_termination_requests() {
    PROCESS_HANDLES_TERMINATION.store(true, Ordering::SeqCst);
}

/// Whether this process asked for iceoryx2's termination handling
/// ([`handle_termination_requests`]).
pub fn handles_termination_requests() -> bool {
    PROCESS_HANDLES_TERMINATION.load(Ordering::SeqCst)
}

/// Whether this process was asked to stop: SIGINT or SIGTERM in a process that called
/// [`handle_termination_requests`] (once seen, for the life of the process), or the
/// program's stop flag ([`stop_when`]). Never asks iceoryx2's handler otherwise.
pub fn stop_requested() -> bool {
    program_stop_flag_set() || termination_seen() || read_termination_record()
}

/// Reads (and clears) iceoryx2's record of a termination request, in a process that asked for
/// its handling, counting one it finds; whether it found one.
fn read_termination_record() -> bool {
    let seen = handles_termination_requests()
        && iceoryx2_bb_posix::signal::SignalHandler::termination_requested();
    if seen {
        TERMINATIONS.fetch_add(1, Ordering::SeqCst);
    }
    seen
}

/// Where the stop requests stood when a wait began ([`stop_mark`]).
#[derive(Debug, Clone, Copy)]
pub struct StopMark {
    terminations: u64,
    flag: bool,
}

/// The stop requests seen so far, for a wait that only a request made during it may cut
/// short ([`stopped_since`]): a publisher's flush when it is dropped, after its loop ended on
/// the request, still waits for the field (a second Ctrl-C cuts it). For a program's own wait
/// at its end, too.
pub fn stop_mark() -> StopMark {
    StopMark {
        terminations: TERMINATIONS.load(Ordering::SeqCst),
        flag: program_stop_flag_set(),
    }
}

/// Whether a stop was requested after `mark`: a termination request not yet seen then (a
/// record not read yet counts), or the program's flag set since.
pub fn stopped_since(mark: StopMark) -> bool {
    read_termination_record();
    (program_stop_flag_set() && !mark.flag)
        || TERMINATIONS.load(Ordering::SeqCst) > mark.terminations
}

/// The iceoryx2 signal handling of a node this process creates.
pub(crate) fn node_signal_mode() -> iceoryx2::prelude::SignalHandlingMode {
    if handles_termination_requests() {
        iceoryx2::prelude::SignalHandlingMode::HandleTerminationRequests
    } else {
        iceoryx2::prelude::SignalHandlingMode::Disabled
    }
}
