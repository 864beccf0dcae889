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
//! A program that wants iceoryx2's handling instead — the `pheromone` binary, the examples —
//! calls [`handle_termination_requests`] once, first thing in `main`: from then on every node
//! this process creates handles termination requests (its `wait` fails on SIGINT/SIGTERM), the
//! waits treat other interruptions as spurious wake-ups, and [`stop_requested`] reports Ctrl-C.

use std::sync::atomic::{AtomicBool, Ordering};

static PROCESS_HANDLES_TERMINATION: AtomicBool = AtomicBool::new(false);

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

/// Whether SIGINT or SIGTERM asked this process to stop: only in a process that called
/// [`handle_termination_requests`] (reading it installs and consumes iceoryx2's handler's
/// record); always false otherwise, where the program's own handler sees the signal.
pub fn stop_requested() -> bool {
    handles_termination_requests()
        && iceoryx2_bb_posix::signal::SignalHandler::termination_requested()
}

/// The iceoryx2 signal handling of a node this process creates.
pub(crate) fn node_signal_mode() -> iceoryx2::prelude::SignalHandlingMode {
    if handles_termination_requests() {
        iceoryx2::prelude::SignalHandlingMode::HandleTerminationRequests
    } else {
        iceoryx2::prelude::SignalHandlingMode::Disabled
    }
}
