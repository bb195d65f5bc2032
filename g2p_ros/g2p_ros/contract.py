"""Names and QoS of the rig contract, identical for the simulator and the hardware driver."""

import time
from collections.abc import Callable

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Topics and services, relative to the node's namespace (default /leg) so that remapping swaps rigs.
JOINT_STATES = "joint_states"
TREADMILL = "treadmill"
MOTOR_POWER = "motor_power"
APPLIED_ACTIVATION = "applied_activation"
ACTIVATION_CMD = "activation_cmd"
RUN_ACTIVATIONS = "run_activations"
RESET = "reset"
DEFAULT_NAMESPACE = "/leg"

# Rig samples: reliable, so a recorder loses nothing. A reliable writer drops samples its readers have not
# acknowledged yet once its history is full, and acknowledgements come at heartbeat pace: 10,000 samples
# (2 min at 78 Hz, 4 s of fast simulation at 30x) cover a reader's longest pauses (docs/BAGS.md).
SAMPLE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
# Commands: reliable; only the newest matters to the rig.
COMMAND_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
# /clock as rosbag2 and Gazebo publish it: any time source subscription (best effort) accepts it.
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)

# A client that has just discovered a server must give the server time to discover the client's reply
# reader too: rmw_fastrtps drops a reply whose reader has not matched within 100 ms (ros2/rmw_fastrtps#390),
# and on a busy machine discovery takes longer. Clients call a server only once they have known it this long.
DISCOVERY_SETTLE_S = 1.0


class ServerWatch:
    """Waits until a server is available and this client has known it for DISCOVERY_SETTLE_S.

    Args:
        is_ready: whether the server is available now (e.g. ActionClient.server_is_ready).
        wait: block until the server is available or a timeout (s) passes; True if available.
    """

    def __init__(self, is_ready: Callable[[], bool], wait: Callable[[float], bool]) -> None:
        self._is_ready = is_ready
        self._wait = wait
        self._known_since: float | None = None

    def wait_until_ready(self, timeout_s: float) -> bool:
        """True once the server can be called; False when it did not appear within `timeout_s` (s)."""
        if not self._is_ready():
            self._known_since = None  # gone (or never seen): a restarted server is a new one
            if not self._wait(timeout_s):
                return False
        if self._known_since is None:
            self._known_since = time.monotonic()
        delay = self._known_since + DISCOVERY_SETTLE_S - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        return True
