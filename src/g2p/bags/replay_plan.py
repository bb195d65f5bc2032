"""Replay planning: which topics to publish where, with which QoS, and when each message is due.

The ROS player (g2p_recorder replay) owns the publishers and the sleeping; this module decides everything
else, so that it can be tested without ROS.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from g2p.bags.metadata import TopicInfo
from g2p.bags.qos import EndpointQos, replay_qos
from g2p.validation import ConfigError, require, require_non_negative

CLOCK_TOPIC = "/clock"


@dataclass(frozen=True)
class ReplayOptions:
    """How a bag is replayed (the `replay` command's options).

    Attributes:
        rate: playback speed factor (2.0 plays twice as fast as recorded).
        topics: replay only these topics (recorded names); empty for all.
        remaps: (recorded name, published name) pairs.
        loop: start over after the last message, until stopped.
        clock_hz: publish the playback time on /clock at this rate (Hz); 0 for no /clock. The recorded
            /clock topic is then not replayed, so that there is one time source.
        delay_s: wait this long before the first message (s, wall time).
        wait_for_subscribers_s: before playing, wait up to this long until every replayed topic has a
            subscriber (s, wall time; 0 to start at once).
        default_depth: publisher queue depth when the bag does not know the recorded one (messages).
    """

    rate: float = 1.0
    topics: tuple[str, ...] = ()
    remaps: tuple[tuple[str, str], ...] = ()
    loop: bool = False
    clock_hz: float = 0.0
    delay_s: float = 0.0
    wait_for_subscribers_s: float = 0.0
    default_depth: int = 1000

    def __post_init__(self) -> None:
        require(
            math.isfinite(self.rate) and self.rate > 0,
            "rate",
            f"must be a finite number > 0, got {self.rate!r}",
        )
        require_non_negative(self.clock_hz, "clock")
        require_non_negative(self.delay_s, "delay")
        require_non_negative(self.wait_for_subscribers_s, "wait_for_subscribers")
        require(self.default_depth >= 1, "default_depth", f"must be >= 1, got {self.default_depth}")
        sources = [s for s, _ in self.remaps]
        require(len(set(sources)) == len(sources), "remap", f"a topic is remapped twice: {sources}")
        for source, target in self.remaps:
            require(
                source.startswith("/") and target.startswith("/"),
                "remap",
                f"names must be fully qualified (start with /): {source}:={target}",
            )


def parse_remap(text: str) -> tuple[str, str]:
    """Parse a `from:=to` remapping.

    Raises:
        ConfigError: the text is not of that form.
    """
    source, sep, target = text.partition(":=")
    require(bool(sep and source and target), "remap", f"expected from:=to, got {text!r}")
    return source, target


@dataclass(frozen=True)
class ReplayTopic:
    """One topic to replay.

    Attributes:
        source: the topic's name in the bag.
        output: the name it is published on.
        msgtype: its message type.
        qos: the publisher QoS (from the recorded offers).
    """

    source: str
    output: str
    msgtype: str
    qos: EndpointQos


def plan_topics(topics: Mapping[str, TopicInfo], options: ReplayOptions) -> list[ReplayTopic]:
    """The topics to replay, in name order.

    Raises:
        ConfigError: a selected or remapped topic is not in the bag, or two topics would be published
            on the same name.
    """
    missing = [t for t in (*options.topics, *(s for s, _ in options.remaps)) if t not in topics]
    require(
        not missing,
        "topics",
        f"not in the bag: {', '.join(missing)} (the bag has {', '.join(sorted(topics))})",
    )
    remap = dict(options.remaps)
    selected = options.topics or tuple(sorted(topics))
    plan = [
        ReplayTopic(
            name,
            remap.get(name, name),
            topics[name].msgtype,
            replay_qos(topics[name].offered_qos, options.default_depth),
        )
        for name in sorted(selected)
        if not (options.clock_hz > 0 and name == CLOCK_TOPIC)
    ]
    outputs = [t.output for t in plan]
    clash = sorted({o for o in outputs if outputs.count(o) > 1})
    require(not clash, "remap", f"several topics would be published on {', '.join(clash)}")
    if options.clock_hz > 0:
        require(CLOCK_TOPIC not in outputs, "remap", f"{CLOCK_TOPIC} is published by --clock")
    return plan


class Timeline:
    """Maps bag time to wall time for one pass through the bag.

    Args:
        bag_start_ns: bag time that plays at `wall_start_s` (ns).
        wall_start_s: wall (monotonic) time of the start (s).
        rate: playback speed factor.
    """

    def __init__(self, bag_start_ns: int, wall_start_s: float, rate: float) -> None:
        if not (math.isfinite(rate) and rate > 0):
            raise ConfigError(f"rate: must be a finite number > 0, got {rate!r}")
        self.bag_start_ns = bag_start_ns
        self.wall_start_s = wall_start_s
        self.rate = rate

    def due_s(self, timestamp_ns: int) -> float:
        """Wall time (s) at which the message recorded at `timestamp_ns` is due."""
        return self.wall_start_s + (timestamp_ns - self.bag_start_ns) * 1e-9 / self.rate

    def bag_time_ns(self, wall_s: float) -> int:
        """Bag time (ns) playing at wall time `wall_s`."""
        return self.bag_start_ns + round((wall_s - self.wall_start_s) * self.rate * 1e9)
