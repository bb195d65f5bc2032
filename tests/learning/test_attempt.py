"""One attempt: the tracking error, the plan (kinematics and the map's activations), and playing it on a rig.

The rig is an in-process one over a tiny plant that is the exact inverse of a hand-written map: it turns
its joints to the angles whose activations the map predicts, `delay` ticks after it is given them. So the
map's command lead, played right, tracks perfectly; the belt and the energy follow M2's activation alone.
"""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from g2p.inverse_map import InverseMap
from g2p.learning.attempt import AttemptOutcome, TrackingError, plan_attempt, run_attempt, tracking_error
from g2p.learning.limit_cycle import LimitCycleConfig, attempt_kinematics
from g2p.plant import NOMINAL_TICK_HZ, TickSample
from g2p.rig import PlantRig, RigCancelled
from g2p.rig.closed_loop import ControlMode, FeedbackConfig
from g2p.rig.envelope import EnvelopeConfig
from g2p.rig.tick_loop import TickLoopConfig
from g2p.safety import BASELINE_ACTIVATION, check_activation

# The map: M0 = 0.5 + 0.2 tanh(q_prox), M1 = 0.5 + 0.2 tanh(q_dist + 0.6), M2 = 0.3, whatever the velocities
# and accelerations.
M2 = 0.3
BELT_MM_PER_TICK = 4.0 * M2  # the plant's belt moves 4 mm per unit of M2 each tick
ENERGY_J_PER_TICK = M2  # and M2 draws its activation in J each tick
# A short attempt: 10 spokes x 2 ticks x 2 cycles = 40 ticks.
CYCLE = LimitCycleConfig(samples_per_segment=2, n_cycles=2)
N = 40
FEATURES = np.linspace(0.3, 0.9, 10)
# The tick loop's plumbing only: no soft joint limits, no ramp (the thermal budget stays far off).
UNLIMITED = TickLoopConfig(envelope=EnvelopeConfig(soft_limits=False, max_step=1.0))


def known_map() -> InverseMap:
    """The map above, as a 2-unit network (no training)."""
    return InverseMap.from_arrays(
        {
            "format_version": np.array([1.0]),
            "w_hidden": np.array([[1.0, 0, 0, 0, 0, 0], [0, 1.0, 0, 0, 0, 0]]),
            "b_hidden": np.zeros(2),
            "w_out": np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]),
            "b_out": np.zeros(3),
            "x_offset": np.array([0.0, -0.6, 0.0, 0.0, 0.0, 0.0]),
            "x_scale": np.ones(6),
            "y_offset": np.array([0.5, 0.5, M2]),
            "y_scale": np.full(3, 0.2),
            "activation_range": np.array([BASELINE_ACTIVATION, 1.0]),
        },
        source="known map",
    )


def map_by_hand(desired: np.ndarray) -> np.ndarray:
    """The map's activations for kinematics (N, 6), computed from its formula."""
    q = desired[:, :2]
    return np.column_stack(
        [0.5 + 0.2 * np.tanh(q[:, 0]), 0.5 + 0.2 * np.tanh(q[:, 1] + 0.6), np.full(len(q), M2)]
    )


class InverseMapPlant:
    """Turns its joints to the angles the map gives the activations of `delay` ticks ago (0 before).

    Angles q_prox = atanh((M0 - 0.5) / 0.2), q_dist = atanh((M1 - 0.5) / 0.2) - 0.6, the argument clipped to
    +-0.9 for activations the map never gives (babbling). Each tick the belt moves 4 M2 mm and M2 draws
    M2 J; belt and energy count from creation.
    """

    tick_hz = NOMINAL_TICK_HZ

    def __init__(self, delay: int = 0) -> None:
        self.delay = delay
        self.ticks = 0
        self.resets = 0
        self.belt_mm = 0.0
        self.energy_j = np.zeros(3)
        self._given: list[np.ndarray] = []

    def _sample(self, a: np.ndarray, position: np.ndarray) -> TickSample:
        power = np.array([0.0, 0.0, a[2] * self.tick_hz])
        return TickSample(
            self.ticks / self.tick_hz,
            a,
            position,
            np.zeros(2),
            self.belt_mm,
            4.0 * a[2] * self.tick_hz,
            power / 12.0,
            power,
            self.energy_j.copy(),
        )

    def reset(self) -> TickSample:
        self.resets += 1
        self._given = []
        return self._sample(np.full(3, BASELINE_ACTIVATION), np.zeros(2))

    def step(self, activation: np.ndarray) -> TickSample:
        a = check_activation(activation)
        self.ticks += 1
        self._given.append(a)
        position = np.zeros(2)
        if len(self._given) > self.delay:
            past = self._given[-1 - self.delay]
            u = np.clip((past[:2] - 0.5) / 0.2, -0.9, 0.9)
            position = np.arctanh(u) + np.array([0.0, -0.6])
        self.belt_mm += 4.0 * a[2]
        self.energy_j = self.energy_j + np.array([0.0, 0.0, a[2]])
        return self._sample(a, position)

    def close(self) -> None:
        pass


# tracking_error --------------------------------------------------------------------------------------------


def test_tracking_error_is_over_the_second_half_summed_per_joint_in_deg2() -> None:
    desired = np.array([[0.1, -0.2], [0.3, 0.4], [0.5, -0.6], [0.7, 0.8]])
    err_deg = np.array([[50.0, -50.0], [40.0, 40.0], [1.0, 2.0], [3.0, -2.0]])  # the first half is ignored
    result = tracking_error(desired, desired + np.radians(err_deg))
    assert isinstance(result, TrackingError)
    # Per joint: (1 + 9) / 2 = 5 and (4 + 4) / 2 = 4 deg^2, summed: 9 deg^2.
    assert result.mse_deg2 == pytest.approx(9.0)
    # Over both joints together: sqrt((1 + 4 + 9 + 4) / 4) = sqrt(4.5) deg.
    assert result.rmse_rad == pytest.approx(math.radians(math.sqrt(4.5)))


def test_tracking_error_of_an_odd_length_starts_at_tick_n_over_2_rounded_down() -> None:
    actual = np.zeros((5, 2))
    actual[1] = [1.0, 1.0]  # before the second half
    actual[2:, 1] = np.radians([3.0, 0.0, 0.0])  # ticks 2, 3, 4
    result = tracking_error(np.zeros((5, 2)), actual)
    assert result.mse_deg2 == pytest.approx(9.0 / 3)
    assert result.rmse_rad == pytest.approx(math.radians(math.sqrt(9.0 / 6)))
    perfect = tracking_error(np.ones((6, 2)), np.ones((6, 2)))
    assert (perfect.mse_deg2, perfect.rmse_rad) == (0.0, 0.0)


@pytest.mark.parametrize(
    ("desired", "actual"),
    [((4, 2), (5, 2)), ((4, 2), (4, 3)), ((1, 2), (1, 2)), ((4,), (4,)), ((2, 2, 2), (2, 2, 2))],
)
def test_tracking_error_refuses_angles_that_are_not_two_matching_n_by_2_arrays(
    desired: tuple[int, ...], actual: tuple[int, ...]
) -> None:
    with pytest.raises(ValueError, match=r"shape \(N >= 2, 2\)"):
        tracking_error(np.zeros(desired), np.zeros(actual))


# plan_attempt ----------------------------------------------------------------------------------------------


def test_the_plan_is_the_cycle_repeated_and_the_maps_activations_for_it() -> None:
    desired, activations = plan_attempt(FEATURES, known_map(), CYCLE)
    assert desired.shape == (N, 6) and activations.shape == (N, 3)
    np.testing.assert_array_equal(desired, attempt_kinematics(FEATURES, CYCLE))
    # Every second tick is a spoke point: centre (0, -0.6) + f_k (-0.6, 0.6) (sin theta_k, cos theta_k).
    theta = 2 * np.pi * np.arange(10) / 10
    points = np.column_stack([-0.6 * FEATURES * np.sin(theta), -0.6 + 0.6 * FEATURES * np.cos(theta)])
    np.testing.assert_allclose(desired[0:20:2, :2], points, atol=1e-12)
    np.testing.assert_allclose(desired[20:, :2], desired[:20, :2], atol=1e-12)  # the second cycle
    np.testing.assert_allclose(activations, map_by_hand(desired), atol=1e-12)


@pytest.mark.parametrize("lead", [1, 3, N + 2])
def test_the_lead_plays_each_activation_lead_ticks_early_rolling_over_the_cycle(lead: int) -> None:
    desired, activations = plan_attempt(FEATURES, known_map(), CYCLE, lead_ticks=lead)
    expected = map_by_hand(desired)
    for k in (0, 5, N - 1):
        np.testing.assert_allclose(activations[k], expected[(k + lead) % N], atol=1e-12)
    _, unled = plan_attempt(FEATURES, known_map(), CYCLE)
    np.testing.assert_array_equal(activations, np.roll(unled, -lead, axis=0))


def test_the_plan_refuses_features_outside_the_bounds_naming_the_index() -> None:
    bad = FEATURES.copy()
    bad[3] = 1.2
    with pytest.raises(ValueError, match=r"features\[3\] = 1.2 is outside \[0.15, 1.0\]"):
        plan_attempt(bad, known_map(), CYCLE)
    with pytest.raises(ValueError, match=r"expected shape \(10,\)"):
        plan_attempt(FEATURES[:9], known_map(), CYCLE)


# run_attempt -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("lead", [0, 3])
def test_an_attempt_scores_the_belt_travel_and_energy_of_its_ticks(lead: int) -> None:
    plant = InverseMapPlant(delay=lead)
    rig = PlantRig(plant, config=UNLIMITED)
    progress: list[tuple[int, int]] = []
    outcome = run_attempt(
        rig, known_map(), FEATURES, CYCLE, lead, progress=lambda d, t: progress.append((d, t))
    )
    assert isinstance(outcome, AttemptOutcome)
    assert plant.resets == 1 and plant.ticks == N  # from rest, one tick per row
    assert outcome.features.shape == (10,) and outcome.desired.shape == (N, 6)
    assert outcome.activations.shape == (N, 3) and len(outcome.recording) == N
    np.testing.assert_array_equal(outcome.recording.activation, outcome.activations)  # nothing limited
    # Belt and energy from the end of the first tick to the end of the last: 39 ticks of M2 = 0.3.
    assert outcome.reward_mm == pytest.approx((N - 1) * BELT_MM_PER_TICK, rel=1e-12)
    assert outcome.energy_j == pytest.approx((N - 1) * ENERGY_J_PER_TICK, rel=1e-12)
    # A plant that lags the map's lead reaches every desired angle: no error over the second half.
    assert outcome.tracking.mse_deg2 < 1e-18 and outcome.tracking.rmse_rad < 1e-10
    assert outcome.control is ControlMode.OPEN and outcome.correction_rad_s is None
    assert progress[-1] == (N, N)


def test_a_lead_the_plant_does_not_lag_shows_as_tracking_error() -> None:
    outcome = run_attempt(
        PlantRig(InverseMapPlant(delay=0), config=UNLIMITED), known_map(), FEATURES, CYCLE, 3
    )
    desired = outcome.desired[:, :2]
    # The plant is at the angles 3 ticks ahead of the desired ones (rolled over the cycle).
    np.testing.assert_allclose(outcome.recording.position_rad, np.roll(desired, -3, axis=0), atol=1e-12)
    expected = tracking_error(desired, np.roll(desired, -3, axis=0))
    assert outcome.tracking.mse_deg2 == pytest.approx(expected.mse_deg2) and expected.mse_deg2 > 1.0


def test_a_second_attempt_scores_the_same_although_the_belt_and_energy_counted_on() -> None:
    plant = InverseMapPlant(delay=3)
    rig = PlantRig(plant, config=UNLIMITED)
    first = run_attempt(rig, known_map(), FEATURES, CYCLE, 3)
    second = run_attempt(rig, known_map(), FEATURES, CYCLE, 3)
    assert plant.resets == 2
    assert second.recording.belt_mm[0] > first.recording.belt_mm[-1]
    assert second.reward_mm == pytest.approx(first.reward_mm, rel=1e-12)
    assert second.energy_j == pytest.approx(first.energy_j, rel=1e-12)
    np.testing.assert_array_equal(second.activations, first.activations)


def test_in_closed_loop_a_map_blind_to_velocity_plays_the_open_loop_activations() -> None:
    # The feedback corrects the velocity fed to the map; this map ignores velocities.
    feedback = FeedbackConfig(p_gain_per_s=(10.0, 15.0), i_gain_per_s2=(2.0, 6.0), velocity_gain=(0.3, 0.3))
    rig = PlantRig(InverseMapPlant(delay=3), config=UNLIMITED)
    closed = run_attempt(rig, known_map(), FEATURES, CYCLE, 3, feedback=feedback)
    _, planned = plan_attempt(FEATURES, known_map(), CYCLE, 3)
    assert closed.control is ControlMode.CLOSED
    assert closed.correction_rad_s is not None and closed.correction_rad_s.shape == (N, 2)
    np.testing.assert_allclose(closed.activations, planned, atol=1e-12)
    np.testing.assert_array_equal(closed.activations, closed.recording.activation)
    assert closed.reward_mm == pytest.approx((N - 1) * BELT_MM_PER_TICK, rel=1e-12)


def test_a_cancelled_attempt_raises_and_invalid_features_play_nothing() -> None:
    plant = InverseMapPlant()
    rig = PlantRig(plant, config=UNLIMITED)
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(RigCancelled):
        run_attempt(rig, known_map(), FEATURES, CYCLE, cancel=cancel)
    assert plant.ticks < N
    ticks = plant.ticks
    with pytest.raises(ValueError, match=r"features\[0\]"):
        run_attempt(rig, known_map(), np.full(10, 0.05), CYCLE)
    assert plant.ticks == ticks
