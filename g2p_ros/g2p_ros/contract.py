"""Names and QoS of the rig contract, identical for the simulator and the hardware driver."""

import threading
import time
from collections.abc import Callable, Iterable

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Topics and services, relative to the node's namespace (default /leg) so that remapping swaps rigs.
JOINT_STATES = "joint_states"
TREADMILL = "treadmill"
MOTOR_POWER = "motor_power"
APPLIED_ACTIVATION = "applied_activation"
ACTIVATION_CMD = "activation_cmd"
RUN_ACTIVATIONS = "run_activations"
RUN_TRAJECTORY = "run_trajectory"
RESET = "reset"
# The leg's URDF (g2p.description.urdf), latched: robot_state_publisher, RViz and Foxglove draw it from
# joint_states.
ROBOT_DESCRIPTION = "robot_description"
# What the rig publishes every tick.
RIG_SAMPLE_TOPICS = (JOINT_STATES, TREADMILL, MOTOR_POWER, APPLIED_ACTIVATION)
# What the rig's limits did each tick (g2p_interfaces/RigLimits), with SAMPLE_QOS, beside the samples.
RIG_LIMITS = "rig_limits"


def qos(depth: int, *, reliable: bool = True, latched: bool = False) -> QoSProfile:
    """Keep the last `depth` messages; reliable or best effort; latched (transient local) or volatile."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


# Rig samples: reliable, so a recorder loses nothing. A reliable writer drops samples its readers have not
# acknowledged yet once its history is full, and acknowledgements come at heartbeat pace: 10,000 samples
# (2 min at 78 Hz, 4 s of fast simulation at 30x) cover a reader's longest pauses (docs/BAGS.md).
SAMPLE_QOS = qos(10000)
# Commands: reliable; only the newest matters to the rig.
COMMAND_QOS = qos(10)
# The learner's topics, relative to the learner node (`~/events`, `~/inverse_map`): its run's events and
# every inverse map it fitted.
LEARNER_EVENTS = "events"
LEARNER_INVERSE_MAP = "inverse_map"
# Events and maps must reach the recorder whole, even one that joins late (and a viewer started late sees
# the run so far): transient local, with a history longer than a run's events.
EVENT_QOS = qos(1000, latched=True)
MAP_QOS = qos(100, latched=True)
# robot_description as robot_state_publisher publishes it: one message, kept for late subscribers.
DESCRIPTION_QOS = qos(1, latched=True)
# /diagnostics: reliable, depth 100 (100 s of rig time, a few seconds of fast simulation): a recorder
# lagging a fast simulation loses none.
DIAGNOSTICS_QOS = qos(100)
# /clock as rosbag2 and Gazebo publish it: any time source subscription (best effort) accepts it.
CLOCK_QOS = qos(1, reliable=False)


def action_name(node: Node, name: str) -> str:
    """The fully qualified name of action `name` for `node`, with the node's remap rules applied.

    Create every action client and server with it: Jazzy's rcl_action applies no remap rules to action
    names (ros2/rcl#1170 came after Jazzy), so `-r run_activations:=/pi/leg/run_activations` would be
    ignored there. A name resolved here is not remapped again by distributions that do remap actions.
    """
    return node.resolve_topic_name(name)


# A client that has just discovered a server must give the server time to discover the client's reply
# reader too: rmw_fastrtps drops a reply whose reader has not matched within 100 ms (ros2/rmw_fastrtps#390),
# and on a busy machine discovery takes longer. Clients call a server only once they have known it this long.
DISCOVERY_SETTLE_S = 1.0


class ServerWatch:
    """Whether a server can be called: it is available and this client has known it for `settle_s`.

    Args:
        name: what is watched, for messages (e.g. the server's name).
        is_ready: whether the server is available now (e.g. ActionClient.server_is_ready).
        settle_s: how long the server must have been known before it is called (s).
    """

    def __init__(self, name: str, is_ready: Callable[[], bool], settle_s: float = DISCOVERY_SETTLE_S) -> None:
        self.name = name
        self._is_ready = is_ready
        self._settle_s = settle_s
        self._known_since: float | None = None

    def poll(self) -> bool:
        """True once the server can be called; notes when it was first seen."""
        if not self._is_ready():
            self._known_since = None  # gone (or never seen): a restarted server is a new one
            return False
        now = time.monotonic()
        if self._known_since is None:
            self._known_since = now
        return now - self._known_since >= self._settle_s

    def wait_until_ready(self, timeout_s: float) -> bool:
        """True once the server can be called; False when it was not within `timeout_s` (s)."""
        return not wait_all([self], timeout_s)


def wait_all(
    watches: Iterable[ServerWatch],
    timeout_s: float,
    stop: threading.Event | None = None,
    poll_s: float = 0.02,
) -> list[str]:
    """Wait for every watch at once, so discoveries and settling overlap.

    Returns:
        the names of the watches still not ready after `timeout_s` (s) or when `stop` was set; empty when
        all are ready.
    """
    pending = list(watches)
    deadline = time.monotonic() + timeout_s
    while True:
        pending = [w for w in pending if not w.poll()]
        if not pending or time.monotonic() > deadline or (stop is not None and stop.is_set()):
            return [w.name for w in pending]
        time.sleep(poll_s)
