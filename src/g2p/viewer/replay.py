"""A recorded run shown in the viewer, paced by its rig clock: `view bags/<run> [--rate R]`.

The bag's joint states, treadmill samples, learner events and robot_description go through the same
`LegViewer` calls as the live node's subscriptions, in recording order. The pace follows the joint
states' header stamps (the rig's clock: simulated time in fast simulation), so rate 1 shows the run as
the rig lived it, and the idle gaps of a fast simulated run (no ticks) take no time.

A bag knows more than a live viewer: each attempt's "attempt_end" event holds all its desired angles and
its first tick's stamp. They are read first and handed over with the attempt's "attempt_start", so the
desired curve lines up with the ticks exactly as g2p.bags.dataset cuts them (bags recorded before the
learner announced the desired cycle at the start show it too).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import defaultdict, deque
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from g2p.bags.dataset import ROBOT_DESCRIPTION, ROBOT_DESCRIPTION_TYPE
from g2p.bags.errors import BagReadError
from g2p.bags.events import LEARNER_EVENT_TYPE, RunEvent, run_event
from g2p.bags.metadata import read_metadata
from g2p.bags.reader import BagReader
from g2p.bags.ticks import header_stamp_ns, rig_topic_names
from g2p.description.urdf import parse_leg_urdf
from g2p.learning.run_events import DESIRED_CYCLE_RAD, DESIRED_RAD, FIRST_TICK_STAMP_NS, Event
from g2p.rig import DEFAULT_NAMESPACE
from g2p.viewer.server import LegViewer


class _AttemptEnds:
    """What each attempt's end event tells about it, handed to its start event."""

    _KEYS = (DESIRED_RAD, FIRST_TICK_STAMP_NS)

    def __init__(self, events: Iterable[RunEvent]) -> None:
        self._ends: dict[tuple[str, int], deque[dict[str, object]]] = defaultdict(deque)
        for e in events:
            if e.event == Event.ATTEMPT_END:
                known = {k: e.detail[k] for k in self._KEYS if k in e.detail}
                self._ends[(e.run_id, e.attempt)].append(known)

    def completed(self, start: RunEvent) -> RunEvent:
        """The start event with its attempt's desired angles and first tick, when the bag has them."""
        ends = self._ends.get((start.run_id, start.attempt))
        if start.event != Event.ATTEMPT_START or not ends:
            return start
        known = ends.popleft()
        detail = dict(start.detail)
        if DESIRED_RAD in known:
            detail[DESIRED_CYCLE_RAD] = known[DESIRED_RAD]  # the whole attempt: row k is tick k
        if FIRST_TICK_STAMP_NS in known:
            detail[FIRST_TICK_STAMP_NS] = known[FIRST_TICK_STAMP_NS]
        return dataclasses.replace(start, detail=detail)


def replay_message_bound(bag: Path | str, rig_namespace: str = DEFAULT_NAMESPACE) -> int:
    """Most messages `replay_bag` logs for `bag` (a viewer whose client backlog holds them drops none).

    A joint frame and a scene per joint state, an attempt and a scene per learner event.

    Raises:
        BagReadError: the bag's metadata cannot be read.
    """
    topics = read_metadata(Path(bag)).topics.values()
    joint_states = f"{rig_namespace.rstrip('/')}/joint_states"
    shown = (t.message_count for t in topics if t.name == joint_states or t.msgtype == LEARNER_EVENT_TYPE)
    return 2 * sum(shown)


def replay_bag(
    bag: Path | str,
    viewer: LegViewer,
    rate: float = 1.0,
    rig_namespace: str = DEFAULT_NAMESPACE,
    stop: threading.Event | None = None,
    sleep: Callable[[float], None] = time.sleep,
) -> int:
    """Show a recorded run in `viewer`.

    Args:
        bag: the run's bag directory.
        viewer: the viewer to feed.
        rate: playback speed relative to the rig's clock (> 0; `float("inf")`: as fast as it reads).
        rig_namespace: namespace of the rig topics.
        stop: set to end the replay early.
        sleep: how to wait (s).

    Returns:
        The number of joint states shown.

    Raises:
        ValueError: rate is not positive.
        BagReadError: the bag cannot be read, has no joint states, or its robot_description is not the
            leg's URDF.
    """
    if not rate > 0.0:
        raise ValueError(f"rate: must be > 0, got {rate!r}")
    shown = 0
    with BagReader(bag) as reader:
        source = str(reader.metadata.storage_files[0]) if reader.metadata.storage_files else str(bag)
        rig = rig_topic_names(reader.topics, rig_namespace)
        if "joint_states" not in rig:
            raise BagReadError("the bag has no joint states to show", source)
        events = {t.name for t in reader.topics.values() if t.msgtype == LEARNER_EVENT_TYPE}
        description = f"{rig_namespace.rstrip('/')}/{ROBOT_DESCRIPTION}"
        descriptions = {
            t.name
            for t in reader.topics.values()
            if (t.name, t.msgtype) == (description, ROBOT_DESCRIPTION_TYPE)
        }
        ends = _AttemptEnds(run_event(m.msg, m.timestamp_ns) for m in reader.messages(events))
        start: tuple[float, int] | None = None  # (wall s, rig stamp ns) of the first joint state
        for m in reader.messages([rig["joint_states"], rig.get("treadmill", ""), *events, *descriptions]):
            if stop is not None and stop.is_set():
                break
            if m.topic == rig["joint_states"]:
                stamp = header_stamp_ns(m.msg.header)
                if start is None:
                    start = (time.monotonic(), stamp)
                wait = start[0] + (stamp - start[1]) * 1e-9 / rate - time.monotonic()
                if wait > 0.0:
                    sleep(wait)
                viewer.joint_state(
                    stamp, np.asarray(m.msg.position[:2], dtype=np.float64), np.asarray(m.msg.velocity[:2])
                )
                shown += 1
            elif m.topic in events:
                viewer.event(ends.completed(run_event(m.msg, m.timestamp_ns)))
            elif m.topic in descriptions:
                try:
                    viewer.set_description(parse_leg_urdf(str(m.msg.data), f"{source}: {m.topic}"))
                except ValueError as err:
                    raise BagReadError(str(err), source) from err
            else:
                viewer.treadmill(float(m.msg.displacement_mm))
    return shown
