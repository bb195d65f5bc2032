"""init_with_stop_event: SIGINT and SIGTERM stop an executable whatever its main thread is doing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

# The main thread waits on the stop event in a hot loop, as replay does at a high --rate: it holds the
# event's lock most of the time, where a handler calling Event.set would wait for that lock forever.
CHILD = """
from g2p_ros.signals import init_with_stop_event
stop = init_with_stop_event(None)
print("ready", flush=True)
while not stop.wait(0):
    pass
print("stopped", flush=True)
"""
PROCESSES = 8


def test_a_signal_during_a_wait_on_the_stop_event_sets_it() -> None:
    # An Event.set in the handler itself hung 60 of 100 such processes: this test would pass by chance
    # once in about 1,500 runs.
    children = [
        subprocess.Popen(
            [sys.executable, "-c", CHILD],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=os.environ.copy(),
        )
        for _ in range(PROCESSES)
    ]
    try:
        for child in children:
            assert child.stdout is not None
            assert child.stdout.readline() == "ready\n"
        for i, child in enumerate(children):
            child.send_signal(signal.SIGINT if i % 2 else signal.SIGTERM)
        for child in children:
            out, _ = child.communicate(timeout=60)
            assert (child.returncode, out) == (0, "stopped\n")
    finally:
        for child in children:
            if child.poll() is None:
                child.kill()
                child.wait(timeout=10)
