"""PCA9685 register sequences against a fake chip with the datasheet's MODE1/PRE_SCALE behaviour."""

from __future__ import annotations

import pytest

from g2p.hardware import pca9685 as pca
from g2p.hardware.pca9685 import PCA9685
from g2p.hardware_fake.chips import FakePCA9685, FakeSMBus
from tests.hardware.fake_legs import RecordingChip


def bus_with_chip(address: int = 0x40) -> tuple[FakeSMBus, FakePCA9685, RecordingChip]:
    chip = FakePCA9685()
    rec = RecordingChip(chip)
    bus = FakeSMBus(1)
    bus.chips[address] = rec  # type: ignore[assignment]
    return bus, chip, rec


def test_prescale_known_answers() -> None:
    assert pca.prescale_for(200.0) == 0x1E  # the power-on value is 200 Hz
    assert pca.prescale_for(1000.0) == 5
    assert pca.prescale_for(1526.0) == 3
    with pytest.raises(ValueError, match="frequency_hz"):
        pca.prescale_for(5000.0)


def test_led_registers_known_answers() -> None:
    assert pca.led_registers(0.0) == [0, 0, 0, 0x10]  # full off
    assert pca.led_registers(1.0) == [0, 0x10, 0, 0]  # full on
    assert pca.led_registers(0.5) == [0, 0, 0x00, 0x08]  # off at count 2048
    assert pca.duty_of([0, 0x10, 0, 0x10]) == 0.0  # full off wins
    with pytest.raises(ValueError):
        pca.led_registers(1.5)


def test_configure_sleeps_to_set_the_prescaler_then_restarts_with_auto_increment() -> None:
    bus, chip, rec = bus_with_chip()
    frequency = PCA9685(bus, sleep=lambda s: None).configure(1000.0)
    assert frequency == pytest.approx(25e6 / (4096 * 6))
    assert chip.regs[pca.REG_PRESCALE] == 5
    mode1 = chip.regs[pca.REG_MODE1]
    assert mode1 & pca.MODE1_AI and not mode1 & pca.MODE1_SLEEP
    writes = [d for kind, d in rec.wire if kind == "w" and len(d) == 2]
    assert [0xFD, 0x10] in writes  # all channels full off first
    i = writes.index([pca.REG_PRESCALE, 5])
    assert writes[i - 1][0] == pca.REG_MODE1 and writes[i - 1][1] & pca.MODE1_SLEEP


def test_prescale_written_while_awake_is_ignored_by_the_chip() -> None:
    bus, chip, _ = bus_with_chip()
    bus.write_byte_data(0x40, pca.REG_MODE1, pca.MODE1_AI)  # awake
    bus.write_byte_data(0x40, pca.REG_PRESCALE, 5)
    assert chip.regs[pca.REG_PRESCALE] == 0x1E


def test_duties_round_trip_through_four_byte_auto_increment_writes() -> None:
    bus, chip, rec = bus_with_chip()
    device = PCA9685(bus, sleep=lambda s: None)
    device.configure(1000.0)
    rec.wire.clear()
    device.set_duty(2, 0.25)
    assert rec.wire == [("w", [0x06 + 8, 0, 0, 0x00, 0x04])]
    assert chip.output_duty(2) == 0.25 and device.read_duty(2) == 0.25
    device.set_duty(3, 1.0)
    assert chip.output_duty(3) == 1.0
    device.all_off()
    assert all(chip.output_duty(c) == 0.0 for c in range(16))


def test_block_write_without_auto_increment_lands_in_one_register() -> None:
    bus, chip, _ = bus_with_chip()
    bus.write_i2c_block_data(0x40, 0x06, [1, 2, 3, 4])  # power-on MODE1: AI off
    assert chip.regs[0x06:0x0A] == [4, 0, 0, 0x10]


def test_sleep_stops_the_outputs_and_restart_resumes_them() -> None:
    bus, chip, _ = bus_with_chip()
    device = PCA9685(bus, sleep=lambda s: None)
    device.configure(1000.0)
    device.set_duty(0, 0.5)
    mode1 = chip.regs[pca.REG_MODE1]
    bus.write_byte_data(0x40, pca.REG_MODE1, mode1 | pca.MODE1_SLEEP)
    assert chip.output_duty(0) == 0.0 and chip.regs[pca.REG_MODE1] & pca.MODE1_RESTART
    bus.write_byte_data(0x40, pca.REG_MODE1, mode1)
    assert chip.output_duty(0) == 0.0  # awake, but not restarted yet
    bus.write_byte_data(0x40, pca.REG_MODE1, mode1 | pca.MODE1_RESTART)
    assert chip.output_duty(0) == 0.5 and not chip.regs[pca.REG_MODE1] & pca.MODE1_RESTART


def test_close_leaves_every_channel_off_and_the_chip_asleep() -> None:
    bus, chip, _ = bus_with_chip()
    device = PCA9685(bus, sleep=lambda s: None)
    device.configure(1000.0)
    device.set_duty(1, 0.7)
    device.close()
    assert chip.sleeping and all(chip.output_duty(c) == 0.0 for c in range(16))
    assert pca.duty_of(chip.channel_registers(1)) == 0.0


def test_absent_or_wrong_chip() -> None:
    bus, _, _ = bus_with_chip(0x41)
    with pytest.raises(OSError):
        PCA9685(bus, 0x40, sleep=lambda s: None).configure(1000.0)
