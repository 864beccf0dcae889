//! [`Housekeeping`]: what every long-running command (`pheromone field`, `bridge`, `field
//! --mirror`, `ros2`, `gateway`) does besides its work — removing what killed clients left
//! behind (`shm::cleanup_dead_nodes`: a walk of iceoryx2's node directory, a millisecond or
//! more with a few dozen nodes) once a second, a status line every period, and the end of the
//! loop (Ctrl-C/SIGTERM as iceoryx2 reports them to the node, or a duration). The field runs
//! the cleanup on a thread of its own at the default scheduler, so that it never delays a tick
//! (issue 33: a 1 kHz field beside busy loops lost 4 periods to it once a second).

use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use iceoryx2::config::Config;
use iceoryx2::node::Node;

use crate::shm::Svc;

/// How often [`Housekeeping`] removes what dead nodes left behind.
pub const CLEANUP_EVERY: Duration = Duration::from_secs(1);

/// The periodic chores of a long-running loop, and its end:
///
/// ```text
/// let mut chores = Housekeeping::new(Duration::from_secs(5)).with_cleanup().until(duration);
/// while chores.running(&node) {
///     work.step(Duration::from_millis(20))?;
///     if chores.due(&node) {
///         eprintln!("{}", work.status_line());
///     }
/// }
/// ```
///
/// It installs no signal handler and never exits: the loop ends when the node's wait reports a
/// termination request (the handler is the program's, see `shm::handle_termination_requests`).
pub struct Housekeeping {
    started: Instant,
    duration: Option<Duration>,
    status_every: Duration,
    last_status: Instant,
    cleanup: Cleanup,
}

/// Where the dead nodes' cleanup runs.
enum Cleanup {
    Off,
    /// In [`Housekeeping::due`], on the loop's thread.
    Inline {
        last: Instant,
        cleaned: Cell<u64>,
    },
    /// On a thread of its own.
    Thread(Housekeeper),
}

impl Housekeeping {
    /// A status line due every `status_every`; no cleanup, no end but a termination request.
    pub fn new(status_every: Duration) -> Self {
        let now = Instant::now();
        Self {
            started: now,
            duration: None,
            status_every,
            last_status: now,
            cleanup: Cleanup::Off,
        }
    }

    /// The loop ends once `duration` (if any) has passed since [`Housekeeping::new`].
    pub fn until(mut self, duration: Option<Duration>) -> Self {
        self.duration = duration;
        self
    }

    /// Removes what dead nodes left behind every [`CLEANUP_EVERY`], in [`Housekeeping::due`]
    /// (not in a child of a supervisor that does it: `shm::cleaned_by_supervisor`).
    pub fn with_cleanup(mut self) -> Self {
        if crate::shm::cleaned_by_supervisor() {
            return self;
        }
        self.cleanup = Cleanup::Inline {
            last: Instant::now(),
            cleaned: Cell::new(0),
        };
        self
    }

    /// Removes what dead nodes of `node`'s configuration left behind every [`CLEANUP_EVERY`]
    /// on a thread of its own (stopped when this is dropped): for a loop the cleanup must never
    /// delay. A thread that cannot be started leaves the cleanup undone (said on stderr).
    pub fn with_cleanup_thread(mut self, node: &Node<Svc>) -> Self {
        if crate::shm::cleaned_by_supervisor() {
            return self;
        }
        self.cleanup = Cleanup::Thread(Housekeeper::start(node.config().clone(), CLEANUP_EVERY));
        self
    }

    /// Whether the loop goes on: not once the node was asked to stop (Ctrl-C, SIGTERM) nor
    /// past the duration.
    pub fn running(&self, node: &Node<Svc>) -> bool {
        !crate::shm::should_stop(node) && self.duration.is_none_or(|d| self.started.elapsed() < d)
    }

    /// Runs the cleanup if it is due; `true` once per status period (the caller then writes
    /// its status line).
    pub fn due(&mut self, node: &Node<Svc>) -> bool {
        if let Cleanup::Inline { last, cleaned } = &mut self.cleanup {
            if last.elapsed() >= CLEANUP_EVERY {
                *last = Instant::now();
                cleaned.set(cleaned.get() + crate::shm::cleanup_dead_nodes(node));
            }
        }
        if self.last_status.elapsed() >= self.status_every {
            self.last_status = Instant::now();
            return true;
        }
        false
    }

    /// Dead nodes removed since the last call.
    pub fn take_cleaned(&self) -> u64 {
        match &self.cleanup {
            Cleanup::Off => 0,
            Cleanup::Inline { cleaned, .. } => cleaned.take(),
            Cleanup::Thread(h) => h.take_cleaned(),
        }
    }

    /// Time since [`Housekeeping::new`].
    pub fn elapsed(&self) -> Duration {
        self.started.elapsed()
    }
}

/// The housekeeping thread; stopped and joined on drop.
struct Housekeeper {
    cleaned: Arc<AtomicU64>,
    stop: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Housekeeper {
    /// Cleans up after dead nodes of `config` every `every`. A thread that cannot be started
    /// leaves the cleanup undone (said on stderr), as the field's work does not depend on it.
    fn start(config: Config, every: Duration) -> Self {
        let cleaned = Arc::new(AtomicU64::new(0));
        let (stop, stopped) = mpsc::channel::<()>();
        let count = Arc::clone(&cleaned);
        let thread = std::thread::Builder::new()
            .name("field-housekeeping".into())
            .spawn(move || {
                // Started by a SCHED_FIFO field, it would compete with the tick at its priority.
                crate::process::realtime::default_scheduling_for_this_thread();
                while let Err(RecvTimeoutError::Timeout) = stopped.recv_timeout(every) {
                    let n = crate::shm::cleanup_dead_nodes_of(&config);
                    count.fetch_add(n, Ordering::Relaxed);
                }
            })
            .map_err(|e| eprintln!("field: no housekeeping thread ({e}): dead clients stay"))
            .ok();
        Self {
            cleaned,
            stop: Some(stop),
            thread,
        }
    }

    /// Dead nodes removed since the last call.
    fn take_cleaned(&self) -> u64 {
        self.cleaned.swap(0, Ordering::Relaxed)
    }
}

impl Drop for Housekeeper {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
