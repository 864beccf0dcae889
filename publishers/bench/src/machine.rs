//! The machine the figures were measured on, and pinning to cores.

use serde::Serialize;

#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    pub cpu_model: String,
    /// Online cores.
    pub cores: usize,
    pub os: String,
    pub kernel: String,
}

impl Machine {
    pub fn detect() -> Self {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let cpu_model = cpuinfo
            .lines()
            .find(|l| l.starts_with("model name"))
            .and_then(|l| l.split_once(':'))
            .map(|(_, v)| v.trim().to_string())
            .unwrap_or_else(|| "unknown".into());
        let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease")
            .map(|s| s.trim().to_string())
            .unwrap_or_else(|_| "unknown".into());
        Self {
            cpu_model,
            cores: cores(),
            os: std::env::consts::OS.into(),
            kernel,
        }
    }
}

/// Cores of the machine (online processors, whatever this process is pinned to).
pub fn cores() -> usize {
    let listed = std::fs::read_to_string("/proc/cpuinfo")
        .map(|s| s.lines().filter(|l| l.starts_with("processor")).count())
        .unwrap_or(0);
    if listed > 0 {
        listed
    } else {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    }
}

/// Pins the calling process to `core` (modulo the core count); returns whether it worked.
pub fn pin_to_core(core: usize) -> bool {
    use nix::sched::{sched_setaffinity, CpuSet};
    use nix::unistd::Pid;
    let mut set = CpuSet::new();
    if set.set(core % cores()).is_err() {
        return false;
    }
    sched_setaffinity(Pid::from_raw(0), &set).is_ok()
}

/// Lets the calling process run on every core again.
pub fn unpin() -> bool {
    use nix::sched::{sched_setaffinity, CpuSet};
    use nix::unistd::Pid;
    let mut set = CpuSet::new();
    for c in 0..cores().min(CpuSet::count()) {
        // `c` is below `CpuSet::count()`, the only way `set` fails.
        let _ = set.set(c);
    }
    sched_setaffinity(Pid::from_raw(0), &set).is_ok()
}

/// The process's CPU time (user + system) so far, from `/proc/PID/schedstat` (ns).
pub(crate) fn cpu_ns(pid: u32) -> Result<u64, crate::BenchError> {
    let path = format!("/proc/{pid}/schedstat");
    let text = std::fs::read_to_string(&path).map_err(|source| crate::BenchError::Io {
        what: format!("read {path}"),
        source,
    })?;
    text.split_whitespace()
        .next()
        .and_then(|v| v.parse().ok())
        .ok_or_else(|| {
            crate::BenchError::Peer(format!("{path}: '{}' has no CPU time", text.trim()))
        })
}

/// `SCHED_FIFO` at `priority` with `mlockall`, best effort: what the OS refused, each said on
/// stderr as `who`.
pub(crate) fn realtime(priority: Option<i32>, who: &str) -> Result<Vec<String>, crate::BenchError> {
    let Some(priority) = priority else {
        return Ok(Vec::new());
    };
    let o = pheromone_field::process::realtime::RealtimeOptions {
        priority,
        cpu: None,
        best_effort: true,
    };
    let applied = pheromone_field::process::realtime::apply(&o)
        .map_err(|e| crate::BenchError::Peer(format!("{who}: {e}")))?;
    for r in &applied.refused {
        eprintln!("{who}: going on without it: {r}");
    }
    Ok(applied.refused)
}
