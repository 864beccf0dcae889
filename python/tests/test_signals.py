"""A Python program keeps its own SIGTERM handling while it waits on a field (issue 47).

The test installs its own SIGTERM handler, blocks in `Field.wait_frame` on a live field that
ticks once per 100 s (so only a signal ends a wait early), and a thread (that blocks SIGTERM
itself) sends SIGTERMs to this process with the `kill` command: each wait raises
`pheromone.Interrupted` after the handler ran, so does a confirmed deposit waiting for its
receipt, and the handler sees every SIGTERM sent."""

import os
import signal
import subprocess
import threading
import time

import pytest

import pheromone

WAITS = 4


def _send_until(progress, target, sent):
    """Sends SIGTERM to this process until `progress[0]` reaches `target`: one, then another
    every 0.5 s while the step it waits for has not come (a SIGTERM that lands between two waits
    runs the handler without interrupting a wait). Counts them in `sent[0]`."""
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
    deadline = time.monotonic() + 60
    while progress[0] < target and time.monotonic() < deadline:
        step = progress[0]
        subprocess.run(["kill", "-TERM", str(os.getpid())], check=True)
        sent[0] += 1
        resend = time.monotonic() + 0.5
        while progress[0] == step and time.monotonic() < resend:
            time.sleep(0.005)


def test_the_programs_sigterm_handler_runs_and_waits_raise_interrupted(start_field):
    f = start_field("s", "--width", "16", "--height", "16", "--model", "none",
                    "--tick-hz", "0.01")
    seen = []

    def handler(signum, _frame):
        seen.append(signum)

    previous = signal.signal(signal.SIGTERM, handler)
    progress, sent = [0], [0]
    try:
        with pheromone.Field.attach(f.name, timeout_s=10) as field:
            sender = threading.Thread(target=_send_until, args=(progress, WAITS + 1, sent))
            sender.start()
            try:
                for i in range(1, WAITS + 1):
                    at_start = len(seen)
                    with pytest.raises(pheromone.Interrupted, match="interrupted by a signal"):
                        field.wait_frame(60)
                    assert len(seen) > at_start, f"wait {i}: the handler did not run"
                    progress[0] = i
                at_start = len(seen)
                with pytest.raises(pheromone.Interrupted):
                    field.deposit(0.5, 0.5, 0.01, cov=(0.04, 0.0, 0.04), timeout_s=60)
                assert len(seen) > at_start, "deposit: the handler did not run"
            finally:
                progress[0] = WAITS + 1
                sender.join()
        assert sent[0] >= WAITS + 1
        assert len(seen) == sent[0], f"the handler saw {len(seen)} of {sent[0]} SIGTERMs"
        assert signal.getsignal(signal.SIGTERM) is handler
    finally:
        signal.signal(signal.SIGTERM, previous)
