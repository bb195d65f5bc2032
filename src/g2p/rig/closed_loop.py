"""Closed-loop G2P: a PI correction of the inverse map's velocity input, evaluated on the rig every tick.

The paper plays the map's activations open loop. Its authors' follow-up (Marjaninejad et al. 2019,
"Simple kinematic feedback enhances autonomous learning in bio-inspired tendon-driven systems",
arXiv 1907.04539) closes the loop on the map's input, not on the motor commands: each tick the joint-angle
error e = desired - measured feeds a PI term that is added to the desired velocity fed to the map,

    velocity input = desired velocity + P e + I * integral(e dt) + V (desired velocity - measured velocity)

per joint, while the desired angles and accelerations are fed unchanged. The follow-up's law is V = 0; the
velocity term V is this project's addition: on the simulated leg the follow-up's angle terms make tracking
worse than open loop, while the velocity term with the integral cuts the error by about 3.5
(docs/ALGORITHM.md, "Closed loop"; docs/RESULTS.md). `TrajectoryTracker` does that for one trajectory,
in numpy only (the map's forward pass, no torch), so that the rig's own tick loop runs it: the
simulator's and the hardware driver's (g2p_ros.rig_server), and `g2p.rig.PlantRig` in-process.

Timing, tick by tick (k = 0 .. N-1; row j of a recording is the state at the end of tick j):
    the errors of tick j are e_j = desired[j, :2] - measured angles[j] and desired[j, 2:4] - measured
    velocities[j];
    before tick k the tracker knows the errors of ticks j <= k - 1 - delay_ticks (no correction before);
    the activation of tick k is the map on desired[(k + lead) % N] with the corrected velocity (the lead
    as in open loop, g2p.learning.attempt.plan_attempt).
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from g2p.inverse_map import N_INPUTS, InverseMap
from g2p.plant import N_JOINTS, NOMINAL_TICK_HZ, Recording, TickSample
from g2p.validation import require

FloatArray = NDArray[np.float64]

# Documented ranges of the feedback settings (a goal outside them is rejected).
MAX_P_GAIN_PER_S = 100.0
MAX_I_GAIN_PER_S2 = 100.0
MAX_VELOCITY_GAIN = 20.0
MAX_INTEGRAL_LIMIT_RAD_S = 10.0
MAX_CORRECTION_LIMIT_RAD_S = 50.0
MAX_DELAY_TICKS = round(NOMINAL_TICK_HZ)  # 1 s


class ControlMode(str, enum.Enum):
    """How an attempt's activations are decided."""

    OPEN = "open"
    """The paper's G2P: the map's activations for the desired kinematics, computed once and played blind."""
    CLOSED = "closed"
    """The map evaluated on the rig every tick, on the desired kinematics corrected by feedback."""


@dataclass(frozen=True)
class FeedbackConfig:
    """The correction of the map's velocity input.

    The defaults are the best of a sweep on the simulated leg in the air, without delay
    (benchmarks/bench_closed_loop.py --experiments sweep; docs/ALGORITHM.md, "Closed loop"): no
    proportional term, the integral, and the velocity term. The follow-up's gains are
    `FeedbackConfig(p_gain_per_s=(10, 15), i_gain_per_s2=(2, 6), velocity_gain=(0, 0))`; on the simulated
    leg they track worse than open loop.

    Attributes:
        p_gain_per_s: proportional gain per joint (proximal, distal): rad/s of velocity input per rad of
            angle error (1/s); in [0, 100]. The follow-up's [10, 15].
        i_gain_per_s2: integral gain per joint: rad/s of velocity input per rad*s of integrated error
            (1/s^2); in [0, 100]. The follow-up's [2, 6].
        velocity_gain: velocity-error gain per joint: rad/s of velocity input per rad/s of velocity error
            (dimensionless); in [0, 20]. 0 in the follow-up.
        integral_limit_rad_s: bound on each joint's integrated error, |integral(e dt)| (rad*s): the
            transition from rest must not wind the integral up; in (0, 10].
        correction_limit_rad_s: bound on each joint's whole correction (rad/s), the velocity term
            included: keeps the map's input near the range it was fitted on; in (0, 50].
        delay_ticks: extra ticks between a measurement and its use, for experiments on sensory delay
            (0 = the latest measurement; 4 ticks = 51 ms at 78 Hz); in [0, 78].
    """

    p_gain_per_s: tuple[float, float] = (0.0, 0.0)
    i_gain_per_s2: tuple[float, float] = (4.0, 6.0)
    velocity_gain: tuple[float, float] = (3.0, 3.0)
    integral_limit_rad_s: float = 1.0
    correction_limit_rad_s: float = 10.0
    delay_ticks: int = 0

    def __post_init__(self) -> None:
        for name, high in (
            ("p_gain_per_s", MAX_P_GAIN_PER_S),
            ("i_gain_per_s2", MAX_I_GAIN_PER_S2),
            ("velocity_gain", MAX_VELOCITY_GAIN),
        ):
            value = tuple(float(v) for v in getattr(self, name))
            require(
                len(value) == N_JOINTS and all(0.0 <= v <= high for v in value),
                name,
                f"must be {N_JOINTS} values in [0, {high:g}], got {getattr(self, name)}",
            )
            object.__setattr__(self, name, value)
        for name, high in (
            ("integral_limit_rad_s", MAX_INTEGRAL_LIMIT_RAD_S),
            ("correction_limit_rad_s", MAX_CORRECTION_LIMIT_RAD_S),
        ):
            value = getattr(self, name)
            require(
                math.isfinite(value) and 0.0 < value <= high, name, f"must be in (0, {high:g}], got {value}"
            )
        require(
            isinstance(self.delay_ticks, int) and 0 <= self.delay_ticks <= MAX_DELAY_TICKS,
            "delay_ticks",
            f"must be an integer in [0, {MAX_DELAY_TICKS}], got {self.delay_ticks!r}",
        )


class FeedbackLaw:
    """The correction of the map's velocity input from one tick's errors: one trajectory's state.

    The integral of the angle error and the correction are both bounded.

    Args:
        config: gains and limits (its delay is the tracker's business).
        tick_s: the integration step: one rig tick (s).
    """

    def __init__(self, config: FeedbackConfig, tick_s: float = 1.0 / NOMINAL_TICK_HZ) -> None:
        self._p = np.array(config.p_gain_per_s)
        self._i = np.array(config.i_gain_per_s2)
        self._v = np.array(config.velocity_gain)
        self._integral_limit = config.integral_limit_rad_s
        self._limit = config.correction_limit_rad_s
        self._tick_s = tick_s
        self.integral = np.zeros(N_JOINTS)
        """The integrated angle error so far, shape (2,) (rad*s)."""

    def update(self, angle_error_rad: FloatArray, velocity_error_rad_s: FloatArray) -> FloatArray:
        """Integrate one tick's angle error (2,) (rad) and return the correction (2,) (rad/s)."""
        self.integral = np.clip(
            self.integral + angle_error_rad * self._tick_s, -self._integral_limit, self._integral_limit
        )
        correction = self._p * angle_error_rad + self._i * self.integral + self._v * velocity_error_rad_s
        return np.clip(correction, -self._limit, self._limit)


@dataclass(frozen=True)
class Trajectory:
    """What a rig needs to play one trajectory in closed loop (the `run_trajectory` goal).

    Attributes:
        desired: desired kinematics, one row per tick, shape (N, 6) (rad, rad/s, rad/s^2).
        inverse_map: the fitted map the rig evaluates every tick.
        feedback: the feedback law's settings.
        lead_ticks: ticks each activation is played ahead of the kinematics it is for (the map's command
            lead, as in open loop).
    """

    desired: FloatArray
    inverse_map: InverseMap
    feedback: FeedbackConfig
    lead_ticks: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "desired", check_trajectory(self.desired))
        if not self.inverse_map.is_fitted:
            raise ValueError("inverse_map: not fitted")
        if not 0 <= self.lead_ticks < len(self.desired):
            raise ValueError(f"lead_ticks: must be in [0, {len(self.desired)}), got {self.lead_ticks}")

    def __len__(self) -> int:
        return len(self.desired)


@dataclass(frozen=True)
class TrackedRecording:
    """What the rig recorded while playing a trajectory in closed loop.

    Attributes:
        recording: the ticks played (activations applied, angles measured, ...), N rows.
        correction_rad_s: the velocity correction of each tick, shape (N, 2) (rad/s).
    """

    recording: Recording
    correction_rad_s: FloatArray


class TrajectoryTracker:
    """Decides each tick's activation of one trajectory from the map and the measured joint state.

    Call `next_activation` once per tick, in order, with what was measured at the end of the previous
    tick (None before the first tick).

    Args:
        trajectory: the trajectory, map and feedback settings.
        tick_s: the integration step (s).
    """

    def __init__(self, trajectory: Trajectory, tick_s: float = 1.0 / NOMINAL_TICK_HZ) -> None:
        self.trajectory = trajectory
        self._law = FeedbackLaw(trajectory.feedback, tick_s)
        self._delay = trajectory.feedback.delay_ticks
        self._errors: deque[tuple[FloatArray, FloatArray]] = deque()  # measured, not yet used (the delay)
        self._correction = np.zeros(N_JOINTS)
        self.correction_rad_s = np.zeros((len(trajectory), N_JOINTS))
        """The velocity correction applied at each tick so far, shape (N, 2) (rad/s)."""
        self.ticks_done = 0
        """Ticks decided so far."""

    def __len__(self) -> int:
        return len(self.trajectory)

    def next_activation(self, previous: TickSample | None) -> FloatArray:
        """The activation of the next tick, shape (3,), within the map's activation range.

        Args:
            previous: the sample of this trajectory's previous tick; None before its first tick.

        Raises:
            IndexError: every tick was decided already.
            ValueError: a sample with non-finite angles or velocities.
        """
        k = self.ticks_done
        desired = self.trajectory.desired
        if k >= len(desired):
            raise IndexError(f"the trajectory has {len(desired)} ticks, all decided")
        if previous is not None and k > 0:
            q, dq = previous.position_rad, previous.velocity_rad_s
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
                raise ValueError(f"measured joint state is not finite: {q.tolist()}, {dq.tolist()}")
            self._errors.append((desired[k - 1, :N_JOINTS] - q, desired[k - 1, N_JOINTS : 2 * N_JOINTS] - dq))
            if len(self._errors) > self._delay:
                self._correction = self._law.update(*self._errors.popleft())
        x = desired[(k + self.trajectory.lead_ticks) % len(desired)].copy()
        x[N_JOINTS : 2 * N_JOINTS] += self._correction
        self.correction_rad_s[k] = self._correction
        self.ticks_done = k + 1
        activation: FloatArray = self.trajectory.inverse_map.predict(x[np.newaxis])[0]
        return activation


def check_trajectory(desired: ArrayLike) -> FloatArray:
    """Desired kinematics as a float array (N, 6), N >= 1, finite.

    Raises:
        ValueError: another shape or non-finite values.
    """
    d = np.array(desired, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != N_INPUTS or len(d) == 0:
        raise ValueError(f"desired kinematics: expected shape (N >= 1, {N_INPUTS}), got {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ValueError("desired kinematics: non-finite values")
    return d
