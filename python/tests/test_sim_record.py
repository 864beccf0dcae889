"""`pheromone sim --record FILE.mcap` read back with ROS 2's Python tools: `mcap` reads the file,
`rosbags` (Stores.ROS2_JAZZY, grid_map_msgs registered, pheromone_msgs/msg/Deposit from the
file's own schema) deserializes every message; counts, stamps and values are checked against
the run's own outputs (metrics.json, robot_<id>.csv, field_final.npy) (docs/ros2.md). The same
file also opens as rosbag2 files do: `mcap-ros2-support`'s decoder (Foxglove's, which builds its
types from the schemas' `.msg` text alone) decodes every message, and rosbags' rosbag2 reader
reads it as a bag from the `rosbag2` metadata record the file carries (QoS, type hashes,
counts).

Needs `pip install './python[ros2]'` (rosbags, mcap, mcap-ros2-support); without them the tests
are skipped, unless PHEROMONE_REQUIRE_ZENOH=1 (tests/all.sh), where they fail instead."""

import csv
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from ros_msgs import GRID, register_grid_map

from conftest import BIN, STARTED_PIDS, deadline_loop, run_cli

try:
    from mcap.exceptions import EndOfFile, RecordLengthLimitExceeded
    from mcap.reader import make_reader
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.rosbag2 import Reader as BagReader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    from ruamel.yaml import YAML
except ImportError as e:
    if os.environ.get("PHEROMONE_REQUIRE_ZENOH") == "1":
        raise
    pytest.skip(f"pip install './python[ros2]' for these tests ({e})", allow_module_level=True)

OCC = "nav_msgs/msg/OccupancyGrid"
POSE = "geometry_msgs/msg/PoseWithCovarianceStamped"
PATH = "nav_msgs/msg/Path"
DEPOSIT = "pheromone_msgs/msg/Deposit"
WORLD_ID = 2**32 - 1
# blind-leader: robots 0 and 1, a depositor on robot 0, snapshots at 20 s and 40 s.
DURATION_S = 25.0


def _store():
    return register_grid_map(get_typestore(Stores.ROS2_JAZZY), get_types_from_msg)


def _stamp(header):
    return header.stamp.sec * 10**9 + header.stamp.nanosec


def read_mcap(path):
    """Every message deserialized by rosbags: {topic: [(log_time, msg, raw)]}, schema names."""
    store = _store()
    by_topic, types = {}, {}
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            if schema.name not in store.types:
                # Our own type: its definition is the file's schema, as `ros2 bag` reads it.
                store.register(get_types_from_msg(schema.data.decode(), schema.name))
            types[channel.topic] = schema.name
            msg = store.deserialize_cdr(message.data, schema.name)
            # Log time = the header stamp (simulated time).
            assert message.log_time == _stamp(msg.header), channel.topic
            by_topic.setdefault(channel.topic, []).append((message.log_time, msg, message.data))
    return by_topic, types


def check_ros_tools(mcap, tmp_path):
    """The file as ROS tools see it; returns {topic: message count}."""
    # mcap-ros2-support: every message decoded from the schema text alone.
    decoded = {}
    with open(mcap, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages(log_time_order=False):
            assert "/msg/" not in schema.data.decode(), schema.name
            assert message.log_time == _stamp(msg.header), channel.topic
            decoded[channel.topic] = decoded.get(channel.topic, 0) + 1
    # The mcap library: summary statistics, channel metadata and the rosbag2 record.
    with open(mcap, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        [record] = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
    store = _store()
    stats = summary.statistics
    assert stats.message_count == sum(decoded.values())
    for cid, ch in summary.channels.items():
        assert stats.channel_message_counts[cid] == decoded[ch.topic]
        schema = summary.schemas[ch.schema_id].name
        if schema in store.types:
            assert ch.metadata["topic_type_hash"] == store.hash_rihs01(schema)
        [qos] = YAML(typ="safe").load(ch.metadata["offered_qos_profiles"])
        maps = schema in (GRID, OCC)
        assert qos["durability"] == ("transient_local" if maps else "volatile"), ch.topic
        assert (qos["reliability"], qos["history"], qos["depth"]) == ("reliable", "keep_last", 1)
    meta = YAML(typ="safe").load(record.metadata["serialized_metadata"])
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == stats.message_count
    # rosbags' rosbag2 reader: the file in a bag directory whose metadata.yaml is the record's.
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / mcap.name).symlink_to(mcap)
    with open(bag / "metadata.yaml", "w") as fh:
        YAML(typ="safe").dump({"rosbag2_bagfile_information": meta}, fh)
    counts = {}
    with BagReader(bag) as r:
        assert r.message_count == stats.message_count
        for conn in r.connections:
            assert conn.msgcount == decoded[conn.topic]
            [qos] = conn.ext.offered_qos_profiles
            maps = conn.msgtype in (GRID, OCC)
            assert qos.durability.name == ("TRANSIENT_LOCAL" if maps else "VOLATILE")
            if conn.msgtype in store.types:
                assert conn.digest == store.hash_rihs01(conn.msgtype)
        with open(mcap, "rb") as fh:
            for schema in make_reader(fh).get_summary().schemas.values():
                if schema.name not in store.types:
                    store.register(get_types_from_msg(schema.data.decode(), schema.name))
        for conn, t, raw in r.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            assert t == _stamp(msg.header)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    assert counts == decoded
    return decoded


def run_sim(tmp_path, name, *args):
    """`pheromone sim blind-leader` for DURATION_S with --record and --out: metrics, out, file."""
    out = tmp_path / name
    mcap = tmp_path / f"{name}.mcap"
    text = run_cli("sim", "blind-leader", "--duration", DURATION_S, "--record", mcap,
                   "--out", out, "--json", *args, timeout=600)
    return json.loads(text.strip().splitlines()[-1]), out, mcap


def test_a_process_run_records_every_message_rosbags_reads(tmp_path):
    metrics, out, mcap = run_sim(tmp_path, "proc")
    assert metrics["mode"] == "processes"
    by_topic, types = read_mcap(mcap)
    robots = sorted(r["id"] for r in metrics["robots"])
    assert robots == [0, 1]
    want = {"/pheromone/grid_map": GRID, "/pheromone/occupancy/channel_0": OCC,
            "/pheromone/deposits": DEPOSIT}
    for r in robots:
        for what in ("true_pose", "estimated_pose"):
            want[f"/robot_{r}/{what}"] = POSE
        for what in ("true_path", "estimated_path"):
            want[f"/robot_{r}/{what}"] = PATH
    assert types == want
    rec = metrics["record"]
    assert rec["messages"] == sum(len(v) for v in by_topic.values())
    assert rec["deposit_mismatches"] == 0
    assert check_ros_tools(mcap, tmp_path) == {t: len(v) for t, v in by_topic.items()}

    # The field: one GridMap and OccupancyGrid per frame the run pictured (its snapshot PNGs).
    shots = out.glob("field_trail_t*s.png")
    shot_times = sorted(float(p.name.rsplit("_t", 1)[1][:-5]) for p in shots)
    grids = by_topic["/pheromone/grid_map"]
    assert len(grids) == len(shot_times) == 2
    assert [round(t / 1e9, 1) for t, _, _ in grids] == shot_times
    assert len(by_topic["/pheromone/occupancy/channel_0"]) == len(grids)
    final = np.load(out / "field_final.npy")
    last = grids[-1][1]
    assert list(last.layers) == ["channel_0"] and last.header.frame_id == "map"
    h, w = final.shape[1:]
    np.testing.assert_array_equal(last.data[0].data[::-1].reshape(h, w), final[0])
    assert final[0].max() > 0

    # Poses: one true and one estimated per robot and step, as robot_<id>.csv lists them.
    steps = metrics["steps"]
    assert steps == round(DURATION_S / 0.1)
    end_ns = metrics["sim_time_s"] * 1e9 + 1
    for r in robots:
        with open(out / f"robot_{r}.csv") as fh:
            rows = list(csv.DictReader(fh))
        truths = by_topic[f"/robot_{r}/true_pose"]
        ests = by_topic[f"/robot_{r}/estimated_pose"]
        assert len(truths) == len(ests) == len(rows) == steps
        stamps = [t for t, _, _ in truths]
        assert all(a < b for a, b in zip(stamps, stamps[1:]))
        assert stamps[0] > 0 and stamps[-1] <= end_ns
        assert [t for t, _, _ in ests] == stamps
        for (t, m, _), row in zip(truths, rows):
            assert t == pytest.approx(float(row["t_s"]) * 1e9, abs=1)
            p = m.pose.pose.position
            assert (p.x, p.y) == pytest.approx((float(row["true_x_m"]), float(row["true_y_m"])),
                                               abs=1e-9)
            assert not m.pose.covariance.any()
        for (_, m, _), row in zip(ests, rows):
            p = m.pose.pose.position
            assert (p.x, p.y) == pytest.approx((float(row["est_x_m"]), float(row["est_y_m"])),
                                               abs=1e-9)
            cov = m.pose.covariance.reshape(6, 6)
            assert cov[0, 0] > 0 and cov[1, 1] > 0 and cov[5, 5] > 0 and cov[2, 2] == 0
            np.testing.assert_array_equal(cov, cov.T)
        # Paths: published with each field frame, the trajectory so far.
        paths = by_topic[f"/robot_{r}/true_path"]
        assert [t for t, _, _ in paths] == [t for t, _, _ in grids]
        last_path = paths[-1][1].poses
        assert len(last_path) == steps
        assert [_stamp(p.header) for p in last_path] == stamps
        assert len(by_topic[f"/robot_{r}/estimated_path"][-1][1].poses) == steps

    # Deposits: as many as the field applied, stamped within the run, from the depositor (0).
    deps = by_topic["/pheromone/deposits"]
    assert len(deps) == metrics["field"]["deposits_applied"] > 0
    dstamps = [t for t, _, _ in deps]
    assert dstamps == sorted(dstamps) and dstamps[0] > 0 and dstamps[-1] <= end_ns
    for _, d, _ in deps:
        assert d.robot_id == 0 and d.kernel == "ellipse" and d.channel == 0
        assert 0 < d.peak <= d.gamma_max and d.covariance[0] > 0


def test_both_modes_record_the_same_messages(tmp_path):
    _, _, proc = run_sim(tmp_path, "proc")
    _, _, single = run_sim(tmp_path, "single", "--single-process")
    a, _ = read_mcap(proc)
    b, _ = read_mcap(single)
    assert sorted(a) == sorted(b)
    for topic in a:
        assert [raw for _, _, raw in a[topic]] == [raw for _, _, raw in b[topic]], topic


@pytest.mark.parametrize("codec", ["zstd", "lz4"])
def test_compressed_chunks_hold_the_same_messages(tmp_path, codec):
    """--record-compression: every chunk compressed with the codec (the mcap library's chunk
    index), the same message bytes as an uncompressed run, and the ROS tools read it."""
    _, _, plain = run_sim(tmp_path, "plain", "--single-process")
    _, _, packed = run_sim(tmp_path, codec, "--single-process", "--record-compression", codec)
    with open(packed, "rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    assert chunks and {c.compression for c in chunks} == {codec}
    assert sum(c.compressed_size for c in chunks) < sum(c.uncompressed_size for c in chunks)
    a, _ = read_mcap(plain)
    b, _ = read_mcap(packed)
    assert sorted(a) == sorted(b)
    for topic in a:
        assert [raw for _, _, raw in a[topic]] == [raw for _, _, raw in b[topic]], topic
    assert check_ros_tools(packed, tmp_path) == {t: len(v) for t, v in b.items()}
    print(f"\n{codec}: {packed.stat().st_size} bytes, uncompressed {plain.stat().st_size}")


def test_an_unwritable_record_path_is_refused_up_front(tmp_path):
    bad = tmp_path / "no" / "such" / "dir" / "x.mcap"
    p = subprocess.Popen([str(BIN), "sim", "blind-leader", "--duration", "1", "--no-out",
                          "--record", str(bad)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    STARTED_PIDS.add(p.pid)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 2, err
    assert f"--record {bad}" in err
    assert not Path(bad).exists()


def _streamed_topics(path):
    """Topics of the messages a streaming reader reads from a file still being written: up to
    the chunk being written (the mcap crate writes its length, u64::MAX, when it closes it)."""
    topics, names = [], {}
    with open(path, "rb") as fh:
        try:
            for r in StreamReader(fh).records:
                if isinstance(r, Channel):
                    names[r.id] = r.topic
                elif isinstance(r, Message):
                    topics.append(names[r.channel_id])
        except (EndOfFile, RecordLengthLimitExceeded):
            pass
    return topics


def test_an_interrupted_run_leaves_a_finished_file(tmp_path):
    """Readable while the run goes; Ctrl-C stops every process and finishes the file."""
    mcap = tmp_path / "int.mcap"
    err = open(tmp_path / "sim.stderr", "wb")
    p = subprocess.Popen([str(BIN), "sim", "blind-leader", "--duration", "600", "--no-out",
                          "--record", str(mcap)], stdout=subprocess.DEVNULL, stderr=err)
    STARTED_PIDS.add(p.pid)
    try:
        for _ in deadline_loop(120, "a field frame (at 20 s simulated) in the file being written"):
            if mcap.exists() and "/pheromone/grid_map" in _streamed_topics(mcap):
                break
            time.sleep(0.05)
        seen = len(_streamed_topics(mcap))
        p.send_signal(signal.SIGINT)
        p.wait(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        err.close()
    text = (tmp_path / "sim.stderr").read_text(errors="replace")
    assert p.returncode != 0 and "interrupted" in text, text
    with open(mcap, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None, "the interrupted run's file has no summary"
    by_topic, _ = read_mcap(mcap)
    total = sum(len(v) for v in by_topic.values())
    assert total >= seen > 0
    assert summary.statistics.message_count == total
    truths = [t for t, _, _ in by_topic["/robot_0/true_pose"]]
    assert truths == sorted(truths) and truths[-1] < 600e9
    assert len(by_topic["/pheromone/grid_map"]) >= 1
