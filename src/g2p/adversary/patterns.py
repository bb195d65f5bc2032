"""Open-loop activation sequences an adversarial client plays: the two spaces the adversary searches.

- `Pattern` (the "periodic" space): each motor follows its own trapezoid wave, `level` for a `duty` share
  of its `period_s`, baseline the rest, shifted by `phase` (a share of the period), each edge slewing at
  most `rise` per tick; 15 numbers.
- `StepSequence` (the "steps" space): free steps, 16 levels per motor each held the same number of ticks,
  looped; 49 numbers. No shape is assumed: any command sequence of that resolution is one of them.

Both map from the unit cube for a search (`from_unit`, `to_unit`) and play as one row of activations per
tick (`activations`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np
from numpy.typing import NDArray

from g2p.plant import N_MOTORS
from g2p.safety import BASELINE_ACTIVATION
from g2p.validation import require

FloatArray = NDArray[np.float64]

# The ranges a search draws from: periods 0.1-2 s (0.5-10 Hz), duty 10-90 %, levels baseline-1, edges
# slewing 0.02-1 per tick (a stair step in one tick).
PERIOD_RANGE_S = (0.1, 2.0)
DUTY_RANGE = (0.1, 0.9)
RISE_RANGE = (0.02, 1.0)
N_PARAMETERS = 5 * N_MOTORS
# A step sequence: 16 steps per motor, each held 1-16 ticks (a loop of 16-256 ticks: 0.2-3.3 s).
N_STEPS = 16
HOLD_RANGE_TICKS = (1, 16)


class Space(Protocol):
    """What a searched space of activation sequences offers (`Pattern`, `StepSequence`)."""

    n_parameters: ClassVar[int]

    @classmethod
    def from_unit(cls, x: FloatArray) -> Space:
        """The sequence at `x` in the unit cube, shape (n_parameters,)."""

    def to_unit(self) -> FloatArray:
        """The sequence's point in the unit cube, shape (n_parameters,)."""

    def activations(self, seconds: float, tick_hz: float) -> FloatArray:
        """The sequence for `seconds` at `tick_hz`, one row per tick, shape (N, 3)."""

    def describe(self) -> dict[str, list[Any]]:
        """The sequence's numbers, rounded, for a report."""


@dataclass(frozen=True)
class Pattern:
    """One trapezoid wave per motor (module docstring); each attribute has shape (3,).

    Attributes:
        period_s: each motor's period (s).
        phase: where in its period each motor starts (share of the period, [0, 1)).
        duty: the share of the period each motor is at its level ((0, 1)).
        level: each motor's activation while on ([baseline, 1]); baseline while off.
        rise: the most each motor's activation moves in one tick, up or down ((0, 1]).
    """

    n_parameters: ClassVar[int] = N_PARAMETERS

    period_s: FloatArray
    phase: FloatArray
    duty: FloatArray
    level: FloatArray
    rise: FloatArray

    def __post_init__(self) -> None:
        for name in ("period_s", "phase", "duty", "level", "rise"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            require(value.shape == (N_MOTORS,), name, f"must have shape (3,), got {value.shape}")
            require(bool(np.all(np.isfinite(value))), name, f"must be finite, got {value.tolist()}")
            object.__setattr__(self, name, value)
        require(bool(np.all(self.period_s > 0)), "period_s", f"must be > 0, got {self.period_s.tolist()}")
        require(bool(np.all((self.duty > 0) & (self.duty < 1))), "duty", "must be in (0, 1)")
        require(bool(np.all((self.level >= 0) & (self.level <= 1))), "level", "must be in [0, 1]")
        require(bool(np.all((self.rise > 0) & (self.rise <= 1))), "rise", "must be in (0, 1]")

    @classmethod
    def from_unit(cls, x: FloatArray) -> Pattern:
        """The pattern at `x` in the unit cube, shape (15,).

        Per motor: period (log scale), phase, duty, level, rise (log scale).
        """
        x = np.asarray(x, dtype=np.float64).reshape(5, N_MOTORS)
        require(bool(np.all((x >= 0) & (x <= 1))), "x", "must lie in the unit cube")

        def log_range(u: FloatArray, lo: float, hi: float) -> FloatArray:
            return np.exp(math.log(lo) + u * (math.log(hi) - math.log(lo)))

        return cls(
            period_s=log_range(x[0], *PERIOD_RANGE_S),
            phase=np.minimum(x[1], 1.0 - 1e-12),
            duty=DUTY_RANGE[0] + x[2] * (DUTY_RANGE[1] - DUTY_RANGE[0]),
            level=BASELINE_ACTIVATION + x[3] * (1.0 - BASELINE_ACTIVATION),
            rise=log_range(x[4], *RISE_RANGE),
        )

    def to_unit(self) -> FloatArray:
        """The pattern's point in the unit cube, shape (15,): the inverse of `from_unit`, clipped to it."""

        def log_unit(value: FloatArray, lo: float, hi: float) -> FloatArray:
            result: FloatArray = (np.log(value) - math.log(lo)) / (math.log(hi) - math.log(lo))
            return result

        x = np.stack(
            [
                log_unit(self.period_s, *PERIOD_RANGE_S),
                self.phase,
                (self.duty - DUTY_RANGE[0]) / (DUTY_RANGE[1] - DUTY_RANGE[0]),
                (self.level - BASELINE_ACTIVATION) / (1.0 - BASELINE_ACTIVATION),
                log_unit(self.rise, *RISE_RANGE),
            ]
        )
        result: FloatArray = np.clip(x, 0.0, 1.0).ravel()
        return result

    def activations(self, seconds: float, tick_hz: float) -> FloatArray:
        """The pattern from baseline for `seconds` at `tick_hz`, one row per tick, shape (N, 3)."""
        t = np.arange(round(seconds * tick_hz)) / tick_hz
        cycle = (t[:, None] / self.period_s + self.phase) % 1.0
        target = np.where(cycle < self.duty, self.level, BASELINE_ACTIVATION)  # (N, 3)
        out = np.empty_like(target)
        last = np.full(N_MOTORS, BASELINE_ACTIVATION)
        for k, row in enumerate(target):
            step = row - last  # a step within the slew lands on its target exactly
            last = np.where(np.abs(step) <= self.rise, row, last + np.sign(step) * self.rise)
            out[k] = last
        return out

    def describe(self) -> dict[str, list[float]]:
        """The pattern's numbers, rounded, for a report."""
        return {
            "period_s": self.period_s.round(3).tolist(),
            "phase": self.phase.round(3).tolist(),
            "duty": self.duty.round(3).tolist(),
            "level": self.level.round(3).tolist(),
            "rise": self.rise.round(3).tolist(),
        }


@dataclass(frozen=True)
class StepSequence:
    """Free steps, looped (module docstring).

    Attributes:
        levels: each step's activation per motor, shape (N_STEPS, 3), each in [baseline, 1].
        hold_ticks: ticks each step is held (1-16).
    """

    n_parameters: ClassVar[int] = N_STEPS * N_MOTORS + 1

    levels: FloatArray
    hold_ticks: int

    def __post_init__(self) -> None:
        levels = np.asarray(self.levels, dtype=np.float64)
        require(levels.shape == (N_STEPS, N_MOTORS), "levels", f"must have shape (16, 3), got {levels.shape}")
        require(
            bool(np.all((levels >= BASELINE_ACTIVATION) & (levels <= 1))),
            "levels",
            f"must lie in [{BASELINE_ACTIVATION}, 1]",
        )
        lo, hi = HOLD_RANGE_TICKS
        require(lo <= self.hold_ticks <= hi, "hold_ticks", f"must be in [{lo}, {hi}], got {self.hold_ticks}")
        object.__setattr__(self, "levels", levels)

    @classmethod
    def from_unit(cls, x: FloatArray) -> StepSequence:
        """The sequence at `x` in the unit cube, shape (49,): 48 levels (step-major), then the hold."""
        x = np.asarray(x, dtype=np.float64)
        require(x.shape == (cls.n_parameters,), "x", f"must have shape ({cls.n_parameters},), got {x.shape}")
        require(bool(np.all((x >= 0) & (x <= 1))), "x", "must lie in the unit cube")
        lo, hi = HOLD_RANGE_TICKS
        return cls(
            levels=BASELINE_ACTIVATION + x[:-1].reshape(N_STEPS, N_MOTORS) * (1.0 - BASELINE_ACTIVATION),
            hold_ticks=round(lo + x[-1] * (hi - lo)),
        )

    def to_unit(self) -> FloatArray:
        """The sequence's point in the unit cube, shape (49,): the inverse of `from_unit`."""
        lo, hi = HOLD_RANGE_TICKS
        levels = (self.levels - BASELINE_ACTIVATION) / (1.0 - BASELINE_ACTIVATION)
        result: FloatArray = np.append(levels.ravel(), (self.hold_ticks - lo) / (hi - lo))
        return result

    def activations(self, seconds: float, tick_hz: float) -> FloatArray:
        """The loop from its first step for `seconds` at `tick_hz`, one row per tick, shape (N, 3)."""
        loop = np.repeat(self.levels, self.hold_ticks, axis=0)
        n = round(seconds * tick_hz)
        result: FloatArray = np.tile(loop, (-(-n // len(loop)), 1))[:n]
        return result

    def describe(self) -> dict[str, list[Any]]:
        """The sequence's numbers, rounded, for a report."""
        return {"levels": self.levels.round(3).tolist(), "hold_ticks": [float(self.hold_ticks)]}


# The searched spaces by name.
SPACES: dict[str, type[Space]] = {"periodic": Pattern, "steps": StepSequence}


def square_wave(
    seconds: float, tick_hz: float, hz: float, high: tuple[float, ...], low: tuple[float, ...]
) -> FloatArray:
    """`high` for half of each period at `hz`, then `low`, from the first tick: shape (N, 3)."""
    t = np.arange(round(seconds * tick_hz)) / tick_hz
    first = (np.floor(t * hz * 2) % 2 == 0)[:, None]
    return np.where(first, np.asarray(high, dtype=np.float64), np.asarray(low, dtype=np.float64))


def rising_by(activations: FloatArray, step: float) -> FloatArray:
    """`activations` (N, 3) with every rise spread over ticks of at most `step` (falls pass at once).

    The walk-around of a ramp that caps one tick's rise: each tick rises by no more than it allows.
    """
    out = np.empty_like(activations)
    last = np.full(activations.shape[1], BASELINE_ACTIVATION)
    for k, row in enumerate(activations):
        last = np.minimum(row, last + step)
        out[k] = last
    return out


def known_attacks() -> dict[str, Pattern]:
    """The plain attacks as patterns, to start a search from.

    The 0.97 Hz two-phase square wave (M0 and M2 against M1) and the 4 Hz square wave of M0 against M1,
    each stepped at once and slewing 0.2 a tick.
    """
    out = {}
    for name, hz, level, phase in (
        ("square_0.97hz", 0.97, (1.0, 1.0, 1.0), (0.0, 0.5, 0.0)),
        ("square_4hz_m0_m1", 4.0, (1.0, 1.0, BASELINE_ACTIVATION), (0.0, 0.5, 0.0)),
    ):
        for rise in (1.0, 0.2):
            out[f"{name}_rising_{rise:g}"] = Pattern(
                period_s=np.full(N_MOTORS, 1.0 / hz),
                phase=np.array(phase),
                duty=np.full(N_MOTORS, 0.5),
                level=np.array(level),
                rise=np.full(N_MOTORS, rise),
            )
    return out
