"""`pheromone ros2` behind a Zenoh router configured as ROS 2's `rmw_zenohd`, seen by peers
configured as rmw_zenoh_cpp configures a node (docs/ros2.md, "Zenoh session").

The router is eclipse-zenoh in router mode with the settings of upstream's
`DEFAULT_RMW_ZENOH_ROUTER_CONFIG.json5` (python/tests/rmw_zenohd/*.json5, each citing its
commit), on the newest eclipse-zenoh (the `zenoh` extra, 1.10.2) and on the oldest Zenoh 1.x
that rmw_zenoh releases shipped (1.1.0, in the venv $PHEROMONE_OLD_ZENOH_PYTHON, default
.venv-zenoh-old, which tests/all.sh installs). The ROS side is eclipse-zenoh peers with the
settings of upstream's `DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5` (peer mode, connect to the router
only, listen on an ephemeral localhost port, multicast scouting off, gossip scouting on, to the
router): nothing of ours. They know only the router's address; they must see the node's
liveliness tokens, receive its GridMap and OccupancyGrid samples, and a pose they publish (CDR
written from the message's documented layout, with rmw_zenoh's attachment) must become a deposit
in the field. The node is started with nothing but `--connect ROUTER` (or nothing but
ZENOH_SESSION_CONFIG_URI), as docs/ros2.md tells a user to."""

import json
import math
import os
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from ros_msgs import GRID, OCC, POSE, dds, free_port, register_grid_map
from ros_msgs import ONE_CHANNEL_FIELD as FIELD

from conftest import BIN, REPO, STARTED_PIDS, deadline_loop, run_cli

REQUIRED = os.environ.get("PHEROMONE_REQUIRE_ZENOH") == "1"

try:
    import zenoh
    import zenoh.ext
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
except ImportError as e:
    if REQUIRED:
        raise
    pytest.skip(f"pip install './python[zenoh,ros2]' for these tests ({e})",
                allow_module_level=True)

HERE = Path(__file__).resolve().parent
ROUTER_PY = HERE / "rmw_zenohd" / "router.py"
OLD_PYTHON = Path(os.environ.get("PHEROMONE_OLD_ZENOH_PYTHON",
                                 REPO / ".venv-zenoh-old" / "bin" / "python"))
#: eclipse-zenoh version → (python, router configuration of that generation).
ROUTERS = {
    "1.10.2": (Path(sys.executable), HERE / "rmw_zenohd" / "router_rolling.json5"),
    "1.1.0": (OLD_PYTHON, HERE / "rmw_zenohd" / "router_2024.json5"),
}


@pytest.fixture(scope="module")
def store():
    return register_grid_map(get_typestore(Stores.ROS2_JAZZY), get_types_from_msg)


class Router:
    """router.py under the given interpreter; stopped by closing its stdin, killed if needed."""

    def __init__(self, version, tmp_path):
        python, config = ROUTERS[version]
        if not python.exists():
            msg = (f"no Python with eclipse-zenoh {version} at {python} (tests/all.sh creates "
                   "it; or set PHEROMONE_OLD_ZENOH_PYTHON)")
            if REQUIRED:
                pytest.fail(msg)
            pytest.skip(msg)
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.err = open(tmp_path / f"router-{version}.stderr", "wb")
        self.proc = subprocess.Popen([str(python), str(ROUTER_PY), str(config), self.endpoint],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self.err)
        STARTED_PIDS.add(self.proc.pid)
        line = b""
        for _ in deadline_loop(30, f"the eclipse-zenoh {version} router to start"):
            if self.proc.poll() is not None:
                pytest.fail(f"the router exited {self.proc.returncode}: "
                            f"{open(self.err.name).read()}")
            if select.select([self.proc.stdout], [], [], 0.1)[0]:
                line = self.proc.stdout.readline()
                break
        words = line.decode().split()
        assert words[:1] == ["ready"], line
        self.version = words[1]
        assert self.version == version, f"router.py ran eclipse-zenoh {self.version}"

    def stop(self):
        if self.proc.poll() is None:
            self.proc.stdin.close()
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc.stdout.close()
        self.err.close()


@pytest.fixture(params=list(ROUTERS))
def router(request, tmp_path):
    r = Router(request.param, tmp_path)
    try:
        yield r
    finally:
        r.stop()


def ros_peer(router_endpoint):
    """A session configured as rmw_zenoh_cpp's DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5 configures
    a node (commit 30f303058d00e8c6ca476c553280c012a6dabfb4: mode, connect, listen, scouting,
    timestamping, shared_memory), pointed at the test's router instead of tcp/localhost:7447."""
    conf = zenoh.Config()
    for key, value in [
        ("mode", '"peer"'),
        ("connect/endpoints", json.dumps([router_endpoint])),
        ("listen/endpoints", '["tcp/localhost:0"]'),
        ("scouting/multicast/enabled", "false"),
        ("scouting/gossip/enabled", "true"),
        ("scouting/gossip/multihop", "false"),
        ("scouting/gossip/target", '{router: ["router", "peer"], peer: ["router"]}'),
        ("scouting/gossip/autoconnect", '{router: [], peer: ["router", "peer"]}'),
        ("timestamping/enabled", "{router: true, peer: true, client: true}"),
        ("queries_default_timeout", "60000"),
        ("transport/shared_memory/enabled", "false"),
    ]:
        conf.insert_json5(key, value)
    return zenoh.open(conf)


class Node:
    """`pheromone ros2` with the given arguments and environment; --json summary on SIGINT."""

    def __init__(self, tmp_path, field, args, env=None):
        self.err_path = tmp_path / "ros2.stderr"
        self.err = open(self.err_path, "wb")
        rate = [] if "--rate-hz" in args else ["--rate-hz", "20"]
        self.proc = subprocess.Popen(
            [str(BIN), "ros2", "--field", field, "--json", *rate, *args],
            stdout=subprocess.PIPE, stderr=self.err, env={**os.environ, **(env or {})})
        STARTED_PIDS.add(self.proc.pid)

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            out, _ = self.proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.communicate()
            raise AssertionError("pheromone ros2 did not stop on SIGINT") from None
        finally:
            self.err.close()
        text = self.err_path.read_text(errors="replace")
        assert self.proc.returncode == 0, f"pheromone ros2 exited {self.proc.returncode}: {text}"
        return json.loads(out.decode().strip().splitlines()[-1])


@pytest.fixture
def start_node(tmp_path):
    nodes = []

    def start(field, *args, env=None):
        n = Node(tmp_path, field, args, env)
        nodes.append(n)
        return n

    yield start
    for n in nodes:
        if n.proc.poll() is None:
            n.stop()


def _tokens(session, want, timeout_s=20):
    for _ in deadline_loop(timeout_s, f"{want} liveliness tokens through the router"):
        toks = sorted(str(r.ok.key_expr) for r in session.liveliness().get("@ros2_lv/**",
                                                                             timeout=2.0)
                      if r.ok is not None)
        if len(toks) >= want:
            return toks
        time.sleep(0.05)


def pose_cdr(x, y, cov_xx, cov_xy, cov_yy, frame="map", sec=50):
    """PoseWithCovarianceStamped in little-endian CDR from its documented layout: the
    encapsulation header 00 01 00 00, then header.stamp (int32 sec, uint32 nanosec),
    header.frame_id (uint32 length with the NUL, the bytes, NUL), padding to 8, pose.position
    (3 float64), pose.orientation (4 float64), covariance (36 float64, row-major)."""
    name = frame.encode() + b"\0"
    body = struct.pack("<iII", sec, 0, len(name)) + name
    body += b"\0" * (-len(body) % 8)
    cov = [0.0] * 36
    cov[0], cov[1], cov[6], cov[7], cov[35] = cov_xx, cov_xy, cov_xy, cov_yy, 0.01
    q = (0.0, 0.0, math.sin(0.1), math.cos(0.1))
    body += struct.pack("<3d", x, y, 0.0) + struct.pack("<4d", *q) + struct.pack("<36d", *cov)
    return b"\x00\x01\x00\x00" + body


def attachment(seq, gid):
    """rmw_zenoh_cpp's attachment (>= 0.2.4): int64 sequence number, int64 source timestamp (ns),
    the GID as a byte sequence (length 16 as one byte, the 16 bytes)."""
    return struct.pack("<qq", seq, time.time_ns()) + b"\x10" + gid


def _field_with_deposit(start_field, tmp_path, name):
    cfg = tmp_path / "field.toml"
    cfg.write_text(FIELD)
    f = start_field(name, "--config", str(cfg))
    run_cli("deposit", "--field", f.name, "--x", "0.05", "--y", "1.05", "--amount", "0.5")
    return f


def test_ros_peers_behind_rmw_zenohd_see_the_node_and_deposit(router, start_field, start_node,
                                                              store, tmp_path):
    f = _field_with_deposit(start_field, tmp_path, "rt")
    node = start_node(f.name, "--connect", router.endpoint, "--deposit-from", "/amcl_pose=2")
    hashes = {t: store.hash_rihs01(t) for t in (GRID, OCC, POSE)}
    listener, talker = ros_peer(router.endpoint), ros_peer(router.endpoint)
    try:
        # The node, its two publishers and its subscription: 4 tokens.
        toks = _tokens(listener, 4)
        kinds = sorted(t.split("/")[5] for t in toks if t.split("/")[8] == "pheromone")
        assert kinds == ["MP", "MP", "MS", "NN"], toks
        assert any(t.split("/")[9:12] == ["%amcl_pose", dds(POSE), hashes[POSE]] for t in toks)
        grids, occs = [], []
        subs = [listener.declare_subscriber("0/pheromone/grid_map/**", grids.append),
                listener.declare_subscriber("0/pheromone/occupancy/**", occs.append)]
        started = time.monotonic()

        def grid_with_the_deposit():
            for g in grids:
                m = store.deserialize_cdr(bytes(g.payload.to_bytes()), GRID)
                if float(m.data[0].data.max()) > 0.0:
                    return g, m
            return None

        for _ in deadline_loop(20, "a GridMap with the deposit and 3 OccupancyGrid samples "
                                   "through the router"):
            if len(occs) >= 3 and (found := grid_with_the_deposit()):
                break
            time.sleep(0.02)
        first_s = time.monotonic() - started
        g, msg = found
        assert str(g.key_expr) == f"0/pheromone/grid_map/{dds(GRID)}/{hashes[GRID]}"
        assert list(msg.layers) == ["channel_0"] and msg.header.frame_id == "map"
        att = bytes(g.attachment.to_bytes())
        assert len(att) == 33 and att[16] == 16
        occ = store.deserialize_cdr(bytes(occs[-1].payload.to_bytes()), OCC)
        assert (occ.info.width, occ.info.height) == (40, 30)

        # A ROS node's publisher: its token (rmw_zenoh's shape) and the pose with its attachment.
        zid = str(talker.info.zid())
        token = talker.liveliness().declare_token(
            f"@ros2_lv/0/{zid}/0/1/MP/%/%/amcl/%amcl_pose/{dds(POSE)}/{hashes[POSE]}/::,1:,:,:,,")
        pub = talker.declare_publisher(f"0/amcl_pose/{dds(POSE)}/{hashes[POSE]}")
        x, y = -1.0 + 20.5 * 0.1, 0.5 + 10.5 * 0.1
        pub.put(pose_cdr(x, y, 0.1, 0.0, 0.1), attachment=attachment(1, bytes(range(16))))
        for _ in deadline_loop(20, "the pose published through the router to be deposited"):
            got = json.loads(run_cli("probe", "--field", f.name, "--x", repr(x), "--y", repr(y),
                                     "--json", "--timeout", "10"))
            if got["value"] > 0.0:
                break
            time.sleep(0.05)
        assert got["value"] == pytest.approx(0.2 / (0.1 * 0.1), rel=1e-5)
        print(f"\nrouter eclipse-zenoh {router.version}: {len(toks)} tokens; {len(grids)} "
              f"GridMap + {len(occs)} OccupancyGrid samples, {first_s:.2f} s after subscribing "
              "until one GridMap with the deposit and 3 OccupancyGrids had come")
        for x in [*subs, token, pub]:
            x.undeclare()
    finally:
        listener.close()
        talker.close()
    summary = node.stop()["ros2"]
    assert summary["poses_received"] == 1 and summary["deposits_sent"] == 1
    assert summary["refused_type"] == 0 and summary["refused_cdr"] == 0


def test_zenoh_session_config_uri_configures_the_node_as_it_does_an_rmw_zenoh_node(
        start_field, start_node, tmp_path):
    """The variable names the whole configuration (here: rmw_zenoh's defaults with the router
    at the test's port, as a ROS user edits a copy of the default file); --zenoh-config wins
    over it; a file that does not parse is refused with exit status 2 naming where it came
    from."""
    r = Router("1.10.2", tmp_path)
    try:
        f = _field_with_deposit(start_field, tmp_path, "uri")
        session = tmp_path / "session.json5"
        session.write_text(f"{{ mode: 'peer', connect: {{ endpoints: ['{r.endpoint}'] }},"
                           " listen: { endpoints: ['tcp/localhost:0'] },"
                           " scouting: { multicast: { enabled: false },"
                           " gossip: { enabled: true } },"
                           " transport: { shared_memory: { enabled: false } } }")
        bad = tmp_path / "bad.json5"
        bad.write_text("{ mode: 'peer', ")
        start_node(f.name, env={"ZENOH_SESSION_CONFIG_URI": str(session)})
        start_node(f.name, "--node-name", "second", "--zenoh-config", str(session),
                   env={"ZENOH_SESSION_CONFIG_URI": str(bad)})
        peer = ros_peer(r.endpoint)
        try:
            toks = _tokens(peer, 2 * 3)
            names = sorted({t.split("/")[8] for t in toks if t.split("/")[5] == "NN"})
            assert names == ["pheromone", "second"], toks
        finally:
            peer.close()
    finally:
        r.stop()
    for env, args, named in [
        ({"ZENOH_SESSION_CONFIG_URI": str(bad)}, [], f"ZENOH_SESSION_CONFIG_URI={bad}: "),
        ({}, ["--zenoh-config", str(bad)], f"--zenoh-config {bad}: "),
    ]:
        p = subprocess.run([str(BIN), "ros2", "--field", "no-such-field", *args],
                           capture_output=True, text=True, timeout=30,
                           env={**os.environ, **env})
        assert p.returncode == 2, p.stderr
        assert named in p.stderr, p.stderr


def test_a_late_ros_peer_behind_the_router_gets_the_newest_map(router, start_field, start_node,
                                                                store, tmp_path):
    """A map every 4 s; a ROS peer subscribes volatile and sees each as it comes; right after
    one, another ROS peer (a new session, as a node started later) subscribes as rmw_zenoh_cpp's
    transient-local subscription does (rmw_subscription_data.cpp: zenoh-ext advanced
    subscriber, history with late-publisher detection, max_samples 1, heartbeat recovery,
    subscriber detection): through the router it gets that map from the node's cache, before
    the next one is published. The latency is printed, not asserted."""
    f = _field_with_deposit(start_field, tmp_path, "lj")
    node = start_node(f.name, "--connect", router.endpoint, "--rate-hz", "0.25")
    key = f"0/pheromone/grid_map/{dds(GRID)}/{store.hash_rihs01(GRID)}"
    early_peer, late_peer = ros_peer(router.endpoint), ros_peer(router.endpoint)
    early, late = [], []
    joined = threading.Event()

    def on_late(s):
        late.append((time.monotonic(), s))
        joined.set()

    try:
        _tokens(early_peer, 3)
        sub = early_peer.declare_subscriber(key, early.append)
        for _ in deadline_loop(20, "a map through the router"):
            if early:
                break
            time.sleep(0.01)
        count = len(early)
        for _ in deadline_loop(20, "the next map through the router"):
            if len(early) > count:
                break
            time.sleep(0.005)
        newest = early[-1]
        t0 = time.monotonic()
        adv = zenoh.ext.declare_advanced_subscriber(
            late_peer, key, on_late,
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
            recovery=zenoh.ext.RecoveryConfig(heartbeat=True), subscriber_detection=True)
        assert joined.wait(15), "the late ROS peer got no map"
        t1, first = late[0]
        meanwhile = len(early) - (count + 1)
        adv.undeclare()
        sub.undeclare()
    finally:
        early_peer.close()
        late_peer.close()
    print(f"\nrouter eclipse-zenoh {router.version}: the late peer got the newest map "
          f"{(t1 - t0) * 1e3:.1f} ms after subscribing")
    assert meanwhile == 0, "a map was published before the late peer got one"
    assert bytes(first.payload.to_bytes()) == bytes(newest.payload.to_bytes())
    assert bytes(first.attachment.to_bytes()) == bytes(newest.attachment.to_bytes())
    node.stop()
