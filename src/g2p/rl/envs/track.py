"""`TrackEnv` (`g2p/Track-v0`): follow a limit cycle in the air; the reward is the tracking error.

The G2P tracking task (paper Fig 5) for a model-free learner: the desired joint kinematics are the limit
cycle of a feature vector (g2p.learning.limit_cycle), played for 20 cycles as in a G2P attempt.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from g2p.learning.limit_cycle import LimitCycleConfig, check_features, cycle_kinematics
from g2p.plant import FloatArray, Plant, TickSample
from g2p.rl.envs.leg_env import RIG_OBSERVATION, LegEnv
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLegConfig


class TrackEnv(LegEnv):
    """Negative squared joint-angle error to a limit cycle, per step.

    Observation (12,): TreadmillEnv's 8 entries, then the desired joint angles (rad) and velocities (rad/s)
    at the end of the coming tick. Action (3,): the activations of M0, M1, M2 in [0, 1].

    Reward: -tracking_weight * the mean over the step's ticks of the summed squared joint-angle error
    (rad^2), each tick's angles against the cycle's desired angles for that tick (as g2p.learning.attempt
    scores an attempt). `info` carries reward_tracking and the step's tracking_rmse_rad.

    Args:
        features: the limit cycle (n_spokes,) within the cycle's feature bounds; None draws one uniformly
            per episode from the environment's generator. `reset(options={"features": f})` sets one episode's.
        plant: as LegEnv; None builds the simulated rig in the air (carriage raised, the paper's Fig 5).
        plant_config: settings of that rig (default: MujocoLegConfig with the air carriage height).
        cycle: limit-cycle parameters (default: the in-air preset, features in [0.2, 0.8]).
        tracking_weight: weight of the squared error (per rad^2).
        **kwargs: LegEnv's (frame_skip, reset_noise_scale, render_mode, ...).
    """

    observation_names = (
        *RIG_OBSERVATION,
        "proximal_desired_rad",
        "distal_desired_rad",
        "proximal_desired_rad_s",
        "distal_desired_rad_s",
    )

    def __init__(
        self,
        features: ArrayLike | None = None,
        plant: Plant | None = None,
        plant_config: MujocoLegConfig | None = None,
        cycle: LimitCycleConfig | None = None,
        tracking_weight: float = 1.0,
        **kwargs: Any,
    ) -> None:
        if plant is None and plant_config is None:
            plant_config = MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M)
        cycle = cycle if cycle is not None else LimitCycleConfig.in_air()
        self._fixed = None if features is None else check_features(features, cycle)
        super().__init__(plant=plant, plant_config=plant_config, cycle=cycle, **kwargs)
        self.tracking_weight = tracking_weight
        self.features: FloatArray = self._fixed if self._fixed is not None else np.zeros(cycle.n_spokes)
        """The current episode's limit cycle (n_spokes,)."""
        self._desired = np.zeros((self.cycle.samples_per_cycle, 4))

    def _on_reset(self, options: dict[str, Any] | None) -> None:
        given = (options or {}).get("features")
        if given is not None:
            self.features = check_features(given, self.cycle)
        elif self._fixed is not None:
            self.features = self._fixed
        else:
            self.features = self.np_random.uniform(
                self.cycle.feature_low, self.cycle.feature_high, self.cycle.n_spokes
            )
        self._desired = cycle_kinematics(self.features, self.cycle)[:, :4]

    def _extra_observation(self) -> FloatArray:
        return np.asarray(self._desired[self.ticks % len(self._desired)], dtype=np.float64)

    def _reward(self, samples: list[TickSample], first_tick: int) -> tuple[float, dict[str, float]]:
        rows = np.arange(first_tick, first_tick + len(samples) - 1) % len(self._desired)
        actual = np.array([s.position_rad for s in samples[1:]])
        sq = np.sum((actual - self._desired[rows, :2]) ** 2, axis=1)  # (frame_skip,) rad^2
        reward = -self.tracking_weight * float(np.mean(sq))
        return reward, {"reward_tracking": reward, "tracking_rmse_rad": float(np.sqrt(np.mean(sq) / 2))}
