"""PCA9685 16-channel 12-bit PWM controller over I2C (NXP PCA9685 datasheet, rev. 4).

Registers: MODE1 0x00 (bit 7 RESTART, 5 AI auto-increment, 4 SLEEP, 0 ALLCALL; power-on 0x11), MODE2
0x01 (bit 4 INVRT, 3 OCH, 2 OUTDRV totem pole; power-on 0x04), LEDn_ON_L/ON_H/OFF_L/OFF_H at 0x06 + 4n,
ALL_LED_ON_L..ALL_LED_OFF_H 0xFA..0xFD (writing them writes every channel), PRE_SCALE 0xFE. A channel's
output goes high at count ON and low at count OFF of a 4096-count period; bit 4 of ON_H is "full on" and
bit 4 of OFF_H is "full off" (full off wins). The PWM frequency is osc / (4096 (PRE_SCALE + 1)) with the
25 MHz internal oscillator, PRE_SCALE in 3..255 (24..1526 Hz), writable only while SLEEP is set. Sequence
used here: MODE1 = mode | SLEEP, PRE_SCALE, MODE1 = mode (wake), wait 500 us for the oscillator, then
MODE1 = mode | RESTART to restart the channels. Outputs change at the I2C STOP (OCH = 0).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from g2p.hardware.buses import I2cBus
from g2p.hardware.errors import DeviceError

REG_MODE1 = 0x00
REG_MODE2 = 0x01
REG_LED0_ON_L = 0x06
REG_ALL_LED_ON_L = 0xFA
REG_ALL_LED_OFF_H = 0xFD
REG_PRESCALE = 0xFE

MODE1_RESTART = 0x80
MODE1_EXTCLK = 0x40
MODE1_AI = 0x20
MODE1_SLEEP = 0x10
MODE1_ALLCALL = 0x01
MODE2_INVRT = 0x10
MODE2_OUTDRV = 0x04
FULL_BIT = 0x10  # bit 4 of ON_H (full on) and of OFF_H (full off)

N_CHANNELS = 16
PERIOD_COUNTS = 4096
INTERNAL_OSC_HZ = 25_000_000.0
PRESCALE_MIN, PRESCALE_MAX = 3, 255
OSC_STARTUP_S = 0.0005


def prescale_for(frequency_hz: float, oscillator_hz: float = INTERNAL_OSC_HZ) -> int:
    """PRE_SCALE for a PWM frequency: round(osc / (4096 f)) - 1 (datasheet eq. 1).

    Raises:
        ValueError: the frequency is outside what PRE_SCALE 3..255 reaches.
    """
    prescale = round(oscillator_hz / (PERIOD_COUNTS * frequency_hz)) - 1
    if not PRESCALE_MIN <= prescale <= PRESCALE_MAX:
        lo = oscillator_hz / (PERIOD_COUNTS * (PRESCALE_MAX + 1))
        hi = oscillator_hz / (PERIOD_COUNTS * (PRESCALE_MIN + 1))
        raise ValueError(f"frequency_hz: must be in [{lo:.1f}, {hi:.1f}] Hz, got {frequency_hz}")
    return prescale


def led_registers(duty: float) -> list[int]:
    """LEDn_ON_L, ON_H, OFF_L, OFF_H for a duty cycle in [0, 1]: 0 is full off, 1 is full on.

    In between, the output rises at count 0 and falls at round(duty * 4096).
    """
    if not 0.0 <= duty <= 1.0:
        raise ValueError(f"duty: must be in [0, 1], got {duty}")
    counts = round(duty * PERIOD_COUNTS)
    if counts <= 0:
        return [0, 0, 0, FULL_BIT]
    if counts >= PERIOD_COUNTS:
        return [0, FULL_BIT, 0, 0]
    return [0, 0, counts & 0xFF, counts >> 8]


def duty_of(registers: list[int]) -> float:
    """The duty cycle (0..1) that LEDn_ON_L, ON_H, OFF_L, OFF_H produce (full off wins over full on)."""
    on_l, on_h, off_l, off_h = registers
    if off_h & FULL_BIT:
        return 0.0
    if on_h & FULL_BIT:
        return 1.0
    on = ((on_h & 0x0F) << 8) | on_l
    off = ((off_h & 0x0F) << 8) | off_l
    return ((off - on) % PERIOD_COUNTS) / PERIOD_COUNTS


class PCA9685:
    """One PCA9685 on an I2C bus, its channels driving the motor drivers' PWM set-value inputs.

    Args:
        bus: the I2C bus.
        address: 7-bit address (0x40 with A5..A0 low).
        oscillator_hz: the clock the prescaler divides (25 MHz internal).
        name: for messages (e.g. "PCA9685 0x40 on i2c-1").
        sleep: how to wait for the oscillator to start (s -> None); time.sleep on the rig.
    """

    def __init__(
        self,
        bus: I2cBus,
        address: int = 0x40,
        oscillator_hz: float = INTERNAL_OSC_HZ,
        name: str = "PCA9685",
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self._bus = bus
        self.address = address
        self.oscillator_hz = oscillator_hz
        self.name = name
        self._sleep = sleep

    def configure(self, frequency_hz: float, invert: bool = False) -> float:
        """Put every channel full off, set the PWM frequency, wake the chip with auto-increment on.

        Args:
            frequency_hz: the PWM frequency wanted (Hz).
            invert: invert the outputs (MODE2 INVRT), for drivers behind an inverting stage.

        Returns:
            The PWM frequency obtained (Hz): osc / (4096 (PRE_SCALE + 1)).

        Raises:
            ValueError: the frequency is out of range.
            DeviceError: PRE_SCALE or MODE2 read back wrong (no chip, or another chip at the address).
            OSError: an I2C transaction failed.
        """
        prescale = prescale_for(frequency_hz, self.oscillator_hz)
        mode2 = MODE2_OUTDRV | (MODE2_INVRT if invert else 0)
        self.all_off()
        self._bus.write_byte_data(self.address, REG_MODE2, mode2)
        old = self._bus.read_byte_data(self.address, REG_MODE1)
        awake = (old & ~(MODE1_RESTART | MODE1_SLEEP)) | MODE1_AI
        self._bus.write_byte_data(self.address, REG_MODE1, awake | MODE1_SLEEP)
        self._bus.write_byte_data(self.address, REG_PRESCALE, prescale)
        self._bus.write_byte_data(self.address, REG_MODE1, awake)
        self._sleep(OSC_STARTUP_S)
        self._bus.write_byte_data(self.address, REG_MODE1, awake | MODE1_RESTART)
        got_prescale = self._bus.read_byte_data(self.address, REG_PRESCALE)
        got_mode2 = self._bus.read_byte_data(self.address, REG_MODE2)
        if got_prescale != prescale or got_mode2 != mode2:
            raise DeviceError(
                f"{self.name}: PRE_SCALE/MODE2 read back {got_prescale:#04x}/{got_mode2:#04x}, wrote "
                f"{prescale:#04x}/{mode2:#04x}: is a PCA9685 at address {self.address:#04x}?"
            )
        return self.oscillator_hz / (PERIOD_COUNTS * (prescale + 1))

    def set_duty(self, channel: int, duty: float) -> None:
        """Set one channel's duty cycle (0..1) in one 4-byte auto-increment write.

        Raises:
            ValueError: bad channel or duty.
            OSError: the I2C write failed.
        """
        if not 0 <= channel < N_CHANNELS:
            raise ValueError(f"channel: must be in [0, {N_CHANNELS}), got {channel}")
        self._bus.write_i2c_block_data(self.address, REG_LED0_ON_L + 4 * channel, led_registers(duty))

    def read_duty(self, channel: int) -> float:
        """Read back one channel's duty cycle (0..1) from its four LED registers."""
        regs = self._bus.read_i2c_block_data(self.address, REG_LED0_ON_L + 4 * channel, 4)
        return duty_of(list(regs))

    def all_off(self) -> None:
        """Every channel full off in one write (ALL_LED_OFF_H bit 4)."""
        self._bus.write_byte_data(self.address, REG_ALL_LED_OFF_H, FULL_BIT)

    def sleep(self) -> None:
        """Every channel full off, then the oscillator off (low-power mode)."""
        self.all_off()
        mode1 = self._bus.read_byte_data(self.address, REG_MODE1)
        self._bus.write_byte_data(self.address, REG_MODE1, (mode1 & ~MODE1_RESTART) | MODE1_SLEEP)

    def close(self) -> None:
        """Every channel full off and the chip asleep (the bus is closed by its owner)."""
        self.sleep()
