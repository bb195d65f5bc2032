"""Fixtures of the MuJoCo plant tests: a fresh plant per test, in each carriage mode."""

from __future__ import annotations

import pytest

from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig


@pytest.fixture
def air_plant() -> MujocoLeg:
    return MujocoLeg(MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M))


@pytest.fixture
def treadmill_plant() -> MujocoLeg:
    return MujocoLeg(MujocoLegConfig())
