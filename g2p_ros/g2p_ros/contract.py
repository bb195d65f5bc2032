"""Names and QoS of the rig contract, identical for the simulator and the hardware driver."""

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
