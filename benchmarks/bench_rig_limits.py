"""What the rig's limits see of a client: the two-phase square wave, and a G2P run (babbling, attempts).

Each is played on the in-process rig (`PlantRig`: the rig's tick loop with its safety envelope, over the
simulated rig with its limits) and measured at the ticks and at the physics sub-steps:

- the joints' speeds entering their stops (median, 95th percentile, max over the entries, from the ticks'
  joint velocities; g2p.envelope.stop_entry_speeds), and how many entries;
- the tendons' peak tension (sub-steps) and the ticks beyond the rated tension; the most cable paid out
  into a slack tendon;
- the motors' RMS current and copper loss, the hottest winding;
- the belt travel, the ticks the envelope changed, and the trip (if one ended the pattern).

The square wave: M0 and M2 at 1 with M1 at 0.15 for half a period, then the reverse, at 0.97 Hz (G2P's
own cycle rate), from rest. The G2P run is `g2p.experiments.run_treadmill` with the default settings:
its babbling (5 min), all its attempts, and its best attempt.

    python benchmarks/bench_rig_limits.py [--seconds 30] [--g2p-seeds 1] [--no-soft-limits]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

import g2p.inverse_map.training  # noqa: F401  (torch first: its import is slow and belongs to no tick)
from g2p.envelope import JOINT_STOPS_RAD, EnvelopeConfig, stop_entry_speeds
from g2p.experiments import TreadmillRun
from g2p.learner import Learner, LearnerConfig
from g2p.limit_cycle import LimitCycleConfig
from g2p.plant import FloatArray, TickSample
from g2p.rig import PlantRig, RigError
from g2p.search import SearchConfig
from g2p.sim import MujocoLeg, MujocoLegConfig
from g2p.tick_loop import TickLoopConfig


def square_wave(seconds: float, tick_hz: float, hz: float = 0.97) -> FloatArray:
    """M0 and M2 at 1 with M1 at 0.15 for half a period, then the reverse, from rest: shape (N, 3)."""
    t = np.arange(round(seconds * tick_hz)) / tick_hz
    first = (np.floor(t * hz * 2) % 2 == 0)[:, None]
    return np.where(first, [1.0, 0.15, 1.0], [0.15, 1.0, 0.15])


@dataclass
class MeteredLeg:
    """The simulated rig, with what its sub-steps saw kept per tick (the plant's own readings)."""

    leg: MujocoLeg
    samples: list[TickSample] = field(default_factory=list)
    peak_tension_n: list[FloatArray] = field(default_factory=list)
    winding_c: list[FloatArray] = field(default_factory=list)

    def __getattr__(self, name: str) -> Any:  # the Plant protocol and `fault`, from the leg
        return getattr(self.leg, name)

    def step(self, activation: FloatArray) -> TickSample:
        """One tick of the leg, kept."""
        sample = self.leg.step(activation)
        self.samples.append(sample)
        self.peak_tension_n.append(self.leg.peak_tension_n.copy())
        self.winding_c.append(self.leg.winding_temperature_c.copy())
        return sample


def figures(meter: MeteredLeg, ticks: slice, envelope_ticks: int, trip: str = "") -> dict[str, Any]:
    """The figures (module docstring) of the ticks `ticks` of `meter`'s record."""
    samples = meter.samples[ticks]
    q = np.array([s.position_rad for s in samples])
    v = np.array([s.velocity_rad_s for s in samples])
    current = np.array([s.current_a for s in samples])
    peak = np.array(meter.peak_tension_n[ticks])
    out: dict[str, Any] = {"ticks": len(samples)}
    for j, name in enumerate(("hip", "knee")):
        entries = stop_entry_speeds(q[:, j], v[:, j], JOINT_STOPS_RAD[j])
        out[f"{name}_stop_entries"] = len(entries)
        if len(entries):
            out[f"{name}_entry_rad_s"] = [round(float(x), 1) for x in np.percentile(entries, [50, 95, 100])]
    rms = np.sqrt((current**2).mean(axis=0))
    limits = meter.leg.limits
    out.update(
        peak_tension_n=peak.max(axis=0).round(1).tolist(),
        ticks_over_rated_tension=(peak > limits.tendon_rated_n).sum(axis=0).tolist(),
        current_rms_a=rms.round(2).tolist(),
        copper_loss_w=(rms**2 * meter.leg.leg_model.motor.resistance_ohm).round(1).tolist(),
        hottest_winding_c=np.max(meter.winding_c[ticks], axis=0).round(1).tolist(),
        belt_mm=round(samples[-1].belt_mm - samples[0].belt_mm),
        envelope_ticks=envelope_ticks,
        trip=trip,
    )
    return out


def new_rig(envelope: EnvelopeConfig, seed: int = 0) -> tuple[PlantRig, MeteredLeg]:
    """An in-process rig with `envelope` over a metered simulated rig of leg seed `seed`."""
    meter = MeteredLeg(MujocoLeg(MujocoLegConfig(seed=seed)))
    return PlantRig(meter, config=TickLoopConfig(envelope=envelope)), meter  # type: ignore[arg-type]


def play_square_wave(seconds: float, envelope: EnvelopeConfig) -> dict[str, Any]:
    """The square wave, one tick at a time until it ends or the rig trips."""
    rig, meter = new_rig(envelope)
    rig.reset()
    trip = ""
    try:
        rig.play(square_wave(seconds, meter.leg.tick_hz))
    except RigError as err:  # a trip ends the sequence with its reason
        trip = str(err)
    out = figures(meter, slice(0, None), rig.counters.envelope_ticks, trip)
    out["max_slack_payout_mm"] = (1000 * meter.leg.max_slack_payout_m).round(1).tolist()
    return out


def g2p_run(seed: int, envelope: EnvelopeConfig) -> dict[str, Any]:
    """A G2P run (babbling, then the two-phase search); figures for babbling, all attempts, the best."""
    rig, meter = new_rig(envelope, seed)
    learner = Learner(replace(LearnerConfig(), seed=seed))
    learner.babble(rig)
    babbled, babble_env = len(meter.samples), rig.counters.envelope_ticks
    run = TreadmillRun(learner, SearchConfig(), LimitCycleConfig(), seed)
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
        "max_slack_payout_mm": (1000 * meter.leg.max_slack_payout_m).round(1).tolist(),
        "trips": rig.counters.trips,
    }


def main() -> None:
    """Play the patterns and print their figures as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="the square wave's duration (s)")
    parser.add_argument("--g2p-seeds", type=int, default=1, help="G2P runs (seeds 0..N-1); 0: none")
    parser.add_argument("--no-soft-limits", action="store_true", help="the envelope without soft limits")
    args = parser.parse_args()
    envelope = replace(EnvelopeConfig(), soft_limits=not args.no_soft_limits)
    out: dict[str, Any] = {"soft_limits": envelope.soft_limits}
    out["square_wave"] = play_square_wave(args.seconds, envelope)
    print(json.dumps(out["square_wave"]), flush=True)
    for seed in range(args.g2p_seeds):
        out[f"g2p_seed{seed}"] = g2p_run(seed, envelope)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
