"""Known answers for a calibration: babbling recorded on a hidden rig; the same gaits played on two rigs."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from g2p.identification.segments import Segment, segment_of
from g2p.inverse_map import InverseMap
from g2p.learning.attempt import run_attempt
from g2p.learning.babbling import BabblingConfig, babbling_activations
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.plant import Recording
from g2p.rig import PlantRig
from g2p.sim.calibration import LegCalibration
from g2p.sim.config import MujocoLegConfig
from g2p.sim.leg import MujocoLeg


def hidden_babbling(
    leg_config: MujocoLegConfig, calibration: LegCalibration, seconds: float, seed: int
) -> Segment:
    """Babbling recorded in process on a rig with `calibration` (its jittered ticks, its encoders).

    Args:
        leg_config: the simulated rig; its `seed` is replaced by `seed` + 1 (the ticks' jitter).
        calibration: the hidden rig's parameters.
        seconds: babbling recorded (s of rig time, at the nominal tick rate).
        seed: seeds the babbling's activations (and the jitter).
    """
    hidden = MujocoLeg(replace(leg_config, seed=seed + 1), calibration=calibration)
    n = round(seconds * leg_config.tick_hz)
    activations = babbling_activations(np.random.default_rng(seed), BabblingConfig(), n)
    start = hidden.reset()
    recording = Recording.from_samples([hidden.step(a) for a in activations])
    hidden.close()
    return segment_of(recording, "babbling", leg_config.tick_hz, previous_t_s=start.t_s)


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
