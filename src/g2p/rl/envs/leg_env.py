"""`LegEnv`: the rig as a Gymnasium environment, one or a few rig ticks per step, over any `Plant`.

The conventions are those of Gymnasium's MuJoCo v5 environments: the observation is what the rig's sensors
read, the action is held for `frame_skip` ticks, the reward returns its terms in `info`, an episode
truncates after a fixed number of ticks, `reset(seed=...)` seeds everything random, `reset_noise_scale`
perturbs the resting posture, and `render()` returns an RGB array.

Two properties of the real rig are options here: the real-time rig's action delay (a command plays from
the tick after the one it arrives in: `action_delay_ticks=1`), and the rig time a reset takes (`reset_s`:
the rig holds baseline that long between episodes, and its windings keep the heat of the episodes before,
cooling meanwhile). By default an episode starts on a fresh rig, without delay.

The rig's limits hold as on every rig: on the simulated rig in-process, each tick's action passes the
rig's safety envelope (g2p.rig.envelope), as the tick loop of a ROS rig passes it. An episode **terminates**
when a limit trips (a winding's cut-out, a snapped or derailed tendon: g2p.sim.limits), as a real rig's
operator would stop it; `info["trip"]` says why, and the next `reset` puts the rig right.

Subclasses (g2p.rl.envs.treadmill, g2p.rl.envs.track) add to the observation and define the reward.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.plant import N_JOINTS, N_MOTORS, FloatArray, Plant, TickSample
from g2p.rig.envelope import EnvelopeConfig, SafetyEnvelope
from g2p.safety import BASELINE_ACTIVATION
from g2p.sim import MujocoLeg, MujocoLegConfig

# Observation entries every environment of the rig starts with: joint angles (rad), joint velocities
# (rad/s), belt velocity (m/s, so that every entry is of order 1), the activations applied last.
RIG_OBSERVATION = (
    "proximal_rad",
    "distal_rad",
    "proximal_rad_s",
    "distal_rad_s",
    "belt_velocity_m_s",
    "M0_applied",
    "M1_applied",
    "M2_applied",
)


class LegEnv(gym.Env[NDArray[np.float64], NDArray[np.float32]]):
    """The leg on its treadmill as an environment (base class; see TreadmillEnv and TrackEnv).

    Args:
        plant: the rig to drive; None builds the simulated rig (MujocoLeg) from `plant_config`, which the
            environment then owns and closes. A plant other than MujocoLeg (the ROS rig contract,
            g2p_ros.tick_plant.TickPlant) needs `reset_noise_scale` 0 and `render_mode` None.
        plant_config: settings of the simulated rig built when `plant` is None.
        cycle: the limit cycles' timing: an episode lasts `n_cycles` cycles of `samples_per_cycle` ticks
            (20 x 80 ticks, about 20.5 s, like one G2P attempt).
        frame_skip: ticks each action is held for (a divisor of the episode's ticks).
        reset_noise_scale: on reset the joint angles move by U(-s, s) rad and their velocities by
            s N(0, 1) rad/s (simulated rig only).
        action_delay_ticks: ticks between a step's action and the first tick that plays it; the ticks
            before play the previous action (baseline after a reset). The real-time rig's is 1 (docs/RL.md,
            "Timing limits"); 0 is lockstep (simulated rig only).
        reset_s: rig time a reset takes (s; simulated rig only): after putting a tripped rig right, the
            rig holds baseline this long before the episode starts, and the windings keep their heat
            (the safety envelope its estimate) across episodes. 0: each episode starts on a fresh rig,
            windings at ambient, and no rig time passes.
        envelope: the in-process rig's safety envelope (simulated rig only; a ROS rig applies its own).
        render_mode: None or "rgb_array" (MuJoCo's offscreen renderer: set MUJOCO_GL=egl on a machine
            without a display).
        width: rendered image width (pixels).
        height: rendered image height (pixels).

    Raises:
        ValueError: an invalid argument, or noise or rendering asked of a plant that cannot do it.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 78}  # noqa: RUF012
    observation_names: tuple[str, ...] = RIG_OBSERVATION
    """Names of the observation's entries, in order."""

    def __init__(
        self,
        plant: Plant | None = None,
        plant_config: MujocoLegConfig | None = None,
        cycle: LimitCycleConfig | None = None,
        frame_skip: int = 1,
        reset_noise_scale: float = 5e-3,
        action_delay_ticks: int = 0,
        reset_s: float = 0.0,
        envelope: EnvelopeConfig | None = None,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 360,
    ) -> None:
        self.cycle = cycle if cycle is not None else LimitCycleConfig()
        self.episode_ticks = self.cycle.samples_per_cycle * self.cycle.n_cycles
        """Ticks per episode."""
        if frame_skip < 1 or self.episode_ticks % frame_skip:
            raise ValueError(
                f"frame_skip: must divide the episode's {self.episode_ticks} ticks, got {frame_skip}"
            )
        if not (math.isfinite(reset_noise_scale) and reset_noise_scale >= 0):
            raise ValueError(f"reset_noise_scale: must be finite and >= 0, got {reset_noise_scale}")
        if action_delay_ticks < 0:
            raise ValueError(f"action_delay_ticks: must be >= 0, got {action_delay_ticks}")
        if not (math.isfinite(reset_s) and reset_s >= 0):
            raise ValueError(f"reset_s: must be finite and >= 0, got {reset_s}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode: must be None or 'rgb_array', got {render_mode!r}")
        self._owns_plant = plant is None
        self.plant: Plant = MujocoLeg(plant_config) if plant is None else plant
        if not isinstance(self.plant, MujocoLeg) and (
            reset_noise_scale or render_mode or action_delay_ticks or reset_s
        ):
            raise ValueError(
                f"{type(self.plant).__name__}: reset noise, rendering, an action delay and a reset's time "
                "need the simulated rig (MujocoLeg; a ROS rig has its own); pass reset_noise_scale=0, "
                "render_mode=None, action_delay_ticks=0 and reset_s=0"
            )
        self.frame_skip = frame_skip
        self.reset_noise_scale = reset_noise_scale
        self.action_delay_ticks = action_delay_ticks
        self.reset_s = reset_s
        self.render_mode = render_mode
        self._size = (width, height)
        self._renderer: Any = None
        self.metadata = {**self.metadata, "render_fps": self.plant.tick_hz / frame_skip}
        self.action_space = gym.spaces.Box(0.0, 1.0, shape=(N_MOTORS,), dtype=np.float32)
        n_obs = len(self.observation_names)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(n_obs,), dtype=np.float64)
        self.ticks = 0
        """Ticks played in the current episode."""
        self._last: TickSample | None = None
        self.envelope_config = envelope if envelope is not None else EnvelopeConfig()
        self._envelope: SafetyEnvelope | None = None  # the in-process rig's; a ROS rig applies its own
        self._trip = ""
        self._delayed: deque[FloatArray] = deque()  # commands on their way: the oldest plays next

    @property
    def dt(self) -> float:
        """Nominal duration of one step (s)."""
        return self.frame_skip / self.plant.tick_hz

    # Subclasses --------------------------------------------------------------------------------------
    def _extra_observation(self) -> FloatArray:
        """Entries the subclass appends to the rig's observation (after the step's ticks)."""
        return np.zeros(0)

    def _on_reset(self, options: dict[str, Any] | None) -> None:
        """Start a new episode's task (called before the plant resets)."""

    def _reward(self, samples: list[TickSample], first_tick: int) -> tuple[float, dict[str, float]]:
        """The step's reward and its terms, from the ticks it played (episode ticks first_tick, ...)."""
        raise NotImplementedError

    # Gymnasium API -----------------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float64], dict[str, Any]]:
        """Return the leg to rest (perturbed by the reset noise) and start an episode."""
        super().reset(seed=seed)
        self._on_reset(options)
        if isinstance(self.plant, MujocoLeg):
            warm = self.reset_s > 0 and self._envelope is not None
            if warm:
                self._rest()
            else:
                # The windings start at ambient, as reset_episode's.
                self._envelope = SafetyEnvelope(self.envelope_config)
            self._last = self.plant.reset_episode(self.np_random, self.reset_noise_scale, keep_heat=warm)
            assert self._envelope is not None
            self._envelope.observe(self._last, at_rest=True)
        else:
            self._last = self.plant.reset()
        self.ticks = 0
        self._trip = ""
        self._delayed = deque(np.full(N_MOTORS, BASELINE_ACTIVATION) for _ in range(self.action_delay_ticks))
        return self._observation(), self._info({})

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        """Hold `action` (3 activations in [0, 1]; the rig applies at least its baseline) frame_skip ticks.

        Raises:
            ValueError: the action is not 3 finite numbers (nothing reaches the plant).
            RuntimeError: step before reset, or after the episode was truncated.
        """
        if self._last is None:
            raise RuntimeError("call reset() before step()")
        if self.ticks >= self.episode_ticks or self._trip:
            raise RuntimeError("the episode is over (truncated or terminated); call reset()")
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (N_MOTORS,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action: expected 3 finite activations, got {np.asarray(action).tolist()}")
        commanded = np.clip(a, 0.0, 1.0)
        first = self.ticks
        samples = [self._last]
        for _ in range(self.frame_skip):
            self._delayed.append(commanded)
            samples.append(self._tick(self._delayed.popleft(), samples[-1]))
            if self._trip:
                break
        self._last = samples[-1]
        self.ticks += len(samples) - 1
        reward, terms = self._reward(samples, first)
        truncated = self.ticks >= self.episode_ticks and not self._trip
        info = self._info(terms)
        if self._trip:
            info["trip"] = self._trip
        return self._observation(), reward, bool(self._trip), truncated, info

    def render(self) -> NDArray[np.uint8] | None:
        """The leg seen from its side, shape (height, width, 3) (render_mode "rgb_array"); else None."""
        if self.render_mode is None:
            return None
        assert isinstance(self.plant, MujocoLeg)
        import mujoco  # the renderer needs an OpenGL context, made only when asked for

        if self._renderer is None:
            width, height = self._size
            self._renderer = mujoco.Renderer(self.plant.model, height, width)
            self._camera = mujoco.MjvCamera()
            self._camera.lookat[:] = self.plant.model.body_pos[self.plant.leg_model.carriage_body]
            self._camera.lookat[2] *= 0.5  # between the hip and the belt
            self._camera.distance = 4.0 * float(self._camera.lookat[2]) + 0.3
            self._camera.azimuth, self._camera.elevation = 90.0, -5.0
        self._renderer.update_scene(self.plant.data, self._camera)
        image: NDArray[np.uint8] = self._renderer.render()
        return image

    def close(self) -> None:
        """Release the renderer, and the plant when the environment built it."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._owns_plant:
            self.plant.close()

    # Internals ---------------------------------------------------------------------------------------
    def _tick(self, commanded: FloatArray, last: TickSample) -> TickSample:
        """One tick of `commanded` (3,), through the in-process rig's envelope (a ROS rig applies its own)."""
        envelope = self._envelope
        if envelope is None:
            sample = self.plant.step(commanded)
        else:
            action = envelope.limit(commanded, last.position_rad, last.velocity_rad_s)
            sample = self.plant.step(action.applied)
            envelope.observe(sample)
            self._trip = envelope.trip
        self._trip = getattr(self.plant, "fault", "") or self._trip
        return sample

    def _rest(self) -> None:
        """A reset's rig time: put a tripped rig right, then hold baseline for `reset_s` (simulated rig)."""
        assert isinstance(self.plant, MujocoLeg) and self._envelope is not None
        last = self.plant.reset()
        self._envelope.observe(last, at_rest=True)  # the time a tripped rig took to cool
        for _ in range(round(self.reset_s * self.plant.tick_hz)):
            last = self._tick(np.full(N_MOTORS, BASELINE_ACTIVATION), last)

    def _observation(self) -> NDArray[np.float64]:
        s = self._last
        assert s is not None
        rig = np.concatenate(
            [s.position_rad, s.velocity_rad_s, [s.belt_velocity_mm_s * 1e-3], s.activation]
        ).astype(np.float64)
        return np.concatenate([rig, self._extra_observation()])

    def _info(self, terms: dict[str, float]) -> dict[str, Any]:
        # Only what the episode decides: the plant's clock and odometer run on across episodes.
        return {**terms, "ticks": self.ticks}


assert len(RIG_OBSERVATION) == 2 * N_JOINTS + 1 + N_MOTORS
