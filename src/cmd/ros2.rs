//! `pheromone ros2` (feature `zenoh`) and `pheromone record --mcap`: the field for ROS 2 tools.
//! The library is `ros2` (publishers/ros2); docs/ros2.md.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use pheromone_roles::depositor::{AmountForm, DepositorConfig};

use super::{bad, bad_from};

/// Depositor settings of `--deposit-from` (paper 000's uncertainty-aware deposit).
#[derive(Args, Debug, Clone)]
pub struct RosDepositArgs {
    /// τ of paper 000 (pheromone·m⁴): a pose deposits γ = τ / det Σxy at its peak, capped at
    /// --gamma-max.
    #[arg(long, value_parser = super::f32_pos(1e9), default_value_t = 0.2)]
    pub tau: f32,
    /// γmax, the cap on γ.
    #[arg(long, value_parser = super::f32_pos(1e9), default_value_t = 100.0)]
    pub gamma_max: f32,
    /// Sensor range z_rng (m): no cell farther than this from the pose receives pheromone.
    #[arg(long, value_parser = super::f32_pos(1e6), default_value_t = 1.0)]
    pub range_m: f32,
    /// Deposit again once the robot moved this far (m) from its last deposit; 0 = off.
    #[arg(long, value_parser = super::f64_in(0.0, 1e6), default_value_t = 0.25)]
    pub interval_m: f64,
    /// Deposit again once this many seconds (of the poses' stamps) elapsed; 0 = off.
    #[arg(long, value_parser = super::secs0(), default_value_t = 0.0)]
    pub interval_s: f64,
    /// Field channel the deposits go to.
    #[arg(long, value_parser = super::int::<u32>(0, 63), default_value_t = 0)]
    pub channel: u32,
}

impl RosDepositArgs {
    #[cfg_attr(not(feature = "zenoh"), allow(dead_code))]
    pub fn config(&self) -> DepositorConfig {
        DepositorConfig {
            tau: self.tau,
            gamma_max: self.gamma_max,
            range_m: self.range_m,
            interval_m: self.interval_m,
            interval_s: self.interval_s,
            channel: self.channel,
            // The peak is γ = τ/det Σxy capped at --gamma-max, as these flags and docs/ros2.md
            // say (eqs. 12, 14 as printed), not the sim depositors' eq. 11 intent.
            amount: AmountForm::Literal,
            ..DepositorConfig::default()
        }
    }
}

/// How the OccupancyGrids' values are scaled (docs/ros2.md, "OccupancyGrid").
#[derive(Args, Debug, Clone)]
pub struct OccupancyArgs {
    /// The OccupancyGrid scale: linear (fixed: --occupancy-min → 0, --occupancy-max → 100,
    /// clamped; the same value is the same occupancy in every frame), binary (100 from
    /// --occupancy-max up, else 0) or frame (min(0, smallest) → 0 and largest → 100 of each
    /// channel and frame: not comparable between frames).
    #[arg(long, value_name = "MODE", value_parser = pheromone_ros2::grid::OccupancyMode::NAMES, default_value = "linear")]
    pub occupancy: String,
    /// The value that is occupancy 0 (linear).
    #[arg(long, value_parser = super::f32_in(-1e9, 1e9), value_name = "V", default_value_t = 0.0)]
    pub occupancy_min: f32,
    /// The value that is occupancy 100 (linear), and binary's threshold.
    #[arg(long, value_parser = super::f32_in(-1e9, 1e9), value_name = "V", default_value_t = 1.0)]
    pub occupancy_max: f32,
    /// What a trail is: cost (occupancy as scaled) or free (100 − occupancy: the trail is free
    /// space, the rest cost).
    #[arg(long, value_name = "AS", value_parser = ["cost", "free"], default_value = "cost")]
    pub occupancy_trail: String,
    /// Cells under this value have no data: −1 (unknown) [default: only non-finite cells].
    #[arg(long, value_parser = super::f32_in(-1e9, 1e9), value_name = "V")]
    pub occupancy_unknown_below: Option<f32>,
}

impl OccupancyArgs {
    /// The library's occupancy settings; a linear or binary scale needs min < max.
    pub fn occupancy(&self) -> anyhow::Result<pheromone_ros2::grid::Occupancy> {
        use pheromone_ros2::grid::{Occupancy, OccupancyMode};
        let mode = OccupancyMode::from_name(&self.occupancy)
            .ok_or_else(|| bad(format!("--occupancy {}: unknown", self.occupancy)))?;
        if mode == OccupancyMode::Linear && self.occupancy_min >= self.occupancy_max {
            return Err(bad(format!(
                "--occupancy-min {} must be under --occupancy-max {}",
                self.occupancy_min, self.occupancy_max
            )));
        }
        Ok(Occupancy {
            mode,
            min: self.occupancy_min,
            max: self.occupancy_max,
            trail_free: self.occupancy_trail == "free",
            unknown_below: self.occupancy_unknown_below,
        })
    }
}

/// Show a running field to ROS 2 nodes over Zenoh, in the wire format of rmw_zenoh_cpp
/// (docs/ros2.md), and let ROS 2 robots deposit into it.
///
/// Publishes, at most --rate-hz times a second and each time the field publishes a frame,
/// `<ns>/pheromone/grid_map` (grid_map_msgs/msg/GridMap: every channel a float32 layer named
/// channel_<c>) and `<ns>/pheromone/occupancy/channel_<c>` (nav_msgs/msg/OccupancyGrid, the
/// channel on the scale of --occupancy), in frame --frame-id, with the field's cell size and
/// lower-left corner; both transient local with a one-sample cache (a late subscriber gets the
/// newest map at once). Each
/// --deposit-from TOPIC[=ROBOT_ID] subscribes a geometry_msgs/msg/PoseWithCovarianceStamped
/// topic (AMCL's /amcl_pose, robot_localization's pose) and turns each pose into paper 000's
/// deposit: γ = τ / det Σxy at the pose, the shape of its error ellipse, again once the robot
/// moved --interval-m. Poses with a NaN or non-positive-definite covariance, another frame_id,
/// another type or hash, or truncated CDR are refused and counted, never deposited.
///
/// Declares rmw_zenoh's liveliness tokens for the node, its publishers and subscriptions (so
/// `ros2 node list` / `ros2 topic list` show them) and attaches the sequence number, source
/// timestamp and GID to every message. Its Zenoh session opens as an rmw_zenoh node's does:
/// the file of --zenoh-config or of ZENOH_SESSION_CONFIG_URI, else rmw_zenoh's default session
/// settings (a peer connecting to the router `rmw_zenohd` at tcp/localhost:7447, listening on
/// an ephemeral localhost port, gossip scouting on); --connect, --listen and the TLS and
/// credential flags override only what they name. Needs a build with `--features zenoh`.
/// Ctrl-C stops it.
#[derive(Args, Debug)]
pub struct Ros2Args {
    /// The field to publish (it must run on this host, in this iceoryx2 domain).
    #[arg(long, default_value = "main")]
    pub field: String,
    /// Most frames published per second.
    #[arg(long, value_parser = super::f64_pos(1000.0), value_name = "HZ", default_value_t = 10.0)]
    pub rate_hz: f64,
    /// While no subscriber matches, the maps are still serialized this many times a second into
    /// their transient-local cache (a late joiner's first map is at most 1/HZ old); 0: nothing
    /// is serialized while nobody subscribes.
    #[arg(long, value_parser = super::f64_in(0.0, 1000.0), value_name = "HZ", default_value_t = 1.0)]
    pub cache_rate_hz: f64,
    /// The time base of every stamp: wall (the wall clock, a live field) or sim (the field's
    /// simulated time, and /clock is published) [default: sim with --world, else wall].
    #[arg(long, value_name = "BASE", value_parser = ["wall", "sim"])]
    pub time: Option<String>,
    #[command(flatten)]
    pub occupancy: OccupancyArgs,
    /// ROS domain id (the first component of every key expression).
    #[arg(long, value_parser = super::int::<u32>(0, 232), default_value_t = 0)]
    pub domain_id: u32,
    /// ROS namespace of the node and its relative topics.
    #[arg(long, default_value = "/")]
    pub namespace: String,
    /// ROS node name.
    #[arg(long, default_value = "pheromone")]
    pub node_name: String,
    /// frame_id of the published messages; poses in another frame are refused.
    #[arg(long, default_value = "map")]
    pub frame_id: String,
    /// The ROS 2 distribution of the graph: humble writes `TypeHashNotSupported` in keys and
    /// tokens where jazzy, kilted and rolling write the type's RIHS01 hash (poses are accepted
    /// with that distribution's form only); all follow the current rmw_zenoh release's QoS and
    /// attachment conventions (docs/ros2.md, "ROS 2 distributions").
    #[arg(long, value_name = "DISTRO", value_parser = ["humble", "jazzy", "kilted", "rolling"], default_value = "jazzy")]
    pub ros_distro: String,
    /// The distribution's rmw_zenoh release X.Y.Z, when older than its current one: Humble
    /// 0.1.0–0.1.1 and Jazzy 0.2.0–0.2.3 get the keyed attachment, Humble 0.1.0–0.1.1 and Jazzy
    /// 0.2.0–0.2.2 QoS strings against a transient-local default (docs/ros2.md, "ROS 2
    /// distributions") [default: the current release's conventions].
    #[arg(long, value_name = "X.Y.Z")]
    pub rmw_zenoh_release: Option<String>,
    /// Zenoh endpoint to connect to, e.g. a router: tcp/ROS_HOST:7447 (repeatable); replaces
    /// the configuration's connect endpoints [default: the file's, else rmw_zenoh's
    /// tcp/localhost:7447].
    #[arg(long, value_name = "ENDPOINT", value_parser = super::check::zenoh_endpoint())]
    pub connect: Vec<String>,
    /// Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7448 (repeatable); replaces the
    /// configuration's listen endpoints [default: the file's, else rmw_zenoh's
    /// tcp/localhost:0, where the router's other peers on this host connect]. An address other
    /// hosts reach should be a tls/ one with --tls-cert/--tls-key and --users-file
    /// (docs/mirrors.md, "Security").
    #[arg(long, value_name = "ENDPOINT", value_parser = super::check::zenoh_endpoint())]
    pub listen: Vec<String>,
    /// Subscribe TOPIC (PoseWithCovarianceStamped) and deposit its poses as robot ROBOT_ID
    /// [default id: 0] (repeatable; a relative TOPIC is in --namespace).
    #[arg(long, value_name = "TOPIC[=ROBOT_ID]")]
    pub deposit_from: Vec<String>,
    #[command(flatten)]
    pub deposit: RosDepositArgs,
    /// Also publish the robots of simulated world W (`pheromone sim`'s world, or `pheromone
    /// world --name W`): per robot <ns>/robot_<ID>/true_pose and …/estimated_pose
    /// (geometry_msgs/msg/PoseWithCovarianceStamped: the world's truth with a zero covariance,
    /// the localizer's estimate with its x, y, yaw covariance), the newest of each as it comes,
    /// and …/true_path, …/estimated_path (nav_msgs/msg/Path) every 1/--path-rate-hz s, stamped
    /// with simulated time. Robots are found as their services appear (checked every second).
    #[arg(long, value_name = "W")]
    pub world: Option<String>,
    /// With --world: only these robot ids (comma-separated) [default: every robot found,
    /// ids 0–63].
    #[arg(long, value_name = "IDS", value_delimiter = ',', requires = "world")]
    pub robots: Option<Vec<u32>>,
    /// With --world: paths published per second.
    #[arg(long, value_parser = super::f64_pos(1000.0), value_name = "HZ", default_value_t = 1.0)]
    pub path_rate_hz: f64,
    /// With --world: poses a path keeps at most; beyond it the oldest pose is dropped (and
    /// counted: path_poses_dropped in --json).
    #[arg(long, value_parser = super::int::<usize>(1, 10_000_000), value_name = "N", default_value_t = 10_000)]
    pub path_max_poses: usize,
    /// Seconds to wait for the field and its first frame.
    #[arg(long, value_parser = super::secs(), value_name = "SECS", default_value_t = 10.0)]
    pub timeout: f64,
    /// Stop after this many seconds.
    #[arg(long, value_parser = super::secs(), value_name = "SECS")]
    pub duration: Option<f64>,
    /// Once listening, print each endpoint with its port on stdout (as `bridge` does).
    #[arg(long)]
    pub print_address: bool,
    #[command(flatten)]
    pub zenoh: super::zenoh_args::ZenohArgs,
    /// At exit, print one JSON summary on stdout: counts, refusals, bytes, latency p50/p99.
    #[arg(long)]
    pub json: bool,
}

#[cfg(feature = "zenoh")]
fn parse_deposit_from(s: &str) -> anyhow::Result<pheromone_ros2::node::DepositFrom> {
    let (topic, id) = match s.split_once('=') {
        Some((t, id)) => {
            let id = id.parse::<u32>().map_err(|e| {
                bad(format!(
                    "--deposit-from {s}: robot id {id:?} is not a number: {e}"
                ))
            })?;
            (t, id)
        }
        None => (s, 0),
    };
    Ok(pheromone_ros2::node::DepositFrom {
        topic: topic.to_string(),
        robot_id: id,
    })
}

#[cfg(feature = "zenoh")]
pub fn run(a: Ros2Args) -> anyhow::Result<()> {
    use pheromone_ros2::node::{Ros2Error, Ros2Node};
    pheromone_field::shm::check_name(&a.field).map_err(bad_from)?;
    let options = ros2_options(&a)?;
    let node = pheromone_field::shm::create_node(&format!("ros2-{}", std::process::id()))?;
    let timeout = Duration::from_secs_f64(a.timeout);
    let ros = Ros2Node::start(&node, options, timeout).map_err(|e| match e {
        Ros2Error::Name(_) | Ros2Error::Depositor(_) | Ros2Error::Session(_) => bad_from(e),
        e => e.into(),
    })?;
    announce(&a, &ros)?;
    let summary = ros.run(&node, a.duration.map(Duration::from_secs_f64))?;
    if a.json {
        println!("{summary}");
    }
    Ok(())
}

/// The node's options from its flags (their parsers have checked the numbers).
#[cfg(feature = "zenoh")]
fn ros2_options(a: &Ros2Args) -> anyhow::Result<pheromone_ros2::node::Ros2Options> {
    let session = pheromone_ros2::session::SessionSettings {
        security: a.zenoh.security(),
        env_file: None,
        listen: a.listen.clone(),
        connect: a.connect.clone(),
        admin_space: a.print_address,
    }
    .with_env();
    // A configuration that cannot be built (a file that does not parse) is refused now.
    session.config().map_err(bad_from)?;
    let deposit_from = a
        .deposit_from
        .iter()
        .map(|s| parse_deposit_from(s))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let depositor = a.deposit.config();
    depositor.validate().map_err(bad_from)?;
    let distro = pheromone_ros2::rmw_zenoh::RosDistro::from_name(&a.ros_distro)
        .ok_or_else(|| bad(format!("--ros-distro {}: unknown", a.ros_distro)))?;
    Ok(pheromone_ros2::node::Ros2Options {
        field: a.field.clone(),
        domain_id: a.domain_id,
        namespace: a.namespace.clone(),
        node_name: a.node_name.clone(),
        frame_id: a.frame_id.clone(),
        distro,
        conventions: distro
            .conventions(a.rmw_zenoh_release.as_deref())
            .map_err(bad_from)?,
        rate_hz: a.rate_hz,
        cache_rate_hz: a.cache_rate_hz,
        time: time_base(a)?,
        occupancy: a.occupancy.occupancy()?,
        session,
        deposit_from,
        depositor,
        world: world_options(a)?,
    })
}

/// `--world`'s options.
#[cfg(feature = "zenoh")]
fn world_options(a: &Ros2Args) -> anyhow::Result<Option<pheromone_ros2::node::WorldOptions>> {
    let Some(world) = &a.world else {
        return Ok(None);
    };
    pheromone_field::shm::check_name(world).map_err(bad_from)?;
    Ok(Some(pheromone_ros2::node::WorldOptions {
        world: world.clone(),
        robots: a.robots.clone(),
        path_rate_hz: a.path_rate_hz,
        path_max_poses: a.path_max_poses,
    }))
}

/// `--time`: simulated time by default with `--world` (whose poses carry simulated time, so
/// `--time wall` is refused with it), else the wall clock.
#[cfg(feature = "zenoh")]
fn time_base(a: &Ros2Args) -> anyhow::Result<pheromone_ros2::frames::TimeBase> {
    use pheromone_ros2::frames::TimeBase;
    let default = if a.world.is_some() { "sim" } else { "wall" };
    let name = a.time.as_deref().unwrap_or(default);
    let time = TimeBase::from_name(name).ok_or_else(|| bad(format!("--time {name}: unknown")))?;
    if time == TimeBase::Wall && a.world.is_some() {
        return Err(bad(
            "--time wall with --world: the world's poses carry simulated time (one time base \
             a session: --time sim)",
        ));
    }
    Ok(time)
}

#[cfg(feature = "zenoh")]
fn announce(a: &Ros2Args, ros: &pheromone_ros2::node::Ros2Node) -> anyhow::Result<()> {
    use std::io::Write;
    eprintln!(
        "ros2 '{}': node {} in {}, publishing {:?}, depositing from {:?}",
        a.field,
        a.node_name,
        a.namespace,
        ros.topics().names,
        ros.subscription_topics()
    );
    if a.print_address {
        let mut out = std::io::stdout().lock();
        for l in ros.listen_locators()? {
            writeln!(out, "{l}")?;
        }
        out.flush()?;
    }
    Ok(())
}

#[cfg(not(feature = "zenoh"))]
pub fn run(_a: Ros2Args) -> anyhow::Result<()> {
    Err(bad(
        "this build has no Zenoh: rebuild with `cargo build --release --features zenoh`",
    ))
}

/// Record a running field as a ROS 2 MCAP file (profile ros2, ros2msg schemas, CDR messages)
/// for `ros2 bag play` and Foxglove: the GridMap and OccupancyGrid messages `pheromone ros2`
/// publishes, at most --rate-hz frames a second. Each frame's messages close a chunk and are
/// flushed, so a killed recorder leaves a file readable up to its last frame; Ctrl-C (or
/// --duration) finishes it with its summary.
#[derive(Args, Debug)]
pub struct RecordArgs {
    /// The field to record.
    #[arg(long, default_value = "main")]
    pub field: String,
    /// Output MCAP file.
    #[arg(long, value_name = "FILE", value_parser = super::check::out_file())]
    pub mcap: PathBuf,
    /// Most frames recorded per second.
    #[arg(long, value_parser = super::f64_pos(1000.0), value_name = "HZ", default_value_t = 10.0)]
    pub rate_hz: f64,
    /// ROS namespace of the topics.
    #[arg(long, default_value = "/")]
    pub namespace: String,
    /// frame_id of the messages.
    #[arg(long, default_value = "map")]
    pub frame_id: String,
    /// Seconds to wait for the field and its first frame.
    #[arg(long, value_parser = super::secs(), value_name = "SECS", default_value_t = 10.0)]
    pub timeout: f64,
    /// Stop after this many seconds.
    #[arg(long, value_parser = super::secs(), value_name = "SECS")]
    pub duration: Option<f64>,
    /// Stop after this many frames.
    #[arg(long, value_parser = super::int::<u64>(1, 1_000_000_000_000), value_name = "N")]
    pub frames: Option<u64>,
    #[command(flatten)]
    pub occupancy: OccupancyArgs,
    /// At exit, print one JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run_record(a: RecordArgs) -> anyhow::Result<()> {
    use pheromone_ros2::run::{record_field, RecordOptions};
    pheromone_field::shm::check_name(&a.field).map_err(bad_from)?;
    let options = RecordOptions {
        field: a.field.clone(),
        mcap: a.mcap.clone(),
        rate_hz: a.rate_hz,
        namespace: a.namespace.clone(),
        frame_id: a.frame_id.clone(),
        timeout: Duration::from_secs_f64(a.timeout),
        duration: a.duration.map(Duration::from_secs_f64),
        frames: a.frames,
        occupancy: a.occupancy.occupancy()?,
    };
    let node = pheromone_field::shm::create_node(&format!("record-{}", std::process::id()))?;
    let summary = match record_field(&node, &options) {
        Ok(s) => s,
        Err(e) if e.is_bad_input() => return Err(bad_from(e)),
        Err(e) => return Err(e.into()),
    };
    if a.json {
        println!("{}", summary.json(&options));
    }
    Ok(())
}
