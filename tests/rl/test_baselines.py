"""The comparison's pieces: a tiny PPO run that learns in a known direction; what each method's rig charges;
replayed policies that play what they should; curve summaries."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

from g2p.learning.learner import LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.plant import TickSample
from g2p.rl import baselines
from g2p.rl.baselines import (
    RESIDUAL_SCALE,
    RIG_AS_IT_RUNS,
    Curve,
    Episode,
    EpisodeLog,
    ResidualGait,
    RigWithResets,
    chance_threshold_mm,
    curve_summary,
    evaluate,
    g2p_curve,
    g2p_then_rl_curve,
    open_loop_policy,
    random_patterns_curve,
    rl_curve,
    run_method,
)
from g2p.rl.envs import TreadmillEnv
from g2p.sim import MujocoLeg, MujocoLegConfig


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


def test_bad_arguments_are_refused_before_any_rig_time() -> None:
    with pytest.raises(ValueError, match="method"):
        rl_curve("dqn", 0, 10.0)
    with pytest.raises(ValueError, match="budget_s"):
        rl_curve("ppo", 0, 0.0)
    with pytest.raises(ValueError, match="cycle_ticks"):
        run_method("g2p", 0, 10.0, cycle_ticks=35)


def test_curve_summary_known_answers() -> None:
    episodes = [Episode(20.0, 10.0, 1.0), Episode(500.0, 70.0, 1.0), Episode(3000.0, 150.0, 30.0)]
    s = curve_summary(Curve([*episodes, Episode(5000.0, 90.0, 1.0)], 5010.0))
    assert s["rig_time_to_threshold_s"] == 500.0
    assert s["best_mm_2min"] == 10.0 and s["best_mm_10min"] == 70.0 and s["best_mm_30min"] == 70.0
    assert s["best_mm_60min"] == 150.0 and s["best_mm"] == 150.0 and s["best_j_per_mm"] == 0.2
    assert s["rig_time_s"] == 5010.0 and s["episodes"] == 4
    never = curve_summary(Curve([Episode(700.0, 10.0, 1.0)], 700.0), threshold_mm=20.0)
    assert never["rig_time_to_threshold_s"] is None and never["best_mm_10min"] is None
    assert never["best_mm_60min"] == 10.0


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


def _applied(env: TreadmillEnv, policy, episodes: int = 1) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The activations each tick applied (the observation's last 3 entries), shape (ticks, 3)."""
    obs, _ = env.reset(seed=0)
    applied, done = [], False
    while not done:
        obs, _, terminated, truncated, _ = env.step(policy(obs, env.ticks))
        applied.append(obs[-3:])
        done = terminated or truncated
    return np.array(applied)


def _smooth_sequence(ticks: int) -> np.ndarray:
    t = np.arange(ticks)[:, None]
    return 0.35 + 0.1 * np.sin(2 * np.pi * t / 80 + np.arange(3))


def test_an_open_loop_policy_plays_its_sequence_on_the_rig_as_it_runs() -> None:
    """Known answer: sent a delay ahead, each tick of the delayed rig applies the sequence's row for it."""
    cycle = LimitCycleConfig(n_cycles=2)
    sequence = _smooth_sequence(160)
    env = TreadmillEnv(cycle=cycle, reset_noise_scale=0.0, **RIG_AS_IT_RUNS)
    applied = _applied(env, open_loop_policy(sequence, RIG_AS_IT_RUNS["action_delay_ticks"]))
    np.testing.assert_allclose(applied[0], 0.15)  # tick 0 plays the reset's baseline
    # then the envelope's ramp limits the rise from baseline for two ticks
    np.testing.assert_array_less(applied[1:3], sequence[1:3] + 1e-9)
    np.testing.assert_allclose(applied[3:], sequence[3:], atol=1e-6)


def test_a_residual_of_zero_is_gs_gait_and_a_residual_moves_it_by_its_scale() -> None:
    cycle = LimitCycleConfig(n_cycles=2)
    gait = _smooth_sequence(160)
    residual = ResidualGait(TreadmillEnv(cycle=cycle, reset_noise_scale=0.0, **RIG_AS_IT_RUNS), gait)
    obs, _ = residual.reset(seed=0)
    assert obs.shape == residual.observation_space.shape == (10,)
    np.testing.assert_allclose(obs[-2:], [1.0, 0.0])  # the cycle's phase 0 as (cos, sin)
    applied = []
    for tick in range(160):
        action = np.zeros(3, np.float32) if tick < 100 else np.array([1.0, -1.0, 0.0], np.float32)
        obs, *_ = residual.step(action)
        applied.append(obs[-5:-2])
    np.testing.assert_allclose(np.array(applied)[3:100], gait[3:100], atol=1e-6)  # after the ramp
    # the rig applies at least its baseline, and its ramp limits the jump for two ticks
    moved = np.maximum(gait[103:] + RESIDUAL_SCALE * np.array([1.0, -1.0, 0.0]), 0.15)
    np.testing.assert_allclose(np.array(applied)[103:], moved, atol=1e-6)
    with pytest.raises(ValueError, match="frame_skip 1"):
        ResidualGait(TreadmillEnv(cycle=cycle, frame_skip=4), gait)


def test_a_reset_of_the_rig_as_it_runs_costs_its_time_for_g2p_too() -> None:
    """RigWithResets: a reset puts the plant at rest, then holds baseline reset_s (78 ticks of rig time)."""
    plant = MujocoLeg(MujocoLegConfig(seed=0))
    rig = RigWithResets(plant, 1.0)
    rig.reset()
    assert plant.time_s == pytest.approx(1.0, rel=5e-3)
    rig.play(np.full((10, 3), 0.3))
    rig.reset()
    assert plant.time_s == pytest.approx(2.0 + 10 / 78.0, rel=5e-3)
    plant.close()


def test_evaluate_is_deterministic_on_held_out_episodes() -> None:
    policy = open_loop_policy(_smooth_sequence(80), 1)
    config = MujocoLegConfig(seed=4)
    first, again = evaluate(policy, config, episodes=2), evaluate(policy, config, episodes=2)
    np.testing.assert_array_equal(first.travel_mm, again.travel_mm)
    assert first.travel_mm.shape == first.energy_j.shape == (2,)
    assert first.travel_mm[0] != first.travel_mm[1]  # each episode's reset noise is its own
    assert np.all(first.energy_j > 0)


def test_rl_runs_to_its_budget_of_rig_time_resets_included() -> None:
    """TQC (no update yet: its first 1,000 steps are random) for 50 s of rig time: each episode lasts its
    1,600 ticks, or less if the rig trips (random activations can pay cable into a slack tendon until the
    envelope trips), and a reset's 1 s follows it; it stops at the step that reaches the budget."""
    curve = rl_curve("tqc", 0, 50.0, frame_skip=4)
    times = np.array([e.rig_time_s for e in curve.episodes])
    durations = np.diff(np.r_[-1.0, times]) - 1.0  # between ends, less the reset's 78 ticks (1 s)
    assert len(times) >= 2 and np.all(durations > 0)
    assert np.all(durations <= 1600 / 78.0 * (1 + 5e-3))
    assert np.isclose(durations, 1600 / 78.0, rtol=5e-3).sum() >= 1  # at least one ran its 1,600 ticks
    assert 50.0 <= curve.rig_time_s < 50.0 + 4 / 78.0 + 0.01
    assert curve.policy is not None and curve.frame_skip == 4


@pytest.mark.slow
def test_g2p_searches_on_after_the_papers_stop_and_g2p_then_rl_starts_from_its_gait() -> None:
    """G2P with a budget goes on after its 15 exploitation attempts; G2P-then-RL's G2P is the paper's run,
    the same attempts bit for bit, then PPO's episodes on the same rig."""
    learner = LearnerConfig(seed=1)
    learner = LearnerConfig(seed=1, babbling=type(learner.babbling)(duration_s=20.0))
    g2p = g2p_curve(1, 600.0, learner_config=learner)
    times = np.array([e.rig_time_s for e in g2p.episodes])
    assert g2p.marks is not None and g2p.marks["paper_stop_s"] < times[-1]
    assert times[-2] < 600.0 <= times[-1] == pytest.approx(g2p.rig_time_s, abs=1e-9)
    # Each attempt: a 1 s reset, then 1600 ticks.
    np.testing.assert_allclose(np.diff(times), (78 + 1600) / 78.0, rtol=5e-3)
    both = g2p_then_rl_curve(1, g2p.marks["paper_stop_s"] + 60.0, learner_config=learner)
    assert both.marks == g2p.marks
    # G2P's episodes up to the one that ended at the paper's stop (the mark is that episode's end, summed
    # otherwise than the episodes' times: equal to within rounding, not bit for bit).
    n = int(np.argmin(np.abs(times - g2p.marks["paper_stop_s"]))) + 1
    assert times[n - 1] == pytest.approx(g2p.marks["paper_stop_s"], abs=1e-6)
    assert [e.reward_mm for e in both.episodes[:n]] == [e.reward_mm for e in g2p.episodes[:n]]
    # Then PPO's episodes (1600 ticks and a reset each, 21.5 s) on until the budget: two whole ones in 60 s.
    assert len(both.episodes) == n + 2
    assert both.rig_time_s >= g2p.marks["paper_stop_s"] + 60.0


class DerailsOnCue(MujocoLeg):
    """The simulated rig, whose tendon M1 derails on cue: on the `after_ticks`-th step after its `on_reset`-th
    reset, whatever the physics did. It trips as the plant's own limit does (g2p.sim.limits: the tendon
    carries no force, `fault` says why) and `reset` puts it right; the physical limits themselves are moved
    out of reach, so that the cue is the only trip."""

    def __init__(self, config: MujocoLegConfig, on_reset: int, after_ticks: int) -> None:
        super().__init__(config)
        self.limits = replace(self.limits, tendon_breaking_n=1e6, tendon_derail_payout_m=1e3)
        self.cue, self.resets, self.ticks, self.trips = (on_reset, after_ticks), 0, 0, 0
        self._derailed = ""

    @property
    def fault(self) -> str:
        return super().fault or self._derailed

    def reset(self) -> TickSample:
        self.resets, self.ticks, self._derailed = self.resets + 1, 0, ""
        return super().reset()  # re-tendons M1

    def step(self, activation: np.ndarray, period_s: float | None = None) -> TickSample:
        self.ticks += 1
        if (self.resets, self.ticks) == self.cue:
            self.model.tendon_stiffness[1] = 0.0  # off its spool: it carries no force
            self._derailed = "tendon M1 left its channel (on cue)"
            self.trips += 1
        return super().step(activation, period_s)


@pytest.mark.slow
def test_g2p_goes_on_after_an_attempt_trips_a_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    """Tendon M1 derails 210 ticks into the second attempt (its reset's 78 ticks, then 210 of its play): as
    an RL episode would, the attempt ends there, scoring nothing, the next reset puts the rig right and the
    run goes on to its budget. (The fault is cued: which attempt of a seeded run trips a limit by itself
    depends on the CPU's rounding.)"""
    hold_ticks, play_ticks = 78, 400  # a reset holds baseline 1 s; an attempt of 5 cycles of 80 ticks
    plants: list[DerailsOnCue] = []

    def derailing_leg(config: MujocoLegConfig) -> DerailsOnCue:
        # Resets: babbling's, the first attempt's, the second's.
        plants.append(DerailsOnCue(config, on_reset=3, after_ticks=hold_ticks + 210))
        return plants[-1]

    monkeypatch.setattr(baselines, "MujocoLeg", derailing_leg)
    learner = LearnerConfig(seed=3)
    learner = LearnerConfig(seed=3, babbling=type(learner.babbling)(duration_s=20.0))
    curve = g2p_curve(3, 60.0, learner_config=learner, cycle=LimitCycleConfig(n_cycles=5))
    (plant,) = plants
    assert plant.trips == 1 and curve.marks["faults"] == 1 and plant.fault == ""
    times = np.array([e.rig_time_s for e in curve.episodes])
    # Attempt 1, the fault (no episode), its retry, then attempts until the one that crosses the budget.
    assert len(times) >= 4 and times[-2] < 60.0 <= times[-1] == pytest.approx(curve.rig_time_s, abs=1e-9)
    # Between two attempts' ends: a reset and a play; around the fault also its reset and its 210 ticks.
    gaps = np.diff(times) * 78.0
    normal = hold_ticks + play_ticks
    np.testing.assert_allclose(gaps[1:], normal, atol=5)
    assert gaps[0] == pytest.approx(normal + hold_ticks + 210, abs=5)
