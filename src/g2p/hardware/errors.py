"""Errors of the hardware layer: one hierarchy, so a caller can catch all of them at once."""

from __future__ import annotations


class HardwareError(Exception):
    """Base class of every error raised by `g2p.hardware`."""


class DeviceError(HardwareError):
    """A device did not answer as the chip does (absent, miswired, or misconfigured); names the device."""


class EncoderError(HardwareError):
    """An absolute encoder frame could not be trusted."""


class EncoderParityError(EncoderError):
    """The frame read back from an encoder failed its even-parity check."""


class EncoderErrorFlag(EncoderError):
    """The encoder set its error flag (a framing, command or parity error in an earlier frame).

    Attributes:
        error_bits: the encoder's error register, read (and so cleared) after the flag was seen.
    """

    def __init__(self, message: str, error_bits: int) -> None:
        super().__init__(message)
        self.error_bits = error_bits


class HardwareFault(HardwareError):
    """A persistent fault: reads or writes failed on too many consecutive ticks.

    The plant has already driven its outputs to baseline (or off when the outputs themselves failed); it
    refuses to step until it is closed.
    """
