"""Confirmed deposits from Python: `Field.deposit` waits for the field's receipt (at most once).

Separate Python processes that exit as soon as `deposit()` returns have their deposit applied
exactly once at 0.2 Hz and 100 Hz; refusals raise `DepositRejected` naming the reason and the
values, non-finite numbers never leave the process; `wait=False` deposits are applied after
`flush()` (and after `close()` of a script that exits at once); a sender SIGKILLed while it waits
is applied at most once and leaves nothing behind."""

import math
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import iceoryx2 as iox2
import pytest

import pheromone
from conftest import IOX_ROOT, STARTED_PIDS, _entries, _node_pid, deadline_loop
from pheromone import _wire

# No evaporation: a cell holds exactly the deposits applied to it.
GRID = ("--width", "64", "--height", "64", "--cell-size", "0.1", "--model", "none", "--json")
#: γ at the centre of one ellipse deposit of `amount` 0.005 with cov (0.01, 0, 0.01): τ / det Σ.
PEAK = 50.0
Y_M = 3.05

#: A depositor process: attaches, deposits once (waiting for the receipt unless told not to) and
#: exits as soon as `deposit()` returns (leaving the `with` block closes the Field).
SENDER = textwrap.dedent(
    """
    import sys
    import pheromone

    name, x, robot, mode = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    with pheromone.Field.attach(name, timeout_s=30, robot_id=robot) as field:
        print("attached", flush=True)
        r = field.deposit(x, float(sys.argv[5]), 0.005, cov=(0.01, 0.0, 0.01), range_m=0.4,
                          wait=mode == "wait")
        print("sent" if r is None else f"{r.status} {r.sequence}", flush=True)
    """
)


def x_of(i):
    """The centre of sender `i`'s deposit (i < 6): the centre of cell (5 + 10 i, 30); footprints
    of 0.4 m do not overlap and stay on the 6.4 m grid."""
    return 0.55 + i


def cell_of(x):
    return round((x - 0.05) / 0.1)


def spawn_sender(field, i, mode="wait"):
    # The same package as this test imports (the child's `pheromone` is not looked up anew).
    env = dict(os.environ, PYTHONPATH=str(Path(pheromone.__file__).resolve().parents[1]))
    p = subprocess.Popen(
        [sys.executable, "-c", SENDER, field, repr(x_of(i)), str(i), mode, repr(Y_M)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )
    STARTED_PIDS.add(p.pid)
    return p


def finish(p, timeout=60):
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        out, err = p.communicate()
        pytest.fail(f"sender {p.pid} did not finish in {timeout} s: {out} {err}")
    assert p.returncode == 0, f"sender {p.pid} exited with {p.returncode}: {err}"
    return out.split()


def attach(f, timeout_s=30.0):
    return pheromone.Field.attach(f.name, timeout_s=timeout_s)


@pytest.mark.parametrize(("hz", "senders"), [(0.2, 3), (100.0, 5)])
def test_a_process_that_exits_when_deposit_returns_has_it_applied_exactly_once(
    start_field, hz, senders
):
    f = start_field(f"hz{hz:g}".replace(".", "_"), *GRID, "--tick-hz", str(hz))
    # Senders in parallel, each its own process that exits as soon as its deposit is confirmed.
    procs = [spawn_sender(f.name, i) for i in range(senders)]
    outs = [finish(p) for p in procs]
    for out in outs:
        assert out[0] == "attached" and out[1] == "applied", outs
    frames = [int(out[2]) for out in outs]
    # Every sender has exited: every deposit is in the field, once.
    summary = f.summary()
    assert summary["deposits_applied"] == senders, summary
    assert sum(summary["deposits_rejected"].values()) == 0, summary
    assert summary["sequence"] >= max(frames), (summary, frames)
    assert summary["max"] == [pytest.approx(PEAK, rel=1e-5)], summary
    print(f"\n{hz} Hz: {senders} senders applied in frames {sorted(frames)}")


def test_refused_deposits_raise_naming_the_reason_and_nan_is_never_sent(start_field):
    f = start_field("bad", *GRID, "--tick-hz", "100")
    with attach(f) as field:
        assert field.channels == 1
        with pytest.raises(pheromone.DepositRejected, match=r"unknown_channel: .*channel 7 ") as e:
            field.deposit(1.0, 1.0, 0.005, channel=7)
        assert isinstance(e.value, ValueError) and e.value.reason == "unknown_channel"
        assert "x_m 1, y_m 1, amount 0.005" in str(e.value)
        with pytest.raises(
            pheromone.DepositRejected, match=r"not_psd: .*cov \(0\.01, 0\.02, 0\.01\)"
        ) as e:
            field.deposit(2.0, 2.0, 0.005, cov=(0.01, 0.02, 0.01))
        assert e.value.reason == "not_psd" and e.value.sequence > 0
        # Non-finite numbers are refused before anything is sent, naming parameter and value.
        nan, inf = math.nan, math.inf
        for kwargs, named in [
            ({"x_m": nan}, "x_m nan"),
            ({"amount": -inf}, "amount -inf"),
            ({"cov": (0.01, nan, 0.01)}, "cov xy nan"),
            ({"range_m": 1e39}, "range_m 1e+39"),
        ]:
            args = {"x_m": 1.0, "y_m": 1.0, "amount": 0.005, **kwargs}
            with pytest.raises(ValueError, match=re.escape(named)) as e:
                field.deposit(**args)
            assert not isinstance(e.value, pheromone.DepositRejected)
        msg = _wire.ellipse(0, 1.0, nan, 0.005, (0.01, 0.0, 0.01), 1.0, 100.0)
        with pytest.raises(ValueError, match=r"DepositMsg\.y_m nan"):
            field.send(msg)
        with pytest.raises(ValueError, match="timeout_s nan"):
            field.deposit(1.0, 1.0, 0.005, timeout_s=nan)
        r = field.deposit(3.0, 3.0, 0.005)
        assert r.status == "applied" and r.reason is None
        # The receipt's frame is held once deposit() returns.
        h = field.frame().header
        assert h.sequence >= r.sequence
        assert h.deposits_applied == 1
        rejected = h.deposits_rejected_by_reason()
        assert (rejected["unknown_channel"], rejected["not_psd"]) == (1, 1), rejected
        assert rejected["non_finite"] == 0, rejected
        summary = f.summary()
        # The field has stopped: nobody answers.
        with pytest.raises(pheromone.DepositNotDelivered, match="no field serves"):
            field.deposit(3.0, 3.0, 0.005)
    assert summary["deposits_applied"] == 1, summary
    assert summary["deposits_rejected"]["non_finite"] == 0, summary
    assert summary["deposits_rejected"]["unknown_channel"] == 1, summary


def test_without_waiting_deposits_are_applied_after_flush_and_close(start_field):
    """`wait=False` returns None at once; `flush()` waits for the field's answer to a flush
    request (at 0.5 Hz, longer than the two frames it used to wait for), and a script that sends
    without waiting and exits at once still has its deposit applied (its close() flushes)."""
    f = start_field("nowait", *GRID, "--tick-hz", "0.5")
    with attach(f) as field:
        assert field.frame().header.deposits_applied == 0
        assert field.flush(timeout_s=0.0), "nothing to flush"
        assert field.deposit(x_of(0), Y_M, 0.005, range_m=0.4, wait=False) is None
        assert field.flush(timeout_s=30)
        h = field.frame().header
        assert h.deposits_applied == 1, h
        assert field.frame().cells[0, cell_of(Y_M), cell_of(x_of(0))] == pytest.approx(PEAK)
        out = finish(spawn_sender(f.name, 1, "nowait"))
        assert out == ["attached", "sent"], out
        # Its close() returned after the field's answer to the flush, sent after the frame.
        field.update()
        h = field.frame().header
        assert h.deposits_applied == 2, h
        assert field.frame().cells[0, cell_of(Y_M), cell_of(x_of(1))] == pytest.approx(PEAK)
    assert f.summary()["deposits_applied"] == 2


def _confirm_clients(field):
    factory = (
        field._node.service_builder(iox2.ServiceName.new(_wire.deposit_confirm_service(field.name)))
        .request_response(_wire.DepositMsg, _wire.DepositReceipt)
        .open()
    )
    return factory.dynamic_config.number_of_clients


def _node_tokens(pids):
    """Ids of the iceoryx2 nodes and ports of processes `pids` (not of the services they use,
    which are the field's)."""
    tokens = set()
    for d in (IOX_ROOT / "nodes").iterdir():
        if d.is_dir() and _node_pid(d) in pids:
            tokens.add(d.name)
            tokens |= {
                f.name[len("iox2_"):].split(".")[0]
                for f in d.iterdir()
                if f.name.startswith("iox2_") and f.name.endswith(".port_tag")
            }
    return tokens


def _wait_removed(field, tokens, clients):
    """Waits until the field has removed what killed senders left (it cleans dead nodes once a
    second): their entries (`tokens`) are gone and `clients` client ports remain."""
    for _ in deadline_loop(30, "the killed senders' ports and entries to be removed"):
        left = {e for e in _entries() if any(t in e for t in tokens)}
        if _confirm_clients(field) == clients and not left:
            return
        field.wait_frame(0.05)


def _next_frame(field):
    """Waits for a frame newer than the newest one now."""
    field.update()
    seq = field.frame().header.sequence
    for _ in deadline_loop(30, f"a frame after {seq}"):
        if field.wait_frame(1.0) and field.frame().header.sequence > seq:
            return


def _kill(procs):
    for p in procs:
        p.send_signal(signal.SIGKILL)
    for p in procs:
        p.communicate(timeout=10)
        assert p.returncode == -signal.SIGKILL


def test_a_sender_killed_while_it_waits_is_applied_at_most_once(start_field):
    """At 0.2 Hz, six senders wait for their receipt: three are SIGKILLed before the field's
    next tick (their requests die with their ports, or are applied if the tick comes first);
    three are SIGSTOPped, the field takes their requests at its next tick and answers nobody,
    then they are SIGKILLed. No deposit is applied twice, and nothing of theirs is left."""
    senders = 6
    f = start_field("kill", *GRID, "--tick-hz", "0.2")
    with attach(f) as field:
        procs = [spawn_sender(f.name, i) for i in range(senders)]
        # Each sender creates its client port just before it sends.
        for _ in deadline_loop(30, f"{senders} senders waiting for their receipt"):
            if _confirm_clients(field) == senders:
                break
            assert all(p.poll() is None for p in procs), [p.communicate() for p in procs]
            field.wait_frame(0.01)
        killed, stopped = procs[:3], procs[3:]
        tokens = _node_tokens({p.pid for p in killed})
        assert tokens
        for p in stopped:
            p.send_signal(signal.SIGSTOP)
        _kill(killed)
        _wait_removed(field, tokens, clients=len(stopped))
        # The stopped senders' requests are taken and answered at the next tick.
        _next_frame(field)
        tokens = _node_tokens({p.pid for p in stopped})
        _kill(stopped)
        _wait_removed(field, tokens, clients=0)
        # One more frame: whatever the field took from them is applied by then.
        _next_frame(field)
        frame = field.frame()
        values = [float(frame.cells[0, cell_of(Y_M), cell_of(x_of(i))]) for i in range(senders)]
        applied = frame.header.deposits_applied
    # Each deposit at most once: a cell holds nothing or one deposit's peak, never two.
    for v in values:
        assert v == 0.0 or v == pytest.approx(PEAK, rel=1e-5), values
    summary = f.summary()
    assert summary["deposits_applied"] == applied == sum(v > 0 for v in values), (summary, values)
    assert sum(summary["deposits_rejected"].values()) == 0, summary
    print(f"\napplied: {sum(v > 0 for v in values[:3])} of 3 killed while waiting, "
          f"{sum(v > 0 for v in values[3:])} of 3 killed after the field answered")


def test_tau_is_the_third_argument_and_amount_its_old_name(start_field):
    f = start_field("tau", *GRID, "--tick-hz", "100")
    with attach(f) as field:
        assert field.deposit(1.0, 1.0, tau=0.005).status == "applied"
        assert field.deposit(2.0, 2.0, amount=0.005).status == "applied"
        for kwargs in [{}, {"tau": 0.005, "amount": 0.005}]:
            with pytest.raises(TypeError, match="tau"):
                field.deposit(3.0, 3.0, **kwargs)
        with pytest.raises(ValueError, match="tau -inf"):
            field.deposit(3.0, 3.0, -math.inf)
