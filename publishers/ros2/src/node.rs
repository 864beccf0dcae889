//! The ROS 2 node over Zenoh (`pheromone ros2`): publishes the field's GridMap and
//! OccupancyGrids at a chosen rate, each frame serialized straight from shared memory once
//! the field's frame-ready event wakes it, and turns the `PoseWithCovarianceStamped`s of its
//! `--deposit-from` topics into seed 000 deposits through the depositor library. Liveliness
//! tokens announce the node, its publishers and its subscriptions to the ROS graph; every
//! sample carries rmw_zenoh's attachment ([`crate::rmw_zenoh`]). With a world (`--world`), it also
//! publishes each robot's true and estimated pose and paths ([`crate::robots`]), declaring a
//! robot's publishers when the robot is found.
//!
//! The maps (GridMap, OccupancyGrids) are offered transient local with a one-sample cache,
//! declared as rmw_zenoh declares a transient-local publisher (`rmw_publisher_data.cpp`:
//! zenoh-ext's `AdvancedPublisher` with a cache of `depth` samples, publisher detection and,
//! being reliable, sporadic heartbeats every 500 ms for sample-miss detection), so a late
//! joiner gets the newest map when it subscribes. In simulated time (`--time sim`) the node
//! also publishes `/clock`.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::shm::{now_ns, DepositPublisher, FieldReader, ShmError, Svc};
use thiserror::Error;
use zenoh::handlers::FifoChannelHandler;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::{CongestionControl, Reliability};
use zenoh::sample::Sample;
use zenoh::Wait;

use crate::deps::depositor::{Depositor, DepositorConfig, DepositorConfigError};
use crate::frames::{clock_cdr, frame_messages, wall_now_ns, FieldTopics, TimeBase};
use crate::grid::{Occupancy, Stamp};
use crate::pose::{check_pose, PoseWithCovarianceStamped};
use crate::rmw_zenoh::{
    self, split_topic_key, topic_key, Attachment, AttachmentLayout, Conventions, EntityKind,
    NameError, NodeIdentity, Qos, RosDistro,
};
use crate::robots::{robot_topics, WorldRobots};
use crate::session::{SessionConfigError, SessionSettings};
use crate::types::{TypeInfo, CLOCK, POSE_COV_STAMPED};

#[derive(Debug, Error)]
pub enum Ros2Error {
    #[error(transparent)]
    Shm(#[from] ShmError),
    #[error(transparent)]
    Name(#[from] NameError),
    #[error(transparent)]
    Depositor(#[from] DepositorConfigError),
    #[error(transparent)]
    Session(#[from] SessionConfigError),
    #[error("zenoh: {action}: {detail}")]
    Zenoh { action: String, detail: String },
    #[error("field {0}: no frame within the timeout")]
    NoFrame(String),
}

pheromone_field::from_shm_errors!(Ros2Error);

fn zerr(action: impl Into<String>, e: impl std::fmt::Display) -> Ros2Error {
    Ros2Error::Zenoh {
        action: action.into(),
        detail: e.to_string(),
    }
}

/// A `--deposit-from TOPIC[=ROBOT_ID]` subscription.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DepositFrom {
    pub topic: String,
    pub robot_id: u32,
}

#[derive(Debug, Clone)]
pub struct Ros2Options {
    pub field: String,
    pub domain_id: u32,
    pub namespace: String,
    pub node_name: String,
    pub frame_id: String,
    /// Whose rmw_zenoh conventions the keys and tokens follow.
    pub distro: RosDistro,
    /// The conventions of the distribution's rmw_zenoh release (`--rmw-zenoh-release`): the
    /// attachment layout, the default durability of the tokens' QoS strings.
    pub conventions: Conventions,
    pub rate_hz: f64,
    /// While no subscriber matches, the maps are still serialized this often (per second) into
    /// their transient-local cache, so a late joiner gets a map at most 1/`cache_rate_hz` old
    /// at once; 0: never (nothing serialized while nobody subscribes).
    pub cache_rate_hz: f64,
    /// The session's time base: every stamp, and `/clock` in simulated time.
    pub time: TimeBase,
    /// How the OccupancyGrids' values are scaled.
    pub occupancy: Occupancy,
    /// The Zenoh session: rmw_zenoh's settings, a file's, and the flags over them.
    pub session: SessionSettings,
    pub deposit_from: Vec<DepositFrom>,
    pub depositor: DepositorConfig,
    /// The simulated world whose robots to publish, if any.
    pub world: Option<WorldOptions>,
}

/// `--world W [--robots IDS] [--path-rate-hz HZ] [--path-max-poses N]`.
#[derive(Debug, Clone)]
pub struct WorldOptions {
    pub world: String,
    /// The robots to publish; `None`: every robot found (ids below `robots::DISCOVER_MAX`).
    pub robots: Option<Vec<u32>>,
    /// Paths published per second (each robot's two).
    pub path_rate_hz: f64,
    /// Poses a path keeps at most (the newest).
    pub path_max_poses: usize,
}

/// What the node did, cumulative.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Ros2Stats {
    pub frames_published: u64,
    /// Frames due while no subscriber matched any of the field's topics (Zenoh's matching
    /// status): nothing was serialized for them.
    pub frames_without_subscribers: u64,
    /// Frames serialized while no subscriber matched, only to keep the maps' transient-local
    /// cache fresh (at most `cache_rate_hz` a second).
    pub frames_for_cache: u64,
    /// `/clock` messages published (`--time sim`).
    pub clock_published: u64,
    pub messages_published: u64,
    pub bytes_published: u64,
    pub last_sequence: u64,
    pub poses_received: u64,
    pub deposits_sent: u64,
    pub deposits_skipped_interval: u64,
    /// The field took no deposit (not running, or its buffer full).
    pub deposits_not_taken: u64,
    /// Samples on a `--deposit-from` topic with another type name or type hash in their key.
    pub refused_type: u64,
    /// Truncated or malformed CDR.
    pub refused_cdr: u64,
    /// Poses in another frame than `--frame-id`.
    pub refused_frame: u64,
    /// Refused poses by reason (`non_finite`, `not_psd`, `not_positive_definite`, …).
    pub refused_pose: BTreeMap<String, u64>,
    /// Samples on `--deposit-from` topics by attachment layout (`positional`, `keyed`, `none`,
    /// `other`); an attachment is not required.
    pub attachments: BTreeMap<String, u64>,
    /// `--world`: robots found, truths and estimates received from their links, poses and
    /// paths published, and poses the paths dropped at `--path-max-poses` (oldest first).
    pub robots_found: u64,
    pub robot_messages_received: u64,
    pub robot_poses_published: u64,
    pub robot_paths_published: u64,
    pub path_poses_dropped: u64,
}

impl Ros2Stats {
    pub fn refused_total(&self) -> u64 {
        self.refused_type
            + self.refused_cdr
            + self.refused_frame
            + self.refused_pose.values().sum::<u64>()
    }
}

/// A volatile topic's plain publisher, or a transient-local topic's advanced one (with its
/// cache).
enum ZPublisher {
    Volatile(Publisher<'static>),
    TransientLocal(zenoh_ext::AdvancedPublisher<'static>),
}

struct RosPublisher {
    publisher: ZPublisher,
    _token: LivelinessToken,
    gid: [u8; 16],
    sequence: i64,
    layout: AttachmentLayout,
}

impl RosPublisher {
    /// Whether a subscriber somewhere matches the publisher (Zenoh's matching status; if it
    /// cannot be read, as if one did).
    fn matched(&self) -> bool {
        let status = match &self.publisher {
            ZPublisher::Volatile(p) => p.matching_status().wait(),
            ZPublisher::TransientLocal(p) => p.matching_status().wait(),
        };
        status.map_or(true, |s| s.matching())
    }

    fn put(&mut self, cdr: Vec<u8>) -> Result<(), Ros2Error> {
        self.sequence += 1;
        let att = Attachment {
            sequence_number: self.sequence,
            source_timestamp_ns: wall_now_ns(),
            source_gid: self.gid,
        }
        .encode_as(self.layout);
        let (done, key) = match &self.publisher {
            ZPublisher::Volatile(p) => (p.put(cdr).attachment(att).wait(), p.key_expr()),
            ZPublisher::TransientLocal(p) => (p.put(cdr).attachment(att).wait(), p.key_expr()),
        };
        done.map_err(|e| zerr(format!("put {key}"), e))
    }
}

struct RosSubscription {
    topic: String,
    subscriber: Subscriber<FifoChannelHandler<Sample>>,
    _token: LivelinessToken,
    depositor: Depositor,
    robot_id: u32,
}

/// The running node.
pub struct Ros2Node {
    o: Ros2Options,
    session: zenoh::Session,
    _node_token: LivelinessToken,
    reader: FieldReader,
    deposits: Option<DepositPublisher>,
    topics: FieldTopics,
    publishers: Vec<RosPublisher>,
    /// `/clock` (`--time sim`) and the newest time it published.
    clock: Option<(RosPublisher, Stamp)>,
    subscriptions: Vec<RosSubscription>,
    pose_type: TypeInfo,
    identity: NodeIdentity,
    /// The next entity id a publisher gets.
    next_entity: u32,
    world: Option<WorldBridge>,
    period: Duration,
    /// When the next frame is due (`None`: the first frame is).
    next_publish: Option<Instant>,
    /// While nobody subscribes: when the maps' cache is refreshed.
    cache: CacheRefresh,
    /// Frame-to-publish latencies (µs), one per published frame.
    pub latencies_us: Vec<u32>,
    pub stats: Ros2Stats,
}

/// The QoS of the robots' topics: reliable, volatile, keep last 1.
pub const PUBLISHER_QOS: Qos = Qos {
    reliable: true,
    transient_local: false,
    depth: 1,
};
/// The QoS of the maps (GridMap, OccupancyGrids): reliable, transient local, keep last 1, as a
/// map server offers them.
pub const MAP_QOS: Qos = Qos {
    reliable: true,
    transient_local: true,
    depth: 1,
};
/// The QoS of `/clock`: rclcpp's `ClockQoS` (the sensor-data profile with depth 1: best
/// effort, volatile, keep last 1), what simulators and `ros2 bag play --clock` offer.
pub const CLOCK_QOS: Qos = Qos {
    reliable: false,
    transient_local: false,
    depth: 1,
};
/// The QoS of `--deposit-from` subscriptions: reliable, volatile, keep last 10.
pub const SUBSCRIPTION_QOS: Qos = Qos {
    reliable: true,
    transient_local: false,
    depth: 10,
};

impl Ros2Node {
    /// Attaches to the field (waiting up to `timeout` for its first frame), opens the Zenoh
    /// session and declares the node's publishers, subscriptions and liveliness tokens.
    pub fn start(node: &Node<Svc>, o: Ros2Options, timeout: Duration) -> Result<Self, Ros2Error> {
        let namespace = rmw_zenoh::namespace(&o.namespace)?;
        let name = rmw_zenoh::node_name(&o.node_name)?;
        let mut reader = FieldReader::attach_within(node, &o.field, timeout)?;
        let channels = match reader.wait_until(timeout, |_| true)? {
            Some(f) => f.header.channels as usize,
            None => return Err(Ros2Error::NoFrame(o.field.clone())),
        };
        let mut topics = FieldTopics::new(&namespace, channels)?;
        topics.types = topics.types.iter().map(|t| o.distro.type_info(t)).collect();
        let deposits = if o.deposit_from.is_empty() {
            None
        } else {
            Some(DepositPublisher::attach(node, &o.field, u32::MAX)?)
        };
        let config = o.session.config()?;
        let session = zenoh::open(config)
            .wait()
            .map_err(|e| zerr(format!("open session ({})", o.session.origin()), e))?;
        let identity = NodeIdentity {
            domain_id: o.domain_id,
            zid: session.info().zid().wait().to_string(),
            namespace,
            name,
            conventions: o.conventions,
        };
        let node_token = declare_token(&session, &identity.token(EntityKind::Node, 0, None))?;
        let mut publishers = Vec::new();
        for (i, (topic, t)) in topics.names.iter().zip(&topics.types).enumerate() {
            publishers.push(declare_publisher(
                &session,
                &identity,
                1 + i as u32,
                (topic, t),
                MAP_QOS,
            )?);
        }
        let mut next_id = 1 + publishers.len() as u32;
        let clock = match o.time {
            TimeBase::Sim => {
                let topic = rmw_zenoh::resolve_topic("/", "/clock")?;
                let t = o.distro.type_info(&TypeInfo::of(CLOCK));
                let p = declare_publisher(&session, &identity, next_id, (&topic, &t), CLOCK_QOS)?;
                next_id += 1;
                Some((p, Stamp::default()))
            }
            TimeBase::Wall => None,
        };
        let pose_type = o.distro.type_info(&TypeInfo::of(POSE_COV_STAMPED));
        let mut subscriptions = Vec::new();
        for (i, d) in o.deposit_from.iter().enumerate() {
            let id = next_id + i as u32;
            subscriptions.push(declare_subscription(
                &session,
                &identity,
                id,
                d,
                &pose_type,
                &o.depositor,
            )?);
        }
        let period = Duration::from_secs_f64(1.0 / o.rate_hz);
        let o_cache_rate_hz = o.cache_rate_hz;
        let next_entity = next_id + subscriptions.len() as u32;
        let world = o.world.as_ref().map(WorldBridge::new);
        Ok(Self {
            o,
            session,
            _node_token: node_token,
            reader,
            deposits,
            topics,
            publishers,
            clock,
            subscriptions,
            pose_type,
            identity,
            next_entity,
            world,
            period,
            next_publish: None,
            cache: CacheRefresh::new(o_cache_rate_hz),
            latencies_us: Vec::new(),
            stats: Ros2Stats::default(),
        })
    }

    /// The field's topics (absolute names) and their types.
    pub fn topics(&self) -> &FieldTopics {
        &self.topics
    }

    /// The `--deposit-from` topics (absolute names).
    pub fn subscription_topics(&self) -> Vec<String> {
        self.subscriptions.iter().map(|s| s.topic.clone()).collect()
    }

    /// The endpoints the session listens on (needs `admin_space`).
    pub fn listen_locators(&self) -> Result<Vec<String>, Ros2Error> {
        crate::deps::listen_locators(&self.session).map_err(|e| zerr("listen locators", e))
    }

    /// One round: takes the poses that came, waits up to `timeout` for a frame and publishes
    /// it if the rate allows.
    pub fn step(&mut self, timeout: Duration) -> Result<(), Ros2Error> {
        self.take_poses();
        if self.reader.wait_frame(timeout)? {
            self.publish_clock()?;
            if self.due() {
                self.publish_frame()?;
            }
        }
        self.take_poses();
        Ok(())
    }

    /// `--world`: looks for new robots (once a second), publishes the newest true and
    /// estimated pose of every robot that sent one, and the paths when they are due.
    pub fn step_robots(&mut self, node: &Node<Svc>) -> Result<(), Ros2Error> {
        let Some(w) = self.world.as_mut() else {
            return Ok(());
        };
        if Instant::now() >= w.next_scan {
            w.next_scan = Instant::now() + ROBOT_SCAN_PERIOD;
            for id in w.robots.scan(node)? {
                let mut pubs = Vec::with_capacity(4);
                for (topic, t) in robot_topics(&self.identity.namespace, id)? {
                    pubs.push(declare_publisher(
                        &self.session,
                        &self.identity,
                        self.next_entity,
                        (&topic, &self.o.distro.type_info(&t)),
                        PUBLISHER_QOS,
                    )?);
                    self.next_entity += 1;
                }
                w.publishers.insert(id, pubs);
                self.stats.robots_found += 1;
                eprintln!("ros2: robot {id} of world {}", w.name);
            }
        }
        let paths_due = Instant::now() >= w.next_path;
        if paths_due {
            w.next_path = Instant::now() + w.path_period;
        }
        let frame_id = self.o.frame_id.as_str();
        for (id, feed) in w.robots.robots.iter_mut() {
            let Some(pubs) = w.publishers.get_mut(id) else {
                continue;
            };
            let fresh = feed.drain(frame_id)?;
            self.stats.robot_messages_received += fresh.received;
            for (i, m) in [(0, fresh.true_pose), (1, fresh.estimated_pose)] {
                if let Some(m) = m {
                    self.stats.bytes_published += m.len() as u64;
                    pubs[i].put(m)?;
                    self.stats.robot_poses_published += 1;
                    self.stats.messages_published += 1;
                }
            }
            if paths_due {
                let paths = [
                    (2, feed.true_path.cdr(frame_id)),
                    (3, feed.estimated_path.cdr(frame_id)),
                ];
                for (i, m) in paths {
                    if let Some(m) = m {
                        self.stats.bytes_published += m.len() as u64;
                        pubs[i].put(m)?;
                        self.stats.robot_paths_published += 1;
                        self.stats.messages_published += 1;
                    }
                }
            }
        }
        self.stats.path_poses_dropped = w
            .robots
            .robots
            .values()
            .map(|f| f.true_path.dropped + f.estimated_path.dropped)
            .sum();
        Ok(())
    }

    /// The robots published so far (`--world`).
    pub fn robot_ids(&self) -> Vec<u32> {
        self.world
            .as_ref()
            .map(|w| w.publishers.keys().copied().collect())
            .unwrap_or_default()
    }

    /// Whether a frame arriving now is published: a tenth of a period early counts as on time,
    /// so frames of a field ticking at a multiple of the rate are not skipped by jitter.
    fn due(&self) -> bool {
        self.next_publish
            .is_none_or(|t| Instant::now() + self.period / 10 >= t)
    }

    /// Deadlines advance by whole periods (no drift); a node that fell behind starts over.
    fn schedule_next(&mut self) {
        let now = Instant::now();
        self.next_publish = Some(match self.next_publish {
            Some(t) if t + self.period > now => t + self.period,
            _ => now + self.period,
        });
    }

    /// `--time sim`: the newest frame's field time on `/clock`, when it advanced and someone
    /// subscribes.
    fn publish_clock(&mut self) -> Result<(), Ros2Error> {
        let Some((p, last)) = self.clock.as_mut() else {
            return Ok(());
        };
        let Some(frame) = self.reader.frame() else {
            return Ok(());
        };
        let stamp = TimeBase::Sim.frame_stamp(frame.header);
        if stamp > *last && p.matched() {
            p.put(clock_cdr(stamp))?;
            *last = stamp;
            self.stats.clock_published += 1;
            self.stats.messages_published += 1;
        }
        Ok(())
    }

    fn publish_frame(&mut self) -> Result<(), Ros2Error> {
        let matched = self.publishers.iter().any(RosPublisher::matched);
        if !matched && !self.cache.due(Instant::now()) {
            // Nobody listens and the cache is fresh enough: the frame is not serialized (the
            // schedule goes on).
            self.schedule_next();
            self.stats.frames_without_subscribers += 1;
            return Ok(());
        }
        let Some(fm) = frame_messages(
            &self.reader,
            &self.o.frame_id,
            self.o.time,
            &self.o.occupancy,
        ) else {
            return Ok(());
        };
        if !matched {
            self.stats.frames_for_cache += 1;
        }
        if fm.messages.len() != self.publishers.len() {
            // The field restarted with another channel count: its topics are not ours.
            return Ok(());
        }
        self.schedule_next();
        for (p, m) in self.publishers.iter_mut().zip(fm.messages) {
            self.stats.bytes_published += m.len() as u64;
            p.put(m)?;
            self.stats.messages_published += 1;
        }
        let latency_ns = now_ns().saturating_sub(fm.stamp_mono_ns);
        self.latencies_us
            .push((latency_ns / 1000).min(u32::MAX as u64) as u32);
        self.stats.frames_published += 1;
        self.stats.last_sequence = fm.sequence;
        Ok(())
    }

    fn take_poses(&mut self) {
        for s in &mut self.subscriptions {
            while let Ok(Some(sample)) = s.subscriber.try_recv() {
                self.stats.poses_received += 1;
                handle_pose(
                    &sample,
                    &self.pose_type,
                    &self.o.frame_id,
                    s,
                    self.deposits.as_mut(),
                    &mut self.stats,
                );
            }
        }
    }

    /// Frame-to-publish latency percentile `q` (0–1) in µs, over the frames published.
    pub fn latency_percentile_us(&self, q: f64) -> Option<u32> {
        let mut v = self.latencies_us.clone();
        if v.is_empty() {
            return None;
        }
        v.sort_unstable();
        let i = ((v.len() - 1) as f64 * q).round() as usize;
        Some(v[i])
    }

    /// The field it publishes.
    pub fn field(&self) -> &str {
        &self.o.field
    }

    /// Flushes the deposits sent and closes the session (tokens are withdrawn).
    pub fn close(mut self) {
        if let Some(d) = self.deposits.as_mut() {
            d.flush(Duration::from_secs(1));
        }
        let _ = self.session.close().wait();
    }
}

/// While nobody subscribes, when the maps' transient-local cache gets a fresh frame: at most once
/// a period (`--cache-rate-hz`; never for 0), the first one at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct CacheRefresh {
    period: Option<Duration>,
    next: Option<Instant>,
}

impl CacheRefresh {
    fn new(rate_hz: f64) -> Self {
        Self {
            period: (rate_hz > 0.0).then(|| Duration::from_secs_f64(1.0 / rate_hz)),
            next: None,
        }
    }

    /// Whether a frame due at `now` goes into the cache (and if so, when the next one may).
    fn due(&mut self, now: Instant) -> bool {
        let Some(period) = self.period else {
            return false;
        };
        if self.next.is_some_and(|t| now < t) {
            return false;
        }
        self.next = Some(now + period);
        true
    }
}

/// How often `--world` looks for robots it has not found yet.
const ROBOT_SCAN_PERIOD: Duration = Duration::from_secs(1);

/// `--world`: the robots' links and their publishers (true pose, estimated pose, true path,
/// estimated path, in this order).
struct WorldBridge {
    name: String,
    robots: WorldRobots,
    publishers: BTreeMap<u32, Vec<RosPublisher>>,
    path_period: Duration,
    next_path: Instant,
    next_scan: Instant,
}

impl WorldBridge {
    fn new(o: &WorldOptions) -> Self {
        Self {
            name: o.world.clone(),
            robots: WorldRobots::new(&o.world, o.robots.clone(), o.path_max_poses),
            publishers: BTreeMap::new(),
            path_period: Duration::from_secs_f64(1.0 / o.path_rate_hz),
            next_path: Instant::now(),
            next_scan: Instant::now(),
        }
    }
}

fn declare_token(session: &zenoh::Session, key: &str) -> Result<LivelinessToken, Ros2Error> {
    session
        .liveliness()
        .declare_token(key.to_string())
        .wait()
        .map_err(|e| zerr(format!("declare liveliness token {key}"), e))
}

/// rmw_zenoh's heartbeat period for a reliable transient-local publisher
/// (`SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD`, rmw_publisher_data.cpp).
const SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD: Duration = Duration::from_millis(500);

/// Declares a publisher of `topic` with QoS `qos` as rmw_zenoh's `PublisherData::make` does
/// (rmw_publisher_data.cpp): congestion control *drop* (keep-last), the reliability of the QoS,
/// and for transient local zenoh-ext's advanced publisher with a cache of `depth` samples,
/// publisher detection and, when reliable, sporadic heartbeats; then its liveliness token.
fn declare_publisher(
    session: &zenoh::Session,
    identity: &NodeIdentity,
    entity_id: u32,
    (topic, t): (&str, &TypeInfo),
    qos: Qos,
) -> Result<RosPublisher, Ros2Error> {
    use zenoh_ext::{AdvancedPublisherBuilderExt, CacheConfig, MissDetectionConfig};
    let token_key = identity.token(EntityKind::Publisher, entity_id, Some((topic, t, qos)));
    let key = topic_key(identity.domain_id, topic, t);
    let builder = session
        .declare_publisher(key.clone())
        .congestion_control(CongestionControl::Drop)
        .reliability(if qos.reliable {
            Reliability::Reliable
        } else {
            Reliability::BestEffort
        });
    let err = |e| zerr(format!("declare publisher {key}"), e);
    let publisher = if qos.transient_local {
        let mut b = builder
            .advanced()
            .cache(CacheConfig::default().max_samples(qos.depth as usize))
            .publisher_detection();
        if qos.reliable {
            let miss = MissDetectionConfig::default()
                .sporadic_heartbeat(SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD);
            b = b.sample_miss_detection(miss);
        }
        ZPublisher::TransientLocal(b.wait().map_err(err)?)
    } else {
        ZPublisher::Volatile(builder.wait().map_err(err)?)
    };
    Ok(RosPublisher {
        publisher,
        _token: declare_token(session, &token_key)?,
        gid: rmw_zenoh::gid(&token_key),
        sequence: 0,
        layout: identity.conventions.attachment_layout(),
    })
}

fn declare_subscription(
    session: &zenoh::Session,
    identity: &NodeIdentity,
    entity_id: u32,
    d: &DepositFrom,
    t: &TypeInfo,
    config: &DepositorConfig,
) -> Result<RosSubscription, Ros2Error> {
    let topic = rmw_zenoh::resolve_topic(&identity.namespace, &d.topic)?;
    let token_key = identity.token(
        EntityKind::Subscription,
        entity_id,
        Some((&topic, t, SUBSCRIPTION_QOS)),
    );
    // Any type and hash: a sample of another type is refused and counted, not silently missed.
    let key = format!("{}/{}/*/*", identity.domain_id, topic.trim_matches('/'));
    let subscriber = session
        .declare_subscriber(key.clone())
        .wait()
        .map_err(|e| zerr(format!("subscribe {key}"), e))?;
    Ok(RosSubscription {
        topic,
        subscriber,
        _token: declare_token(session, &token_key)?,
        depositor: Depositor::new(config.clone())?,
        robot_id: d.robot_id,
    })
}

/// Checks one sample of a `--deposit-from` topic and deposits it, counting whatever is refused.
fn handle_pose(
    sample: &Sample,
    t: &TypeInfo,
    frame_id: &str,
    s: &mut RosSubscription,
    deposits: Option<&mut DepositPublisher>,
    stats: &mut Ros2Stats,
) {
    let layout = match sample.attachment() {
        None => "none",
        Some(a) => Attachment::decode_any(&a.to_bytes()).map_or("other", |(_, l)| l.name()),
    };
    *stats.attachments.entry(layout.to_string()).or_default() += 1;
    let key = sample.key_expr().as_str();
    let typed = split_topic_key(key).is_some_and(|(_, ty, h)| ty == t.dds_name && h == t.hash);
    if !typed {
        stats.refused_type += 1;
        eprintln!("ros2: {key}: refused: not {} {}", t.dds_name, t.hash);
        return;
    }
    let payload = sample.payload().to_bytes();
    let msg = match PoseWithCovarianceStamped::from_cdr(&payload) {
        Ok(m) => m,
        Err(e) => {
            stats.refused_cdr += 1;
            eprintln!("ros2: {}: refused: {e}", s.topic);
            return;
        }
    };
    if msg.frame_id != frame_id {
        stats.refused_frame += 1;
        eprintln!(
            "ros2: {}: refused: frame_id {:?}, the field's is {frame_id:?}",
            s.topic, msg.frame_id
        );
        return;
    }
    let pose = msg.to_pose_msg(s.robot_id);
    if let Err(e) = check_pose(&pose) {
        *stats.refused_pose.entry(e.name().to_string()).or_default() += 1;
        eprintln!("ros2: {}: {e}", s.topic);
        return;
    }
    match s.depositor.process(&pose) {
        Ok(Some(mut d)) => {
            // The field's stamps are CLOCK_MONOTONIC: the publisher stamps it on sending.
            d.stamp_ns = 0;
            match deposits.map(|p| p.send_as(d)) {
                Some(Ok(())) => stats.deposits_sent += 1,
                _ => stats.deposits_not_taken += 1,
            }
        }
        Ok(None) => stats.deposits_skipped_interval += 1,
        Err(e) => {
            *stats
                .refused_pose
                .entry(e.reason().name().to_string())
                .or_default() += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cache_is_refreshed_at_most_once_a_period_and_never_at_rate_zero() {
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        let mut c = CacheRefresh::new(2.0);
        // Frames due every 100 ms for 1.2 s: the first, then one every 500 ms.
        let cached: Vec<u64> = (0..12)
            .filter(|&i| c.due(t0 + ms(100 * i)))
            .map(|i| 100 * i)
            .collect();
        assert_eq!(cached, [0, 500, 1000]);
        let mut never = CacheRefresh::new(0.0);
        assert!(!(0..10).any(|i| never.due(t0 + ms(1000 * i))));
    }
}
