//! A termination request is never lost in a program that uses iceoryx2's handling (as the
//! `pheromone` binary does). iceoryx2 keeps one record of the last signal and clears it on the
//! node wait that reads it: a sleep that ignored its wait's result swallowed a SIGINT, and the
//! loop's next `should_stop` saw nothing (a 0.4 Hz field ran on after SIGINT in a CI run).
//!
//! Its own test binary with one test: `handle_termination_requests` is process-wide and cannot
//! be undone.

use std::time::{Duration, Instant};

use nix::sys::signal::{raise, Signal};
use pheromone_field::shm::{
    create_node, handle_termination_requests, node_wait, should_stop, stop_mark, stop_requested,
    stopped_since,
};
use pheromone_testkit::unique;

#[test]
fn a_request_read_by_a_sleep_that_ignores_it_still_stops_every_later_check() {
    handle_termination_requests();
    let node = create_node(&unique("latch")).unwrap();
    assert!(!should_stop(&node), "no request yet");
    // iceoryx2's handler (installed with the node) records the signal; the process lives on.
    raise(Signal::SIGTERM).unwrap();
    // A sleep that ignores its result, as the field's pacing does between deposits.
    let _ = node_wait(&node, Duration::from_millis(1));
    assert!(should_stop(&node), "the request read by the sleep was lost");
    assert!(stop_requested());
    // Later waits still sleep (a loop that ignores them never spins) and report the request.
    let start = Instant::now();
    assert!(node_wait(&node, Duration::from_millis(20)).is_err());
    assert!(
        start.elapsed() >= Duration::from_millis(20),
        "{:?}",
        start.elapsed()
    );
    assert!(should_stop(&node));
    // A wait of the orderly end (a publisher's flush on drop) is cut only by a request made
    // while it waits: not by the latched one, by a second Ctrl-C.
    let mark = stop_mark();
    assert!(
        !stopped_since(mark),
        "the latched request cut the end's wait"
    );
    raise(Signal::SIGTERM).unwrap();
    assert!(
        stopped_since(mark),
        "a second request did not cut the end's wait"
    );
}
