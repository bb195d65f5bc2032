"""The simulated rig's physical limits (g2p.sim.limits), each against a known answer."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from g2p.plant import hold
from g2p.rig.envelope import JOINT_STOPS_RAD, WindingRating
from g2p.rig.tendons import TENDON_ARMS_M, DriveRating
from g2p.sim import ModelError, MujocoLeg, MujocoLegConfig, packaged_model_path
from g2p.sim.limits import COOLDOWN_HYSTERESIS_K, NUMERICS, available_current_a


def test_an_unloaded_spool_runs_up_to_its_no_load_speed_at_the_supply_voltage(air_plant: MujocoLeg) -> None:
    # M1's tendon off its spool: at activation 1 the spool accelerates until the back-EMF leaves just
    # the current that balances its own damping b and friction f: Kt (V - Kt w) / R = b w + f.
    plant, model = air_plant, air_plant.model
    model.tendon_stiffness[1] = 0.0
    motor, dof = plant.leg_model.motor, plant.leg_model.spool_dof[1]
    kt, r, v = motor.kt_nm_per_a, motor.resistance_ohm, plant.limits.supply_voltage_v
    b, f = float(model.dof_damping[dof]), float(model.dof_frictionloss[dof])
    expected_rad_s = (kt * v / r - f) / (kt * kt / r + b)
    recording = hold(plant, (0.15, 1.0, 0.15), 156)
    assert float(plant.data.qvel[dof]) == pytest.approx(expected_rad_s, rel=0.01)
    assert expected_rad_s < v / kt  # below the ideal no-load speed by what the losses take
    assert recording.current_a[-1, 1] == pytest.approx((v - kt * expected_rad_s) / r, rel=0.05)
    assert recording.current_a[-1, 1] < 0.05 * motor.max_current_a  # not the 8 A commanded


def test_the_supply_caps_the_current_only_of_a_spool_that_reels_in_fast(air_plant: MujocoLeg) -> None:
    motor = air_plant.leg_model.motor
    speeds = np.array([-100.0, 0.0, 100.0])
    current = available_current_a(np.full(3, 8.0), speeds, motor, 12.0)
    assert current[:2].tolist() == [8.0, 8.0]
    assert current[2] == pytest.approx((12.0 - motor.kt_nm_per_a * 100.0) / motor.resistance_ohm)


def test_a_winding_heats_as_the_first_order_solution_of_its_copper_loss(air_plant: MujocoLeg) -> None:
    # Every motor at activation 1 with the leg held still against its stops: 8 A, I^2 R = 38.4 W each.
    plant, limits = air_plant, air_plant.limits
    seconds = 20.0
    recording = hold(plant, (1.0, 1.0, 1.0), round(seconds * plant.tick_hz))
    elapsed = recording.t_s[-1] - recording.t_s[0] + (recording.t_s[1] - recording.t_s[0])
    loss_w = plant.leg_model.motor.max_current_a**2 * plant.leg_model.motor.resistance_ohm
    rise = loss_w * limits.winding_thermal_resistance_k_per_w
    tau = limits.winding_time_constant_s
    expected = limits.ambient_c + rise * (1.0 - math.exp(-elapsed / tau))
    # 0.5 K: the current reaches 8 A through the motors' 30 ms lag, 0.15 % of the interval.
    np.testing.assert_allclose(plant.winding_temperature_c, expected, atol=0.5)
    assert plant.fault == ""


def test_a_winding_at_its_cut_out_switches_its_motor_off_until_it_cooled_and_was_reset(
    air_plant: MujocoLeg,
) -> None:
    plant, limits = air_plant, air_plant.limits
    for _ in range(round(120 * plant.tick_hz)):  # 38.4 W: 80 degC after about 76 s
        plant.step(np.array([1.0, 0.15, 0.15]))
        if plant.fault:
            break
    assert "M0's winding reached" in plant.fault and "cut out" in plant.fault
    after = hold(plant, (1.0, 0.15, 0.15), 10)
    assert after.current_a[-1, 0] == 0.0  # the driver keeps it off
    t_before, hot_c = plant.time_s, float(plant.winding_temperature_c[0])
    plant.reset()
    assert plant.fault == ""
    assert plant.winding_temperature_c[0] == pytest.approx(
        limits.winding_cutout_c - COOLDOWN_HYSTERESIS_K, abs=1e-6
    )
    target_c = limits.winding_cutout_c - COOLDOWN_HYSTERESIS_K
    rise_ratio = (hot_c - limits.ambient_c) / (target_c - limits.ambient_c)
    wait_s = limits.winding_time_constant_s * math.log(rise_ratio)
    assert plant.time_s - t_before == pytest.approx(wait_s)  # the operator waited for it to cool
    assert hold(plant, (1.0, 0.15, 0.15), 5).current_a[-1, 0] > 1.0


def test_a_tendon_beyond_its_breaking_tension_snaps_and_carries_no_force(air_plant: MujocoLeg) -> None:
    plant = air_plant
    plant.limits = replace(plant.limits, tendon_rated_n=30.0, tendon_breaking_n=40.0)
    hold(plant, (0.15, 1.0, 0.15), 78)
    assert "tendon M1 snapped" in plant.fault
    hold(plant, (0.15, 1.0, 0.15), 10)
    assert plant.tendon_tension_n[1] == 0.0
    plant.reset()
    assert plant.fault == ""
    hold(plant, (0.15, 0.3, 0.15), 78)  # 18 N static, with its overshoot below 40 N
    assert plant.fault == ""
    assert plant.tendon_tension_n[1] > 10.0


def test_a_spool_paying_out_into_its_slack_tendon_derails_it(treadmill_plant: MujocoLeg) -> None:
    # The two-phase square wave at 0.97 Hz slams the joints; its slack tendons' spools pay out cable.
    plant = treadmill_plant
    t = np.arange(round(10 * plant.tick_hz)) / plant.tick_hz
    first = (np.floor(t * 0.97 * 2) % 2 == 0)[:, None]
    square = np.where(first, [1.0, 0.15, 1.0], [0.15, 1.0, 0.15])
    plant.limits = replace(plant.limits, tendon_derail_payout_m=0.002)
    for row in square:
        plant.step(row)
        if plant.fault:
            break
    assert "left its channel" in plant.fault
    assert float(np.max(plant.max_slack_payout_m)) > 0.002


def test_babbling_trips_no_limit(treadmill_plant: MujocoLeg) -> None:
    from g2p.learning.babbling import babbling_activations

    plant = treadmill_plant
    for row in babbling_activations(np.random.default_rng(3), n_samples=round(60 * plant.tick_hz)):
        plant.step(row)
    assert plant.fault == ""
    assert float(np.max(plant.max_slack_payout_m)) < plant.limits.tendon_derail_payout_m


def test_the_envelopes_rated_values_are_the_simulated_rigs(air_plant: MujocoLeg) -> None:
    model, limits, rating = air_plant.model, air_plant.limits, WindingRating()
    assert rating.resistance_ohm == air_plant.leg_model.motor.resistance_ohm
    assert rating.thermal_resistance_k_per_w == limits.winding_thermal_resistance_k_per_w
    assert rating.time_constant_s == limits.winding_time_constant_s
    assert rating.ambient_c == limits.ambient_c
    for name, stops in zip(("proximal", "distal"), JOINT_STOPS_RAD, strict=True):
        np.testing.assert_allclose(model.jnt_range[model.joint(name).id], stops, atol=1e-12)
    motor, drive = air_plant.leg_model.motor, DriveRating()
    assert (drive.kt_nm_per_a, drive.resistance_ohm, drive.spool_radius_m) == (
        motor.kt_nm_per_a,
        motor.resistance_ohm,
        motor.spool_radius_m,
    )
    np.testing.assert_array_equal(model.tendon_stiffness[:3], drive.tendon_stiffness_n_per_m)
    np.testing.assert_allclose(air_plant._tendon_joint_arms(), TENDON_ARMS_M, atol=1e-12)


def without_numerics(tmp_path: Path, names: Iterable[str]) -> Path:
    """The packaged model with the custom numerics `names` removed, written into tmp_path."""
    text = packaged_model_path().read_text()
    for name in names:
        text, found = re.subn(rf'\s*<numeric name="{name}" [^>]*/>[^\n]*', "", text)
        assert found == 1, name
    path = tmp_path / "my_leg.xml"
    path.write_text(text)
    return path


def test_a_model_written_before_the_limits_is_refused_naming_every_missing_numeric(tmp_path: Path) -> None:
    path = without_numerics(tmp_path, NUMERICS.values())
    with pytest.raises(ModelError) as raised:
        MujocoLeg(MujocoLegConfig(model_path=str(path)))
    message = str(raised.value)
    assert message.startswith(f"{path}: model lacks the custom numerics {', '.join(NUMERICS.values())}; ")
    # The packaged values, as lines to copy into the model's <custom> block.
    packaged = packaged_model_path().read_text()
    for name in NUMERICS.values():
        line = re.search(rf'<numeric name="{name}" data="[^"]*"/>', packaged)
        assert line is not None and f"\n    {line.group()}" in message, name
    assert '<numeric name="supply_voltage" data="12"/>' in message
    assert "motor_kt" not in message  # what the model has is not asked for


def test_a_model_without_custom_numerics_is_refused_naming_the_motors_and_the_limits(tmp_path: Path) -> None:
    motors = ("motor_kt", "motor_resistance", "motor_max_current", "spool_radius")
    path = without_numerics(tmp_path, (*motors, *NUMERICS.values()))
    with pytest.raises(ModelError, match=", ".join((*motors, *NUMERICS.values()))):
        MujocoLeg(MujocoLegConfig(model_path=str(path)))
