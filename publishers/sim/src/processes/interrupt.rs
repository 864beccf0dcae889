//! A run stopped by SIGINT/SIGTERM: every child stopped, the run summed up from what the children printed or, where one printed nothing, from the observer's recording.

use super::*;

/// A run stopped by SIGINT/SIGTERM once recording: every process still running is stopped
/// (SIGTERM, SIGKILL after 5 s), and the run is summed up from what the children printed as
/// they stopped, or from the observer's recording where a child printed nothing (its last
/// frame's counters for the field, the robots' last recorded poses for the world).
pub(super) fn finish_interrupted(
    scenario: &Scenario,
    observer: Observer,
    children: &Children,
    sup: &mut Supervisor,
    participants: usize,
) -> (RunSummary, Recording, ProcessRunInfo) {
    let killed = sup.stop_all(Duration::from_secs(5));
    if !killed.is_empty() {
        eprintln!(
            "sim: killed after 5 s without stopping: {}",
            killed.join(", ")
        );
    }
    let header = observer.last_header();
    let sim_time_s = observer.sim_time_s().unwrap_or(0.0);
    let world: Option<WorldSummary> = sup.last_summary(children.world);
    let field: Option<FieldRunSummary> = sup.last_summary(children.field);
    let reports = sup
        .ids()
        .into_iter()
        .filter_map(|id| {
            let summary: serde_json::Value = sup.last_summary(id)?;
            Some(ProcessReport {
                role: sup.spec(id).who(),
                summary,
            })
        })
        .collect();
    let (rec, mcap) = observer.finish_with_mcap();
    let record = match mcap.transpose() {
        Ok(totals) => totals,
        Err(e) => {
            eprintln!("sim: the --record file could not be finished: {e}");
            None
        }
    };
    let counters = match (&field, header) {
        (Some(f), _) => FieldCounters::of(f),
        (None, Some(h)) => FieldCounters {
            ticks: h.sequence,
            deposits_applied: h.deposits_applied,
            deposits_rejected: crate::single::rejected_by_reason(&h.deposits_rejected),
        },
        (None, None) => FieldCounters::default(),
    };
    let world = world.unwrap_or_else(|| world_from_recording(&rec, sim_time_s));
    let summary = run_summary(scenario, &world, &counters, &rec);
    let info = ProcessRunInfo {
        startup_s: 0.0,
        processes: participants,
        reports,
        record,
        interrupted: true,
    };
    (summary, rec, info)
}

/// The world's summary from the recording, for a world that printed none: the steps and
/// robots recorded, the last frame's time.
pub(super) fn world_from_recording(rec: &Recording, sim_time_s: f64) -> WorldSummary {
    WorldSummary {
        steps: rec
            .robots
            .values()
            .map(|r| r.len() as u64)
            .max()
            .unwrap_or(0),
        sim_time_s,
        robots: rec
            .robots
            .iter()
            .filter_map(|(&id, rows)| {
                Some(pheromone_world::RobotSummary {
                    id,
                    true_pose: rows.last()?.true_pose,
                    distance_travelled_m: rec.distance_travelled_m(id),
                    collisions: 0,
                })
            })
            .collect(),
        deposits_sent: 0,
        interrupted: true,
        startup_s: 0.0,
        participants: 0,
    }
}

/// The field's counters a run's summary takes.
#[derive(Default)]
pub(super) struct FieldCounters {
    pub(super) ticks: u64,
    pub(super) deposits_applied: u64,
    pub(super) deposits_rejected: std::collections::BTreeMap<String, u64>,
}

impl FieldCounters {
    pub(super) fn of(f: &FieldRunSummary) -> Self {
        Self {
            ticks: f.ticks,
            deposits_applied: f.deposits_applied,
            deposits_rejected: f.deposits_rejected.clone(),
        }
    }
}
