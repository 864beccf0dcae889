//! `pheromone_field::process::run::Housekeeping`, the chores of every long-running command's loop: its end (a
//! duration; a termination request ends it too, see `signals.rs`), the status line's period,
//! and the dead-node cleanup inline or on a thread of its own.

use std::time::{Duration, Instant};

use pheromone_field::process::run::Housekeeping;
use pheromone_field::shm::create_node;
use pheromone_testkit::unique;

#[test]
fn the_loop_ends_after_its_duration_with_a_status_line_due_once_a_period() {
    let node = create_node(&unique("housekeeping")).unwrap();
    let started = Instant::now();
    let mut chores = Housekeeping::new(Duration::from_millis(50))
        .with_cleanup()
        .until(Some(Duration::from_millis(300)));
    let mut due = 0;
    while chores.running(&node) {
        if chores.due(&node) {
            due += 1;
        }
        // A loop's work, paced as the commands pace theirs: on the node.
        let _ = pheromone_field::shm::node_wait(&node, Duration::from_millis(1));
    }
    let took = started.elapsed();
    assert!(took >= Duration::from_millis(300), "{took:?}");
    assert!(took < Duration::from_secs(30), "{took:?}");
    // At most one line per 50 ms period of the 300 ms; at least one however late the waits.
    assert!((1..=6).contains(&due), "{due} status lines");
    assert!(chores.elapsed() >= Duration::from_millis(300));
    // The count is taken once.
    let _ = chores.take_cleaned();
    assert_eq!(chores.take_cleaned(), 0);
}

#[test]
fn without_a_duration_it_runs_and_a_cleanup_thread_stops_when_dropped() {
    let node = create_node(&unique("housekeeping")).unwrap();
    let chores = Housekeeping::new(Duration::MAX).with_cleanup_thread(&node);
    assert!(chores.running(&node));
    let mut chores = chores;
    // A status period of `Duration::MAX` is never due.
    assert!(!chores.due(&node));
    let started = Instant::now();
    drop(chores);
    // The thread is told to stop and joined at once, not after its next period.
    assert!(
        started.elapsed() < Duration::from_millis(900),
        "{:?}",
        started.elapsed()
    );
}
