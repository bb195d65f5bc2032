"""AS5048A / AS5047P 14-bit absolute magnetic encoders over SPI (ams datasheets, "SPI interface").

Framing (both chips, SPI mode 1, 16-bit frames, MSB first, chip select released between frames):
    command frame: bit 15 = even parity over bits 14..0, bit 14 = 1 read / 0 write, bits 13..0 = address.
    read frame:    bit 15 = even parity over bits 14..0, bit 14 = error flag (EF), bits 13..0 = data.
A read is pipelined: the data of a command comes back in the NEXT frame, so `read_register` sends the
command, then a NOP (address 0x0000) whose answer carries the data. "Read angle" is 0xFFFF (address
0x3FFF, read, parity 1); "read error register" is 0x4001 (address 0x0001, read, parity 0). Reading the
error register clears it and the error flag: bit 0 framing error, bit 1 invalid command, bit 2 parity
error. The diagnostics register (AS5048A: 0x3FFD DIAG+AGC, AS5047P: 0x3FFC DIAAGC) has the same bits
where this module reads them: 7..0 AGC, 9 CORDIC overflow, 10 field too strong, 11 field too weak.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from g2p.hardware.buses import SpiDevice
from g2p.hardware.errors import EncoderErrorFlag, EncoderParityError

COUNTS_PER_TURN = 1 << 14
PARITY_BIT = 0x8000
READ_BIT = 0x4000
ERROR_FLAG = 0x4000
DATA_MASK = 0x3FFF

REG_NOP = 0x0000
REG_ERROR = 0x0001
REG_MAGNITUDE = 0x3FFE
REG_ANGLE = 0x3FFF

ERROR_FRAMING = 0x1
ERROR_COMMAND_INVALID = 0x2
ERROR_PARITY = 0x4

_DIAG_COF = 1 << 9
_DIAG_TOO_STRONG = 1 << 10
_DIAG_TOO_WEAK = 1 << 11


class EncoderModel(enum.Enum):
    """Which chip: they share the framing, the angle and error registers; diagnostics differ in address."""

    AS5048A = "as5048a"
    AS5047P = "as5047p"

    @property
    def diagnostics_register(self) -> int:
        """Address of the AGC / magnet diagnostics register."""
        return 0x3FFD if self is EncoderModel.AS5048A else 0x3FFC


def has_even_parity(word: int) -> bool:
    """Whether the 16-bit `word` has an even number of ones (what a valid frame has)."""
    return bin(word & 0xFFFF).count("1") % 2 == 0


def command_frame(address: int, read: bool = True) -> int:
    """The 16-bit command frame for `address` (14 bits): R/W bit and even parity in bit 15."""
    if not 0 <= address <= DATA_MASK:
        raise ValueError(f"address: must be in [0, 0x3FFF], got {address:#x}")
    frame = address | (READ_BIT if read else 0)
    return frame | (0 if has_even_parity(frame) else PARITY_BIT)


READ_ANGLE = command_frame(REG_ANGLE)  # 0xFFFF
CLEAR_ERROR = command_frame(REG_ERROR)  # 0x4001
NOP = command_frame(REG_NOP)  # 0xC000


@dataclass(frozen=True)
class MagnetStatus:
    """The encoder's view of its magnet.

    Attributes:
        agc: automatic gain control value, 0..255 (high = weak field).
        cordic_overflow: the angle computation overflowed: angle data invalid.
        too_strong: the magnetic field is too strong (magnet too close).
        too_weak: the magnetic field is too weak (magnet too far or missing).
    """

    agc: int
    cordic_overflow: bool
    too_strong: bool
    too_weak: bool

    @property
    def ok(self) -> bool:
        """Whether the angle can be trusted."""
        return not (self.cordic_overflow or self.too_strong or self.too_weak)


@dataclass
class EncoderCounters:
    """Faults seen on one encoder since it was opened."""

    parity_errors: int = 0
    error_flags: int = 0


class AS5048A:
    """One AS5048A (or AS5047P) on its own chip select, reporting a joint angle.

    Args:
        spi: the SPI device (mode 1, up to 10 MHz).
        zero_offset_counts: raw reading (0..16383) when the joint is at its zero (leg hanging straight).
        direction: +1 when the raw count grows as the joint turns counter-clockwise (the plant's positive
            direction), -1 otherwise.
        model: which chip, for the diagnostics register.
        name: for messages (e.g. "proximal encoder (spi0.0)").
    """

    def __init__(
        self,
        spi: SpiDevice,
        zero_offset_counts: int = 0,
        direction: int = 1,
        model: EncoderModel = EncoderModel.AS5048A,
        name: str = "AS5048A",
    ) -> None:
        if not 0 <= zero_offset_counts < COUNTS_PER_TURN:
            raise ValueError(
                f"zero_offset_counts: must be in [0, {COUNTS_PER_TURN}), got {zero_offset_counts}"
            )
        if direction not in (-1, 1):
            raise ValueError(f"direction: must be +1 or -1, got {direction}")
        self._spi = spi
        self.zero_offset_counts = zero_offset_counts
        self.direction = direction
        self.model = model
        self.name = name
        self.counters = EncoderCounters()

    def _transfer(self, frame: int) -> int:
        rx = self._spi.xfer2([frame >> 8, frame & 0xFF])
        if len(rx) != 2:
            raise OSError(f"{self.name}: SPI transfer returned {len(rx)} bytes, expected 2")
        return (rx[0] << 8) | rx[1]

    def _check(self, word: int) -> int:
        if not has_even_parity(word):
            self.counters.parity_errors += 1
            raise EncoderParityError(f"{self.name}: parity error in frame {word:#06x}")
        return word

    def read_register(self, address: int) -> int:
        """Read a 14-bit register: the command frame, then a NOP frame whose answer carries the data.

        Raises:
            EncoderParityError: the answer failed its parity check.
            EncoderErrorFlag: the chip flagged an error; the error register was read (and so cleared).
            OSError: the SPI transfer failed.
        """
        self._transfer(command_frame(address))
        word = self._check(self._transfer(NOP))
        if word & ERROR_FLAG:
            self.counters.error_flags += 1
            bits = self.clear_error()
            raise EncoderErrorFlag(f"{self.name}: error flag set (error register {bits:#05b})", bits)
        return word & DATA_MASK

    def clear_error(self) -> int:
        """Read (and so clear) the error register; returns its bits (framing, command, parity).

        Raises:
            EncoderParityError: the answer failed its parity check.
            OSError: the SPI transfer failed.
        """
        self._transfer(CLEAR_ERROR)
        return self._check(self._transfer(NOP)) & 0x7

    def read_raw(self) -> int:
        """The raw angle, 0..16383 counts per turn (see `read_register` for the errors)."""
        return self.read_register(REG_ANGLE)

    def counts_to_rad(self, raw: int) -> float:
        """Joint angle (rad, in [-pi, pi)) for a raw reading, with the zero offset and direction applied."""
        counts = (raw - self.zero_offset_counts) % COUNTS_PER_TURN
        if counts >= COUNTS_PER_TURN // 2:
            counts -= COUNTS_PER_TURN
        return self.direction * counts * (2.0 * math.pi / COUNTS_PER_TURN)

    def read_angle_rad(self) -> float:
        """The joint angle (rad, ccw positive, 0 at the configured zero; see `read_register` for errors)."""
        return self.counts_to_rad(self.read_raw())

    def read_magnet(self) -> MagnetStatus:
        """The magnet diagnostics (see `read_register` for the errors)."""
        diag = self.read_register(self.model.diagnostics_register)
        return MagnetStatus(
            agc=diag & 0xFF,
            cordic_overflow=bool(diag & _DIAG_COF),
            too_strong=bool(diag & _DIAG_TOO_STRONG),
            too_weak=bool(diag & _DIAG_TOO_WEAK),
        )
