"""The plant interface: recordings, stamps, playing sequences on a plant, the motors' thermal model.

The plant is a tiny one written here, whose every reading follows from the activations by hand.
"""

from __future__ import annotations

import json
import math
from dataclasses import fields

import numpy as np
import pytest

from g2p.plant import (
    BASELINE_ACTIVATION,
    N_JOINTS,
    N_MOTORS,
    Plant,
    Recording,
    TickSample,
    concatenate,
    first_order_temperature,
    hold,
    on_stamp_grid,
    run_sequence,
    stamp_ns,
)
from g2p.safety import InvalidActivation, check_activation

TICK_HZ = 10.0


class CountingPlant:
    """A plant whose readings are sums of the activations it was given, one tick = 0.1 s.

    Per tick with activation a: the hip turns by a1 - a0 rad and the knee by -a2 rad; the belt moves 2 a0 mm;
    motor m draws a_m A at 12 V, so 12 a_m W and 1.2 a_m J. Belt and energy count from creation, across
    resets; a reset puts the joints back at 0.
    """

    tick_hz = TICK_HZ

    def __init__(self) -> None:
        self.ticks = 0
        self.steps = 0
        self.resets = 0
        self.position = np.zeros(N_JOINTS)
        self.belt_mm = 0.0
        self.energy_j = np.zeros(N_MOTORS)

    def _sample(self, a: np.ndarray, velocity: np.ndarray, belt_velocity: float) -> TickSample:
        return TickSample(
            t_s=self.ticks / self.tick_hz,
            activation=a.copy(),
            position_rad=self.position.copy(),
            velocity_rad_s=velocity,
            belt_mm=self.belt_mm,
            belt_velocity_mm_s=belt_velocity,
            current_a=a.copy(),
            power_w=12.0 * a,
            energy_j=self.energy_j.copy(),
        )

    def reset(self) -> TickSample:
        self.resets += 1
        self.position = np.zeros(N_JOINTS)
        return self._sample(np.full(N_MOTORS, BASELINE_ACTIVATION), np.zeros(N_JOINTS), 0.0)

    def step(self, activation: np.ndarray) -> TickSample:
        a = check_activation(activation)
        self.steps += 1
        self.ticks += 1
        turn = np.array([a[1] - a[0], -a[2]])
        self.position = self.position + turn
        self.belt_mm += 2.0 * a[0]
        self.energy_j = self.energy_j + 12.0 * a / self.tick_hz
        return self._sample(a, turn * self.tick_hz, 2.0 * a[0] * self.tick_hz)

    def close(self) -> None:
        pass


def sample(k: int) -> TickSample:
    """A sample whose every value tells its tick k and its column apart."""

    def row(width: int) -> np.ndarray:
        return k + np.arange(width) / 10.0

    return TickSample(
        t_s=0.5 * k,
        activation=row(3),
        position_rad=row(2),
        velocity_rad_s=-row(2),
        belt_mm=10.0 * k,
        belt_velocity_mm_s=-10.0 * k,
        current_a=row(3) + 100,
        power_w=row(3) + 200,
        energy_j=row(3) + 300,
    )


# Recording ---------------------------------------------------------------------------------------------


def test_from_samples_stacks_one_row_per_tick_with_the_documented_shapes() -> None:
    rec = Recording.from_samples([sample(k) for k in range(4)])
    assert len(rec) == 4
    shapes = {f.name: getattr(rec, f.name).shape for f in fields(Recording)}
    assert shapes == {
        "t_s": (4,),
        "activation": (4, 3),
        "position_rad": (4, 2),
        "velocity_rad_s": (4, 2),
        "belt_mm": (4,),
        "belt_velocity_mm_s": (4,),
        "current_a": (4, 3),
        "power_w": (4, 3),
        "energy_j": (4, 3),
    }
    assert all(getattr(rec, f.name).dtype == np.float64 for f in fields(Recording))
    assert rec.t_s.tolist() == [0.0, 0.5, 1.0, 1.5]
    assert rec.activation[2].tolist() == [2.0, 2.1, 2.2]
    assert rec.velocity_rad_s[3].tolist() == [-3.0, -3.1]
    assert rec.energy_j[:, 0].tolist() == [300.0, 301.0, 302.0, 303.0]
    assert rec.belt_velocity_mm_s.tolist() == [0.0, -10.0, -20.0, -30.0]


def test_an_empty_recording_has_zero_rows_of_every_width() -> None:
    for rec in (Recording.empty(), Recording.from_samples([])):
        assert len(rec) == 0
        assert rec.activation.shape == (0, 3) and rec.position_rad.shape == (0, 2)
        assert rec.t_s.shape == (0,)
        assert rec.belt_travel_mm == 0.0 and rec.energy_used_j == 0.0


def test_a_field_of_the_wrong_shape_is_refused_naming_it() -> None:
    good = Recording.from_samples([sample(0), sample(1)])
    arrays = {f.name: getattr(good, f.name) for f in fields(Recording)}
    with pytest.raises(ValueError, match=r"Recording\.position_rad: expected shape \(2, 2\), got \(2, 3\)"):
        Recording(**{**arrays, "position_rad": np.zeros((2, 3))})
    with pytest.raises(ValueError, match=r"Recording\.belt_mm: expected shape \(2,\), got \(3,\)"):
        Recording(**{**arrays, "belt_mm": np.zeros(3)})


def test_slice_and_take_keep_the_chosen_ticks_of_every_field() -> None:
    rec = Recording.from_samples([sample(k) for k in range(5)])
    part = rec.slice(1, 3)
    assert len(part) == 2 and part.t_s.tolist() == [0.5, 1.0]
    assert part.position_rad.tolist() == [[1.0, 1.1], [2.0, 2.1]]
    assert rec.slice(3).t_s.tolist() == [1.5, 2.0]
    assert rec.slice(stop=-4).belt_mm.tolist() == [0.0]
    assert len(rec.slice(4, 2)) == 0
    picked = rec.take(np.array([0, 4]))
    assert picked.t_s.tolist() == [0.0, 2.0] and picked.current_a[:, 0].tolist() == [100.0, 104.0]
    for f in fields(Recording):  # every field follows the ticks
        np.testing.assert_array_equal(getattr(part, f.name), getattr(rec, f.name)[1:3])


def test_belt_travel_and_energy_count_from_the_end_of_the_first_tick() -> None:
    rec = Recording.from_samples([sample(k) for k in range(2, 6)])
    assert rec.belt_travel_mm == 50.0 - 20.0
    assert rec.energy_used_j == pytest.approx(3 * (305.0 - 302.0))  # three motors, 3 J each
    assert Recording.from_samples([sample(7)]).belt_travel_mm == 0.0


def test_concatenate_joins_end_to_end_and_keeps_the_stamps() -> None:
    a = Recording.from_samples([sample(k) for k in range(3)])
    b = Recording.from_samples([sample(k) for k in (10, 11)])
    joined = concatenate([a, b])
    assert len(joined) == 5
    assert joined.t_s.tolist() == [0.0, 0.5, 1.0, 5.0, 5.5]
    assert joined.energy_j.shape == (5, 3)
    np.testing.assert_array_equal(joined.slice(3).activation, b.activation)
    assert len(concatenate([])) == 0
    assert len(concatenate([Recording.empty(), a])) == 3


# Stamps ------------------------------------------------------------------------------------------------


def test_stamps_are_whole_nanoseconds_rounded_to_the_nearest() -> None:
    assert stamp_ns(1.5) == 1_500_000_000
    assert stamp_ns(1.4e-9) == 1 and stamp_ns(1.6e-9) == 2 and stamp_ns(-1.6e-9) == -2
    # One tick at 78 Hz is 12,820,512.82 ns.
    assert stamp_ns(1 / 78) == 12_820_513
    assert isinstance(stamp_ns(0.25), int)
    assert json.dumps(stamp_ns(2.0)) == "2000000000"


def test_on_stamp_grid_is_the_time_a_ros_stamp_carries() -> None:
    assert on_stamp_grid(1 / 78) == 12_820_513 * 1e-9
    assert on_stamp_grid(2.0) == 2.0
    for t in (1 / 78, 123.456789012345, 1e-10):
        assert stamp_ns(on_stamp_grid(t)) == stamp_ns(t)  # a stamp read back gives the same stamp
        assert abs(on_stamp_grid(t) - t) <= 0.5e-9 + 1e-15 * t


# Playing on a plant ------------------------------------------------------------------------------------


def test_the_tiny_plant_satisfies_the_protocol() -> None:
    assert isinstance(CountingPlant(), Plant)


def test_hold_plays_one_activation_for_the_ticks_asked() -> None:
    plant = CountingPlant()
    plant.reset()
    rec = hold(plant, (0.2, 0.6, 0.3), 4)
    assert len(rec) == 4 and plant.steps == 4
    np.testing.assert_allclose(rec.t_s, [0.1, 0.2, 0.3, 0.4])
    np.testing.assert_allclose(rec.activation, np.tile([0.2, 0.6, 0.3], (4, 1)))
    # The hip turns 0.4 rad a tick, the knee -0.3 rad; the belt moves 0.4 mm.
    np.testing.assert_allclose(rec.position_rad, [[0.4, -0.3], [0.8, -0.6], [1.2, -0.9], [1.6, -1.2]])
    np.testing.assert_allclose(rec.velocity_rad_s, np.tile([4.0, -3.0], (4, 1)))
    np.testing.assert_allclose(rec.belt_mm, [0.4, 0.8, 1.2, 1.6])
    assert rec.belt_travel_mm == pytest.approx(1.2)  # three ticks after the first's end
    np.testing.assert_allclose(rec.power_w, np.tile([2.4, 7.2, 3.6], (4, 1)))
    assert rec.energy_used_j == pytest.approx(3 * 1.2 * (0.2 + 0.6 + 0.3))


def test_run_sequence_plays_the_rows_in_order() -> None:
    plant = CountingPlant()
    plant.reset()
    rows = np.array([[0.5, 0.5, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.5]])
    rec = run_sequence(plant, rows)
    np.testing.assert_array_equal(rec.activation, rows)
    np.testing.assert_allclose(rec.position_rad[:, 0], [0.0, 1.0, 0.0])
    np.testing.assert_allclose(rec.position_rad[:, 1], [0.0, 0.0, -0.5])
    np.testing.assert_allclose(rec.belt_mm, [1.0, 1.0, 3.0])
    # Belt and energy go on counting across a reset; the joints start again from 0.
    plant.reset()
    again = run_sequence(plant, rows[:1])
    assert again.belt_mm.tolist() == [4.0] and again.position_rad[0].tolist() == [0.0, 0.0]
    np.testing.assert_allclose(again.t_s, [0.4])


@pytest.mark.parametrize(
    ("activations", "reason"),
    [
        (np.zeros((3, 2)), "shape"),
        (np.zeros((0, 3)), "shape"),
        (np.zeros(3), "shape"),
        (np.array([[0.2, 0.2, 0.2], [0.2, math.inf, 0.2]]), "non-finite values, first at row 1"),
        (np.array([[0.2, -0.1, 0.2]]), "outside"),
        (np.array([[0.2, 0.2, 0.2], [1.5, 0.2, 0.2]]), "outside"),
    ],
)
def test_an_invalid_sequence_is_refused_before_any_tick_is_played(
    activations: np.ndarray, reason: str
) -> None:
    plant = CountingPlant()
    plant.reset()
    with pytest.raises(InvalidActivation, match=reason):
        run_sequence(plant, activations)
    assert plant.steps == 0


def test_hold_for_no_ticks_or_an_invalid_activation_is_refused() -> None:
    plant = CountingPlant()
    with pytest.raises(ValueError, match="shape"):
        hold(plant, (0.2, 0.2, 0.2), 0)
    with pytest.raises(ValueError, match="outside"):
        hold(plant, (0.2, 1.2, 0.2), 3)
    with pytest.raises(ValueError, match="non-finite"):
        hold(plant, (0.2, math.nan, 0.2), 3)
    assert plant.steps == 0


# Thermal model -----------------------------------------------------------------------------------------

R_TH = 2.0  # K/W
TAU = 60.0  # s
AMBIENT = 25.0  # deg C


def test_the_steady_state_stays_put() -> None:
    heat = np.array([0.0, 5.0, 20.0])
    steady = AMBIENT + heat * R_TH  # 25, 35, 65 deg C
    after = first_order_temperature(steady, heat, 7.0, R_TH, TAU, AMBIENT)
    np.testing.assert_allclose(after, [25.0, 35.0, 65.0])


def test_after_one_time_constant_a_winding_has_covered_1_minus_1_over_e_of_the_way() -> None:
    heat = np.array([10.0, 0.0])
    start = np.array([AMBIENT, 45.0])  # heating from ambient toward 45; cooling from 45 toward ambient
    after = first_order_temperature(start, heat, TAU, R_TH, TAU, AMBIENT)
    np.testing.assert_allclose(after, [25.0 + 20.0 * (1 - 1 / math.e), 25.0 + 20.0 / math.e])


def test_the_solution_is_exact_in_steps_of_any_size() -> None:
    heat = np.array([[3.0, 8.0], [0.0, 1.0]])  # any shape
    start = np.array([[25.0, 90.0], [60.0, 25.0]])
    whole = first_order_temperature(start, heat, 10.0, R_TH, TAU, AMBIENT)
    halves = first_order_temperature(
        first_order_temperature(start, heat, 4.0, R_TH, TAU, AMBIENT), heat, 6.0, R_TH, TAU, AMBIENT
    )
    assert whole.shape == (2, 2)
    np.testing.assert_allclose(halves, whole, rtol=1e-13)
    np.testing.assert_array_equal(first_order_temperature(start, heat, 0.0, R_TH, TAU, AMBIENT), start)
    np.testing.assert_allclose(
        first_order_temperature(start, heat, 1e6, R_TH, TAU, AMBIENT), AMBIENT + heat * R_TH
    )
