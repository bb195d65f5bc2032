"""The bring-up tendon check on the fake rig: a correct rig passes, each miswiring is named."""

from __future__ import annotations

from dataclasses import replace

import pytest

from g2p.config import ConfigError
from g2p.hardware import HardwareLeg, RigConfig, SimulatedClock, build_devices
from g2p.hardware.bringup import TendonCheckConfig, check_tendons
from g2p.hardware.fakes import FakeRig
from g2p.rig import PlantRig
from tests.hardware.rigs import FAST

RIG = RigConfig()


def check(truth: RigConfig) -> tuple[bool, str]:
    clock = SimulatedClock()
    fake = FakeRig(RIG, None, clock, truth=truth)
    leg = HardwareLeg(build_devices(RIG, fake), RIG, FAST, clock)
    report = check_tendons(PlantRig(leg))
    leg.close()
    return report.ok, report.text()


def test_a_correctly_wired_rig_passes() -> None:
    ok, text = check(RIG)
    assert ok, text
    assert "every tendon moves its joints as in Fig 1d" in text


@pytest.mark.parametrize(
    ("truth", "hint"),
    [
        (
            replace(RIG, encoders=replace(RIG.encoders, distal=replace(RIG.encoders.distal, direction=-1))),
            "flip encoders.distal.direction",
        ),
        (
            replace(
                RIG, encoders=replace(RIG.encoders, proximal=replace(RIG.encoders.proximal, direction=-1))
            ),
            "flip encoders.proximal.direction",
        ),
        (replace(RIG, pwm=replace(RIG.pwm, channels=(2, 1, 0))), "M2 does not act as in Fig 1d"),
        (replace(RIG, pwm=replace(RIG.pwm, channels=(1, 0, 2))), "M1 does not act as in Fig 1d"),
    ],
    ids=["distal-encoder-reversed", "proximal-encoder-reversed", "M0-M2-swapped", "M0-M1-swapped"],
)
def test_miswiring_fails_and_is_named(truth: RigConfig, hint: str) -> None:
    ok, text = check(truth)
    assert not ok
    assert hint in text, text


def test_levels_are_capped() -> None:
    with pytest.raises(ConfigError, match="levels"):
        TendonCheckConfig(levels=(0.4, 0.9, 0.5))
