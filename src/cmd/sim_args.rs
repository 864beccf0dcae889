//! The arguments of `pheromone sim`, shared by the grid runs (`sim`) and the node-graph runs
//! (`graph`), so neither command module depends on the other.

use std::path::PathBuf;

use clap::Args;
use pheromone_world::scenario::DEFAULT_SCENARIO;

/// Run a scenario and report what happened.
///
/// By default every role runs as its own process on this host: `pheromone field --clock`, the
/// world, and for every robot a localizer, a depositor and a follower where the scenario gives
/// them, in lockstep (as fast as the processes answer). Every process is stopped at the end, on
/// Ctrl-C, or when one of them fails. `--single-process` runs the same role types in this
/// process, deterministic bit for bit for a seed.
///
/// Built-in scenarios: blind-leader (paper 000, the default), wrong-area (paper 000),
/// trail-following (paper 002), ias-ss, ias-ss-open, ias-ss-rooms (paper 004), evaporation
/// (paper 000 Figs. 6–8) and trail; or a TOML file of your own (examples/scenarios/*.toml show
/// every key; --print-scenario NAME prints one). "Paper" is one of the papers the models come
/// from (docs/glossary.md); --seed is the random seed.
///
/// Node-graph scenarios (paper 001): regions (a corridor with regions A–E; 2, 3 and 4 robots,
/// region capture against the shortest-path baseline) and regions-skeleton (8 robots on a
/// skeletonized map, 7 regions, one with Max-R 2). They run a `graph` writer and one
/// `graph-robot` process per robot and print the paper's tables (captures, final link values,
/// area capture matrix) and the time to the goal of each strategy.
#[derive(Args, Debug)]
pub struct SimArgs {
    /// Scenario: a built-in name or a TOML file.
    #[arg(default_value = DEFAULT_SCENARIO)]
    pub scenario: String,
    /// Number of robots (the first N the scenario places).
    #[arg(long, value_parser = super::int::<usize>(1, 512), value_name = "N")]
    pub robots: Option<usize>,
    /// Seed of the run (world noise, the followers' random draws).
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// Simulated seconds (default: the scenario's duration_s).
    #[arg(long, value_parser = super::secs(), value_name = "SECS")]
    pub duration: Option<f64>,
    /// Write heat maps (PNG, with the robots' true and estimated trajectories), a CSV per robot,
    /// metrics.json and run.json (the command line, version, seeds, start and end) into this
    /// directory, which must be empty unless --force [default: a new
    /// pheromone-out/<SCENARIO>/<UTC time>-<tag>/ per run; pheromone-out/latest and
    /// pheromone-out/<SCENARIO>/latest link to the newest].
    #[arg(long, value_name = "DIR", value_parser = super::check::out_dir())]
    pub out: Option<PathBuf>,
    /// Write into a non-empty --out DIR (an earlier run's files that this run does not write
    /// stay; run.json lists this run's).
    #[arg(long, requires = "out")]
    pub force: bool,
    /// Write no files.
    #[arg(long, conflicts_with = "out")]
    pub no_out: bool,
    /// Print the TOML of the built-in scenario NAME and exit, to start a scenario of your own
    /// (`pheromone sim --print-scenario wrong-area > mine.toml`, edit, `pheromone sim
    /// mine.toml`).
    #[arg(long, value_name = "NAME")]
    pub print_scenario: Option<String>,
    /// Also write the run, as it goes, to this ROS 2 MCAP file (profile ros2, CDR; for Foxglove
    /// and `ros2 bag play`), stamped with simulated time: the field as
    /// grid_map_msgs/msg/GridMap (/pheromone/grid_map) and one nav_msgs/msg/OccupancyGrid per
    /// channel at each frame the run records (snapshots_s and the last), every robot's true
    /// and estimated pose at every step (/robot_<ID>/true_pose, …/estimated_pose:
    /// geometry_msgs/msg/PoseWithCovarianceStamped) and its paths so far with each field frame
    /// (…/true_path, …/estimated_path: nav_msgs/msg/Path), and every deposit the field applied
    /// (/pheromone/deposits: pheromone_msgs/msg/Deposit). Both modes write the same messages;
    /// a run that fails or is interrupted leaves a file readable up to its last message
    /// (docs/ros2.md). Not with --trials or node-graph scenarios.
    #[arg(long, value_name = "FILE.mcap", conflicts_with = "trials", value_parser = super::check::out_file())]
    pub record: Option<PathBuf>,
    /// --record's chunk compression: none, zstd or lz4 (the readers of MCAP decompress either;
    /// zstd and lz4 need a build with the feature `record-compression` or `zenoh`).
    #[arg(long, value_name = "CODEC", value_parser = pheromone_ros2::record::ChunkCompression::NAMES, default_value = "none", requires = "record")]
    pub record_compression: String,
    /// Print one JSON metrics object on stdout.
    #[arg(long)]
    pub json: bool,
    /// Run every role in this process, in lockstep: deterministic for a seed.
    #[arg(long)]
    pub single_process: bool,
    /// Step the world on wall time (dt per step) instead of lockstep (separate processes only).
    #[arg(long, conflicts_with = "single_process")]
    pub realtime: bool,
    /// Serve `pheromone view` of the run's field and robots on ADDR (default
    /// 127.0.0.1:8080) while it runs (separate processes only); with --realtime one can watch
    /// the scenario unfold.
    #[arg(long, value_name = "ADDR", value_parser = super::check::socket_addr(), num_args = 0..=1, default_missing_value = "127.0.0.1:8080",
          conflicts_with = "single_process")]
    pub view: Option<String>,
    /// Paper 002's thin clients: the antenna robots read the field only through a `pheromone
    /// gateway` this run starts (UDP on a loopback port the system picks), by PIR requests, with
    /// no shared memory of the field; the other roles are unchanged. Lockstep holds: a robot asks
    /// again until the PIR reply comes from the frame of its step. Separate processes only
    /// (`--single-process` has no processes to put a gateway between).
    #[arg(long, conflicts_with = "single_process")]
    pub remote: bool,
    /// With --remote: N thin clients share one simulated radio channel (paper 002's shared air:
    /// listen-before-talk, random back-off, collisions, airtime at 9600 bit/s; the scenario's
    /// `[radio]` or its defaults, docs/gateway.md). The antenna robots are clients 0..R−1 (by
    /// ID), the rest send the same PIRs at the same rate; a step whose request the air loses
    /// keeps the robot's last command. metrics.radio reports delivered/sent, collisions and
    /// latency.
    #[arg(long, value_name = "N", requires = "remote", value_parser = super::int::<u32>(1, 1024))]
    pub clients: Option<u32>,
    /// Show the run in ROS 2 while it runs (a build with --features zenoh; separate processes
    /// only): starts `pheromone ros2 --field F --world W --robots IDS --connect ENDPOINT` as a
    /// child, stopped with the run, which publishes the field (/pheromone/grid_map,
    /// /pheromone/occupancy/channel_<c>) and every robot's /robot_<ID>/true_pose,
    /// …/estimated_pose and …/true_path, …/estimated_path over Zenoh in rmw_zenoh_cpp's format.
    /// ENDPOINT [default: tcp/127.0.0.1:7447, where `ros2 run rmw_zenoh_cpp rmw_zenohd`
    /// listens] is the Zenoh router or peer to connect to (docs/ros2.md). Add --realtime to
    /// watch the run at the speed of simulated time.
    #[arg(long, value_name = "ENDPOINT", value_parser = super::check::zenoh_endpoint(), num_args = 0..=1,
          default_missing_value = "tcp/127.0.0.1:7447", conflicts_with = "single_process")]
    pub ros2: Option<String>,
    /// The ROS 2 distribution of the --ros2 child's graph (`pheromone ros2 --ros-distro`:
    /// humble, jazzy, kilted or rolling). Only with --ros2.
    #[arg(long, value_name = "DISTRO", value_parser = ["humble", "jazzy", "kilted", "rolling"], requires = "ros2")]
    pub ros_distro: Option<String>,
    /// The distribution's rmw_zenoh release X.Y.Z of the --ros2 child's graph, when older than
    /// its current one (`pheromone ros2 --rmw-zenoh-release`; docs/ros2.md, "ROS 2
    /// distributions"). Only with --ros2.
    #[arg(long, value_name = "X.Y.Z", requires = "ros2")]
    pub rmw_zenoh_release: Option<String>,
    /// TLS, credentials and Zenoh configuration of the --ros2 child (`pheromone ros2`'s flags
    /// of the same names, passed on to it; docs/mirrors.md, "Security"). Only with --ros2.
    #[command(flatten)]
    pub zenoh: super::zenoh_args::ZenohArgs,
    /// How every follower process waits for the frame of its step (`pheromone follower
    /// --wait`): event, spin:US or busy-poll. The metrics do not depend on it; separate
    /// processes only.
    #[arg(
        long,
        value_name = "event|spin:US|busy-poll",
        conflicts_with = "single_process"
    )]
    pub follower_wait: Option<pheromone_field::shm::WaitPolicy>,
    /// Real-time scheduling for the run's control loops: every child but the view and the ROS 2
    /// bridge (the field, the world, each role and mapper, the gateway) gets `--rt-priority N`
    /// (SCHED_FIFO N and memory locked, docs/field.md). A child the OS refuses fails the run
    /// naming the missing permission, unless --rt-best-effort. Separate processes only.
    #[arg(long, value_parser = super::int::<i32>(1, 99), value_name = "N",
          conflicts_with = "single_process")]
    pub rt_priority: Option<i32>,
    /// With --rt-priority: every child starts anyway without what the OS refuses.
    #[arg(long, requires = "rt_priority")]
    pub rt_best_effort: bool,
    /// Every depositor deposits a constant amount, whatever its localization (the traditional
    /// scheme paper 000 argues against).
    #[arg(long)]
    pub constant: bool,
    /// Strategy of every follower that is not a route-driven leader: gradient, antenna,
    /// inverse, uniform. Regions scenarios: pheromone or shortest-path (default: both).
    #[arg(long)]
    pub strategy: Option<String>,
    /// Run T trials (seeds S, S+1, …) with the strategy and with the other sector strategy
    /// (inverse vs uniform) and report mean, standard deviation and Welch's t of the
    /// exploration (scenarios with an exploration metric). Node-graph scenarios: each run on
    /// each seed with `--localize constant` and with `rho`, and the paired t of rho − constant
    /// of the time to the goal and of the mean capture time (`regions-loop`).
    #[arg(long, value_parser = super::int::<u32>(2, 100_000), value_name = "T")]
    pub trials: Option<u32>,
    /// Run on a ROS map_server map (map.yaml + its PGM), or on a built-in map by name (from
    /// any directory): `rooms` (examples/maps/rooms.yaml, 30 m × 20 m, four rooms around a
    /// hall). A file of that name wins. Its occupied cells replace the scenario's walls, and
    /// the field and the exploration sectors cover the map.
    #[arg(long, value_name = "FILE.yaml|NAME")]
    pub map: Option<PathBuf>,
    /// Paper 004's local maps with integration: every robot maps with its range sensor and
    /// merges the maps of the robots it meets within R_C (`[mapping]`); adds
    /// `exploration_known` (sectors a robot knows, visited or merged) and the merge figures to
    /// the metrics.
    #[arg(long, conflicts_with = "no_merge")]
    pub merge: bool,
    /// Paper 004's local maps without integration: every robot maps, none exchanges.
    #[arg(long)]
    pub no_merge: bool,
    /// The communication radius R_C of --merge (m, finite and > 0).
    #[arg(long, value_parser = super::f64_pos(1e6), value_name = "R", allow_negative_numbers = true)]
    pub rc_m: Option<f64>,
    /// What the sector followers steer on (paper 004, `[mapping] steer_on`): `own-map`, each
    /// robot's own local map, merged maps included (needs --merge or --no-merge), or `shared`,
    /// the shared field [default: the scenario's, shared].
    #[arg(long, value_name = "own-map|shared")]
    pub steer: Option<pheromone_roles::mapper::SteerOn>,
    /// EKF-SLAM localizers (the map of landmarks is not given to them).
    #[arg(long)]
    pub slam: bool,
    /// Every localizer's filter: ekf (default), ukf, or pf (particle filter; turns the world's
    /// laser of paper 000 Table 1 on).
    #[arg(long, value_name = "ekf|ukf|pf", value_parser = super::roles::parse_filter, conflicts_with = "slam")]
    pub filter: Option<pheromone_roles::localizer::FilterKind>,
    /// Particles of every particle filter (10..=100000).
    #[arg(long, value_name = "N", value_parser = super::roles::parse_particles)]
    pub particles: Option<usize>,
    /// Paper 000's comparison of filters (Figs. 13–18): run the scenario once with each of ekf,
    /// ukf and pf (same seed, scripted loss off; --particles applies to the PF) and write, for
    /// one robot, `filters.csv`, the error in x, y, φ and combined against time, the deposits
    /// against time, σ against deposit (log–log) and `filters.json` (RMS errors, σ, deposits,
    /// and the correlation of ln σ and ln γ). --json prints the summary.
    #[arg(long, conflicts_with_all = ["filter", "trials", "record", "slam", "remote", "view", "ros2"])]
    pub compare_filters: bool,
    /// The robot --compare-filters compares [default: the lowest id with a depositor].
    #[arg(long, value_name = "ID", requires = "compare_filters")]
    pub compare_robot: Option<u32>,
    /// Turn every localizer's scripted loss (`loss.after_s`) off.
    #[arg(long)]
    pub no_scripted_loss: bool,
    /// The scenario's `[scripted_loss]` instead of its leader losing itself by its own filter
    /// (`wrong-area`: the old EKF loss script at 20 s; docs/localization.md).
    #[arg(long, conflicts_with = "no_scripted_loss")]
    pub scripted_loss: bool,
    /// Node-graph scenarios: every robot localizes on landmarks with the EKF (paper 001
    /// Algorithm 1; a region holder matches only its region's landmarks, the others only the
    /// free areas') and deposits on a link its constant −1 (`constant`) or −1 × ρ_t of its
    /// covariance (`rho`); the run reports the landmark comparisons and η1, η2 (eq. 13,
    /// Fig. 6). As processes each `graph-robot` owns its localizer; the metrics (all but the
    /// step times) equal --single-process's. Off by default (no localizer).
    #[arg(long, value_name = "constant|rho")]
    pub localize: Option<pheromone_graph::localize::DepositWeight>,
    /// Seconds the whole run may take before it is stopped as failed (separate processes).
    #[arg(long, value_parser = super::secs(), default_value_t = 900.0, value_name = "SECS")]
    pub timeout: f64,
    /// Seconds every process may take to start and join the run (separate processes)
    /// [default: 10 s + 0.5 s per process].
    #[arg(long, value_parser = super::secs(), value_name = "SECS")]
    pub attach_timeout: Option<f64>,
    /// Seconds a lockstep step may make no progress before the run fails (separate processes).
    #[arg(long, value_parser = super::secs(), default_value_t = 30.0, value_name = "SECS")]
    pub stall_timeout: f64,
}

impl SimArgs {
    /// `--merge` → Some(true), `--no-merge` → Some(false), neither → None.
    pub fn merge_flag(&self) -> Option<bool> {
        match (self.merge, self.no_merge) {
            (true, _) => Some(true),
            (_, true) => Some(false),
            _ => None,
        }
    }
}
