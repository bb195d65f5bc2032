"""A recorded run that cannot be calibrated on gets an error naming the file and what is missing."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import pytest

from g2p.description.urdf import leg_urdf
from g2p.identification import CalibrationInputError, load_recorded_run
from g2p.identification.calibrate import main as calibrate_main
from g2p.sim import MujocoLeg
from g2p.sim.model_description import leg_description
from tests.bags.bagdata import TICK_NS, Messages, SyntheticRun, TickPlan, write_plan


def test_too_little_babbling_is_named(synthetic_run: Callable[..., SyntheticRun]) -> None:
    run = synthetic_run()
    with pytest.raises(CalibrationInputError, match=r"200 babbling ticks \(2\.6 s\); a calibration needs"):
        load_recorded_run(run.path)
    with pytest.raises(CalibrationInputError, match=str(run.path)):
        load_recorded_run(run.path)


def test_a_bag_without_babbling_is_named(tmp_path: Path, messages: Messages) -> None:
    plan = TickPlan()
    plan.event(0, "attempt_start", attempt=1, phase="exploration")
    for k in range(1, 100):
        plan.tick(k * TICK_NS, k)
    plan.event(100 * TICK_NS, "attempt_end", attempt=1, phase="exploration")
    write_plan(tmp_path / "no-babbling", messages, plan)
    with pytest.raises(CalibrationInputError, match=r"no-babbling: no babbling to calibrate on"):
        load_recorded_run(tmp_path / "no-babbling")


def test_another_leg_layout_is_named(synthetic_run: Callable[..., SyntheticRun]) -> None:
    leg = leg_description(MujocoLeg().model)
    longer = dataclasses.replace(leg, thigh=dataclasses.replace(leg.thigh, length_m=0.25))
    run = synthetic_run(robot_descriptions=(leg_urdf(longer),))
    with pytest.raises(
        CalibrationInputError, match=r"another leg layout: its thigh is 0\.250 m long, the model's 0\.200"
    ):
        load_recorded_run(run.path, min_babbling_s=1.0)
    # The same layout passes the check.
    same = synthetic_run("same", robot_descriptions=(leg_urdf(leg),))
    assert len(load_recorded_run(same.path, min_babbling_s=1.0).babbling[0]) == len(same.babbling_ticks)


def test_the_command_exits_2_and_writes_nothing(
    tmp_path: Path, synthetic_run: Callable[..., SyntheticRun], capsys: pytest.CaptureFixture[str]
) -> None:
    run = synthetic_run()
    out = tmp_path / "calib.yaml"
    assert calibrate_main([str(run.path), "--out", str(out)]) == 2
    assert "a calibration needs at least 10 s" in capsys.readouterr().err
    assert not out.exists()
    assert calibrate_main([str(tmp_path / "missing"), "--out", str(out)]) == 2
    assert "missing: cannot be read" in capsys.readouterr().err


def test_a_fit_that_does_not_converge_exits_1_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sample = Path(__file__).resolve().parents[2] / "bags" / "samples" / "treadmill-60s-babbling"
    out = tmp_path / "calib.yaml"
    args = [str(sample), "--out", str(out), "--params", "motor_lag_s,m1_proximal_arm_m", "--workers", "1"]
    assert calibrate_main([*args, "--max-evaluations", "1"]) == 1
    assert "did not converge after 1 evaluations" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "calib.yaml.report").exists()
