"""`pheromone ros2` and `pheromone record --mcap` checked from outside, with independent
implementations: `eclipse-zenoh` receives and sends in rmw_zenoh_cpp's format, `rosbags`
(Stores.ROS2_JAZZY, grid_map_msgs registered from its jazzy .msg files) computes the type
hashes and (de)serializes CDR, `mcap` reads the recorded file (docs/ros2.md).

A real field (two channels, no evaporation: after the deposits every frame holds the same
cells) and a real node on a loopback port. Needs a `pheromone` binary built with
`--features zenoh` and `pip install './python[zenoh]' rosbags mcap`; without them the tests
are skipped, unless PHEROMONE_REQUIRE_ZENOH=1 (tests/all.sh), where they fail instead."""

import json
import math
import os
import signal
import struct
import subprocess
import time

import numpy as np
import pytest
from ros_msgs import GRID, OCC, POSE, dds, free_port, register_grid_map

import pheromone
from conftest import BIN, STARTED_PIDS, deadline_loop, probe, run_cli

REQUIRED = os.environ.get("PHEROMONE_REQUIRE_ZENOH") == "1"

try:
    import zenoh
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
except ImportError as e:
    if REQUIRED:
        raise
    pytest.skip(f"pip install './python[zenoh]' rosbags mcap for these tests ({e})",
                allow_module_level=True)

TWO_CHANNELS = """
width = 40
height = 30
cell_size_m = 0.1
origin_x_m = -1.0
origin_y_m = 0.5
tick_hz = 50.0

[[channel]]
name = "trail"
evaporation = { model = "none" }

[[channel]]
name = "other"
evaporation = { model = "none" }
"""


@pytest.fixture(scope="module")
def store():
    return register_grid_map(get_typestore(Stores.ROS2_JAZZY), get_types_from_msg)


@pytest.fixture(scope="module")
def zenoh_bin():
    p = subprocess.run([str(BIN), "ros2", "--field", "no/such", "--listen", "tcp/127.0.0.1:1"],
                       capture_output=True, text=True, timeout=30)
    if "no Zenoh" in p.stderr or "unrecognized subcommand" in p.stderr:
        msg = f"{BIN} has no `ros2` with Zenoh (cargo build --features zenoh): {p.stderr.strip()}"
        if REQUIRED:
            pytest.fail(msg)
        pytest.skip(msg)
    return BIN


class Ros2Node:
    """`pheromone ros2` on the field, listening on a free port; `--rate-hz 20` unless the
    caller's arguments set it."""

    def __init__(self, tmp_path, field, *args):
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.err = open(tmp_path / "ros2.stderr", "wb")
        rate = [] if "--rate-hz" in args else ["--rate-hz", "20"]
        self.proc = subprocess.Popen(
            [str(BIN), "ros2", "--field", field, "--listen", self.endpoint, "--json", *rate,
             *args],
            stdout=subprocess.PIPE, stderr=self.err)
        STARTED_PIDS.add(self.proc.pid)

    def stop(self):
        """SIGINT; the --json summary."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            out, _ = self.proc.communicate(timeout=15)
        except subprocess.TimeoutExpired as e:
            self.proc.kill()
            self.proc.communicate()
            raise AssertionError("pheromone ros2 did not stop on SIGINT") from e
        self.err.close()
        text = open(self.err.name, errors="replace").read()
        assert self.proc.returncode == 0, f"pheromone ros2 exited {self.proc.returncode}: {text}"
        return json.loads(out.decode().strip().splitlines()[-1])


@pytest.fixture
def ros2_node(tmp_path, zenoh_bin):
    started = []

    def start(field, *args):
        n = Ros2Node(tmp_path, field, *args)
        started.append(n)
        return n

    yield start
    for n in started:
        if n.proc.poll() is None:
            n.stop()


def _session(endpoint):
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    # No shared-memory transport: eclipse-zenoh's would leave a `<n>.zenoh` file in /dev/shm
    # (our node speaks TCP only; rmw_zenoh's peers likewise fall back to the network).
    conf.insert_json5("transport/shared_memory/enabled", "false")
    # The node listens once the field has published its first frame.
    conf.insert_json5("connect/timeout_ms", "15000")
    conf.insert_json5(
        "connect/retry", "{period_init_ms: 100, period_max_ms: 500, period_increase_factor: 2}")
    return zenoh.open(conf)


def _tokens(session, want):
    """The liveliness tokens under @ros2_lv once there are `want` of them."""
    for _ in deadline_loop(15, f"{want} liveliness tokens"):
        toks = sorted(str(r.ok.key_expr) for r in session.liveliness().get("@ros2_lv/**",
                                                                             timeout=2.0)
                      if r.ok is not None)
        if len(toks) >= want:
            return toks
        time.sleep(0.1)


def _recv(sub, what, timeout_s=15):
    for _ in deadline_loop(timeout_s, what):
        s = sub.try_recv()
        if s is not None:
            return s
        time.sleep(0.01)


def _deposit_cells(field_name):
    with pheromone.Field.attach(field_name, timeout_s=10) as f:
        f.deposit(0.05, 1.05, 0.5, cov=(0.01, 0.0, 0.01))
        f.deposit(1.45, 3.05, 0.3, cov=(0.02, 0.0, 0.01), channel=1)
        for _ in deadline_loop(10, "2 deposits applied"):
            f.wait_frame(0.2)
            with f.frame() as fr:
                if fr.header.deposits_applied >= 2:
                    return fr.header.sequence


def test_topics_tokens_and_messages_are_rmw_zenohs_and_equal_the_field(
        start_field, ros2_node, store, tmp_path):
    cfg = tmp_path / "two.toml"
    cfg.write_text(TWO_CHANNELS)
    f = start_field("r2", "--config", str(cfg))
    _deposit_cells(f.name)
    node = ros2_node(f.name, "--deposit-from", "/amcl_pose=3", "--domain-id", "7",
                     "--occupancy", "frame")
    npy = tmp_path / "frame.npy"
    run_cli("export", "--field", f.name, "--out", npy)
    cells = np.load(npy)
    assert cells.shape == (2, 30, 40)
    hashes = {t: store.hash_rihs01(t) for t in (GRID, OCC, POSE)}
    with _session(node.endpoint) as s:
        toks = _tokens(s, 5)
        zid = toks[0].split("/")[2]
        assert all(t.split("/")[:3] == ["@ros2_lv", "7", zid] for t in toks), toks
        by_kind = {}
        for t in toks:
            parts = t.split("/")
            by_kind.setdefault(parts[5], []).append(parts)
        assert [p[6:] for p in by_kind["NN"]] == [["%", "%", "pheromone"]]
        pubs = sorted((p[9], p[10], p[11]) for p in by_kind["MP"])
        assert pubs == sorted([("%pheromone%grid_map", dds(GRID), hashes[GRID]),
                               ("%pheromone%occupancy%channel_0", dds(OCC), hashes[OCC]),
                               ("%pheromone%occupancy%channel_1", dds(OCC), hashes[OCC])])
        [sub_tok] = by_kind["MS"]
        assert sub_tok[9:12] == ["%amcl_pose", dds(POSE), hashes[POSE]]
        for p in by_kind["MP"] + by_kind["MS"]:
            assert len(p) == 13 and p[3] == "0" and p[4].isdigit(), p
            assert p[12].count(":") == 5, p  # reliability:durability:history,depth:…
        assert len({p[4] for p in by_kind["MP"] + by_kind["MS"] + by_kind["NN"]}) == 5

        grid_sub = s.declare_subscriber("7/pheromone/grid_map/**")
        occ_sub = s.declare_subscriber("7/pheromone/occupancy/channel_1/**")
        for _ in deadline_loop(15, "a GridMap of a frame after the deposits"):
            sample = _recv(grid_sub, "a GridMap")
            msg = store.deserialize_cdr(bytes(sample.payload.to_bytes()), GRID)
            if msg.header.stamp.sec > 0:
                break
        assert str(sample.key_expr) == f"7/pheromone/grid_map/{dds(GRID)}/{hashes[GRID]}"
        att = bytes(sample.attachment.to_bytes())
        seq, stamp_ns = struct.unpack_from("<qq", att)
        assert len(att) == 33 and att[16] == 16 and seq >= 1
        assert abs(stamp_ns - time.time_ns()) < 30e9
        assert msg.header.frame_id == "map"
        assert list(msg.layers) == ["channel_0", "channel_1"]
        assert msg.info.resolution == pytest.approx(0.1)
        assert (msg.info.length_x, msg.info.length_y) == pytest.approx((4.0, 3.0))
        assert (msg.info.pose.position.x, msg.info.pose.position.y) == pytest.approx((1.0, 2.0))
        for c in range(2):
            arr = msg.data[c]
            assert [(d.label, d.size, d.stride) for d in arr.layout.dim] == [
                ("column_index", 30, 1200), ("row_index", 40, 40)]
            # Column-major from the corner of largest x and y: the plane back to front.
            np.testing.assert_array_equal(arr.data[::-1].reshape(30, 40), cells[c])

        occ_sample = _recv(occ_sub, "an OccupancyGrid")
        assert str(occ_sample.key_expr) == (
            f"7/pheromone/occupancy/channel_1/{dds(OCC)}/{hashes[OCC]}")
        occ = store.deserialize_cdr(bytes(occ_sample.payload.to_bytes()), OCC)
        assert (occ.info.width, occ.info.height) == (40, 30)
        assert occ.info.resolution == pytest.approx(0.1)
        assert (occ.info.origin.position.x, occ.info.origin.position.y) == pytest.approx(
            (-1.0, 0.5))
        plane = cells[1]
        lo, hi = min(0.0, float(plane.min())), float(plane.max())
        want = np.clip(np.round(100 * (plane - lo) / (hi - lo)), 0, 100).astype(np.int8)
        np.testing.assert_array_equal(occ.data.reshape(30, 40), want)
        assert occ.data.max() == 100 and occ.data.min() == 0
    summary = node.stop()
    assert summary["ros2"]["frames_published"] >= 1 and summary["refused_total"] == 0


def _pose_cdr(store, x, y, cov_xx, cov_xy, cov_yy, frame="map", sec=100):
    Time = store.types["builtin_interfaces/msg/Time"]
    Header = store.types["std_msgs/msg/Header"]
    G = {n: store.types[f"geometry_msgs/msg/{n}"] for n in
         ("Point", "Quaternion", "Pose", "PoseWithCovariance", "PoseWithCovarianceStamped")}
    cov = np.zeros(36)
    cov[0], cov[1], cov[6], cov[7], cov[35] = cov_xx, cov_xy, cov_xy, cov_yy, 0.01
    msg = G["PoseWithCovarianceStamped"](
        header=Header(stamp=Time(sec=sec, nanosec=0), frame_id=frame),
        pose=G["PoseWithCovariance"](
            pose=G["Pose"](position=G["Point"](x=x, y=y, z=0.0),
                           orientation=G["Quaternion"](x=0.0, y=0.0, z=math.sin(0.2),
                                                       w=math.cos(0.2))),
            covariance=cov))
    return bytes(store.serialize_cdr(msg, POSE))


def test_amcl_poses_deposit_and_bad_ones_are_refused(start_field, ros2_node, store, tmp_path):
    cfg = tmp_path / "two.toml"
    cfg.write_text(TWO_CHANNELS)
    f = start_field("dep", "--config", str(cfg))
    node = ros2_node(f.name, "--deposit-from", "/amcl_pose=3", "--tau", "0.2")
    key = f"0/amcl_pose/{dds(POSE)}/{store.hash_rihs01(POSE)}"
    # Cell centres: x = -1.0 + (col + 0.5)·0.1, y = 0.5 + (row + 0.5)·0.1.
    x, y = -1.0 + 10.5 * 0.1, 0.5 + 20.5 * 0.1
    cov = (0.1, 0.02, 0.2)
    gamma = 0.2 / (cov[0] * cov[2] - cov[1] ** 2)  # τ / det Σxy = 10.526…
    with _session(node.endpoint) as s:
        _tokens(s, 5)
        pub = s.declare_publisher(key)
        gid = bytes(range(16))

        sent = [0]

        def put(payload, k=None):
            sent[0] += 1
            att = struct.pack("<qq", sent[0], time.time_ns()) + b"\x10" + gid
            if k is None:
                pub.put(payload, attachment=att)
            else:
                s.put(k, payload, attachment=att)

        bad_nan = _pose_cdr(store, 0.5, 1.5, float("nan"), 0.0, 0.1)
        bad_neg = _pose_cdr(store, 0.5, 1.5, -0.1, 0.0, 0.1)
        good = _pose_cdr(store, x, y, *cov)
        put(bad_nan)
        put(bad_neg)
        put(good[:-9])  # truncated covariance
        put(good, k=f"0/amcl_pose/{dds(POSE)}/RIHS01_{'0' * 64}")
        put(_pose_cdr(store, 0.5, 1.5, *cov, frame="odom"))
        put(good)
        for _ in deadline_loop(15, "the AMCL pose's deposit in the field"):
            got = json.loads(run_cli("probe", "--field", f.name, "--x", repr(x), "--y", repr(y),
                                     "--json", "--timeout", "10"))
            if got["deposits_applied"] >= 1:
                break
            time.sleep(0.05)
    assert got["value"] == pytest.approx(gamma, rel=1e-5)
    assert got["deposits_applied"] == 1 and got["deposits_rejected"] == 0
    # Nothing anywhere else: the refused poses at (0.5, 1.5) left no trace.
    assert probe(f.name, 0.55, 1.55)["value"] == 0.0
    summary = node.stop()["ros2"]
    assert summary["poses_received"] == 6
    assert summary["deposits_sent"] == 1
    assert summary["refused_pose"] == {"non_finite": 1, "not_psd": 1}
    assert (summary["refused_cdr"], summary["refused_type"], summary["refused_frame"]) == (1, 1, 1)


def test_record_writes_a_ros2_mcap_that_rosbags_reads(start_field, store, tmp_path):
    cfg = tmp_path / "two.toml"
    cfg.write_text(TWO_CHANNELS)
    f = start_field("rec", "--config", str(cfg))
    _deposit_cells(f.name)
    out = tmp_path / "field.mcap"
    rec = json.loads(run_cli("record", "--field", f.name, "--mcap", out, "--frames", "3",
                             "--rate-hz", "20", "--json", timeout=60))
    assert rec["frames"] == 3 and rec["messages"] == 9
    npy = tmp_path / "frame.npy"
    run_cli("export", "--field", f.name, "--out", npy)
    cells = np.load(npy)
    counts, last_grid, stamps = {}, None, []
    with open(out, "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            # The schema text defines the type rosbags knows, with the same hash.
            ts = get_typestore(Stores.EMPTY)
            ts.register(get_types_from_msg(schema.data.decode(), schema.name))
            assert ts.hash_rihs01(schema.name) == store.hash_rihs01(schema.name)
            msg = store.deserialize_cdr(message.data, schema.name)
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert message.log_time == stamp
            if schema.name == GRID:
                last_grid = msg
                stamps.append(stamp)
    assert counts == {"/pheromone/grid_map": 3, "/pheromone/occupancy/channel_0": 3,
                      "/pheromone/occupancy/channel_1": 3}
    assert stamps == sorted(stamps) and abs(stamps[-1] - time.time_ns()) < 60e9
    for c in range(2):
        np.testing.assert_array_equal(last_grid.data[c].data[::-1].reshape(30, 40), cells[c])


def test_nothing_is_serialized_while_nobody_subscribes(start_field, ros2_node, tmp_path):
    """Zenoh's matching status: with --cache-rate-hz 0 (no refresh of the maps' transient-local
    cache), frames due while no subscriber matches any topic are counted and not serialized; a
    subscriber that comes gets the next frame."""
    cfg = tmp_path / "two.toml"
    cfg.write_text(TWO_CHANNELS)
    f = start_field("idle", "--config", str(cfg))
    node = ros2_node(f.name, "--cache-rate-hz", "0")
    with _session(node.endpoint) as s:
        _tokens(s, 4)
        # 10 field frames (0.2 s at 50 Hz: about 4 of the node's 20 Hz periods), nobody listening.
        with pheromone.Field.attach(f.name, timeout_s=10) as field:
            with field.frame() as fr:
                first = fr.header.sequence
            for _ in deadline_loop(10, "10 field frames"):
                field.wait_frame(0.2)
                with field.frame() as fr:
                    if fr.header.sequence >= first + 10:
                        break
        got = []
        sub = s.declare_subscriber("0/pheromone/grid_map/**", got.append)
        for _ in deadline_loop(15, "a GridMap once a subscriber came"):
            if got:
                break
            time.sleep(0.02)
        sub.undeclare()
    summary = node.stop()["ros2"]
    assert summary["frames_without_subscribers"] >= 1, summary
    assert summary["frames_for_cache"] == 0, summary
    assert summary["frames_published"] >= 1, summary
    assert summary["messages_published"] == 3 * summary["frames_published"], summary
