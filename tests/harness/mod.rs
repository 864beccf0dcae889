//! The helpers of the process tests: the binary under test, `run`, `Proc::spawn`, `eventually`.
//!
//! Unique names and the argv builder `Cmd` come from the test kit (`tests/kit`); child processes
//! are killed and reaped when dropped; `eventually` waits for a condition with a deadline.

#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Output;
use std::time::{Duration, Instant};

use pheromone_supervisor::ChildSpec;

/// Path of the `pheromone` binary under test.
pub fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_pheromone"))
}

pub use pheromone_testkit::{unique, Cmd};

/// Runs `pheromone ARGS` to completion.
pub fn run(args: &[&str]) -> Output {
    pheromone_testkit::Cli::new(&bin()).args(args).output()
}

pub use pheromone_testkit::Proc;

/// `Proc::spawn(args)`: the `pheromone` binary under test, started under the supervisor.
pub trait SpawnExt {
    fn spawn(args: &[&str]) -> Self;
    /// Starts it as `spec` says (working directory, log file).
    fn spawn_spec(spec: ChildSpec) -> Self;
}

impl SpawnExt for Proc {
    fn spawn(args: &[&str]) -> Self {
        Self::spawn_spec(ChildSpec::new(
            args.first().copied().unwrap_or("pheromone"),
            None,
            args.iter().map(|a| a.to_string()).collect(),
        ))
    }

    fn spawn_spec(spec: ChildSpec) -> Self {
        Proc::start(&bin(), spec)
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

/// Every entry of /dev/shm (iceoryx2 names hash service names, so callers look for node names
/// or compare counts before/after).
pub fn shm_entries() -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default()
}
