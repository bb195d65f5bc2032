"""The physical rig described in one YAML file: buses, chip selects, addresses, calibration, PWM map.

    rig = load_wiring("g2p_driver/config/wiring.yaml")

The file's sections map 1:1 onto the frozen dataclasses below (unknown or missing keys are errors that
name the key). Every value is validated; a `ConfigError` names the offending field by its dotted path,
e.g. `encoders.distal.direction: must be +1 or -1, got 0`.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import yaml

from g2p.hardware.as5048a import COUNTS_PER_TURN, EncoderModel
from g2p.hardware.pca9685 import N_CHANNELS, prescale_for
from g2p.validation import ConfigError, require, require_positive

T = TypeVar("T")


class PwmBackend(enum.Enum):
    """What generates the motor drivers' PWM set-value signals."""

    PCA9685 = "pca9685"
    SYSFS = "sysfs"


def _require_direction(value: int, name: str) -> None:
    require(value in (-1, 1), name, f"must be +1 or -1, got {value!r}")


def _require_int_range(value: int, low: int, high: int, name: str) -> None:
    require(low <= value <= high, name, f"must be an integer in [{low}, {high}], got {value!r}")


@dataclass(frozen=True)
class SpiConfig:
    """One SPI chip select, /dev/spidev<bus>.<chip_select>.

    Attributes:
        bus: SPI bus number (0 = SPI0 on GPIO 9-11, 1 = SPI1 on GPIO 19-21 with dtoverlay=spi1-1cs).
        chip_select: chip select number on that bus (CE0 = 0, CE1 = 1, ...).
        max_speed_hz: SPI clock (Hz); 1 MHz is safe over 30 cm of ribbon cable.
    """

    bus: int = 0
    chip_select: int = 0
    max_speed_hz: int = 1_000_000

    def __post_init__(self) -> None:
        _require_int_range(self.bus, 0, 15, "bus")
        _require_int_range(self.chip_select, 0, 15, "chip_select")
        _require_int_range(self.max_speed_hz, 10_000, 10_000_000, "max_speed_hz")


@dataclass(frozen=True)
class EncoderConfig:
    """An absolute joint encoder (AS5048A or AS5047P, SPI mode 1).

    Attributes:
        spi: where the encoder is wired.
        model: "as5048a" or "as5047p" (same framing; the diagnostics register differs).
        zero_offset_counts: raw reading (0..16383) with the leg hanging straight down (the joint's zero).
        direction: +1 if the raw reading grows when the joint turns counter-clockwise (the positive
            direction seen with the leg facing +x, z up), -1 if it shrinks.
    """

    spi: SpiConfig = field(default_factory=SpiConfig)
    model: EncoderModel = EncoderModel.AS5048A
    zero_offset_counts: int = 0
    direction: int = 1

    def __post_init__(self) -> None:
        _require_int_range(self.zero_offset_counts, 0, COUNTS_PER_TURN - 1, "zero_offset_counts")
        _require_direction(self.direction, "direction")


@dataclass(frozen=True)
class EncodersConfig:
    """The two joint encoders.

    Attributes:
        proximal: the hip encoder.
        distal: the knee encoder.
    """

    proximal: EncoderConfig = field(default_factory=EncoderConfig)
    distal: EncoderConfig = field(default_factory=lambda: EncoderConfig(spi=SpiConfig(chip_select=1)))


@dataclass(frozen=True)
class BeltConfig:
    """The treadmill drum's incremental encoder, counted by an LS7366R (SPI mode 0).

    Attributes:
        spi: where the LS7366R is wired.
        counts_per_rev: counts per drum revolution at the chosen quadrature (x4: 4 x the encoder's lines).
        quadrature: 1, 2 or 4 counts per encoder line cycle.
        drum_radius_mm: radius of the drum the belt wraps, to the belt's neutral line (mm).
        direction: +1 if the count grows when the belt moves backward (the foot pushing it, the reward
            direction), -1 otherwise.
    """

    spi: SpiConfig = field(default_factory=lambda: SpiConfig(bus=1))
    counts_per_rev: float = 4096.0
    quadrature: int = 4
    drum_radius_mm: float = 25.0
    direction: int = 1

    def __post_init__(self) -> None:
        require_positive(self.counts_per_rev, "counts_per_rev")
        require(self.quadrature in (1, 2, 4), "quadrature", f"must be 1, 2 or 4, got {self.quadrature!r}")
        require_positive(self.drum_radius_mm, "drum_radius_mm")
        _require_direction(self.direction, "direction")


@dataclass(frozen=True)
class PwmConfig:
    """The PWM set-value signals of the three motor drivers and the activation-to-duty map.

    duty = duty_at_zero + activation * (duty_at_full - duty_at_zero); "off" is duty 0 on every channel.

    Attributes:
        backend: "pca9685" (I2C PWM controller) or "sysfs" (the SoC's PWM through /sys/class/pwm).
        frequency_hz: PWM frequency (Hz); the PCA9685 reaches 24..1526 Hz.
        channels: PWM channel of M0, M1, M2 (PCA9685 outputs 0..15, or sysfs pwmM numbers).
        duty_at_zero: duty cycle (0..1) the motor drivers read as zero current (e.g. 0.1 for ESCON-style
            10-90 % set values).
        duty_at_full: duty cycle (0..1) they read as the maximal current (activation 1).
        i2c_bus: PCA9685 backend: the I2C bus number (1 = GPIO 2/3).
        address: PCA9685 backend: 7-bit I2C address.
        invert: PCA9685 backend: invert the outputs (for an inverting level shifter).
        sysfs_root: sysfs backend: the PWM class directory.
        sysfs_chip: sysfs backend: N of pwmchipN.
    """

    backend: PwmBackend = PwmBackend.PCA9685
    frequency_hz: float = 1000.0
    channels: tuple[int, int, int] = (0, 1, 2)
    duty_at_zero: float = 0.1
    duty_at_full: float = 0.9
    i2c_bus: int = 1
    address: int = 0x40
    invert: bool = False
    sysfs_root: str = "/sys/class/pwm"
    sysfs_chip: int = 0

    def __post_init__(self) -> None:
        require_positive(self.frequency_hz, "frequency_hz")
        if self.backend is PwmBackend.PCA9685:
            try:
                prescale_for(self.frequency_hz)
            except ValueError as err:
                raise ConfigError(str(err)) from err
            require(
                all(0 <= c < N_CHANNELS for c in self.channels),
                "channels",
                f"must be PCA9685 outputs 0..15, got {list(self.channels)}",
            )
            _require_int_range(self.address, 0x40, 0x7F, "address")
        require(len(set(self.channels)) == 3, "channels", f"must be 3 distinct channels, got {self.channels}")
        require(min(self.channels) >= 0, "channels", f"must be >= 0, got {list(self.channels)}")
        for name in ("duty_at_zero", "duty_at_full"):
            v = getattr(self, name)
            require(math.isfinite(v) and 0.0 <= v <= 1.0, name, f"must be in [0, 1], got {v!r}")
        # Off is duty 0 on every channel: it must command no more than zero current.
        require(
            self.duty_at_zero < self.duty_at_full,
            "duty_at_full",
            f"must exceed duty_at_zero ({self.duty_at_zero}), got {self.duty_at_full!r} (for an inverting "
            "stage set invert: true instead)",
        )

    def duty(self, activation: float) -> float:
        """The duty cycle (0..1) for an activation (0..1)."""
        return self.duty_at_zero + activation * (self.duty_at_full - self.duty_at_zero)

    def activation(self, duty: float) -> float:
        """The activation a duty cycle commands (inverse of `duty`, not clipped)."""
        return (duty - self.duty_at_zero) / (self.duty_at_full - self.duty_at_zero)


@dataclass(frozen=True)
class MotorEnableConfig:
    """The GPIO line enabling the three motor drivers (wire a pull-down so a released line disables them).

    Attributes:
        chip: GPIO chip device (the Pi 4 and Pi 5 40-pin header: /dev/gpiochip0).
        line: line offset on that chip (BCM GPIO number on the Pi).
        active_low: the drivers are enabled by a low level.
    """

    chip: str = "/dev/gpiochip0"
    line: int = 17
    active_low: bool = False

    def __post_init__(self) -> None:
        require(bool(self.chip), "chip", "must name a GPIO chip device")
        _require_int_range(self.line, 0, 511, "line")


@dataclass(frozen=True)
class CurrentSensorsConfig:
    """Three INA219 measuring the supply current and voltage of each motor driver.

    Attributes:
        i2c_bus: I2C bus number.
        addresses: 7-bit addresses of the INA219 of M0, M1, M2 (0x40..0x4F, set by A1/A0).
        shunt_ohm: shunt resistor (ohm).
        max_current_a: largest supply current to measure (A); sets range and resolution.
    """

    i2c_bus: int = 1
    addresses: tuple[int, int, int] = (0x41, 0x44, 0x45)
    shunt_ohm: float = 0.1
    max_current_a: float = 3.2

    def __post_init__(self) -> None:
        require(
            all(0x40 <= a <= 0x4F for a in self.addresses) and len(set(self.addresses)) == 3,
            "addresses",
            f"must be 3 distinct addresses in 0x40..0x4F, got {[hex(a) for a in self.addresses]}",
        )
        require_positive(self.shunt_ohm, "shunt_ohm")
        require_positive(self.max_current_a, "max_current_a")
        require(
            self.shunt_ohm * self.max_current_a <= 0.32 * (1 + 1e-9),
            "max_current_a",
            f"max_current_a * shunt_ohm = {self.shunt_ohm * self.max_current_a * 1e3:.0f} mV exceeds the "
            "INA219's 320 mV range",
        )


@dataclass(frozen=True)
class WiringConfig:
    """The physical rig: what is wired where and how raw readings become the plant's units.

    Attributes:
        encoders: the two joint encoders.
        belt: the treadmill drum counter.
        pwm: the motor drivers' set-value PWM.
        motor_enable: the drivers' enable line; null when the drivers have none (then "off" is duty 0).
        current_sensors: the three supply current monitors.
    """

    encoders: EncodersConfig = field(default_factory=EncodersConfig)
    belt: BeltConfig = field(default_factory=BeltConfig)
    pwm: PwmConfig = field(default_factory=PwmConfig)
    motor_enable: MotorEnableConfig | None = field(default_factory=MotorEnableConfig)
    current_sensors: CurrentSensorsConfig = field(default_factory=CurrentSensorsConfig)

    def __post_init__(self) -> None:
        pwm_i2c = self.pwm.backend is PwmBackend.PCA9685
        if pwm_i2c and self.pwm.i2c_bus == self.current_sensors.i2c_bus:
            require(
                self.pwm.address not in self.current_sensors.addresses,
                "current_sensors.addresses",
                f"{self.pwm.address:#04x} is the PCA9685's address on the same bus",
            )
        seen = [(e.spi.bus, e.spi.chip_select) for e in (self.encoders.proximal, self.encoders.distal)]
        seen.append((self.belt.spi.bus, self.belt.spi.chip_select))
        require(len(set(seen)) == 3, "encoders", f"the two encoders and the belt share a chip select: {seen}")


def wiring_from_dict(data: dict[str, Any]) -> WiringConfig:
    """Build and validate a WiringConfig from a mapping shaped like the YAML file.

    Raises:
        ConfigError: unknown or missing keys, wrong types or invalid values (the message names the field).
    """
    return _build(WiringConfig, data, "")


def load_wiring(path: str | Path) -> WiringConfig:
    """Read the rig's YAML file.

    Raises:
        ConfigError: the file is unreadable, not YAML, or describes an invalid rig (names the field).
    """
    try:
        text = Path(path).read_text()
    except OSError as err:
        raise ConfigError(f"wiring: cannot read {path}: {err}") from err
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(f"wiring: {path} is not valid YAML: {err}") from err
    if not isinstance(data, dict):
        raise ConfigError(f"wiring: {path} must hold a mapping of sections")
    return wiring_from_dict(data)


def _build(cls: type[T], data: object, path: str) -> T:
    if not isinstance(data, dict):
        raise ConfigError(f"{path or 'rig'}: must be a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - names)
    if unknown:
        raise ConfigError(f"{path}{unknown[0]}: unknown key (expected one of {sorted(names)})")
    values = {name: _convert(hints[name], data[name], f"{path}{name}") for name in names if name in data}
    try:
        return cls(**values)
    except ConfigError as err:
        raise ConfigError(f"{path}{err}") from err


def _convert(kind: Any, value: object, path: str) -> Any:
    origin = typing.get_origin(kind)
    if origin in (typing.Union, types.UnionType):
        options = [a for a in typing.get_args(kind) if a is not type(None)]
        return None if value is None else _convert(options[0], value, path)
    if dataclasses.is_dataclass(kind):
        return _build(kind, value, path + ".")  # type: ignore[arg-type]
    if isinstance(kind, type) and issubclass(kind, enum.Enum):
        try:
            return kind(value)
        except ValueError as err:
            raise ConfigError(f"{path}: must be one of {[m.value for m in kind]}, got {value!r}") from err
    if origin is tuple:
        args = typing.get_args(kind)
        if not isinstance(value, list | tuple) or len(value) != len(args):
            raise ConfigError(f"{path}: must be a list of {len(args)} values, got {value!r}")
        return tuple(_convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True)))
    if kind is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: must be true or false, got {value!r}")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: must be an integer, got {value!r}")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{path}: must be a number, got {value!r}")
        return float(value)
    if kind is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path}: must be a string, got {value!r}")
        return value
    raise TypeError(f"{path}: unsupported field type {kind!r}")  # a programming error, not a config error
