"""The installed graph description (g2p_bringup/config/graph.yaml): every rig resolves, treadmill or air."""

from __future__ import annotations

from pathlib import Path

import pytest
from ament_index_python.packages import get_package_share_directory

from g2p.hardware_fake.buses import FakeBusesConfig
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, TREADMILL_CARRIAGE_HEIGHT_M, MujocoLegConfig
from g2p_bringup.graph import GraphError, load_graph

GRAPH = Path(get_package_share_directory("g2p_bringup")) / "config" / "graph.yaml"
SUBSTITUTIONS = {"run_id": "test-run", "bags_dir": "bags"}


def carriage_height_m(rig: str) -> float:
    """The carriage height the rig of that name starts with (its parameters, else the config default)."""
    spec = load_graph(GRAPH, rig, SUBSTITUTIONS).nodes[0]
    if spec.parameters.get("fake_devices"):
        return float(spec.parameters.get("fake.carriage_height_m", FakeBusesConfig().carriage_height_m))
    return float(spec.parameters.get("leg.carriage_height_m", MujocoLegConfig().carriage_height_m))


@pytest.mark.parametrize("rig", ["sim", "sim_realtime", "hardware_fake"])
def test_learning_rigs_stand_the_foot_on_the_treadmill(rig: str) -> None:
    assert carriage_height_m(rig) == TREADMILL_CARRIAGE_HEIGHT_M


def test_air_rig_hangs_the_foot_in_the_air() -> None:
    assert carriage_height_m("sim_air") == AIR_CARRIAGE_HEIGHT_M


def test_every_rig_ends_with_the_learner_as_main_node() -> None:
    for rig in ("sim", "sim_realtime", "sim_air", "hardware", "hardware_fake"):
        graph = load_graph(GRAPH, rig, SUBSTITUTIONS)
        assert graph.namespace == "/leg"
        assert [n.name for n in graph.nodes[1:]] == ["recorder", "learner"]
        assert graph.main is not None and graph.main.name == "learner"


def test_two_hosts_split_the_graph_rig_and_recorder_beside_it_learner_on_the_workstation() -> None:
    rig_side = load_graph(GRAPH, "hardware", SUBSTITUTIONS, host="rig")
    assert [n.name for n in rig_side.nodes] == ["driver", "recorder"]
    assert rig_side.main is None  # the rig host serves until it is stopped
    workstation = load_graph(GRAPH, "hardware", SUBSTITUTIONS, host="workstation")
    assert [n.name for n in workstation.nodes] == ["learner"]
    assert workstation.main is not None and workstation.main.name == "learner"
    with pytest.raises(GraphError, match="unknown host 'laptop'"):
        load_graph(GRAPH, "sim", SUBSTITUTIONS, host="laptop")


def test_the_viewer_starts_only_when_asked_for_on_the_workstation_listening_on_loopback() -> None:
    assert "viewer" not in [n.name for n in load_graph(GRAPH, "sim", SUBSTITUTIONS).nodes]
    graph = load_graph(GRAPH, "sim", SUBSTITUTIONS, optional=frozenset({"viewer"}))
    assert [n.name for n in graph.nodes[1:]] == ["recorder", "learner", "viewer"]
    viewer = graph.nodes[-1]
    assert (viewer.package, viewer.executable, viewer.host) == ("g2p_viewer", "view", "workstation")
    assert viewer.parameters["host"] == "127.0.0.1"
    assert viewer.parameters["use_sim_time"] is True  # on the simulated rig's /clock like the others
    workstation = load_graph(
        GRAPH, "hardware", SUBSTITUTIONS, host="workstation", optional=frozenset({"viewer"})
    )
    assert [n.name for n in workstation.nodes] == ["learner", "viewer"]
    with pytest.raises(GraphError, match=r"no optional nodes \['plotter'\]"):
        load_graph(GRAPH, "sim", SUBSTITUTIONS, optional=frozenset({"plotter"}))
    with pytest.raises(GraphError, match="bringup --view"):
        load_graph(GRAPH, "sim", SUBSTITUTIONS, overrides={"viewer": {"port": 9000}})
