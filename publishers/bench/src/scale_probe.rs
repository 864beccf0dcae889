//! What a run costs the host, read from outside while it runs (issue 52 part 3): the processes
//! of a process tree (from `/proc/*/stat`), their resident memory (RSS from `/proc/PID/statm`,
//! PSS from `/proc/PID/smaps_rollup`: shared pages divided among the processes that map them),
//! the `/dev/shm` files they map (allocated bytes, each file once) and the run's iceoryx2
//! services (listed in this process's domain, by the run's tag).

use std::collections::{BTreeMap, HashMap};
use std::os::unix::fs::MetadataExt;

use iceoryx2::prelude::CallbackProgression;
use iceoryx2::service::Service;

/// The processes of the tree rooted at `root` (itself included), found by their parent ids.
pub fn tree(root: i32) -> Vec<i32> {
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return vec![root];
    };
    let mut children: HashMap<i32, Vec<i32>> = HashMap::new();
    for e in dir.flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<i32>().ok()) else {
            continue;
        };
        if let Some(ppid) = parent(pid) {
            children.entry(ppid).or_default().push(pid);
        }
    }
    let mut out = vec![root];
    let mut i = 0;
    while i < out.len() {
        if let Some(c) = children.get(&out[i]) {
            out.extend_from_slice(c);
        }
        i += 1;
    }
    out
}

/// The parent of `pid` (field 4 of `/proc/PID/stat`, after the command's closing parenthesis).
fn parent(pid: i32) -> Option<i32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(1)?.parse().ok()
}

/// Resident bytes of `pid` (`/proc/PID/statm`, field 2, in pages); 0 for a process gone.
pub fn rss_bytes(pid: i32) -> u64 {
    let page = nix::unistd::sysconf(nix::unistd::SysconfVar::PAGE_SIZE)
        .ok()
        .flatten()
        .unwrap_or(4096) as u64;
    std::fs::read_to_string(format!("/proc/{pid}/statm"))
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map_or(0, |pages| pages * page)
}

/// Proportional set size of `pid` (`/proc/PID/smaps_rollup`, `Pss:` in kB); 0 for a process gone.
pub fn pss_bytes(pid: i32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/smaps_rollup"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("Pss:"))?
                .split_whitespace()
                .nth(1)?
                .parse::<u64>()
                .ok()
        })
        .map_or(0, |kb| kb * 1024)
}

/// Adds the `/dev/shm` files `pid` maps to `files` (path → allocated bytes, the largest seen).
pub fn shm_files(pid: i32, files: &mut BTreeMap<String, u64>) {
    let Ok(maps) = std::fs::read_to_string(format!("/proc/{pid}/maps")) else {
        return;
    };
    for path in maps.lines().filter_map(|l| l.split_once("/dev/shm/")) {
        let name = path.1.trim_end_matches(" (deleted)");
        let full = format!("/dev/shm/{name}");
        let bytes = std::fs::metadata(&full).map_or(0, |m| m.blocks() * 512);
        let seen = files.entry(full).or_insert(0);
        *seen = (*seen).max(bytes);
    }
}

/// The iceoryx2 services of this process's domain whose name holds `tag` as a path segment
/// (`pheromone/<tag>/frame`, `sim/<tag>/r0/pose`, `pheromone/<tag>-map-r0/frame`).
pub fn services_of(tag: &str) -> usize {
    let Ok(config) = pheromone_field::shm::domain_config() else {
        return 0;
    };
    let (exact, map) = (format!("/{tag}/"), format!("/{tag}-map-"));
    let mut n = 0;
    let listed = pheromone_field::shm::Svc::list(&config, |s| {
        let name = s.static_details.name().as_str();
        if name.contains(&exact) || name.contains(&map) {
            n += 1;
        }
        CallbackProgression::Continue
    });
    listed.map_or(0, |_| n)
}

/// The largest values seen over a run's samples.
#[derive(Debug, Clone, Copy, Default)]
pub struct Peaks {
    pub processes: usize,
    pub rss_bytes: u64,
    pub pss_bytes: u64,
    pub shm_bytes: u64,
    pub services: usize,
}

/// Samples the tree of `root` (every `full_every`-th call also its PSS, `/dev/shm` maps and
/// services) into `peaks`.
pub struct Sampler {
    pub root: i32,
    /// The root alone, no walk of `/proc` (a run in one process: sampled every few ms).
    pub root_only: bool,
    pub tag: Option<String>,
    pub peaks: Peaks,
    calls: u64,
}

impl Sampler {
    pub fn new(root: i32, tag: Option<String>) -> Self {
        Self {
            root,
            root_only: false,
            tag,
            peaks: Peaks::default(),
            calls: 0,
        }
    }

    /// One sample; `full`: PSS, shared memory and services too (heavier: every map of every
    /// process is read).
    pub fn sample(&mut self, full: bool) {
        self.calls += 1;
        let pids = match self.root_only {
            true => vec![self.root],
            false => tree(self.root),
        };
        let p = &mut self.peaks;
        p.processes = p.processes.max(pids.len());
        p.rss_bytes = p.rss_bytes.max(pids.iter().map(|&q| rss_bytes(q)).sum());
        if !full {
            return;
        }
        p.pss_bytes = p.pss_bytes.max(pids.iter().map(|&q| pss_bytes(q)).sum());
        let mut files = BTreeMap::new();
        for &q in &pids {
            shm_files(q, &mut files);
        }
        p.shm_bytes = p.shm_bytes.max(files.values().sum());
        if let Some(tag) = &self.tag {
            p.services = p.services.max(services_of(tag));
        }
    }

    /// How many samples were taken.
    pub fn samples(&self) -> u64 {
        self.calls
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn this_process_is_its_own_tree_with_memory_and_a_parent() {
        let me = std::process::id() as i32;
        assert_eq!(tree(me)[0], me);
        assert!(rss_bytes(me) > 0);
        assert!(pss_bytes(me) > 0);
        assert_eq!(parent(me), Some(nix::unistd::getppid().as_raw()));
        assert_eq!(rss_bytes(-1), 0);
    }

    #[test]
    fn a_child_is_in_the_tree_of_its_parent() {
        let mut child = std::process::Command::new("sleep")
            .arg("5")
            .spawn()
            .unwrap();
        let me = std::process::id() as i32;
        let t = tree(me);
        child.kill().unwrap();
        child.wait().unwrap();
        assert!(t.contains(&(child.id() as i32)), "{t:?}");
    }
}
