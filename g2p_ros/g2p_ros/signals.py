"""rclpy start-up for executables that stop cleanly on SIGINT and SIGTERM."""

from __future__ import annotations

import os
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

    The handler does not set the event: it runs in the main thread between two bytecodes, possibly inside
    `Event.wait`, which holds the event's lock, and `Event.set` would wait for that lock forever (the
    deadlock python/cpython#126434 reports for multiprocessing.Event). The signal's number goes through the
    wakeup fd to a thread that sets the event.

    Args:
        args: command-line arguments for rclpy (None: sys.argv).
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)  # set_wakeup_fd requires it
    signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)

    def set_on_signal() -> None:
        while os.read(read_fd, 1)[0] not in (signal.SIGINT, signal.SIGTERM):
            pass
        stop.set()

    threading.Thread(target=set_on_signal, name="stop-on-signal", daemon=True).start()
    # A handler must exist for the wakeup byte to be written; the thread does the rest.
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: None)
    return stop


def spin_until_stopped(executor: Executor, stop: threading.Event) -> None:
    """Spin `executor` until `stop` is set (SIGINT or SIGTERM) or the default context shuts down.

    The caller then makes its outputs safe and destroys its node while the context is still valid.
    """
    while not stop.is_set() and rclpy.ok():
        executor.spin_once(timeout_sec=0.1)
