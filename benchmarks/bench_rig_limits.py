"""What the rig's limits see of a client: the two-phase square wave, G2P (babbling, attempts), PPO and SAC.

Each is played on the in-process rig (`PlantRig`: the rig's tick loop with its safety envelope, over the
simulated rig with its limits) and measured at the ticks and at the physics sub-steps:

- the joints' speeds entering their stops (median, 95th percentile, max over the entries, from the ticks'
  joint velocities; g2p.rig.envelope.stop_entry_speeds), and how many entries;
- the tendons' peak tension (sub-steps) and the ticks beyond the rated tension; the share of ticks each
  tendon carried no force at all (slack); the most cable paid out into a slack tendon;
- the motors' RMS current and copper loss, the hottest winding;
- the belt travel, the ticks the envelope changed, and the trip (if one ended the pattern).

The square wave: M0 and M2 at 1 with M1 at 0.15 for half a period, then the reverse, at 0.97 Hz (G2P's
own cycle rate), from rest. The G2P run is `g2p.learning.experiments.run_treadmill` with the default settings:
its babbling (5 min), all its attempts, and its best attempt. PPO and SAC (`--rl ppo,sac`) train inside
the envelope for `--rl-hours` of rig time, then their deterministic gaits play for 5 min without a reset.

    python benchmarks/bench_rig_limits.py [--seconds 30] [--square-seeds 1] [--g2p-seeds 1] [--thermal-only]
                                          [--rl ppo,sac] [--rl-hours 1]

`--thermal-only` leaves the envelope its thermal budget alone (no soft joint limits, no ramp): the rig's
limits without the rules that protect the joints.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np

import g2p.inverse_map.training  # noqa: F401  (torch first: its import is slow and belongs to no tick)
from g2p.learning.experiments import TreadmillRun
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.search import SearchConfig
from g2p.plant import FloatArray, TickSample
from g2p.rig import PlantRig, RigError
from g2p.rig.envelope import JOINT_STOPS_RAD, EnvelopeConfig, stop_entry_speeds
from g2p.rig.tick_loop import TickLoopConfig
from g2p.rl.baselines import rl_model
from g2p.rl.envs import TreadmillEnv
from g2p.safety import BASELINE_ACTIVATION
from g2p.sim import MujocoLeg, MujocoLegConfig


def square_wave(seconds: float, tick_hz: float, hz: float = 0.97) -> FloatArray:
    """M0 and M2 at 1 with M1 at 0.15 for half a period, then the reverse, from rest: shape (N, 3)."""
    t = np.arange(round(seconds * tick_hz)) / tick_hz
    first = (np.floor(t * hz * 2) % 2 == 0)[:, None]
    return np.where(first, [1.0, 0.15, 1.0], [0.15, 1.0, 0.15])


class MeteredLeg(MujocoLeg):
    """The simulated rig, with what its sub-steps saw kept per tick (the plant's own readings)."""

    def __init__(self, config: MujocoLegConfig) -> None:
        super().__init__(config)
        self.samples: list[TickSample] = []
        self.peaks_n: list[FloatArray] = []  # each tick's sub-step peak tension, (3,) (N)
        self.windings_c: list[FloatArray] = []  # each tick's winding temperatures, (3,) (deg C)

    def step(self, activation: FloatArray) -> TickSample:
        """One tick of the leg, kept."""
        sample = super().step(activation)
        self.samples.append(sample)
        self.peaks_n.append(self.peak_tension_n)
        self.windings_c.append(self.winding_temperature_c.copy())
        return sample

    def forget(self) -> None:
        """Drop what was kept so far."""
        self.samples, self.peaks_n, self.windings_c = [], [], []


def figures(meter: MeteredLeg, ticks: slice, envelope_ticks: int, trip: str = "") -> dict[str, Any]:
    """The figures (module docstring) of the ticks `ticks` of `meter`'s record."""
    samples = meter.samples[ticks]
    q = np.array([s.position_rad for s in samples])
    v = np.array([s.velocity_rad_s for s in samples])
    current = np.array([s.current_a for s in samples])
    peak = np.array(meter.peaks_n[ticks])
    out: dict[str, Any] = {"ticks": len(samples)}
    for j, name in enumerate(("hip", "knee")):
        entries = stop_entry_speeds(q[:, j], v[:, j], JOINT_STOPS_RAD[j])
        out[f"{name}_stop_entries"] = len(entries)
        if len(entries):
            out[f"{name}_entry_rad_s"] = [round(float(x), 1) for x in np.percentile(entries, [50, 95, 100])]
    rms = np.sqrt((current**2).mean(axis=0))
    limits = meter.limits
    out.update(
        peak_tension_n=peak.max(axis=0).round(1).tolist(),
        ticks_over_rated_tension=(peak > limits.tendon_rated_n).sum(axis=0).tolist(),
        slack_share=(peak == 0.0).mean(axis=0).round(3).tolist(),
        current_rms_a=rms.round(2).tolist(),
        copper_loss_w=(rms**2 * meter.leg_model.motor.resistance_ohm).round(1).tolist(),
        hottest_winding_c=np.max(meter.windings_c[ticks], axis=0).round(1).tolist(),
        belt_mm=round(samples[-1].belt_mm - samples[0].belt_mm),
        envelope_ticks=envelope_ticks,
        trip=trip,
    )
    return out


def new_rig(envelope: EnvelopeConfig, seed: int = 0) -> tuple[PlantRig, MeteredLeg]:
    """An in-process rig with `envelope` over a metered simulated rig of leg seed `seed`."""
    meter = MeteredLeg(MujocoLegConfig(seed=seed))
    return PlantRig(meter, config=TickLoopConfig(envelope=envelope)), meter


def play_square_wave(seconds: float, envelope: EnvelopeConfig, seed: int = 0) -> dict[str, Any]:
    """The square wave on leg seed `seed`, one tick at a time until it ends or the rig trips."""
    rig, meter = new_rig(envelope, seed)
    rig.reset()
    trip = ""
    try:
        rig.play(square_wave(seconds, meter.tick_hz))
    except RigError as err:  # a trip ends the sequence with its reason
        trip = str(err)
    out = figures(meter, slice(0, None), rig.counters.envelope_ticks, trip)
    out["max_slack_payout_mm"] = (1000 * meter.max_slack_payout_m).round(1).tolist()
    return out


def g2p_run(seed: int, envelope: EnvelopeConfig) -> dict[str, Any]:
    """A G2P run (babbling, then the two-phase search); figures for babbling, all attempts, the best."""
    rig, meter = new_rig(envelope, seed)
    learner = Learner(replace(LearnerConfig(), seed=seed))
    learner.babble(rig)
    babbled, babble_env = len(meter.samples), rig.counters.envelope_ticks
    run = TreadmillRun(learner, SearchConfig(), LimitCycleConfig())
    spans = []
    while not run.finished:
        start, env_before = len(meter.samples), rig.counters.envelope_ticks
        report = run.next_attempt(rig)
        ticks = slice(start, len(meter.samples))
        spans.append((report.outcome.reward_mm, ticks, rig.counters.envelope_ticks - env_before))
    best_reward, best_ticks, best_env = max(spans, key=lambda s: s[0])
    return {
        "babbling": figures(meter, slice(0, babbled), babble_env),
        "attempts": figures(meter, slice(babbled, None), rig.counters.envelope_ticks - babble_env),
        "best_attempt": {"reward_mm": round(best_reward, 1), **figures(meter, best_ticks, best_env)},
        "rewards_mm": [round(r, 1) for r, _, _ in spans],
        "max_slack_payout_mm": (1000 * meter.max_slack_payout_m).round(1).tolist(),
        "trips": rig.counters.trips,
    }


def rl_gait(method: str, seed: int, hours: float, play_s: float = 300.0) -> dict[str, Any]:
    """PPO or SAC trained for `hours` of rig time inside the envelope; figures of its deterministic gait.

    Trains as benchmarks/bench_rl.py does (g2p.rl.baselines.rl_model, frame_skip 4) on g2p/Treadmill-v0 over
    the in-process rig, whose envelope limits every action, and counts the training episodes a trip ended.
    Then plays the deterministic policy for `play_s` without a reset, as a rig would run the gait (an
    episode's reset starts the windings cold: one 20 s episode never meets the thermal budget), and
    measures its first episode's length of ticks and the whole play.
    """
    meter = MeteredLeg(MujocoLegConfig(seed=seed))
    env = TreadmillEnv(plant=meter, frame_skip=4)
    trips: list[str] = []

    class CountTrips(gym.Wrapper):  # type: ignore[type-arg]
        def step(self, action: Any) -> Any:
            out = super().step(action)
            if out[2]:
                trips.append(out[4]["trip"])
            meter.forget()  # the training's ticks are not measured
            return out

    model = rl_model(method, CountTrips(env), seed)
    model.learn(total_timesteps=round(hours * 3600 * meter.tick_hz / env.frame_skip))
    normalize = getattr(model.get_env(), "normalize_obs", lambda o: o)  # PPO's VecNormalize
    episode_ticks = env.episode_ticks
    env.episode_ticks = round(play_s * meter.tick_hz / env.frame_skip) * env.frame_skip
    obs, _ = env.reset(seed=seed + 1000)
    meter.forget()
    changed, done, info = [], False, {}
    while not done:
        action, _ = model.predict(normalize(obs), deterministic=True)
        first = len(meter.samples)
        obs, _, terminated, truncated, info = env.step(action)
        decided = np.clip(np.asarray(action, dtype=np.float64), BASELINE_ACTIVATION, 1.0)
        changed += [bool(np.any(s.activation != decided)) for s in meter.samples[first:]]
        done = terminated or truncated
    episode = slice(0, episode_ticks)
    return {
        "training_trips": len(trips),
        "training_trip_reasons": sorted(set(trips))[:5],
        "episode": figures(meter, episode, sum(changed[episode])),
        "play": figures(meter, slice(0, None), sum(changed), info.get("trip", "")),
        "max_slack_payout_mm": (1000 * meter.max_slack_payout_m).round(1).tolist(),
    }


def main() -> None:
    """Play the patterns and print their figures as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="the square wave's duration (s)")
    parser.add_argument("--square-seeds", type=int, default=1, help="square waves (leg seeds 0..N-1)")
    parser.add_argument("--g2p-seeds", type=int, default=1, help="G2P runs (seeds 0..N-1); 0: none")
    parser.add_argument("--thermal-only", action="store_true", help="no soft joint limits, no ramp")
    parser.add_argument("--rl", default="", help="RL methods to train and measure, e.g. ppo,sac")
    parser.add_argument("--rl-hours", type=float, default=1.0, help="each RL method's rig time (h)")
    args = parser.parse_args()
    envelope = EnvelopeConfig()
    if args.thermal_only:
        envelope = replace(envelope, soft_limits=False, max_step=1.0)
    out: dict[str, Any] = {"thermal_only": args.thermal_only}
    out["square_wave"] = play_square_wave(args.seconds, envelope)
    print(json.dumps(out["square_wave"]), flush=True)
    if args.square_seeds > 1:  # the knee's entries (median, p95, max) on other seeds of the simulated rig
        out["square_wave_knee_rad_s_by_seed"] = [out["square_wave"]["knee_entry_rad_s"]] + [
            play_square_wave(args.seconds, envelope, seed)["knee_entry_rad_s"]
            for seed in range(1, args.square_seeds)
        ]
        print(json.dumps(out["square_wave_knee_rad_s_by_seed"]), flush=True)
    for seed in range(args.g2p_seeds):
        out[f"g2p_seed{seed}"] = g2p_run(seed, envelope)
        print(json.dumps(out[f"g2p_seed{seed}"]), flush=True)
    for method in filter(None, args.rl.split(",")):
        out[method] = rl_gait(method, 0, args.rl_hours)
        print(json.dumps(out[method]), flush=True)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
