"""The Plant contract, checked on every plant: MuJoCo simulation now, the hardware rig on fake buses later.

To add a plant, append one `pytest.param(factory, id=...)` to PLANT_FACTORIES: the factory builds a fresh
plant (reset not yet called) and must be cheap enough to call once per test.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import fields

import numpy as np
import pytest

from g2p.plant import N_JOINTS, N_MOTORS, Plant, TickSample, hold
from g2p.safety import BASELINE_ACTIVATION, clamp_activation
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, TREADMILL_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig
from tests.hardware.fake_legs import hardware_leg_on_fake_buses

PlantFactory = Callable[[], Plant]

PLANT_FACTORIES = [
    pytest.param(
        lambda: MujocoLeg(MujocoLegConfig(carriage_height_m=TREADMILL_CARRIAGE_HEIGHT_M)),
        id="mujoco-treadmill",
    ),
    pytest.param(
        lambda: MujocoLeg(MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M)), id="mujoco-air"
    ),
    pytest.param(hardware_leg_on_fake_buses, id="hardware-fake-buses-air"),
]

_VECTOR_WIDTHS = {
    "activation": N_MOTORS,
    "position_rad": N_JOINTS,
    "velocity_rad_s": N_JOINTS,
    "current_a": N_MOTORS,
    "power_w": N_MOTORS,
    "energy_j": N_MOTORS,
}


@pytest.fixture(params=PLANT_FACTORIES)
def plant(request: pytest.FixtureRequest) -> Iterator[Plant]:
    factory: PlantFactory = request.param
    p = factory()
    yield p
    p.close()


def ticks_for(plant: Plant, seconds: float) -> int:
    return max(1, round(seconds * plant.tick_hz))


def assert_well_formed(sample: TickSample) -> None:
    assert isinstance(sample, TickSample)
    for f in fields(TickSample):
        value = getattr(sample, f.name)
        if f.name in _VECTOR_WIDTHS:
            assert isinstance(value, np.ndarray) and value.dtype == np.float64, f.name
            assert value.shape == (_VECTOR_WIDTHS[f.name],), f.name
            assert np.all(np.isfinite(value)), f.name
        else:
            assert isinstance(value, float) and math.isfinite(value), f.name


def test_is_a_plant_with_a_plausible_tick_rate(plant: Plant) -> None:
    assert isinstance(plant, Plant)
    assert 10.0 <= plant.tick_hz <= 1000.0


def test_reset_returns_a_rest_sample(plant: Plant) -> None:
    rest = plant.reset()
    assert_well_formed(rest)
    np.testing.assert_array_equal(rest.activation, np.full(N_MOTORS, BASELINE_ACTIVATION))
    assert np.all(np.abs(rest.velocity_rad_s) < 0.05)


def test_reset_returns_to_the_same_rest_after_moving(plant: Plant) -> None:
    rest = plant.reset()
    moved = hold(plant, (0.15, 0.8, 0.15), ticks_for(plant, 0.5))
    assert np.max(np.abs(moved.position_rad[-1] - rest.position_rad)) > math.radians(5)
    again = plant.reset()
    np.testing.assert_allclose(again.position_rad, rest.position_rad, atol=math.radians(0.5))


def test_steps_return_well_formed_samples_with_increasing_stamps(plant: Plant) -> None:
    rest = plant.reset()
    rng = np.random.default_rng(0)
    samples = [plant.step(rng.uniform(0.0, 1.0, N_MOTORS)) for _ in range(50)]
    for s in samples:
        assert_well_formed(s)
    stamps = np.array([rest.t_s] + [s.t_s for s in samples])
    assert np.all(np.diff(stamps) > 0.0)
    # About one nominal tick apart (the rig measured 78 +/- 5 Hz).
    assert np.all(np.abs(np.diff(stamps) * plant.tick_hz - 1.0) < 0.25)
    energy = np.array([rest.energy_j] + [s.energy_j for s in samples])
    assert np.sum(energy[-1] - energy[0]) > 0.0  # the motors always draw at least the baseline current


@pytest.mark.parametrize("command", [[0.5, 0.5, 0.5], [0.0, 0.1, 0.149], [1.0, 0.15, 0.7], [-1.0, 2.0, 0.3]])
def test_applied_activation_is_the_clamped_command(plant: Plant, command: list[float]) -> None:
    plant.reset()
    sample = plant.step(np.asarray(command))
    expected = clamp_activation(np.asarray(command), BASELINE_ACTIVATION)
    np.testing.assert_array_equal(sample.activation, expected)
    assert np.all(sample.activation >= BASELINE_ACTIVATION)


@pytest.mark.parametrize("bad", [[math.nan, 0.3, 0.3], [0.3, -math.inf, 0.3], [0.3, 0.3], [0.3] * 4])
def test_invalid_command_raises_without_a_tick(plant: Plant, bad: list[float]) -> None:
    plant.reset()
    before = plant.step(np.full(N_MOTORS, 0.3))
    with pytest.raises(ValueError):
        plant.step(np.asarray(bad))
    after = plant.step(np.full(N_MOTORS, 0.3))
    assert 0.0 < (after.t_s - before.t_s) * plant.tick_hz < 1.5  # exactly one tick passed, not two


def _pulse(
    plant: Plant,
    prep: tuple[float, float, float] | None,
    pulse: tuple[float, float, float],
    seconds: float = 1.0,
) -> np.ndarray:
    """Joint angle change (rad, (2,)) from holding `pulse` for `seconds` after an optional 1 s `prep`."""
    start = plant.reset().position_rad
    if prep is not None:
        start = hold(plant, prep, ticks_for(plant, 1.0)).position_rad[-1]
    end = hold(plant, pulse, ticks_for(plant, seconds)).position_rad[-1]
    return np.asarray(end - start)


def test_m1_alone_flexes_the_proximal_joint(plant: Plant) -> None:
    change = _pulse(plant, None, (0.15, 0.8, 0.15))
    assert change[0] > math.radians(15)


def test_m0_alone_extends_the_proximal_joint_and_straightens_the_distal(plant: Plant) -> None:
    # From a posture with the knee flexed (M1 and M2), so that the knee has room to straighten.
    change = _pulse(plant, (0.15, 0.45, 0.6), (0.8, 0.15, 0.15))
    assert change[0] < math.radians(-10)
    assert change[1] > math.radians(10)


def test_m2_alone_extends_the_proximal_joint_and_flexes_the_distal(plant: Plant) -> None:
    # From the hip flexed (M1, some M2), the foot well above the belt in treadmill mode.
    change = _pulse(plant, (0.15, 0.5, 0.3), (0.15, 0.15, 0.8))
    assert change[0] < math.radians(-10)
    assert change[1] < math.radians(-10)


def test_close_is_safe_after_use(plant: Plant) -> None:
    plant.reset()
    plant.step(np.full(N_MOTORS, 0.5))
    plant.close()
