"""A Python program keeps its own SIGTERM handling while it waits on a field (issue 47).

The test installs its own SIGTERM handler, blocks in `Field.wait_frame` on a live field that
ticks once per 100 s (so only a signal ends a wait early), and a thread (that blocks SIGTERM
itself) has another process send SIGTERMs to this one: each wait raises
`pheromone.Interrupted` after the handler ran, so does a confirmed deposit waiting for its
receipt, and the handler sees every SIGTERM sent.

One long-lived sender process sends them all, not a `kill` command per signal: a child that
exits while its parent thread still blocks every signal (the few microseconds around `vfork`)
queues a SIGCHLD that the kernel may wake this process's waiting thread for, and a socket wait
with a timeout then fails with EINTR although no handler runs (CI run of stop 58)."""

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

import pheromone

WAITS = 4


#: Sends SIGTERM to the pid on each line it reads, and answers each with one line.
SENDER = (
    "import os, signal, sys\n"
    "for line in sys.stdin:\n"
    "    os.kill(int(line), signal.SIGTERM)\n"
    "    print('sent', flush=True)\n"
)


def _send_until(progress, target, sent, sender):
    """Has `sender` (a `SENDER` process) send SIGTERM to this process until `progress[0]`
    reaches `target`: one, then another every 0.5 s while the step it waits for has not come (a
    SIGTERM that lands between two waits runs the handler without interrupting a wait). Counts
    them in `sent[0]`."""
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
    deadline = time.monotonic() + 60
    while progress[0] < target and time.monotonic() < deadline:
        step = progress[0]
        sender.stdin.write(f"{os.getpid()}\n")
        sender.stdin.flush()
        assert sender.stdout.readline() == "sent\n", "the sender process died"
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

    sender = subprocess.Popen([sys.executable, "-c", SENDER], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    previous = signal.signal(signal.SIGTERM, handler)
    progress, sent = [0], [0]
    try:
        with pheromone.Field.attach(f.name, timeout_s=10) as field:
            sending = threading.Thread(target=_send_until,
                                       args=(progress, WAITS + 1, sent, sender))
            sending.start()
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
                sending.join()
        assert sent[0] >= WAITS + 1
        assert len(seen) == sent[0], f"the handler saw {len(seen)} of {sent[0]} SIGTERMs"
        assert signal.getsignal(signal.SIGTERM) is handler
    finally:
        signal.signal(signal.SIGTERM, previous)
        sender.stdin.close()
        sender.wait(timeout=10)
