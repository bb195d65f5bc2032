"""`TreadmillEnv` (`g2p/Treadmill-v0`): walk the leg on the treadmill; the reward is belt travel.

The G2P treadmill task (paper Fig 4) for a model-free learner: the episode is as long as a G2P attempt
(20 cycles, 1600 ticks, about 20.5 s), so an episode's return is the reward G2P gives an attempt.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from g2p.plant import Plant, TickSample
from g2p.rl.envs.leg_env import LegEnv
from g2p.sim import MujocoLegConfig


class TreadmillEnv(LegEnv):
    """Belt travel per step (mm), optionally less an energy cost.

    Observation (8,): joint angles (rad), joint velocities (rad/s), belt velocity (m/s), the activations
    applied in the last tick. Action (3,): the activations of M0, M1, M2 in [0, 1], held for frame_skip ticks.

    Reward: forward_reward_weight * belt travel over the step (mm, + backward = forward locomotion)
    - energy_cost_weight * electrical energy the motors drew over the step (J). `info` carries both terms
    (reward_forward, reward_energy) and the episode's totals so far (belt_travel_mm, energy_used_j).

    Args:
        forward_reward_weight: weight of the belt travel (per mm).
        energy_cost_weight: weight of the energy (per J; 0 = the paper's reward, belt travel alone).
        **kwargs: LegEnv's (plant, plant_config, cycle, frame_skip, reset_noise_scale, render_mode, ...).
    """

    def __init__(
        self,
        plant: Plant | None = None,
        plant_config: MujocoLegConfig | None = None,
        forward_reward_weight: float = 1.0,
        energy_cost_weight: float = 0.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(plant=plant, plant_config=plant_config, **kwargs)
        self.forward_reward_weight = forward_reward_weight
        self.energy_cost_weight = energy_cost_weight
        self._start: TickSample | None = None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float64], dict[str, Any]]:
        """Return the leg to rest and start an episode; the belt travel and energy count from here."""
        obs, info = super().reset(seed=seed, options=options)
        self._start = self._last
        return obs, {**info, "belt_travel_mm": 0.0, "energy_used_j": 0.0}

    def _reward(self, samples: list[TickSample], first_tick: int) -> tuple[float, dict[str, float]]:
        start, end = samples[0], samples[-1]
        assert self._start is not None
        travel_mm = end.belt_mm - start.belt_mm
        energy_j = float(np.sum(end.energy_j - start.energy_j))
        forward = self.forward_reward_weight * travel_mm
        energy = -self.energy_cost_weight * energy_j
        return forward + energy, {
            "reward_forward": forward,
            "reward_energy": energy,
            "belt_travel_mm": end.belt_mm - self._start.belt_mm,
            "energy_used_j": float(np.sum(end.energy_j - self._start.energy_j)),
        }
