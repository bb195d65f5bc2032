"""What the rig's electronics add to the physics: the jittered tick clock and the joint encoders."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class TickClock:
    """Draws the period of each rig tick: nominal period plus uniform jitter.

    The Raspberry Pi loop of the rig ran at 78 +/- 5 Hz, not uniformly; each period is drawn
    independently as 1/hz + U(-jitter_s, +jitter_s) from the generator given.

    Args:
        rng: the generator the periods are drawn from (the only randomness of the plant).
        hz: nominal tick rate (Hz), > 0.
        jitter_s: half-width of the jitter (s), in [0, 0.5 / hz).
    """

    def __init__(self, rng: np.random.Generator, hz: float, jitter_s: float) -> None:
        if not (math.isfinite(hz) and hz > 0):
            raise ValueError(f"hz: must be a finite number > 0, got {hz!r}")
        if not (math.isfinite(jitter_s) and 0.0 <= jitter_s < 0.5 / hz):
            raise ValueError(f"jitter_s: must be in [0, {0.5 / hz}), got {jitter_s!r}")
        self._rng = rng
        self.nominal_period_s = 1.0 / hz
        self.jitter_s = jitter_s

    def next_period(self) -> float:
        """The duration of the next tick (s)."""
        return self.nominal_period_s + float(self._rng.uniform(-self.jitter_s, self.jitter_s))


def encoder_step_rad(bits: int) -> float:
    """Angle of one count of an absolute encoder with `bits` bits per turn (rad)."""
    return 2.0 * math.pi / (1 << bits)


def quantize_angle(angle_rad: FloatArray, bits: int) -> FloatArray:
    """What an absolute encoder with `bits` bits per turn reads for the angles given.

    Args:
        angle_rad: true angles, any shape (rad).
        bits: encoder resolution (bits per turn).

    Returns:
        The angles rounded to the nearest count, same shape (rad).
    """
    step = encoder_step_rad(bits)
    return np.round(np.asarray(angle_rad, dtype=np.float64) / step) * step
