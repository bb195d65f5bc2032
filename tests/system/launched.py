"""The graph started as `ros2 launch g2p_bringup g2p.launch.py` starts it, without launch (not on PyPI),
and the checks of a stop as launch stops it.

Every node of config/graph.yaml runs as the installed executable with the launch file's parameters,
remappings and Fast DDS profile, all in one process group; `interrupt` sends SIGINT to the whole group at
once, as a terminal's Ctrl-C does under launch (launch itself then waits 5 s before SIGTERM).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from ament_index_python.packages import get_package_prefix, get_package_share_directory

from g2p.bags import BagReader, bag_is_complete
from g2p.bags.ticks import header_stamp_ns
from g2p.plant import NOMINAL_TICK_HZ
from g2p.safety import BASELINE_ACTIVATION
from g2p_bringup.dds import one_host_environment
from g2p_bringup.graph import load_graph
from g2p_ros import contract
from tests.ros.rosproc import executable

# How long `ros2 launch` waits after SIGINT before it sends SIGTERM (s): every node must be done by then.
LAUNCH_SIGTERM_TIMEOUT_S = 5.0
RIG_TOPICS = [
    f"/leg/{t}"
    for t in (contract.JOINT_STATES, contract.TREADMILL, contract.MOTOR_POWER, contract.APPLIED_ACTIVATION)
]
# Output that must never appear: an rclpy task's exception nobody awaited, or any traceback.
# The rig's last log line (g2p_ros.rig_server.RigServer.stop).
STOP_LINE = re.compile(r"stopped after publishing (\d+) ticks, the last at baseline \(stamp (\d+) ns\)")
EXCEPTION = re.compile(r"never retrieved|Traceback \(most recent call last\)")


@dataclass(frozen=True)
class Stopped:
    """How one process ended: its exit code and how long after the signal (s)."""

    code: int
    after_s: float


class LaunchedGraph:
    """The graph's nodes in one process group, their output in `<workdir>/<node>.log`.

    Args:
        workdir: working directory (bags/ goes there), parameter files and logs.
        rig: the graph's rig (config/graph.yaml), e.g. "sim_realtime".
        overrides: parameter overrides per node, e.g. {"learner": {"cycle.n_cycles": 4}}.
        run_id: the run's id, hence its bag `workdir/bags/<run_id>`.
    """

    def __init__(
        self, workdir: Path, rig: str, overrides: dict[str, dict[str, Any]], run_id: str = "launched"
    ) -> None:
        self.workdir = workdir
        self.bag = workdir / "bags" / run_id
        graph_file = Path(get_package_share_directory("g2p_bringup")) / "config" / "graph.yaml"
        graph = load_graph(graph_file, rig, {"run_id": run_id, "bags_dir": str(workdir / "bags")}, overrides)
        env = dict(os.environ)
        env.update(one_host_environment(env, workdir))
        self.names = [spec.name for spec in graph.nodes]
        self._logs: dict[str, IO[bytes]] = {}
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        group = 0  # the first process leads a new group; the others join it
        for spec in graph.nodes:
            params = workdir / f"{spec.name}.yaml"
            params.write_text(spec.parameters_yaml())
            exe = executable(spec.package, spec.executable)
            assert Path(get_package_prefix(spec.package)) in exe.parents
            self._logs[spec.name] = open(workdir / f"{spec.name}.log", "wb")
            self.procs[spec.name] = subprocess.Popen(
                [str(exe), *spec.arguments, *spec.ros_arguments(params)],
                stdout=self._logs[spec.name],
                stderr=subprocess.STDOUT,
                cwd=workdir,
                env=env,
                process_group=group,
            )
            group = group or self.procs[spec.name].pid
        self.group = group

    def log(self, name: str) -> str:
        """What node `name` printed so far."""
        if not self._logs[name].closed:
            self._logs[name].flush()
        return (self.workdir / f"{name}.log").read_text(errors="replace")

    def interrupt(self, timeout_s: float = 30.0) -> dict[str, Stopped]:
        """SIGINT to the whole group at once; wait for every process (kill after `timeout_s`)."""
        os.killpg(self.group, signal.SIGINT)
        sent = time.monotonic()
        stopped: dict[str, Stopped] = {}
        while len(stopped) < len(self.procs):
            for name, proc in self.procs.items():
                if name not in stopped and proc.poll() is not None:
                    stopped[name] = Stopped(proc.returncode, time.monotonic() - sent)
            if time.monotonic() > sent + timeout_s:
                self.close()
            time.sleep(0.01)
        return stopped

    def close(self) -> None:
        """Kill whatever still runs and close the logs."""
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        for log in self._logs.values():
            log.close()


def rig_stop(rig_log: str) -> tuple[int, int]:
    """The rig's own account of its stop: ticks published, and the stamp of the last (ns)."""
    found = STOP_LINE.findall(rig_log)
    assert len(found) == 1, f"the rig did not report its last baseline tick once:\n{rig_log[-2000:]}"
    return int(found[0][0]), int(found[0][1])


def assert_stopped_cleanly(name: str, how: Stopped, log: str) -> None:
    """A process stopped as launch expects: exit 0 within its 5 s, no exception printed."""
    assert how.code == 0 and how.after_s < LAUNCH_SIGTERM_TIMEOUT_S, (name, how, log[-3000:])
    assert not EXCEPTION.search(log), log[-3000:]


def assert_every_tick_recorded(bag_path: Path, rig_log: str) -> int:
    """The bag is complete and holds the rig's ticks without a gap on each of its four topics, from the
    first that all four recorded to the rig's last, which is at baseline; returns the ticks the rig
    published. (A realtime rig ticks before the recorder subscribes, to each topic at its own moment.)"""
    published, last_stamp_ns = rig_stop(rig_log)
    assert bag_is_complete(bag_path)
    stamps = {}
    with BagReader(bag_path) as bag:
        for topic in RIG_TOPICS:
            msgs = list(bag.messages([topic]))
            # In header-stamp order: under sim time, ticks between two /clock messages share a recording
            # time, and the bag's order among equal recording times is not the publishing order.
            order = np.argsort([header_stamp_ns(m.msg.header) for m in msgs], kind="stable")
            msgs = [msgs[k] for k in order]
            stamps[topic] = np.array([header_stamp_ns(m.msg.header) for m in msgs])
    np.testing.assert_array_equal(msgs[-1].msg.activation, BASELINE_ACTIVATION)  # applied_activation
    # Aligned on the last tick: a tick missing on one topic shifts it against the others.
    n = min(len(s) for s in stamps.values())
    common = stamps[RIG_TOPICS[0]][-n:]
    for topic, s in stamps.items():
        np.testing.assert_array_equal(s[-n:], common, err_msg=topic)
    assert common[-1] == last_stamp_ns, "the rig's last tick is not in the bag"
    gaps = np.diff(common) * 1e-9
    assert np.all(gaps < 1.5 / NOMINAL_TICK_HZ), f"ticks missing: a gap of {gaps.max():.3f} s"
    return published
