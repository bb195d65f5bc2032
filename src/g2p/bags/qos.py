"""QoS for recording and replay, adapted to the publishers' offers the way rosbag2 adapts them.

Offered profiles are rosbags `Qos` values (the form a bag stores). The ROS adapters convert them to and
from rclpy profiles; the enum values of both are the rmw values.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import TypeVar

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

_E = TypeVar("_E", bound=Enum)

# rmw's "infinite" duration, as rosbag2 writes it.
INFINITE = QosTime(9_223_372_036, 854_775_807)


@dataclass(frozen=True)
class EndpointQos:
    """The QoS policies the recorder or the player chooses for one topic.

    Attributes:
        reliable: reliable (True) or best effort (False).
        transient_local: transient local (True, late joiners get the history) or volatile (False).
        keep_all: keep all samples (True) or the last `depth` (False).
        depth: history depth when keeping the last samples (messages).
    """

    reliable: bool
    transient_local: bool
    keep_all: bool
    depth: int


def recording_qos(offers: Sequence[Qos], depth: int) -> EndpointQos:
    """The subscription QoS that receives from every offering publisher without losing compatibility.

    Like rosbag2: reliable only if every publisher is reliable, transient local only if every publisher
    is transient local; keep the last `depth` messages (a deep queue absorbs the recorder's pauses).

    Args:
        offers: the publishers' offered profiles (at least one).
        depth: subscription queue depth (messages).

    Raises:
        ValueError: no offers, or depth < 1.
    """
    if not offers:
        raise ValueError("recording_qos needs at least one offered profile")
    if depth < 1:
        raise ValueError(f"depth must be >= 1, got {depth}")
    return EndpointQos(
        reliable=all(q.reliability == QosReliability.RELIABLE for q in offers),
        transient_local=all(q.durability == QosDurability.TRANSIENT_LOCAL for q in offers),
        keep_all=False,
        depth=depth,
    )


def replay_qos(recorded: Sequence[Qos], default_depth: int) -> EndpointQos:
    """The publisher QoS that replays a topic as its recorded publishers offered it.

    Reliable if every recorded publisher was reliable (a reliable publisher serves best-effort and
    reliable subscribers alike), transient local if every one was. The history is the recorded one when
    all publishers agree and it is known (DDS discovery does not carry it, so it usually is not); else
    keep the last `default_depth`.

    Args:
        recorded: the offered profiles stored in the bag (may be empty: then reliable, volatile).
        default_depth: depth when the recorded history is unknown (messages).

    Raises:
        ValueError: default_depth < 1.
    """
    if default_depth < 1:
        raise ValueError(f"default_depth must be >= 1, got {default_depth}")
    histories = {(q.history, q.depth) for q in recorded}
    keep_all, depth = False, default_depth
    if len(histories) == 1:
        history, recorded_depth = next(iter(histories))
        if history == QosHistory.KEEP_ALL:
            keep_all = True
        elif history == QosHistory.KEEP_LAST and recorded_depth > 0:
            depth = recorded_depth
    return EndpointQos(
        reliable=all(q.reliability == QosReliability.RELIABLE for q in recorded),
        transient_local=bool(recorded)
        and all(q.durability == QosDurability.TRANSIENT_LOCAL for q in recorded),
        keep_all=keep_all,
        depth=depth,
    )


def duration_qos_time(nanoseconds: int) -> QosTime:
    """A QoS duration (ns) as rosbag2 stores it; rmw's infinite values map to INFINITE."""
    if nanoseconds >= INFINITE.sec * 1_000_000_000 + INFINITE.nsec:
        return INFINITE
    return QosTime(nanoseconds // 1_000_000_000, nanoseconds % 1_000_000_000)


def make_qos(
    history: int,
    depth: int,
    reliability: int,
    durability: int,
    deadline_ns: int,
    lifespan_ns: int,
    liveliness: int,
    liveliness_lease_ns: int,
    avoid_ros_namespace_conventions: bool,
) -> Qos:
    """A rosbags Qos from rmw policy numbers and durations in nanoseconds.

    Unknown policy numbers become the UNKNOWN member of their enum.
    """
    return Qos(
        _member(QosHistory, history),
        int(depth),
        _member(QosReliability, reliability),
        _member(QosDurability, durability),
        duration_qos_time(deadline_ns),
        duration_qos_time(lifespan_ns),
        _member(QosLiveliness, liveliness),
        duration_qos_time(liveliness_lease_ns),
        bool(avoid_ros_namespace_conventions),
    )


def _member(enum: type[_E], value: int) -> _E:
    """The member of `enum` with the rmw number `value`, or its UNKNOWN member."""
    try:
        return enum(value)
    except ValueError:
        return enum["UNKNOWN"]
