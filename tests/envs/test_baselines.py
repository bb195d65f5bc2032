"""The comparison's pieces: a tiny PPO run that learns in a known direction; curve summaries."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

from g2p.baselines import (
    Curve,
    Episode,
    EpisodeLog,
    chance_threshold_mm,
    curve_summary,
    random_patterns_curve,
    rl_curve,
)
from g2p.envs import TreadmillEnv
from g2p.limit_cycle import LimitCycleConfig
from g2p.sim import MujocoLegConfig


def _mean_action(model: PPO, env: TreadmillEnv, seed: int) -> float:
    obs, _ = env.reset(seed=seed)
    actions = []
    for _ in range(env.episode_ticks // env.frame_skip):
        action, _ = model.predict(obs, deterministic=True)
        actions.append(np.clip(action, 0.0, 1.0))
        obs, *_ = env.step(action)
    return float(np.mean(actions))


@pytest.mark.slow
def test_tiny_ppo_learns_to_draw_more_energy() -> None:
    """Known direction: rewarded for the energy its motors draw, PPO raises its activations in 4096 steps.

    (The untrained policy's mean action is about 0, which the rig clamps to the baseline: saving energy
    could not be learned from there.)
    """
    torch.set_num_threads(1)
    env = TreadmillEnv(
        cycle=LimitCycleConfig(n_cycles=1), frame_skip=4, forward_reward_weight=0.0, energy_cost_weight=-1.0
    )
    model = PPO("MlpPolicy", env, seed=0, device="cpu", n_steps=256, batch_size=64, learning_rate=3e-3)
    before = _mean_action(model, env, seed=1)
    model.learn(total_timesteps=4096)
    after = _mean_action(model, env, seed=1)
    assert after > before + 0.1, (before, after)


def test_episode_log_and_rig_time() -> None:
    """Every finished episode is logged with the plant's clock: one episode = its ticks of rig time."""
    env = EpisodeLog(TreadmillEnv(cycle=LimitCycleConfig(n_cycles=1), frame_skip=8))
    for seed in (0, 1):
        env.reset(seed=seed)
        truncated = False
        while not truncated:
            _, _, _, truncated, info = env.step(np.full(3, 0.5, dtype=np.float32))
    assert len(env.episodes) == 2
    # 160 ticks of 12.8 ms, each jittered by up to 0.8 ms (mean 0).
    assert env.episodes[1].rig_time_s == pytest.approx(2 * 80 / 78.0, rel=5e-3)
    assert env.episodes[1].reward_mm == info["belt_travel_mm"]


def test_rl_curve_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="method"):
        rl_curve("dqn", 0, 10.0)
    with pytest.raises(ValueError, match="budget_s"):
        rl_curve("ppo", 0, 0.0)


def test_curve_summary_known_answers() -> None:
    episodes = [Episode(20.0, 10.0, 1.0), Episode(500.0, 70.0, 1.0), Episode(3000.0, 150.0, 1.0)]
    s = curve_summary(Curve([*episodes, Episode(5000.0, 90.0, 1.0)], 5010.0))
    assert s["rig_time_to_threshold_s"] == 500.0
    assert s["best_mm_10min"] == 70.0 and s["best_mm_1h"] == 150.0 and s["best_mm"] == 150.0
    assert s["rig_time_s"] == 5010.0 and s["episodes"] == 4
    never = curve_summary(Curve([Episode(700.0, 10.0, 1.0)], 700.0))
    assert never["rig_time_to_threshold_s"] is None and never["best_mm_10min"] is None
    assert never["best_mm_1h"] == 10.0


def test_random_patterns_search_until_the_budget_on_the_rig_as_it_runs() -> None:
    """Episodes of random periodic patterns until the budget: each logged with its belt travel; between two
    episodes' ends, an episode's ticks and the reset's 1 s; the same seed gives the same curve."""
    cycle = LimitCycleConfig(n_cycles=1)
    curve = random_patterns_curve(3, 10.0, cycle=cycle)
    times = np.array([e.rig_time_s for e in curve.episodes])
    assert times[-2] < 10.0 <= times[-1] == curve.rig_time_s
    # 80 ticks of 12.8 ms and 78 ticks of reset, each jittered by up to 0.8 ms (mean 0)
    np.testing.assert_allclose(np.diff(times), (80 + 78) / 78.0, atol=0.02)
    rewards = [e.reward_mm for e in curve.episodes]
    assert len(set(rewards)) == len(rewards)  # a new pattern each episode
    again = random_patterns_curve(3, 10.0, cycle=cycle)
    assert [e.reward_mm for e in again.episodes] == rewards
    with pytest.raises(ValueError, match="budget_s"):
        random_patterns_curve(0, 0.0)


def test_chance_threshold_is_a_quantile_of_random_episodes() -> None:
    config = MujocoLegConfig(seed=2)
    low, high = (chance_threshold_mm(config, episodes=6, quantile=q, seed=1) for q in (0.1, 0.9))
    assert low < high  # the same six episodes, a higher quantile
    assert chance_threshold_mm(config, episodes=6, quantile=0.9, seed=1) == high
    with pytest.raises(ValueError, match="quantile"):
        chance_threshold_mm(config, episodes=1)
