"""What gait each method of the comparison ends with, on the same simulated rig run as it runs.

    scripts/with-env python benchmarks/bench_rl_gait.py --calibration paper --seed 0

Runs each method as bench_rl does (g2p.rl.baselines.method_curve, --budget-min of rig time), rolls its
final policy out for one held-out 20-cycle episode (as g2p.rl.baselines.evaluate does), and describes the
gait: belt travel (mm), energy (J) and energy per mm, the joints' ranges (rad), the dominant frequency of
the hip angle (Hz), the mean applied activations, and the share of ticks at which each motor is at its
baseline (0.15) or saturated (>= 0.98). Prints one JSON line per method.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from g2p.rl.baselines import HELD_OUT_SEED, RIG_AS_IT_RUNS, Curve, method_curve
from g2p.rl.envs import TreadmillEnv
from g2p.safety import BASELINE_ACTIVATION
from g2p.sim import MujocoLegConfig


def describe(position_rad: np.ndarray, activation: np.ndarray, dt_s: float) -> dict[str, Any]:
    """A gait from its ticks: positions (N, 2) (rad) and applied activations (N, 3), dt_s apart (s)."""
    hip = position_rad[:, 0] - position_rad[:, 0].mean()
    freq = np.fft.rfftfreq(len(hip), d=dt_s)
    spectrum = np.abs(np.fft.rfft(hip))
    return {
        "joint_range_rad": np.round(np.ptp(position_rad, axis=0), 3).tolist(),
        "hip_frequency_hz": round(float(freq[1 + np.argmax(spectrum[1:])]), 3),
        "mean_activation": np.round(activation.mean(axis=0), 3).tolist(),
        "share_at_baseline": np.round(np.mean(activation <= BASELINE_ACTIVATION + 1e-6, axis=0), 3).tolist(),
        "share_saturated": np.round(np.mean(activation >= 0.98, axis=0), 3).tolist(),
    }


def rollout(curve: Curve, config: MujocoLegConfig) -> dict[str, Any]:
    """The curve's final policy on one held-out episode of the rig as it runs, described."""
    assert curve.policy is not None
    seed = config.seed + HELD_OUT_SEED
    env = TreadmillEnv(plant_config=replace(config, seed=seed), frame_skip=curve.frame_skip, **RIG_AS_IT_RUNS)
    obs, _ = env.reset(seed=seed)
    positions, activations, done = [], [], False
    info: dict[str, Any] = {}
    while not done:
        obs, _, terminated, truncated, info = env.step(curve.policy(obs, env.ticks))
        positions.append(obs[:2])
        activations.append(obs[5:8])
        done = terminated or truncated
    env.close()
    travel, energy = float(info["belt_travel_mm"]), float(info["energy_used_j"])
    return {
        "belt_travel_mm": round(travel, 1),
        "energy_j": round(energy, 1),
        "j_per_mm": round(energy / travel, 2) if travel > 0 else None,
        "best_training_mm": round(max(e.reward_mm for e in curve.episodes), 1),
        **describe(np.array(positions), np.array(activations), env.dt),
    }


def main() -> None:
    """Run each method, roll its final policy out, describe it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--calibration", default="", help='the simulated rig: "" (default) or "paper"')
    parser.add_argument("--budget-min", type=float, default=60.0, help="rig time per method (min)")
    parser.add_argument("--methods", default="g2p,random,ppo")
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = MujocoLegConfig(seed=args.seed, calibration=args.calibration)
    budget_s = args.budget_min * 60.0
    for method in args.methods.split(","):
        curve = method_curve(method, args.seed, budget_s, config)
        print(json.dumps({"method": method, **rollout(curve, config)}), flush=True)


if __name__ == "__main__":
    main()
