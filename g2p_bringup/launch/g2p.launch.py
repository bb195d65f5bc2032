"""Launch the G2P graph on a full ROS 2 install, from the same description as `ros2 run g2p_bringup bringup`.

    ros2 launch g2p_bringup g2p.launch.py rig:=sim run_id:=my-run bags_dir:=bags
    ros2 launch g2p_bringup g2p.launch.py rig:=sim_realtime view:=true      # with the Foxglove viewer
    ros2 launch g2p_bringup g2p.launch.py host:=rig dds_interface:=eth0 rig:=hardware     # on the Pi
    ros2 launch g2p_bringup g2p.launch.py host:=workstation dds_interface:=wlan0 rig:=hardware

Every node of config/graph.yaml starts with its parameters and remappings, all at once as `bringup` starts
them; the learner begins only once the recorder hears the rig (its `recorder_node` parameter). With
`host`, only that host's nodes start, with the two-host DDS profile for `dds_interface` (as `bringup
--host`). Unlike `bringup`, launch does not write the report; run `g2p-report bags/<run_id>` after.
"""

import os
import tempfile
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from g2p.bags.runs import new_run_id
from g2p_bringup.dds import (
    clean_shared_memory,
    interface_address,
    one_host_environment,
    two_host_environment,
)
from g2p_bringup.graph import load_graph


def _nodes(context, *args, **kwargs):
    graph_file = LaunchConfiguration("graph").perform(context)
    run_id = LaunchConfiguration("run_id").perform(context) or new_run_id(
        datetime.now(timezone.utc), np.random.default_rng()
    )
    host = LaunchConfiguration("host").perform(context) or None
    view = LaunchConfiguration("view").perform(context) == "true"
    graph = load_graph(
        Path(graph_file),
        LaunchConfiguration("rig").perform(context) or None,
        {"run_id": run_id, "bags_dir": LaunchConfiguration("bags_dir").perform(context)},
        host=host,
        optional=frozenset({"viewer"}) if view else frozenset(),
    )
    env = None
    if host is not None:
        interface = LaunchConfiguration("dds_interface").perform(context)
        if not interface:
            raise RuntimeError("host:=... needs dds_interface:=<the interface joining the two hosts>")
        profile_dir = Path(tempfile.mkdtemp(prefix="g2p-launch-"))
        env = two_host_environment(dict(os.environ), interface_address(interface), profile_dir)
    return [
        Node(
            package=spec.package,
            executable=spec.executable,
            name=spec.name,
            namespace=spec.namespace,
            parameters=[spec.parameters],
            remappings=list(spec.remappings.items()),
            arguments=list(spec.arguments),
            output="screen",
            env=env,
            on_exit=Shutdown() if spec is graph.main else None,
        )
        for spec in graph.nodes
    ]


def generate_launch_description():
    """The graph of config/graph.yaml as launch actions."""
    share = Path(get_package_share_directory("g2p_bringup"))
    default_graph = str(share / "config" / "graph.yaml")
    clean_shared_memory()  # what killed processes left in /dev/shm
    profile = one_host_environment(dict(os.environ), Path(tempfile.mkdtemp(prefix="g2p-launch-")))
    return LaunchDescription(
        [
            *(SetEnvironmentVariable(name, value) for name, value in profile.items()),
            DeclareLaunchArgument(
                "graph", default_value=default_graph, description="graph description (YAML)"
            ),
            DeclareLaunchArgument(
                "rig", default_value="", description="rig entry of the description (default: first)"
            ),
            DeclareLaunchArgument(
                "run_id", default_value="", description="run id (default: UTC time + suffix)"
            ),
            DeclareLaunchArgument("bags_dir", default_value="bags", description="directory of recorded runs"),
            DeclareLaunchArgument(
                "host",
                default_value="",
                description="rig or workstation: that host's part only (default: all)",
            ),
            DeclareLaunchArgument(
                "dds_interface", default_value="", description="with host: the interface DDS may use"
            ),
            DeclareLaunchArgument(
                "view", default_value="false", description="true: also start the Foxglove viewer"
            ),
            OpaqueFunction(function=_nodes),
        ]
    )
