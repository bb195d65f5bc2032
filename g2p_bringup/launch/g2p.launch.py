"""Launch the G2P graph on a full ROS 2 install, from the same description as `ros2 run g2p_bringup bringup`.

    ros2 launch g2p_bringup g2p.launch.py rig:=sim run_id:=my-run bags_dir:=bags

Every node of config/graph.yaml starts with its parameters and remappings, all at once as `bringup` starts
them; the learner begins only once the recorder hears the rig (its `recorder_node` parameter). Unlike
`bringup`, launch does not write the report; run `g2p-report bags/<run_id>` after.
"""

import os
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from g2p.bags.runs import new_run_id
from g2p_bringup.dds import profile_environment
from g2p_bringup.graph import load_graph


def _nodes(context, *args, **kwargs):
    graph_file = LaunchConfiguration("graph").perform(context)
    run_id = LaunchConfiguration("run_id").perform(context) or new_run_id(
        datetime.now(timezone.utc), np.random.default_rng()
    )
    graph = load_graph(
        Path(graph_file),
        LaunchConfiguration("rig").perform(context) or None,
        {"run_id": run_id, "bags_dir": LaunchConfiguration("bags_dir").perform(context)},
    )
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
            on_exit=Shutdown() if spec is graph.main else None,
        )
        for spec in graph.nodes
    ]


def generate_launch_description():
    """The graph of config/graph.yaml as launch actions."""
    share = Path(get_package_share_directory("g2p_bringup"))
    default_graph = str(share / "config" / "graph.yaml")
    profile = profile_environment(dict(os.environ), share / "config" / "fastdds_discovery.xml")
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
            OpaqueFunction(function=_nodes),
        ]
    )
