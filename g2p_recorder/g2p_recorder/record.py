"""`ros2 run g2p_recorder record`: record the graph's topics into `bags/<run-id>/`, like `ros2 bag record -a`.

The node polls the graph for topics, subscribes to each new one (raw, QoS adapted to its publishers'
offers) and hands the serialized messages to `g2p.bags.BagWriter`, stamped with the node clock (sim
time under use_sim_time). SIGINT and SIGTERM stop discovery, write what was already received and
finalize the bag; after kill -9, `recover_bag bags/<run-id>` makes the bag readable again.

Parameters: see `g2p.bags.config.RecorderConfig` (bags_dir, run_id, include_regex, exclude_regex, ...).
"""

from __future__ import annotations

import importlib
import sys
import threading
import time
from collections.abc import Callable
from datetime import datetime, timezone
from typing import Any

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.executors import Executor

try:  # rclpy's C++ events executor (Kilted and later); Jazzy has only the Python executors.
    from rclpy.experimental import EventsExecutor as _FastExecutor
except ImportError:  # pragma: no cover - exercised on Jazzy
    from rclpy.executors import SingleThreadedExecutor as _FastExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from rclpy.topic_endpoint_info import TopicEndpointInfo

from g2p.bags import BagError, InterfaceError, InterfaceLibrary, TopicSpec, TypeRegistry, ament_share_dirs
from g2p.bags.config import RecorderConfig
from g2p.bags.qos import EndpointQos, Qos, make_qos, recording_qos
from g2p.bags.writer import create_run_bag
from g2p_ros.executable import run_node, spin
from g2p_ros.params import (
    config_as_dict,
    declare_config,
    parameter_names,
    publish_config,
    refuse_undeclared_overrides,
)


def message_class(msgtype: str) -> Any:
    """The generated Python class of a message type name.

    Args:
        msgtype: "package/msg/Name", or an action's "package/action/Name_Goal" (_Result, _Feedback).

    Raises:
        ImportError: the package is not installed or has no such type.
    """
    pkg, kind, name = msgtype.split("/")
    module = importlib.import_module(f"{pkg}.{kind}")
    if kind == "action":
        base, _, part = name.rpartition("_")
        found = getattr(getattr(module, base, None), part, None)
    else:
        found = getattr(module, name, None)
    if found is None:
        raise ImportError(f"no Python class for {msgtype}")
    return found


def offered_qos(info: TopicEndpointInfo) -> Qos:
    """A publisher's offered QoS (from graph discovery) as the bag stores it."""
    p = info.qos_profile
    return make_qos(
        int(p.history),
        int(p.depth),
        int(p.reliability),
        int(p.durability),
        p.deadline.nanoseconds,
        p.lifespan.nanoseconds,
        int(p.liveliness),
        p.liveliness_lease_duration.nanoseconds,
        bool(p.avoid_ros_namespace_conventions),
    )


def qos_profile(qos: EndpointQos) -> QoSProfile:
    """An rclpy QoS profile from the policies the core chose."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if qos.keep_all else HistoryPolicy.KEEP_LAST,
        depth=qos.depth,
        reliability=ReliabilityPolicy.RELIABLE if qos.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.transient_local else DurabilityPolicy.VOLATILE,
    )


class RecorderNode(Node):
    """Discovers topics, subscribes to them raw and writes every message into the run's bag."""

    def __init__(self) -> None:
        super().__init__("recorder")
        self.config = declare_config(self, RecorderConfig)
        refuse_undeclared_overrides(self)  # before the bag exists: a refused recorder leaves none behind
        self._selection = self.config.selection()
        self._types = TypeRegistry(InterfaceLibrary(ament_share_dirs()))
        self.bag = create_run_bag(
            self.config.bags_dir,
            datetime.now(timezone.utc),
            np.random.default_rng(),
            self.config.run_id,
            {"g2p.recorder": self.get_fully_qualified_name()},
        )
        self.run_id = self.bag.path.name
        self.received = 0
        # Message timestamps: the node clock. Without sim time it is the system clock, read directly (faster).
        clock = self.get_clock()
        self._now_ns: Callable[[], int] = (
            (lambda: clock.now().nanoseconds) if self.get_parameter("use_sim_time").value else time.time_ns
        )
        self._early: list[tuple[Any, bytes]] = []
        self._recorded: dict[str, Subscription] = {}
        self._ignored: set[str] = set()
        self._config_pub = publish_config(
            self, {**config_as_dict(self.config), "run_id": self.run_id, "bag": str(self.bag.path)}
        )
        # Wall-clock timers: under use_sim_time, ROS-time timers would stall until /clock runs.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._discovery = self.create_timer(self.config.discovery_period_s, self.discover, clock=steady)
        self._chunks = self.create_timer(self.config.chunk_period_s, self.bag.close_chunk, clock=steady)
        self.get_logger().info(f"recording run {self.run_id} into {self.bag.path}")
        self.discover()

    def discover(self) -> None:
        """Subscribe to every selected topic that has publishers and is not recorded yet."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self._recorded or topic in self._ignored or not self._selection.matches(topic):
                continue
            if len(types) != 1:
                self._ignore(topic, f"it has several types ({', '.join(types)})")
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if publishers:  # wait for a publisher: its QoS decides the subscription's
                self._record(topic, types[0], publishers)

    def _record(self, topic: str, msgtype: str, publishers: list[TopicEndpointInfo]) -> None:
        try:
            cls = message_class(msgtype)
            definition = self._types.definition(msgtype)
        except (ImportError, ValueError, InterfaceError) as err:
            self._ignore(topic, f"its type {msgtype} is not available here: {err}")
            return
        for info in publishers:
            offered = str(info.topic_type_hash)
            if info.topic_type_hash.version == 1 and offered != definition.rihs01:
                self.get_logger().error(
                    f"{topic}: publisher {info.node_namespace}/{info.node_name} uses type hash {offered}, "
                    f"the installed {msgtype} has {definition.rihs01}: recording with the installed one"
                )
        offers = [offered_qos(info) for info in publishers]
        handle = self.bag.add_topic(TopicSpec(topic, definition, tuple(offers)))
        qos = recording_qos(offers, self.config.queue_depth)
        self._recorded[topic] = self.create_subscription(
            cls, topic, self._writer(handle), qos_profile(qos), raw=True
        )
        self.get_logger().info(
            f"recording {topic} ({msgtype}, {'reliable' if qos.reliable else 'best effort'}, "
            f"{'transient local' if qos.transient_local else 'volatile'})"
        )

    def _writer(self, handle: Any) -> Callable[[bytes], None]:
        bag, now_ns, early = self.bag, self._now_ns, self._early

        def on_message(data: bytes) -> None:
            t = now_ns()
            if t == 0:  # sim time before the first /clock message: hold until the clock runs
                early.append((handle, data))
            else:
                if early:
                    self._write_early(t)
                bag.write(handle, t, data)
            self.received += 1

        return on_message

    def _write_early(self, timestamp_ns: int) -> None:
        """Write the messages held while sim time had not started, stamped `timestamp_ns`."""
        for handle, data in self._early:
            self.bag.write(handle, timestamp_ns, data)
        self._early.clear()

    def _ignore(self, topic: str, why: str) -> None:
        self._ignored.add(topic)
        self.get_logger().warning(f"not recording {topic}: {why}")

    def drain(self, executor: Executor, timeout_s: float) -> None:
        """Stop discovering; record until the recorded topics' other publishers have left, then finish.

        Under `ros2 launch` (or a terminal's Ctrl-C) every node gets the signal at once: the rig then
        still publishes its last ticks and its final baseline tick, and waits for them to be
        acknowledged, while this node stops. So this node keeps its subscriptions until no other node
        publishes on a recorded topic of its namespace, then writes what is still queued, until nothing
        arrives for 0.1 s; all within `timeout_s` (a publisher that stays, when only the recorder is
        stopped, ends it then).
        """
        self._discovery.cancel()
        deadline = time.monotonic() + timeout_s
        while self._publishers_left() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
        # Quiet for 0.1 s of wall time, not one spin: a spin may run a timer instead of a message.
        count, last = self.received, time.monotonic()
        while time.monotonic() < min(deadline, last + 0.1):
            executor.spin_once(timeout_sec=0.02)
            if self.received != count:
                count, last = self.received, time.monotonic()
        if left := self._publishers_left():
            self.get_logger().warning(
                f"closing the bag after {timeout_s:g} s while {', '.join(sorted(left))} still publish: "
                "what they publish from now on is not recorded"
            )

    def _publishers_left(self) -> set[str]:
        """The graph's other nodes still publishing on a recorded topic (fully qualified names).

        The graph's: topics in this node's namespace (/leg/...). Global topics (/rosout,
        /parameter_events) have publishers outside the graph (the ros2 daemon, viewers), which stay.
        """
        me = (self.get_name(), self.get_namespace())
        prefix = self.get_namespace().rstrip("/") + "/"
        return {
            f"{info.node_namespace.rstrip('/')}/{info.node_name}"
            for topic in self._recorded
            if topic.startswith(prefix)
            for info in self.get_publishers_info_by_topic(topic)
            if (info.node_name, info.node_namespace) != me
        }

    def close_bag(self) -> None:
        """Finalize the bag (idempotent)."""
        if self.bag.closed:
            return
        self._write_early(0)  # sim time never started: the node clock read 0 all along
        self.bag.close()
        self.get_logger().info(
            f"closed {self.bag.path}: {self.bag.message_count} messages on "
            f"{len(self.bag.topic_counts)} topics"
        )

    def destroy_node(self) -> None:
        """Finalize the bag, then destroy the node."""
        if hasattr(self, "bag"):  # not when construction failed: rclpy's shutdown destroys such nodes too
            self.close_bag()
        super().destroy_node()


def node_parameters() -> list[str]:
    """The parameters RecorderNode declares besides rclpy's (bringup checks its `--set` against them)."""
    return parameter_names(RecorderConfig)


def _record(node: RecorderNode, executor: Executor, stop: threading.Event) -> int:
    """Record until SIGINT or SIGTERM, then what the graph's other publishers still send."""
    spin(node, executor, stop)
    node.drain(executor, node.config.drain_timeout_s)
    return 0


def main(args: list[str] | None = None) -> None:
    """Record until SIGINT or SIGTERM, then write what was received and finalize the bag.

    SIGINT and SIGTERM only set a flag, so the bag is never closed in the middle of a write. Exit status 2:
    an invalid parameter, or a bag that cannot be written.
    """
    sys.exit(
        run_node(
            "record",
            RecorderNode,
            args,
            # The Python executors cannot keep up with fast simulation (docs/BAGS.md); they are enough for
            # the rig's 78 Hz on Jazzy, where the events executor does not exist.
            executor=_FastExecutor,
            run=_record,
            errors={BagError: ("error", 2)},
        )
    )


if __name__ == "__main__":
    main()
