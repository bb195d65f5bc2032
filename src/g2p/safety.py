"""What stands between a command and the motors: validation, clamping, baseline tension, watchdog.

Both rigs (the MuJoCo simulator and the hardware driver) pass every command through an
`ActivationGate`, so invalid commands never reach the physics or the PWM outputs, and a rig whose
commands stop drops to baseline tension within a fixed number of ticks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

N_MOTORS = 3
# Tendons go slack below this activation, so the rig always applies at least 15% (paper, Methods).
BASELINE_ACTIVATION = 0.15


class InvalidActivation(ValueError):
    """An activation command is not 3 finite numbers."""


def check_activation(activation: ArrayLike) -> FloatArray:
    """Return `activation` as a float array of shape (3,), or raise InvalidActivation.

    Values outside [0, 1] are allowed here; `clamp_activation` deals with them.
    """
    a = np.asarray(activation, dtype=np.float64)
    if a.shape != (N_MOTORS,):
        raise InvalidActivation(f"activation must have {N_MOTORS} values, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InvalidActivation(f"activation must be finite, got {a.tolist()}")
    return a


def check_activation_sequence(activations: ArrayLike) -> FloatArray:
    """Return `activations` as a float array of shape (N, 3) with N >= 1, finite, in [0, 1].

    Raises:
        InvalidActivation: wrong shape, empty, non-finite or out-of-range values (the message says which).
    """
    a = np.asarray(activations, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != N_MOTORS or a.shape[0] == 0:
        raise InvalidActivation(f"activation sequence must have shape (N >= 1, {N_MOTORS}), got {a.shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        raise InvalidActivation(
            f"activation sequence has {int(bad.sum())} non-finite values, first at row "
            f"{int(np.argwhere(bad)[0, 0])}"
        )
    out = (a < 0.0) | (a > 1.0)
    if out.any():
        row = int(np.argwhere(out)[0, 0])
        raise InvalidActivation(
            f"activation sequence has {int(out.sum())} values outside [0, 1], first at "
            f"row {row}: {a[row].tolist()}"
        )
    return a


def clamp_activation(activation: FloatArray, baseline: float = BASELINE_ACTIVATION) -> FloatArray:
    """Clamp finite activations (3,) to [baseline, 1]: what a rig actually applies."""
    return np.clip(activation, baseline, 1.0)


@dataclass
class GateCounters:
    """How many commands the gate saw, by outcome."""

    accepted: int = 0
    clamped: int = 0
    rejected: int = 0
    watchdog_trips: int = 0


class ActivationGate:
    """Holds the latest valid command and decides the activation of each tick.

    Commands are validated (`command`); each tick asks `next_activation`, which returns the held command
    clamped to [baseline, 1], or baseline once no valid command came for `timeout_ticks` ticks.

    Args:
        timeout_ticks: ticks without a valid command after which the motors drop to baseline (> 0).
        baseline: the minimal activation always applied (dimensionless).
    """

    def __init__(self, timeout_ticks: int = 3, baseline: float = BASELINE_ACTIVATION) -> None:
        if timeout_ticks < 1:
            raise ValueError(f"timeout_ticks: must be >= 1, got {timeout_ticks}")
        if not 0.0 <= baseline < 1.0:
            raise ValueError(f"baseline: must be in [0, 1), got {baseline}")
        self.timeout_ticks = timeout_ticks
        self.baseline = baseline
        self.counters = GateCounters()
        self._held = np.full(N_MOTORS, baseline)
        self._ticks_since_command = timeout_ticks + 1  # start at baseline, as after a stop: no trip counted

    @property
    def baseline_activation(self) -> FloatArray:
        """The baseline activation vector, shape (3,)."""
        return np.full(N_MOTORS, self.baseline)

    def command(self, activation: Sequence[float] | FloatArray) -> FloatArray | None:
        """Accept a new command, or reject it.

        Returns:
            The command as it will be applied (clamped), or None when it was rejected (NaN, Inf or a
            wrong length): a rejected command changes nothing and does not feed the watchdog.
        """
        try:
            a = check_activation(activation)
        except InvalidActivation:
            self.counters.rejected += 1
            return None
        clamped = clamp_activation(a, self.baseline)
        if np.any((a < 0.0) | (a > 1.0)):
            self.counters.clamped += 1
        self.counters.accepted += 1
        self._held = clamped
        self._ticks_since_command = 0
        return clamped

    def next_activation(self) -> FloatArray:
        """The activation to apply during the coming tick; advances the watchdog by one tick."""
        if self._ticks_since_command >= self.timeout_ticks:
            if self._ticks_since_command == self.timeout_ticks:
                self.counters.watchdog_trips += 1
            self._held = self.baseline_activation
        self._ticks_since_command += 1
        return self._held.copy()

    def stop(self) -> FloatArray:
        """Drop to baseline at once (cancel, fault, shutdown); returns the baseline activation."""
        self._held = self.baseline_activation
        self._ticks_since_command = self.timeout_ticks + 1
        return self._held.copy()
