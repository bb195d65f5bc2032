"""The learner's handshake with the recorder of its namespace: a goal waits until the recorder records.

The recorder announces its run on its latched `~/config` (run id, bag); it records the rig once it
subscribes to every rig sample topic. A learner without a run id of its own takes the recorder's.
"""

from __future__ import annotations

import json
from typing import Any

from rclpy.node import Node
from std_msgs.msg import String

from g2p_ros.contract import RIG_SAMPLE_TOPICS, ServerWatch
from g2p_ros.params import CONFIG_QOS


class RecorderLink:
    """The recorder `recorder_node` of `node`'s namespace, as the learner waits for it.

    Args:
        node: the learner node.
        recorder_node: the recorder's node name (in the learner's namespace).
    """

    def __init__(self, node: Node, recorder_node: str) -> None:
        self._node = node
        self._name = recorder_node
        self._config: dict[str, Any] | None = None
        self.watch = ServerWatch(
            f"recorder {node.get_namespace().rstrip('/')}/{recorder_node}", self._ready, settle_s=0.0
        )
        """Ready once the recorder announced its run and subscribes to every rig sample topic."""
        self._sub = node.create_subscription(String, f"{recorder_node}/config", self._on_config, CONFIG_QOS)

    def run(self) -> tuple[str, str] | None:
        """The recorder's run: (run id, bag path as its host names it), once it announced it."""
        if self._config is None:
            return None
        return str(self._config.get("run_id", "")), str(self._config.get("bag", ""))

    def _on_config(self, msg: String) -> None:
        try:
            self._config = json.loads(msg.data)
        except json.JSONDecodeError:
            self._node.get_logger().warning(f"unreadable recorder configuration: {msg.data[:200]!r}")

    def _ready(self) -> bool:
        return self._config is not None and self._listening()

    def _listening(self) -> bool:
        """Whether the recorder subscribes to every rig sample topic (as the node's remappings name them)."""
        namespace = self._node.get_namespace()
        return all(
            any(
                s.node_name == self._name and s.node_namespace == namespace
                for s in self._node.get_subscriptions_info_by_topic(topic)
            )
            for topic in RIG_SAMPLE_TOPICS
        )
