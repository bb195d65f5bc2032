"""Calibrations of the simulated rig: the file, what each parameter changes, the encoders' offset, delay."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from g2p.plant import Recording
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig
from g2p.sim.calibration import (
    PARAMETERS,
    CalibrationError,
    LegCalibration,
    model_values,
    packaged_calibrations,
)
from g2p.sim.sensors import encoder_step_rad
from g2p.validation import ConfigError

AIR = MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M)


def test_every_model_parameter_reads_back_what_was_written() -> None:
    model = model_values(MujocoLeg(AIR).model)
    changed = {}
    for name, p in PARAMETERS.items():
        if p.is_sensor:
            continue
        value = model[name] * 1.1 if model[name] else 0.5 * (p.low + p.high)
        changed[name] = min(max(value, p.low), p.high)
    leg = MujocoLeg(AIR, calibration=LegCalibration(changed))
    values = model_values(leg.model)
    for name, value in changed.items():
        assert values[name] == pytest.approx(value), name
    # The actuators' gain is Kt * I_max, both changed here: it follows both (the model check passes).
    motor = leg.leg_model.motor
    assert motor.max_current_a == pytest.approx(changed["motor_max_current_a"])
    assert motor.kt_nm_per_a == pytest.approx(changed["motor_kt_nm_per_a"])
    assert motor.resistance_ohm == pytest.approx(changed["motor_resistance_ohm"])
    assert leg.model.actuator_gainprm[:3, 0] == pytest.approx([motor.max_torque_nm] * 3)


def test_the_file_round_trips(tmp_path: Path) -> None:
    cal = LegCalibration(
        {"belt_drag_n": 3.0, "encoder_delay_s": 0.01},
        intervals={"belt_drag_n": 0.1, "encoder_delay_s": math.inf},
        undetermined=("encoder_delay_s",),
        fit={"bag": "bags/x"},
    )
    path = tmp_path / "c.yaml"
    path.write_text(cal.to_yaml())
    back = LegCalibration.load(str(path))
    assert dict(back.parameters) == dict(cal.parameters)
    assert dict(back.intervals) == dict(cal.intervals)
    assert back.undetermined == cal.undetermined and back.fit == cal.fit and back.source == str(path)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("format: other\n", "not a leg calibration"),
        ("format: g2p-leg-calibration\nversion: 2\nmodel: g2p_leg\n", "version 2 is not supported"),
        ("format: g2p-leg-calibration\nversion: 1\nmodel: other_leg\n", "calibrates model 'other_leg'"),
        (
            "format: g2p-leg-calibration\nversion: 1\nmodel: g2p_leg\nparameters: {knee_size: 1}\n",
            "unknown parameter",
        ),
        (
            "format: g2p-leg-calibration\nversion: 1\nmodel: g2p_leg\nparameters: {motor_lag_s: -1}\n",
            r"motor_lag_s must be a number in \[0.002, 0.2\]",
        ),
        ("{{{", "cannot read the calibration"),
    ],
)
def test_an_invalid_file_is_named(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(CalibrationError, match=message) as err:
        LegCalibration.load(str(path))
    assert str(path) in str(err.value)
    with pytest.raises(ConfigError, match=f"calibration: .*{message}"):
        MujocoLegConfig(calibration=str(path))


def test_packaged_calibrations_load_by_name() -> None:
    assert packaged_calibrations()
    for name in packaged_calibrations():
        assert MujocoLeg(MujocoLegConfig(calibration=name)).calibration.parameters
    with pytest.raises(CalibrationError, match="no calibration file 'nope'"):
        LegCalibration.load("nope")


def _babble(leg: MujocoLeg, n: int = 300) -> Recording:
    rng = np.random.default_rng(3)
    acts = np.repeat(rng.uniform(0.15, 1.0, size=(n // 20, 3)), 20, axis=0)
    leg.reset()
    return Recording.from_samples([leg.step(a, period_s=1 / 78) for a in acts])


def test_encoder_offset_shifts_every_reading() -> None:
    offset = (0.05, -0.03)
    plain = _babble(MujocoLeg(AIR))
    shifted = _babble(
        MujocoLeg(
            AIR,
            calibration=LegCalibration(
                dict(zip(("proximal_encoder_offset_rad", "distal_encoder_offset_rad"), offset, strict=True))
            ),
        )
    )
    # Same physics, readings moved by the offset (to within one encoder count of rounding).
    np.testing.assert_allclose(
        shifted.position_rad - plain.position_rad, np.tile(offset, (300, 1)), atol=encoder_step_rad(14)
    )


def test_encoder_delay_of_one_tick_reads_the_previous_ticks_angles() -> None:
    plain = _babble(MujocoLeg(AIR))
    delayed = _babble(MujocoLeg(AIR, calibration=LegCalibration({"encoder_delay_s": 1 / 78})))
    np.testing.assert_allclose(delayed.position_rad[1:], plain.position_rad[:-1], atol=1e-12)
    np.testing.assert_array_equal(delayed.current_a, plain.current_a)  # only the encoders are late
    # Half a tick reads about halfway between the two.
    half = _babble(MujocoLeg(AIR, calibration=LegCalibration({"encoder_delay_s": 0.5 / 78})))
    mid = 0.5 * (plain.position_rad[:-1] + plain.position_rad[1:])
    step = plain.position_rad[1:] - plain.position_rad[:-1]
    assert np.sqrt(np.mean((half.position_rad[1:] - mid) ** 2)) < 0.2 * np.sqrt(np.mean(step**2))


def test_the_default_plant_is_unchanged_by_an_empty_calibration() -> None:
    a = _babble(MujocoLeg(AIR))
    b = _babble(MujocoLeg(AIR, calibration=LegCalibration({})))
    np.testing.assert_array_equal(a.position_rad, b.position_rad)


def test_set_joint_state_keeps_every_tendons_stretch() -> None:
    leg = MujocoLeg(AIR)
    _babble(leg, 60)
    mujoco.mj_forward(leg.model, leg.data)  # the tensions of the present state
    tension = leg.tendon_tension_n
    leg.set_joint_state(np.array([0.3, -0.6]), np.array([0.5, -0.2]))
    np.testing.assert_allclose(leg.true_position_rad, [0.3, -0.6])
    np.testing.assert_allclose(leg.data.qvel[leg.leg_model.joint_dof], [0.5, -0.2])
    np.testing.assert_allclose(leg.tendon_tension_n, tension, rtol=1e-9)
