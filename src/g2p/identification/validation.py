"""Whether a calibrated rig behaves like the recorded one: the same gaits played on both, their rewards."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from g2p.attempt import run_attempt
from g2p.inverse_map import InverseMap
from g2p.limit_cycle import LimitCycleConfig
from g2p.rig import PlantRig
from g2p.sim.calibration import LegCalibration
from g2p.sim.config import MujocoLegConfig
from g2p.sim.leg import MujocoLeg


def rewards_mm(
    leg_config: MujocoLegConfig,
    calibration: LegCalibration,
    inverse_map: InverseMap,
    features: Sequence[Sequence[float]],
    cycle: LimitCycleConfig,
    lead_ticks: int = 0,
) -> list[float]:
    """The reward (belt travel, mm) of each feature vector's attempt, open loop, on one simulated rig.

    The same map and features give the same activations on every rig, so rewards of two rigs compare
    the rigs alone.

    Args:
        leg_config: the simulated rig (a treadmill carriage height for rewards).
        calibration: its calibration.
        inverse_map: the map that turns each limit cycle into activations.
        features: the limit cycles' feature vectors, shape (K, n_spokes).
        cycle: the limit-cycle settings.
        lead_ticks: the map's command lead (LearnerConfig.preprocess.command_lead_ticks).
    """
    rig = PlantRig(MujocoLeg(leg_config, calibration=calibration))
    out = [run_attempt(rig, inverse_map, np.asarray(f), cycle, lead_ticks).reward_mm for f in features]
    rig.plant.close()
    return out
