"""`clean_shared_memory` (bringup, the launch file and every test session call it): the Fast DDS files a
killed node left in /dev/shm are removed, those of a running node are kept."""

from __future__ import annotations

import signal
from pathlib import Path

from g2p_bringup.dds import clean_shared_memory
from tests.ros.rosproc import NodeProcess, wait_until

SHM = Path("/dev/shm")


def fastdds_files() -> set[str]:
    return {p.name for p in SHM.iterdir() if p.name.startswith(("fastdds_", "fastrtps_"))}


def files_of(pid: int) -> set[str]:
    """The shared-memory segments process `pid` owns, with their lock files, but the port files (shared by
    every participant that listens on the port). A segment's owner holds its `<segment>_el` file open;
    its peers map the segment too, so mapping does not tell ownership. Read from /proc rather than by
    comparing /dev/shm before and after a start, which would count the files of any other ROS 2 process
    started meanwhile (`make test` runs the Kilted and Jazzy suites at once)."""
    opened = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            opened.add(fd.readlink())
        except FileNotFoundError:  # closed since the directory was listed: not one of its segments' locks
            continue
    locks = {
        path.name
        for path in opened
        if path.parent == SHM and path.name.startswith(("fastdds_", "fastrtps_")) and "_port" not in path.name
    }
    return locks | {lock.removesuffix("_el") for lock in locks}


def start_sim_and_its_files(log_dir: Path) -> tuple[NodeProcess, set[str]]:
    """A simulator node, and the shared-memory segments it holds."""
    sim = NodeProcess("g2p_sim", "sim", ["--ros-args", "-r", "__ns:=/shm_test"], log_dir)
    wait_until(lambda: "serving the rig contract" in sim.log(), 60.0, "the simulator")
    return sim, files_of(sim.popen.pid)


def test_the_files_of_a_killed_node_are_removed_and_a_running_nodes_kept(tmp_path: Path) -> None:
    killed, killed_files = start_sim_and_its_files(tmp_path)
    running, running_files = start_sim_and_its_files(tmp_path)
    assert killed_files and running_files
    killed.stop(signal.SIGKILL)
    assert killed_files <= fastdds_files()  # nothing removes them: Fast DDS's own watchdog does not

    report = clean_shared_memory()

    assert "zombie" in report, report
    left = fastdds_files()
    assert not killed_files & left
    assert running_files <= left
    assert running.stop() == 0
