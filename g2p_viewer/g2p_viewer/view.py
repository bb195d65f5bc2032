"""`ros2 run g2p_viewer view`: a run live in Foxglove; `view bags/<run> [--rate R]`: a recorded one.

Live, the node subscribes to the rig's `joint_states` and `treadmill` (best effort, so a slow viewer never
holds the rig back), its latched `robot_description` (the leg it draws), and the learner's `~/events`,
and serves them to Foxglove clients (g2p.viewer): by default on ws://127.0.0.1:8765, loopback only.

    ros2 run g2p_viewer view                                   # in /leg, beside the rig and the learner
    ros2 run g2p_viewer view --ros-args -p host:=0.0.0.0       # reachable from other machines
    ros2 run g2p_viewer view bags/<run> --rate 2               # replay a bag at twice the rig's pace

A replay needs no ROS graph: it reads the bag, waits for a Foxglove client, plays the run once and exits
when the client disconnects (or on Ctrl-C): stopping the server sooner would drop what it has not sent.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import threading
from pathlib import Path

import numpy as np
import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from g2p.bags.errors import BagError
from g2p.bags.events import run_event
from g2p.bags.reader import BagReader
from g2p.description.urdf import packaged_leg_description, parse_leg_urdf
from g2p.rig import DEFAULT_NAMESPACE
from g2p.validation import ConfigError
from g2p.viewer.replay import replay_bag, replay_message_bound
from g2p.viewer.server import LegViewer, ViewerConfig
from g2p_interfaces.msg import LearnerEvent, Treadmill
from g2p_ros import contract
from g2p_ros.contract import DESCRIPTION_QOS, JOINT_STATES, ROBOT_DESCRIPTION, TREADMILL
from g2p_ros.executable import run_node
from g2p_ros.params import declare_config, parameter_names
from g2p_ros.signals import init_with_stop_event

# The rig's samples, best effort: the viewer may drop ticks, the rig never waits for it.
VIEW_QOS = contract.qos(100, reliable=False)


class ViewerNode(Node):
    """Feeds the rig's topics and the learner's events to a LegViewer."""

    def __init__(self, learner_node: str = "learner") -> None:
        super().__init__("viewer", namespace=DEFAULT_NAMESPACE)
        config = declare_config(self, ViewerConfig)
        described = ParameterDescriptor(
            description="the learner node whose ~/events are shown", read_only=True
        )
        self.declare_parameter("learner_node", learner_node, described)
        learner = str(self.get_parameter("learner_node").value)
        self.viewer = LegViewer(packaged_leg_description(), config)
        self.create_subscription(JointState, JOINT_STATES, self._joint_state, VIEW_QOS)
        self.create_subscription(Treadmill, TREADMILL, self._treadmill, VIEW_QOS)
        self.create_subscription(String, ROBOT_DESCRIPTION, self._description, DESCRIPTION_QOS)
        self.create_subscription(
            LearnerEvent, f"{learner}/{contract.LEARNER_EVENTS}", self._event, contract.EVENT_QOS
        )
        self.get_logger().info(
            f"Foxglove viewer of {self.get_namespace()} on {self.viewer.url}: open it in Foxglove "
            "(Open connection -> Foxglove WebSocket) with the layout src/g2p/viewer/layout.json"
        )

    def _joint_state(self, msg: JointState) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.viewer.joint_state(stamp, np.asarray(msg.position[:2]), np.asarray(msg.velocity[:2]))

    def _treadmill(self, msg: Treadmill) -> None:
        self.viewer.treadmill(msg.displacement_mm)

    def _description(self, msg: String) -> None:
        try:
            self.viewer.set_description(parse_leg_urdf(msg.data, self.resolve_topic_name(ROBOT_DESCRIPTION)))
        except ValueError as err:
            self.get_logger().error(f"not drawing the rig's robot_description: {err}")

    def _event(self, msg: LearnerEvent) -> None:
        self.viewer.event(run_event(msg, self.get_clock().now().nanoseconds))

    def destroy_node(self) -> None:
        """Stop the WebSocket server, then destroy the node."""
        if hasattr(self, "viewer"):
            self.viewer.close()
        super().destroy_node()


def _replay(bag: Path, rate: float, config: ViewerConfig, stop: threading.Event) -> int:
    with BagReader(bag):  # an unreadable bag is an error now, not once a client has connected
        pass
    # A recorded run is shown whole: the client's backlog holds all of it, however slow the client.
    backlog = max(config.message_backlog, replay_message_bound(bag))
    config = dataclasses.replace(config, message_backlog=backlog)
    with LegViewer(packaged_leg_description(), config) as viewer:
        print(f"view: {bag} on {viewer.url}; waiting for a Foxglove client", flush=True)
        if not viewer.wait_for_client(stop=stop):
            return 0  # stopped before a client came: a clean stop
        shown = replay_bag(bag, viewer, rate, stop=stop)
        print(f"view: replayed {shown} ticks; serving them until the client disconnects", flush=True)
        viewer.wait_for_clients_to_leave(stop=stop)
    return 0


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="view", description=__doc__.splitlines()[0])
    parser.add_argument("bag", type=Path, nargs="?", help="replay this run's bag instead of the live graph")
    parser.add_argument("--rate", type=float, default=1.0, help="replay speed, relative to the rig's clock")
    parser.add_argument("--host", default=ViewerConfig.host, help="replay: address to listen on")
    parser.add_argument("--port", type=int, default=ViewerConfig.port, help="replay: TCP port")
    return parser.parse_args(remove_ros_args(argv)[1:])


def node_parameters() -> list[str]:
    """The parameters ViewerNode declares besides rclpy's (bringup checks its `--set` against them)."""
    return [*parameter_names(ViewerConfig), "learner_node"]


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run g2p_viewer view`."""
    argv = sys.argv if args is None else args
    options = _parse(argv)
    if options.bag is None:
        sys.exit(run_node("view", ViewerNode, argv, errors={RuntimeError: ("cannot serve", 1)}))
    sys.exit(_replay_main(options, argv))


def _replay_main(options: argparse.Namespace, argv: list[str]) -> int:
    """`view bags/<run>`: the replay's exit status (no node: rclpy only for its signal handling)."""
    stop = init_with_stop_event(argv)
    try:
        return _replay(options.bag, options.rate, ViewerConfig(options.host, options.port), stop)
    except (ConfigError, ValueError) as err:
        print(f"view: {err}", file=sys.stderr)
        return 2
    except BagError as err:
        print(f"view: error: {err}", file=sys.stderr)
        return 2
    except RuntimeError as err:  # the server cannot listen
        print(f"view: cannot serve: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
