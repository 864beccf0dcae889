"""`pheromone.Field` against real fields: attach, zero-copy frames, values and deposits as Rust's.

Also the grid as attributes, deposits equal to `pheromone deposit`'s, refusal of another layout,
frame lifetimes, `wait_frame`'s spin and timeout, and the watch example."""

import ctypes
import os
import signal
import statistics
import subprocess
import sys
import time

import numpy as np
import pytest

import pheromone
from conftest import REPO, STARTED_PIDS, deadline_loop, probe, run_cli

F32 = np.float32
CELLS = ("--width", "40", "--height", "30", "--cell-size", "0.1")
GRID = (*CELLS, "--tick-hz", "50")


def attach(f, timeout_s=10.0, **kw):
    return pheromone.Field.attach(f.name, timeout_s=timeout_s, **kw)


def wait_applied(field, n, timeout_s=10):
    """Waits (with a deadline) until the field's header counts `n` applied deposits."""
    for _ in deadline_loop(timeout_s, f"{n} deposits applied"):
        field.wait_frame(0.2)
        h = field.frame().header
        assert h.deposits_rejected_total() == 0, h.deposits_rejected_by_reason()
        if h.deposits_applied >= n:
            return field.frame()


def test_attach_reads_the_header_of_the_running_field(start_field):
    f = start_field("a", *GRID, "--origin-x", "-1.5", "--origin-y", "0.5")
    t0 = time.monotonic()
    with attach(f) as field:
        attach_s = time.monotonic() - t0
        header, cells = field.frame()
        assert header.layout_version == pheromone.LAYOUT_VERSION
        assert (header.channels, header.width, header.height) == (1, 40, 30)
        assert header.cell_size_m == pytest.approx(0.1)
        assert (header.origin_x_m, header.origin_y_m) == (-1.5, 0.5)
        assert header.dt_s == pytest.approx(0.02)
        assert len(header.deposits_rejected) == 7
        assert cells.shape == (1, 30, 40) and cells.dtype == np.float32
        assert not cells.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            cells[0, 0, 0] = 1.0
        # Making it writable is refused (it would let a write reach the field's published
        # memory, which segfaults): for the frame, a view of it and a reshaped copy-free view.
        for a in (cells, cells[0], cells.reshape(-1)):
            with pytest.raises(ValueError, match="WRITEABLE"):
                a.setflags(write=True)
        seq = header.sequence
        assert field.wait_frame(2.0)
        assert field.frame().header.sequence > seq
        # The grid as attributes, from the first frame.
        assert field.name == f.name
        assert (field.channels, field.height, field.width) == field.shape == (1, 30, 40)
        assert field.cell_size_m == pytest.approx(0.1)
        assert field.origin == (field.origin_x_m, field.origin_y_m) == (-1.5, 0.5)
        assert "1×30×40" in repr(field)
    print(f"\nattach (field already running) {attach_s * 1e3:.1f} ms")


def test_a_field_is_made_by_attach_only():
    with pytest.raises(TypeError, match=r"Field\.attach"):
        pheromone.Field()
    with pytest.raises(ValueError, match="invalid field name"):
        pheromone.Field.attach("no/such", timeout_s=0.1)


def test_attach_without_a_field_names_it(start_field):
    name = "no-such-field-" + str(os.getpid())
    t0 = time.monotonic()
    with pytest.raises(pheromone.FieldNotFound, match=f"'{name}'"):
        pheromone.Field.attach(name, timeout_s=0.5)
    assert time.monotonic() - t0 < 3


def test_a_field_in_an_iceoryx2_domain_is_found_with_that_domain_only(start_field, monkeypatch):
    dom = f"py{os.getpid()}"
    f = start_field("dom", *GRID, "--iox-domain", dom)
    with attach(f, domain=dom) as field:
        assert field.domain == dom
        assert field.wait_frame(2.0)
        assert field.frame().header.width == 40
    monkeypatch.delenv("PHEROMONE_IOX_DOMAIN", raising=False)
    with pytest.raises(pheromone.FieldNotFound, match=f"'{f.name}'"):
        pheromone.Field.attach(f.name, timeout_s=0.5)
    # The domain a `pheromone --iox-domain` parent hands its children.
    monkeypatch.setenv("PHEROMONE_IOX_DOMAIN", dom)
    with attach(f) as field:
        assert field.domain == dom
    with pytest.raises(ValueError, match="invalid iceoryx2 domain 'a/b'"):
        attach(f, domain="a/b")


def test_attach_waits_for_a_field_that_starts_later(start_field):
    import threading

    box = {}

    def later():
        box["f"] = start_field("late", *GRID)

    t = threading.Timer(0.5, later)
    t.start()
    try:
        for _ in deadline_loop(5, "the late field to be started"):
            if "f" in box:
                break
            time.sleep(0.01)
        with attach(box["f"], timeout_s=10) as field:
            assert field.frame().header.width == 40
    finally:
        t.join()


def test_generation_counts_the_field_processes_a_client_read_across_a_restart(start_field):
    f = start_field("gen", *GRID)
    with attach(f) as field:
        assert field.generation == 1
        f.kill()  # SIGKILL: no goodbye from the field
        field.wait_frame(0.2)  # nothing comes from a dead field
        assert field.generation == 1
        start_field("gen", *GRID)  # the same name again
        for _ in deadline_loop(10, "a frame of the restarted field"):
            if field.wait_frame(0.1) and field.generation == 2:
                break
        assert field.generation == 2


def _shm_mapping(address):
    """The /proc/self/maps line of the mapping holding `address`."""
    with open("/proc/self/maps") as m:
        for line in m:
            lo, hi = (int(v, 16) for v in line.split()[0].split("-"))
            if lo <= address < hi:
                return lo, hi, line.strip()
    return None


def test_frame_is_a_zero_copy_view_of_the_shared_memory_sample(start_field):
    f = start_field("z", "--width", "512", "--height", "512", "--cell-size", "0.05")
    with attach(f) as field:
        with field.frame() as frame:
            _header, cells = frame
            data = cells.__array_interface__["data"][0]
            sample = frame._sample
            lo = sample.payload_ptr
            hi = lo + sample.header.number_of_elements * ctypes.sizeof(ctypes.c_float)
            # The array's buffer is the sample's payload, and the whole array lies inside it.
            assert lo <= data and data + cells.nbytes <= hi, (hex(data), hex(lo), hex(hi))
            assert data == lo and cells.nbytes == hi - lo == 512 * 512 * 4
            # … which is a shared mapping of an iceoryx2 segment in /dev/shm.
            mapping = _shm_mapping(data)
            assert mapping and "/dev/shm/iox2_" in mapping[2], mapping
            assert mapping[0] <= data and data + cells.nbytes <= mapping[1]
            # The array owns nothing: its base is a flat array over a read-only memoryview of
            # the ctypes array at the sample's address.
            assert not cells.flags.owndata and not cells.base.flags.owndata
            view = cells.base.base
            assert isinstance(view, memoryview) and view.readonly
            assert ctypes.addressof(view.obj) == lo
            print(f"\nzero-copy: array at {data:#x}, sample payload {lo:#x}..{hi:#x}, "
                  f"mapping {mapping[2]}")
        # Getting a new frame costs no copy: time from the field's publish stamp to the array.
        lat, get = [], []
        for _ in range(100):
            assert field.wait_frame(2.0)
            t0 = time.perf_counter_ns()
            fr = field.frame()
            arr = fr.cells
            get.append(time.perf_counter_ns() - t0)
            lat.append(time.monotonic_ns() - fr.header.stamp_ns)
            assert arr.shape == (1, 512, 512)
            del fr, arr
        lat.sort()
        print(f"1 MiB frames: publish → NumPy view p50 {lat[50] / 1e3:.0f} µs, "
              f"p99 {lat[98] / 1e3:.0f} µs; frame() {statistics.median(get) / 1e3:.1f} µs "
              f"(100 frames)")


def test_values_equal_rusts_frameview(start_field):
    # No evaporation: every frame after the deposits holds the same values.
    f = start_field("v", *GRID, "--origin-x", "-1.3", "--origin-y", "0.7", "--model", "none")
    with attach(f) as field:
        field.deposit(0.4, 2.1, 0.004, cov=(0.02, 0.005, 0.01))
        field.deposit(1.37, 1.21, 0.003, cov=(0.01, -0.004, 0.03), range_m=0.6)
        field.deposit(-0.95, 3.35, 0.002)
        frame = wait_applied(field, 3)
        h = frame.header
        points = [
            (0.4, 2.1), (0.43, 2.07), (1.37, 1.21), (1.4011, 1.19), (-0.95, 3.35),
            (-1.3, 0.7), (-1.28, 0.72), (2.7, 3.7), (2.69, 3.69), (0.0, 2.0), (-2.0, 2.0),
            (1.0, 1.0) , (0.9, 2.5),
        ]
        for x, y in points:
            rust = probe(f.name, x, y)
            assert rust["sequence"] >= h.sequence
            ours = frame.sample(x, y)
            assert ours == rust["value"], (x, y, ours, rust["value"])
        # The gradient from Rust's values one cell apart (FrameView::gradient's definition).
        c = F32(h.cell_size_m)
        for x, y in [(0.43, 2.07), (1.3, 1.25)]:
            x32, y32 = F32(x), F32(y)
            v = {k: F32(probe(f.name, float(px), float(py))["value"])
                 for k, (px, py) in {"xp": (x32 + c, y32), "xm": (x32 - c, y32),
                                     "yp": (x32, y32 + c), "ym": (x32, y32 - c)}.items()}
            rust_g = (float((v["xp"] - v["xm"]) / (F32(2) * c)),
                      float((v["yp"] - v["ym"]) / (F32(2) * c)))
            assert pheromone.gradient(frame, x, y) == rust_g
            assert rust_g != (0.0, 0.0)


def _ellipse_peak(tau, cov, gamma_max):
    det = (0.5 * (cov[0] + cov[2])) ** 2 - (0.25 * (cov[0] - cov[2]) ** 2 + cov[1] ** 2)
    return min(tau / det, gamma_max)


def test_python_deposit_appears_where_and_as_high_as_expected(start_field):
    f = start_field("d", *GRID, "--model", "none")
    with attach(f) as field:
        before = field.frame().header
        # At the centre of cell (12, 7): γ = τ / det Σ = 0.005 / 1e-4 = 50.
        x, y = (12 + 0.5) * 0.1, (7 + 0.5) * 0.1
        field.deposit(x, y, 0.005, cov=(0.01, 0.0, 0.01))
        frame = wait_applied(field, before.deposits_applied + 1)
        cells = frame.cells
        peak = np.unravel_index(int(np.argmax(cells)), cells.shape)
        assert tuple(int(i) for i in peak) == (0, 7, 12)
        peak_value = _ellipse_peak(0.005, (0.01, 0, 0.01), 100)
        assert float(cells.max()) == pytest.approx(peak_value, rel=1e-5)
        assert frame.header.deposits_this_tick in (0, 1)
        assert frame.sample(x, y) == pytest.approx(50.0, rel=1e-5)
        # Symmetric around its centre, cut at range_m = 1 m.
        assert cells[0, 7, 11] == pytest.approx(cells[0, 7, 13])
        assert cells[0, 7, 0] == pytest.approx(50 * np.exp(-0.5 * 1.2 ** 2 / 0.01), abs=1e-6)


@pytest.mark.parametrize(
    ("kernel", "kwargs", "cli"),
    [
        ("ellipse", {"cov": (0.02, 0.006, 0.015), "range_m": 0.8, "gamma_max": 40.0},
         ["--cov", "0.02,0.006,0.015", "--range", "0.8", "--gamma-max", "40"]),
        ("paper", {"cov": (0.03, 0.0, 0.01)}, ["--cov", "0.03,0,0.01"]),
        ("saturating", {"sigma_m": 0.25, "range_m": 0.7}, ["--sigma", "0.25", "--range", "0.7"]),
        ("z-shape", {"plateau_m": 0.15, "slope_m": 0.35}, ["--plateau", "0.15", "--slope", "0.35"]),
    ],
)
def test_python_deposit_equals_the_same_deposit_from_rust(start_field, kernel, kwargs, cli):
    """Twin fields: one gets the deposit from Python, the other from `pheromone deposit` (Rust's
    DepositMsg); both frames are equal cell for cell."""
    amount = {"saturating": "0.6", "ellipse": "0.004", "paper": "0.004"}.get(kernel, "2.5")
    model = ("--model", "none")
    py, rs = start_field("p", *GRID, *model), start_field("r", *GRID, *model)
    with attach(py) as a, attach(rs) as b:
        a.deposit(1.83, 1.47, float(amount), kernel=kernel, channel=0, **kwargs)
        run_cli("deposit", "--field", rs.name, "--kernel", kernel, "--x", "1.83", "--y", "1.47",
                "--amount", amount, *cli)
        fa, fb = wait_applied(a, 1), wait_applied(b, 1)
        assert fa.cells.max() > 0
        np.testing.assert_array_equal(fa.cells, fb.cells)


def test_deposit_refuses_parameters_its_kernel_does_not_use(start_field):
    f = start_field("k", *GRID)
    with attach(f) as field:
        with pytest.raises(ValueError, match="does not use sigma_m"):
            field.deposit(1.0, 1.0, 0.1, sigma_m=0.2)
        with pytest.raises(ValueError, match="unknown kernel"):
            field.deposit(1.0, 1.0, 0.1, kernel="gauss")


def test_a_client_of_another_layout_is_refused_naming_both_types(start_field):
    f = start_field("l", *GRID)
    newer = pheromone.LAYOUT_VERSION + 1

    class NextHeader(pheromone.FrameHeader):
        @staticmethod
        def type_name():
            return pheromone.wire_type_name("FrameHeader", newer)

    with pytest.raises(pheromone.LayoutMismatch) as e:
        attach(f, timeout_s=5, header_type=NextHeader)
    msg = str(e.value)
    assert f"pheromone::FrameHeader/v{newer}" in msg
    assert f"pheromone::FrameHeader/v{pheromone.LAYOUT_VERSION}" in msg
    assert f"pheromone/{f.name}/frame" in msg
    # The same field still serves a client of its own layout.
    with attach(f) as field:
        assert field.frame().header.layout_version == pheromone.LAYOUT_VERSION


def test_frames_live_as_long_as_they_are_held(start_field):
    f = start_field("h", *CELLS, "--tick-hz", "100")
    with attach(f) as field:
        first = field.frame()
        cells = first.cells[0]  # a view keeps the sample alive too
        seq = first.header.sequence
        del first
        for _ in range(5):
            assert field.wait_frame(2.0)
        assert field.frame().header.sequence > seq
        second = field.frame()  # the reader now holds two frames

        def wait_for_a_third_frame():
            for _ in deadline_loop(5, "a third frame"):
                field.wait_frame(0.2)

        with pytest.raises(pheromone.FramesHeld):
            wait_for_a_third_frame()
        del cells, second
        for _ in range(3):
            assert field.wait_frame(2.0)
        with field.frame() as fr:
            assert not fr.closed
        assert fr.closed
        assert field.wait_frame(2.0)


def test_watch_example_prints_a_line_per_frame_until_ctrl_c(start_field):
    f = start_field("w", *CELLS, "--tick-hz", "20", "--model", "none")
    with attach(f) as field:
        field.deposit(2.05, 1.55, 0.003)
        wait_applied(field, 1)
    # Ctrl-C as in a terminal: SIGINT at its default even if this run inherited it ignored (a
    # non-interactive shell's background job), where Python would install no KeyboardInterrupt.
    p = subprocess.Popen([sys.executable, str(REPO / "examples" / "python" / "watch.py"), f.name],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    STARTED_PIDS.add(p.pid)
    lines = []
    try:
        for _ in deadline_loop(15, "three lines from watch.py"):
            line = p.stdout.readline()
            if line:
                lines.append(line)
            if len(lines) >= 3 or p.poll() is not None:
                break
    finally:
        p.send_signal(signal.SIGINT)
        _out, err = p.communicate(timeout=10)
    assert len(lines) >= 3, (lines, err)
    assert p.returncode == 0, err
    # "frame <seq> max <value> at channel 0 cell (x, y) = (… m, … m)"
    assert "max 30" in lines[-1] and "cell (20, 15)" in lines[-1], lines


def test_a_python_deposit_wakes_a_field_that_publishes_on_deposit(start_field):
    """`pheromone field --publish-on-deposit-ms`: a Python deposit notifies the field's
    `deposit-ready` event, so it is in a frame long before the next tick (one every 50 s)."""
    f = start_field("od", *CELLS, "--tick-hz", "0.02", "--publish-on-deposit-ms", "0",
                    "--model", "none")
    with attach(f) as field:
        for _ in deadline_loop(10, "the first frame"):
            field.wait_frame(0.2)
            if field.frame() is not None:
                break
        first = field.frame().header
        field.deposit(1.25, 0.75, 0.005, cov=(0.01, 0.0, 0.01))
        frame = wait_applied(field, 1, timeout_s=20)
        assert frame.header.sequence == first.sequence + 1
        assert frame.sample(1.25, 0.75) > 0
        # Stepped by the real time since the last frame, not by the 50 s period.
        assert frame.header.sim_time_s < 20, frame.header.sim_time_s


def test_wait_frame_spins_or_sleeps_as_asked_and_honours_its_timeout(start_field):
    """`wait_frame(timeout_s, spin_s)`: sleeping on the event, spinning first, or busy-polling
    (spin ≥ timeout), each sees the next frame of a ticking field; with no frame due it returns
    False at its timeout, not before; bad arguments are refused naming them."""
    ticking = start_field("tick", *CELLS, "--tick-hz", "50")
    with attach(ticking) as field:
        for spin_s in (0.0, 0.005, 10.0):
            for _ in range(3):
                assert field.wait_frame(5.0), "the field ticks at 50 Hz"
                before = field.frame().header.sequence
                assert field.wait_frame(5.0, spin_s=spin_s), f"spin_s={spin_s}: no frame in 5 s"
                assert field.frame().header.sequence > before, spin_s
        for bad in ({"timeout_s": -1.0}, {"timeout_s": 1.0, "spin_s": float("nan")}):
            with pytest.raises(ValueError, match="spin_s"):
                field.wait_frame(**bad)
    # One frame every 50 s: after the first (which attaching may already hold), none is due.
    slow = start_field("slow", *CELLS, "--tick-hz", "0.02")
    with attach(slow) as field:
        field.wait_frame(1.0)
        assert field.frame().header.sequence == 0
        for spin_s in (0.0, 0.1, 1.0):
            t = time.monotonic()
            assert not field.wait_frame(0.3, spin_s=spin_s), spin_s
            took = time.monotonic() - t
            assert 0.3 <= took < 5.0, (spin_s, took)


def test_attach_leaves_iceoryx2s_log_level_alone_and_set_log_level_is_the_callers(
    start_field, monkeypatch
):
    import iceoryx2 as iox2

    calls = []
    real = iox2.set_log_level
    monkeypatch.setattr(iox2, "set_log_level", lambda level: (calls.append(level), real(level)))
    f = start_field("loglevel", *GRID)
    with attach(f):
        pass
    assert calls == [], "attach changed iceoryx2's process-wide log level"
    pheromone.set_log_level("error")
    assert calls == [iox2.LogLevel.Error]
    with pytest.raises(ValueError, match="'loud'"):
        pheromone.set_log_level("loud")


def test_a_reader_beyond_max_readers_is_refused_naming_the_field_and_the_flag(start_field):
    f = start_field("full", *GRID, "--max-readers", "2")
    held = []
    refused = None
    try:
        # Two readers and whatever the field itself counts: attach until one is refused.
        for _ in range(8):
            try:
                held.append(attach(f))
            except pheromone.PheromoneError as e:
                refused = e
                break
        assert refused is not None, f"{len(held)} readers attached to a field of --max-readers 2"
        assert not isinstance(refused, pheromone.FieldNotFound), refused
        msg = str(refused)
        assert f.name in msg and "--max-readers" in msg, msg
        assert len(held) >= 2, f"only {len(held)} reader(s) attached before the refusal: {msg}"
        # The readers that attached still read.
        assert held[0].wait_frame(10)
    finally:
        for r in held:
            r.close()
