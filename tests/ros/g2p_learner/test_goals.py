"""The learner's goals, checked before they are accepted: each refusal's reason names what is wrong."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from g2p.learning.learner import Learner
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p_interfaces.action import Attempt, Babble, Learn, Track
from g2p_learner.config import LearnerNodeConfig
from g2p_learner.goals import GoalRejected, check_attempt, check_babble, check_learn, check_track
from tests.learning.test_attempt import known_map

TREADMILL = LimitCycleConfig()  # features in [0.15, 1]
AIR = LearnerNodeConfig().air_cycle  # features in [0.2, 0.8]
GOOD = [0.5] * 10


def fitted() -> Learner:
    learner = Learner()
    learner.inverse_map = known_map()
    return learner


def test_a_rejection_is_a_value_error() -> None:
    assert issubclass(GoalRejected, ValueError)


@pytest.mark.parametrize("duration_s", [0.0, 0.5, 300.0])
def test_a_babble_of_a_finite_non_negative_duration_is_accepted(duration_s: float) -> None:
    check_babble(Babble.Goal(duration_s=duration_s))


@pytest.mark.parametrize("duration_s", [-1.0, math.nan, math.inf])
def test_a_babble_of_a_negative_or_non_finite_duration_is_refused(duration_s: float) -> None:
    with pytest.raises(GoalRejected, match=f"duration_s must be finite and >= 0, got {duration_s}"):
        check_babble(Babble.Goal(duration_s=duration_s))


def test_an_attempt_within_the_treadmill_bounds_with_a_map_is_accepted() -> None:
    check_attempt(Attempt.Goal(features=GOOD), TREADMILL, fitted())
    check_attempt(Attempt.Goal(features=[0.15] * 5 + [1.0] * 5), TREADMILL, fitted())  # the bounds


@pytest.mark.parametrize(
    ("features", "reason"),
    [
        ([0.5] * 9, r"features: expected shape \(10,\), got \(9,\)"),
        ([], r"features: expected shape \(10,\), got \(0,\)"),
        ([0.5, 0.5, 1.2, *[0.5] * 7], r"features\[2\] = 1.2 is outside \[0.15, 1.0\]"),
        ([*[0.5] * 9, 0.1], r"features\[9\] = 0.1 is outside"),
        ([0.5, math.nan, *[0.5] * 8], r"features\[1\] = nan is not finite"),
    ],
)
def test_an_attempt_with_bad_features_is_refused_naming_the_feature(
    features: list[float], reason: str
) -> None:
    with pytest.raises(GoalRejected, match=reason):
        check_attempt(Attempt.Goal(features=features), TREADMILL, fitted())
    with pytest.raises(GoalRejected, match=reason):  # the features are checked first
        check_attempt(Attempt.Goal(features=features), TREADMILL, Learner())


def test_an_attempt_before_any_map_is_refused() -> None:
    with pytest.raises(GoalRejected, match="no inverse map yet: babble first"):
        check_attempt(Attempt.Goal(features=GOOD), TREADMILL, Learner())


def test_a_learn_goal_with_defaults_or_existing_bags_is_accepted(tmp_path: Path) -> None:
    check_learn(Learn.Goal())
    check_learn(Learn.Goal(babbling_duration_s=60.0, threshold_mm=100.0, dataset_bag=str(tmp_path)))
    check_learn(Learn.Goal(resume_bag=str(tmp_path)))


@pytest.mark.parametrize("name", ["babbling_duration_s", "threshold_mm"])
@pytest.mark.parametrize("value", [-0.5, math.nan, -math.inf])
def test_a_learn_goal_with_a_bad_number_is_refused_naming_it(name: str, value: float) -> None:
    with pytest.raises(GoalRejected, match=f"{name} must be finite and >= 0, got {value}"):
        check_learn(Learn.Goal(**{name: value}))


@pytest.mark.parametrize("name", ["dataset_bag", "resume_bag"])
def test_a_learn_goal_whose_bag_is_not_a_directory_is_refused_naming_it(name: str, tmp_path: Path) -> None:
    missing = tmp_path / "no_such_bag"
    a_file = tmp_path / "file.mcap"
    a_file.write_bytes(b"")
    for bag in (missing, a_file):
        with pytest.raises(GoalRejected, match=f"{name} '{bag}' is not a directory"):
            check_learn(Learn.Goal(**{name: str(bag)}))


def test_a_learn_goal_with_two_bags_is_refused(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    with pytest.raises(GoalRejected, match="give dataset_bag or resume_bag, not both"):
        check_learn(Learn.Goal(dataset_bag=str(tmp_path / "a"), resume_bag=str(tmp_path / "b")))


@pytest.mark.parametrize("mode", [Track.Goal.MODE_REFINE_ONE, Track.Goal.MODE_GENERALIZATION])
def test_a_track_goal_in_either_mode_with_or_without_features_is_accepted(mode: int) -> None:
    check_track(Track.Goal(mode=mode), AIR, fitted())
    check_track(Track.Goal(mode=mode, features=[0.2] * 5 + [0.8] * 5), AIR, fitted())


def test_a_track_goal_is_refused_for_an_unknown_mode_features_outside_the_air_bounds_or_no_map() -> None:
    with pytest.raises(GoalRejected, match="mode must be 0 or 1, got 2"):
        check_track(Track.Goal(mode=2), AIR, fitted())
    # 0.9 is a treadmill feature, not a free-movement one.
    with pytest.raises(GoalRejected, match=r"features\[4\] = 0.9 is outside \[0.2, 0.8\]"):
        check_track(Track.Goal(features=[0.5] * 4 + [0.9] + [0.5] * 5), AIR, fitted())
    with pytest.raises(GoalRejected, match="no inverse map yet"):
        check_track(Track.Goal(), AIR, Learner())


def test_the_air_bounds_come_from_the_nodes_settings() -> None:
    air = LearnerNodeConfig(air_feature_low=0.3, air_feature_high=0.6).air_cycle
    assert (air.feature_low, air.feature_high) == (0.3, 0.6)
    check_track(Track.Goal(features=np.full(10, 0.6)), air, fitted())
    with pytest.raises(GoalRejected, match=r"features\[0\] = 0.25 is outside \[0.3, 0.6\]"):
        check_track(Track.Goal(features=np.full(10, 0.25)), air, fitted())
