"""`pheromone sim --ros2`: one time base for the whole session, simulated time, and `/clock`
(rosgraph_msgs/msg/Clock) published (docs/ros2.md, "Time"). An `eclipse-zenoh` peer the child
connects to receives `/clock`, the GridMap and a robot's true pose; rosbags deserializes them
and computes the Clock's RIHS01 hash; the run's `robot_0.csv` has the simulated times. The child
runs with `--ros-distro rolling` (sim passes it on). Needs a `pheromone` binary built with
`--features zenoh`; skipped without it unless PHEROMONE_REQUIRE_ZENOH=1."""

import csv
import os
import threading

import pytest
from ros_msgs import (
    GRID,
    POSE,
    dds,
    free_port,
    listening_session,
    register_grid_map,
    run_sim_watching_tokens,
)

REQUIRED = os.environ.get("PHEROMONE_REQUIRE_ZENOH") == "1"

try:
    import zenoh  # noqa: F401  (the skip below when it is missing)
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
except ImportError as e:
    if REQUIRED:
        raise
    pytest.skip(f"pip install './python[zenoh,ros2]' for these tests ({e})",
                allow_module_level=True)

CLOCK = "rosgraph_msgs/msg/Clock"
SIM_S = 4.0


def _t(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def _run_sim(tmp_path, endpoint, z):
    out = tmp_path / "out"
    rc, tokens, _ = run_sim_watching_tokens(
        z, ["blind-leader", "--duration", SIM_S, "--realtime", "--ros2", endpoint,
            "--ros-distro", "rolling", "--out", out, "--json"], tmp_path / "sim.stderr")
    assert rc == 0, (tmp_path / "sim.stderr").read_text(errors="replace")
    return out, tokens


def test_sim_ros2_publishes_clock_and_stamps_everything_in_simulated_time(tmp_path):
    store = register_grid_map(get_typestore(Stores.ROS2_JAZZY), get_types_from_msg)
    hashes = {t: store.hash_rihs01(t) for t in (CLOCK, GRID, POSE)}
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    got, lock = {}, threading.Lock()

    def on_sample(s):
        with lock:
            got.setdefault(str(s.key_expr), []).append(bytes(s.payload.to_bytes()))

    with listening_session(endpoint) as z:
        subs = [z.declare_subscriber(k, on_sample)
                for k in ("0/clock/**", "0/pheromone/grid_map/**", "0/robot_0/true_pose/**")]
        out, tokens = _run_sim(tmp_path, endpoint, z)
        for s in subs:
            s.undeclare()

    def msgs(key, t):
        return [store.deserialize_cdr(b, t) for b in got.get(key, [])]

    clocks = [_t(m.clock) for m in msgs(f"0/clock/{dds(CLOCK)}/{hashes[CLOCK]}", CLOCK)]
    grids = [_t(m.header.stamp)
             for m in msgs(f"0/pheromone/grid_map/{dds(GRID)}/{hashes[GRID]}", GRID)]
    truths = [_t(m.header.stamp)
              for m in msgs(f"0/robot_0/true_pose/{dds(POSE)}/{hashes[POSE]}", POSE)]
    print(f"\n{len(clocks)} /clock, {len(grids)} GridMap, {len(truths)} true poses; "
          f"last /clock {clocks[-1] if clocks else None} s")
    assert set(got) <= {f"0/clock/{dds(CLOCK)}/{hashes[CLOCK]}",
                        f"0/pheromone/grid_map/{dds(GRID)}/{hashes[GRID]}",
                        f"0/robot_0/true_pose/{dds(POSE)}/{hashes[POSE]}"}, set(got)
    assert len(clocks) >= 10 and grids and len(truths) >= 10
    # /clock: simulated time, strictly increasing, within the run.
    assert clocks == sorted(clocks) and len(set(clocks)) == len(clocks)
    assert clocks[0] > 0.0 and clocks[-1] <= SIM_S + 1e-6
    # One time base: every GridMap stamp is a time /clock published (both are the frame's
    # field time), every pose stamp a step time of the run's robot_0.csv.
    assert set(grids) <= set(clocks), (grids, clocks[:5])
    with open(out / "robot_0.csv") as f:
        steps = {round(float(r["t_s"]), 6) for r in csv.DictReader(f)}
    assert {round(t, 6) for t in truths} <= steps
    # The clock and the poses advance together (the field ticks once per world step).
    assert abs(clocks[-1] - truths[-1]) < 1.0, (clocks[-1], truths[-1])

    # The /clock publisher's token: Rolling's form, rclcpp's ClockQoS (best effort, depth 1).
    [clock_tok] = [t for t in tokens if "%clock/" in t]
    parts = clock_tok.split("/")
    assert parts[5] == "MP" and parts[9:12] == ["%clock", dds(CLOCK), hashes[CLOCK]], parts
    assert parts[12] == "2::,1:,:,:,,", parts
