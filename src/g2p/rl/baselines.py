"""G2P against model-free reinforcement learning on the same simulated rig, measured in rig time.

One job is one method and one seed on a fresh simulated rig (MujocoLeg) run as the real rig runs
(RIG_AS_IT_RUNS: its action delay, resets charged as rig time, the windings' heat kept), to a budget of
rig time (simulated seconds of interaction; G2P's babbling counts). Every 20-cycle episode (RL) or attempt
(G2P) is logged with the rig time at its end, its belt travel and its energy; at the end, the method's
final policy is evaluated deterministically on held-out episodes (`evaluate`):

    g2p_curve(seed, budget_s)        G2P: babbling, exploration, then exploitation until the budget
    g2p_then_rl_curve(seed, budget_s)    G2P's run, then PPO from its best gait (a residual policy)
    rl_curve("ppo" | "sac" | "tqc", seed, budget_s)    Stable-Baselines3 / sb3-contrib on g2p/Treadmill-v0
    random_patterns_curve(seed, budget_s)     the trivial baseline: the best of random open-loop patterns

`curve_summary` reduces a curve to the benchmark's figures (benchmarks/bench_rl.py, docs/RL.md), and
`chance_threshold_mm` finds a threshold relative to chance on a rig: a quantile of random episodes.
Hyperparameters are the RL Zoo's for MuJoCo tasks (rl-baselines3-zoo hyperparams/ppo.yml and sac.yml): PPO
with SB3's defaults and VecNormalize on observations and rewards; SAC with SB3's defaults and
learning_starts 10,000. TQC, the sample-efficient baseline, has sb3-contrib's defaults and learning_starts
1,000, as the RL Zoo's real-robot entries start early (tqc.yml, WalkingBertSim: 1,200): its updates start
after 51 s of rig time at 19.5 Hz, not 8.5 min.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike, NDArray

from g2p.learning.attempt import AttemptOutcome
from g2p.learning.experiments import TreadmillRun
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.search import SearchConfig
from g2p.plant import N_MOTORS
from g2p.rig import PlantRig, RigError
from g2p.rl.envs import TreadmillEnv
from g2p.safety import BASELINE_ACTIVATION
from g2p.sim import MujocoLeg, MujocoLegConfig

RL_METHODS = ("ppo", "sac", "tqc")
METHODS = ("g2p", "g2p_ppo", *RL_METHODS, "random")
# The paper's exploration threshold (mm of belt travel in one 20-cycle attempt).
THRESHOLD_MM = 64.0
# Rig-time marks at which the best reward so far is reported (s): 2, 10, 30 and 60 min.
MARKS_S = (120.0, 600.0, 1800.0, 3600.0)
# Held-out episodes each final policy is evaluated on, and the offset of their rig's seed from the job's.
EVAL_EPISODES = 5
HELD_OUT_SEED = 1_000_000
# G2P-then-RL: the residual policy moves each activation by at most this much from G2P's gait.
RESIDUAL_SCALE = 0.3

# The rig as it runs, for every method of the comparison (LegEnv's options): a command plays from the tick
# after the one it arrives in (the real-time rig's delay), and a reset holds baseline 1 s with the windings
# keeping their heat (the hardware's reset holds baseline at least 0.5 s and until the joints have been
# still for 0.5 s: g2p.hardware.leg).
RIG_AS_IT_RUNS: dict[str, Any] = {"action_delay_ticks": 1, "reset_s": 1.0}

Policy = Callable[[NDArray[np.float64], int], NDArray[np.float32]]
"""A final policy: (observation, the episode's ticks played so far) -> the step's action."""


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


@dataclass(frozen=True)
class Curve:
    """A job's learning curve, and the policy it ends with.

    Attributes:
        episodes: every finished 20-cycle episode or attempt, in order.
        rig_time_s: the rig time the job used in all (s; an RL run's last, unfinished episode included).
        policy: the method's final policy, to evaluate on held-out episodes (None: not kept).
        frame_skip: ticks the policy holds each action for.
        marks: the method's own figures, e.g. G2P's "paper_stop_s" (rig time of the paper's stop, s) and
            "faults" (attempts a limit tripped).
    """

    episodes: list[Episode]
    rig_time_s: float
    policy: Policy | None = None
    frame_skip: int = 1
    marks: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Evaluation:
    """A final policy played deterministically on held-out episodes of the rig as it runs.

    Attributes:
        travel_mm: each episode's belt travel, shape (episodes,) (mm).
        energy_j: each episode's electrical energy, shape (episodes,) (J).
    """

    travel_mm: NDArray[np.float64]
    energy_j: NDArray[np.float64]

    @property
    def j_per_mm(self) -> float | None:
        """Energy per mm of belt travel over all episodes (J/mm); None when they travelled nowhere forward."""
        travel = float(self.travel_mm.sum())
        return float(self.energy_j.sum()) / travel if travel > 0 else None


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


class RigWithResets(PlantRig):
    """A PlantRig whose reset holds baseline `reset_s` after putting the plant at rest.

    As the rig as it runs does (RIG_AS_IT_RUNS): G2P's resets, before babbling and before each attempt,
    cost rig time as the RL methods' do.
    """

    def __init__(self, plant: MujocoLeg, reset_s: float) -> None:
        super().__init__(plant)
        self._hold = np.full((round(reset_s * plant.tick_hz), N_MOTORS), BASELINE_ACTIVATION)

    def reset(self) -> None:
        """Put the plant at rest, then hold baseline for the reset's time."""
        super().reset()
        if len(self._hold):
            self.play(self._hold)


def open_loop_policy(activations: NDArray[np.float64], delay_ticks: int) -> Policy:
    """A policy that plays an open-loop sequence (N, 3), one row per tick, on a rig with `delay_ticks`.

    A step's action plays `delay_ticks` ticks later, so the step at tick t sends row t + delay (cyclic).
    """
    seq = np.asarray(activations, dtype=np.float32)

    def act(_obs: NDArray[np.float64], tick: int) -> NDArray[np.float32]:
        row: NDArray[np.float32] = seq[(tick + delay_ticks) % len(seq)]
        return row

    return act


def evaluate(
    policy: Policy,
    plant_config: MujocoLegConfig,
    frame_skip: int = 1,
    episodes: int = EVAL_EPISODES,
) -> Evaluation:
    """Play `policy` on `episodes` held-out episodes of the rig as it runs (no learning).

    The rig is `plant_config` with its seed moved by HELD_OUT_SEED: its tick jitter and each episode's
    reset noise (Gymnasium's 5e-3) were never seen in training.
    """
    seed = plant_config.seed + HELD_OUT_SEED
    env = TreadmillEnv(plant_config=replace(plant_config, seed=seed), frame_skip=frame_skip, **RIG_AS_IT_RUNS)
    travel, energy = np.zeros(episodes), np.zeros(episodes)
    obs, _ = env.reset(seed=seed)
    for k in range(episodes):
        if k:
            obs, _ = env.reset()
        done = False
        info: dict[str, Any] = {}
        while not done:
            obs, _, terminated, truncated, info = env.step(policy(obs, env.ticks))
            done = terminated or truncated
        travel[k], energy[k] = info["belt_travel_mm"], info["energy_used_j"]
    env.close()
    return Evaluation(travel, energy)


def _g2p_run(
    seed: int,
    plant: MujocoLeg,
    budget_s: float,
    learner_config: LearnerConfig | None,
    keep_searching: bool = True,
    cycle: LimitCycleConfig | None = None,
) -> tuple[list[AttemptOutcome], dict[str, float]]:
    """G2P on `plant`: babble, then attempts until `budget_s` of rig time.

    With `keep_searching` the search goes on exploiting after the paper's 15 attempts: each draw is around
    the best gait so far with the paper's reward-dependent sigma, and each attempt refines the map; else
    it stops there, as the paper's does.

    Returns every attempt's outcome, and the curve's marks: `paper_stop_s`, the rig time at the paper's
    stop (after its 15th exploitation attempt; absent if the budget ended first), and `faults`, the
    attempts a limit tripped.
    """
    rig = RigWithResets(plant, RIG_AS_IT_RUNS["reset_s"])
    learner = Learner(learner_config if learner_config is not None else LearnerConfig(seed=seed))
    learner.babble(rig)
    paper = SearchConfig()
    search = replace(paper, exploitation_attempts=2**31) if keep_searching else paper
    run = TreadmillRun(learner, search, cycle or LimitCycleConfig())
    outcomes: list[AttemptOutcome] = []
    paper_stop_s = None
    faults = 0
    while not run.finished and plant.time_s < budget_s:
        try:
            outcomes.append(run.next_attempt(rig).outcome)
        except RigError:
            # A limit tripped mid-attempt (a derailed tendon, a cut-out): as for an RL episode, the attempt
            # ends there and scores nothing, its rig time spent; the next reset puts the rig right, and the
            # run tries the same features again (TreadmillRun's retry, as after a fault on the hardware).
            faults += 1
        if paper_stop_s is None and run.search.n_exploitation == paper.exploitation_attempts:
            paper_stop_s = plant.time_s
    marks = {"faults": float(faults)}
    return outcomes, marks if paper_stop_s is None else {**marks, "paper_stop_s": paper_stop_s}


def _episodes(outcomes: list[AttemptOutcome]) -> list[Episode]:
    return [Episode(float(o.recording.t_s[-1]), o.reward_mm, o.energy_j) for o in outcomes]


def _best(outcomes: list[AttemptOutcome]) -> AttemptOutcome:
    return max(outcomes, key=lambda o: o.reward_mm)


def g2p_curve(
    seed: int,
    budget_s: float,
    plant_config: MujocoLegConfig | None = None,
    learner_config: LearnerConfig | None = None,
    cycle: LimitCycleConfig | None = None,
) -> Curve:
    """G2P on a fresh simulated rig run as it runs, until `budget_s` of rig time, babbling included.

    Exploitation goes on after the paper's 15 attempts (new draws around the best gait, the map refined
    after each); the curve's mark "paper_stop_s" is where the paper's run ends. The final policy replays
    the best attempt's activations (its gait, open loop).

    Args:
        seed: seed of the learner and of the rig.
        budget_s: rig time (s); the attempt that crosses it is the last.
        plant_config: the simulated rig (default: MujocoLegConfig(seed=seed)).
        learner_config: the learner (default: LearnerConfig(seed=seed), the paper's 5 min of babbling).
        cycle: the limit cycles (default: LimitCycleConfig(), the paper's 20 cycles of 80 ticks).
    """
    _check_budget(budget_s)
    cfg = plant_config if plant_config is not None else MujocoLegConfig(seed=seed)
    plant = MujocoLeg(cfg)
    outcomes, marks = _g2p_run(seed, plant, budget_s, learner_config, cycle=cycle)
    rig_time_s = plant.time_s
    plant.close()
    policy = open_loop_policy(_best(outcomes).activations, RIG_AS_IT_RUNS["action_delay_ticks"])
    return Curve(_episodes(outcomes), rig_time_s, policy, 1, marks)


def random_patterns_curve(
    seed: int,
    budget_s: float,
    plant_config: MujocoLegConfig | None = None,
    cycle: LimitCycleConfig | None = None,
) -> Curve:
    """The trivial baseline: random open-loop patterns, one per episode, until `budget_s` of rig time.

    Each pattern is periodic: per motor, `n_spokes` activations drawn uniformly in [0, 1], linearly
    interpolated around the cycle (80 ticks) and played for the episode's `n_cycles` cycles, tick by tick,
    on the rig as it runs (RIG_AS_IT_RUNS). Its best-so-far is what search without any model finds; its
    final policy replays the best pattern.

    Args:
        seed: seed of the patterns and of the rig.
        budget_s: rig time to search for (s; resets included); the episode that crosses it is the last.
        plant_config: the simulated rig (default: MujocoLegConfig(seed=seed)).
        cycle: the episodes' timing (default: LimitCycleConfig(), one G2P attempt).

    Raises:
        ValueError: a non-positive budget.
    """
    _check_budget(budget_s)
    cfg = plant_config if plant_config is not None else MujocoLegConfig(seed=seed)
    log = EpisodeLog(TreadmillEnv(plant_config=cfg, cycle=cycle, reset_noise_scale=0.0, **RIG_AS_IT_RUNS))
    env: TreadmillEnv = log.unwrapped  # type: ignore[assignment]
    rng = np.random.default_rng(seed)
    m, spokes = env.cycle.samples_per_cycle, env.cycle.n_spokes
    phase = np.arange(m) / m * spokes  # each tick's position around the cycle, in spokes
    best: tuple[float, Policy] | None = None
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
        if best is None or log.episodes[-1].reward_mm > best[0]:
            # The pattern is what was sent (each row played a tick later): replayed, it is sent as it was.
            best = (log.episodes[-1].reward_mm, open_loop_policy(pattern, 0))
        if log.rig_time_s >= budget_s:
            break
        log.reset()
    rig_time_s = log.rig_time_s
    log.close()
    return Curve(log.episodes, rig_time_s, best[1], 1)


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


def rl_model(method: str, env: gym.Env[Any, Any], seed: int, **kwargs: Any) -> Any:
    """A learner for `env` with the hyperparameters of the module's docstring; `kwargs` override.

    PPO trains on `VecNormalize(env)` (observations and rewards normalized): act with
    `model.predict(model.get_env().normalize_obs(obs))`. SAC and TQC train on `env` as it is.

    Raises:
        ValueError: an unknown method.
    """
    from sb3_contrib import TQC
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    if method == "ppo":
        return PPO("MlpPolicy", VecNormalize(DummyVecEnv([lambda: env])), seed=seed, device="cpu", **kwargs)
    if method == "sac":
        return SAC("MlpPolicy", env, seed=seed, device="cpu", **{"learning_starts": 10_000, **kwargs})
    if method == "tqc":
        return TQC("MlpPolicy", env, seed=seed, device="cpu", **{"learning_starts": 1_000, **kwargs})
    raise ValueError(f"method: expected one of {RL_METHODS}, got {method!r}")


def _greedy(model: Any, obs_of: Callable[[NDArray[np.float64], int], NDArray[np.float64]]) -> Policy:
    """The deterministic policy of a trained model (PPO: through its VecNormalize's frozen statistics)."""
    vec = model.get_env()
    normalize = getattr(vec, "normalize_obs", None)
    if vec is not None and hasattr(vec, "training"):
        vec.training = False

    def act(obs: NDArray[np.float64], tick: int) -> NDArray[np.float32]:
        o = obs_of(obs, tick)
        action, _ = model.predict(normalize(o) if normalize else o, deterministic=True)
        return np.asarray(action, dtype=np.float32)

    return act


def rl_curve(
    method: str,
    seed: int,
    budget_s: float,
    frame_skip: int = 4,
    plant_config: MujocoLegConfig | None = None,
) -> Curve:
    """PPO, SAC or TQC on g2p/Treadmill-v0, on the rig as it runs, for `budget_s` of rig time.

    Args:
        method: "ppo", "sac" or "tqc".
        seed: seed of the learner, the environment and the rig.
        budget_s: rig time to train for (s; resets included); training stops at the step that reaches it.
        frame_skip: ticks each action is held for (4: 19.5 Hz control; 1: 78 Hz).
        plant_config: the simulated rig (default: MujocoLegConfig(seed=seed)).

    Raises:
        ValueError: an unknown method or a non-positive budget.
    """
    if method not in RL_METHODS:
        raise ValueError(f"method: expected one of {RL_METHODS}, got {method!r}")
    _check_budget(budget_s)
    cfg = plant_config if plant_config is not None else MujocoLegConfig(seed=seed)
    log = EpisodeLog(TreadmillEnv(plant_config=cfg, frame_skip=frame_skip, **RIG_AS_IT_RUNS))
    model = rl_model(method, log, seed)
    _learn(model, log, budget_s)
    rig_time_s = log.rig_time_s
    log.close()
    return Curve(log.episodes, rig_time_s, _greedy(model, lambda obs, _tick: obs), frame_skip)


def _learn(model: Any, log: EpisodeLog, budget_s: float) -> None:
    """Train until the rig's clock reaches `budget_s` (resets and cooling included), to within one step."""
    from stable_baselines3.common.callbacks import BaseCallback

    class UntilRigTime(BaseCallback):
        def _on_step(self) -> bool:
            return log.rig_time_s < budget_s

    model.learn(total_timesteps=2**62, callback=UntilRigTime())


class ResidualGait(gym.Wrapper[Any, Any, Any, Any]):
    """G2P's gait plus a learned correction: the base for RL that starts from G2P's best gait.

    The action a in [-1, 1]^3 plays as clip(gait[t] + RESIDUAL_SCALE a, 0, 1), gait the open-loop sequence
    of G2P's best attempt (one row per tick, sent a delay ahead as `open_loop_policy` does); a = 0 is G2P's
    gait. The observation is the rig's (8,) then the cycle's phase as (cos, sin). Needs frame_skip 1.
    """

    def __init__(self, env: gym.Env[Any, Any], gait: NDArray[np.float64]) -> None:
        super().__init__(env)
        leg: TreadmillEnv = env.unwrapped  # type: ignore[assignment]
        if leg.frame_skip != 1 or len(gait) != leg.episode_ticks:
            raise ValueError("ResidualGait: needs frame_skip 1 and one gait row per episode tick")
        self._gait = open_loop_policy(gait, leg.action_delay_ticks)
        self._period = leg.cycle.samples_per_cycle
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(N_MOTORS,), dtype=np.float32)
        n = env.observation_space.shape[0] + 2  # type: ignore[index]
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(n,), dtype=np.float64)

    def observe(self, obs: NDArray[np.float64], tick: int) -> NDArray[np.float64]:
        """The rig's observation with the cycle's phase at `tick` appended."""
        angle = 2 * math.pi * (tick % self._period) / self._period
        return np.concatenate([obs, [math.cos(angle), math.sin(angle)]])

    def play(self, residual: NDArray[np.float32], tick: int) -> NDArray[np.float32]:
        """The activations a residual action plays at `tick`, shape (3,)."""
        base = self._gait(np.zeros(0), tick)
        return np.clip(base + RESIDUAL_SCALE * np.asarray(residual, np.float32), 0.0, 1.0)

    def reset(self, **kwargs: Any) -> tuple[NDArray[np.float64], dict[str, Any]]:
        """Reset the rig; the phase starts at 0."""
        obs, info = self.env.reset(**kwargs)
        return self.observe(obs, 0), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Play the gait's tick plus the residual."""
        tick = self.env.unwrapped.ticks  # type: ignore[attr-defined]
        obs, reward, terminated, truncated, info = self.env.step(self.play(action, tick))
        return self.observe(obs, tick + 1), reward, terminated, truncated, info


def g2p_then_rl_curve(
    seed: int,
    budget_s: float,
    plant_config: MujocoLegConfig | None = None,
    learner_config: LearnerConfig | None = None,
) -> Curve:
    """G2P, then PPO from G2P's best gait, as the paper proposes, on one rig until `budget_s`.

    G2P runs as the paper does (to its 15th exploitation attempt, or the budget); PPO then trains a
    residual policy on the same rig (its clock, heat and wear carry on) at 78 Hz, the rate G2P's gait is
    played at (ResidualGait; PPO's initial policy has mean 0, G2P's gait, and log_std_init -1: each
    activation's exploration noise starts at RESIDUAL_SCALE x 0.37 = 0.11).

    Raises:
        ValueError: a non-positive budget.
    """
    _check_budget(budget_s)
    cfg = plant_config if plant_config is not None else MujocoLegConfig(seed=seed)
    plant = MujocoLeg(cfg)
    outcomes, marks = _g2p_run(seed, plant, budget_s, learner_config, keep_searching=False)
    episodes = _episodes(outcomes)
    gait = _best(outcomes).activations
    log = EpisodeLog(TreadmillEnv(plant=plant, **RIG_AS_IT_RUNS))
    residual = ResidualGait(log, gait)
    if plant.time_s < budget_s:
        model = rl_model("ppo", residual, seed, policy_kwargs={"log_std_init": -1.0})
        _learn(model, log, budget_s)
        greedy = _greedy(model, residual.observe)
        policy: Policy = lambda obs, tick: residual.play(greedy(obs, tick), tick)  # noqa: E731
    else:
        policy = open_loop_policy(gait, RIG_AS_IT_RUNS["action_delay_ticks"])
    rig_time_s = plant.time_s
    plant.close()
    return Curve(episodes + log.episodes, rig_time_s, policy, 1, marks)


def _check_budget(budget_s: float) -> None:
    if not (math.isfinite(budget_s) and budget_s > 0):
        raise ValueError(f"budget_s: must be > 0, got {budget_s}")


def best_by(rig_time_s: ArrayLike, reward_mm: ArrayLike, mark_s: float) -> float | None:
    """The best reward (mm) among episodes ended by rig time `mark_s` (s); None before the first ended.

    Args:
        rig_time_s: each episode's end (s), shape (E,).
        reward_mm: each episode's reward (mm), shape (E,).
        mark_s: the mark (s).
    """
    done = np.asarray(reward_mm)[np.asarray(rig_time_s) <= mark_s]
    return float(done.max()) if len(done) else None


def curve_summary(curve: Curve, threshold_mm: float = THRESHOLD_MM) -> dict[str, Any]:
    """The benchmark's figures of one curve.

    Returns:
        rig_time_to_threshold_s: rig time at the end of the first episode above `threshold_mm` (None if
            none was); best_mm_<m>min for each mark of MARKS_S: the best reward among episodes ended by it
            (None when none had ended); best_mm: the best of all; best_j_per_mm: the best episode's energy
            per mm of travel; rig_time_s: the rig time used; episodes: how many.
    """
    episodes = curve.episodes
    times = np.array([e.rig_time_s for e in episodes])
    rewards = np.array([e.reward_mm for e in episodes])
    above = np.flatnonzero(rewards > threshold_mm)

    best = episodes[int(np.argmax(rewards))] if episodes else None
    return {
        "rig_time_to_threshold_s": float(times[above[0]]) if len(above) else None,
        **{f"best_mm_{mark / 60:g}min": best_by(times, rewards, mark) for mark in MARKS_S},
        "best_mm": best.reward_mm if best else None,
        "best_j_per_mm": best.energy_j / best.reward_mm if best and best.reward_mm > 0 else None,
        "rig_time_s": curve.rig_time_s,
        "episodes": len(episodes),
    }


def method_curve(
    method: str,
    seed: int,
    budget_s: float,
    plant_config: MujocoLegConfig,
    frame_skip: int = 4,
    babbling_s: float = 0.0,
    cycle_ticks: int = 0,
    recent_attempts: int = 0,
) -> Curve:
    """One method's curve on `plant_config` (the arguments as `run_method`'s)."""
    learner = LearnerConfig(seed=seed, refine_recent_attempts=recent_attempts)
    if babbling_s:
        learner = replace(learner, babbling=replace(learner.babbling, duration_s=babbling_s))
    cycle = None
    if cycle_ticks:
        if cycle_ticks % 10 or 1600 % cycle_ticks:
            raise ValueError(f"cycle_ticks: a multiple of 10 that divides 1600, got {cycle_ticks}")
        cycle = LimitCycleConfig(samples_per_segment=cycle_ticks // 10, n_cycles=1600 // cycle_ticks)
    if method == "g2p":
        return g2p_curve(seed, budget_s, plant_config, learner, cycle)
    if method == "g2p_ppo":
        return g2p_then_rl_curve(seed, budget_s, plant_config, learner)
    if method == "random":
        return random_patterns_curve(seed, budget_s, plant_config)
    return rl_curve(method, seed, budget_s, frame_skip, plant_config)


def run_method(
    method: str,
    seed: int,
    budget_s: float,
    frame_skip: int = 4,
    calibration: str = "",
    threshold_mm: float = THRESHOLD_MM,
    babbling_s: float = 0.0,
    cycle_ticks: int = 0,
    recent_attempts: int = 0,
) -> dict[str, Any]:
    """One job of the comparison: the curve, its summary, the held-out evaluation, wall and CPU time (s).

    Args:
        method: one of METHODS.
        seed: seed of the method and of the rig.
        budget_s: rig time (s).
        frame_skip: the RL methods' ticks per action (G2P plays at 78 Hz; G2P-then-RL's PPO too).
        calibration: the simulated rig (MujocoLegConfig.calibration: "" the default, "paper" the
            paper-like rig).
        threshold_mm: the threshold the summary's rig time to threshold counts to.
        babbling_s: G2P's babbling (s); 0: the paper's 5 min.
        cycle_ticks: G2P's limit-cycle period (ticks, a multiple of its 10 spokes dividing 1600); 0: the
            paper's 80 (0.98 Hz). An attempt stays 1600 ticks: 1600 / cycle_ticks cycles.
        recent_attempts: G2P refines its map on the babbling and this many most recent attempts; 0:
            on every attempt (the paper's).
    """
    wall0, cpu0 = time.perf_counter(), time.process_time()
    cfg = MujocoLegConfig(seed=seed, calibration=calibration)
    curve = method_curve(method, seed, budget_s, cfg, frame_skip, babbling_s, cycle_ticks, recent_attempts)
    train_wall_s = time.perf_counter() - wall0
    assert curve.policy is not None
    held_out = evaluate(curve.policy, cfg, curve.frame_skip)
    return {
        **curve_summary(curve, threshold_mm),
        **curve.marks,
        "eval_mm": float(np.mean(held_out.travel_mm)),
        "eval_j_per_mm": held_out.j_per_mm,
        "eval_travel_mm": held_out.travel_mm.tolist(),
        "wall_s": train_wall_s,
        "cpu_s": time.process_time() - cpu0,
        "curve_rig_time_s": [e.rig_time_s for e in curve.episodes],
        "curve_reward_mm": [e.reward_mm for e in curve.episodes],
        "curve_energy_j": [e.energy_j for e in curve.episodes],
    }
