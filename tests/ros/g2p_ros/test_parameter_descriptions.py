"""Every parameter every node declares is described (`ros2 param describe`), with its unit, and is one
bringup knows without starting the node.

The nodes run as the installed executables; the test asks each one over its parameter services, as
`ros2 param describe` does.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, ListParameters

from g2p_bringup.bringup import node_parameters
from g2p_bringup.graph import NodeSpec
from g2p_ros.params import RCLPY_PARAMETERS
from tests.ros.rosproc import NodeProcess, RosPeer

# A unit, or a word saying there is none, in parentheses: "(s)", "(mm of belt travel)", "(dimensionless)".
UNIT = re.compile(
    r"\([^()]*\b(s|ms|Hz|mm|m|rad|rad/s|deg|N|N m|N/m|A|W|J|V|ohm|kg|mm/s|m/s|dimensionless|ticks?|samples?|"
    r"messages?|feature units|normalized units|mm of belt travel|0\.\.1)\b[^()]*\)"
)
FLOAT_TYPES = {ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_DOUBLE_ARRAY}


def describe(name: str) -> dict[str, tuple[int, str]]:
    """Every parameter of node `name` (in /leg): its type and description."""
    peer = RosPeer("parameter_peer")
    try:
        listing = peer.node.create_client(ListParameters, f"{name}/list_parameters")
        describing = peer.node.create_client(DescribeParameters, f"{name}/describe_parameters")
        peer.start()
        peer.wait_for_servers(
            {"list_parameters": listing.service_is_ready, "describe_parameters": describing.service_is_ready},
            60.0,
        )
        names = list(peer.wait(listing.call_async(ListParameters.Request()), 30.0).result.names)
        response = peer.wait(describing.call_async(DescribeParameters.Request(names=names)), 30.0)
        return {d.name: (d.type, d.description) for d in response.descriptors}
    finally:
        peer.close()


NODES = {
    "sim": ("g2p_sim", "sim", ["-p", "time_mode:=fast"]),
    "learner": ("g2p_learner", "learn", []),
    "driver": ("g2p_driver", "driver", ["-p", "fake_devices:=true"]),
    "recorder": ("g2p_recorder", "record", []),
    "viewer": ("g2p_viewer", "view", ["-p", "port:=0"]),
}


@pytest.mark.parametrize("node", sorted(NODES))
def test_every_parameter_has_a_description_and_every_float_its_unit(node: str, tmp_path: Path) -> None:
    package, executable, params = NODES[node]
    args = ["--serve"] if node == "learner" else []
    params = [*params, "-p", f"bags_dir:={tmp_path}"] if node == "recorder" else params
    if node == "driver":
        params = [*params, "-p", f"fake.state_dir:={tmp_path}"]
    proc = NodeProcess(package, executable, [*args, "--ros-args", "-r", "__ns:=/leg", *params], tmp_path)
    try:
        described = describe(node)
    finally:
        assert proc.stop() == 0, proc.log()
    ours = {
        k: v for k, v in described.items() if k not in RCLPY_PARAMETERS and not k.startswith("qos_overrides.")
    }
    assert len(ours) >= 5, described
    undescribed = sorted(k for k, (_, text) in ours.items() if not text.strip())
    assert not undescribed, f"{node}: no description for {undescribed}"
    unitless = sorted(k for k, (kind, text) in ours.items() if kind in FLOAT_TYPES and not UNIT.search(text))
    assert not unitless, f"{node}: no unit in the description of {unitless}"
    # What bringup checks a `--set` against, listed from the configurations without a node: the same names.
    listed = node_parameters(NodeSpec(node, package, executable, "/leg"))
    assert listed is not None
    assert set(ours) == listed - set(RCLPY_PARAMETERS)
