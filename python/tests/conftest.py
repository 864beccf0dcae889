"""Fixtures of the Python tests: real `pheromone field` processes, and nothing left behind.

Fixtures: real `pheromone field` processes (binary from $PHEROMONE_BIN, default
`target/debug/pheromone` of the repository), each with a field name unique to this run, stopped
with SIGINT and waited for (also when a test fails); and a session check that the run leaves
nothing in /dev/shm or iceoryx2's node directory."""

import json
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BIN = Path(os.environ.get("PHEROMONE_BIN", REPO / "target" / "debug" / "pheromone"))
if not BIN.is_absolute():
    BIN = REPO / BIN

# Hermetic against the caller's shell (issue 51): a `PHEROMONE_IOX_DOMAIN` set there would put
# the spawned fields and this process's clients in that domain, with other /dev/shm names and
# node directories than the tests look for. The tests of domains set it themselves.
os.environ.pop("PHEROMONE_IOX_DOMAIN", None)

#: Unique to this pytest run: every field name starts with it.
RUN = f"pyt{os.getpid()}{uuid.uuid4().hex[:6]}"

IOX_ROOT = Path("/tmp/iceoryx2")


def deadline_loop(timeout_s, what):
    """Yields until the caller breaks; fails the test naming `what` after `timeout_s`."""
    end = time.monotonic() + timeout_s
    while True:
        yield
        if time.monotonic() > end:
            pytest.fail(f"timed out after {timeout_s} s waiting for {what}")


#: Fixtures that start `pheromone` processes: a test using one is marked `process`
#: (`pytest -m "not process"` runs the tests that need no binary).
PROCESS_FIXTURES = {"start_field", "sim_run", "start_bridge", "zenoh_bin"}


def pytest_collection_modifyitems(items):
    for item in items:
        if PROCESS_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.process)


# ---- leftovers --------------------------------------------------------------------------------


def _entries():
    out = set()
    # iceoryx2's entries, and the `<n>.zenoh` segments of a Zenoh session with shared memory.
    def ours(n: str) -> bool:
        return n.startswith("iox2_") or n.endswith(".zenoh")

    for d, keep in ((Path("/dev/shm"), ours), (IOX_ROOT / "nodes", None),
                    (IOX_ROOT / "services", None)):
        try:
            for n in os.listdir(d):
                if n.endswith(".global_mgmt"):
                    continue
                if keep is None or keep(n):
                    out.add(str(d / n))
        except FileNotFoundError:
            pass
    return out


def _node_pid(node_dir: Path):
    """The pid recorded in an iceoryx2 node's details file, if readable."""
    import re

    try:
        text = (node_dir / "iox2_node.details").read_bytes().decode("utf-8", "replace")
    except OSError:
        return None
    m = re.search(r"^process = (\d+)", text, re.M)
    return int(m.group(1)) if m else None


def _alive(pid):
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        return True


def _foreign_tokens(our_pids):
    """Ids (node, port, service hash) used by iceoryx2 nodes of live processes that are not this
    run's: entries naming one of them belong to someone else on this host."""
    tokens, services = set(), 0
    try:
        nodes = list((IOX_ROOT / "nodes").iterdir())
    except FileNotFoundError:
        return tokens, services
    for d in nodes:
        if not d.is_dir():
            continue
        pid = _node_pid(d)
        if pid is None or pid in our_pids or not _alive(pid):
            continue
        tokens.add(d.name)
        for f in d.iterdir():
            stem = f.name.split(".")[0]
            if stem.startswith("iox2_"):
                tokens.add(stem[len("iox2_"):])
                services += f.name.endswith(".service_tag")
    return tokens, services


@pytest.fixture(scope="session", autouse=True)
def nothing_left_behind():
    """Every field, probe and Python client of this run is gone at the end, and so are their
    entries: nothing new in /dev/shm (`iox2_*`), /tmp/iceoryx2/nodes or …/services, except
    entries that live iceoryx2 processes of others on this host use."""
    before = _entries()
    yield
    import gc

    gc.collect()
    our_pids = {os.getpid(), *STARTED_PIDS}
    left = set()
    for _ in deadline_loop(10, "this run's iceoryx2 and Zenoh shared-memory entries to disappear"):
        new = _entries() - before
        tokens, foreign_services = _foreign_tokens(our_pids)
        left = {e for e in new if not any(t in e for t in tokens)}
        # A service's dynamic config is named by neither a node nor a port: count it against the
        # services the other processes hold.
        dynamic = sorted(e for e in left if e.endswith(".dynamic"))
        left -= set(dynamic[:foreign_services])
        if not left:
            break
    # No service of this run's fields remains either.
    assert not left, "the Python tests left iceoryx2 entries behind:\n" + "\n".join(sorted(left))
    listing = subprocess.run(
        [sys.executable, "-c", _LIST_SERVICES], capture_output=True, text=True, timeout=30
    )
    assert listing.returncode == 0, f"listing the services failed: {listing.stderr}"
    assert RUN not in listing.stdout, f"services of this run remain: {listing.stdout}"


_LIST_SERVICES = """
import iceoryx2 as iox2
iox2.set_log_level(iox2.LogLevel.Fatal)
for s in iox2.Service.list(iox2.config.global_config(), iox2.ServiceType.Ipc):
    print(s.name().to_string())
"""


# ---- fields -----------------------------------------------------------------------------------

STARTED_PIDS = set()


class FieldProcess:
    def __init__(self, name, args, tmp_path):
        self.name = name
        self.args = args
        self.stderr_path = tmp_path / f"{name}.stderr"
        self.stdout_path = tmp_path / f"{name}.stdout"
        self._stderr = open(self.stderr_path, "wb")
        self._stdout = open(self.stdout_path, "wb")
        self.proc = subprocess.Popen(
            [str(BIN), "field", "--name", name, *args],
            stdout=self._stdout,
            stderr=self._stderr,
        )
        STARTED_PIDS.add(self.proc.pid)
        self.killed = False

    def kill(self):
        """SIGKILLs the field (the crash a test wants) and reaps it; the fixture then takes
        that exit status as expected."""
        self.proc.kill()
        self.proc.wait()
        self.killed = True

    def stderr(self):
        return self.stderr_path.read_text(errors="replace")

    def summary(self):
        """Stops the field (SIGINT) and returns its `--json` summary (start it with `--json`)."""
        rc = self.stop()
        assert rc in (0, -signal.SIGINT, 130), f"field {self.name} exited with {rc}"
        out = self.stdout_path.read_text()
        assert out.strip(), f"field {self.name} printed no summary (--json?): {self.stderr()}"
        return json.loads(out.strip().splitlines()[-1])

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                raise AssertionError(
                    f"field {self.name} did not stop on SIGINT: {self.stderr()}"
                ) from None
        self._stderr.close()
        self._stdout.close()
        return self.proc.returncode


@pytest.fixture
def start_field(request, tmp_path):
    """`start_field(suffix, *args)` starts `pheromone field --name <run>-<test>-<suffix> args`;
    every field is stopped with SIGINT and waited for at the end of the test."""
    started = []
    test = request.node.name.replace("test_", "")[:20]
    test = "".join(c if c.isalnum() else "-" for c in test)

    def start(suffix="f", *args):
        if not BIN.exists():
            pytest.fail(f"pheromone binary not found at {BIN} (set PHEROMONE_BIN or cargo build)")
        f = FieldProcess(f"{RUN}-{test}-{suffix}"[:64], list(args), tmp_path)
        started.append(f)
        return f

    yield start
    errors = []
    for f in started:
        try:
            rc = f.stop()
            if rc not in (0, -signal.SIGINT, 130) and not (f.killed and rc == -signal.SIGKILL):
                errors.append(f"field {f.name} exited with {rc}: {f.stderr()[-2000:]}")
        except AssertionError as e:
            errors.append(str(e))
    assert not errors, "\n".join(errors)


def run_cli(*args, timeout=30):
    """Runs the `pheromone` binary (probe, deposit…); returns the completed process."""
    STARTED = subprocess.Popen([str(BIN), *map(str, args)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    STARTED_PIDS.add(STARTED.pid)
    try:
        out, err = STARTED.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        STARTED.send_signal(signal.SIGINT)
        out, err = STARTED.communicate()
        raise AssertionError(f"pheromone {' '.join(map(str, args))} timed out: {err}") from None
    assert STARTED.returncode == 0, f"pheromone {' '.join(map(str, args))} failed: {err}"
    return out


def probe(field, x, y, channel=0):
    """Rust's value (`FrameView::value` via `pheromone probe --json`) at a point."""
    return json.loads(run_cli("probe", "--field", field, "--x", repr(x), "--y", repr(y),
                              "--channel", channel, "--json", "--timeout", 10))
