"""`pheromone ros2`'s maps for late joiners, and its OccupancyGrid scale (docs/ros2.md,
"Late joiners" and "OccupancyGrid").

The maps are offered transient local with a one-sample cache, declared as rmw_zenoh_cpp declares a
transient-local publisher (zenoh-ext's AdvancedPublisher: cache, publisher detection). The late
joiner here is built as rmw_zenoh_cpp builds a transient-local subscription
(`rmw_subscription_data.cpp`, `SubscriptionData::init`: eclipse-zenoh's `zenoh.ext` advanced
subscriber with history, late-publisher detection, `max_samples` = the depth, heartbeat
recovery, subscriber detection): nothing of ours on that side. rosbags deserializes the CDR;
`pheromone export` gives the field's values the OccupancyGrids are compared with."""

import json
import os
import struct
import subprocess
import threading
import time

import numpy as np
import pytest
from ros_msgs import GRID, OCC, dds, free_port, register_grid_map

from conftest import BIN, deadline_loop, run_cli

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

from test_ros2 import TWO_CHANNELS, _session, _tokens, ros2_node, zenoh_bin  # noqa: E402, F401

#: The token's QoS of a reliable, transient-local, keep-last-1 publisher (rmw_zenoh's
#: qos_to_keyexpr; its defaults are reliable, volatile, keep last 42).
TRANSIENT_LOCAL_DEPTH_1 = ":1:,1:,:,:,,"


@pytest.fixture(scope="module")
def store():
    return register_grid_map(get_typestore(Stores.ROS2_JAZZY), get_types_from_msg)


@pytest.fixture
def node(ros2_node):  # noqa: F811
    """test_ros2's node (its --rate-hz 20 unless a test sets it)."""
    return ros2_node


def _late_joiner(session, key, on_sample):
    """A transient-local, reliable, keep-last-1 subscription as rmw_zenoh_cpp declares one."""
    return zenoh.ext.declare_advanced_subscriber(
        session, key, on_sample,
        history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
        recovery=zenoh.ext.RecoveryConfig(heartbeat=True),
        subscriber_detection=True)


def _field(start_field, tmp_path, name):
    cfg = tmp_path / "two.toml"
    cfg.write_text(TWO_CHANNELS)
    return start_field(name, "--config", str(cfg))


def _seq(sample):
    return struct.unpack_from("<q", bytes(sample.attachment.to_bytes()))[0]


def test_a_late_joiner_gets_the_newest_map_from_the_cache(start_field, node, store, tmp_path):
    """A map every 4 s (--rate-hz 0.25); a volatile subscriber sees each as it is published.
    Right after one came, a late joiner subscribes: it gets that map (same bytes, same
    attachment) long before the next is due. The latency is printed, not asserted."""
    f = _field(start_field, tmp_path, "late")
    run_cli("deposit", "--field", f.name, "--x", "0.05", "--y", "1.05", "--amount", "0.5")
    n = node(f.name, "--rate-hz", "0.25")
    key = f"0/pheromone/grid_map/{dds(GRID)}/{store.hash_rihs01(GRID)}"
    early, late, lock = [], [], threading.Lock()
    joined = threading.Event()

    def on_late(s):
        with lock:
            late.append((time.monotonic(), s))
        joined.set()

    with _session(n.endpoint) as s:
        toks = _tokens(s, 4)
        maps = [t for t in toks if t.split("/")[5] == "MP"]
        assert len(maps) == 3, toks
        assert all(t.split("/")[12] == TRANSIENT_LOCAL_DEPTH_1 for t in maps), maps
        sub = s.declare_subscriber(key, early.append)
        for _ in deadline_loop(20, "a map on the early subscriber"):
            if early:
                break
            time.sleep(0.01)
        # Right after a publication: the next one is ~4 s away.
        count = len(early)
        for _ in deadline_loop(20, "the next map on the early subscriber"):
            if len(early) > count:
                break
            time.sleep(0.005)
        newest = early[-1]
        t0 = time.monotonic()
        adv = _late_joiner(s, key, on_late)
        assert joined.wait(15), "the late joiner got no map"
        with lock:
            t1, first = late[0]
        published_meanwhile = len(early) - (count + 1)
        adv.undeclare()
        sub.undeclare()
    latency_ms = (t1 - t0) * 1e3
    print(f"\nlate joiner: the newest map {latency_ms:.1f} ms after subscribing "
          f"({len(bytes(first.payload.to_bytes()))} bytes, seq {_seq(first)})")
    assert published_meanwhile == 0, "a map was published before the late joiner got one"
    assert str(first.key_expr) == key
    assert bytes(first.payload.to_bytes()) == bytes(newest.payload.to_bytes())
    assert bytes(first.attachment.to_bytes()) == bytes(newest.attachment.to_bytes())
    msg = store.deserialize_cdr(bytes(first.payload.to_bytes()), GRID)
    assert float(msg.data[0].data.max()) > 0.0
    summary = n.stop()["ros2"]
    assert summary["frames_published"] >= 2


def test_with_nobody_subscribed_the_cache_still_gets_a_map(start_field, node, store, tmp_path):
    """While no subscriber matches, frames still go into the cache (at most --cache-rate-hz a
    second, never more than --rate-hz; the first one at once): with a map due every 5 s, a
    late joiner that subscribes right after the node started gets a map serialized before it
    subscribed, from the cache. (How often the cache is refreshed: a unit test of node.rs.)"""
    f = _field(start_field, tmp_path, "idle")
    n = node(f.name, "--rate-hz", "0.2", "--cache-rate-hz", "1")
    key = f"0/pheromone/occupancy/channel_0/{dds(OCC)}/{store.hash_rihs01(OCC)}"
    got = []
    with _session(n.endpoint) as s:
        _tokens(s, 4)
        # The cache holds a map: asked as zenoh-ext's advanced subscriber asks for history
        # (`<key>/@adv/**?_max=1`, replies under the publisher's key accepted); a query is no
        # subscriber, so nothing is published live meanwhile.
        for _ in deadline_loop(15, "a map in the node's cache"):
            replies = s.get(f"{key}/@adv/**?_max=1", timeout=2.0,
                            accept_replies=zenoh.ReplyKeyExpr.ANY)
            if any(r.ok is not None for r in replies):
                break
            time.sleep(0.05)
        t_sub = time.time_ns()
        adv = _late_joiner(s, key, got.append)
        for _ in deadline_loop(15, "an OccupancyGrid on the late joiner"):
            if got:
                break
            time.sleep(0.005)
        first = store.deserialize_cdr(bytes(got[0].payload.to_bytes()), OCC)
        adv.undeclare()
    stamp = first.header.stamp.sec * 10**9 + first.header.stamp.nanosec
    assert stamp < t_sub, "the late joiner's first map was not the cached one"
    summary = n.stop()["ros2"]
    assert summary["frames_for_cache"] >= 1, summary


def _occupancy(store, sample):
    m = store.deserialize_cdr(bytes(sample.payload.to_bytes()), OCC)
    return np.asarray(m.data, dtype=np.int8).reshape(m.info.height, m.info.width)


def test_occupancy_is_a_fixed_scale_comparable_between_frames(start_field, node, store,
                                                             tmp_path):
    """--occupancy linear --occupancy-max 20 --occupancy-trail free
    --occupancy-unknown-below 1e-6: each cell is 100 − round(100·v/20) clamped, −1 where the
    field holds nothing; two frames (before and after a second, stronger deposit) each equal
    the field's exported values, and a cell the second deposit did not touch keeps its value."""
    f = _field(start_field, tmp_path, "occ")
    n = node(f.name, "--occupancy", "linear", "--occupancy-max", "20", "--occupancy-trail",
             "free", "--occupancy-unknown-below", "1e-6")
    key = f"0/pheromone/occupancy/channel_0/{dds(OCC)}/{store.hash_rihs01(OCC)}"

    def want(cells):
        v = np.clip(np.round(100.0 * cells.astype(np.float64) / 20.0), 0, 100)
        out = (100 - v).astype(np.int8)
        out[cells < 1e-6] = -1
        return out

    frames = []
    with _session(n.endpoint) as s:
        _tokens(s, 4)
        sub = s.declare_subscriber(key)
        # Peaks τ/det Σxy = 2 and 6 (under --gamma-max): 10 % and 30 % of the scale.
        for i, (x, amount) in enumerate([(0.05, 0.02), (2.05, 0.06)]):
            run_cli("deposit", "--field", f.name, "--x", repr(x), "--y", "1.05", "--amount",
                    repr(amount), "--cov", "0.1,0,0.1")
            applied = i + 1
            for _ in deadline_loop(20, f"the field to apply deposit {applied}"):
                got = json.loads(run_cli("probe", "--field", f.name, "--x", "0", "--y", "1",
                                         "--json", "--timeout", "10"))
                if got["deposits_applied"] >= applied:
                    break
                time.sleep(0.02)
            npy = tmp_path / f"frame{i}.npy"
            run_cli("export", "--field", f.name, "--out", npy)
            cells = np.load(npy)[0]
            # No evaporation: every frame from now on holds these cells.
            for _ in deadline_loop(20, f"an OccupancyGrid of frame {i}"):
                sample = sub.try_recv()
                if sample is not None:
                    occ = _occupancy(store, sample)
                    if np.array_equal(occ, want(cells)):
                        frames.append((cells, occ))
                        break
                else:
                    time.sleep(0.01)
        sub.undeclare()
    n.stop()
    (c0, o0), (c1, o1) = frames
    for cells, occ in frames:
        assert (occ == -1).sum() == (cells < 1e-6).sum() > 0
        assert occ.max() <= 100 and occ[occ >= 0].min() < 100
    # The first deposit's cells: unchanged values, unchanged occupancy, although the frame's
    # largest value grew (a per-frame scale would have changed them).
    first = (c0 > 1e-6) & (c1 == c0)
    assert first.any() and c1.max() > c0.max()
    np.testing.assert_array_equal(o0[first], o1[first])


def test_an_empty_linear_scale_is_refused(zenoh_bin):  # noqa: F811
    p = subprocess.run([str(BIN), "ros2", "--field", "nosuch", "--listen",
                        f"tcp/127.0.0.1:{free_port()}", "--occupancy-min", "2",
                        "--occupancy-max", "1"],
                       capture_output=True, text=True, timeout=30)
    assert p.returncode == 2, p.stderr
    assert "--occupancy-min 2 must be under --occupancy-max 1" in p.stderr, p.stderr
