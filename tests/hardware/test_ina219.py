"""INA219 set-up and conversions, with the byte order on the wire checked against a fake chip."""

from __future__ import annotations

import pytest

from g2p.hardware import ina219 as ina
from g2p.hardware.errors import DeviceError
from g2p.hardware.ina219 import INA219, settings_for
from g2p.hardware_fake.chips import FakeINA219, FakeSMBus
from tests.hardware.fake_legs import RecordingChip


def bus_with(
    measure: list[tuple[float, float]], shunt: float = 0.1
) -> tuple[FakeSMBus, FakeINA219, RecordingChip]:
    chip = FakeINA219(shunt, lambda: measure[0])
    rec = RecordingChip(chip)
    bus = FakeSMBus(1)
    bus.chips[0x41] = rec  # type: ignore[assignment]
    return bus, chip, rec


def test_settings_known_answer_for_a_0_1_ohm_shunt_and_3_2_a() -> None:
    s = settings_for(0.1, 3.2)
    # 32 V range, PGA /8 (320 mV), 12-bit ADCs, continuous: the power-on configuration.
    assert s.config == 0x399F
    # Current_LSB = 3.2 / 2^15 = 97.66 uA; Cal = trunc(0.04096 / (97.66e-6 * 0.1)) = 4194.
    assert s.calibration == 4194
    assert s.current_lsb_a == pytest.approx(0.04096 / (4194 * 0.1))
    assert s.power_lsb_w == pytest.approx(20 * s.current_lsb_a)
    small = settings_for(0.1, 0.35)  # 35 mV: the +-40 mV range
    assert (small.config >> ina.PGA_SHIFT) & 0x3 == 0
    assert small.calibration % 2 == 0
    with pytest.raises(ValueError):
        settings_for(0.2, 3.2)  # 640 mV


def test_words_travel_msb_first_although_smbus_words_are_low_byte_first() -> None:
    measure = [(1.0, 12.0)]
    bus, chip, rec = bus_with(measure)
    device = INA219(bus, 0x41, 0.1, 3.2)
    device.configure()
    assert chip.config == 0x399F and chip.calibration == 4194
    assert ("w", [0x05, 0x10, 0x62]) in rec.wire  # 4194 = 0x1062, MSB first on the wire
    assert ("w", [0x00, 0x80, 0x00]) in rec.wire  # reset bit 15
    rec.wire.clear()
    # 1 A through 0.1 ohm = 10000 shunt counts; current register = 10000 * 4194 / 4096 = 10239.
    assert device.read_current_a() == pytest.approx(10239 * 0.04096 / (4194 * 0.1))
    assert rec.wire == [("w", [0x04]), ("r", [0x27, 0xFF])]
    assert device.read_current_a() == pytest.approx(1.0, abs=2 * device.settings.current_lsb_a)
    assert device.read_bus_voltage_v() == (pytest.approx(12.0), False)
    assert device.read_shunt_voltage_v() == pytest.approx(0.1)
    assert device.read_power_w() == pytest.approx(12.0, rel=0.01)


def test_negative_current_and_overflow_flag() -> None:
    measure = [(-0.5, 24.0)]
    bus, _, _ = bus_with(measure)
    device = INA219(bus, 0x41, 0.1, 3.2)
    device.configure()
    assert device.read_current_a() == pytest.approx(-0.5, abs=2 * device.settings.current_lsb_a)
    narrow = INA219(bus, 0x41, 0.1, 1.0)  # +-160 mV range, larger calibration
    narrow.configure()
    measure[0] = (2.0, 24.0)  # the shunt voltage saturates, the current register overflows
    assert narrow.read_bus_voltage_v()[1] is True


def test_configure_detects_a_chip_that_does_not_keep_the_values() -> None:
    bus, chip, _ = bus_with([(0.0, 0.0)])
    device = INA219(bus, 0x41, 0.1, 3.2)
    chip.write = lambda data: None  # type: ignore[method-assign]  # e.g. another chip at the address
    with pytest.raises(DeviceError, match="0x41"):
        device.configure()


def test_swap16() -> None:
    assert ina.swap16(0x1234) == 0x3412
    assert ina.to_signed16(0xFFFE) == -2
