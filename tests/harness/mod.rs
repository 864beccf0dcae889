//! Helper harness for the integration tests: unique names, child processes that are killed and
//! reaped when dropped, and waiting for a condition with a deadline.

#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use publishers::sim::supervisor::{ChildId, ChildSpec, Supervisor};

/// Path of the `pheromone` binary under test.
pub fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_pheromone"))
}

/// A name no other test (or test run) uses.
pub fn unique(tag: &str) -> String {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos();
    format!(
        "{tag}-{}-{}-{nanos}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// Runs `pheromone ARGS` to completion.
pub fn run(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .output()
        .expect("run pheromone")
}

/// A background `pheromone` process under the project's supervisor
/// (`publishers::sim::supervisor`); stopped (SIGTERM, then SIGKILL) and reaped on drop.
pub struct Proc {
    sup: Supervisor,
    id: ChildId,
    pub what: String,
}

impl Proc {
    pub fn spawn(args: &[&str]) -> Self {
        Self::spawn_spec(ChildSpec::new(
            args.first().copied().unwrap_or("pheromone"),
            None,
            args.iter().map(|a| a.to_string()).collect(),
        ))
    }

    /// Starts `pheromone` as `spec` says (working directory, log file).
    pub fn spawn_spec(spec: ChildSpec) -> Self {
        let what = spec.args.join(" ");
        let mut sup = Supervisor::new(&bin());
        let id = sup.spawn(spec).expect("spawn pheromone");
        Self { sup, id, what }
    }

    pub fn pid(&self) -> u32 {
        self.sup.pid(self.id)
    }

    /// Sends SIGINT (as Ctrl-C would).
    pub fn interrupt(&self) {
        self.sup.signal(self.id, Signal::SIGINT);
    }

    /// Kills the process (SIGKILL), as a crash would.
    pub fn kill(&self) {
        self.sup.signal(self.id, Signal::SIGKILL);
    }

    /// Whether the process is still running.
    pub fn is_running(&mut self) -> bool {
        self.sup.poll(Duration::ZERO);
        self.sup.exit_status(self.id).is_none()
    }

    /// Waits for the process to exit by itself (woken by its exit), at most `timeout`; returns
    /// its output.
    pub fn wait_exit(mut self, timeout: Duration) -> Output {
        assert!(
            self.sup.wait_exit(self.id, timeout),
            "'pheromone {}' did not exit within {timeout:?}",
            self.what
        );
        let status = self.sup.exit_status(self.id).expect("exited");
        let (stdout, stderr) = self.sup.output(self.id);
        Output {
            status,
            stdout: stdout.into_bytes(),
            stderr: stderr.into_bytes(),
        }
    }
}

/// Retries `f` until it returns `Some`, for at most `timeout`.
pub fn eventually<T>(timeout: Duration, what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(t) = f() {
            return t;
        }
        assert!(
            Instant::now() < deadline,
            "timed out after {timeout:?} waiting for {what}"
        );
        std::thread::park_timeout(Duration::from_millis(20));
    }
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Parses the single JSON object a `--json` command prints.
pub fn json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout is not one JSON object ({e}): {}\nstderr: {}",
            stdout(o),
            stderr(o)
        )
    })
}

/// Entries of /dev/shm whose names mention `needle` (iceoryx2 names hash service names, so
/// callers pass node names or compare counts before/after).
pub fn shm_entries() -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default()
}
