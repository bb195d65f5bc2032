"""INA219 current and power monitor over I2C (TI INA219 datasheet, SBOS448).

Registers are 16-bit and travel MSB first on the wire, whereas an SMBus word transaction puts the LOW
byte first: every word read or written here is byte-swapped (`swap16`). Registers: 0x00 configuration
(bit 15 RST, 13 BRNG 16/32 V, 12..11 PGA gain /1../8 = +-40..+-320 mV, 10..7 BADC, 6..3 SADC, 2..0 mode;
power-on 0x399F), 0x01 shunt voltage (signed, 10 uV/LSB), 0x02 bus voltage (bits 15..3, 4 mV/LSB; bit 1
CNVR conversion ready, bit 0 OVF math overflow), 0x03 power, 0x04 current (signed), 0x05 calibration.
Calibration: Cal = trunc(0.04096 / (Current_LSB * R_shunt)) with bit 0 always 0, then
Current = ShuntVoltage * Cal / 4096 in Current_LSB units, Power_LSB = 20 Current_LSB. Here
Current_LSB = max current / 2^15, and both ADCs convert 12 bits once (532 us each, so a shunt + bus pair
every 1.06 ms, enough to sample at 500 Hz).
"""

from __future__ import annotations

from dataclasses import dataclass

from g2p.hardware.buses import I2cBus
from g2p.hardware.errors import DeviceError

REG_CONFIG = 0x00
REG_SHUNT_VOLTAGE = 0x01
REG_BUS_VOLTAGE = 0x02
REG_POWER = 0x03
REG_CURRENT = 0x04
REG_CALIBRATION = 0x05

CONFIG_RESET = 0x8000
CONFIG_POWER_ON = 0x399F
BRNG_32V = 0x2000
PGA_SHIFT = 11
BADC_SHIFT = 7
SADC_SHIFT = 3
ADC_12BIT = 0x3  # 12-bit, one sample, 532 us
MODE_SHUNT_BUS_CONTINUOUS = 0x7

SHUNT_LSB_V = 10e-6
BUS_LSB_V = 0.004
BUS_CNVR = 0x2
BUS_OVF = 0x1
PGA_RANGES_V = (0.04, 0.08, 0.16, 0.32)  # PG = 00, 01, 10, 11


def swap16(word: int) -> int:
    """Swap the two bytes of a 16-bit word (INA219 MSB-first <-> SMBus low-byte-first)."""
    return ((word & 0xFF) << 8) | ((word >> 8) & 0xFF)


def to_signed16(value: int) -> int:
    """A 16-bit two's complement value as a Python int."""
    value &= 0xFFFF
    return value - 0x10000 if value & 0x8000 else value


@dataclass(frozen=True)
class Ina219Settings:
    """How one INA219 is set up, derived from the shunt and the largest current expected.

    Attributes:
        config: the configuration register value.
        calibration: the calibration register value (bit 0 clear).
        current_lsb_a: current of one count of the current register (A).
        power_lsb_w: power of one count of the power register (W).
    """

    config: int
    calibration: int
    current_lsb_a: float
    power_lsb_w: float


def settings_for(shunt_ohm: float, max_current_a: float, bus_32v: bool = True) -> Ina219Settings:
    """Configuration and calibration for a shunt (ohm) and the largest current to measure (A).

    The PGA range is the smallest that holds max_current_a * shunt_ohm.

    Raises:
        ValueError: the shunt voltage at max_current_a exceeds +-320 mV, or the calibration overflows.
    """
    if not (shunt_ohm > 0 and max_current_a > 0):
        raise ValueError(f"shunt_ohm and max_current_a must be > 0, got {shunt_ohm}, {max_current_a}")
    v_max = shunt_ohm * max_current_a
    pga = next((i for i, r in enumerate(PGA_RANGES_V) if v_max <= r * (1 + 1e-9)), None)
    if pga is None:
        raise ValueError(f"shunt voltage at max current is {v_max * 1e3:.0f} mV, above the 320 mV range")
    calibration = int(0.04096 / (max_current_a / 32768 * shunt_ohm)) & 0xFFFE
    if not 0 < calibration <= 0xFFFE:
        raise ValueError(f"calibration {calibration} out of range: use a larger max current or shunt")
    current_lsb = 0.04096 / (calibration * shunt_ohm)  # exact, after the truncation
    config = (
        (BRNG_32V if bus_32v else 0)
        | (pga << PGA_SHIFT)
        | (ADC_12BIT << BADC_SHIFT)
        | (ADC_12BIT << SADC_SHIFT)
        | MODE_SHUNT_BUS_CONTINUOUS
    )
    return Ina219Settings(config, calibration, current_lsb, 20.0 * current_lsb)


class INA219:
    """One INA219 measuring a motor driver's supply current and voltage.

    Args:
        bus: the I2C bus.
        address: 7-bit address (0x40..0x4F, set by A1/A0).
        shunt_ohm: the shunt resistor (ohm).
        max_current_a: the largest current to measure (A): sets the range and resolution.
        name: for messages (e.g. "M0 current (0x41 on i2c-1)").
    """

    def __init__(
        self, bus: I2cBus, address: int, shunt_ohm: float, max_current_a: float, name: str = "INA219"
    ) -> None:
        self._bus = bus
        self.address = address
        self.settings = settings_for(shunt_ohm, max_current_a)
        self.name = name

    def _read(self, register: int) -> int:
        return swap16(self._bus.read_word_data(self.address, register))

    def _write(self, register: int, value: int) -> None:
        self._bus.write_word_data(self.address, register, swap16(value))

    def configure(self) -> None:
        """Reset the chip, write configuration and calibration, and read them back.

        Raises:
            DeviceError: a register read back wrong (no INA219 at the address).
            OSError: an I2C transaction failed.
        """
        self._write(REG_CONFIG, CONFIG_RESET)
        self._write(REG_CONFIG, self.settings.config)
        self._write(REG_CALIBRATION, self.settings.calibration)
        config = self._read(REG_CONFIG)
        calibration = self._read(REG_CALIBRATION)
        if config != self.settings.config or calibration != self.settings.calibration:
            raise DeviceError(
                f"{self.name}: configuration/calibration read back {config:#06x}/{calibration:#06x}, "
                f"wrote {self.settings.config:#06x}/{self.settings.calibration:#06x}: is an INA219 at "
                f"address {self.address:#04x}?"
            )

    def read_current_a(self) -> float:
        """The current through the shunt (A, signed) from the current register."""
        return to_signed16(self._read(REG_CURRENT)) * self.settings.current_lsb_a

    def read_shunt_voltage_v(self) -> float:
        """The shunt voltage (V, signed)."""
        return to_signed16(self._read(REG_SHUNT_VOLTAGE)) * SHUNT_LSB_V

    def read_bus_voltage_v(self) -> tuple[float, bool]:
        """The bus voltage (V) and the math-overflow flag (current or power out of range)."""
        raw = self._read(REG_BUS_VOLTAGE)
        return (raw >> 3) * BUS_LSB_V, bool(raw & BUS_OVF)

    def read_power_w(self) -> float:
        """The power register (W, unsigned): bus voltage times current, as the chip computes it."""
        return self._read(REG_POWER) * self.settings.power_lsb_w
