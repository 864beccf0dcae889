//! `--rt-priority N [--rt-cpu C] [--rt-best-effort]`: real-time scheduling for the processes
//! that serve a control loop (the field, the gateway, every robot role), the work of
//! `pheromone_field::process::realtime`.

use clap::Args;

use super::bad;

/// Real-time scheduling options, the same for every process that takes them.
#[derive(Args, Debug, Clone, Default)]
pub struct RtArgs {
    /// Real-time scheduling: SCHED_FIFO at priority N (1–99) and every page locked in memory
    /// (mlockall, so shared memory is faulted in before the loop starts). Without CAP_SYS_NICE
    /// or a large enough RLIMIT_RTPRIO (and CAP_IPC_LOCK or RLIMIT_MEMLOCK) the process refuses
    /// to start and says which is missing, unless --rt-best-effort.
    #[arg(long, value_parser = super::int::<i32>(1, 99), value_name = "N")]
    pub rt_priority: Option<i32>,
    /// With --rt-priority: run on this CPU only.
    #[arg(long, value_parser = super::int::<usize>(0, 1023), value_name = "CPU", requires = "rt_priority")]
    pub rt_cpu: Option<usize>,
    /// With --rt-priority: start anyway without what the OS refuses, and say what it refused.
    #[arg(long, requires = "rt_priority")]
    pub rt_best_effort: bool,
}

impl RtArgs {
    /// Applies what was asked (nothing without --rt-priority) and says what it got on stderr,
    /// as `who` ("field 'main'", "gateway", "depositor r3"). A priority the OS refuses is exit
    /// status 1 naming what is missing; a bad priority is bad input (2).
    pub fn apply(&self, who: &str) -> anyhow::Result<()> {
        let Some(priority) = self.rt_priority else {
            return Ok(());
        };
        let o = pheromone_field::process::realtime::RealtimeOptions {
            priority,
            cpu: self.rt_cpu,
            best_effort: self.rt_best_effort,
        };
        let applied = match pheromone_field::process::realtime::apply(&o) {
            Ok(applied) => applied,
            Err(e @ pheromone_field::process::realtime::RealtimeError::Priority(_)) => {
                return Err(bad(e.to_string()))
            }
            Err(e) => return Err(e.into()),
        };
        for refused in &applied.refused {
            eprintln!("{who}: going on without it (--rt-best-effort): {refused}");
        }
        eprintln!(
            "{who}: real-time: SCHED_FIFO {}, memory {}, CPU {}",
            applied
                .fifo_priority
                .map_or("refused".to_string(), |p| format!("priority {p}")),
            if applied.memory_locked {
                "locked"
            } else {
                "not locked"
            },
            applied.cpu.map_or("any".to_string(), |c| c.to_string()),
        );
        Ok(())
    }
}
