"""The learner's run events: their names and the keys of their detail JSON, defined once.

The learner node produces them; g2p.bags.dataset, g2p.bags.resume and g2p.viewer read them. A run is
recorded as a stream of LearnerEvent messages (g2p_interfaces/msg/LearnerEvent.msg): the fixed fields
carry the figures (reward, energy, tracking errors, sigma), `detail` a JSON object whose keys are below.
The builders make the details the readers rely on; a reader gets a key with `.get` and treats a missing
one as "not recorded".
"""

from __future__ import annotations

import enum
from typing import Any

from g2p.learning.attempt import AttemptOutcome
from g2p.plant import Recording, stamp_ns


class Event(str, enum.Enum):
    """The `event` field: what happened."""

    RUN_START = "run_start"
    PHASE_START = "phase_start"
    """Babbling: a sequence (segment) starts."""
    PHASE_END = "phase_end"
    """Babbling: a sequence ended (its ticks in the detail), or the fit on a recorded run's data."""
    ATTEMPT_START = "attempt_start"
    ATTEMPT_END = "attempt_end"
    CHECKPOINT = "checkpoint"
    """The run's state after an attempt (g2p.learning.checkpoint), to resume from."""
    RIG_LOST = "rig_lost"
    RIG_BACK = "rig_back"
    RUN_END = "run_end"


# Detail keys.
CONTROL = "control"
"""How an attempt was played: "open" or "closed" (loop)."""
DESIRED_CYCLE_RAD = "desired_cycle_rad"
"""attempt_start: one cycle of the desired joint angles, N x 2 (rad), for live viewers."""
DESIRED_RAD = "desired_rad"
"""attempt_end: the desired joint angles of every tick played, N x 2 (rad)."""
CORRECTION_RAD_S = "correction_rad_s"
"""attempt_end in closed loop: the rig's velocity correction of every tick, N x 2 (rad/s)."""
TICKS = "ticks"
"""A played sequence's tick count."""
FIRST_TICK_STAMP_NS = "first_tick_stamp_ns"
"""A played sequence's first tick's header stamp (ns, the rig's clock)."""
CHECKPOINT = "checkpoint"
"""checkpoint: the run's state as g2p.learning.checkpoint's JSON."""
SEARCH = "search"
"""run_start: the search's configuration."""
CANCELLED = "cancelled"
"""run_end: why the run was cancelled."""
ERROR = "error"
"""run_end: the error that ended the run; rig_lost: the rig's error."""
RESUME = "resume"
"""run_end after an error: the bag to resume from."""


def segment_detail(recording: Recording) -> dict[str, int]:
    """Where a played sequence's ticks are: their count and the first one's stamp (ns)."""
    return {TICKS: len(recording), FIRST_TICK_STAMP_NS: stamp_ns(float(recording.t_s[0]))}


def attempt_start_detail(control: str, desired_cycle_rad: list[list[float]] | None) -> dict[str, Any]:
    """An attempt's start: how it is played and, when known, one cycle of its desired angles (N x 2, rad)."""
    detail: dict[str, Any] = {CONTROL: control}
    if desired_cycle_rad is not None:
        detail[DESIRED_CYCLE_RAD] = desired_cycle_rad
    return detail


def attempt_end_detail(outcome: AttemptOutcome) -> dict[str, Any]:
    """An attempt's end: its desired angles, where its ticks are, how it was played (and corrected)."""
    detail: dict[str, Any] = {
        DESIRED_RAD: outcome.desired[:, :2].tolist(),
        **segment_detail(outcome.recording),
        CONTROL: outcome.control.value,
    }
    if outcome.correction_rad_s is not None:
        detail[CORRECTION_RAD_S] = outcome.correction_rad_s.tolist()
    return detail
