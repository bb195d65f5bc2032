"""Executors stopped before what they use is destroyed; futures awaited from other threads.

A multi-threaded executor whose shutdown waits for its callbacks, and a background spinner.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from rclpy import executors
from rclpy.executors import Executor
from rclpy.task import Future, Task

STOP_TIMEOUT_S = 5.0
FUTURE_POLL_S = 0.002
# How long the spinning thread sleeps when the callback it is handed waits in the pool's queue already (s).
QUEUED_POLL_S = 0.001
# How long a shutdown waits for the callbacks the executor's threads still run (s), within the 5 s that
# `ros2 launch` grants a stopping process before it escalates.
CALLBACKS_TIMEOUT_S = 3.0


class MultiThreadedExecutor(executors.MultiThreadedExecutor):
    """rclpy's MultiThreadedExecutor, handing each callback to its threads once, shutting down last.

    rclpy's (9.1.2 on Kilted, 7.1.6 on Jazzy; ros2/rclpy#1452, fixed upstream by ros2/rclpy#1547) yields a
    callback again as long as no pool thread has started it, and queues it again each time: while it
    waits in the pool's queue, the spinning thread loops without waiting, holding the GIL the pool's
    threads need to start it, and its list of futures grows by one per loop. The fast simulator in
    lockstep then ran at 100 % CPU while idle, and a command's tick came after up to 6.9 s (1,000 steps:
    median 46 ms, 209 steps over 200 ms; a client's 5 s wait for its tick failed). Here a callback already
    queued is not queued again: the spinning thread sleeps `QUEUED_POLL_S` instead, letting a pool
    thread take it.

    rclpy's (9.1.2 on Kilted, 7.1.6 on Jazzy) destroys its guard condition at once: `Executor.shutdown`
    skips its wait for outstanding work (it tests the flag it has just set), Kilted's override joins the
    thread pool only afterwards and Jazzy's never does. A callback still running in a pool thread (a
    message that arrived as spinning stopped, an action's execute callback returning) then triggers the
    destroyed guard condition, and rclpy prints "The following exception was never retrieved: cannot use
    Destroyable because destruction was requested" (the learner, in 1 of 10 stops of the fast graph).
    Call `shutdown` once nothing spins the executor any more, before destroying its nodes.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._queued: set[Task] = set()  # handed to the pool, not yet started by a pool thread
        self._queued_lock = threading.Lock()

    def _spin_once_impl(
        self,
        timeout_sec: float | executors.TimeoutObject | None = None,
        wait_condition: Callable[[], bool] = lambda: False,
    ) -> None:
        """rclpy's, except that a callback waiting in the pool's queue is not queued again."""
        try:
            handler, _, _ = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (
            executors.ExternalShutdownException,
            executors.ShutdownException,
            executors.TimeoutException,
            executors.ConditionReachedException,
        ):
            return
        with self._queued_lock:
            queued = handler in self._queued
            self._queued.add(handler)
        if queued:
            time.sleep(QUEUED_POLL_S)
            return
        self._executor.submit(self._start, handler)
        self._futures.append(handler)
        for future in self._futures[:]:
            if future.done():
                self._futures.remove(future)
                future.result()  # raise any exceptions, as rclpy's does

    def _start(self, handler: Task) -> None:
        """Run a callback in a pool thread: from now on it is executing, not queued."""
        with self._queued_lock:
            self._queued.discard(handler)
        handler()

    def shutdown(self, timeout_sec: float | None = CALLBACKS_TIMEOUT_S, **kwargs: Any) -> bool:
        """Wait up to `timeout_sec` for the running callbacks (rclpy's handler futures), then shut down."""
        deadline = time.monotonic() + (timeout_sec if timeout_sec is not None else float("inf"))
        while any(not f.done() for f in list(self._futures)) and time.monotonic() < deadline:
            time.sleep(FUTURE_POLL_S)
        return bool(super().shutdown(timeout_sec, **kwargs))


def wait_for_future(future: Future, timeout_s: float, stop: threading.Event | None = None) -> bool:
    """Block until `future` is done, from a thread the executor does not use; False on timeout or `stop`.

    Polls `future.done()` instead of waiting on a done callback: rclpy runs done callbacks as executor
    tasks, and on a busy 2-core machine those were measured arriving up to a second after the response
    (docs/RESULTS.md, "Through the ROS graph").
    """
    deadline = time.monotonic() + timeout_s
    while not future.done():
        if (stop is not None and stop.is_set()) or time.monotonic() > deadline:
            return False
        time.sleep(FUTURE_POLL_S)
    return True


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
