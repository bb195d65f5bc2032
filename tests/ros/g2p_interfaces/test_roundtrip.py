"""Every g2p_interfaces type round-trips through rclpy's CDR serialization with all fields set."""

from __future__ import annotations

import array

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header

from g2p_interfaces.action import Attempt, Babble, Learn, RunActivations, RunTrajectory, Track
from g2p_interfaces.msg import (
    InverseMapWeights,
    MotorActivation,
    MotorPower,
    NamedArray,
    RigSamples,
    Treadmill,
)

HEADER = Header(stamp=Time(sec=12, nanosec=345_678_901), frame_id="leg")


def _samples(n: int) -> RigSamples:
    rng = np.random.default_rng(0)
    return RigSamples(
        stamp_ns=3_000_000_007 + np.arange(n, dtype=np.int64) * 12_820_513,
        applied_activation=rng.uniform(0.15, 1, 3 * n),
        position_rad=rng.normal(size=2 * n),
        velocity_rad_s=rng.normal(size=2 * n),
        belt_displacement_mm=rng.normal(size=n),
        belt_velocity_mm_s=rng.normal(size=n),
        current_a=rng.uniform(0, 2, 3 * n),
        power_w=rng.normal(size=3 * n),
        energy_j=rng.uniform(0, 100, 3 * n),
    )


MESSAGES = [
    MotorActivation(header=HEADER, activation=[0.15, 0.5, 1.0]),
    Treadmill(header=HEADER, displacement_mm=-12.5, velocity_mm_s=3.25),
    MotorPower(
        header=HEADER, current_a=[0.1, 0.2, 0.3], power_w=[1.0, -0.5, 2.0], energy_j=[10.0, 20.0, 30.0]
    ),
    _samples(500),
    RunActivations.Goal(activation=np.linspace(0, 1, 30)),
    RunActivations.Result(samples=_samples(7), message="cancelled"),
    RunActivations.Feedback(ticks_done=5, ticks_total=10),
    RunTrajectory.Goal(
        desired=np.linspace(-1, 1, 6 * 80),
        inverse_map=InverseMapWeights(
            header=HEADER,
            format_version=1,
            arrays=[NamedArray(name="w_out", shape=[3, 2], data=np.linspace(-1, 1, 6))],
        ),
        p_gain_per_s=[10.0, 15.0],
        i_gain_per_s2=[2.0, 6.0],
        velocity_gain=[0.3, 0.0],
        integral_limit_rad_s=1.0,
        correction_limit_rad_s=10.0,
        delay_ticks=4,
        lead_ticks=-3,
    ),
    RunTrajectory.Result(samples=_samples(7), correction_rad_s=np.linspace(-2, 2, 14), message="cancelled"),
    RunTrajectory.Feedback(ticks_done=5, ticks_total=10),
    Babble.Goal(duration_s=300.0),
    Babble.Result(sample_count=23400, validation_rmse=0.05),
    Babble.Feedback(progress=0.5, samples_done=11700),
    Attempt.Goal(features=np.linspace(0.15, 1, 10), cycles=20, skip_refinement=True),
    Attempt.Result(
        reward_mm=88.5, energy_j=120.0, tracking_mse_deg2=83.0, tracking_rmse_rad=0.11, refined=True
    ),
    Attempt.Feedback(stage="refining", ticks_done=1600, ticks_total=1600),
    Learn.Goal(
        dataset_bag="bags/run",
        babbling_duration_s=60.0,
        threshold_mm=64.0,
        max_exploration_attempts=100,
        exploitation_attempts=15,
    ),
    Learn.Result(
        best_features=np.linspace(0.2, 0.9, 10),
        best_reward_mm=188.0,
        crossed_threshold=True,
        exploration_attempts=14,
        exploitation_attempts=15,
        run_id="20261121T120000Z-ab12",
        bag_path="bags/20261121T120000Z-ab12",
    ),
    Learn.Feedback(phase="exploitation", attempt=17, reward_mm=70.0, best_reward_mm=90.0, sigma=0.056),
    Track.Goal(
        mode=Track.Goal.MODE_GENERALIZATION,
        features=[],
        refinements=5,
        train_trajectories=30,
        test_trajectories=30,
    ),
    Track.Result(attempt_mse_deg2=[300.0, 200.0], babbling_map_mse_deg2=[337.0], refined_map_mse_deg2=[83.0]),
    Track.Feedback(stage="testing", index=3, tracking_mse_deg2=90.0),
]


def _equal(a: object, b: object) -> bool:
    """Field-by-field equality that treats numpy arrays and array.array by value."""
    if hasattr(a, "get_fields_and_field_types"):
        return type(a) is type(b) and all(
            _equal(getattr(a, f), getattr(b, f)) for f in a.get_fields_and_field_types()
        )
    if isinstance(a, np.ndarray | array.array | list):
        return np.array_equal(np.asarray(a), np.asarray(b))
    return a == b


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: type(m).__name__)
def test_roundtrip(msg: object) -> None:
    data = serialize_message(msg)
    back = deserialize_message(data, type(msg))
    assert _equal(msg, back)
