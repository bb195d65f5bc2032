"""Waiting for servers before calling them: discovery, settling, and several servers at once."""

from __future__ import annotations

import time

from g2p_ros.contract import ServerWatch, wait_all

SETTLE_S = 0.2


class Appears:
    """A server that becomes available `after_s` seconds from now (or never)."""

    def __init__(self, after_s: float | None) -> None:
        self.at = None if after_s is None else time.monotonic() + after_s

    def __call__(self) -> bool:
        return self.at is not None and time.monotonic() >= self.at


def test_a_server_is_callable_only_once_known_for_the_settle_time() -> None:
    available = [True]
    watch = ServerWatch("srv", lambda: available[0], settle_s=SETTLE_S)
    assert not watch.poll()  # just seen
    time.sleep(SETTLE_S)
    assert watch.poll()
    available[0] = False  # gone: a server that comes back is a new one and settles again
    assert not watch.poll()
    available[0] = True
    assert not watch.poll()
    assert watch.wait_until_ready(5.0)


def test_wait_all_waits_for_every_server_and_names_the_missing() -> None:
    watches = [
        ServerWatch("early", Appears(0.0), settle_s=SETTLE_S),
        ServerWatch("late", Appears(0.3), settle_s=SETTLE_S),
        ServerWatch("never", Appears(None), settle_s=0.0),
    ]
    assert wait_all(watches, timeout_s=1.0) == ["never"]
    assert all(w.poll() for w in watches[:2])
    assert wait_all(watches[:2], timeout_s=0.0) == []  # already settled: no further wait
