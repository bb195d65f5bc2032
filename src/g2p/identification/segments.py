"""What a calibration fits: recorded segments (babbling, attempts) that each start from the resting posture.

Every babbling phase and every attempt of a G2P run starts with a reset to the resting posture, so each
one is replayed in the simulated rig from its own resting posture: its recorded activations, one per tick,
each held for the tick's recorded duration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from g2p.bags.dataset import load_run
from g2p.bags.errors import BagError
from g2p.description import LegDescription
from g2p.plant import NOMINAL_TICK_HZ, FloatArray, Recording, concatenate
from g2p.rig import DEFAULT_NAMESPACE
from g2p.sim.config import TREADMILL_CARRIAGE_HEIGHT_M, MujocoLegConfig
from g2p.sim.leg import MujocoLeg
from g2p.sim.model_description import leg_description

# A tick whose recorded duration is outside this share of the nominal period (a gap in the recording, or a
# stamp out of order) is replayed with the nominal period: the physics is sub-stepped within a tick.
_PERIOD_RANGE = (0.5, 2.0)
# Link lengths and joint limits of the recorded leg must match the model's to this (m, rad).
_LAYOUT_TOLERANCE = (1e-3, 1e-2)


class CalibrationInputError(ValueError):
    """A recorded run cannot be calibrated on; the message names the file and what is missing."""


@dataclass(frozen=True)
class Segment:
    """Consecutive rig ticks from the resting posture, as the calibration replays and compares them.

    Attributes:
        name: "babbling" or "attempt K".
        activation: the applied activations, shape (N, 3).
        period_s: each tick's duration, shape (N,) (s).
        position_rad: the encoder angles at the end of each tick, shape (N, 2) (rad).
        current_a: mean motor currents over each tick, shape (N, 3) (A).
        belt_velocity_mm_s: mean belt velocity over each tick, shape (N,) (mm/s, + backward).
        power_w: mean electrical power of each motor over each tick, shape (N, 3) (W).
        start_position_rad: None for a segment that starts at rest; for a stretch cut from the middle of
            one (`block`), the encoder angles before its first tick, shape (2,) (rad).
        scored_from: the ticks before this one are replayed but not compared: they let the replay's
            motor currents, tendon stretch and velocities, which start at rest, catch up with the rig.
    """

    name: str
    activation: FloatArray
    period_s: FloatArray
    position_rad: FloatArray
    current_a: FloatArray
    belt_velocity_mm_s: FloatArray
    power_w: FloatArray
    start_position_rad: FloatArray | None = None
    scored_from: int = 0

    def __len__(self) -> int:
        return len(self.period_s)

    @property
    def duration_s(self) -> float:
        """Recorded duration (s)."""
        return float(np.sum(self.period_s))

    def head(self, n: int) -> Segment:
        """The first `n` ticks."""
        return self.block(0, n, 0)

    def block(self, start: int, stop: int, settle_ticks: int) -> Segment:
        """Ticks [start, stop) as a segment of their own: a stretch of the recording to fit on.

        A stretch after the first tick begins `settle_ticks` earlier, at the recorded angles, with those
        ticks replayed but not compared (`scored_from`).
        """
        if self.start_position_rad is not None or self.scored_from:
            raise ValueError(f"{self.name}: a block of a block")
        first = max(0, start - settle_ticks)
        return Segment(
            self.name,
            self.activation[first:stop],
            self.period_s[first:stop],
            self.position_rad[first:stop],
            self.current_a[first:stop],
            self.belt_velocity_mm_s[first:stop],
            self.power_w[first:stop],
            start_position_rad=self.position_rad[first - 1].copy() if first > 0 else None,
            scored_from=start - first,
        )


def segment_of(
    recording: Recording, name: str, tick_hz: float = NOMINAL_TICK_HZ, previous_t_s: float | None = None
) -> Segment:
    """A recorded segment from a recording of consecutive ticks that started at rest.

    Args:
        recording: the segment's ticks.
        name: what it is.
        tick_hz: the rig's nominal tick rate (Hz).
        previous_t_s: the stamp of the tick (or reset sample) before the first one (s): the first tick's
            duration starts there. None takes the nominal period, as for any duration outside [0.5, 2]
            nominal periods. The rig's physics is sensitive enough for the first tick's duration to
            matter: a replay that starts off by a fraction of a millisecond parts from the recording.
    """
    nominal = 1.0 / tick_hz
    period = np.empty(0)
    if len(recording):
        start = previous_t_s if previous_t_s is not None else recording.t_s[0] - nominal
        period = np.diff(recording.t_s, prepend=start)
    bad = (period < _PERIOD_RANGE[0] * nominal) | (period > _PERIOD_RANGE[1] * nominal)
    period = np.where(bad, nominal, period)
    belt = np.diff(recording.belt_mm, prepend=recording.belt_mm[0] if len(recording) else 0.0) / period
    return Segment(
        name=name,
        activation=recording.activation.copy(),
        period_s=period,
        position_rad=recording.position_rad.copy(),
        current_a=recording.current_a.copy(),
        belt_velocity_mm_s=belt,
        power_w=recording.power_w.copy(),
    )


@dataclass(frozen=True)
class RecordedRun:
    """The segments of a recorded run and the rig settings they were recorded with.

    Attributes:
        bag: the bag directory.
        babbling: the babbling segment(s).
        attempts: the attempts' segments, in order.
        leg_config: the simulated rig that replays them (carriage height, tick rate, sub-steps from the
            recording rig's configuration when it was a simulator; the physics is the model's).
    """

    bag: Path
    babbling: list[Segment]
    attempts: list[Segment]
    leg_config: MujocoLegConfig


def _rig_settings(configs: dict[str, Any], namespace: str) -> dict[str, Any]:
    """Carriage height, tick rate and sub-steps of the rig that recorded, when its configuration says."""
    for topic, config in configs.items():
        if topic.startswith(namespace.rstrip("/") + "/") and isinstance(config, dict):
            leg = config.get("leg") or config.get("fake")
            if isinstance(leg, dict) and "carriage_height_m" in leg:
                keys = ("carriage_height_m", "tick_hz", "substeps", "settle_s", "baseline_activation")
                return {k: leg[k] for k in keys if k in leg}
    return {}


def _contiguous(recordings: list[Recording], stamps: FloatArray) -> list[Recording]:
    """Join recordings whose ticks follow each other with no tick or reset sample between them.

    The learner babbles in chunks after a single reset (each chunk its own phase in the bag): one segment
    from rest, however many chunks.
    """
    out: list[Recording] = []
    for rec in (r for r in recordings if len(r)):
        if out:
            last = int(np.searchsorted(stamps, out[-1].t_s[-1], side="left"))
            first = int(np.searchsorted(stamps, rec.t_s[0], side="left"))
            if first == last + 1:
                out[-1] = concatenate([out[-1], rec])
                continue
        out.append(rec)
    return out


def check_layout(recorded: LegDescription, model: LegDescription, source: str) -> None:
    """Raise CalibrationInputError unless the recorded leg has the model's links and joint ranges."""
    length_tol, angle_tol = _LAYOUT_TOLERANCE
    for rec, mod in zip(recorded.links, model.links, strict=True):
        if not math.isclose(rec.length_m, mod.length_m, abs_tol=length_tol):
            raise CalibrationInputError(
                f"{source}: recorded on another leg layout: its {rec.name} is {rec.length_m:.3f} m long, the "
                f"model's {mod.length_m:.3f} m"
            )
    for rj, mj in zip(recorded.joints, model.joints, strict=True):
        if abs(rj.lower_rad - mj.lower_rad) > angle_tol or abs(rj.upper_rad - mj.upper_rad) > angle_tol:
            raise CalibrationInputError(
                f"{source}: recorded on another leg layout: its {rj.name} joint spans "
                f"[{rj.lower_rad:.3f}, {rj.upper_rad:.3f}] rad, the model's "
                f"[{mj.lower_rad:.3f}, {mj.upper_rad:.3f}]"
            )


def load_recorded_run(
    bag: Path | str,
    min_babbling_s: float = 10.0,
    rig_namespace: str = DEFAULT_NAMESPACE,
    leg_config: MujocoLegConfig | None = None,
) -> RecordedRun:
    """The babbling and attempts of a recorded run, checked for a calibration.

    Args:
        bag: the bag directory.
        min_babbling_s: the least babbling a calibration accepts (s).
        rig_namespace: the rig's namespace in the bag.
        leg_config: the simulated rig to replay on; None takes the recording rig's carriage height, tick
            rate and sub-steps from its recorded configuration (the treadmill defaults otherwise). Its
            calibration is never taken from the bag: the fit starts from the model.

    Raises:
        CalibrationInputError: the bag cannot be read, has no babbling or too little of it, lacks motor
            currents, or was recorded on another leg layout.
    """
    source = str(bag)
    try:
        run = load_run(bag, rig_namespace)
    except BagError as err:
        raise CalibrationInputError(f"{source}: cannot be read: {err}") from err
    if leg_config is None:
        settings = _rig_settings(run.configs, rig_namespace)
        leg_config = (
            MujocoLegConfig(**settings)
            if settings
            else MujocoLegConfig(carriage_height_m=TREADMILL_CARRIAGE_HEIGHT_M)
        )
    tick_hz = leg_config.tick_hz
    stamps = run.ticks.recording.t_s

    def of(recording: Recording, name: str) -> Segment:
        before = stamps[stamps < recording.t_s[0]]
        return segment_of(recording, name, tick_hz, float(before.max()) if before.size else None)

    babbling = [of(r, "babbling") for r in _contiguous(run.babbling_segments, stamps) if len(r)]
    if not babbling:
        raise CalibrationInputError(
            f"{source}: no babbling to calibrate on (no ticks between a 'phase_start' and 'phase_end' event "
            "of phase 'babbling')"
        )
    seconds = sum(s.duration_s for s in babbling)
    if seconds < min_babbling_s:
        raise CalibrationInputError(
            f"{source}: {sum(len(s) for s in babbling)} babbling ticks ({seconds:.1f} s); "
            "a calibration needs "
            f"at least {min_babbling_s:.0f} s"
        )
    if not any(np.any(s.current_a != 0.0) for s in babbling):
        raise CalibrationInputError(f"{source}: the motor currents (motor_power) are all zero or missing")
    if run.leg_description is not None:
        model_leg = leg_description(MujocoLeg(leg_config).model)
        check_layout(run.leg_description, model_leg, source)
    attempts = [of(a.recording, f"attempt {a.attempt}") for a in run.attempts if len(a.recording)]
    return RecordedRun(Path(bag), babbling, attempts, leg_config)
