"""What gait PPO finds after 1 h of rig time, beside G2P's best attempt on the same simulated rig.

    scripts/with-env python benchmarks/bench_rl_gait.py --seed 0

Trains PPO as bench_rl does (g2p.baselines.rl_model: the RL Zoo's MuJoCo defaults, frame_skip 4),
rolls its deterministic policy out for one 20-cycle episode, and describes it beside G2P's best attempt:
belt travel (mm), energy (J), the joints' ranges (rad), the dominant frequency of the hip angle (Hz),
the mean activations. Prints one JSON line per method.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch

from g2p.baselines import rl_model
from g2p.envs import TreadmillEnv
from g2p.experiments import run_treadmill
from g2p.learner import Learner, LearnerConfig
from g2p.limit_cycle import LimitCycleConfig
from g2p.rig import PlantRig
from g2p.search import SearchConfig
from g2p.sim import MujocoLeg, MujocoLegConfig


def describe(position_rad: np.ndarray, activation: np.ndarray, dt_s: float) -> dict[str, object]:
    """Joint ranges (rad), the hip angle's dominant frequency (Hz) and mean activations of a gait."""
    hip = position_rad[:, 0] - position_rad[:, 0].mean()
    freq = np.fft.rfftfreq(len(hip), d=dt_s)
    spectrum = np.abs(np.fft.rfft(hip))
    return {
        "joint_range_rad": np.round(np.ptp(position_rad, axis=0), 3).tolist(),
        "hip_frequency_hz": round(float(freq[1 + np.argmax(spectrum[1:])]), 3),
        "mean_activation": np.round(activation.mean(axis=0), 3).tolist(),
    }


def main() -> None:
    """Train, roll out, describe."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--hours", type=float, default=1.0, help="PPO's rig time")
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = MujocoLegConfig(seed=args.seed)

    env = TreadmillEnv(plant_config=config, frame_skip=4)
    model = rl_model("ppo", env, args.seed)
    model.learn(total_timesteps=round(args.hours * 3600 * config.tick_hz / env.frame_skip))
    obs, _ = env.reset(seed=args.seed + 1000)
    positions, activations, truncated = [], [], False
    while not truncated:
        action, _ = model.predict(model.get_env().normalize_obs(obs), deterministic=True)
        obs, _, _, truncated, info = env.step(action)
        positions.append(obs[:2])
        activations.append(obs[5:8])
    print(
        json.dumps(
            {
                "method": "ppo",
                "belt_travel_mm": round(info["belt_travel_mm"], 1),
                "energy_j": round(info["energy_used_j"], 1),
                **describe(np.array(positions), np.array(activations), env.dt),
            }
        )
    )

    result = run_treadmill(
        Learner(LearnerConfig(seed=args.seed)),
        PlantRig(MujocoLeg(config)),
        SearchConfig(),
        LimitCycleConfig(),
    )
    best = max(result.reports, key=lambda r: r.outcome.reward_mm).outcome
    print(
        json.dumps(
            {
                "method": "g2p",
                "belt_travel_mm": round(best.reward_mm, 1),
                "energy_j": round(best.energy_j, 1),
                **describe(best.recording.position_rad, best.recording.activation, 1.0 / config.tick_hz),
            }
        )
    )


if __name__ == "__main__":
    main()
