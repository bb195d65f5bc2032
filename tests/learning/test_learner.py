"""The learner's dataset: what each refinement trains on, all attempts (the paper's) or the recent ones."""

from __future__ import annotations

import numpy as np
import pytest

from g2p.learning.kinematics import TrainingPairs
from g2p.learning.learner import BABBLING, Dataset, Learner, LearnerConfig
from g2p.validation import ConfigError
from tests.learning.test_checkpoint import synthetic_recording


def pairs(value: float, n: int) -> TrainingPairs:
    """n pairs whose every entry is `value`, to tell segments apart."""
    return TrainingPairs(np.zeros(n), np.full((n, 6), value), np.full((n, 3), value))


def test_recent_attempts_are_the_babbling_and_the_last_attempts() -> None:
    data = Dataset()
    data.add(BABBLING, pairs(0.0, 5))
    data.add(BABBLING, pairs(0.5, 4))
    for k in range(1, 5):
        data.add(f"attempt {k}", pairs(float(k), 3))
    kinematics, activation = data.arrays()
    assert len(kinematics) == len(data) == 5 + 4 + 4 * 3
    assert kinematics[data.recent(2), 0].tolist() == [0.0] * 5 + [0.5] * 4 + [3.0] * 3 + [4.0] * 3
    np.testing.assert_array_equal(activation[:, 0], kinematics[:, 0])
    assert data.recent(10).all() and data.recent(0).all()


@pytest.mark.parametrize("recent", [0, 1])
def test_each_refinement_trains_on_the_babbling_and_the_configured_attempts(recent: int) -> None:
    rng = np.random.default_rng(3)
    learner = Learner(LearnerConfig(seed=1, refine_recent_attempts=recent))
    learner.fit_babbling([synthetic_recording(rng, 10.0, 0.0)])
    babbling = len(learner.dataset)
    sizes = []
    for k in range(3):
        before = len(learner.dataset)
        report = learner.refine_with(synthetic_recording(rng, 4.0, 20.0 + 5.0 * k), f"attempt {k + 1}")
        sizes.append(len(learner.dataset) - before)
        trained = report.n_train + report.n_validation
        assert trained == (babbling + sizes[-1] if recent else len(learner.dataset))
    assert len(learner.dataset) == babbling + sum(sizes)  # every attempt's data is kept either way


def test_a_negative_number_of_recent_attempts_is_refused() -> None:
    with pytest.raises(ConfigError, match="refine_recent_attempts"):
        LearnerConfig(refine_recent_attempts=-1)
