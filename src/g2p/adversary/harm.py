"""What a pattern does to the simulated leg through a rig's tick loop and envelope.

`MeteredLeg` keeps the physics' own readings of each tick (sub-step tension peaks, the cable paid into
each slack tendon), which no real rig measures; `play_harm` plays a sequence through `PlantRig` (the tick
loop with its envelope) over one, `play_harm_in_env` through the Gymnasium environment `g2p/Treadmill-v0`
as the RL baselines run it (RIG_AS_IT_RUNS: the action a tick late, a reset's rig time), and `Harm` sums up
how close it came to breaking the leg.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from g2p.plant import FloatArray, Recording, TickSample
from g2p.rig import PlantRig, RigError
from g2p.rig.envelope import JOINT_STOPS_RAD, EnvelopeConfig, stop_entry_speeds
from g2p.rig.tick_loop import TickLoopConfig
from g2p.safety import BASELINE_ACTIVATION
from g2p.sim import MujocoLeg, MujocoLegConfig

JOINTS = ("hip", "knee")


class MeteredLeg(MujocoLeg):
    """The simulated rig, with what its sub-steps saw kept per tick (the plant's own readings)."""

    def __init__(self, config: MujocoLegConfig) -> None:
        super().__init__(config)
        self.forget()

    def step(self, activation: FloatArray, period_s: float | None = None) -> TickSample:
        """One tick of the leg, kept."""
        sample = super().step(activation, period_s)
        self.samples.append(sample)
        self.peaks_n.append(self.peak_tension_n)
        self.payouts_m.append(self.slack_payout_m)
        self.windings_c.append(self.winding_temperature_c)
        return sample

    def forget(self) -> None:
        """Drop what was kept so far."""
        self.samples: list[TickSample] = []
        self.peaks_n: list[FloatArray] = []  # each tick's sub-step peak tension, (3,) (N)
        self.payouts_m: list[FloatArray] = []  # each tick's cable in slack loops at its end, (3,) (m)
        self.windings_c: list[FloatArray] = []  # each tick's winding temperatures, (3,) (deg C)

    @property
    def recording(self) -> Recording:
        """The ticks kept, as a recording."""
        return Recording.from_samples(self.samples)


@dataclass(frozen=True)
class Harm:
    """How close the ticks of one pattern came to breaking the leg.

    Attributes:
        ticks: ticks played (fewer than the pattern's when a trip ended it).
        entry_speed_rad_s: each joint's fastest entry into its stops (hip, knee) (rad/s; 0 with none).
        entry_p95_rad_s: each joint's 95th percentile entry speed (rad/s; 0 with none).
        peak_tension_n: each tendon's highest sub-step tension (N), shape (3,).
        ticks_over_rated: each tendon's ticks above its working load, shape (3,).
        max_slack_payout_m: the most cable paid into each slack tendon (m), shape (3,).
        fault: the leg's own trip (a derail, a snapped tendon, a cut-out: the harm done), "" for none.
        trip: the rig's trip that ended the pattern (the envelope's, or the leg's fault), "" for none.
        envelope_ticks: ticks whose activation the envelope changed.
    """

    ticks: int
    entry_speed_rad_s: tuple[float, float]
    entry_p95_rad_s: tuple[float, float]
    peak_tension_n: tuple[float, float, float]
    ticks_over_rated: tuple[int, int, int]
    max_slack_payout_m: tuple[float, float, float]
    fault: str
    trip: str
    envelope_ticks: int

    def score(self, objective: str, limits: dict[str, float]) -> float:
        """The harm as one number for a search: the objective's share of its limit; 2 + that on a fault.

        Args:
            objective: "slack" (payout / derail payout), "impact" (fastest entry / `impact_rad_s`) or
                "tension" (peak / breaking tension).
            limits: "derail_m", "impact_rad_s", "breaking_n".
        """
        share = {
            "slack": max(self.max_slack_payout_m) / limits["derail_m"],
            "impact": max(self.entry_speed_rad_s) / limits["impact_rad_s"],
            "tension": max(self.peak_tension_n) / limits["breaking_n"],
        }[objective]
        return share + (2.0 if self.fault else 0.0)


def measure(meter: MeteredLeg, fault: str, trip: str, envelope_ticks: int) -> Harm:
    """The harm of the ticks `meter` kept."""
    rec = meter.recording
    fastest, p95 = [], []
    for j in range(2):
        entries = stop_entry_speeds(rec.position_rad[:, j], rec.velocity_rad_s[:, j], JOINT_STOPS_RAD[j])
        fastest.append(float(entries.max()) if entries.size else 0.0)
        p95.append(float(np.percentile(entries, 95)) if entries.size else 0.0)
    peaks = np.array(meter.peaks_n) if meter.peaks_n else np.zeros((1, 3))
    payouts = np.array(meter.payouts_m) if meter.payouts_m else np.zeros((1, 3))
    rated = meter.limits.tendon_rated_n
    return Harm(
        ticks=len(rec),
        entry_speed_rad_s=(fastest[0], fastest[1]),
        entry_p95_rad_s=(p95[0], p95[1]),
        peak_tension_n=tuple(float(x) for x in peaks.max(axis=0)),  # type: ignore[arg-type]
        ticks_over_rated=tuple(int(x) for x in (peaks > rated).sum(axis=0)),  # type: ignore[arg-type]
        max_slack_payout_m=tuple(float(x) for x in payouts.max(axis=0)),  # type: ignore[arg-type]
        fault=fault,
        trip=trip,
        envelope_ticks=envelope_ticks,
    )


def play_harm(
    activations: FloatArray, envelope: EnvelopeConfig, leg_seed: int = 0, calibration: str = ""
) -> Harm:
    """Play `activations` (N, 3) from rest through a rig with `envelope` over a fresh simulated leg.

    The sequence plays until its end or a trip (the envelope's, or the leg's own fault).

    Args:
        activations: one row per tick, shape (N, 3).
        envelope: the rig's envelope.
        leg_seed: the simulated leg's seed (its tick jitter).
        calibration: the simulated rig (MujocoLegConfig.calibration: "" the default, "paper" sim_paper).
    """
    meter = MeteredLeg(MujocoLegConfig(seed=leg_seed, calibration=calibration))
    rig = PlantRig(meter, config=TickLoopConfig(envelope=envelope))
    rig.reset()
    meter.forget()
    trip = ""
    try:
        rig.play(activations)
    except RigError as err:  # a trip ends the sequence with its reason
        trip = str(err)
    return measure(meter, meter.fault, trip, rig.counters.envelope_ticks)


def play_harm_in_env(
    activations: FloatArray, envelope: EnvelopeConfig, leg_seed: int = 0, calibration: str = ""
) -> Harm:
    """Play `activations` (N, 3) as one episode of `g2p/Treadmill-v0`, as the RL baselines run it.

    One action per tick (frame_skip 1), with RIG_AS_IT_RUNS (each action plays a tick late, a reset takes
    rig time). The episode ends at its 1,600 ticks, at the sequence's end or at a trip. Args as
    `play_harm`'s; the episode's reset noise is `leg_seed`'s.
    """
    from g2p.rl.baselines import RIG_AS_IT_RUNS  # the RL stack (torch), only when asked for
    from g2p.rl.envs import TreadmillEnv

    meter = MeteredLeg(MujocoLegConfig(seed=leg_seed, calibration=calibration))
    env = TreadmillEnv(plant=meter, frame_skip=1, envelope=envelope, **RIG_AS_IT_RUNS)
    env.reset(seed=leg_seed)
    meter.forget()
    trip, changed, commanded = "", 0, np.full(activations.shape[1], BASELINE_ACTIVATION)
    for row in activations[: env.episode_ticks]:
        *_, terminated, _, info = env.step(row.astype(np.float32))
        changed += int(np.any(meter.samples[-1].activation != np.maximum(commanded, BASELINE_ACTIVATION)))
        commanded = np.clip(row.astype(np.float32).astype(np.float64), 0.0, 1.0)  # plays next tick
        if terminated:
            trip = info["trip"]
            break
    env.close()
    return measure(meter, meter.fault, trip, changed)
