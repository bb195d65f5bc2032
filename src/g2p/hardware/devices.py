"""Opening the rig's devices: real Linux buses on the Pi, or any other `BusFactory` (the fakes in tests).

`open_devices(rig)` opens /dev/spidevN.M (spidev), /dev/i2c-N (smbus2), the enable line (gpiod 2.x) and
sysfs PWM, importing those libraries only when called, so the rest of the package imports anywhere.
`build_devices(rig, buses)` does the chip set-up for any bus factory: the same code runs against the
physics-backed fake rig of `g2p.hardware_fake.buses`.
"""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

from g2p.hardware.as5048a import AS5048A
from g2p.hardware.buses import I2cBus, OutputLine, SpiDevice
from g2p.hardware.errors import DeviceError, EncoderError
from g2p.hardware.ina219 import INA219
from g2p.hardware.ls7366r import LS7366R
from g2p.hardware.outputs import MotorOutputs, PwmOutputs
from g2p.hardware.pca9685 import PCA9685
from g2p.hardware.sysfs_pwm import SysfsPwmGroup
from g2p.hardware.wiring import MotorEnableConfig, PwmBackend, SpiConfig, WiringConfig

SPI_MODE_AS5048A = 1  # CPOL 0, CPHA 1
SPI_MODE_LS7366R = 0  # CPOL 0, CPHA 0
GPIO_CONSUMER = "g2p_driver"


class BusFactory(Protocol):
    """Opens the buses the devices sit on; the same bus number gives the same bus object."""

    def spi(self, config: SpiConfig, mode: int) -> SpiDevice:
        """Open a chip select in an SPI mode (0..3)."""
        ...

    def i2c(self, bus: int) -> I2cBus:
        """Open an I2C bus by number."""
        ...

    def output_line(self, config: MotorEnableConfig) -> OutputLine:
        """Request a GPIO line as an output, initially inactive."""
        ...

    def pwm_root(self, configured: str) -> Path:
        """The sysfs PWM class directory to use for the configured one."""
        ...

    def close(self) -> None:
        """Release every bus opened."""
        ...


@dataclass
class RigDevices:
    """The rig's devices, set up and with the motor outputs off.

    Attributes:
        encoders: proximal and distal joint encoders.
        belt: the treadmill drum counter.
        current_sensors: the INA219 of M0, M1, M2.
        outputs: the motor drivers' PWM and enable line.
        pwm_frequency_hz: the PWM frequency obtained (Hz).
        buses: the factory that opened the buses (closed last).
    """

    encoders: tuple[AS5048A, AS5048A]
    belt: LS7366R
    current_sensors: tuple[INA219, INA219, INA219]
    outputs: MotorOutputs
    pwm_frequency_hz: float
    buses: BusFactory

    def close(self) -> None:
        """Outputs off, then every bus released (even if switching off failed)."""
        try:
            self.outputs.close()
        finally:
            self.buses.close()


@contextlib.contextmanager
def _setting_up(name: str) -> Iterator[None]:
    """Turn a bus error while setting a chip up into a DeviceError naming the chip."""
    try:
        yield
    except (OSError, EncoderError) as err:
        text = str(err)
        raise DeviceError(text if text.startswith(name) else f"{name}: {text}") from err


def build_devices(wiring: WiringConfig, buses: BusFactory) -> RigDevices:
    """Set every chip up as `rig` describes, on the buses `buses` opens; motor outputs end off.

    The outputs first (a PWM chip keeps its last duty cycles across a crash of the process that set
    them): enable line requested inactive, every PWM channel off, frequency set. Then the encoders (error
    register cleared, magnet checked), the belt counter (x4 quadrature, read back, zeroed) and the
    current sensors (reset, configured, calibrated, read back).

    Raises:
        DeviceError: a chip is absent, fails a transaction or answers wrongly (the message names it and
            where it is wired).
    """
    try:
        line = None
        if wiring.motor_enable is not None:
            m = wiring.motor_enable
            with _setting_up(f"motor enable line ({m.chip} line {m.line})"):
                line = buses.output_line(m)
        p = wiring.pwm
        pwm: PwmOutputs
        if p.backend is PwmBackend.PCA9685:
            pca = PCA9685(
                buses.i2c(p.i2c_bus), p.address, name=f"PCA9685 ({p.address:#04x} on i2c-{p.i2c_bus})"
            )
            with _setting_up(pca.name):
                frequency = pca.configure(p.frequency_hz, p.invert)
            pwm = pca
        else:
            group = SysfsPwmGroup(buses.pwm_root(p.sysfs_root), p.sysfs_chip, p.channels)
            with _setting_up(f"sysfs PWM chip {p.sysfs_chip} channels {list(p.channels)}"):
                frequency = group.configure(p.frequency_hz)
            pwm = group
        outputs = MotorOutputs(pwm, p, line)

        encoders = tuple(
            AS5048A(
                buses.spi(e.spi, SPI_MODE_AS5048A),
                e.zero_offset_counts,
                e.direction,
                e.model,
                name=f"{joint} encoder (spi{e.spi.bus}.{e.spi.chip_select})",
            )
            for joint, e in (("proximal", wiring.encoders.proximal), ("distal", wiring.encoders.distal))
        )
        for enc in encoders:
            with _setting_up(enc.name):
                enc.clear_error()
                magnet = enc.read_magnet()
            if not magnet.ok:
                raise DeviceError(f"{enc.name}: magnet not usable: {magnet}")
        b = wiring.belt
        belt = LS7366R(
            buses.spi(b.spi, SPI_MODE_LS7366R), name=f"belt counter (spi{b.spi.bus}.{b.spi.chip_select})"
        )
        with _setting_up(belt.name):
            belt.configure(b.quadrature)
        cs = wiring.current_sensors
        i2c = buses.i2c(cs.i2c_bus)
        sensors = tuple(
            INA219(
                i2c,
                addr,
                cs.shunt_ohm,
                cs.max_current_a,
                name=f"M{i} current sensor ({addr:#04x} on i2c-{cs.i2c_bus})",
            )
            for i, addr in enumerate(cs.addresses)
        )
        for sensor in sensors:
            with _setting_up(sensor.name):
                sensor.configure()
    except BaseException:
        buses.close()
        raise
    return RigDevices(
        encoders=(encoders[0], encoders[1]),
        belt=belt,
        current_sensors=(sensors[0], sensors[1], sensors[2]),
        outputs=outputs,
        pwm_frequency_hz=frequency,
        buses=buses,
    )


def _import(module: str, hint: str) -> ModuleType:
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise DeviceError(f"cannot import {module} ({hint}): {err}") from err


class _GpiodLine:
    """A gpiod 2.x line request holding one output line."""

    def __init__(self, config: MotorEnableConfig) -> None:
        gpiod = _import("gpiod", "pip install gpiod==2.5.0, or apt install python3-libgpiod on 24.04+")
        line = _import("gpiod.line", "gpiod 2.x")
        self._value: Any = line.Value
        settings = gpiod.LineSettings(
            direction=line.Direction.OUTPUT, output_value=line.Value.INACTIVE, active_low=config.active_low
        )
        try:
            self._request: Any = gpiod.request_lines(
                config.chip, consumer=GPIO_CONSUMER, config={config.line: settings}
            )
        except OSError as err:
            raise DeviceError(f"cannot request GPIO line {config.line} of {config.chip}: {err}") from err
        self._line = config.line
        self._released = False

    def set_value(self, active: bool) -> None:
        """Drive the line active (True) or inactive (False)."""
        self._request.set_value(self._line, self._value.ACTIVE if active else self._value.INACTIVE)

    def close(self) -> None:
        """Release the line once (wire a pull-down: the released level is not guaranteed)."""
        if not self._released:
            self._released = True
            self._request.release()


class LinuxBuses:
    """Opens the Raspberry Pi's buses with spidev, smbus2 and gpiod (imported here, lazily)."""

    def __init__(self) -> None:
        self._spi: dict[tuple[int, int], Any] = {}
        self._i2c: dict[int, Any] = {}
        self._lines: list[_GpiodLine] = []

    def spi(self, config: SpiConfig, mode: int) -> SpiDevice:
        """Open /dev/spidev<bus>.<chip_select> in `mode` at the configured clock."""
        key = (config.bus, config.chip_select)
        if key not in self._spi:
            spidev = _import("spidev", "pip install spidev==3.8, or apt install python3-spidev")
            dev = spidev.SpiDev()
            try:
                dev.open(config.bus, config.chip_select)
            except OSError as err:
                raise DeviceError(
                    f"cannot open /dev/spidev{config.bus}.{config.chip_select}: {err} (enable the SPI "
                    "overlay in /boot/firmware/config.txt and add yourself to the spi group)"
                ) from err
            dev.max_speed_hz = config.max_speed_hz
            dev.mode = mode
            dev.bits_per_word = 8
            self._spi[key] = dev
        return self._spi[key]  # type: ignore[no-any-return]

    def i2c(self, bus: int) -> I2cBus:
        """Open /dev/i2c-<bus>."""
        if bus not in self._i2c:
            smbus2 = _import("smbus2", "pip install smbus2==0.6.1")
            try:
                self._i2c[bus] = smbus2.SMBus(bus)
            except OSError as err:
                raise DeviceError(
                    f"cannot open /dev/i2c-{bus}: {err} (dtparam=i2c_arm=on, and the i2c group)"
                ) from err
        return self._i2c[bus]  # type: ignore[no-any-return]

    def output_line(self, config: MotorEnableConfig) -> OutputLine:
        """Request the enable line as an output, inactive."""
        line = _GpiodLine(config)
        self._lines.append(line)
        return line

    def pwm_root(self, configured: str) -> Path:
        """The configured sysfs PWM directory, as is."""
        return Path(configured)

    def close(self) -> None:
        """Close every bus and line opened (errors while closing are ignored: nothing more can be done)."""
        for handle in [*self._spi.values(), *self._i2c.values(), *self._lines]:
            try:
                handle.close()
            except OSError:
                pass
        self._spi.clear()
        self._i2c.clear()
        self._lines.clear()


def open_devices(wiring: WiringConfig) -> RigDevices:
    """Open and set up the real devices of the rig described by `rig` (on the Raspberry Pi).

    Raises:
        DeviceError: a library is missing, a bus cannot be opened, or a chip answers wrongly.
        OSError: a bus transaction failed.
    """
    return build_devices(wiring, LinuxBuses())
