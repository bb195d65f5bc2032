"""Helpers for tests that run the installed executables as a user does, and talk to them over ROS 2.

`NodeProcess` starts `<install>/<pkg>/lib/<pkg>/<exe>` (the file `ros2 run <pkg> <exe>` executes) and
stops it with SIGINT; `RosPeer` is an rclpy node in its own Context, spun in a background thread, for
the test's side of the conversation.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import rclpy
from ament_index_python.packages import get_package_prefix
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future

from g2p_ros.contract import ServerWatch, wait_all
from g2p_ros.spinner import BackgroundSpinner, wait_for_future

ROOT = Path(__file__).resolve().parents[2]


def executable(package: str, name: str) -> Path:
    """The installed executable `ros2 run <package> <name>` would run, in the sourced environment."""
    path = Path(get_package_prefix(package)) / "lib" / package / name
    assert path.is_file(), f"{path} is not installed (run scripts/bootstrap)"
    return path


def stop_process(popen: subprocess.Popen[Any], sig: int, timeout_s: float) -> int:
    """Signal a running process and wait for it; kill it after `timeout_s` (s). Returns the exit code."""
    if popen.poll() is None:
        popen.send_signal(sig)
        try:
            popen.wait(timeout_s)
        except subprocess.TimeoutExpired:
            popen.kill()
            popen.wait()
    return popen.returncode


class NodeProcess:
    """An installed executable running as a child process, its output captured to a log file.

    Args:
        package: ROS package.
        name: executable name.
        args: command-line arguments (e.g. ["--ros-args", "-p", "time_mode:=fast"]).
        log_dir: where to write `<name>.log`.
    """

    def __init__(self, package: str, name: str, args: list[str], log_dir: Path) -> None:
        self.log_path = log_dir / f"{package}-{name}-{time.monotonic_ns()}.log"
        self._log = open(self.log_path, "wb")
        self.popen = subprocess.Popen(
            [str(executable(package, name)), *args],
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=os.environ.copy(),
        )
        _started.append(self)

    def log(self) -> str:
        """What the process printed so far."""
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def stop(self, sig: int = signal.SIGINT, timeout_s: float = 20.0) -> int:
        """Signal the process and wait for it; kill it after `timeout_s`. Returns the exit code."""
        code = stop_process(self.popen, sig, timeout_s)
        self._log.close()
        return code


_started: list[NodeProcess] = []


def started() -> list[NodeProcess]:
    """The node processes started since the last `stop_leftovers` (the running test's)."""
    return list(_started)


def stop_leftovers() -> None:
    """Stop every NodeProcess a test left running (a failed assertion skipped its stop).

    Run after each test (tests/conftest.py), so that a leftover rig cannot answer the next test's peers.
    """
    for proc in _started:
        proc.stop()
    _started.clear()


class RosPeer:
    """A test-side rclpy node in its own Context, spun in a background thread once `start` is called.

    Subclasses create their entities, then call `start`: rclpy's ActionClient registers itself with the
    node before it is fully built, and an executor spinning meanwhile fails on it (ros2/rclpy#1589).

    Args:
        name: node name.
        namespace: node namespace (the rig contract's default is /leg).
    """

    def __init__(self, name: str = "test_peer", namespace: str = "/leg") -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node(name, namespace=namespace, context=self.context)
        # Single-threaded: rclpy's MultiThreadedExecutor can fall behind a 78 Hz topic on a loaded machine
        # (ros2/rclpy#1452); the test's own thread waits on futures, so one spinning thread is enough.
        executor = SingleThreadedExecutor(context=self.context)
        executor.add_node(self.node)
        self._spinner = BackgroundSpinner(executor)

    def start(self) -> None:
        """Start spinning the node (after its entities are created)."""
        self._spinner.start()

    def wait(self, future: Future, timeout_s: float) -> Any:
        """The future's result; fails the test after `timeout_s` (s)."""
        assert wait_for_future(future, timeout_s), f"no result within {timeout_s} s"
        return future.result()

    def wait_for_servers(self, ready: dict[str, Callable[[], bool]], timeout_s: float) -> None:
        """Wait until every server is available and settled (`contract.ServerWatch`); fail the test naming
        those that are not after `timeout_s` (s).

        A call made as soon as `wait_for_service` returns can lose its reply: rmw_fastrtps drops a reply whose
        reader the server has not matched within 100 ms (ros2/rmw_fastrtps#390), and on a busy machine
        the server discovers this peer later than the peer discovers it.

        Args:
            ready: per server name, whether it is available now (e.g. `Client.service_is_ready`).
        """
        missing = wait_all([ServerWatch(name, is_ready) for name, is_ready in ready.items()], timeout_s)
        assert not missing, f"never appeared: {missing}"

    def close(self) -> None:
        """Shut the node and its context down: stop spinning first, then destroy what the node holds."""
        self._spinner.stop()
        self.destroy_entities()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)

    def destroy_entities(self) -> None:
        """Destroy entities the node does not destroy itself (action clients); called by `close`."""


def wait_until(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Poll `condition` every 10 ms until it holds; fail the test with `what` after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"timed out after {timeout_s} s waiting for {what}"
        time.sleep(0.01)
