"""The tendon check on the fake rig: a correct rig passes, each miswiring is named."""

from __future__ import annotations

from dataclasses import replace

import pytest

from g2p.hardware import HardwareLeg, SimulatedClock, WiringConfig, build_devices
from g2p.hardware_fake.buses import FakeBuses
from g2p.rig import PlantRig
from g2p.rig.tendon_check import TendonCheckConfig, check_tendons
from g2p.validation import ConfigError
from tests.hardware.fake_legs import FAST

WIRING = WiringConfig()


def check(truth: WiringConfig) -> tuple[bool, str]:
    clock = SimulatedClock()
    fake = FakeBuses(WIRING, None, clock, truth=truth)
    leg = HardwareLeg(build_devices(WIRING, fake), WIRING, FAST, clock)
    report = check_tendons(PlantRig(leg))
    leg.close()
    return report.ok, report.text()


def test_a_correctly_wired_rig_passes() -> None:
    ok, text = check(WIRING)
    assert ok, text
    assert "every tendon moves its joints as in Fig 1d" in text


@pytest.mark.parametrize(
    ("truth", "hint"),
    [
        (
            replace(
                WIRING,
                encoders=replace(WIRING.encoders, distal=replace(WIRING.encoders.distal, direction=-1)),
            ),
            "flip encoders.distal.direction",
        ),
        (
            replace(
                WIRING,
                encoders=replace(WIRING.encoders, proximal=replace(WIRING.encoders.proximal, direction=-1)),
            ),
            "flip encoders.proximal.direction",
        ),
        (replace(WIRING, pwm=replace(WIRING.pwm, channels=(2, 1, 0))), "M2 does not act as in Fig 1d"),
        (replace(WIRING, pwm=replace(WIRING.pwm, channels=(1, 0, 2))), "M1 does not act as in Fig 1d"),
    ],
    ids=["distal-encoder-reversed", "proximal-encoder-reversed", "M0-M2-swapped", "M0-M1-swapped"],
)
def test_miswiring_fails_and_is_named(truth: WiringConfig, hint: str) -> None:
    ok, text = check(truth)
    assert not ok
    assert hint in text, text


def test_levels_are_capped() -> None:
    with pytest.raises(ConfigError, match="levels"):
        TendonCheckConfig(levels=(0.4, 0.9, 0.5))
