"""The rig's Gymnasium environments: API checks, determinism, rewards with known answers, rendering."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils import seeding
from gymnasium.utils.env_checker import check_env

import g2p.rl.envs
from g2p.learning.limit_cycle import LimitCycleConfig, cycle_kinematics
from g2p.rig.envelope import SafetyEnvelope
from g2p.rl.envs import TRACK_ID, TREADMILL_ID, TrackEnv, TreadmillEnv
from g2p.safety import BASELINE_ACTIVATION
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig

# A short episode (2 cycles, 160 ticks) keeps the tests fast; the defaults are checked on their own.
SHORT = LimitCycleConfig(n_cycles=2)


def _actions(n: int, seed: int = 7) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0.0, 1.0, (n, 3)).astype(np.float32)


@pytest.mark.parametrize("env_id", [TREADMILL_ID, TRACK_ID])
def test_check_env_passes(env_id: str) -> None:
    env = gym.make(env_id, cycle=LimitCycleConfig(n_cycles=1) if env_id == TREADMILL_ID else None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Box(-inf, inf) observations, as in Gymnasium's MuJoCo envs
        check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_defaults_are_a_g2p_attempt() -> None:
    """20 cycles of 80 ticks per episode; frame_skip divides them; spaces as documented."""
    env = TreadmillEnv(frame_skip=4)
    assert env.episode_ticks == 1600
    assert env.observation_space.shape == (8,)
    assert env.action_space.shape == (3,)
    assert env.dt == pytest.approx(4 / 78.0)
    env.reset(seed=0)
    n, truncated = 0, False
    while not truncated:
        _, _, terminated, truncated, info = env.step(np.full(3, 0.3, dtype=np.float32))
        assert not terminated
        n += 1
    assert n == 400 and info["ticks"] == 1600
    with pytest.raises(RuntimeError, match="truncated"):
        env.step(np.zeros(3, dtype=np.float32))
    env.close()
    with pytest.raises(ValueError, match="frame_skip"):
        TreadmillEnv(frame_skip=7)


@pytest.mark.parametrize("env_cls", [TreadmillEnv, TrackEnv])
def test_same_seed_same_episode(env_cls: type) -> None:
    """Two environments, and one environment reset twice, replay a seeded episode bit for bit."""
    actions = _actions(SHORT.samples_per_cycle * SHORT.n_cycles // 2)
    kwargs = {"cycle": SHORT if env_cls is TreadmillEnv else LimitCycleConfig.in_air(n_cycles=2)}

    def episode(env: gym.Env, seed: int) -> tuple[np.ndarray, np.ndarray]:
        obs = [env.reset(seed=seed)[0]]
        rewards = []
        for a in actions:
            o, r, _, _, _ = env.step(a)
            obs.append(o)
            rewards.append(r)
        return np.array(obs), np.array(rewards)

    a, b = env_cls(frame_skip=2, **kwargs), env_cls(frame_skip=2, **kwargs)
    first = episode(a, 11)
    np.testing.assert_array_equal(first[0], episode(b, 11)[0])
    again = episode(a, 11)
    np.testing.assert_array_equal(first[0], again[0])
    np.testing.assert_array_equal(first[1], again[1])
    assert not np.array_equal(first[0], episode(a, 12)[0])  # the seed matters (reset noise, jitter)


def test_treadmill_reward_is_the_belt_travel_the_plant_reports() -> None:
    """Known answer: the same seed's plant, played the same activations, reports the episode's travel."""
    seed, frame_skip = 5, 2
    config = MujocoLegConfig(seed=3)
    env = TreadmillEnv(plant_config=config, cycle=SHORT, frame_skip=frame_skip, energy_cost_weight=0.01)
    actions = _actions(SHORT.samples_per_cycle * SHORT.n_cycles // frame_skip)
    env.reset(seed=seed)
    forward = energy = 0.0
    for a in actions:
        _, reward, _, truncated, info = env.step(a)
        assert reward == pytest.approx(info["reward_forward"] + info["reward_energy"])
        forward += info["reward_forward"]
        energy += info["reward_energy"]
    assert truncated

    # The same plant, each tick's activation through the rig's safety envelope as the env's rig applies it.
    plant = MujocoLeg(config)
    rest = last = plant.reset_episode(seeding.np_random(seed)[0], env.reset_noise_scale)
    envelope = SafetyEnvelope()
    envelope.observe(rest, at_rest=True)
    for a in np.repeat(actions.astype(np.float64), frame_skip, axis=0):
        applied = envelope.limit(a, last.position_rad, last.velocity_rad_s).applied
        last = plant.step(applied)
        envelope.observe(last)
    travel = last.belt_mm - rest.belt_mm
    used = float(np.sum(last.energy_j - rest.energy_j))
    assert abs(travel) > 0.1  # the episode moved the belt: the comparison is not 0 == 0
    assert forward == pytest.approx(travel, rel=1e-12, abs=1e-12)
    assert info["belt_travel_mm"] == pytest.approx(travel, rel=1e-12, abs=1e-12)
    assert energy == pytest.approx(-0.01 * used, rel=1e-12)
    assert info["energy_used_j"] == pytest.approx(used, rel=1e-12)
    # The observation ends with what the rig applied: the activations, clamped at the baseline, enveloped.
    np.testing.assert_array_equal(env._observation()[5:], last.activation)
    np.testing.assert_array_equal(last.activation, np.maximum(applied, BASELINE_ACTIVATION))


def test_track_reward_and_observation_follow_the_cycle() -> None:
    """Known answer: the reward is minus the squared error to the cycle's desired angles, tick by tick."""
    cycle = LimitCycleConfig.in_air(n_cycles=1)
    features = np.full(cycle.n_spokes, 0.5)
    env = TrackEnv(features=features, cycle=cycle, frame_skip=1, reset_noise_scale=0.0)
    desired = cycle_kinematics(features, cycle)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs[8:], desired[0, :4])
    a = np.array([0.4, 0.4, 0.4], dtype=np.float32)
    for k in range(cycle.samples_per_cycle):
        obs, reward, _, truncated, info = env.step(a)
        error = obs[:2] - desired[k, :2]
        assert reward == pytest.approx(-np.sum(error**2), rel=1e-12)
        assert info["tracking_rmse_rad"] == pytest.approx(np.sqrt(np.mean(error**2)), rel=1e-12)
        np.testing.assert_array_equal(obs[8:], desired[(k + 1) % len(desired), :4])
    assert truncated
    # The default rig of Track-v0 hangs in the air.
    assert TrackEnv().plant.config.carriage_height_m == AIR_CARRIAGE_HEIGHT_M  # type: ignore[attr-defined]
    # Features from reset options, checked against the cycle's bounds.
    env.reset(options={"features": np.full(cycle.n_spokes, 0.3)})
    assert np.all(env.features == 0.3)
    with pytest.raises(ValueError, match=r"features\[0\]"):
        env.reset(options={"features": np.full(cycle.n_spokes, 0.9)})


def test_invalid_actions_are_rejected_before_the_plant() -> None:
    env = TreadmillEnv(cycle=SHORT)
    env.reset(seed=0)
    t_before = env.plant.time_s  # type: ignore[attr-defined]
    for bad in ([np.nan, 0.2, 0.2], [0.2, 0.2], [np.inf, 0, 0]):
        with pytest.raises(ValueError, match="action"):
            env.step(np.array(bad, dtype=np.float32))
    assert env.plant.time_s == t_before and env.ticks == 0  # type: ignore[attr-defined]
    # Out of the box, the action is clipped as the rig would clamp it (once the rig's ramp has climbed the
    # step from rest: 12 ticks).
    for _ in range(12):
        env.step(np.array([2.0, -1.0, 0.5], dtype=np.float32))
    np.testing.assert_allclose(env._observation()[5:], [1.0, BASELINE_ACTIVATION, 0.5])


def test_noise_and_rendering_need_the_simulated_rig() -> None:
    """A plant other than MujocoLeg (the ROS rig contract) cannot be perturbed at reset, nor rendered."""

    class Recorded:  # a real plant: the simulated leg behind a thin wrapper that hides its type
        def __init__(self) -> None:
            self.leg = MujocoLeg()
            self.tick_hz = self.leg.tick_hz
            self.reset, self.step, self.close = self.leg.reset, self.leg.step, self.leg.close

    with pytest.raises(ValueError, match="reset_noise_scale=0"):
        TreadmillEnv(plant=Recorded())  # type: ignore[arg-type]
    env = TreadmillEnv(plant=Recorded(), reset_noise_scale=0.0, cycle=SHORT)  # type: ignore[arg-type]
    obs, _ = env.reset(seed=0)
    assert obs.shape == (8,)


def test_registered_ids() -> None:
    assert g2p.rl.envs.TREADMILL_ID in gym.registry and g2p.rl.envs.TRACK_ID in gym.registry
    env = gym.make(TREADMILL_ID, frame_skip=8, energy_cost_weight=0.5)
    assert env.unwrapped.frame_skip == 8 and env.unwrapped.energy_cost_weight == 0.5
    env.close()


@pytest.mark.slow
def test_render_gives_the_leg_as_an_rgb_array() -> None:
    """MuJoCo's offscreen renderer through EGL, in a process of its own (MUJOCO_GL is read at import)."""
    script = (
        "import numpy as np, gymnasium as gym, g2p.rl.envs\n"
        "env = gym.make('g2p/Treadmill-v0', render_mode='rgb_array', width=160, height=120)\n"
        "env.reset(seed=0)\n"
        "img = env.render()\n"
        "assert img.shape == (120, 160, 3) and img.dtype == np.uint8, (img.shape, img.dtype)\n"
        "assert img.std() > 5, 'a blank image'\n"
        "print('ok')\n"
    )
    env = {**os.environ, "MUJOCO_GL": "egl"}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]


def test_an_action_delay_plays_each_action_a_tick_later() -> None:
    """Known answer: with a one-tick delay, actions a_0, a_1, ... play as baseline, a_0, a_1, ... without."""
    config = MujocoLegConfig(seed=3)
    actions = _actions(SHORT.samples_per_cycle * SHORT.n_cycles).astype(np.float64)
    delayed = TreadmillEnv(plant_config=config, cycle=SHORT, action_delay_ticks=1)
    lockstep = TreadmillEnv(plant_config=config, cycle=SHORT)
    delayed.reset(seed=1)
    lockstep.reset(seed=1)
    shifted = np.vstack([np.full((1, 3), BASELINE_ACTIVATION), actions[:-1]])
    for a, b in zip(actions, shifted, strict=True):
        obs_delayed, reward_delayed, *_ = delayed.step(a)
        obs_lockstep, reward_lockstep, *_ = lockstep.step(b)
        np.testing.assert_array_equal(obs_delayed, obs_lockstep)
        assert reward_delayed == reward_lockstep
    with pytest.raises(ValueError, match="action_delay_ticks"):
        TreadmillEnv(action_delay_ticks=-1)


def test_a_reset_with_rig_time_keeps_the_heat_and_costs_its_time() -> None:
    """An episode at full activation heats the windings; a reset of 5 s holds baseline for 5 s of rig time
    and the next episode starts warmer than ambient but cooler than the last one ended. Without reset
    time, each episode starts at ambient and no rig time passes."""
    for reset_s in (5.0, 0.0):
        env = TreadmillEnv(cycle=SHORT, reset_s=reset_s, reset_noise_scale=0.0)
        plant = env.plant
        assert isinstance(plant, MujocoLeg)
        env.reset(seed=0)
        ambient = plant.winding_temperature_c.copy()
        truncated = terminated = False
        while not (truncated or terminated):
            _, _, terminated, truncated, _ = env.step(np.ones(3, np.float32))
        hot, ended_s = plant.winding_temperature_c.copy(), plant.time_s
        assert np.all(hot > ambient + 1.0)
        env.reset()
        if reset_s:
            # 390 ticks at 78 Hz, each with the tick clock's jitter (0.8 ms)
            assert plant.time_s - ended_s == pytest.approx(reset_s, abs=0.1)
            assert np.all(plant.winding_temperature_c < hot)
            assert np.all(plant.winding_temperature_c > ambient + 0.5)
            assert env._envelope is not None and np.all(env._envelope.winding_c > ambient + 0.5)
        else:
            assert plant.time_s == ended_s
            np.testing.assert_array_equal(plant.winding_temperature_c, ambient)
        env.close()
