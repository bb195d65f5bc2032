"""A recorded learning run as data: rig ticks cut into babbling and attempts, learner events, inverse maps.

Segments are cut by the learner's events and the ticks' header stamps (docs/BAGS.md, "Event conventions"):

- a babbling segment: from a "phase_start" event of phase "babbling" to the next "phase_end" event of
  that phase (or, when missing, to the next event of any kind, or to the end of the recording);
- attempt k: from its "attempt_start" event to its "attempt_end" event (or, when missing, to the next
  event, or to the end of the recording).

A segment holds the ticks stamped after the opening event's stamp, up to and including the closing
event's stamp. The learner stamps events with its clock, which in fast simulation is the stamp of the
last tick it has seen: shared with the reset sample that follows (simulation time does not advance on
a reset), and possibly one tick behind when the closing event is sent. So when the closing event's
detail says how many ticks were played ("ticks", else the rows of "desired_rad"), the segment is that
many ticks from its start, whatever the closing stamp. When the closing event's detail has
"first_tick_stamp_ns" (the first played tick's stamp, from the RunActivations result), the segment
starts exactly there (needed on the hardware, where the rig ticks at baseline between sequences).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from g2p.bags.errors import BagReadError
from g2p.bags.events import (
    CONFIG_SUFFIX,
    CONFIG_TYPE,
    INVERSE_MAP_TYPE,
    LEARNER_EVENT_TYPE,
    FloatArray,
    InverseMapSnapshot,
    RunEvent,
    inverse_map_snapshot,
    run_event,
)
from g2p.bags.reader import BagReader
from g2p.bags.ticks import TickAssembler, Ticks, header_stamp_ns, rig_topic_names
from g2p.description import LegDescription
from g2p.description.urdf import UrdfError, parse_leg_urdf
from g2p.learning.run_events import CONTROL, DESIRED_RAD, FIRST_TICK_STAMP_NS, TICKS, Event
from g2p.plant import N_JOINTS, Recording, concatenate
from g2p.rig import DEFAULT_NAMESPACE

BABBLING = "babbling"
# The rig nodes publish the leg's URDF here (std_msgs/String, latched), relative to the rig namespace.
ROBOT_DESCRIPTION = "robot_description"
ROBOT_DESCRIPTION_TYPE = "std_msgs/msg/String"
# What the rig's safety envelope did each tick (g2p_ros.contract.RIG_LIMITS), stamped as the tick.
RIG_LIMITS = "rig_limits"
RIG_LIMITS_TYPE = "g2p_interfaces/msg/RigLimits"
# A tick's stamp (ns) -> (the activation decided, shape (3,); the trip after it, "" when none).
RigLimitsByStamp = dict[int, tuple[FloatArray, str]]
_END_OF_TIME = np.iinfo(np.int64).max
_STAMP_SLACK_NS = 1_000_000


@dataclass(frozen=True)
class RecordedAttempt:
    """One attempt of a run.

    Attributes:
        attempt: attempt number (1-based).
        phase: the phase it belongs to ("exploration", "exploitation", "tracking", ...).
        start: its attempt_start event.
        end: its attempt_end event (None when the run stopped during the attempt).
        recording: the rig ticks of the attempt.
        desired_position_rad: the desired joint angles, one row per tick, shape (M, 2) (rad), from the
            events' detail JSON key "desired_rad" (None when not given).
        correction_rad_s: closed loop: the rig's velocity correction of each tick, shape (M, 2) (rad/s),
            from the detail key "correction_rad_s" (None in open loop or when not given).
        envelope_ticks: the attempt's ticks whose activation the rig's safety envelope changed, from the
            `rig_limits` topic (None when the bag has none).
        trip: why the rig tripped during the attempt, from `rig_limits` ("" when it did not).
    """

    attempt: int
    phase: str
    start: RunEvent
    end: RunEvent | None
    recording: Recording
    desired_position_rad: FloatArray | None
    correction_rad_s: FloatArray | None = None
    envelope_ticks: int | None = None
    trip: str = ""

    @property
    def control(self) -> str:
        """How the attempt was played: "open" or "closed" loop (the events' detail key "control").

        Runs recorded without the key were open loop.
        """
        for event in (self.end, self.start):
            if event is not None and isinstance(event.detail.get(CONTROL), str):
                return str(event.detail[CONTROL])
        return "open"

    @property
    def tracking_rmse_rad(self) -> float:
        """Tracking RMSE of the attempt (rad), NaN when not reported."""
        return self.end.tracking_rmse_rad if self.end is not None else float("nan")

    @property
    def correction_rms_rad_s(self) -> float:
        """RMS of the closed loop's velocity correction over the attempt, both joints (rad/s).

        NaN in open loop.
        """
        c = self.correction_rad_s
        return float(np.sqrt(np.mean(c**2))) if c is not None and c.size else float("nan")

    @property
    def reward_mm(self) -> float:
        """Belt travel of the attempt (mm), NaN when not reported."""
        return self.end.reward_mm if self.end is not None else float("nan")

    @property
    def energy_j(self) -> float:
        """Electrical energy of the attempt (J), NaN when not reported."""
        return self.end.energy_j if self.end is not None else float("nan")

    @property
    def tracking_mse_deg2(self) -> float:
        """Tracking MSE of the attempt (deg^2), NaN when not reported."""
        return self.end.tracking_mse_deg2 if self.end is not None else float("nan")


@dataclass(frozen=True)
class RunData:
    """Everything a report needs from a bag.

    Attributes:
        bag: the bag directory.
        run_id: the learner's run id (the bag directory's name when no event says).
        duration_s: recorded duration (s).
        topic_counts: messages per topic.
        ticks: every complete rig tick.
        events: the learner's events, in stamp order.
        babbling_segments: each babbling phase's ticks, in order.
        attempts: the attempts, in order.
        inverse_maps: the inverse-map snapshots, in stamp order.
        configs: each node's configuration (topic -> parsed JSON) from the latched `~/config` topics.
        leg_description: the leg the rig ran, from the last message on its `robot_description` topic
            (the URDF the rig nodes publish, g2p.description.urdf); None when the bag has none (older bags).
        rig_limits: each tick's `rig_limits` message (by stamp, ns): the activation the rig decided,
            before its safety envelope, and the trip; None when the bag has none.
    """

    bag: Path
    run_id: str
    duration_s: float
    topic_counts: dict[str, int]
    ticks: Ticks
    events: list[RunEvent]
    babbling_segments: list[Recording]
    attempts: list[RecordedAttempt]
    inverse_maps: list[InverseMapSnapshot]
    configs: dict[str, Any]
    leg_description: LegDescription | None = None
    rig_limits: RigLimitsByStamp | None = None

    def decided_activation(self, recording: Recording) -> FloatArray | None:
        """The activations the rig decided for `recording`'s ticks, before its envelope, shape (N, 3).

        A tick without its `rig_limits` message gets a row of NaN; None when the bag has none.
        """
        if self.rig_limits is None:
            return None
        entries = _rig_limits_at(self.rig_limits, recording.t_s)
        return np.array([np.full(3, np.nan) if e is None else e[0] for e in entries]).reshape(-1, 3)

    @property
    def babbling(self) -> Recording:
        """All babbling ticks (the segments end to end)."""
        return concatenate(self.babbling_segments)


@dataclass(frozen=True)
class TrainingData:
    """What the learner trains on, recovered from a bag.

    Attributes:
        babbling: each babbling segment's samples (contiguous ticks), in order.
        attempts: each attempt's samples, in order.
        inverse_map: the latest inverse map's arrays (name -> array) with its format_version, as
            g2p.inverse_map.InverseMap.to_arrays gives them; None when the bag has none.
    """

    babbling: list[Recording]
    attempts: list[Recording]
    inverse_map: dict[str, FloatArray] | None


def load_run(bag: Path | str, rig_namespace: str = DEFAULT_NAMESPACE) -> RunData:
    """Read a recorded run.

    Args:
        bag: the bag directory.
        rig_namespace: namespace of the rig topics (their names are `<namespace>/joint_states`, ...).

    Raises:
        BagReadError: the bag cannot be read, or its messages break the rig or learner contract (a
            `robot_description` that is not the URDF of a leg included).
    """
    with BagReader(bag) as reader:
        topics = reader.topics
        rig = rig_topic_names(topics, rig_namespace)
        description_topic = f"{rig_namespace.rstrip('/')}/{ROBOT_DESCRIPTION}"
        limits_topic = f"{rig_namespace.rstrip('/')}/{RIG_LIMITS}"
        limits_topics = [
            t.name for t in topics.values() if t.name == limits_topic and t.msgtype == RIG_LIMITS_TYPE
        ]
        description_topics = [
            t.name
            for t in topics.values()
            if t.name == description_topic and t.msgtype == ROBOT_DESCRIPTION_TYPE
        ]
        role_of = {name: role for role, name in rig.items()}
        event_topics = [t.name for t in topics.values() if t.msgtype == LEARNER_EVENT_TYPE]
        map_topics = [t.name for t in topics.values() if t.msgtype == INVERSE_MAP_TYPE]
        config_topics = [
            t.name for t in topics.values() if t.msgtype == CONFIG_TYPE and t.name.endswith(CONFIG_SUFFIX)
        ]
        assembler = TickAssembler()
        events: list[RunEvent] = []
        maps: list[InverseMapSnapshot] = []
        configs: dict[str, Any] = {}
        urdf: str | None = None
        limits: RigLimitsByStamp | None = {} if limits_topics else None
        source = str(reader.metadata.storage_files[0]) if reader.metadata.storage_files else str(bag)
        for m in reader.messages(
            [*rig.values(), *event_topics, *map_topics, *config_topics, *description_topics, *limits_topics]
        ):
            if m.topic in role_of:
                assembler.add(role_of[m.topic], m.msg)
            elif m.topic in event_topics:
                events.append(run_event(m.msg, m.timestamp_ns))
            elif m.topic in map_topics:
                try:
                    maps.append(inverse_map_snapshot(m.msg))
                except ValueError as err:
                    raise BagReadError(str(err), source) from err
            elif m.topic in limits_topics and limits is not None:  # a tick's first: a reset has none
                entry = (np.asarray(m.msg.commanded, dtype=np.float64), str(m.msg.trip))
                limits.setdefault(header_stamp_ns(m.msg.header), entry)
            elif m.topic in description_topics:
                urdf = str(m.msg.data)  # latched: the last one is the rig's current description
            else:
                configs[m.topic] = _parse_config(str(m.msg.data))
        ticks = assembler.ticks(source)
        counts = {name: info.message_count for name, info in topics.items()}
        duration_s = reader.duration_ns * 1e-9
    events.sort(key=lambda e: (e.stamp_ns, e.log_time_ns))
    maps.sort(key=lambda s: (s.stamp_ns, s.refinement))
    run_ids = [e.run_id for e in events if e.run_id]
    return RunData(
        bag=Path(bag),
        run_id=run_ids[0] if run_ids else Path(bag).name,
        duration_s=duration_s,
        topic_counts=counts,
        ticks=ticks,
        events=events,
        babbling_segments=_babbling(ticks, events),
        attempts=_attempts(ticks, events, limits),
        inverse_maps=maps,
        configs=configs,
        leg_description=_leg_description(urdf, description_topic, source) if urdf is not None else None,
        rig_limits=limits,
    )


def _leg_description(urdf: str, topic: str, source: str) -> LegDescription:
    try:
        return parse_leg_urdf(urdf, source=topic)
    except UrdfError as err:
        raise BagReadError(str(err), source) from err


def load_training_data(bag: Path | str, rig_namespace: str = DEFAULT_NAMESPACE) -> TrainingData:
    """The babbling and attempt segments of a recorded run, and its latest inverse map.

    Raises:
        BagReadError: the bag cannot be read, or its messages break the rig or learner contract.
    """
    run = load_run(bag, rig_namespace)
    return TrainingData(
        babbling=run.babbling_segments,
        attempts=[a.recording for a in run.attempts],
        inverse_map=_map_arrays(run.inverse_maps[-1]) if run.inverse_maps else None,
    )


def _map_arrays(snapshot: InverseMapSnapshot) -> dict[str, FloatArray]:
    return {**snapshot.arrays, "format_version": np.array([float(snapshot.format_version)])}


def _babbling(ticks: Ticks, events: list[RunEvent]) -> list[Recording]:
    segments = []
    for i, start in enumerate(events):
        if start.phase != BABBLING or start.event != Event.PHASE_START:
            continue
        later = events[i + 1 :]
        end = next((e for e in later if e.phase == BABBLING and e.event == Event.PHASE_END), None)
        closes = end is not None and not any(
            e.event == Event.PHASE_START and e.stamp_ns < end.stamp_ns for e in later
        )
        segments.append(_segment(ticks, start, end if closes else next(iter(later), None), closes))
    return segments


def _attempts(ticks: Ticks, events: list[RunEvent], limits: RigLimitsByStamp | None) -> list[RecordedAttempt]:
    attempts = []
    for i, start in enumerate(events):
        if start.event != Event.ATTEMPT_START:
            continue
        later = events[i + 1 :]
        end = next(
            (
                e
                for e in later
                if e.event == Event.ATTEMPT_END and e.attempt == start.attempt and e.run_id == start.run_id
            ),
            None,
        )
        closing = end if end is not None else next(iter(later), None)
        recording = _segment(ticks, start, closing, closes=end is not None)
        phase = start.phase or (end.phase if end is not None else "")
        attempts.append(
            RecordedAttempt(
                start.attempt,
                phase,
                start,
                end,
                recording,
                _per_joint(start, end, DESIRED_RAD),
                _per_joint(start, end, "correction_rad_s"),
                *_envelope(recording, limits),
            )
        )
    return attempts


def _envelope(recording: Recording, limits: RigLimitsByStamp | None) -> tuple[int | None, str]:
    """The ticks of `recording` whose applied activation differs from the one decided, and the first trip."""
    if limits is None:
        return None, ""
    changed, trip = 0, ""
    for applied, entry in zip(recording.activation, _rig_limits_at(limits, recording.t_s), strict=True):
        if entry is not None:
            changed += bool(np.any(applied != entry[0]))
            trip = trip or entry[1]
    return changed, trip


def _rig_limits_at(limits: RigLimitsByStamp, t_s: FloatArray) -> list[tuple[FloatArray, str] | None]:
    """Each tick's `rig_limits` entry (None when it has none), found by the tick's stamp.

    `t_s` is stamp_ns * 1e-9 in float64: system-time stamps keep about 0.2 us of error, so a tick takes
    the nearest stamp within 1 us (ticks are 12.8 ms apart).
    """
    keys = np.array(sorted(limits), dtype=np.int64)
    if not len(keys):
        return [None] * len(t_s)
    wanted = np.asarray(t_s, dtype=np.float64) * 1e9
    right = np.clip(np.searchsorted(keys, wanted), 0, len(keys) - 1)
    left = np.clip(right - 1, 0, len(keys) - 1)
    nearest = np.where(np.abs(keys[left] - wanted) < np.abs(keys[right] - wanted), left, right)
    return [
        limits[int(keys[k])] if abs(keys[k] - w) <= 1000.0 else None
        for k, w in zip(nearest, wanted, strict=True)
    ]


@dataclass(frozen=True)
class _Bounds:
    low_ns: int
    high_ns: int
    include_low: bool
    count: int | None


def _bounds(start: RunEvent, end: RunEvent | None, closes: bool) -> _Bounds:
    """Where the segment opened by `start` and ended by `end` lies.

    Args:
        start: the opening event.
        end: the event ending the segment (None: the end of the recording).
        closes: whether `end` is the segment's own closing event, whose detail describes the segment.
    """
    if end is None:
        return _Bounds(start.stamp_ns, int(_END_OF_TIME), False, None)
    detail = end.detail if closes else {}
    first, ticks = detail.get(FIRST_TICK_STAMP_NS), detail.get(TICKS)
    desired = _per_joint(end, None, DESIRED_RAD) if closes else None
    count = ticks if isinstance(ticks, int) else (len(desired) if desired is not None else None)
    high = int(_END_OF_TIME) if count is not None else end.stamp_ns
    if isinstance(first, int):
        # The learner derives the stamp from float seconds (exact on the stamp grid); a millisecond of
        # slack, far below the 12.8 ms between ticks, finds the right tick all the same.
        return _Bounds(first - _STAMP_SLACK_NS, high, True, count)
    return _Bounds(start.stamp_ns, high, False, count)


def _segment(ticks: Ticks, start: RunEvent, end: RunEvent | None, closes: bool) -> Recording:
    b = _bounds(start, end, closes)
    return ticks.segment(b.low_ns, b.high_ns, b.include_low, b.count)


def _per_joint(start: RunEvent, end: RunEvent | None, key: str) -> FloatArray | None:
    """The events' detail array `key` with one row of 2 per tick (e.g. "desired_rad"); None if absent."""
    for event in (start, end):
        value = event.detail.get(key) if event is not None else None
        if value is None:
            continue
        try:
            desired = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            continue
        if desired.ndim == 2 and desired.shape[1] == N_JOINTS:
            return desired
    return None


def _parse_config(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text
