"""`pheromone ros2 --ros-distro humble|jazzy|kilted|rolling` against peers whose bytes are built
from rmw_zenoh_cpp's own layouts (docs/ros2.md, "ROS 2 distributions"):

- the key expressions' hash part: RIHS01 from Jazzy on (rosbags computes it), the string
  `TypeHashNotSupported` on Humble, which has no type hashes;
- the liveliness tokens' QoS part as upstream's `qos_to_keyexpr` (liveliness_utils.cpp) writes
  it with the current default QoS (qos.cpp: reliable, volatile, keep last, depth 42; volatile
  since ros2/rmw_zenoh#521, backported to Jazzy and Humble), so the GID a receiver computes
  from the token it rebuilds (XXH3-128 of the token) is the GID in our attachment;
- incoming poses in both attachment layouts a distro's releases send, built with zenoh-ext's
  serializer as upstream's attachment_helpers.cpp builds them: keyed (`"sequence_number"`,
  int64, `"source_timestamp"`, int64, `"source_gid"`, 16 bytes; Humble 0.1.0-0.1.1, Jazzy
  0.2.0-0.2.3) and positional (the three values without keys; ros2/rmw_zenoh#601, Rolling 0.6.0,
  Jazzy 0.2.4, Humble 0.1.2); a pose keyed with another distro's hash is refused."""

import json
import math
import os
import signal
import struct
import subprocess
import time

import pytest
from ros_msgs import GRID, OCC, POSE, dds, free_port, register_grid_map
from ros_msgs import ONE_CHANNEL_FIELD as FIELD

from conftest import BIN, STARTED_PIDS, deadline_loop, run_cli

REQUIRED = os.environ.get("PHEROMONE_REQUIRE_ZENOH") == "1"

try:
    import xxhash
    import zenoh
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    from zenoh.ext import Int64, z_serialize
except ImportError as e:
    if REQUIRED:
        raise
    pytest.skip(f"pip install './python[zenoh,ros2]' for these tests ({e})",
                allow_module_level=True)


@pytest.fixture(scope="module")
def store():
    return register_grid_map(get_typestore(Stores.ROS2_JAZZY), get_types_from_msg)


def type_hash(distro, store, name):
    return "TypeHashNotSupported" if distro == "humble" else store.hash_rihs01(name)


def qos_keyexpr(depth, reliable=True, transient_local=False):
    """upstream's qos_to_keyexpr: each policy left empty when it equals the default (reliable=1,
    volatile=2, keep_last=1, depth 42, infinite durations, automatic liveliness)."""
    rel = "" if reliable else "2"
    dur = "1" if transient_local else ""
    d = "" if depth == 42 else str(depth)
    return f"{rel}:{dur}:,{d}:,:,:,,"


def gid(token):
    """Entity::make: XXH3-128 of the token, low 64 bits then high 64 bits, little endian."""
    h = xxhash.xxh3_128_intdigest(token.encode())
    return (h & (2**64 - 1)).to_bytes(8, "little") + (h >> 64).to_bytes(8, "little")


def pose_cdr(x, y, cov=0.1):
    name = b"map\0"
    body = struct.pack("<iII", 7, 0, len(name)) + name
    c = [0.0] * 36
    c[0], c[7], c[35] = cov, cov, 0.01
    body += struct.pack("<3d", x, y, 0.0) + struct.pack("<4d", 0.0, 0.0, 0.0, 1.0)
    return b"\x00\x01\x00\x00" + body + struct.pack("<36d", *c)


def positional(seq, g):
    return z_serialize((Int64(seq), Int64(time.time_ns()), g)).to_bytes()


def keyed(seq, g):
    return z_serialize(("sequence_number", Int64(seq), "source_timestamp",
                        Int64(time.time_ns()), "source_gid", g)).to_bytes()


def _client(endpoint):
    conf = zenoh.Config()
    for k, v in [("mode", '"client"'), ("connect/endpoints", json.dumps([endpoint])),
                 ("scouting/multicast/enabled", "false"),
                 ("transport/shared_memory/enabled", "false"), ("connect/timeout_ms", "15000"),
                 ("connect/retry",
                  "{period_init_ms: 100, period_max_ms: 500, period_increase_factor: 2}")]:
        conf.insert_json5(k, v)
    return zenoh.open(conf)


def _probe(field, x, y):
    return json.loads(run_cli("probe", "--field", field, "--x", repr(x), "--y", repr(y),
                              "--json", "--timeout", "10"))["value"]


@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted", "rolling"])
def test_a_distros_keys_tokens_gids_and_attachments(distro, start_field, store, tmp_path):
    cfg = tmp_path / "field.toml"
    cfg.write_text(FIELD)
    f = start_field(distro[:3], "--config", str(cfg))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    err = open(tmp_path / "ros2.stderr", "wb")
    node = subprocess.Popen(
        [str(BIN), "ros2", "--field", f.name, "--listen", endpoint,
         "--ros-distro", distro, "--deposit-from", "/amcl_pose=4", "--json", "--rate-hz", "20"],
        stdout=subprocess.PIPE, stderr=err)
    STARTED_PIDS.add(node.pid)
    hashes = {t: type_hash(distro, store, t) for t in (GRID, OCC, POSE)}
    other = {t: type_hash("jazzy" if distro == "humble" else "humble", store, t)
             for t in (POSE,)}
    try:
        with _client(endpoint) as s:
            for _ in deadline_loop(20, "the node's 4 liveliness tokens"):
                toks = sorted(str(r.ok.key_expr)
                              for r in s.liveliness().get("@ros2_lv/**", timeout=2.0)
                              if r.ok is not None)
                if len(toks) >= 4:
                    break
                time.sleep(0.05)
            ents = {t.split("/")[5]: t for t in toks}
            grid_tok = next(t for t in toks if "%pheromone%grid_map" in t)
            p = grid_tok.split("/")
            assert p[10:12] == [dds(GRID), hashes[GRID]]
            # The maps: reliable, transient local, keep last 1.
            assert p[12] == qos_keyexpr(1, transient_local=True), grid_tok
            # The token a receiver rebuilds from the parts it parsed, as Entity::make writes it.
            rebuilt = "/".join([*p[:12], qos_keyexpr(1, transient_local=True)])
            assert rebuilt == grid_tok
            sub_p = ents["MS"].split("/")
            assert sub_p[9:13] == ["%amcl_pose", dds(POSE), hashes[POSE], qos_keyexpr(10)]

            got = []
            sub = s.declare_subscriber(f"0/pheromone/grid_map/{dds(GRID)}/{hashes[GRID]}",
                                       got.append)
            for _ in deadline_loop(15, f"a GridMap on the {distro} key"):
                if got:
                    break
                time.sleep(0.02)
            att = bytes(got[0].attachment.to_bytes())
            assert len(att) == 33 and att[17:] == gid(grid_tok)
            sub.undeclare()

            g = bytes(range(16))
            key = f"0/amcl_pose/{dds(POSE)}/{hashes[POSE]}"
            a = (-1.0 + 5.5 * 0.1, 0.5 + 5.5 * 0.1)
            b = (-1.0 + 30.5 * 0.1, 0.5 + 20.5 * 0.1)
            s.put(key, pose_cdr(*a), attachment=positional(1, g))
            s.put(key, pose_cdr(*b), attachment=keyed(2, g))
            s.put(f"0/amcl_pose/{dds(POSE)}/{other[POSE]}", pose_cdr(2.6, 0.7),
                  attachment=positional(3, g))
            for _ in deadline_loop(20, "both poses deposited"):
                if _probe(f.name, *a) > 0 and _probe(f.name, *b) > 0:
                    break
                time.sleep(0.05)
        node.send_signal(signal.SIGINT)
        out, _ = node.communicate(timeout=20)
    finally:
        if node.poll() is None:
            node.kill()
            node.communicate()
        err.close()
    text = (tmp_path / "ros2.stderr").read_text(errors="replace")
    assert node.returncode == 0, text
    summary = json.loads(out.decode().strip().splitlines()[-1])["ros2"]
    assert summary["deposits_sent"] == 2 and summary["refused_type"] == 1, summary
    assert summary["attachments"] == {"positional": 2, "keyed": 1}, summary
    assert _probe(f.name, 2.6, 0.7) == 0.0
    assert math.isclose(_probe(f.name, *a), 0.2 / 0.01, rel_tol=1e-5)


def qos_keyexpr_tl_default(depth, transient_local):
    """qos_to_keyexpr of the releases before ros2/rmw_zenoh#521 (Humble 0.1.0-0.1.1, Jazzy
    0.2.0-0.2.2), whose default durability is transient local: volatile is written (2),
    transient local left out."""
    dur = "" if transient_local else "2"
    d = "" if depth == 42 else str(depth)
    return f":{dur}:,{d}:,:,:,,"


@pytest.mark.parametrize(("distro", "release", "tl_default"),
                         [("humble", "0.1.1", True), ("jazzy", "0.2.2", True),
                          ("jazzy", "0.2.3", False)])
def test_an_older_release_gets_the_keyed_attachment_and_its_qos_defaults(
        distro, release, tl_default, start_field, store, tmp_path):
    """--rmw-zenoh-release: the samples carry the keyed attachment, read back with zenoh-ext's
    deserializer as upstream's attachment_helpers.cpp of those releases reads it (key, int64,
    key, int64, key, 16 bytes); the tokens' QoS strings are written against the release's
    default durability, so the GID a receiver of that release computes from the token is the
    one in the attachment."""
    from zenoh.ext import z_deserialize

    cfg = tmp_path / "field.toml"
    cfg.write_text(FIELD)
    f = start_field(f"{distro[:3]}{release[-1]}", "--config", str(cfg))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    err = open(tmp_path / "ros2.stderr", "wb")
    node = subprocess.Popen(
        [str(BIN), "ros2", "--field", f.name, "--listen", endpoint, "--ros-distro", distro,
         "--rmw-zenoh-release", release, "--deposit-from", "/amcl_pose", "--json",
         "--rate-hz", "20"], stdout=subprocess.PIPE, stderr=err)
    STARTED_PIDS.add(node.pid)
    h = type_hash(distro, store, GRID)
    try:
        with _client(endpoint) as s:
            for _ in deadline_loop(20, "the node's 4 liveliness tokens"):
                toks = sorted(str(r.ok.key_expr)
                              for r in s.liveliness().get("@ros2_lv/**", timeout=2.0)
                              if r.ok is not None)
                if len(toks) >= 4:
                    break
                time.sleep(0.05)
            grid_tok = next(t for t in toks if "%pheromone%grid_map" in t)
            sub_tok = next(t for t in toks if t.split("/")[5] == "MS")
            want_map = (qos_keyexpr_tl_default(1, True) if tl_default
                        else qos_keyexpr(1, transient_local=True))
            want_sub = qos_keyexpr_tl_default(10, False) if tl_default else qos_keyexpr(10)
            assert grid_tok.split("/")[12] == want_map, grid_tok
            assert sub_tok.split("/")[12] == want_sub, sub_tok
            got = []
            sub = s.declare_subscriber(f"0/pheromone/grid_map/{dds(GRID)}/{h}", got.append)
            for _ in deadline_loop(15, "a GridMap"):
                if got:
                    break
                time.sleep(0.02)
            sub.undeclare()
        node.send_signal(signal.SIGINT)
        node.communicate(timeout=20)
    finally:
        if node.poll() is None:
            node.kill()
            node.communicate()
        err.close()
    assert node.returncode == 0, (tmp_path / "ros2.stderr").read_text(errors="replace")
    att = got[0].attachment
    assert len(att.to_bytes()) == 77
    k1, seq, k2, stamp, k3, g = z_deserialize(tuple[str, Int64, str, Int64, str, bytes], att)
    assert (k1, k2, k3) == ("sequence_number", "source_timestamp", "source_gid")
    assert seq >= 1 and abs(stamp - time.time_ns()) < 60e9
    assert g == gid(grid_tok)


def test_sim_passes_the_release_on_to_its_ros2_child(store, tmp_path):
    """`sim --ros2 --ros-distro jazzy --rmw-zenoh-release 0.2.2`: the child writes that release's
    conventions (the GridMap token's QoS string against a transient-local default, the keyed
    attachment with the token's GID), as sim passes `--ros-distro` on; a release the
    distribution does not have is refused before the run starts, and the flag needs --ros2."""
    from ros_msgs import listening_session, run_sim_watching_tokens
    from zenoh.ext import z_deserialize

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    got = []
    with listening_session(endpoint) as z:
        sub = z.declare_subscriber(f"0/pheromone/grid_map/{dds(GRID)}/{store.hash_rihs01(GRID)}",
                                   got.append)
        rc, tokens, _ = run_sim_watching_tokens(
            z, ["blind-leader", "--duration", 3, "--realtime", "--ros2", endpoint,
                "--ros-distro", "jazzy", "--rmw-zenoh-release", "0.2.2", "--no-out"],
            tmp_path / "sim.stderr")
        sub.undeclare()
    assert rc == 0, (tmp_path / "sim.stderr").read_text(errors="replace")
    [grid_tok] = [t for t in tokens if "%pheromone%grid_map" in t]
    assert grid_tok.split("/")[12] == qos_keyexpr_tl_default(1, True), grid_tok
    assert got, "no GridMap from the sim's ros2 child"
    att = got[0].attachment
    assert len(att.to_bytes()) == 77
    k1, seq, k2, _, k3, g = z_deserialize(tuple[str, Int64, str, Int64, str, bytes], att)
    assert (k1, k2, k3) == ("sequence_number", "source_timestamp", "source_gid")
    assert seq >= 1 and g == gid(grid_tok)

    for args, says in [(["--ros2", endpoint, "--ros-distro", "rolling",
                         "--rmw-zenoh-release", "0.2.2"], "--rmw-zenoh-release 0.2.2"),
                       (["--ros2", endpoint, "--rmw-zenoh-release", "0.3.0"], "0.2.x"),
                       (["--rmw-zenoh-release", "0.2.2"], "--ros2")]:
        p = subprocess.run([str(BIN), "sim", "blind-leader", "--duration", "1", "--no-out",
                            *args], capture_output=True, timeout=60)
        assert p.returncode == 2, (args, p.stderr)
        assert says in p.stderr.decode(errors="replace"), (args, p.stderr)
