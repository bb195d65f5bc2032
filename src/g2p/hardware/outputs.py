"""The motor drivers' inputs: three PWM set values and an optional enable line, driven from activations."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from g2p.hardware.buses import OutputLine
from g2p.hardware.wiring import PwmConfig
from g2p.plant import FloatArray


class PwmOutputs(Protocol):
    """A PWM generator addressed by channel (PCA9685 or a group of sysfs channels)."""

    def set_duty(self, channel: int, duty: float) -> None:
        """Set one channel's duty cycle (0..1); raises OSError when the write fails."""
        ...

    def read_duty(self, channel: int) -> float:
        """Read one channel's duty cycle back (0..1)."""
        ...

    def all_off(self) -> None:
        """Every channel to duty 0."""
        ...

    def close(self) -> None:
        """Every channel off and the generator released."""
        ...


class MotorOutputs:
    """Activations to duty cycles on the three motor channels, plus the drivers' enable line.

    Args:
        pwm: the PWM generator, configured (frequency set, outputs off).
        config: channels and the activation-to-duty map.
        enable_line: the drivers' enable line, requested inactive; None when the drivers have none.
    """

    def __init__(self, pwm: PwmOutputs, config: PwmConfig, enable_line: OutputLine | None) -> None:
        self.pwm = pwm
        self.config = config
        self.enable_line = enable_line
        self.enabled = False

    def duties(self, activation: FloatArray) -> FloatArray:
        """Duty cycles (3,) for activations (3,) in [0, 1]."""
        return np.array([self.config.duty(float(a)) for a in activation])

    def apply(self, activation: FloatArray) -> None:
        """Write the duty cycles of activations (3,), already clamped to [0, 1].

        Raises:
            OSError: a write failed (the other channels are still written).
        """
        error: OSError | None = None
        for channel, duty in zip(self.config.channels, self.duties(activation), strict=True):
            try:
                self.pwm.set_duty(channel, float(duty))
            except OSError as err:
                error = error or err
        if error is not None:
            raise error

    def read_activation(self) -> FloatArray:
        """The activations (3,) the channels currently command, read back from the PWM generator."""
        return np.array([self.config.activation(self.pwm.read_duty(c)) for c in self.config.channels])

    def enable(self) -> None:
        """Assert the drivers' enable line (call after writing the baseline duty)."""
        if self.enable_line is not None:
            self.enable_line.set_value(True)
        self.enabled = True

    def off(self) -> None:
        """Every channel to duty 0 and the enable line released to inactive, whichever fails.

        Raises:
            OSError: the PWM or the line could not be written (both were attempted).
        """
        self.enabled = False
        try:
            self.pwm.all_off()
        finally:
            if self.enable_line is not None:
                self.enable_line.set_value(False)

    def close(self) -> None:
        """Outputs off, then the PWM generator and the line released."""
        try:
            self.off()
        finally:
            try:
                self.pwm.close()
            finally:
                if self.enable_line is not None:
                    self.enable_line.close()
