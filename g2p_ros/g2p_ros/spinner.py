"""Spin an executor in a background thread, and stop it before anything it uses is destroyed."""

from __future__ import annotations

import threading

from rclpy.executors import Executor

STOP_TIMEOUT_S = 5.0


class BackgroundSpinner:
    """Spins `executor` in a daemon thread until `stop`.

    `Executor.shutdown` destroys the executor's guard condition while a thread blocked in `spin` may still
    be waiting on it: that thread then fails ("cannot use Destroyable because destruction was requested")
    or, at interpreter exit, aborts the process ("terminate called without an active exception"). Here
    the thread polls with a short timeout and is joined before the executor is shut down.

    Args:
        executor: the executor, nodes already added.
        period_s: longest wait per poll (s); also the longest delay of `stop`.
    """

    def __init__(self, executor: Executor, period_s: float = 0.1) -> None:
        self._executor = executor
        self._period_s = period_s
        self._running = threading.Event()
        self._thread = threading.Thread(target=self._spin, name="spinner", daemon=True)

    def start(self) -> BackgroundSpinner:
        """Start spinning; returns self."""
        self._running.set()
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop spinning, join the thread, then shut the executor down (waiting for running callbacks)."""
        self._running.clear()
        if self._thread.is_alive():
            self._thread.join(STOP_TIMEOUT_S)
        self._executor.shutdown()

    def _spin(self) -> None:
        while self._running.is_set() and self._executor.context.ok():
            self._executor.spin_once(timeout_sec=self._period_s)
