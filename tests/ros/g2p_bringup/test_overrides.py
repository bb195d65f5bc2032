"""bringup refuses a `--set` naming no parameter of its node before it starts anything, and accepts the
graph's own parameters."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
import yaml
from ament_index_python.packages import get_package_share_directory

from g2p_bringup.bringup import node_parameters
from g2p_bringup.graph import load_graph
from tests.ros.rosproc import executable

GRAPH = Path(get_package_share_directory("g2p_bringup")) / "config" / "graph.yaml"


def bringup(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(executable("g2p_bringup", "bringup")), "--bags-dir", str(cwd / "bags"), *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
    )


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        (
            "learner.learner.sed=3",
            "bringup: override learner.learner.sed: node 'learner' (g2p_learner learn) has no parameter "
            "'learner.sed'; nearest: learner.learner.seed",
        ),
        (
            "rig.leg.tick_hzz=78.0",
            "bringup: override rig.leg.tick_hzz: node 'rig' (g2p_sim sim) has no parameter 'leg.tick_hzz'; "
            "nearest: rig.leg.tick_hz",
        ),
    ],
)
def test_a_misspelt_set_exits_2_naming_it_before_anything_starts(
    override: str, expected: str, tmp_path: Path
) -> None:
    done = bringup(tmp_path, "--set", "learner.cycle.n_cycles=4", "--set", override)
    assert done.returncode == 2, done.stdout + done.stderr
    assert len(done.stderr.splitlines()) == 1 and expected in done.stderr
    assert done.stdout == ""  # no "bringup: run ..." line: nothing was started
    assert list(tmp_path.iterdir()) == []  # no log directory, no bag


def test_on_the_workstation_a_misspelt_set_of_the_rig_is_refused_too(tmp_path: Path) -> None:
    """The rig runs on the other host; its override is still a mistake worth saying."""
    done = bringup(tmp_path, "--host", "workstation", "--dds-interface", "lo", "--set", "rig.time_mod=fast")
    assert done.returncode == 2, done.stdout + done.stderr
    assert "nearest: rig.time_mode" in done.stderr
    assert list(tmp_path.iterdir()) == []


RIGS = list(yaml.safe_load(GRAPH.read_text())["rigs"])


@pytest.mark.parametrize("rig", RIGS)
def test_every_parameter_of_the_graph_is_a_parameter_of_its_node(rig: str) -> None:
    """The names bringup checks `--set` against hold every parameter graph.yaml gives (no false refusal)."""
    graph = load_graph(GRAPH, rig, {"run_id": "r", "bags_dir": "b"}, optional=frozenset({"viewer"}))
    for spec in graph.nodes:
        known = node_parameters(spec)
        assert known is not None, spec.name
        assert set(spec.parameters) <= known, (spec.name, sorted(set(spec.parameters) - known))
