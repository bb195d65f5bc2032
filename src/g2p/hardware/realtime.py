"""What keeps the hardware loop safe and on time beside its ticks: a stall watchdog and SCHED_FIFO."""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable

_log = logging.getLogger(__name__)


class StallWatchdog:
    """A thread that calls `on_stall` once when the loop it watches has been idle for `limit_s`.

    It polls every `poll_s`; after a call it waits for activity (`idle_s()` below the limit) before it can
    call again. `on_stall` decides under its own lock whether the stall still holds.

    Args:
        limit_s: idle time that counts as a stall (s, > 0).
        idle_s: time since the loop's last activity (s).
        armed: whether a stall matters now (the loop is expected to run).
        on_stall: called from the watchdog thread on a stall; returns whether it acted.
        poll_s: polling period (s).
    """

    def __init__(
        self,
        limit_s: float,
        idle_s: Callable[[], float],
        armed: Callable[[], bool],
        on_stall: Callable[[], bool],
        poll_s: float = 0.01,
    ) -> None:
        self._limit_s = limit_s
        self._idle_s = idle_s
        self._armed = armed
        self._on_stall = on_stall
        self._poll_s = poll_s
        self._tripped = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hardware_leg_watchdog", daemon=True)
        self._thread.start()

    def rearm(self) -> None:
        """The loop ran: a later stall trips again."""
        self._tripped = False

    def stop(self) -> None:
        """End the thread (waits up to 1 s for it, unless called from it)."""
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(1.0)

    def _run(self) -> None:
        while not self._stop.wait(self._poll_s):
            if self._tripped or not self._armed() or self._idle_s() < self._limit_s:
                continue
            self._tripped = True  # before acting: a tick during `on_stall` re-arms after it
            if not self._on_stall():
                self._tripped = False


def request_sched_fifo(priority: int) -> bool:
    """Run the calling thread under SCHED_FIFO at `priority` (1-99); False, with a warning, if refused."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, AttributeError, OSError) as err:
        _log.warning("SCHED_FIFO %d not permitted (%s): running with normal scheduling", priority, err)
        return False
    return True
