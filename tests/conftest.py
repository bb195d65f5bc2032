"""Session-wide test environment: DDS on loopback and a ROS domain of this session's own."""

from __future__ import annotations

import fcntl
import os
import signal
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

# Fast DDS must never send discovery traffic beyond loopback, in this process and its children.
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
# MuJoCo's offscreen renderer (the environments' render()) without a display: EGL, before mujoco loads.
os.environ.setdefault("MUJOCO_GL", "egl")


def _claim_domain_id() -> int:
    """Lock a ROS domain id (1..101) for this test session, so parallel sessions never see each other.

    The lock is an flock on a file in /tmp, held until the process exits.
    """
    for domain in range(1, 102):
        lock = open(Path("/tmp") / f"g2p-ros-domain-{domain}.lock", "w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _held_locks.append(lock)
        return domain
    raise RuntimeError("no free ROS domain id in 1..101 (too many test sessions at once?)")


_held_locks: list[object] = []
os.environ["ROS_DOMAIN_ID"] = str(_claim_domain_id())
# Every process this session starts inherits this mark: a session that dies (killed, a timeout) releases
# its domain's lock while the nodes it started may live on, and those would answer the next session that
# claims the domain (commands reach two rigs, two clocks interleave on /clock).
SESSION_MARK = f"G2P_TEST_SESSION_DOMAIN={os.environ['ROS_DOMAIN_ID']}"
os.environ["G2P_TEST_SESSION_DOMAIN"] = os.environ["ROS_DOMAIN_ID"]


def kill_marked_processes() -> list[str]:
    """SIGKILL every other process that carries this domain's SESSION_MARK; returns their command lines.

    At the session's start they are orphans of a dead session; at its end, nodes the session left.
    """
    killed = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if SESSION_MARK.encode() not in (entry / "environ").read_bytes().split(b"\0"):
                continue
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            os.kill(int(entry.name), signal.SIGKILL)
        except OSError:  # gone meanwhile, or not ours to read
            continue
        killed.append(f"{entry.name}: {command.strip()}")
    return killed


def pytest_sessionstart(session: pytest.Session) -> None:
    """End the orphans of a dead session that used this domain, then remove the Fast DDS shared-memory
    files that killed processes left (the tests kill nodes on purpose), as `bringup` does before each
    graph."""
    from g2p_bringup.dds import clean_shared_memory

    for orphan in kill_marked_processes():
        print(
            f"conftest: killed an orphan of an earlier session in ROS domain {os.environ['ROS_DOMAIN_ID']}: "
            f"{orphan}",
            file=sys.stderr,
        )
    clean_shared_memory()


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Kill what the session left running (the fixture below stops what each test started; a node's own
    children, or a test killed by its timeout, may remain), so that nothing outlives the domain's lock."""
    for leftover in kill_marked_processes():
        print(f"conftest: killed a process the session left running: {leftover}", file=sys.stderr)


# The end of each node's log a failure report shows (characters).
LOG_TAIL_CHARS = 6000


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
    """A failed test's report ends with the log of every node process it started: a node's side of a
    timeout (a fault, a trip, a rejected goal) is otherwise lost with the test's temporary directory."""
    report = yield
    rosproc = sys.modules.get("tests.ros.rosproc")
    if report.failed and rosproc is not None:
        for proc in rosproc.started():
            report.sections.append((f"log of {proc.log_path.name}", proc.log()[-LOG_TAIL_CHARS:]))
    return report


@pytest.fixture(autouse=True)
def _stop_leftover_processes() -> Iterator[None]:
    """After each test, stop the node processes it left running (only tests that started any)."""
    yield
    rosproc = sys.modules.get("tests.ros.rosproc")
    if rosproc is not None:
        rosproc.stop_leftovers()


@pytest.fixture
def two_hosts() -> Iterator[Any]:
    """A rig and a workstation network namespace joined by a clean link (g2p_twohost), torn down after
    the test; skipped, with the reason, where namespaces cannot be made (not root)."""
    from g2p_twohost.hosts import TwoHosts, available  # only the tests that ask for two hosts

    reason = available()
    if reason is not None:
        pytest.skip(reason)
    with TwoHosts() as hosts:
        yield hosts
