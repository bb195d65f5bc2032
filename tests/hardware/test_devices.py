"""Device set-up on fake buses, and the Linux bus factory on fake spidev, smbus2 and gpiod modules."""

from __future__ import annotations

import enum
import sys
import types
from dataclasses import dataclass, replace
from typing import Any

import pytest

from g2p.hardware import DeviceError, WiringConfig, build_devices, open_devices
from g2p.hardware.wiring import MotorEnableConfig
from g2p.hardware_fake.buses import FakeBuses, FakeBusesConfig
from g2p.hardware_fake.chips import FaultKind

WIRING = WiringConfig()


def test_build_devices_sets_every_chip_up_and_leaves_the_outputs_off() -> None:
    fake = FakeBuses(WIRING)
    devices = build_devices(WIRING, fake)
    assert fake.pca is not None and fake.pca.regs[0xFE] == 5
    assert fake.enable_line is not None and fake.enable_line.active is False
    assert fake.outputs_state()["duty"] == [0.0, 0.0, 0.0]
    assert fake.counter.mdr0 == 0x03
    assert all(s.calibration == 4194 for s in fake.current_sensors)
    assert devices.pwm_frequency_hz == pytest.approx(1017.25, abs=0.01)
    devices.close()
    assert fake.closed and fake.pca.sleeping and fake.enable_line.released


@pytest.mark.parametrize(
    ("breakage", "message"),
    [
        (
            lambda f: f.current_sensors[1].faults.set(FaultKind.OSERROR, -1),
            "M1 current sensor \\(0x44 on i2c-1\\)",
        ),
        (lambda f: f.i2c_buses[1].chips.pop(0x40), "PCA9685 \\(0x40 on i2c-1\\)"),
        (lambda f: f.encoders[1].faults.set(FaultKind.ENCODER_PARITY, -1), "distal encoder \\(spi0.1\\)"),
        (lambda f: setattr(f.encoders[0], "diagnostics", 0x100 | 0x400), "proximal encoder.*magnet"),
        (lambda f: f._spi.pop((1, 0)), "belt counter \\(spi1.0\\)"),
    ],
)
def test_a_broken_chip_fails_the_set_up_naming_it_and_releases_the_buses(breakage: Any, message: str) -> None:
    fake = FakeBuses(WIRING)
    breakage(fake)
    with pytest.raises(DeviceError, match=message):
        build_devices(WIRING, fake)
    assert fake.closed


# ----------------------------------------------------------------------------------------------------
# Fake Linux libraries, exposing the FakeBuses's chips through spidev/smbus2/gpiod's APIs.


@dataclass
class Opened:
    spi: list[tuple[int, int, int, int]]
    i2c: list[int]
    lines: list[tuple[str, str, dict[int, Any]]]


def fake_linux_modules(fake: FakeBuses, opened: Opened) -> dict[str, types.ModuleType]:
    spidev = types.ModuleType("spidev")

    class SpiDev:
        def __init__(self) -> None:
            self.max_speed_hz = 500_000
            self.mode = 0
            self.bits_per_word = 8
            self._chip: Any = None

        def open(self, bus: int, device: int) -> None:
            if (bus, device) not in fake._spi:
                raise FileNotFoundError(2, f"No such file or directory: '/dev/spidev{bus}.{device}'")
            self._chip = fake._spi[(bus, device)]
            self._key = (bus, device)

        def xfer2(self, data: list[int]) -> list[int]:
            opened.spi.append((*self._key, self.mode, self.max_speed_hz))
            self._chip.mode = self.mode
            return self._chip.xfer2(data)  # type: ignore[no-any-return]

        def close(self) -> None:
            pass

    spidev.SpiDev = SpiDev  # type: ignore[attr-defined]

    smbus2 = types.ModuleType("smbus2")

    def smbus(bus: int) -> Any:
        opened.i2c.append(bus)
        return fake.i2c(bus)

    smbus2.SMBus = smbus  # type: ignore[attr-defined]

    gpiod = types.ModuleType("gpiod")
    line = types.ModuleType("gpiod.line")

    class Direction(enum.Enum):
        INPUT = 1
        OUTPUT = 2

    class Value(enum.Enum):
        INACTIVE = 0
        ACTIVE = 1

    @dataclass
    class LineSettings:
        direction: Direction = Direction.INPUT
        output_value: Value = Value.INACTIVE
        active_low: bool = False

    class Request:
        def __init__(self, offsets: list[int]) -> None:
            self.offsets = offsets
            self.released = False
            self.line = fake.output_line(MotorEnableConfig())

        def set_value(self, offset: int, value: Value) -> None:
            assert offset in self.offsets and not self.released
            self.line.set_value(value is Value.ACTIVE)

        def release(self) -> None:
            self.released = True
            self.line.close()

    def request_lines(path: str, consumer: str, config: dict[int, LineSettings]) -> Request:
        opened.lines.append((path, consumer, dict(config)))
        return Request(list(config))

    line.Direction = Direction  # type: ignore[attr-defined]
    line.Value = Value  # type: ignore[attr-defined]
    gpiod.LineSettings = LineSettings  # type: ignore[attr-defined]
    gpiod.request_lines = request_lines  # type: ignore[attr-defined]
    gpiod.line = line  # type: ignore[attr-defined]
    return {"spidev": spidev, "smbus2": smbus2, "gpiod": gpiod, "gpiod.line": line}


def test_open_devices_opens_the_configured_buses_modes_and_line(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = FakeBuses(WIRING)
    opened = Opened([], [], [])
    for name, module in fake_linux_modules(fake, opened).items():
        monkeypatch.setitem(sys.modules, name, module)
    devices = open_devices(WIRING)
    assert {(bus, cs, mode) for bus, cs, mode, _ in opened.spi} == {(0, 0, 1), (0, 1, 1), (1, 0, 0)}
    assert {speed for *_, speed in opened.spi} == {1_000_000}
    assert set(opened.i2c) == {1}
    [(path, consumer, config)] = opened.lines
    assert path == "/dev/gpiochip0" and consumer == "g2p_driver" and list(config) == [17]
    settings = config[17]
    assert settings.direction.name == "OUTPUT" and settings.output_value.name == "INACTIVE"
    assert settings.active_low is False
    assert fake.enable_line is not None and fake.enable_line.active is False
    devices.outputs.enable()
    assert fake.enable_line.active
    devices.close()
    assert fake.enable_line.released and not fake.enable_line.active


def test_open_devices_names_a_missing_library_or_bus(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = FakeBuses(WIRING)
    modules = fake_linux_modules(fake, Opened([], [], []))
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    monkeypatch.setitem(sys.modules, "spidev", None)
    with pytest.raises(DeviceError, match="spidev"):
        open_devices(WIRING)
    monkeypatch.setitem(sys.modules, "spidev", modules["spidev"])
    moved = replace(WIRING, belt=replace(WIRING.belt, spi=replace(WIRING.belt.spi, bus=3)))
    with pytest.raises(DeviceError, match=r"/dev/spidev3\.0"):
        open_devices(moved)


def test_the_sysfs_backend_on_the_fake_tree(tmp_path: Any) -> None:
    wiring = replace(WIRING, pwm=replace(WIRING.pwm, backend=WIRING.pwm.backend.SYSFS, frequency_hz=20000.0))
    fake = FakeBuses(wiring, FakeBusesConfig(state_dir=str(tmp_path)))
    devices = build_devices(wiring, fake)
    assert fake.sysfs is not None
    assert fake.sysfs.channel_state(1) == (50_000, 0, True)
    devices.outputs.apply(__import__("numpy").array([0.0, 0.5, 1.0]))
    assert fake.outputs_state()["duty"] == pytest.approx([0.1, 0.5, 0.9])
    devices.close()
    assert fake.sysfs.output_duty(1) == 0.0
