"""rclpy start-up for executables that stop cleanly on SIGINT and SIGTERM."""

from __future__ import annotations

import signal
import threading

import rclpy
from rclpy.executors import Executor
from rclpy.signals import SignalHandlerOptions


def init_with_stop_event(args: list[str] | None) -> threading.Event:
    """`rclpy.init` without rclpy's signal handlers; returns an event that SIGINT and SIGTERM set.

    rclpy's own handlers shut the context down at once, under running callbacks. Here a signal only sets
    the event: the executable cancels its work (motors to baseline, bag finalized) while the executor still
    spins, then shuts down itself.

    Args:
        args: command-line arguments for rclpy (None: sys.argv).
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, frame: stop.set())
    return stop


def spin_until_stopped(executor: Executor, stop: threading.Event) -> None:
    """Spin `executor` until `stop` is set (SIGINT or SIGTERM) or the default context shuts down.

    The caller then makes its outputs safe and destroys its node while the context is still valid.
    """
    while not stop.is_set() and rclpy.ok():
        executor.spin_once(timeout_sec=0.1)
