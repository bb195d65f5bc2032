"""What the device classes need from a bus: the subset of spidev, smbus2 and gpiod they use.

The device classes take these objects as arguments and never import the Linux libraries themselves;
`g2p.hardware.devices` opens the real ones and `g2p.hardware_fake.chips` provides chips that answer byte for
byte, so everything above this layer is tested without a Raspberry Pi.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol


class SpiDevice(Protocol):
    """One SPI chip select, as `spidev.SpiDev` after `open(bus, device)`."""

    def xfer2(self, data: list[int]) -> list[int]:
        """Clock `data` out with chip select held low for the whole transfer; return the bytes read.

        Raises:
            OSError: the transfer failed.
        """
        ...

    def close(self) -> None:
        """Release the device."""
        ...


class I2cBus(Protocol):
    """An I2C bus adapter, as `smbus2.SMBus(n)`: SMBus transactions addressed to a 7-bit address.

    All methods raise OSError when the transaction fails (no acknowledge, bus error, timeout).
    """

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        """Read one byte from `register`."""
        ...

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        """Write one byte to `register`."""
        ...

    def read_word_data(self, i2c_addr: int, register: int) -> int:
        """Read a 16-bit word from `register`; SMBus order: the first byte on the wire is the LOW byte."""
        ...

    def write_word_data(self, i2c_addr: int, register: int, value: int) -> None:
        """Write a 16-bit word to `register`; SMBus order: the low byte goes first on the wire."""
        ...

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        """Read `length` bytes starting at `register` (I2C block read)."""
        ...

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int]) -> None:
        """Write bytes starting at `register` (I2C block write)."""
        ...

    def close(self) -> None:
        """Release the adapter."""
        ...


class OutputLine(Protocol):
    """One GPIO output line (a gpiod line request), logical value: True = asserted."""

    def set_value(self, active: bool) -> None:
        """Drive the line to its active (True) or inactive (False) level.

        Raises:
            OSError: the line could not be set.
        """
        ...

    def close(self) -> None:
        """Release the line."""
        ...
