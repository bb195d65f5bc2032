"""A talker or a listener of one String topic, for measuring rediscovery after a partition.

    python benchmarks/two_host_probe.py talk|listen

The talker publishes its wall time 20 times a second (reliable, volatile); the listener prints one JSON
line per message it receives: {"sent": s, "received": s}.
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from std_msgs.msg import String


def main() -> None:
    """Talk or listen until killed."""
    rclpy.init()
    node = rclpy.create_node(f"probe_{sys.argv[1]}")
    if sys.argv[1] == "talk":
        pub = node.create_publisher(String, "/probe", 10)
        while rclpy.ok():
            pub.publish(String(data=repr(time.time())))
            rclpy.spin_once(node, timeout_sec=0.05)
    else:

        def heard(msg: String) -> None:
            print(json.dumps({"sent": float(msg.data), "received": time.time()}), flush=True)

        node.create_subscription(String, "/probe", heard, 10)
        rclpy.spin(node)


if __name__ == "__main__":
    main()
