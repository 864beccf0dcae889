"""A mapper's map of `sim ias-ss --merge` (processes), read with `pheromone.Field`.

A mapper's map, read with the Python package: `pheromone sim ias-ss --merge` as processes
starts one `pheromone mapper` per robot, each publishing its occupancy + pheromone map as the
field `<run>-map-r<ID>` (run tag `sim<PID>x0`); the test attaches to robot 1's map while the
run steps, checks its frame (2 channels, finite, the geometry its header states), and stops
the run with SIGINT, waiting for it (also when the test fails)."""

import signal
import subprocess

import numpy as np
import pytest

import pheromone
from conftest import BIN, STARTED_PIDS, deadline_loop


@pytest.fixture
def sim_run(tmp_path):
    if not BIN.exists():
        pytest.fail(f"pheromone binary not found at {BIN} (set PHEROMONE_BIN or cargo build)")
    err_path = tmp_path / "sim.stderr"
    err = open(err_path, "wb")
    proc = subprocess.Popen(
        [str(BIN), "sim", "ias-ss", "--merge", "--robots", "2", "--duration", "100000",
         "--no-out"],
        stdout=subprocess.DEVNULL, stderr=err)
    STARTED_PIDS.add(proc.pid)
    yield proc, err_path
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            raise AssertionError(
                f"sim did not stop on SIGINT: {err_path.read_text()[-2000:]}"
            ) from None
    err.close()
    # Interrupted, the run stops every process of it, sums up the steps it ran and says so
    # (status 130 = 128 + SIGINT).
    text = err_path.read_text()
    assert proc.returncode == 130 and "stopped by a signal, written as far as it ran" in text, (
        f"sim exited with {proc.returncode}: {text[-2000:]}")


def test_a_mappers_map_frame_is_read_by_the_python_package(sim_run):
    proc, err_path = sim_run
    name = f"sim{proc.pid}x0-map-r1"
    field = None
    for _ in deadline_loop(120, f"map field {name}"):
        assert proc.poll() is None, f"sim exited with {proc.returncode}: {err_path.read_text()}"
        try:
            field = pheromone.Field.attach(name, timeout_s=2.0)
            break
        except pheromone.FieldNotFound:
            continue
    with field:
        for _ in deadline_loop(120, f"a frame of {name} after step 10"):
            field.wait_frame(1.0)
            header, cells = field.frame()
            if header.sequence > 10:
                break
        assert header.channels == 2
        assert header.width == header.height and header.width > 0
        assert header.cell_size_m > 0
        assert cells.shape == (2, header.height, header.width) == field.shape
        assert cells.dtype == np.float32
        assert np.isfinite(cells).all()
        # The map knows the cells its scans saw: occupancy log-odds are not all zero.
        assert np.count_nonzero(cells[0]) > 0
        seq = header.sequence
        for _ in deadline_loop(60, f"a newer frame of {name}"):
            if field.wait_frame(1.0) and field.frame().header.sequence > seq:
                break
        h2, c2 = field.frame()
        assert (h2.channels, h2.width, h2.height) == (2, header.width, header.height)
        assert h2.cell_size_m == header.cell_size_m
        assert np.isfinite(c2).all()
