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


def start_sim_and_its_files(log_dir: Path) -> tuple[NodeProcess, set[str]]:
    """A simulator node, and the shared-memory segments that appeared with it (a participant's own; port
    files are shared by the participants that listen on the port)."""
    before = fastdds_files()
    sim = NodeProcess("g2p_sim", "sim", ["--ros-args", "-r", "__ns:=/shm_test"], log_dir)
    wait_until(lambda: "serving the rig contract" in sim.log(), 60.0, "the simulator")
    return sim, {f for f in fastdds_files() - before if "_port" not in f}


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
