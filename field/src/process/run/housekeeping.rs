//! The field's once-a-second housekeeping — removing what killed clients left behind
//! (`shm::cleanup_dead_nodes_of`: a walk of iceoryx2's node directory, a millisecond or more
//! with a few dozen nodes) — on a thread of its own at the default scheduler, so that it never
//! delays a tick (issue 33: a 1 kHz field beside busy loops lost 4 periods to it once a second).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use iceoryx2::config::Config;

/// The housekeeping thread; stopped and joined on drop.
pub(super) struct Housekeeper {
    cleaned: Arc<AtomicU64>,
    stop: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Housekeeper {
    /// Cleans up after dead nodes of `config` every `every`. A thread that cannot be started
    /// leaves the cleanup undone (said on stderr), as the field's work does not depend on it.
    pub(super) fn start(config: Config, every: Duration) -> Self {
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
    pub(super) fn take_cleaned(&self) -> u64 {
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
