"""What the live view shows, from the rig's ticks and the learner's events: pure data, numpy only.

`ViewState` follows a run message by message, live (the viewer node's subscriptions) or from a bag
(g2p.viewer.replay): the leg's posture and foot, the belt's travel, the attempt being played with its
desired cycle, and each finished attempt's figures. g2p.viewer.channels turns its frames into Foxglove
messages.

The desired angles of tick k of an attempt are row k mod N of the desired angles its "attempt_start"
event carries (detail key "desired_cycle_rad", N x 2: the learner sends one cycle), k counting the joint
states stamped after that event (those that arrived before it included), as g2p.bags.dataset cuts
attempts, or from the stamp in its detail key
"first_tick_stamp_ns" on. Live on hardware, where the rig ticks at baseline until the sequence arrives,
the first rule puts the desired curve a few ticks (the goal's latency) early; a replay knows each
attempt's first tick from the bag (g2p.viewer.replay) and is exact.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from g2p.bags.events import RunEvent
from g2p.description import FloatArray, LegDescription, foot_path, forward_kinematics
from g2p.learning.run_events import CONTROL, DESIRED_CYCLE_RAD, FIRST_TICK_STAMP_NS, Event

# Belt marks drawn every 50 mm, so that its travel is visible.
BELT_MARK_SPACING_M = 0.05
# "first_tick_stamp_ns" is the tick's stamp, from its time in float seconds (exact on the stamp grid); a
# millisecond of slack, far below the 12.8 ms between ticks, finds the right tick all the same (as
# g2p.bags.dataset does).
_STAMP_SLACK_NS = 1_000_000
# Ticks an attempt's start event may arrive behind its first tick (10 s at 78 Hz).
_RECENT_TICKS = 780
# Foot trail: the last second and a half of the foot's path (78 Hz ticks).
DEFAULT_TRAIL_TICKS = 117


@dataclass(frozen=True)
class JointFrame:
    """One tick as the joint plot shows it.

    Attributes:
        stamp_ns: the tick's header stamp (ns, the rig's clock).
        position_rad: measured (proximal, distal) angles, shape (2,) (rad).
        velocity_rad_s: measured angular velocities, shape (2,) (rad/s).
        desired_rad: desired angles of this tick of the attempt, shape (2,) (rad); None between attempts.
        foot_m: the foot (bottom of the pad) in the belt frame (x, z) (m), shape (2,).
        belt_displacement_mm: the belt's cumulative travel at the latest treadmill sample (mm).
        attempt: the attempt being played (0: none).
        tick: index of the tick in the attempt (-1: none).
    """

    stamp_ns: int
    position_rad: FloatArray
    velocity_rad_s: FloatArray
    desired_rad: FloatArray | None
    foot_m: FloatArray
    belt_displacement_mm: float
    attempt: int
    tick: int


@dataclass(frozen=True)
class SceneFrame:
    """What the 3D scene draws at one tick; positions in the belt frame (x, z) (m).

    Attributes:
        stamp_ns: the tick's header stamp (ns).
        keypoints: hip, knee, ankle, foot, shape (4, 2).
        belt_half_length_m: half the length of belt drawn (m).
        belt_marks_x: x of the belt marks within it, shape (K,); they move with the belt.
        trail: the foot's recent path, oldest first, shape (T, 2).
        desired_foot_path: the desired cycle's foot path, shape (N, 2); None between attempts.
        label: one line naming the attempt and its latest figures.
    """

    stamp_ns: int
    keypoints: FloatArray
    belt_half_length_m: float
    belt_marks_x: FloatArray
    trail: FloatArray
    desired_foot_path: FloatArray | None
    label: str


@dataclass(frozen=True)
class AttemptSummary:
    """A finished attempt, from its "attempt_end" event.

    Attributes:
        stamp_ns: the event's stamp (ns, the learner's clock).
        attempt: attempt number (1-based).
        phase: "exploration", "exploitation", "tracking", ...
        control: "open" or "closed" loop.
        reward_mm: belt travel (mm).
        best_reward_mm: best reward so far (mm).
        sigma: the exploitation standard deviation after the attempt (NaN outside exploitation).
        energy_j: electrical energy (J).
        tracking_rmse_rad: tracking RMSE (rad).
        tracking_mse_deg2: tracking MSE, second half, joints summed (deg^2).
    """

    stamp_ns: int
    attempt: int
    phase: str
    control: str
    reward_mm: float
    best_reward_mm: float
    sigma: float
    energy_j: float
    tracking_rmse_rad: float
    tracking_mse_deg2: float


@dataclass
class _Attempt:
    number: int
    phase: str
    first_tick_ns: int  # the first joint state stamped at or after this belongs to the attempt
    desired_cycle_rad: FloatArray | None
    desired_foot_path: FloatArray | None
    ticks: int = 0


def belt_marks_x(displacement_mm: float, half_length_m: float) -> FloatArray:
    """The belt marks' x for a belt that has travelled `displacement_mm` (+ = toward -x), shape (K,) (m)."""
    offset = -((displacement_mm * 1e-3) % BELT_MARK_SPACING_M)
    n = math.ceil(half_length_m / BELT_MARK_SPACING_M) + 1
    x = offset + BELT_MARK_SPACING_M * np.arange(-n, n + 1, dtype=np.float64)
    return np.asarray(x[np.abs(x) <= half_length_m], dtype=np.float64)


def _desired_cycle(event: RunEvent) -> FloatArray | None:
    value = event.detail.get(DESIRED_CYCLE_RAD)
    try:
        cycle = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    ok = cycle.ndim == 2 and cycle.shape[1] == 2 and len(cycle) > 0 and bool(np.all(np.isfinite(cycle)))
    return cycle if ok else None


class ViewState:
    """The run as the viewer shows it, updated one message at a time.

    Args:
        description: the leg to draw (replace it with `set_description` when the rig publishes its own).
        belt_half_length_m: half the length of belt drawn (m).
        trail_ticks: ticks of the foot trail.
    """

    def __init__(
        self,
        description: LegDescription,
        belt_half_length_m: float = 0.3,
        trail_ticks: int = DEFAULT_TRAIL_TICKS,
    ) -> None:
        self.description = description
        self.belt_half_length_m = belt_half_length_m
        self.belt_displacement_mm = 0.0
        self.attempts: list[AttemptSummary] = []
        self._trail: deque[FloatArray] = deque(maxlen=trail_ticks)
        # Stamps of the latest ticks: an attempt_start that arrives after some of its ticks (events and
        # ticks come on separate topics) still counts them.
        self._recent_stamps: deque[int] = deque(maxlen=_RECENT_TICKS)
        self._attempt: _Attempt | None = None
        self._last: JointFrame | None = None

    def set_description(self, description: LegDescription) -> None:
        """Draw another leg from now on (the rig's robot_description)."""
        self.description = description
        if self._attempt is not None and self._attempt.desired_cycle_rad is not None:
            self._attempt.desired_foot_path = foot_path(description, self._attempt.desired_cycle_rad)
        self._trail.clear()

    def treadmill(self, displacement_mm: float) -> None:
        """A treadmill sample: the belt's cumulative travel (mm)."""
        self.belt_displacement_mm = float(displacement_mm)

    def joint_state(self, stamp_ns: int, position_rad: FloatArray, velocity_rad_s: FloatArray) -> JointFrame:
        """A joint state of the rig: the tick's frame for the joint plot."""
        q = np.asarray(position_rad, dtype=np.float64).reshape(2)
        foot = forward_kinematics(self.description, q)[3]
        self._trail.append(foot)
        self._recent_stamps.append(int(stamp_ns))
        desired, tick, number = None, -1, 0
        a = self._attempt
        if a is not None and stamp_ns >= a.first_tick_ns:
            tick, number = a.ticks, a.number
            if a.desired_cycle_rad is not None:
                desired = a.desired_cycle_rad[a.ticks % len(a.desired_cycle_rad)]
            a.ticks += 1
        self._last = JointFrame(
            stamp_ns=int(stamp_ns),
            position_rad=q,
            velocity_rad_s=np.asarray(velocity_rad_s, dtype=np.float64).reshape(2),
            desired_rad=desired,
            foot_m=foot,
            belt_displacement_mm=self.belt_displacement_mm,
            attempt=number,
            tick=tick,
        )
        return self._last

    def event(self, event: RunEvent) -> AttemptSummary | None:
        """A learner event; returns the attempt's summary on "attempt_end"."""
        if event.event == Event.ATTEMPT_START:
            cycle = _desired_cycle(event)
            path = foot_path(self.description, cycle) if cycle is not None else None
            first = event.detail.get(FIRST_TICK_STAMP_NS)
            first_ns = first - _STAMP_SLACK_NS if isinstance(first, int) else event.stamp_ns + 1
            seen = sum(1 for s in self._recent_stamps if s >= first_ns)
            self._attempt = _Attempt(event.attempt, event.phase, first_ns, cycle, path, ticks=seen)
            return None
        if event.event != Event.ATTEMPT_END:
            return None
        self._attempt = None
        control = event.detail.get(CONTROL)
        summary = AttemptSummary(
            stamp_ns=event.stamp_ns,
            attempt=event.attempt,
            phase=event.phase,
            control=control if isinstance(control, str) else "open",
            reward_mm=event.reward_mm,
            best_reward_mm=event.best_reward_mm,
            sigma=event.sigma,
            energy_j=event.energy_j,
            tracking_rmse_rad=event.tracking_rmse_rad,
            tracking_mse_deg2=event.tracking_mse_deg2,
        )
        self.attempts.append(summary)
        return summary

    def scene(self) -> SceneFrame | None:
        """The scene at the latest joint state (None before the first)."""
        if self._last is None:
            return None
        a = self._attempt
        return SceneFrame(
            stamp_ns=self._last.stamp_ns,
            keypoints=forward_kinematics(self.description, self._last.position_rad),
            belt_half_length_m=self.belt_half_length_m,
            belt_marks_x=belt_marks_x(self.belt_displacement_mm, self.belt_half_length_m),
            trail=np.array(self._trail),
            desired_foot_path=a.desired_foot_path if a is not None else None,
            label=self._label(),
        )

    def _label(self) -> str:
        parts = []
        if self._attempt is not None:
            parts.append(f"attempt {self._attempt.number} ({self._attempt.phase})")
        if self.attempts:
            last = self.attempts[-1]
            parts.append(f"last {last.reward_mm:.1f} mm")
            if math.isfinite(last.best_reward_mm):
                parts.append(f"best {last.best_reward_mm:.1f} mm")
        parts.append(f"belt {self.belt_displacement_mm:.0f} mm")
        return "  ".join(parts)
