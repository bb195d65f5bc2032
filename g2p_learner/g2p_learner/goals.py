"""The learner's goals, checked before they are accepted.

A rejected goal's reason is logged (ROS actions carry none), and nothing runs.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from g2p.learning.learner import Learner
from g2p.learning.limit_cycle import LimitCycleConfig, check_features
from g2p_interfaces.action import Attempt, Babble, Learn, Track


class GoalRejected(ValueError):
    """A goal is invalid; the message says why."""


def check_babble(goal: Babble.Goal) -> None:
    """Raises GoalRejected: a negative or non-finite duration."""
    _require(
        math.isfinite(goal.duration_s) and goal.duration_s >= 0,
        f"duration_s must be finite and >= 0, got {goal.duration_s}",
    )


def check_attempt(goal: Attempt.Goal, cycle: LimitCycleConfig, learner: Learner) -> None:
    """Raises GoalRejected: features outside the cycle's bounds, or no map to attempt with."""
    _check_features(goal.features, cycle)
    _require(learner.inverse_map.is_fitted, "no inverse map yet: babble first")


def check_learn(goal: Learn.Goal) -> None:
    """Raises GoalRejected: a negative or non-finite number, a bag that is not a directory, or two bags."""
    for name in ("babbling_duration_s", "threshold_mm"):
        value = getattr(goal, name)
        _require(math.isfinite(value) and value >= 0, f"{name} must be finite and >= 0, got {value}")
    for name in ("dataset_bag", "resume_bag"):
        bag = getattr(goal, name)
        _require(not bag or Path(bag).is_dir(), f"{name} {bag!r} is not a directory")
    _require(not (goal.dataset_bag and goal.resume_bag), "give dataset_bag or resume_bag, not both")


def check_track(goal: Track.Goal, air_cycle: LimitCycleConfig, learner: Learner) -> None:
    """Raises GoalRejected: an unknown mode, features outside the air bounds, or no map yet."""
    _require(
        goal.mode in (Track.Goal.MODE_REFINE_ONE, Track.Goal.MODE_GENERALIZATION),
        f"mode must be {Track.Goal.MODE_REFINE_ONE} or {Track.Goal.MODE_GENERALIZATION}, got {goal.mode}",
    )
    if len(goal.features):
        _check_features(goal.features, air_cycle)
    _require(learner.inverse_map.is_fitted, "no inverse map yet: babble first")


def _require(condition: bool, reason: str) -> None:
    if not condition:
        raise GoalRejected(reason)


def _check_features(features: object, cycle: LimitCycleConfig) -> None:
    try:
        check_features(np.asarray(features, dtype=np.float64), cycle)
    except ValueError as err:
        raise GoalRejected(str(err)) from err
