"""LS7366R 32-bit quadrature counter over SPI (LSI/CSI LS7366R datasheet), counting the treadmill drum.

Every transfer starts with an instruction byte (IR): bits 7..6 the operation (00 CLR, 01 RD, 10 WR,
11 LOAD), bits 5..3 the register (001 MDR0, 010 MDR1, 011 DTR, 100 CNTR, 101 OTR, 110 STR), bits 2..0
don't care. Data follows MSB first, in SPI mode 0. This driver sets MDR0 = 0x03 (x4 quadrature,
free-running, index off, filter clock /1) and MDR1 = 0x00 (4-byte counter, counting enabled, no flags),
and reads them back to prove a chip is there. A count is read as LOAD OTR (0xE8: CNTR -> OTR, latched in
one instant) then RD OTR (0x68) with four bytes clocked out.
"""

from __future__ import annotations

import math

from g2p.hardware.buses import SpiDevice
from g2p.hardware.errors import DeviceError

OP_CLR = 0x00
OP_RD = 0x40
OP_WR = 0x80
OP_LOAD = 0xC0

REG_MDR0 = 0x08
REG_MDR1 = 0x10
REG_DTR = 0x18
REG_CNTR = 0x20
REG_OTR = 0x28
REG_STR = 0x30

MDR0_QUADRATURE = {1: 0x01, 2: 0x02, 4: 0x03}  # bits 1..0; free-running (bits 3..2 = 00), index off
MDR1_FOUR_BYTES = 0x00  # bits 1..0 = 00: 4-byte counter; bit 2 = 0: counting enabled

STR_SIGN = 0x01
STR_COUNT_UP = 0x02
STR_COUNT_ENABLED = 0x08


def to_signed32(value: int) -> int:
    """A 32-bit two's complement value as a Python int."""
    value &= 0xFFFFFFFF
    return value - (1 << 32) if value & 0x80000000 else value


class LS7366R:
    """One LS7366R on its own chip select.

    Args:
        spi: the SPI device (mode 0).
        name: for messages (e.g. "belt counter (spi1.0)").
    """

    def __init__(self, spi: SpiDevice, name: str = "LS7366R") -> None:
        self._spi = spi
        self.name = name

    def _xfer(self, data: list[int]) -> list[int]:
        rx = self._spi.xfer2(data)
        if len(rx) != len(data):
            raise OSError(f"{self.name}: SPI transfer returned {len(rx)} bytes, expected {len(data)}")
        return rx

    def configure(self, quadrature: int = 4) -> None:
        """Set x1/x2/x4 quadrature counting with a free-running 4-byte counter, check, and clear it.

        Raises:
            ValueError: `quadrature` is not 1, 2 or 4.
            DeviceError: the mode registers read back wrong (no chip, or a wiring fault).
            OSError: an SPI transfer failed.
        """
        if quadrature not in MDR0_QUADRATURE:
            raise ValueError(f"quadrature: must be 1, 2 or 4, got {quadrature}")
        mdr0 = MDR0_QUADRATURE[quadrature]
        self._xfer([OP_WR | REG_MDR0, mdr0])
        self._xfer([OP_WR | REG_MDR1, MDR1_FOUR_BYTES])
        got0 = self._xfer([OP_RD | REG_MDR0, 0])[1]
        got1 = self._xfer([OP_RD | REG_MDR1, 0])[1]
        if got0 != mdr0 or got1 != MDR1_FOUR_BYTES:
            raise DeviceError(
                f"{self.name}: mode registers read back MDR0={got0:#04x} MDR1={got1:#04x}, wrote "
                f"{mdr0:#04x} {MDR1_FOUR_BYTES:#04x}: is the LS7366R connected?"
            )
        self.clear()

    def clear(self) -> None:
        """Zero the counter and the status register."""
        self._xfer([OP_CLR | REG_CNTR])
        self._xfer([OP_CLR | REG_STR])

    def read_count(self) -> int:
        """The counter (signed 32-bit counts), latched into OTR and read out.

        Raises:
            OSError: an SPI transfer failed.
        """
        self._xfer([OP_LOAD | REG_OTR])
        rx = self._xfer([OP_RD | REG_OTR, 0, 0, 0, 0])
        return to_signed32((rx[1] << 24) | (rx[2] << 16) | (rx[3] << 8) | rx[4])

    def read_status(self) -> int:
        """The status register STR (bit 0 sign, 1 count direction, 3 counting enabled, ...)."""
        return self._xfer([OP_RD | REG_STR, 0])[1]


class BeltOdometer:
    """Cumulative belt travel from a wrapping 32-bit drum count.

    Args:
        counts_per_rev: counts per drum revolution at the counter's quadrature setting.
        drum_radius_mm: radius of the drum the belt runs on (mm).
        direction: +1 when the count grows as the belt moves backward (the reward direction), else -1.
    """

    def __init__(self, counts_per_rev: float, drum_radius_mm: float, direction: int) -> None:
        self.mm_per_count = direction * 2.0 * math.pi * drum_radius_mm / counts_per_rev
        self._last: int | None = None
        self._total_counts = 0

    def update(self, count: int) -> float:
        """Take a new raw count (any 32-bit value) and return the cumulative travel (mm, + backward).

        The first call sets the origin. Steps are taken modulo 2^32, so the counter may wrap.
        """
        if self._last is not None:
            self._total_counts += to_signed32(count - self._last)
        self._last = count
        return self._total_counts * self.mm_per_count

    @property
    def travel_mm(self) -> float:
        """The cumulative travel at the last update (mm, + backward)."""
        return self._total_counts * self.mm_per_count
