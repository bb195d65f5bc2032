"""The clock a hardware loop runs on: the monotonic clock on the rig, a simulated one in tests.

Time comes in as an argument (a `Clock`), so the same absolute-deadline loop runs in real time on the Pi
and as fast as the CPU allows against physics-backed fake buses.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    """Monotonic time and absolute-deadline sleeps."""

    def now(self) -> float:
        """Current time (s, monotonic, arbitrary origin)."""
        ...

    def sleep_until(self, deadline_s: float) -> None:
        """Return at `deadline_s` (s, this clock) or as soon after as possible; at once if it passed."""
        ...


class MonotonicClock:
    """`time.monotonic`; each sleep recomputes the time left to its absolute deadline: no drift."""

    def now(self) -> float:
        """Current monotonic time (s)."""
        return time.monotonic()

    def sleep_until(self, deadline_s: float) -> None:
        """Sleep until the monotonic clock reads `deadline_s` (s)."""
        remaining = deadline_s - time.monotonic()
        while remaining > 0.0:
            time.sleep(remaining)
            remaining = deadline_s - time.monotonic()


class SimulatedClock:
    """A clock that only moves when someone sleeps: `sleep_until` jumps to the deadline at once.

    Thread-safe. With it, a plant whose loop sleeps until each deadline runs as fast as the CPU allows and
    deterministically, while measuring the same intervals it would measure on the rig.

    Args:
        start_s: the initial reading (s).
    """

    def __init__(self, start_s: float = 0.0) -> None:
        self._t = start_s
        self._lock = threading.Lock()

    def now(self) -> float:
        """Current simulated time (s)."""
        with self._lock:
            return self._t

    def sleep_until(self, deadline_s: float) -> None:
        """Advance to `deadline_s` (s) if it lies ahead; never goes back."""
        with self._lock:
            self._t = max(self._t, deadline_s)

    def advance(self, seconds: float) -> None:
        """Let `seconds` (s, >= 0) pass, as a bus transaction or a computation would."""
        if seconds < 0.0:
            raise ValueError(f"seconds: must be >= 0, got {seconds}")
        with self._lock:
            self._t += seconds
