"""`ros2 run g2p_recorder replay bags/<run>`: republish a bag's topics with their recorded timing and QoS.

Options like `ros2 bag play`: --rate, --clock [HZ], --topics, --remap from:=to, --loop, --delay; and
--wait-for-subscribers S to start only once every replayed topic has a subscriber (or S seconds
passed). Each topic is published with the QoS its recorded publishers offered (see
`g2p.bags.qos.replay_qos`); the timing and topic plan come from `g2p.bags.replay_plan`.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from builtin_interfaces.msg import Time
from rclpy.duration import Duration
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rosgraph_msgs.msg import Clock

from g2p.bags import BagError, BagReader
from g2p.bags.replay_plan import ReplayOptions, ReplayTopic, Timeline, parse_remap, plan_topics
from g2p.validation import ConfigError
from g2p_recorder.record import message_class, qos_profile
from g2p_ros import contract
from g2p_ros.executable import run_node

# A message due less than this ahead is published at once rather than slept for (s).
_EARLY_S = 0.0005
# How long the player waits at the end for reliable subscribers to acknowledge everything (s).
_ACK_TIMEOUT_S = 5.0


class ReplayNode(Node):
    """Publishes the messages of one bag, in recorded order and timing.

    Args:
        reader: the open bag.
        topics: what to publish, as what (`plan_topics` of the bag and the options).
        options: rate, topics, remaps, loop, clock.
    """

    def __init__(self, reader: BagReader, topics: list[ReplayTopic], options: ReplayOptions) -> None:
        super().__init__("replay")
        self._reader = reader
        self._options = options
        self.plan: list[ReplayTopic] = []
        self._outputs: dict[str, Publisher] = {}
        for t in topics:
            try:
                cls = message_class(t.msgtype)
            except (ImportError, ValueError) as err:
                self.get_logger().warning(f"not replaying {t.source}: its type is not available here ({err})")
                continue
            self.plan.append(t)
            self._outputs[t.source] = self.create_publisher(cls, t.output, qos_profile(t.qos))
        self._clock = (
            self.create_publisher(Clock, "/clock", contract.CLOCK_QOS) if options.clock_hz > 0 else None
        )
        self._next_clock_s = 0.0
        self.published = 0
        for t in self.plan:
            remapped = f" as {t.output}" if t.output != t.source else ""
            self.get_logger().info(
                f"replaying {t.source}{remapped} ({t.msgtype}, "
                f"{'reliable' if t.qos.reliable else 'best effort'}, "
                f"{'transient local' if t.qos.transient_local else 'volatile'})"
            )

    def play(self, stop: threading.Event) -> None:
        """Play the bag (repeatedly with --loop) until it ends or `stop` is set."""
        if not self.plan:
            self.get_logger().warning("nothing to replay")
            return
        self._wait_for_subscribers(stop)
        if self._options.delay_s > 0 and stop.wait(self._options.delay_s):
            return
        topics = [t.source for t in self.plan]
        while not stop.is_set():
            timeline = Timeline(self._reader.start_ns, time.monotonic(), self._options.rate)
            self._next_clock_s = timeline.wall_start_s
            for message in self._reader.raw_messages(topics):
                if not self._wait_until(timeline.due_s(message.timestamp_ns), timeline, stop):
                    return
                self._outputs[message.topic].publish(message.data)
                self.published += 1
            if not self._options.loop:
                break
        for publisher in self._outputs.values():
            publisher.wait_for_all_acked(Duration(seconds=_ACK_TIMEOUT_S))

    def _wait_for_subscribers(self, stop: threading.Event) -> None:
        timeout_s = self._options.wait_for_subscribers_s
        if timeout_s <= 0:
            return
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not stop.is_set():
            waiting = [p.topic_name for p in self._outputs.values() if p.get_subscription_count() == 0]
            if not waiting:
                return
            stop.wait(0.05)
        waiting = [p.topic_name for p in self._outputs.values() if p.get_subscription_count() == 0]
        if waiting:
            self.get_logger().warning(f"starting without subscribers on {', '.join(waiting)}")

    def _wait_until(self, due_s: float, timeline: Timeline, stop: threading.Event) -> bool:
        """Sleep until `due_s` (monotonic), publishing /clock on its period; False when stopped."""
        period_s = 1.0 / self._options.clock_hz if self._clock is not None else 0.0
        while True:
            now = time.monotonic()
            if self._clock is not None and now >= self._next_clock_s:
                ns = timeline.bag_time_ns(now)
                self._clock.publish(Clock(clock=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)))
                self._next_clock_s = max(self._next_clock_s + period_s, now)
            if due_s - now <= _EARLY_S:
                return not stop.is_set()
            wake_s = min(due_s, self._next_clock_s) if self._clock is not None else due_s
            if stop.wait(max(0.0, wake_s - now)):
                return False


def parse_arguments(argv: Sequence[str]) -> tuple[Path, ReplayOptions]:
    """The bag and the replay options from the command line (without ROS arguments).

    Raises:
        SystemExit: the arguments are invalid (argparse prints why; exit status 2).
    """
    parser = argparse.ArgumentParser(
        prog="replay", description="Republish a bag's topics with their recorded timing and QoS."
    )
    parser.add_argument("bag", type=Path, help="the bag directory (bags/<run-id>)")
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1.0)")
    parser.add_argument("--topics", nargs="+", default=[], metavar="TOPIC", help="replay only these topics")
    parser.add_argument(
        "--remap", nargs="+", action="extend", default=[], metavar="FROM:=TO", help="publish topic FROM as TO"
    )
    parser.add_argument("--loop", action="store_true", help="start over at the end, until stopped")
    parser.add_argument(
        "--clock",
        type=float,
        nargs="?",
        const=40.0,
        default=0.0,
        metavar="HZ",
        help="publish the playback time on /clock (default 40 Hz when given without HZ)",
    )
    parser.add_argument("--delay", type=float, default=0.0, metavar="S", help="wait S seconds before playing")
    parser.add_argument(
        "--wait-for-subscribers",
        type=float,
        default=0.0,
        metavar="S",
        help="wait up to S seconds until every replayed topic has a subscriber",
    )
    parser.add_argument(
        "--qos-depth",
        type=int,
        default=1000,
        metavar="N",
        help="publisher depth when the recorded history depth is unknown (default 1000)",
    )
    ns = parser.parse_args(list(argv))
    try:
        options = ReplayOptions(
            rate=ns.rate,
            topics=tuple(ns.topics),
            remaps=tuple(parse_remap(r) for r in ns.remap),
            loop=ns.loop,
            clock_hz=ns.clock,
            delay_s=ns.delay,
            wait_for_subscribers_s=ns.wait_for_subscribers,
            default_depth=ns.qos_depth,
        )
    except ConfigError as err:
        parser.error(str(err))
    return ns.bag, options


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """Split a command line into this program's arguments and the `--ros-args ... [--]` sections.

    Only the ROS sections go to rclpy: rcl would otherwise take `--remap from:=to` values for (deprecated)
    ROS remapping rules and remove them.
    """
    ours, ros, in_ros = [], [], False
    for arg in argv:
        if arg == "--ros-args":
            in_ros = True
            ros.append(arg)
        elif in_ros and arg == "--":
            in_ros = False
            ros.append(arg)
        else:
            (ros if in_ros else ours).append(arg)
    return ours, ros


def _play(node: ReplayNode, executor: Executor, stop: threading.Event) -> int:
    """Play the bag until it ends (or forever with --loop), SIGINT or SIGTERM."""
    node.play(stop)
    node.get_logger().info(f"published {node.published} messages")
    return 0


def main(args: list[str] | None = None) -> None:
    """Replay a bag until it ends (or forever with --loop), SIGINT or SIGTERM; exit 2 on a bad bag."""
    argv = list(sys.argv if args is None else args)
    ours, ros = split_ros_args(argv[1:])
    bag, options = parse_arguments(ours)
    try:
        with BagReader(bag) as reader:
            # The options checked against the bag before ROS starts.
            topics = plan_topics(reader.topics, options)
            code = run_node(
                "replay",
                lambda: ReplayNode(reader, topics, options),
                [argv[0], *ros],
                run=_play,
                errors={BagError: ("error", 2)},  # damaged data found while playing
            )
    except (BagError, ConfigError) as err:  # unreadable, or without the topics the options name
        print(f"replay: error: {err}", file=sys.stderr)
        code = 2
    sys.exit(code)


if __name__ == "__main__":
    main()
