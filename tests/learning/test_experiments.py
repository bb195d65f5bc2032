"""The paper's free-movement experiments stepped one attempt at a time, on the MuJoCo leg in the air."""

from __future__ import annotations

import numpy as np

from g2p.learning.babbling import BabblingConfig
from g2p.learning.experiments import (
    Generalization,
    TrajectoryRefinement,
    generalization,
    random_features,
    refine_one_trajectory,
)
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.seeds import seed_streams
from g2p.rig import PlantRig
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig

CYCLE = LimitCycleConfig.in_air(n_cycles=2)


def babbled(seed: int = 0) -> tuple[Learner, PlantRig]:
    learner = Learner(LearnerConfig(seed=seed, babbling=BabblingConfig(duration_s=20.0)))
    rig = PlantRig(MujocoLeg(MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M)))
    learner.babble(rig)
    return learner, rig


def test_a_trajectory_is_attempted_once_then_once_after_each_refinement() -> None:
    learner, rig = babbled()
    features = random_features(seed_streams(0).tracking, CYCLE, 1)[0]
    experiment = TrajectoryRefinement(learner, features, CYCLE, refinements=2)
    reports = []
    while not experiment.finished:
        reports.append(experiment.next_attempt(rig))
    assert [r.number for r in reports] == [1, 2, 3]
    assert [r.fit is not None for r in reports] == [True, True, False]  # no refinement after the last
    assert learner.refinements == 2
    assert all(r.stage == "training" and np.array_equal(r.features, features) for r in reports)
    # Stepped or run to the end: the same run, bit for bit.
    again, rig2 = babbled()
    outcomes = refine_one_trajectory(again, rig2, features, CYCLE, refinements=2)
    assert [o.tracking.mse_deg2 for o in outcomes] == [r.tracking.mse_deg2 for r in reports]


def test_generalization_trains_then_tests_both_maps_on_unseen_trajectories() -> None:
    learner, rig = babbled()
    rng = seed_streams(0).tracking
    train, test = random_features(rng, CYCLE, 2), random_features(rng, CYCLE, 2)
    experiment = Generalization(learner, CYCLE, train, test)
    stages = []
    while not experiment.finished:
        report = experiment.next_attempt(rig)
        stages.append((report.stage, report.number, report.babbling_map, report.fit is not None))
        if report.stage == "testing":
            assert report.outcome is None
    assert stages == [
        ("training", 1, False, True),
        ("training", 2, False, True),
        ("testing", 1, True, False),  # every test trajectory with the babbling-only map first
        ("testing", 2, True, False),
        ("testing", 1, False, False),
        ("testing", 2, False, False),
    ]
    assert learner.refinements == 2  # testing never refines
    stepped = experiment.result()
    assert len(stepped.babbling_map) == len(stepped.refined_map) == 2
    again, rig2 = babbled()
    assert generalization(again, rig2, CYCLE, train, test) == stepped
