//! What `pheromone sim` and `sim --compare-filters` share: a scenario run as separate processes
//! with the flags of `sim` (where a run writes its files: `out.rs`).

use pheromone_sim::processes::{
    run_as_processes, ProcessRunError, ProcessRunInfo, ProcessRunOptions,
};
use pheromone_sim::recording::Recording;
use pheromone_sim::ros_record::SimMcap;
use pheromone_sim::single::RunSummary;
use pheromone_world::scenario::Scenario;

use super::sim_args::SimArgs;
use super::stop::Stopped;

pub(super) fn run_processes(
    a: &SimArgs,
    scenario: &Scenario,
    progress: Option<&mut dyn FnMut(f64)>,
    record: Option<SimMcap>,
) -> anyhow::Result<(RunSummary, Recording, ProcessRunInfo)> {
    let stall = super::seconds("stall-timeout", a.stall_timeout)?;
    check_process_flags(a, scenario)?;
    let attach = a
        .attach_timeout
        .map(|v| super::seconds("attach-timeout", v))
        .transpose()?;
    run_as_processes(
        scenario,
        ProcessRunOptions {
            exe: std::env::current_exe()?,
            slam: a.slam,
            realtime: a.realtime,
            timeout: super::seconds("timeout", a.timeout)?,
            attach_timeout: attach,
            stall_timeout: stall,
            progress,
            view: a.view.clone(),
            ros2: a.ros2.clone(),
            ros2_args: ros2_args(a),
            rt_args: rt_args(a.rt_priority, a.rt_best_effort),
            remote: a.remote,
            follower_wait: a.follower_wait,
            record,
        },
    )
    .map_err(|e| match e {
        ProcessRunError::Interrupted => {
            eprintln!("sim: stopped before the run recorded a frame: nothing written");
            Stopped::by_requested().into()
        }
        e => e.into(),
    })
}

/// What the --ros2 child gets besides the run's names: the security flags, `--ros-distro`,
/// `--rmw-zenoh-release`.
fn ros2_args(a: &SimArgs) -> Vec<String> {
    let mut v = a.zenoh.to_args();
    if let Some(d) = &a.ros_distro {
        v.extend(["--ros-distro".to_string(), d.clone()]);
    }
    if let Some(r) = &a.rmw_zenoh_release {
        v.extend(["--rmw-zenoh-release".to_string(), r.clone()]);
    }
    v
}

/// `--ros-distro` with `--rmw-zenoh-release`: a release that distribution has (refused before
/// the run starts, not by its child).
fn check_ros2_release(a: &SimArgs) -> anyhow::Result<()> {
    use pheromone_ros2::rmw_zenoh::RosDistro;
    let Some(release) = &a.rmw_zenoh_release else {
        return Ok(());
    };
    let name = a.ros_distro.as_deref().unwrap_or("jazzy");
    let distro = RosDistro::from_name(name)
        .ok_or_else(|| super::bad(format!("--ros-distro {name}: unknown")))?;
    distro
        .conventions(Some(release))
        .map(|_| ())
        .map_err(super::bad_from)
}

/// What a run as processes refuses of the flags and the scenario; what it says it starts
/// beside the run (the view, the ROS 2 node).
fn check_process_flags(a: &SimArgs, scenario: &Scenario) -> anyhow::Result<()> {
    if let Some(m) = scenario.mapping() {
        if m.merge && m.merge_idle_iterations > 0 {
            return Err(super::bad(format!(
                "scenario '{}': mapping.merge_idle_iterations = {} needs --single-process (a \
                 follower process does not learn of its mapper's merges)",
                scenario.name, m.merge_idle_iterations
            )));
        }
    }
    if let Some(v) = &a.view {
        eprintln!("sim: view: http://{v}/ (stops with the run)");
    }
    if a.ros2.is_some() && !cfg!(feature = "zenoh") {
        return Err(super::bad(
            "--ros2: this build has no Zenoh: rebuild with `cargo build --release --features zenoh`",
        ));
    }
    if a.zenoh.any() && a.ros2.is_none() {
        return Err(super::bad(
            "--zenoh-config, --tls-*, --user, --password-file and --users-file are for the --ros2 \
             child: give --ros2 too",
        ));
    }
    check_ros2_release(a)?;
    if let Some(e) = &a.ros2 {
        eprintln!("sim: ros2: connecting to {e} (stops with the run)");
    }
    Ok(())
}

/// `--rt-priority N [--rt-best-effort]` for each child (none without a priority).
fn rt_args(priority: Option<i32>, best_effort: bool) -> Vec<String> {
    let Some(p) = priority else {
        return Vec::new();
    };
    let mut v = vec!["--rt-priority".to_string(), p.to_string()];
    if best_effort {
        v.push("--rt-best-effort".to_string());
    }
    v
}
