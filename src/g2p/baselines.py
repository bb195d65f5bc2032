"""G2P against model-free reinforcement learning on the same simulated rig, measured in rig time.

One job is one method and one seed on a fresh simulated rig (MujocoLeg), to a budget of rig time (simulated
seconds of interaction; babbling counts for G2P). Every 20-cycle episode (RL) or attempt (G2P) is logged
with the rig time at its end and its belt travel, the reward G2P gives an attempt:

    g2p_curve(seed)        the paper's G2P: 5 min of babbling, exploration, 15 exploitation attempts
    rl_curve("ppo" | "sac", seed, budget_s)    Stable-Baselines3 on g2p/Treadmill-v0

    random_patterns_curve(seed, budget_s)     the trivial baseline: the best of random open-loop patterns

`curve_summary` reduces a curve to the benchmark's figures (benchmarks/bench_rl.py, docs/RL.md), and
`chance_threshold_mm` finds a threshold relative to chance on a rig: a quantile of random episodes.
Hyperparameters are the RL Zoo's for MuJoCo tasks (rl-baselines3-zoo hyperparams/ppo.yml and sac.yml):
PPO with SB3's defaults and VecNormalize on observations and rewards; SAC with SB3's defaults and
learning_starts 10,000.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from g2p.envs import TreadmillEnv
from g2p.experiments import run_treadmill
from g2p.learner import Learner, LearnerConfig
from g2p.limit_cycle import LimitCycleConfig
from g2p.rig import PlantRig
from g2p.search import SearchConfig
from g2p.sim import MujocoLeg, MujocoLegConfig

RL_METHODS = ("ppo", "sac")
METHODS = ("g2p", *RL_METHODS, "random")
# The paper's exploration threshold (mm of belt travel in one 20-cycle attempt).
THRESHOLD_MM = 64.0
# Rig-time marks at which the best reward so far is reported (s): 10 min and 1 h.
MARKS_S = (600.0, 3600.0)


@dataclass(frozen=True)
class Curve:
    """A job's learning curve.

    Attributes:
        episodes: every finished 20-cycle episode or attempt, in order.
        rig_time_s: the rig time the job used in all (s; an RL run's last, unfinished episode included).
    """

    episodes: list[Episode]
    rig_time_s: float


@dataclass(frozen=True)
class Episode:
    """One 20-cycle episode or attempt.

    Attributes:
        rig_time_s: rig time at its end, counted from the rig's start (s).
        reward_mm: belt travel over it (mm).
        energy_j: electrical energy the motors drew over it (J).
    """

    rig_time_s: float
    reward_mm: float
    energy_j: float


class EpisodeLog(gym.Wrapper[Any, Any, Any, Any]):
    """Logs every finished episode of a TreadmillEnv on the simulated rig, with the plant's clock."""

    def __init__(self, env: gym.Env[Any, Any]) -> None:
        super().__init__(env)
        plant = env.unwrapped.plant  # type: ignore[attr-defined]
        if not isinstance(plant, MujocoLeg):
            raise ValueError("EpisodeLog needs the simulated rig (its clock is the rig time)")
        self._plant = plant
        self.episodes: list[Episode] = []

    @property
    def rig_time_s(self) -> float:
        """The rig's clock: rig time since the plant was made (s)."""
        return self._plant.time_s

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Step; log the episode when it ends."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            self.episodes.append(
                Episode(self._plant.time_s, float(info["belt_travel_mm"]), float(info["energy_used_j"]))
            )
        return obs, reward, terminated, truncated, info


def g2p_curve(seed: int, plant_config: MujocoLegConfig | None = None) -> Curve:
    """The paper's G2P on a fresh simulated rig: every attempt, with the rig time babbling included."""
    cfg = plant_config if plant_config is not None else MujocoLegConfig(seed=seed)
    learner = Learner(LearnerConfig(seed=seed))
    plant = MujocoLeg(cfg)
    result = run_treadmill(learner, PlantRig(plant), SearchConfig(), LimitCycleConfig())
    episodes = [
        Episode(float(r.outcome.recording.t_s[-1]), r.outcome.reward_mm, r.outcome.energy_j)
        for r in result.reports
    ]
    return Curve(episodes, plant.time_s)


# The rig as it runs, for every method of the comparison (LegEnv's options): a command plays from the tick
# after the one it arrives in (the real-time rig's delay), and a reset holds baseline 1 s with the windings
# keeping their heat (the hardware's reset holds baseline at least 0.5 s and until the joints have been
# still for 0.5 s: g2p.hardware.leg).
RIG_AS_IT_RUNS: dict[str, Any] = {"action_delay_ticks": 1, "reset_s": 1.0}


def random_patterns_curve(
    seed: int,
    budget_s: float,
    plant_config: MujocoLegConfig | None = None,
    cycle: LimitCycleConfig | None = None,
) -> Curve:
    """The trivial baseline: random open-loop patterns, one per episode, until `budget_s` of rig time.

    Each pattern is periodic: per motor, `n_spokes` activations drawn uniformly in [0, 1], linearly
    interpolated around the cycle (80 ticks) and played for the episode's `n_cycles` cycles, tick by tick,
    on the rig as it runs (RIG_AS_IT_RUNS). Its best-so-far is what search without any model finds.

    Args:
        seed: seed of the patterns and of the rig.
        budget_s: rig time to search for (s; resets included); the episode that crosses it is the last.
        plant_config: the simulated rig (default: MujocoLegConfig(seed=seed)).
        cycle: the episodes' timing (default: LimitCycleConfig(), one G2P attempt).

    Raises:
        ValueError: a non-positive budget.
    """
    if not (math.isfinite(budget_s) and budget_s > 0):
        raise ValueError(f"budget_s: must be > 0, got {budget_s}")
    cfg = plant_config if plant_config is not None else MujocoLegConfig(seed=seed)
    log = EpisodeLog(TreadmillEnv(plant_config=cfg, cycle=cycle, reset_noise_scale=0.0, **RIG_AS_IT_RUNS))
    env: TreadmillEnv = log.unwrapped  # type: ignore[assignment]
    rng = np.random.default_rng(seed)
    m, spokes = env.cycle.samples_per_cycle, env.cycle.n_spokes
    phase = np.arange(m) / m * spokes  # each tick's position around the cycle, in spokes
    log.reset(seed=seed)
    while True:
        levels = rng.uniform(0.0, 1.0, (spokes, 3))
        closed = np.vstack([levels, levels[:1]])  # the cycle returns to its first spoke
        pattern = np.stack([np.interp(phase, np.arange(spokes + 1), closed[:, k]) for k in range(3)], axis=1)
        pattern = pattern.astype(np.float32)
        tick, terminated, truncated = 0, False, False
        while not (terminated or truncated):  # the episode's last tick truncates it
            _, _, terminated, truncated, _ = log.step(pattern[tick % m])
            tick += 1
        if log.rig_time_s >= budget_s:
            break
        log.reset()
    rig_time_s = log.rig_time_s
    log.close()
    return Curve(log.episodes, rig_time_s)


def chance_threshold_mm(
    plant_config: MujocoLegConfig,
    episodes: int = 100,
    quantile: float = 0.95,
    frame_skip: int = 4,
    seed: int = 0,
) -> float:
    """A threshold relative to chance on a rig: the `quantile` of random episodes' belt travel (mm).

    Each episode plays uniformly random actions, a new one every `frame_skip` ticks (a model-free
    learner's first episodes), on the rig as it runs (RIG_AS_IT_RUNS); a method that crosses the threshold
    has found what chance finds in 1 of 1 / (1 - quantile) episodes.

    Raises:
        ValueError: fewer than 2 episodes, or a quantile outside (0, 1).
    """
    if episodes < 2 or not 0 < quantile < 1:
        raise ValueError(f"need episodes >= 2 and 0 < quantile < 1, got {episodes}, {quantile}")
    env = TreadmillEnv(plant_config=plant_config, frame_skip=frame_skip, **RIG_AS_IT_RUNS)
    env.action_space.seed(seed)
    travel = []
    env.reset(seed=seed)
    for _ in range(episodes):
        terminated = truncated = False
        info: dict[str, Any] = {}
        while not (terminated or truncated):
            _, _, terminated, truncated, info = env.step(env.action_space.sample())
        travel.append(float(info["belt_travel_mm"]))
        env.reset()
    env.close()
    return float(np.quantile(travel, quantile))


def rl_model(method: str, env: gym.Env[Any, Any], seed: int) -> Any:
    """A Stable-Baselines3 learner for `env` with the RL Zoo's MuJoCo hyperparameters (see the module).

    PPO trains on `VecNormalize(env)` (observations and rewards normalized): act with
    `model.predict(model.get_env().normalize_obs(obs))`. SAC trains on `env` as it is.

    Raises:
        ValueError: an unknown method.
    """
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    if method == "ppo":
        return PPO("MlpPolicy", VecNormalize(DummyVecEnv([lambda: env])), seed=seed, device="cpu")
    if method == "sac":
        return SAC("MlpPolicy", env, seed=seed, device="cpu", learning_starts=10_000)
    raise ValueError(f"method: expected one of {RL_METHODS}, got {method!r}")


def rl_curve(
    method: str,
    seed: int,
    budget_s: float,
    frame_skip: int = 4,
    plant_config: MujocoLegConfig | None = None,
) -> Curve:
    """PPO or SAC (Stable-Baselines3) on g2p/Treadmill-v0 for `budget_s` of rig time: its training episodes.

    Args:
        method: "ppo" or "sac".
        seed: seed of the learner, the environment and the rig.
        budget_s: rig time to train for (s); rounded up to whole steps.
        frame_skip: ticks each action is held for (4: 19.5 Hz control).
        plant_config: the simulated rig (default: MujocoLegConfig(seed=seed)).

    Raises:
        ValueError: an unknown method or a non-positive budget.
    """
    if method not in RL_METHODS:
        raise ValueError(f"method: expected one of {RL_METHODS}, got {method!r}")
    if not (math.isfinite(budget_s) and budget_s > 0):
        raise ValueError(f"budget_s: must be > 0, got {budget_s}")
    cfg = plant_config if plant_config is not None else MujocoLegConfig(seed=seed)
    log = EpisodeLog(TreadmillEnv(plant_config=cfg, frame_skip=frame_skip))
    model = rl_model(method, log, seed)
    model.learn(total_timesteps=math.ceil(budget_s * cfg.tick_hz / frame_skip))
    rig_time_s = log.rig_time_s
    log.close()
    return Curve(log.episodes, rig_time_s)


def curve_summary(curve: Curve, threshold_mm: float = THRESHOLD_MM) -> dict[str, Any]:
    """The benchmark's figures of one curve.

    Returns:
        rig_time_to_threshold_s: rig time at the end of the first episode above `threshold_mm` (None if
            none was); best_mm_10min, best_mm_1h: the best reward among episodes ended by 600 s and 3600 s
            (None when none had ended); best_mm: the best of all; rig_time_s: the rig time used;
            episodes: how many.
    """
    episodes = curve.episodes
    times = np.array([e.rig_time_s for e in episodes])
    rewards = np.array([e.reward_mm for e in episodes])
    above = np.flatnonzero(rewards > threshold_mm)

    def best_by(t_s: float) -> float | None:
        done = rewards[times <= t_s]
        return float(done.max()) if len(done) else None

    return {
        "rig_time_to_threshold_s": float(times[above[0]]) if len(above) else None,
        "best_mm_10min": best_by(MARKS_S[0]),
        "best_mm_1h": best_by(MARKS_S[1]),
        "best_mm": float(rewards.max()) if len(rewards) else None,
        "rig_time_s": curve.rig_time_s,
        "episodes": len(episodes),
    }


def run_method(
    method: str, seed: int, budget_s: float, frame_skip: int = 4, calibration: str = ""
) -> dict[str, Any]:
    """One job of the comparison: the curve, its summary, and the job's wall and CPU time (s).

    `calibration` chooses the simulated rig (MujocoLegConfig.calibration: "" the default, "paper" the
    paper-like rig).
    """
    wall0, cpu0 = time.perf_counter(), time.process_time()
    cfg = MujocoLegConfig(seed=seed, calibration=calibration)
    if method == "g2p":
        curve = g2p_curve(seed, cfg)
    elif method == "random":
        curve = random_patterns_curve(seed, budget_s, cfg)
    else:
        curve = rl_curve(method, seed, budget_s, frame_skip, cfg)
    return {
        **curve_summary(curve),
        "wall_s": time.perf_counter() - wall0,
        "cpu_s": time.process_time() - cpu0,
        "curve_rig_time_s": [e.rig_time_s for e in curve.episodes],
        "curve_reward_mm": [e.reward_mm for e in curve.episodes],
    }
