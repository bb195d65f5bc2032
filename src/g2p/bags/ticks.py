"""Rig ticks from recorded rig topics: the four messages of a tick share one header stamp.

The rig publishes joint_states, treadmill, motor_power and applied_activation once per tick with the
same stamp. Grouping them back by stamp gives the per-tick samples as a `g2p.plant.Recording`. The k-th
message with a given stamp on one topic joins the k-th group of that stamp, so a stamp seen again later
(a restarted clock) starts a new tick instead of merging with an old one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from g2p.bags.errors import BagReadError
from g2p.bags.metadata import TopicInfo
from g2p.plant import JOINT_NAMES, N_JOINTS, N_MOTORS, Recording

# Rig topics (relative to the rig's namespace) and their message types.
RIG_TOPICS: dict[str, str] = {
    "joint_states": "sensor_msgs/msg/JointState",
    "treadmill": "g2p_interfaces/msg/Treadmill",
    "motor_power": "g2p_interfaces/msg/MotorPower",
    "applied_activation": "g2p_interfaces/msg/MotorActivation",
}


def header_stamp_ns(header: Any) -> int:
    """A std_msgs/Header's stamp in nanoseconds."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def rig_topic_names(topics: Mapping[str, TopicInfo], namespace: str) -> dict[str, str]:
    """The bag's topic for each rig role (joint_states, ...).

    A role's topic is `<namespace>/<role>` when the bag has it with the right type; otherwise the only
    topic of the role's type, if there is exactly one.

    Returns:
        role -> topic name, for the roles found.
    """
    names = {}
    ns = namespace.rstrip("/")
    for role, msgtype in RIG_TOPICS.items():
        preferred = f"{ns}/{role}"
        candidates = [t.name for t in topics.values() if t.msgtype == msgtype]
        if preferred in candidates:
            names[role] = preferred
        elif len(candidates) == 1:
            names[role] = candidates[0]
    return names


@dataclass(frozen=True)
class Ticks:
    """The complete ticks of a recording.

    Attributes:
        stamps_ns: each tick's header stamp, shape (N,) (ns).
        occurrences: 0 for the first tick with its stamp, 1 for the second (a reset sample), ..., shape (N,).
        recording: the samples, one row per tick, ordered by (stamp, occurrence).
        incomplete: stamps seen on some but not all four rig topics (dropped).
    """

    stamps_ns: NDArray[np.int64]
    occurrences: NDArray[np.int64]
    recording: Recording
    incomplete: int

    def segment(
        self, low_ns: int, high_ns: int, include_low: bool = True, count: int | None = None
    ) -> Recording:
        """The ticks stamped from `low_ns` to `high_ns` (inclusive), at most the first `count` of them.

        Of the ticks stamped exactly `high_ns` only the first belongs to the segment: a second one is a
        reset sample that followed it (simulation time does not advance on a reset).

        Args:
            low_ns: lowest stamp (ns).
            high_ns: highest stamp (ns), included once.
            include_low: whether ticks stamped exactly `low_ns` belong to the segment.
            count: keep only the first `count` ticks of the segment (None: all).
        """
        above = self.stamps_ns >= low_ns if include_low else self.stamps_ns > low_ns
        below = (self.stamps_ns < high_ns) | ((self.stamps_ns == high_ns) & (self.occurrences == 0))
        index = np.flatnonzero(above & below)
        if count is not None:
            index = index[: max(count, 0)]
        if len(index) == 0:
            return Recording.empty()
        if _contiguous(index):
            return self.recording.slice(int(index[0]), int(index[-1]) + 1)
        return self.recording.take(index)


class TickAssembler:
    """Collects decoded rig messages and groups them into ticks by header stamp."""

    def __init__(self) -> None:
        self._groups: dict[tuple[int, int], dict[str, Any]] = {}
        self._seen: dict[str, dict[int, int]] = {role: {} for role in RIG_TOPICS}

    def add(self, role: str, msg: Any) -> None:
        """Add one decoded message of the rig topic `role`."""
        stamp = header_stamp_ns(msg.header)
        occurrence = self._seen[role].get(stamp, 0)
        self._seen[role][stamp] = occurrence + 1
        self._groups.setdefault((stamp, occurrence), {})[role] = msg

    def ticks(self, source: str = "") -> Ticks:
        """The complete ticks, ordered by stamp, then by occurrence for ticks sharing a stamp.

        (A simulator's reset sample carries the stamp of the tick before it: simulation time does not
        advance on a reset. Its messages are the second occurrence of that stamp on every topic.)

        Args:
            source: the file the messages came from, for errors.

        Raises:
            BagReadError: a message does not have the rig contract's shape.
        """
        complete = [
            (key, group)
            for key, group in sorted(self._groups.items(), key=lambda item: item[0])
            if len(group) == len(RIG_TOPICS)
        ]
        incomplete = len(self._groups) - len(complete)
        try:
            rows = [_row(group) for _, group in complete]
        except (ValueError, IndexError) as err:
            raise BagReadError(f"rig message does not match the rig contract: {err}", source or None) from err
        stamps = np.array([key[0] for key, _ in complete], dtype=np.int64)
        occurrences = np.array([key[1] for key, _ in complete], dtype=np.int64)
        if not rows:
            return Ticks(stamps, occurrences, Recording.empty(), incomplete)
        columns = {name: np.array([r[name] for r in rows], dtype=np.float64) for name in rows[0]}
        return Ticks(stamps, occurrences, Recording(**columns), incomplete)


def _row(group: Mapping[str, Any]) -> dict[str, Any]:
    joints, treadmill = group["joint_states"], group["treadmill"]
    power, applied = group["motor_power"], group["applied_activation"]
    names = list(joints.name)
    order = [names.index(n) for n in JOINT_NAMES] if names else list(range(N_JOINTS))
    position = np.asarray(joints.position, dtype=np.float64)
    velocity = np.asarray(joints.velocity, dtype=np.float64)
    activation = np.asarray(applied.activation, dtype=np.float64)
    if activation.shape != (N_MOTORS,):
        raise ValueError(f"applied_activation has {activation.size} values, expected {N_MOTORS}")
    return {
        "t_s": header_stamp_ns(joints.header) * 1e-9,
        "activation": activation,
        "position_rad": position[order],
        "velocity_rad_s": velocity[order] if velocity.size else np.full(N_JOINTS, np.nan),
        "belt_mm": float(treadmill.displacement_mm),
        "belt_velocity_mm_s": float(treadmill.velocity_mm_s),
        "current_a": np.asarray(power.current_a, dtype=np.float64),
        "power_w": np.asarray(power.power_w, dtype=np.float64),
        "energy_j": np.asarray(power.energy_j, dtype=np.float64),
    }


def _contiguous(index: NDArray[np.intp]) -> bool:
    return bool(index[-1] - index[0] + 1 == len(index))
