//! A simulated world's robots for ROS 2: each robot's truth (`sim/W/r<ID>/truth`, from the
//! world) and estimate (`pheromone/W/r<ID>/pose`, from its localizer) read as one more
//! receiver of their links (the roles' senders discard for a full receiver, never wait), and
//! turned into `/robot_<id>/true_pose`, `…/estimated_pose` (PoseWithCovarianceStamped) and
//! `…/true_path`, `…/estimated_path` (nav_msgs/Path) as `sim --record` writes them
//! ([`crate::robot`]). Robots are found by looking for their services, so robots that start
//! later are picked up. Stamps are the messages' simulated time (docs/ros2.md).

use std::collections::{BTreeMap, VecDeque};

use crate::deps::{PoseMsg, TruthMsg};
use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use pheromone_field::process::link::Receiver;
use pheromone_field::shm::{AttachError, ReceiveError, Svc};
use pheromone_field::wire::{ready_service, RobotServices, ROBOT_LINK};

use crate::grid::Stamp;
use crate::rmw_zenoh::{resolve_topic, NameError};
use crate::robot::{covariance_6x6, path_cdr, pose_with_covariance_cdr, Pose2};
use crate::types::{TypeInfo, PATH, POSE_COV_STAMPED};

/// Ids looked for when no `--robots` list is given: `r0` … `r<DISCOVER_MAX - 1>`.
pub const DISCOVER_MAX: u32 = 64;

/// A robot's four topics, in this order: true pose, estimated pose, true path, estimated path.
pub fn robot_topics(namespace: &str, id: u32) -> Result<[(String, TypeInfo); 4], NameError> {
    let (pose, path) = (TypeInfo::of(POSE_COV_STAMPED), TypeInfo::of(PATH));
    let t = |s: &str| resolve_topic(namespace, &format!("robot_{id}/{s}"));
    Ok([
        (t("true_pose")?, pose.clone()),
        (t("estimated_pose")?, pose),
        (t("true_path")?, path.clone()),
        (t("estimated_path")?, path),
    ])
}

/// A trajectory of at most `max` poses: when full, the oldest pose goes and is counted.
#[derive(Debug, Clone)]
pub struct BoundedPath {
    poses: VecDeque<(Stamp, Pose2)>,
    max: usize,
    pub dropped: u64,
}

impl BoundedPath {
    pub fn new(max: usize) -> Self {
        Self {
            poses: VecDeque::with_capacity(max.min(4096)),
            max: max.max(1),
            dropped: 0,
        }
    }

    /// Appends a pose; a pose not later than the last one (a repeated step) is ignored.
    pub fn push(&mut self, stamp: Stamp, p: Pose2) {
        if self.poses.back().is_some_and(|&(s, _)| s >= stamp) {
            return;
        }
        if self.poses.len() == self.max {
            self.poses.pop_front();
            self.dropped += 1;
        }
        self.poses.push_back((stamp, p));
    }

    pub fn len(&self) -> usize {
        self.poses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// The path as `nav_msgs/msg/Path`, stamped with its newest pose; `None` when empty.
    pub fn cdr(&mut self, frame_id: &str) -> Option<Vec<u8>> {
        let &(stamp, _) = self.poses.back()?;
        Some(path_cdr(stamp, frame_id, self.poses.make_contiguous()))
    }
}

/// What one robot's links brought since the last look.
#[derive(Debug, Default, Clone)]
pub struct Fresh {
    /// The newest true pose (CDR) and the newest estimate (CDR).
    pub true_pose: Option<Vec<u8>>,
    pub estimated_pose: Option<Vec<u8>>,
    /// Messages received (truths + estimates).
    pub received: u64,
}

/// One robot: its two receivers and its two paths.
pub struct RobotFeed {
    pub id: u32,
    truth: Receiver<TruthMsg>,
    pose: Receiver<PoseMsg>,
    pub true_path: BoundedPath,
    pub estimated_path: BoundedPath,
}

impl RobotFeed {
    /// Drains both links into the paths; the newest of each as CDR.
    pub fn drain(&mut self, frame_id: &str) -> Result<Fresh, ReceiveError> {
        let mut fresh = Fresh::default();
        let mut last_truth = None;
        while let Some(t) = self.truth.try_recv()? {
            fresh.received += 1;
            let stamp = Stamp::from_secs(t.sim_time_s);
            let p = [t.x_m, t.y_m, t.theta_rad];
            self.true_path.push(stamp, p);
            last_truth = Some((stamp, p));
        }
        let mut last_pose = None;
        while let Some(m) = self.pose.try_recv()? {
            fresh.received += 1;
            let stamp = Stamp::from_ns(m.stamp_ns.min(i64::MAX as u64) as i64);
            self.estimated_path.push(stamp, [m.x_m, m.y_m, m.theta_rad]);
            last_pose = Some((stamp, m));
        }
        fresh.true_pose =
            last_truth.map(|(s, p)| pose_with_covariance_cdr(s, frame_id, p, &[0.0; 36]));
        fresh.estimated_pose = last_pose.map(|(s, m)| {
            let p = [m.x_m, m.y_m, m.theta_rad];
            pose_with_covariance_cdr(s, frame_id, p, &covariance_6x6(&m.cov))
        });
        Ok(fresh)
    }
}

/// The robots of world `W`: the ids asked for (or any up to [`DISCOVER_MAX`]) whose services
/// exist.
pub struct WorldRobots {
    world: String,
    ids: Option<Vec<u32>>,
    max_poses: usize,
    pub robots: BTreeMap<u32, RobotFeed>,
}

impl WorldRobots {
    pub fn new(world: &str, ids: Option<Vec<u32>>, max_poses: usize) -> Self {
        Self {
            world: world.to_string(),
            ids,
            max_poses,
            robots: BTreeMap::new(),
        }
    }

    /// Attaches to every robot asked for whose truth or pose service exists now (it never
    /// creates one before the roles do); returns the ids found this time.
    pub fn scan(&mut self, node: &Node<Svc>) -> Result<Vec<u32>, AttachError> {
        let ids: Vec<u32> = match &self.ids {
            Some(ids) => ids.clone(),
            None => (0..DISCOVER_MAX).collect(),
        };
        let mut found = Vec::new();
        for id in ids {
            if self.robots.contains_key(&id) {
                continue;
            }
            let s = RobotServices::new(&self.world, id);
            if !(exists(node, &s.truth) || exists(node, &s.pose)) {
                continue;
            }
            let feed = RobotFeed {
                id,
                truth: Receiver::create(node, &s.truth, &ready_service(&s.truth), ROBOT_LINK)?,
                pose: Receiver::create(node, &s.pose, &ready_service(&s.pose), ROBOT_LINK)?,
                true_path: BoundedPath::new(self.max_poses),
                estimated_path: BoundedPath::new(self.max_poses),
            };
            self.robots.insert(id, feed);
            found.push(id);
        }
        Ok(found)
    }
}

fn exists(node: &Node<Svc>, service: &str) -> bool {
    ServiceName::new(service).is_ok_and(|name| {
        ipc::Service::does_exist(&name, node.config(), MessagingPattern::PublishSubscribe)
            .unwrap_or(false)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(sec: i32) -> Stamp {
        Stamp { sec, nanosec: 0 }
    }

    #[test]
    fn a_full_path_keeps_the_newest_poses_and_counts_the_dropped() {
        let mut p = BoundedPath::new(3);
        for i in 0..5 {
            p.push(s(i), [i as f64, 0.0, 0.0]);
        }
        p.push(s(4), [9.0, 9.0, 9.0]);
        assert_eq!((p.len(), p.dropped), (3, 2));
        let b = p.cdr("map").unwrap();
        let mut r = crate::cdr::CdrReader::new(&b).unwrap();
        assert_eq!(r.i32("sec").unwrap(), 4);
        r.u32("").unwrap();
        assert_eq!(r.string("").unwrap(), "map");
        assert_eq!(r.u32("n").unwrap(), 3);
        assert_eq!(r.i32("sec").unwrap(), 2);
        r.u32("").unwrap();
        r.string("").unwrap();
        assert_eq!(r.f64("x").unwrap(), 2.0);
    }

    #[test]
    fn a_robots_topics_are_those_of_sim_record() {
        let t = robot_topics("/", 3).unwrap();
        assert_eq!(t[0].0, "/robot_3/true_pose");
        assert_eq!(t[3].0, "/robot_3/estimated_path");
        assert_eq!(
            t[1].1.dds_name,
            "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
        );
        assert_eq!(t[2].1.dds_name, "nav_msgs::msg::dds_::Path_");
        assert_eq!(
            robot_topics("/ns", 0).unwrap()[1].0,
            "/ns/robot_0/estimated_pose"
        );
    }
}
