//! The host's limits a run as processes needs, checked before anything starts (issue 52): the
//! processes one lockstep run admits (`pheromone_field::wire::MAX_PARTICIPANTS`, the size of
//! the clock and acknowledgement services), the file descriptors this process holds
//! (`RLIMIT_NOFILE`: two pipes per child and the observer's ports, about 14 per process of the
//! run, measured: 724 at 51 processes) and the free space in `/dev/shm`. A run above one of
//! them is refused naming the limit, its value and what the run needs, instead of failing
//! half-started or waiting for processes that cannot join.

use pheromone_field::wire::MAX_PARTICIPANTS;

use super::ProcessRunError;

/// File descriptors this process holds per process of the run (measured: 724 with 51
/// processes, 16 robots of `ias-ss`; 1 464 with 99), with room.
pub const FDS_PER_PROCESS: u64 = 16;
/// File descriptors this process holds besides them.
pub const FDS_BASE: u64 = 64;
/// `/dev/shm` bytes a run needs per process besides the field's frames (measured: 31 MiB at 27
/// processes, 65 MiB at 51, the frames included), with room.
pub const SHM_PER_PROCESS: u64 = 2 << 20;

/// What a run of `processes` processes (the observer counted in) needs, and whether the host
/// gives it: the processes limit, `nofile` (soft `RLIMIT_NOFILE`, if known) and `shm_free`
/// (free bytes in `/dev/shm`, if known) beside the field's `frames_bytes`.
pub fn check(
    processes: usize,
    nofile: Option<u64>,
    shm_free: Option<u64>,
    frames_bytes: u64,
) -> Result<(), ProcessRunError> {
    if processes > MAX_PARTICIPANTS {
        return Err(ProcessRunError::HostLimit {
            limit: "processes of a lockstep run (pheromone_field::wire::MAX_PARTICIPANTS, \
                    iceoryx2's subscribers of the run's clock)"
                .into(),
            value: MAX_PARTICIPANTS as u64,
            needed: processes as u64,
        });
    }
    let fds = FDS_BASE + FDS_PER_PROCESS * processes as u64;
    if let Some(n) = nofile.filter(|n| *n < fds) {
        return Err(ProcessRunError::HostLimit {
            limit: format!(
                "open files (RLIMIT_NOFILE, soft; raise it with `ulimit -n {}` or prlimit)",
                fds.next_power_of_two()
            ),
            value: n,
            needed: fds,
        });
    }
    let shm = frames_bytes + SHM_PER_PROCESS * processes as u64;
    if let Some(free) = shm_free.filter(|f| *f < shm) {
        return Err(ProcessRunError::HostLimit {
            limit: "free bytes in /dev/shm (its tmpfs size: `mount -o remount,size=… /dev/shm`)"
                .into(),
            value: free,
            needed: shm,
        });
    }
    Ok(())
}

/// This process's soft `RLIMIT_NOFILE`, if it can be read (`None`: unlimited or unknown).
pub fn nofile_soft() -> Option<u64> {
    use nix::sys::resource::{getrlimit, Resource, RLIM_INFINITY};
    getrlimit(Resource::RLIMIT_NOFILE)
        .ok()
        .map(|(soft, _)| soft)
        .filter(|s| *s != RLIM_INFINITY)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_limit_is_named_with_its_value_and_the_need() {
        assert!(check(771, Some(20_000), Some(1 << 34), 1 << 20).is_ok());
        let e = check(MAX_PARTICIPANTS + 1, None, None, 0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("MAX_PARTICIPANTS") && e.contains("1040"), "{e}");
        let e = check(771, Some(1024), None, 0).unwrap_err().to_string();
        assert!(
            e.contains("RLIMIT_NOFILE") && e.contains("1024") && e.contains("12400"),
            "{e}"
        );
        let e = check(10, None, Some(1000), 4096).unwrap_err().to_string();
        assert!(e.contains("/dev/shm") && e.contains("1000"), "{e}");
        assert!(
            check(10, None, None, u64::MAX / 2).is_ok(),
            "unknown: not refused"
        );
    }
}
