"""`pheromone sim --ros2` live on Zenoh: the bridge child (`pheromone ros2 --world`) publishes
every robot's true and estimated pose (geometry_msgs/msg/PoseWithCovarianceStamped) and paths
(nav_msgs/msg/Path); received by an `eclipse-zenoh` peer the bridge connects to, deserialized
with rosbags (Stores.ROS2_JAZZY) and compared with the run's `robot_0.csv` (docs/ros2.md).
Needs a `pheromone` binary built with `--features zenoh` and `pip install './python[zenoh]'
rosbags`; skipped without them unless PHEROMONE_REQUIRE_ZENOH=1."""

import csv
import math
import os
import struct
import threading

import numpy as np
import pytest
from ros_msgs import POSE, dds, free_port, listening_session, run_sim_watching_tokens

REQUIRED = os.environ.get("PHEROMONE_REQUIRE_ZENOH") == "1"

try:
    import zenoh  # noqa: F401  (the skip below when it is missing)
    from rosbags.typesys import Stores, get_typestore
except ImportError as e:
    if REQUIRED:
        raise
    pytest.skip(f"pip install './python[zenoh]' rosbags for these tests ({e})",
                allow_module_level=True)

PATH = "nav_msgs/msg/Path"
SIM_S = "4"


def _stamp(h):
    return h.stamp.sec + h.stamp.nanosec * 1e-9


def _yaw(q):
    return 2.0 * math.atan2(q.z, q.w)


def _rows(path):
    with open(path) as f:
        return {round(float(r["t_s"]), 6): r for r in csv.DictReader(f)}


def test_sim_ros2_publishes_poses_and_paths_that_match_the_run(tmp_path):
    store = get_typestore(Stores.ROS2_JAZZY)
    hashes = {t: store.hash_rihs01(t) for t in (POSE, PATH)}
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    got = {}
    lock = threading.Lock()

    def on_sample(s):
        with lock:
            got.setdefault(str(s.key_expr), []).append(
                (bytes(s.payload.to_bytes()), bytes(s.attachment.to_bytes())))

    out = tmp_path / "out"
    with listening_session(endpoint) as z:
        sub = z.declare_subscriber("0/robot_0/**", on_sample)
        rc, tokens, _ = run_sim_watching_tokens(
            z, ["blind-leader", "--duration", SIM_S, "--realtime", "--ros2", endpoint,
                "--out", out, "--json"], tmp_path / "sim.stderr")
        sub.undeclare()
    assert rc == 0, (tmp_path / "sim.stderr").read_text(errors="replace")

    # Liveliness: the robot's four publishers, with the hashes rosbags computes.
    pubs = sorted(tuple(t.split("/")[9:12]) for t in tokens
                  if t.split("/")[5] == "MP" and "robot_0" in t)
    assert pubs == sorted([
        ("%robot_0%estimated_path", dds(PATH), hashes[PATH]),
        ("%robot_0%estimated_pose", dds(POSE), hashes[POSE]),
        ("%robot_0%true_path", dds(PATH), hashes[PATH]),
        ("%robot_0%true_pose", dds(POSE), hashes[POSE]),
    ]), tokens
    for t in tokens:
        parts = t.split("/")
        if parts[5] == "MP" and "robot_0" in t:
            # Reliable, volatile, keep last 1 with rmw_zenoh's current defaults (volatile since
            # ros2/rmw_zenoh#521): only the depth differs from them.
            assert len(parts) == 13 and parts[12] == "::,1:,:,:,,", t
        elif parts[5] == "MP" and "%pheromone%" in t:
            # The maps: reliable, transient local, keep last 1.
            assert len(parts) == 13 and parts[12] == ":1:,1:,:,:,,", t

    def msgs(topic, t):
        key = f"0/robot_0/{topic}/{dds(t)}/{hashes[t]}"
        samples = got.get(key, [])
        for _, att in samples:
            seq, stamp_ns = struct.unpack_from("<qq", att)
            assert len(att) == 33 and att[16] == 16 and seq >= 1 and stamp_ns > 0
        return [store.deserialize_cdr(b, t) for b, _ in samples]

    truths, estimates = msgs("true_pose", POSE), msgs("estimated_pose", POSE)
    true_paths, est_paths = msgs("true_path", PATH), msgs("estimated_path", PATH)
    assert set(got) <= {f"0/robot_0/{n}/{dds(t)}/{hashes[t]}" for n, t in [
        ("true_pose", POSE), ("estimated_pose", POSE), ("true_path", PATH),
        ("estimated_path", PATH)]}, set(got)
    print(f"received: {len(truths)} true poses, {len(estimates)} estimates, "
          f"{len(true_paths)} true paths, {len(est_paths)} estimated paths")
    assert len(truths) >= 10 and len(estimates) >= 10 and true_paths and est_paths

    rows = _rows(out / "robot_0.csv")
    matched = 0
    for m in truths:
        assert m.header.frame_id == "map"
        row = rows.get(round(_stamp(m.header), 6))
        if row is None:
            continue
        matched += 1
        pos = m.pose.pose.position
        assert (pos.x, pos.y, pos.z) == pytest.approx(
            (float(row["true_x_m"]), float(row["true_y_m"]), 0.0), abs=1e-9)
        assert math.remainder(_yaw(m.pose.pose.orientation) - float(row["true_theta_rad"]),
                              2 * math.pi) == pytest.approx(0.0, abs=1e-9)
        assert not np.any(m.pose.covariance)
    assert matched >= len(truths) - 1, (matched, len(truths))

    matched = 0
    for m in estimates:
        cov = np.asarray(m.pose.covariance).reshape(6, 6)
        np.testing.assert_array_equal(cov, cov.T)
        assert np.linalg.eigvalsh(cov).min() >= -1e-12
        assert cov[0, 0] > 0 and cov[1, 1] > 0 and cov[5, 5] > 0
        # x, y, yaw in rows/columns 0, 1, 5; z, roll, pitch empty.
        assert not cov[2:5, :].any() and not cov[:, 2:5].any()
        row = rows.get(round(_stamp(m.header), 6))
        if row is None or row["est_x_m"] == "":
            continue
        matched += 1
        pos = m.pose.pose.position
        assert (pos.x, pos.y) == pytest.approx(
            (float(row["est_x_m"]), float(row["est_y_m"])), abs=1e-9)
        # est_sigma_m is the square root of Σxy's largest eigenvalue.
        sxy = np.linalg.eigvalsh(cov[:2, :2]).max()
        assert math.sqrt(sxy) == pytest.approx(float(row["est_sigma_m"]), rel=1e-6)
    assert matched >= len(estimates) - 1, (matched, len(estimates))

    for paths, poses in ((true_paths, truths), (est_paths, estimates)):
        last = paths[-1]
        stamps = [_stamp(ps.header) for ps in last.poses]
        assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
        assert len(last.poses) >= 10
        assert _stamp(last.header) == stamps[-1]
        # The path's newest pose is the pose published with that stamp.
        same = [m for m in poses if _stamp(m.header) == stamps[-1]]
        assert same, "the path's last pose was published as a pose"
        a, b = last.poses[-1].pose.position, same[-1].pose.pose.position
        assert (a.x, a.y) == (b.x, b.y)
    # The last true path ends at the latest true pose at the time it was published.
    newest_truth = max(_stamp(m.header) for m in truths)
    assert _stamp(true_paths[-1].header) <= newest_truth
