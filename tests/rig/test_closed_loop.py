"""Closed-loop G2P (g2p.rig.closed_loop): the feedback law, the tracker's timing, and on the plant."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from g2p.inverse_map import InverseMap
from g2p.learning.attempt import plan_attempt, run_attempt
from g2p.learning.kinematics import recording_pairs
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import AIR_FEATURE_BOUNDS, LimitCycleConfig
from g2p.plant import TickSample
from g2p.rig import PlantRig, RigCancelled
from g2p.rig.closed_loop import (
    ControlMode,
    FeedbackConfig,
    FeedbackLaw,
    Trajectory,
    TrajectoryTracker,
)
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig
from g2p.validation import ConfigError

AIR = MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M)
CYCLE = LimitCycleConfig(feature_low=AIR_FEATURE_BOUNDS[0], feature_high=AIR_FEATURE_BOUNDS[1], n_cycles=4)
ZERO = FeedbackConfig(p_gain_per_s=(0.0, 0.0), i_gain_per_s2=(0.0, 0.0), velocity_gain=(0.0, 0.0))


@pytest.fixture(scope="module")
def air_map() -> InverseMap:
    """A map fitted on a minute of babbling in the air."""
    learner = Learner(LearnerConfig(seed=3))
    learner.babble(PlantRig(MujocoLeg(AIR)), duration_s=60.0)
    return learner.inverse_map


def sample(position: tuple[float, float], velocity: tuple[float, float] = (0.0, 0.0)) -> TickSample:
    z = np.zeros(3)
    return TickSample(0.0, z, np.array(position), np.array(velocity), 0.0, 0.0, z, z, z)


# The feedback law -----------------------------------------------------------------------------------


def test_the_feedback_law_against_a_hand_computed_sequence() -> None:
    cfg = FeedbackConfig(
        p_gain_per_s=(2.0, 3.0),
        i_gain_per_s2=(4.0, 5.0),
        velocity_gain=(0.5, 1.0),
        integral_limit_rad_s=0.05,
        correction_limit_rad_s=1.0,
    )
    law = FeedbackLaw(cfg, tick_s=0.1)
    # tick 1: e = (0.1, -0.2), ev = (1, 0): integral (0.01, -0.02);
    #   c = (2*0.1 + 4*0.01 + 0.5*1, 3*-0.2 + 5*-0.02 + 0) = (0.74, -0.70)
    np.testing.assert_allclose(law.update(np.array([0.1, -0.2]), np.array([1.0, 0.0])), [0.74, -0.70])
    # tick 2: e = (0.3, -0.2), ev = (0, -0.2): integral (0.04, -0.04);
    #   c = (0.6 + 0.16, -0.6 - 0.2 - 0.2) = (0.76, -1.00)
    np.testing.assert_allclose(law.update(np.array([0.3, -0.2]), np.array([0.0, -0.2])), [0.76, -1.0])
    # tick 3: e = (0.3, -0.3): integral (0.07, -0.07) bounded to (0.05, -0.05);
    #   c = (0.6 + 0.2, -0.9 - 0.25) = (0.80, -1.15) bounded to (0.80, -1.00)
    np.testing.assert_allclose(law.update(np.array([0.3, -0.3]), np.zeros(2)), [0.80, -1.0])
    np.testing.assert_allclose(law.integral, [0.05, -0.05])


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("p_gain_per_s", (10.0,)),
        ("p_gain_per_s", (-1.0, 1.0)),
        ("i_gain_per_s2", (1.0, 1e3)),
        ("velocity_gain", (float("nan"), 1.0)),
        ("integral_limit_rad_s", 0.0),
        ("correction_limit_rad_s", float("inf")),
        ("delay_ticks", -1),
        ("delay_ticks", 1.5),
        ("delay_ticks", 1000),
    ],
)
def test_feedback_settings_out_of_range_are_rejected_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ConfigError, match=field):
        FeedbackConfig(**{field: value})  # type: ignore[arg-type]


def test_a_trajectory_is_checked(air_map: InverseMap) -> None:
    good = np.zeros((10, 6))
    for desired, match in ((np.zeros((10, 5)), "shape"), (np.full((10, 6), np.nan), "non-finite")):
        with pytest.raises(ValueError, match=match):
            Trajectory(desired, air_map, ZERO)
    with pytest.raises(ValueError, match="lead_ticks"):
        Trajectory(good, air_map, ZERO, lead_ticks=10)
    with pytest.raises(ValueError, match="not fitted"):
        Trajectory(good, InverseMap(), ZERO)


# The tracker's timing -------------------------------------------------------------------------------


@pytest.mark.parametrize("delay", [0, 2])
def test_the_correction_of_tick_k_uses_the_error_of_tick_k_minus_1_minus_delay(
    air_map: InverseMap, delay: int
) -> None:
    p = np.array([10.0, 15.0])
    cfg = replace(ZERO, p_gain_per_s=(10.0, 15.0), delay_ticks=delay)
    desired = np.zeros((8, 6))
    tracker = TrajectoryTracker(Trajectory(desired, air_map, cfg))
    measured = [(0.01 * k, -0.02 * k) for k in range(8)]  # the angles at the end of tick k
    previous = None
    for k in range(8):
        tracker.next_activation(previous)
        previous = sample(measured[k])
    expected = np.zeros((8, 2))
    for k in range(1 + delay, 8):
        expected[k] = p * (0.0 - np.array(measured[k - 1 - delay]))
    np.testing.assert_allclose(tracker.correction_rad_s, expected)
    with pytest.raises(IndexError):
        tracker.next_activation(previous)


def test_with_zero_gains_the_tracker_gives_the_open_loop_activations_bit_for_bit(air_map: InverseMap) -> None:
    features = np.full(CYCLE.n_spokes, 0.5)
    desired, open_loop = plan_attempt(features, air_map, CYCLE, lead_ticks=3)
    tracker = TrajectoryTracker(Trajectory(desired, air_map, ZERO, lead_ticks=3))
    rows = np.array([tracker.next_activation(sample((0.3, -0.3))) for _ in range(len(desired))])
    np.testing.assert_array_equal(rows, open_loop)
    assert not tracker.correction_rad_s.any()


# On the plant ---------------------------------------------------------------------------------------


def test_with_zero_gains_the_plant_plays_exactly_the_open_loop_attempt(air_map: InverseMap) -> None:
    features = np.linspace(0.3, 0.7, CYCLE.n_spokes)
    # Both through the rig's envelope, which changes some of these ticks (the ramp from rest): an open-loop
    # attempt's `activations` are the commands, a closed-loop one's what the rig applied, as played.
    open_loop = run_attempt(PlantRig(MujocoLeg(AIR)), air_map, features, CYCLE, 2)
    closed = run_attempt(PlantRig(MujocoLeg(AIR)), air_map, features, CYCLE, 2, feedback=ZERO)
    assert open_loop.control is ControlMode.OPEN and closed.control is ControlMode.CLOSED
    assert np.any(open_loop.recording.activation != open_loop.activations)  # the envelope acted
    for name in ("activation", "position_rad", "velocity_rad_s", "belt_mm", "energy_j"):
        np.testing.assert_array_equal(getattr(closed.recording, name), getattr(open_loop.recording, name))
    np.testing.assert_array_equal(closed.activations, open_loop.recording.activation)
    assert closed.correction_rad_s is not None and not closed.correction_rad_s.any()
    assert closed.tracking == open_loop.tracking


def test_a_step_in_the_desired_angle_is_corrected_on_the_plant(air_map: InverseMap) -> None:
    """Hold a posture, then step the hip by 0.3 rad: open loop the map misses it (by 0.05 and 0.2 rad on
    this map, the sum depending on the CPU the map was fitted on); the integral of the error drives both
    joints onto it, within 6 s of the step."""
    n = 8 * 78
    desired = np.zeros((n, 6))
    desired[:, 1] = -0.2
    desired[n // 4 :, 0] = 0.3
    cfg = FeedbackConfig(p_gain_per_s=(0.0, 0.0), i_gain_per_s2=(6.0, 6.0), velocity_gain=(0.0, 0.0))
    errors = {}
    for name, feedback in (("open", ZERO), ("closed", cfg)):
        rig = PlantRig(MujocoLeg(AIR))
        rig.reset()
        tracked = rig.play_trajectory(Trajectory(desired, air_map, feedback))
        last_second = desired[-78:, :2] - tracked.recording.position_rad[-78:]
        errors[name] = np.abs(last_second).mean(axis=0)
    assert errors["open"].sum() > 0.1, errors  # the premise: open loop misses the posture
    assert np.all(errors["closed"] < 0.05) and errors["closed"].sum() < errors["open"].sum() / 3, errors


def test_a_closed_loop_attempt_gives_the_learner_what_was_played(air_map: InverseMap) -> None:
    cfg = replace(LearnerConfig(seed=3), control=ControlMode.CLOSED, feedback=FeedbackConfig(delay_ticks=2))
    learner = Learner(cfg)
    learner.inverse_map = InverseMap.from_arrays(air_map.to_arrays())
    outcome = run_attempt(
        PlantRig(MujocoLeg(AIR)), learner.inverse_map, np.full(10, 0.5), CYCLE, 2, feedback=cfg.feedback
    )
    assert outcome.correction_rad_s is not None and outcome.correction_rad_s.any()
    np.testing.assert_array_equal(outcome.activations, outcome.recording.activation)
    # Refinement pairs the activations the rig decided with the kinematics it measured.
    learner.dataset.add("babbling", recording_pairs(outcome.recording, cfg.preprocess))
    learner.refine_with(outcome.recording, "attempt 1")
    expected = recording_pairs(outcome.recording, cfg.preprocess, cfg.preprocess.transition_fraction)
    np.testing.assert_array_equal(learner.dataset.segments[-1][1].activation, expected.activation)


def test_the_learner_plays_its_attempts_in_its_control_mode(air_map: InverseMap) -> None:
    learner = Learner(LearnerConfig(seed=3, control="closed"))  # type: ignore[arg-type]
    learner.inverse_map = InverseMap.from_arrays(air_map.to_arrays())
    outcome, fit = learner.attempt(PlantRig(MujocoLeg(AIR)), np.full(10, 0.5), CYCLE, refine=False)
    assert outcome.control is ControlMode.CLOSED and fit is None
    with pytest.raises(ConfigError, match="control"):
        LearnerConfig(control="sideways")  # type: ignore[arg-type]


def test_a_cancelled_trajectory_leaves_the_plant_at_baseline(air_map: InverseMap) -> None:
    plant = MujocoLeg(AIR)
    rig = PlantRig(plant, progress_every=10)
    cancel = threading.Event()
    desired = np.zeros((200, 6))
    with pytest.raises(RigCancelled, match="after 10 of 200"):
        rig.play_trajectory(
            Trajectory(desired, air_map, FeedbackConfig()), lambda done, _n: cancel.set(), cancel
        )
    last = plant.step(np.zeros(3))
    np.testing.assert_allclose(last.activation, AIR.baseline_activation)


def test_the_closed_loop_runs_without_torch(air_map: InverseMap, tmp_path: Path) -> None:
    """The rig (a Raspberry Pi) has no torch: the tracker and the map's forward pass need only numpy."""
    air_map.save(tmp_path / "map.npz")
    code = f"""
import sys
sys.modules["torch"] = None  # any import of torch fails
import numpy as np
from g2p.rig.closed_loop import FeedbackConfig, Trajectory, TrajectoryTracker
from g2p.inverse_map import InverseMap
tracker = TrajectoryTracker(Trajectory(np.zeros((5, 6)), InverseMap.load({str(tmp_path / "map.npz")!r}),
                                       FeedbackConfig()))
print([tracker.next_activation(None).shape for _ in range(5)])
"""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[(3,), (3,), (3,), (3,), (3,)]"
