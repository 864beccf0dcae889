"""What the ROS 2 tests (test_ros2*.py, test_sim_record.py) share: grid_map_msgs for rosbags (not
in its ROS 2 stores; the .msg texts of the jazzy branch of ANYbotics/grid_map, comments left
out), the type names, the field they start, rmw_zenoh's DDS spelling, a free port, and a
`sim --ros2` run watched by a listening Zenoh peer."""

import contextlib
import json
import socket
import subprocess

from conftest import BIN, STARTED_PIDS

GRID = "grid_map_msgs/msg/GridMap"
OCC = "nav_msgs/msg/OccupancyGrid"
POSE = "geometry_msgs/msg/PoseWithCovarianceStamped"

#: A one-channel 40 × 30 field without evaporation, as the ROS 2 tests start it.
ONE_CHANNEL_FIELD = """
width = 40
height = 30
cell_size_m = 0.1
origin_x_m = -1.0
origin_y_m = 0.5
tick_hz = 50.0

[[channel]]
name = "trail"
evaporation = { model = "none" }
"""

GRID_MAP_MSG = """std_msgs/Header header
GridMapInfo info
string[] layers
string[] basic_layers
std_msgs/Float32MultiArray[] data
uint16 outer_start_index
uint16 inner_start_index
"""
GRID_MAP_INFO_MSG = """float64 resolution
float64 length_x
float64 length_y
geometry_msgs/Pose pose
"""


def register_grid_map(store, get_types_from_msg):
    """Adds grid_map_msgs/msg/GridMap and GridMapInfo to a rosbags type store."""
    types = {}
    types.update(get_types_from_msg(GRID_MAP_MSG, GRID))
    types.update(get_types_from_msg(GRID_MAP_INFO_MSG, "grid_map_msgs/msg/GridMapInfo"))
    store.register(types)
    return store


def dds(name):
    """A ROS 2 type name as rmw_zenoh's key expressions spell it (`pkg::msg::dds_::Type_`)."""
    pkg, sub, base = name.split("/")
    return f"{pkg}::{sub}::dds_::{base}_"


def free_port():
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening_session(endpoint):
    """A Zenoh peer listening on `endpoint` (no multicast, no shared memory), for `sim --ros2`
    to connect to. Needs eclipse-zenoh."""
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/shared_memory/enabled", "false")
    return zenoh.open(conf)


def run_sim_watching_tokens(z, args, err_path):
    """Runs `pheromone sim ARGS` to its end while session `z` collects the ROS 2 liveliness
    tokens (`@ros2_lv/0/**`) it sees; returns (exit status, tokens, stdout); stderr goes to
    `err_path`."""
    tokens = set()
    with open(err_path, "wb") as err:
        p = subprocess.Popen([str(BIN), "sim", *map(str, args)], stdout=subprocess.PIPE,
                             stderr=err)
        STARTED_PIDS.add(p.pid)
        try:
            while p.poll() is None:
                for r in z.liveliness().get("@ros2_lv/0/**", timeout=1.0):
                    if r.ok is not None:
                        tokens.add(str(r.ok.key_expr))
                # Between two looks, wait for the sim to end (not a fixed sleep).
                with contextlib.suppress(subprocess.TimeoutExpired):
                    p.wait(timeout=0.2)
            out, _ = p.communicate(timeout=60)
        finally:
            if p.poll() is None:
                p.kill()
                p.communicate()
    return p.returncode, tokens, out
