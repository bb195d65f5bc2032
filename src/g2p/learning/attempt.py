"""One attempt: a limit cycle through the inverse map, played on a rig, and how well it did.

features (10,) -> target kinematics (N, 6) -> inverse map -> activations (N, 3) clipped to
[baseline, 1] -> played on the rig from rest -> reward (belt travel, mm), energy (J) and tracking error.
In closed loop (g2p.rig.closed_loop) the rig evaluates the map itself every tick, on the target kinematics
corrected by the measured joint state.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from g2p.inverse_map import InverseMap
from g2p.learning.limit_cycle import LimitCycleConfig, attempt_kinematics
from g2p.plant import Recording
from g2p.rig import ProgressCallback, Rig
from g2p.rig.closed_loop import ControlMode, FeedbackConfig, Trajectory

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TrackingError:
    """Joint-angle tracking error over the second half of an attempt.

    Attributes:
        mse_deg2: mean squared error per joint, summed over the two joints (deg^2): the paper's measure.
        rmse_rad: root-mean-square error over both joints together (rad).
    """

    mse_deg2: float
    rmse_rad: float


@dataclass(frozen=True)
class AttemptOutcome:
    """What one attempt asked for, what the rig did, and its scores.

    Attributes:
        features: the limit cycle's features, shape (10,).
        desired: target kinematics, one row per tick, shape (N, 6) (rad, rad/s, rad/s^2).
        activations: activations commanded (open loop) or those the rig applied (closed loop: the tracker's
            decisions through the rig's envelope), shape (N, 3).
        recording: the N ticks the rig recorded.
        reward_mm: belt travel during the attempt (mm, + backward = forward locomotion).
        energy_j: electrical energy the motors drew during the attempt (J).
        tracking: tracking error over the second half.
        control: open or closed loop.
        correction_rad_s: closed loop: the velocity correction of each tick, shape (N, 2) (rad/s); None in
            open loop.
    """

    features: FloatArray
    desired: FloatArray
    activations: FloatArray
    recording: Recording
    reward_mm: float
    energy_j: float
    tracking: TrackingError
    control: ControlMode = ControlMode.OPEN
    correction_rad_s: FloatArray | None = None


def plan_attempt(
    features: ArrayLike, inverse_map: InverseMap, cycle: LimitCycleConfig, lead_ticks: int = 0
) -> tuple[FloatArray, FloatArray]:
    """Target kinematics of an attempt and the activations the inverse map predicts for them.

    Args:
        features: spoke lengths, shape (n_spokes,), within the cycle's feature bounds.
        inverse_map: a fitted map.
        cycle: the limit-cycle parameters (shape, timing, cycles per attempt).
        lead_ticks: ticks by which each activation is played ahead of the kinematics it is for (the
            map's command lead, PreprocessConfig.command_lead_ticks); the cycle is periodic, so this
            rolls the sequence.

    Returns:
        (desired kinematics (N, 6), activations (N, 3) in [activation_low, activation_high]), N = cycles x
        ticks per cycle.

    Raises:
        ValueError: invalid features (the message names the index and value).
    """
    desired = attempt_kinematics(features, cycle)
    return desired, np.roll(inverse_map.predict(desired), -lead_ticks, axis=0)


def tracking_error(desired_rad: ArrayLike, actual_rad: ArrayLike) -> TrackingError:
    """Tracking error over the second half of an attempt, tick by tick.

    Args:
        desired_rad: target joint angles, shape (N, 2) (rad).
        actual_rad: measured joint angles at the same ticks, shape (N, 2) (rad).
    """
    d = np.asarray(desired_rad, dtype=np.float64)
    a = np.asarray(actual_rad, dtype=np.float64)
    if d.shape != a.shape or d.ndim != 2 or d.shape[0] < 2:
        raise ValueError(
            f"desired and actual angles must both have shape (N >= 2, 2), got {d.shape}, {a.shape}"
        )
    err = (a - d)[len(d) // 2 :]
    return TrackingError(
        mse_deg2=float(np.sum(np.mean(np.degrees(err) ** 2, axis=0))),
        rmse_rad=float(np.sqrt(np.mean(err**2))),
    )


def run_attempt(
    rig: Rig,
    inverse_map: InverseMap,
    features: ArrayLike,
    cycle: LimitCycleConfig,
    lead_ticks: int = 0,
    progress: ProgressCallback | None = None,
    cancel: threading.Event | None = None,
    feedback: FeedbackConfig | None = None,
) -> AttemptOutcome:
    """Reset the rig to rest and play one attempt on it, open loop or (given `feedback`) closed loop.

    Args:
        rig: the rig (in-process plant or ROS rig contract).
        inverse_map: a fitted map.
        features: spoke lengths, shape (n_spokes,), within the cycle's feature bounds.
        cycle: the limit-cycle parameters.
        lead_ticks: the map's command lead (see `plan_attempt`).
        progress: called with (ticks done, ticks total).
        cancel: when set, the rig drops to baseline and RigCancelled is raised.
        feedback: None plays the map's activations open loop (the paper's G2P); otherwise the rig plays
            the trajectory in closed loop with these settings.

    Raises:
        ValueError: invalid features.
        RigError: the rig failed (RigCancelled when cancelled).
    """
    f = np.array(features, dtype=np.float64)
    correction = None
    if feedback is None:
        desired, activations = plan_attempt(f, inverse_map, cycle, lead_ticks)
        rig.reset()
        recording = rig.play(activations, progress, cancel)
    else:
        desired = attempt_kinematics(f, cycle)
        rig.reset()
        trajectory = Trajectory(desired, inverse_map, feedback, lead_ticks)
        tracked = rig.play_trajectory(trajectory, progress, cancel)
        recording, correction = tracked.recording, tracked.correction_rad_s
        activations = recording.activation
    return AttemptOutcome(
        features=f,
        desired=desired,
        activations=activations,
        recording=recording,
        reward_mm=recording.belt_travel_mm,
        energy_j=recording.energy_used_j,
        tracking=tracking_error(desired[:, :2], recording.position_rad),
        control=ControlMode.OPEN if feedback is None else ControlMode.CLOSED,
        correction_rad_s=correction,
    )
